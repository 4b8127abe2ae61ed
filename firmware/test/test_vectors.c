/*
 * Host test of the protocol core against docs/protocol-vectors.json.
 *
 * Reads the vectors as flat lines (tests/firmware/test_host.py writes them from
 * the JSON) on stdin:
 *
 *   crc HEX CHECK
 *   cobs DECODED ENCODED                       (hex; "-" for none)
 *   valid INDEX TYPE SEQ MINOR FRAME FIELD...   (the frame with its delimiter)
 *   invalid INDEX CODE RECEIVER_MINOR HAS_HEADER VERSION TYPE SEQ FRAME
 *
 * Every valid frame must decode (whole, and byte by byte through the stream
 * receiver) to its type, seq, layout and fields, be refused by a receiver of an
 * older minor, and re-encode byte-identically; every invalid one must be
 * rejected with its error code and, past the CRC, its header.  Prints one line
 * per failure, "ok N" at the end; exit status 1 on any failure.
 */
#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "rg_proto.h"

static int failures;

#define CHECK(cond, ...)                                  \
    do {                                                  \
        if (!(cond)) {                                    \
            failures++;                                   \
            printf("FAIL %s:%d: ", __FILE__, __LINE__);   \
            printf(__VA_ARGS__);                          \
            printf("\n");                                 \
        }                                                 \
    } while (0)

static size_t unhex(const char *s, uint8_t *out, size_t cap)
{
    if (strcmp(s, "-") == 0)
        return 0;
    size_t n = strlen(s) / 2;
    if (n > cap) {
        printf("FAIL hex string too long\n");
        exit(2);
    }
    for (size_t i = 0; i < n; i++) {
        unsigned v;
        sscanf(s + 2 * i, "%2x", &v);
        out[i] = (uint8_t)v;
    }
    return n;
}

/* Fields of a decoded message, in the order the vector file lists them. */
static int fields_of(const rg_msg_t *m, int64_t *f, uint8_t *fw, size_t *fw_n)
{
    int n = 0;
    *fw_n = 0;
    switch (m->type) {
    case RG_HELLO:
        if (m->u.hello.has_minor)
            f[n++] = m->u.hello.host_minor;
        break;
    case RG_SET_MOTOR_VELOCITY: f[n++] = m->u.velocity_um_s; break;
    case RG_SET_HEATER_DUTY:
        f[n++] = m->u.heater_duty[0];
        f[n++] = m->u.heater_duty[1];
        break;
    case RG_SET_ENABLE: f[n++] = m->u.enable; break;
    case RG_SET_WATCHDOG: f[n++] = m->u.watchdog_ms; break;
    case RG_COMMAND:
        f[n++] = m->u.command.velocity_um_s;
        f[n++] = m->u.command.heater_duty[0];
        f[n++] = m->u.command.heater_duty[1];
        break;
    case RG_GET_STATUS: break;
    case RG_HELLO_ACK: {
        const rg_hello_ack_t *a = &m->u.hello_ack;
        f[n++] = a->ack_seq;
        f[n++] = a->watchdog_ms;
        f[n++] = a->max_velocity_um_s;
        while (*fw_n < RG_FIRMWARE_ID_BYTES && a->firmware_id[*fw_n])
            (*fw_n)++;
        memcpy(fw, a->firmware_id, *fw_n);
        if (a->layout_minor >= 1) {
            f[n++] = a->mcu_minor;
            f[n++] = a->features;
            f[n++] = a->heater_duty_limit;
        }
        break;
    }
    case RG_STATUS: {
        const rg_status_t *s = &m->u.status;
        f[n++] = s->ack_seq;
        f[n++] = s->mcu_time_us;
        f[n++] = s->encoder_position_um;
        f[n++] = s->velocity_um_s;
        f[n++] = s->heater_duty[0];
        f[n++] = s->heater_duty[1];
        f[n++] = s->fault_flags;
        f[n++] = s->state_flags;
        f[n++] = s->rx_error_count;
        f[n++] = s->rx_gap_count;
        if (s->layout_minor >= 1) {
            f[n++] = s->load_cell_counts;
            f[n++] = s->load_cell_time_us;
            f[n++] = s->load_cell_samples;
        }
        break;
    }
    case RG_ERROR:
        f[n++] = m->u.error.ack_seq;
        f[n++] = m->u.error.code;
        f[n++] = m->u.error.offending_type;
        f[n++] = m->u.error.detail;
        break;
    default: break;
    }
    return n;
}

