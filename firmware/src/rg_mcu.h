/*
 * The MCU's side of the protocol (docs/protocol.md §5-§7) as a pure state machine,
 * portable C99: decoded host frames (or their decode errors) and the time in, replies
 * and the outputs to apply out.  The same logic as relaxgrip.hardware.protocol.mcu.McuCore.
 */
#ifndef RG_MCU_H
#define RG_MCU_H

#include "rg_proto.h"

/* Status's LOAD_CELL bit stays set this long after a conversion (µs). */
#define RG_LOAD_CELL_FRESH_US 500000ul
/* An answer, plus an unsolicited Status when the watchdog expired first. */
#define RG_MAX_REPLIES 2

typedef struct {
    char firmware_id[RG_FIRMWARE_ID_BYTES];
    int32_t max_velocity_um_s;
    uint16_t watchdog_default_ms;
    uint16_t heater_duty_limit; /* permyriad, <= 10000 */
    uint8_t features;           /* RG_FEATURE_* */
} rg_mcu_config_t;

typedef struct {
    rg_mcu_config_t cfg;
    uint8_t handshaken;
    uint8_t enabled;
    uint8_t session_minor;
    uint16_t fault_flags;
    uint16_t watchdog_ms;
    uint32_t now_us;
    uint32_t last_feed_us;
    uint16_t last_seq;
    int32_t velocity_um_s;      /* setpoint */
    uint16_t heater_duty[2];    /* setpoint */
    uint16_t rx_error_count;
    uint16_t rx_gap_count;
    int32_t encoder_position_um; /* the caller keeps it current */
    int32_t load_cell_counts;
    uint32_t load_cell_time_us;
    uint16_t load_cell_samples;
    uint8_t load_cell_read; /* a conversion was read since power-up */
} rg_mcu_t;

typedef struct {
    uint8_t n;
    rg_msg_t msg[RG_MAX_REPLIES]; /* seq and version left for the sender to fill */
} rg_replies_t;

void rg_mcu_init(rg_mcu_t *m, const rg_mcu_config_t *cfg, uint32_t now_us);
/* Advance to now_us: trips the watchdog if it expired (an unsolicited Status). */
void rg_mcu_tick(rg_mcu_t *m, uint32_t now_us, rg_replies_t *out);
/* One decoded host frame (code == RG_OK) or a rejected one (err), at now_us. */
void rg_mcu_receive(rg_mcu_t *m, uint8_t code, const rg_msg_t *msg, const rg_frame_error_t *err,
                    uint32_t now_us, rg_replies_t *out);
/* A hardware trip fault (OVERTEMP, ENCODER, MOTOR_DRIVER): outputs off, unsolicited Status. */
void rg_mcu_fault(rg_mcu_t *m, uint16_t flag, uint32_t now_us, rg_replies_t *out);
/* A load-cell conversion read at now_us (raw 24-bit counts, sign-extended). */
void rg_mcu_load_cell(rg_mcu_t *m, int32_t counts, uint32_t now_us);
/* The outputs to apply: the setpoint while enabled, else zero. */
int32_t rg_mcu_velocity(const rg_mcu_t *m);
uint16_t rg_mcu_duty(const rg_mcu_t *m, uint8_t heater);

#endif
