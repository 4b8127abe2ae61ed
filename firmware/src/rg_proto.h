/*
 * relaxgrip host <-> MCU protocol core (docs/protocol.md), portable C99.
 *
 * Framing (COBS, 0x00 delimiter), CRC-16/CCITT-FALSE, the message layouts of
 * every minor version, single-frame encode/decode and a byte-stream receiver.
 * No I/O, no clock, no heap: the firmware (avr-gcc) and the host tests (gcc)
 * compile this same file.
 */
#ifndef RG_PROTO_H
#define RG_PROTO_H

#include <stddef.h>
#include <stdint.h>

#define RG_PROTOCOL_VERSION 1u /* byte 0 of every frame: the major version */
#define RG_PROTOCOL_MINOR 1u   /* newest minor version this code speaks */

#define RG_HEADER_BYTES 4u
#define RG_CRC_BYTES 2u
#define RG_MAX_RAW_BYTES 254u     /* header + payload + CRC: one COBS block */
#define RG_MAX_ENCODED_BYTES 255u /* COBS-encoded, without the delimiter */
#define RG_FIRMWARE_ID_BYTES 16u
#define RG_DUTY_FULL_SCALE 10000u
#define RG_WATCHDOG_DEFAULT_MS 200u
#define RG_WATCHDOG_MIN_MS 20u
#define RG_WATCHDOG_MAX_MS 2000u

enum rg_type {
    RG_HELLO = 0x01,
    RG_SET_MOTOR_VELOCITY = 0x02,
    RG_SET_HEATER_DUTY = 0x03,
    RG_SET_ENABLE = 0x04,
    RG_SET_WATCHDOG = 0x05,
    RG_COMMAND = 0x06,
    RG_GET_STATUS = 0x07,
    RG_HELLO_ACK = 0x81,
    RG_STATUS = 0x82,
    RG_ERROR = 0x83
};

/* Error codes (docs/protocol.md §8); RG_OK is not on the wire. */
enum rg_error {
    RG_OK = 0,
    RG_BAD_COBS = 1,
    RG_BAD_CRC = 2,
    RG_TOO_SHORT = 3,
    RG_OVERSIZE = 4,
    RG_WRONG_VERSION = 5,
    RG_UNKNOWN_TYPE = 6,
    RG_WRONG_LENGTH = 7,
    RG_VALUE_OUT_OF_RANGE = 8,
    RG_NO_HANDSHAKE = 9,
    RG_STALE_SEQUENCE = 10,
    RG_NOT_ENABLED = 11
};

/* Status.fault_flags (§9). */
#define RG_FAULT_WATCHDOG (1u << 0)
#define RG_FAULT_RESET (1u << 1)
#define RG_FAULT_VELOCITY_CLAMPED (1u << 2)
#define RG_FAULT_DUTY_CLAMPED (1u << 3)
#define RG_FAULT_OVERTEMP (1u << 4)
#define RG_FAULT_ENCODER (1u << 5)
#define RG_FAULT_MOTOR_DRIVER (1u << 6)
#define RG_TRIP_FAULTS \
    (RG_FAULT_WATCHDOG | RG_FAULT_OVERTEMP | RG_FAULT_ENCODER | RG_FAULT_MOTOR_DRIVER)

/* Status.state_flags. */
#define RG_STATE_ENABLED (1u << 0)
#define RG_STATE_UNSOLICITED (1u << 1)
#define RG_STATE_LOAD_CELL (1u << 2) /* minor 1 */

/* HelloAck.features (minor 1). */
#define RG_FEATURE_LOAD_CELL (1u << 0)

typedef struct {
    uint8_t has_minor; /* 0: the minor-0 Hello without payload */
    uint8_t host_minor;
} rg_hello_t;

typedef struct {
    uint16_t ack_seq;
    uint16_t watchdog_ms;
    int32_t max_velocity_um_s;
    char firmware_id[RG_FIRMWARE_ID_BYTES]; /* NUL-padded, not NUL-terminated when full */
    uint8_t layout_minor;                   /* 0: 24 bytes; 1: 28 bytes */
    uint8_t mcu_minor;
    uint8_t features;
    uint16_t heater_duty_limit;
} rg_hello_ack_t;

