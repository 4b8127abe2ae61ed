/* relaxgrip protocol core: see rg_proto.h and docs/protocol.md. */
#include "rg_proto.h"

#include <string.h>

/* ------------------------------------------------------------------ CRC and COBS */

uint16_t rg_crc16_update(uint16_t crc, const uint8_t *data, size_t n)
{
    /* CRC-16/CCITT-FALSE, bitwise: 0x1021, no reflection; no table keeps 512 bytes of flash. */
    for (size_t i = 0; i < n; i++) {
        crc ^= (uint16_t)((uint16_t)data[i] << 8);
        for (uint8_t b = 0; b < 8; b++)
            crc = (uint16_t)((crc & 0x8000u) ? (((unsigned)crc << 1) ^ 0x1021u)
                                             : ((unsigned)crc << 1));
    }
    return crc;
}

uint16_t rg_crc16(const uint8_t *data, size_t n) { return rg_crc16_update(0xFFFFu, data, n); }

size_t rg_cobs_encode(const uint8_t *in, size_t n, uint8_t *out)
{
    size_t code_at = 0, o = 1;
    uint8_t code = 1;
    uint8_t after_full_block = 0;
    for (size_t i = 0; i < n; i++) {
        after_full_block = 0;
        if (in[i] == 0) {
            out[code_at] = code;
            code_at = o++;
            code = 1;
        } else {
            out[o++] = in[i];
            if (++code == 0xFF) {
                out[code_at] = code;
                code_at = o++;
                code = 1;
                after_full_block = 1;
            }
        }
    }
    /* A 0xFF block implies no zero after it: input ending right after one needs no
     * final code byte (the canonical encoding). */
    if (after_full_block)
        return o - 1;
    out[code_at] = code;
    return o;
}

int rg_cobs_decode(const uint8_t *in, size_t n, uint8_t *out, size_t *out_n)
{
    size_t i = 0, o = 0;
    if (n == 0)
        return -1;
    while (i < n) {
        uint8_t code = in[i];
        if (code == 0 || (size_t)code > n - i)
            return -1;
        for (size_t k = 1; k < code; k++) {
            if (in[i + k] == 0)
                return -1;
            out[o++] = in[i + k];
        }
        i += code;
        if (code != 0xFF && i < n)
            out[o++] = 0;
    }
    *out_n = o;
    return 0;
}

/* ------------------------------------------------------------------ little-endian */

static void put16(uint8_t *p, uint16_t v)
{
    p[0] = (uint8_t)v;
    p[1] = (uint8_t)(v >> 8);
}
static void put32(uint8_t *p, uint32_t v)
{
    p[0] = (uint8_t)v;
    p[1] = (uint8_t)(v >> 8);
    p[2] = (uint8_t)(v >> 16);
    p[3] = (uint8_t)(v >> 24);
}
static uint16_t get16(const uint8_t *p) { return (uint16_t)(p[0] | ((uint16_t)p[1] << 8)); }
static uint32_t get32(const uint8_t *p)
{
    return (uint32_t)p[0] | ((uint32_t)p[1] << 8) | ((uint32_t)p[2] << 16) |
           ((uint32_t)p[3] << 24);
}

/* ------------------------------------------------------------------ layouts */

#define RG_NO_LAYOUT 0xFFu

/* Payload length by minor version: one column per minor; RG_NO_LAYOUT where a minor
 * left the type's layout as it was (docs/protocol.md §4, §12). */
static const uint8_t LAYOUTS[][1 + RG_PROTOCOL_MINOR + 1] = {
    {RG_HELLO, 0, 1},
    {RG_SET_MOTOR_VELOCITY, 4, RG_NO_LAYOUT},
    {RG_SET_HEATER_DUTY, 4, RG_NO_LAYOUT},
    {RG_SET_ENABLE, 1, RG_NO_LAYOUT},
    {RG_SET_WATCHDOG, 2, RG_NO_LAYOUT},
    {RG_COMMAND, 8, RG_NO_LAYOUT},
    {RG_GET_STATUS, 0, RG_NO_LAYOUT},
    {RG_HELLO_ACK, 24, 28},
    {RG_STATUS, 25, 35},
    {RG_ERROR, 6, RG_NO_LAYOUT},
};

uint8_t rg_payload_bytes(uint8_t type, uint8_t minor, uint8_t *ok)
{
    *ok = 0;
    if (minor > RG_PROTOCOL_MINOR)
        return 0;
    for (size_t i = 0; i < sizeof LAYOUTS / sizeof LAYOUTS[0]; i++) {
        if (LAYOUTS[i][0] != type)
            continue;
        uint8_t len = LAYOUTS[i][1 + minor];
        *ok = (uint8_t)(len != RG_NO_LAYOUT);
        return *ok ? len : 0;
    }
    return 0;
}

static int known_type(uint8_t type)
{
    uint8_t ok;
    rg_payload_bytes(type, 0, &ok);
    return ok;
}