static uint8_t layout_minor(const rg_msg_t *m)
{
    if (m->type == RG_HELLO)
        return m->u.hello.has_minor;
    if (m->type == RG_HELLO_ACK)
        return m->u.hello_ack.layout_minor;
    if (m->type == RG_STATUS)
        return m->u.status.layout_minor;
    return 0;
}

/* Feed a frame byte by byte; return the event at its delimiter and keep what rx holds. */
static uint8_t stream(rg_rx_t *rx, const uint8_t *frame, size_t n)
{
    uint8_t ev = RG_RX_NONE, last = RG_RX_NONE;
    for (size_t i = 0; i < n; i++) {
        ev = rg_rx_byte(rx, frame[i]);
        if (ev != RG_RX_NONE)
            last = ev;
    }
    return last;
}

static void valid(char *rest)
{
    int index;
    unsigned type, seq, minor;
    char hex[1024];
    int used = 0;
    sscanf(rest, "%d %u %u %u %1023s%n", &index, &type, &seq, &minor, hex, &used);
    uint8_t frame[600];
    size_t n = unhex(hex, frame, sizeof frame);
    int64_t want[16];
    int n_want = 0;
    uint8_t want_fw[32];
    size_t want_fw_n = 0;
    char *p = rest + used;
    char tok[128];
    int len;
    while (sscanf(p, "%127s%n", tok, &len) == 1) {
        p += len;
        if (tok[0] == 'h' && tok[1] == ':')
            want_fw_n = unhex(tok + 2, want_fw, sizeof want_fw);
        else
            want[n_want++] = strtoll(tok, NULL, 10);
    }

    uint8_t buf[600];
    memcpy(buf, frame, n);
    rg_msg_t msg;
    rg_frame_error_t err;
    uint8_t code = rg_decode_frame(buf, n - 1, RG_PROTOCOL_VERSION, RG_PROTOCOL_MINOR, &msg, &err);
    CHECK(code == RG_OK, "valid %d: decode error %u", index, code);
    if (code != RG_OK)
        return;
    CHECK(msg.type == type && msg.seq == seq && msg.version == RG_PROTOCOL_VERSION,
          "valid %d: header %u %u", index, msg.type, msg.seq);
    CHECK(layout_minor(&msg) == minor, "valid %d: layout minor %u, want %u", index,
          layout_minor(&msg), minor);
    int64_t got[16];
    uint8_t fw[RG_FIRMWARE_ID_BYTES];
    size_t fw_n;
    int n_got = fields_of(&msg, got, fw, &fw_n);
    CHECK(n_got == n_want, "valid %d: %d fields, want %d", index, n_got, n_want);
    for (int i = 0; i < n_got && i < n_want; i++)
        CHECK(got[i] == want[i], "valid %d: field %d is %" PRId64 ", want %" PRId64, index, i,
              got[i], want[i]);
    CHECK(fw_n == want_fw_n && memcmp(fw, want_fw, fw_n) == 0, "valid %d: firmware id", index);

    uint8_t again[600];
    size_t m = rg_encode_frame(&msg, again, sizeof again);
    CHECK(m == n && memcmp(again, frame, n) == 0, "valid %d: re-encodes to other bytes", index);
    CHECK(rg_encode_frame(&msg, again, n - 1) == 0, "valid %d: encodes into too little room",
          index);

    static rg_rx_t rx;
    rg_rx_init(&rx);
    CHECK(stream(&rx, frame, n) == RG_RX_FRAME && rx.len == n - 1 &&
              memcmp(rx.buf, frame, n - 1) == 0,
          "valid %d: the stream receiver does not return the frame", index);

    if (minor > 0) {
        memcpy(buf, frame, n);
        code = rg_decode_frame(buf, n - 1, RG_PROTOCOL_VERSION, (uint8_t)(minor - 1), &msg, &err);
        CHECK(code == RG_WRONG_LENGTH, "valid %d: a minor-%u receiver gives %u, not WRONG_LENGTH",
              index, minor - 1, code);
    }
}

