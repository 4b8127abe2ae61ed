/*
 * Fuzz of the protocol core and the MCU state machine, for the host under
 * -fsanitize=address,undefined (tests/firmware/test_host.py builds and runs it).
 *
 *   fuzz_proto N SEED
 *
 * N inputs, each one of: random bytes; a valid frame of a random message, mutated
 * (bit flips, truncation, insertion, a changed byte); a valid frame as is.  Each goes
 * to the single-frame decoder (which must accept a valid frame, and whose every accepted
 * message must re-encode and decode to itself) and, byte by byte with its delimiter,
 * through the stream receiver into the state machine, whose replies must encode and
 * decode and whose outputs must stay within the limits.  Any crash or out-of-bounds
 * access is the sanitizers' to report.  Prints "fuzzed N inputs" on success.
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "rg_mcu.h"
#include "rg_proto.h"

static uint64_t rng_state;

static uint32_t rnd(void)
{
    /* xorshift64*: seeded, the same run every time */
    rng_state ^= rng_state >> 12;
    rng_state ^= rng_state << 25;
    rng_state ^= rng_state >> 27;
    return (uint32_t)((rng_state * 2685821657736338717ull) >> 32);
}

static void fail(const char *what, long input)
{
    printf("FAIL input %ld: %s\n", input, what);
    exit(1);
}

static void random_message(rg_msg_t *m)
{
    static const uint8_t types[] = {RG_HELLO,     RG_SET_MOTOR_VELOCITY, RG_SET_HEATER_DUTY,
                                    RG_SET_ENABLE, RG_SET_WATCHDOG,      RG_COMMAND,
                                    RG_GET_STATUS, RG_HELLO_ACK,         RG_STATUS,
                                    RG_ERROR};
    memset(m, 0, sizeof *m);
    m->version = RG_PROTOCOL_VERSION;
    m->type = types[rnd() % sizeof types];
    m->seq = (uint16_t)rnd();
    switch (m->type) {
    case RG_HELLO:
        m->u.hello.has_minor = (uint8_t)(rnd() & 1u);
        m->u.hello.host_minor = m->u.hello.has_minor ? (uint8_t)rnd() : 0;
        break;
    case RG_SET_MOTOR_VELOCITY: m->u.velocity_um_s = (int32_t)rnd(); break;
    case RG_SET_HEATER_DUTY:
        m->u.heater_duty[0] = (uint16_t)rnd();
        m->u.heater_duty[1] = (uint16_t)rnd();
        break;
    case RG_SET_ENABLE: m->u.enable = (uint8_t)(rnd() & 1u); break;
    case RG_SET_WATCHDOG: m->u.watchdog_ms = (uint16_t)rnd(); break;
    case RG_COMMAND:
        m->u.command.velocity_um_s = (int32_t)rnd();
        m->u.command.heater_duty[0] = (uint16_t)(rnd() % 12000u);
        m->u.command.heater_duty[1] = (uint16_t)rnd();
        break;
    case RG_HELLO_ACK: {
        rg_hello_ack_t *a = &m->u.hello_ack;
        a->ack_seq = (uint16_t)rnd();
        a->watchdog_ms = (uint16_t)rnd();
        a->max_velocity_um_s = (int32_t)rnd();
        uint8_t len = (uint8_t)(rnd() % (RG_FIRMWARE_ID_BYTES + 1));
        for (uint8_t k = 0; k < len; k++)
            a->firmware_id[k] = (char)(0x20 + rnd() % 95u);
        a->layout_minor = (uint8_t)(rnd() & 1u);
        if (a->layout_minor) {
            a->mcu_minor = (uint8_t)rnd();
            a->features = (uint8_t)rnd();
            a->heater_duty_limit = (uint16_t)rnd();
        }
        break;
    }
    case RG_STATUS: {
        rg_status_t *s = &m->u.status;
        s->ack_seq = (uint16_t)rnd();
        s->mcu_time_us = rnd();
        s->encoder_position_um = (int32_t)rnd();
        s->velocity_um_s = (int32_t)rnd();
        s->heater_duty[0] = (uint16_t)rnd();
        s->heater_duty[1] = (uint16_t)rnd();
        s->fault_flags = (uint16_t)rnd();
        s->state_flags = (uint8_t)rnd();
        s->rx_error_count = (uint16_t)rnd();
        s->rx_gap_count = (uint16_t)rnd();
        s->layout_minor = (uint8_t)(rnd() & 1u);
        if (s->layout_minor) {
            s->load_cell_counts = (int32_t)rnd();
            s->load_cell_time_us = rnd();
            s->load_cell_samples = (uint16_t)rnd();
        }
        break;
    }
    case RG_ERROR:
        m->u.error.ack_seq = (uint16_t)rnd();
        m->u.error.code = (uint8_t)rnd();
        m->u.error.offending_type = (uint8_t)rnd();
        m->u.error.detail = (uint16_t)rnd();
        break;
    default: break;
    }
}

/* A message decoded from a frame must encode to a frame that decodes to it again. */
static void round_trip(const rg_msg_t *m, long input)
{
    uint8_t frame[300], frame2[300];
    rg_msg_t back;
    rg_frame_error_t err;
    size_t n = rg_encode_frame(m, frame, sizeof frame);
    if (n < 2 || frame[n - 1] != 0)
        fail("a decoded message does not encode", input);
    for (size_t i = 0; i + 1 < n; i++)
        if (frame[i] == 0)
            fail("an encoded frame holds a zero before its delimiter", input);
    memcpy(frame2, frame, n);
    if (rg_decode_frame(frame2, n - 1, RG_PROTOCOL_VERSION, RG_PROTOCOL_MINOR, &back, &err) !=
        RG_OK)
        fail("a re-encoded frame does not decode", input);
    uint8_t again[300];
    size_t n2 = rg_encode_frame(&back, again, sizeof again);
    if (n2 != n || memcmp(again, frame, n) != 0)
        fail("decode . encode is not the identity", input);
}