/* The layout minor (<= minor) whose length is n, or -1. */
static int layout_of(uint8_t type, size_t n, uint8_t minor)
{
    for (uint8_t m = 0; m <= minor; m++) {
        uint8_t ok;
        uint8_t len = rg_payload_bytes(type, m, &ok);
        if (ok && len == n)
            return m;
    }
    return -1;
}

/* ------------------------------------------------------------------ decode */

static uint8_t fail(rg_frame_error_t *err, uint8_t code, uint16_t detail)
{
    err->code = code;
    err->detail = detail;
    return code;
}

uint8_t rg_decode_frame(uint8_t *enc, size_t n, uint8_t expected_version, uint8_t minor,
                        rg_msg_t *msg, rg_frame_error_t *err)
{
    uint8_t *raw = enc;
    size_t raw_n = 0;
    memset(err, 0, sizeof *err);
    if (n > RG_MAX_ENCODED_BYTES)
        return fail(err, RG_OVERSIZE, 0);
    if (rg_cobs_decode(enc, n, raw, &raw_n) != 0)
        return fail(err, RG_BAD_COBS, 0);
    if (raw_n < RG_HEADER_BYTES + RG_CRC_BYTES)
        return fail(err, RG_TOO_SHORT, 0);
    size_t body = raw_n - RG_CRC_BYTES;
    if (rg_crc16(raw, body) != get16(raw + body))
        return fail(err, RG_BAD_CRC, 0);
    err->has_header = 1;
    err->version = raw[0];
    err->type = raw[1];
    err->seq = get16(raw + 2);
    if (raw[0] != expected_version)
        return fail(err, RG_WRONG_VERSION, raw[0]);
    if (!known_type(raw[1]))
        return fail(err, RG_UNKNOWN_TYPE, raw[1]);
    const uint8_t *p = raw + RG_HEADER_BYTES;
    size_t len = body - RG_HEADER_BYTES;
    int layout = layout_of(raw[1], len, minor);
    if (layout < 0)
        return fail(err, RG_WRONG_LENGTH, (uint16_t)len);

    memset(msg, 0, sizeof *msg);
    msg->version = raw[0];
    msg->type = raw[1];
    msg->seq = err->seq;
    switch (msg->type) {
    case RG_HELLO:
        msg->u.hello.has_minor = (uint8_t)(len == 1);
        msg->u.hello.host_minor = len == 1 ? p[0] : 0;
        break;
    case RG_SET_MOTOR_VELOCITY: msg->u.velocity_um_s = (int32_t)get32(p); break;
    case RG_SET_HEATER_DUTY:
        msg->u.heater_duty[0] = get16(p);
        msg->u.heater_duty[1] = get16(p + 2);
        break;
    case RG_SET_ENABLE:
        if (p[0] > 1)
            return fail(err, RG_VALUE_OUT_OF_RANGE, p[0]);
        msg->u.enable = p[0];
        break;
    case RG_SET_WATCHDOG: msg->u.watchdog_ms = get16(p); break;
    case RG_COMMAND:
        msg->u.command.velocity_um_s = (int32_t)get32(p);
        msg->u.command.heater_duty[0] = get16(p + 4);
        msg->u.command.heater_duty[1] = get16(p + 6);
        break;
    case RG_GET_STATUS: break;
    case RG_HELLO_ACK: {
        rg_hello_ack_t *a = &msg->u.hello_ack;
        uint8_t end = RG_FIRMWARE_ID_BYTES;
        while (end > 0 && p[8 + end - 1] == 0)
            end--;
        for (uint8_t k = 0; k < end; k++)
            if (p[8 + k] < 0x20 || p[8 + k] >= 0x7F)
                return fail(err, RG_VALUE_OUT_OF_RANGE, 0);
        a->ack_seq = get16(p);
        a->watchdog_ms = get16(p + 2);
        a->max_velocity_um_s = (int32_t)get32(p + 4);
        memcpy(a->firmware_id, p + 8, end);
        a->layout_minor = (uint8_t)layout;
        if (layout >= 1) {
            a->mcu_minor = p[24];
            a->features = p[25];
            a->heater_duty_limit = get16(p + 26);
        }
        break;
    }
    case RG_STATUS: {
        rg_status_t *s = &msg->u.status;
        s->ack_seq = get16(p);
        s->mcu_time_us = get32(p + 2);
        s->encoder_position_um = (int32_t)get32(p + 6);
        s->velocity_um_s = (int32_t)get32(p + 10);
        s->heater_duty[0] = get16(p + 14);
        s->heater_duty[1] = get16(p + 16);
        s->fault_flags = get16(p + 18);
        s->state_flags = p[20];
        s->rx_error_count = get16(p + 21);
        s->rx_gap_count = get16(p + 23);
        s->layout_minor = (uint8_t)layout;
        if (layout >= 1) {
            s->load_cell_counts = (int32_t)get32(p + 25);
            s->load_cell_time_us = get32(p + 29);
            s->load_cell_samples = get16(p + 33);
        }
        break;
    }
    case RG_ERROR:
        msg->u.error.ack_seq = get16(p);
        msg->u.error.code = p[2];
        msg->u.error.offending_type = p[3];
        msg->u.error.detail = get16(p + 4);
        break;
    default: break; /* known_type() ruled it out */
    }
    err->code = RG_OK;
    return RG_OK;
}