typedef struct {
    uint16_t ack_seq;
    uint32_t mcu_time_us;
    int32_t encoder_position_um;
    int32_t velocity_um_s;
    uint16_t heater_duty[2];
    uint16_t fault_flags;
    uint8_t state_flags;
    uint16_t rx_error_count;
    uint16_t rx_gap_count;
    uint8_t layout_minor; /* 0: 25 bytes; 1: 35 bytes */
    int32_t load_cell_counts;
    uint32_t load_cell_time_us;
    uint16_t load_cell_samples;
} rg_status_t;

typedef struct {
    uint16_t ack_seq;
    uint8_t code;
    uint8_t offending_type;
    uint16_t detail;
} rg_error_reply_t;

/* One message with its header fields. */
typedef struct {
    uint8_t version;
    uint8_t type;
    uint16_t seq;
    union {
        rg_hello_t hello;
        int32_t velocity_um_s;      /* SetMotorVelocity */
        uint16_t heater_duty[2];    /* SetHeaterDuty */
        uint8_t enable;             /* SetEnable: 0 or 1 */
        uint16_t watchdog_ms;       /* SetWatchdog */
        struct {
            int32_t velocity_um_s;
            uint16_t heater_duty[2];
        } command;
        rg_hello_ack_t hello_ack;
        rg_status_t status;
        rg_error_reply_t error;
    } u;
} rg_msg_t;

/* Why a frame was rejected, and the header fields when its CRC made them trustworthy. */
typedef struct {
    uint8_t code;       /* enum rg_error */
    uint8_t has_header; /* version, type and seq are valid (the CRC passed) */
    uint8_t version;
    uint8_t type;
    uint16_t seq;
    uint16_t detail; /* what an MCU puts in Error.detail */
} rg_frame_error_t;

uint16_t rg_crc16_update(uint16_t crc, const uint8_t *data, size_t n);
uint16_t rg_crc16(const uint8_t *data, size_t n);

/* COBS of n <= RG_MAX_RAW_BYTES bytes into out (room for n + 1); returns its length. */
size_t rg_cobs_encode(const uint8_t *in, size_t n, uint8_t *out);
/* Inverse of rg_cobs_encode into out (room for n bytes; out may be in); 0 on success,
 * -1 on bad COBS. */
int rg_cobs_decode(const uint8_t *in, size_t n, uint8_t *out, size_t *out_n);

/* Payload length of a type's layout of minor `minor`, 0 with *ok = 0 if there is none. */
uint8_t rg_payload_bytes(uint8_t type, uint8_t minor, uint8_t *ok);

/*
 * Decode one COBS-encoded frame (delimiter stripped), checking in the order of
 * §8: size, COBS, length, CRC, version, type, payload length (the layouts of
 * minor versions up to `minor`), field values.  Returns RG_OK and fills msg,
 * or the error code and fills err.  The frame is decoded in place: enc is
 * overwritten (COBS never writes ahead of what it has read), so that an MCU
 * needs no second frame buffer.
 */
uint8_t rg_decode_frame(uint8_t *enc, size_t n, uint8_t expected_version, uint8_t minor,
                        rg_msg_t *msg, rg_frame_error_t *err);

/*
 * Encode msg (its header fields, and the layout_minor of a HelloAck or a
 * Status) as COBS + 0x00 into out; returns the bytes written, 0 if cap is too small.
 */
size_t rg_encode_frame(const rg_msg_t *msg, uint8_t *out, size_t cap);

/* Byte-stream receiver: collects one encoded frame up to its delimiter. */
typedef struct {
    uint8_t buf[RG_MAX_ENCODED_BYTES];
    uint16_t len;
    uint8_t skipping; /* after an OVERSIZE, until the next delimiter */
    uint8_t ready;    /* buf holds the frame just returned */
} rg_rx_t;

enum rg_rx_event { RG_RX_NONE = 0, RG_RX_FRAME = 1, RG_RX_OVERSIZE = 2 };

void rg_rx_init(rg_rx_t *rx);
/* Feed one byte.  RG_RX_FRAME: rx->buf[0 .. rx->len) holds a frame (valid until the
 * next call); RG_RX_OVERSIZE: more than 255 bytes without a delimiter, skipped. */
uint8_t rg_rx_byte(rg_rx_t *rx, uint8_t byte);

#endif