static void invalid(char *rest)
{
    int index;
    unsigned code_want, minor, has_header, version, type, seq;
    char hex[2048];
    sscanf(rest, "%d %u %u %u %u %u %u %2047s", &index, &code_want, &minor, &has_header,
           &version, &type, &seq, hex);
    uint8_t frame[1024];
    size_t n = unhex(hex, frame, sizeof frame);
    static rg_rx_t rx;
    rg_rx_init(&rx);
    uint8_t ev = stream(&rx, frame, n);
    uint8_t code;
    rg_msg_t msg;
    rg_frame_error_t err;
    memset(&err, 0, sizeof err);
    if (ev == RG_RX_OVERSIZE) {
        code = RG_OVERSIZE;
    } else {
        CHECK(ev == RG_RX_FRAME, "invalid %d: the stream receiver returned %u", index, ev);
        code = rg_decode_frame(rx.buf, rx.len, RG_PROTOCOL_VERSION, (uint8_t)minor, &msg, &err);
    }
    CHECK(code == code_want, "invalid %d: error %u, want %u", index, code, code_want);
    CHECK(err.has_header == has_header, "invalid %d: has_header %u", index, err.has_header);
    if (has_header)
        CHECK(err.version == version && err.type == type && err.seq == seq,
              "invalid %d: header %u %u %u", index, err.version, err.type, err.seq);
    /* The whole frame at once must give the same error. */
    if (n - 1 <= RG_MAX_ENCODED_BYTES + 64) {
        uint8_t buf[1024];
        memcpy(buf, frame, n);
        uint8_t whole = rg_decode_frame(buf, n - 1, RG_PROTOCOL_VERSION, (uint8_t)minor, &msg,
                                        &err);
        CHECK(whole == code_want, "invalid %d: whole-frame error %u, want %u", index, whole,
              code_want);
    }
}

int main(void)
{
    char line[4096];
    int checked = 0;
    while (fgets(line, sizeof line, stdin)) {
        char kind[16];
        int used = 0;
        if (sscanf(line, "%15s%n", kind, &used) != 1)
            continue;
        char *rest = line + used;
        if (strcmp(kind, "crc") == 0) {
            char text[256];
            unsigned check;
            sscanf(rest, "%255s %x", text, &check);
            CHECK(rg_crc16((const uint8_t *)text, strlen(text)) == check, "crc of %s", text);
        } else if (strcmp(kind, "cobs") == 0) {
            char dec_hex[1200], enc_hex[1200];
            sscanf(rest, "%1199s %1199s", dec_hex, enc_hex);
            uint8_t dec[600], enc[600], out[600];
            size_t nd = unhex(dec_hex, dec, sizeof dec), ne = unhex(enc_hex, enc, sizeof enc);
            size_t m = rg_cobs_encode(dec, nd, out);
            CHECK(m == ne && memcmp(out, enc, ne) == 0, "cobs encode of %s", dec_hex);
            size_t md = 0;
            CHECK(rg_cobs_decode(enc, ne, out, &md) == 0 && md == nd &&
                      memcmp(out, dec, nd) == 0,
                  "cobs decode of %s", enc_hex);
        } else if (strcmp(kind, "valid") == 0) {
            valid(rest);
        } else if (strcmp(kind, "invalid") == 0) {
            invalid(rest);
        } else {
            printf("FAIL unknown line kind %s\n", kind);
            failures++;
        }
        checked++;
    }
    printf("%s %d\n", failures ? "failed" : "ok", checked);
    return failures ? 1 : 0;
}