/* ------------------------------------------------------------------ encode */

static size_t payload_of(const rg_msg_t *msg, uint8_t *p)
{
    switch (msg->type) {
    case RG_HELLO:
        if (!msg->u.hello.has_minor)
            return 0;
        p[0] = msg->u.hello.host_minor;
        return 1;
    case RG_SET_MOTOR_VELOCITY: put32(p, (uint32_t)msg->u.velocity_um_s); return 4;
    case RG_SET_HEATER_DUTY:
        put16(p, msg->u.heater_duty[0]);
        put16(p + 2, msg->u.heater_duty[1]);
        return 4;
    case RG_SET_ENABLE: p[0] = msg->u.enable; return 1;
    case RG_SET_WATCHDOG: put16(p, msg->u.watchdog_ms); return 2;
    case RG_COMMAND:
        put32(p, (uint32_t)msg->u.command.velocity_um_s);
        put16(p + 4, msg->u.command.heater_duty[0]);
        put16(p + 6, msg->u.command.heater_duty[1]);
        return 8;
    case RG_GET_STATUS: return 0;
    case RG_HELLO_ACK: {
        const rg_hello_ack_t *a = &msg->u.hello_ack;
        put16(p, a->ack_seq);
        put16(p + 2, a->watchdog_ms);
        put32(p + 4, (uint32_t)a->max_velocity_um_s);
        memcpy(p + 8, a->firmware_id, RG_FIRMWARE_ID_BYTES);
        if (a->layout_minor == 0)
            return 24;
        p[24] = a->mcu_minor;
        p[25] = a->features;
        put16(p + 26, a->heater_duty_limit);
        return 28;
    }
    case RG_STATUS: {
        const rg_status_t *s = &msg->u.status;
        put16(p, s->ack_seq);
        put32(p + 2, s->mcu_time_us);
        put32(p + 6, (uint32_t)s->encoder_position_um);
        put32(p + 10, (uint32_t)s->velocity_um_s);
        put16(p + 14, s->heater_duty[0]);
        put16(p + 16, s->heater_duty[1]);
        put16(p + 18, s->fault_flags);
        p[20] = s->state_flags;
        put16(p + 21, s->rx_error_count);
        put16(p + 23, s->rx_gap_count);
        if (s->layout_minor == 0)
            return 25;
        put32(p + 25, (uint32_t)s->load_cell_counts);
        put32(p + 29, s->load_cell_time_us);
        put16(p + 33, s->load_cell_samples);
        return 35;
    }
    case RG_ERROR:
        put16(p, msg->u.error.ack_seq);
        p[2] = msg->u.error.code;
        p[3] = msg->u.error.offending_type;
        put16(p + 4, msg->u.error.detail);
        return 6;
    default: return 0;
    }
}

size_t rg_encode_frame(const rg_msg_t *msg, uint8_t *out, size_t cap)
{
    uint8_t raw[RG_HEADER_BYTES + 35 + RG_CRC_BYTES]; /* the longest payload: Status, minor 1 */
    raw[0] = msg->version;
    raw[1] = msg->type;
    put16(raw + 2, msg->seq);
    size_t n = RG_HEADER_BYTES + payload_of(msg, raw + RG_HEADER_BYTES);
    put16(raw + n, rg_crc16(raw, n));
    n += RG_CRC_BYTES;
    if (cap < n + 2)
        return 0;
    size_t m = rg_cobs_encode(raw, n, out);
    out[m] = 0;
    return m + 1;
}

/* ------------------------------------------------------------------ receiver */

void rg_rx_init(rg_rx_t *rx)
{
    rx->len = 0;
    rx->skipping = 0;
    rx->ready = 0;
}

uint8_t rg_rx_byte(rg_rx_t *rx, uint8_t byte)
{
    if (rx->ready) {
        rx->len = 0;
        rx->ready = 0;
    }
    if (byte == 0) {
        uint8_t was_skipping = rx->skipping;
        rx->skipping = 0;
        if (was_skipping || rx->len == 0) {
            rx->len = 0;
            return RG_RX_NONE; /* the end of a skipped run, or an empty frame */
        }
        rx->ready = 1;
        return RG_RX_FRAME;
    }
    if (rx->skipping)
        return RG_RX_NONE;
    if (rx->len >= RG_MAX_ENCODED_BYTES) {
        rx->len = 0;
        rx->skipping = 1;
        return RG_RX_OVERSIZE;
    }
    rx->buf[rx->len++] = byte;
    return RG_RX_NONE;
}