static rg_mcu_t mcu;
static rg_rx_t rx;
static uint32_t now_us;

static void to_mcu(const uint8_t *data, size_t n, long input)
{
    for (size_t i = 0; i < n; i++) {
        uint8_t ev = rg_rx_byte(&rx, data[i]);
        now_us += rnd() % 3000u; /* 0..3 ms between bytes: the watchdog trips now and then */
        rg_replies_t replies;
        replies.n = 0;
        if (ev == RG_RX_NONE) {
            rg_mcu_tick(&mcu, now_us, &replies);
        } else {
            rg_msg_t msg;
            rg_frame_error_t err;
            memset(&err, 0, sizeof err);
            uint8_t code = RG_OVERSIZE;
            if (ev == RG_RX_FRAME)
                code = rg_decode_frame(rx.buf, rx.len, RG_PROTOCOL_VERSION, RG_PROTOCOL_MINOR,
                                       &msg, &err);
            else
                err.code = RG_OVERSIZE;
            rg_mcu_receive(&mcu, code, &msg, &err, now_us, &replies);
            if (replies.n < 1)
                fail("a frame got no answer", input);
        }
        if (replies.n > RG_MAX_REPLIES)
            fail("too many replies", input);
        for (uint8_t k = 0; k < replies.n; k++)
            round_trip(&replies.msg[k], input);
        int32_t v = rg_mcu_velocity(&mcu);
        if (v > mcu.cfg.max_velocity_um_s || v < -mcu.cfg.max_velocity_um_s)
            fail("velocity beyond the limit", input);
        if (rg_mcu_duty(&mcu, 0) > mcu.cfg.heater_duty_limit ||
            rg_mcu_duty(&mcu, 1) > mcu.cfg.heater_duty_limit)
            fail("duty beyond the limit", input);
        if (!mcu.enabled && (v != 0 || rg_mcu_duty(&mcu, 0) || rg_mcu_duty(&mcu, 1)))
            fail("outputs on while disabled", input);
    }
}

int main(int argc, char **argv)
{
    long n = argc > 1 ? atol(argv[1]) : 100000;
    rng_state = argc > 2 ? (uint64_t)atoll(argv[2]) * 0x9E3779B97F4A7C15ull + 1u : 1u;
    static const rg_mcu_config_t cfg = {"relaxgrip-fuzz", 20000, 200, 6000,
                                        RG_FEATURE_LOAD_CELL};
    rg_mcu_init(&mcu, &cfg, 0);
    rg_rx_init(&rx);
    long accepted = 0;
    for (long input = 0; input < n; input++) {
        uint8_t buf[600];
        size_t len;
        uint32_t kind = rnd() % 4u;
        if (kind == 0) { /* random bytes, zeros rare */
            len = rnd() % 300u;
            for (size_t i = 0; i < len; i++)
                buf[i] = (uint8_t)((rnd() % 64u) ? rnd() | 1u : rnd());
        } else {
            rg_msg_t m;
            random_message(&m);
            len = rg_encode_frame(&m, buf, sizeof buf) - 1; /* without the delimiter */
            if (kind == 1) {
                rg_msg_t back;
                rg_frame_error_t err;
                uint8_t copy[300];
                memcpy(copy, buf, len);
                if (rg_decode_frame(copy, len, RG_PROTOCOL_VERSION, RG_PROTOCOL_MINOR, &back,
                                    &err) != RG_OK)
                    fail("a valid frame is rejected", input);
            } else {
                uint32_t ops = 1 + rnd() % 4u;
                for (uint32_t k = 0; k < ops && len > 0; k++) {
                    switch (rnd() % 4u) {
                    case 0: buf[rnd() % len] ^= (uint8_t)(1u << (rnd() % 8u)); break;
                    case 1: len = rnd() % len; break;
                    case 2:
                        if (len < 500) {
                            size_t at = rnd() % (len + 1);
                            memmove(buf + at + 1, buf + at, len - at);
                            buf[at] = (uint8_t)rnd();
                            len++;
                        }
                        break;
                    default: buf[rnd() % len] = (uint8_t)rnd(); break;
                    }
                }
            }
        }
        /* The decoder alone, on the bytes before any zero (what a receiver would pass it). */
        size_t upto = 0;
        while (upto < len && buf[upto] != 0)
            upto++;
        uint8_t copy[600];
        memcpy(copy, buf, upto);
        rg_msg_t msg;
        rg_frame_error_t err;
        uint8_t code = rg_decode_frame(copy, upto, RG_PROTOCOL_VERSION,
                                       (uint8_t)(rnd() % (RG_PROTOCOL_MINOR + 1)), &msg, &err);
        if (code == RG_OK) {
            accepted++;
            round_trip(&msg, input);
        } else if (code > RG_NOT_ENABLED) {
            fail("an unknown error code", input);
        }
        /* The stream: the bytes, then a delimiter. */
        buf[len++] = 0;
        to_mcu(buf, len, input);
    }
    printf("fuzzed %ld inputs (%ld decoded)\n", n, accepted);
    return 0;
}
