/* The MCU state machine: see rg_mcu.h and docs/protocol.md §5-§7, §12. */
#include "rg_mcu.h"

#include <string.h>

void rg_mcu_init(rg_mcu_t *m, const rg_mcu_config_t *cfg, uint32_t now_us)
{
    memset(m, 0, sizeof *m);
    m->cfg = *cfg;
    m->fault_flags = RG_FAULT_RESET;
    m->watchdog_ms = cfg->watchdog_default_ms;
    m->now_us = now_us;
    m->last_feed_us = now_us;
}

int32_t rg_mcu_velocity(const rg_mcu_t *m) { return m->enabled ? m->velocity_um_s : 0; }

uint16_t rg_mcu_duty(const rg_mcu_t *m, uint8_t heater)
{
    return m->enabled ? m->heater_duty[heater & 1u] : 0;
}

static rg_msg_t *push(rg_replies_t *out, uint8_t type)
{
    rg_msg_t *msg = &out->msg[out->n++];
    memset(msg, 0, sizeof *msg);
    msg->version = RG_PROTOCOL_VERSION;
    msg->type = type;
    return msg;
}

static void status(rg_mcu_t *m, uint16_t ack_seq, uint8_t unsolicited, rg_replies_t *out)
{
    rg_status_t *s = &push(out, RG_STATUS)->u.status;
    s->ack_seq = ack_seq;
    s->mcu_time_us = m->now_us;
    s->encoder_position_um = m->encoder_position_um;
    s->velocity_um_s = rg_mcu_velocity(m);
    s->heater_duty[0] = rg_mcu_duty(m, 0);
    s->heater_duty[1] = rg_mcu_duty(m, 1);
    s->fault_flags = m->fault_flags;
    s->state_flags = (uint8_t)((m->enabled ? RG_STATE_ENABLED : 0u) |
                               (unsolicited ? RG_STATE_UNSOLICITED : 0u));
    s->rx_error_count = m->rx_error_count;
    s->rx_gap_count = m->rx_gap_count;
    s->layout_minor = m->session_minor >= 1 ? 1 : 0;
    if (s->layout_minor) {
        if (m->load_cell_read && (uint32_t)(m->now_us - m->load_cell_time_us) <
                                     RG_LOAD_CELL_FRESH_US)
            s->state_flags |= RG_STATE_LOAD_CELL;
        s->load_cell_counts = m->load_cell_counts;
        s->load_cell_time_us = m->load_cell_time_us;
        s->load_cell_samples = m->load_cell_samples;
    }
}

static void reject(rg_mcu_t *m, uint8_t code, uint16_t seq, uint8_t type, uint16_t detail,
                   rg_replies_t *out)
{
    rg_error_reply_t *e = &push(out, RG_ERROR)->u.error;
    m->rx_error_count++;
    e->ack_seq = seq;
    e->code = code;
    e->offending_type = type;
    e->detail = detail;
}

static void trip(rg_mcu_t *m, uint16_t flag, rg_replies_t *out)
{
    m->fault_flags |= flag;
    m->enabled = 0;
    m->velocity_um_s = 0;
    m->heater_duty[0] = m->heater_duty[1] = 0;
    status(m, m->last_seq, 1, out);
}

static void set_flag(rg_mcu_t *m, uint16_t flag, uint8_t on)
{
    m->fault_flags = on ? (uint16_t)(m->fault_flags | flag) : (uint16_t)(m->fault_flags & ~flag);
}

static void advance(rg_mcu_t *m, uint32_t now_us)
{
    /* The clock only moves forward (wrapping at 2^32 µs, as the wire's). */
    if ((int32_t)(now_us - m->now_us) > 0)
        m->now_us = now_us;
}

void rg_mcu_tick(rg_mcu_t *m, uint32_t now_us, rg_replies_t *out)
{
    advance(m, now_us);
    if (m->enabled && (uint32_t)(m->now_us - m->last_feed_us) >= (uint32_t)m->watchdog_ms * 1000u)
        trip(m, RG_FAULT_WATCHDOG, out);
}

void rg_mcu_fault(rg_mcu_t *m, uint16_t flag, uint32_t now_us, rg_replies_t *out)
{
    advance(m, now_us);
    if (flag & RG_TRIP_FAULTS) {
        trip(m, flag, out);
    } else {
        m->fault_flags |= flag;
        status(m, m->last_seq, 1, out);
    }
}

void rg_mcu_load_cell(rg_mcu_t *m, int32_t counts, uint32_t now_us)
{
    if (!(m->cfg.features & RG_FEATURE_LOAD_CELL))
        return;
    if (counts > 0x7FFFFFl)
        counts = 0x7FFFFFl;
    if (counts < -0x800000l)
        counts = -0x800000l;
    m->load_cell_counts = counts;
    m->load_cell_time_us = now_us;
    m->load_cell_samples++;
    m->load_cell_read = 1;
}

static void handle(rg_mcu_t *m, const rg_msg_t *msg, rg_replies_t *out)
{
    uint16_t seq = msg->seq;
    uint8_t type = msg->type;
    if (type == RG_HELLO) {
        uint8_t host_minor = msg->u.hello.has_minor ? msg->u.hello.host_minor : 0;
        m->handshaken = 1;
        m->enabled = 0;
        m->velocity_um_s = 0;
        m->heater_duty[0] = m->heater_duty[1] = 0;
        m->watchdog_ms = m->cfg.watchdog_default_ms;
        m->last_seq = seq;
        /* The session speaks the older of the two minor versions (§12). */
        m->session_minor = host_minor < RG_PROTOCOL_MINOR ? host_minor : RG_PROTOCOL_MINOR;
        rg_hello_ack_t *a = &push(out, RG_HELLO_ACK)->u.hello_ack;
        a->ack_seq = seq;
        a->watchdog_ms = m->watchdog_ms;
        a->max_velocity_um_s = m->cfg.max_velocity_um_s;
        memcpy(a->firmware_id, m->cfg.firmware_id, RG_FIRMWARE_ID_BYTES);
        a->layout_minor = m->session_minor >= 1 ? 1 : 0;
        a->mcu_minor = RG_PROTOCOL_MINOR;
        a->features = m->cfg.features;
        a->heater_duty_limit = m->cfg.heater_duty_limit;
        return;
    }
    if (type & 0x80u) { /* an MCU -> host type sent to the MCU */
        reject(m, RG_UNKNOWN_TYPE, seq, type, type, out);
        return;
    }
    if (!m->handshaken) {
        reject(m, RG_NO_HANDSHAKE, seq, type, 0, out);
        return;
    }
    uint16_t diff = (uint16_t)(seq - m->last_seq);
    if (diff == 0) { /* a retransmission: answered, not applied twice */
        status(m, seq, 0, out);
        return;
    }
    if (diff >= 0x8000u) {
        reject(m, RG_STALE_SEQUENCE, seq, type, m->last_seq, out);
        return;
    }
    m->rx_gap_count = (uint16_t)(m->rx_gap_count + diff - 1u);
    m->last_seq = seq;
    switch (type) {
    case RG_GET_STATUS: status(m, seq, 0, out); return;
    case RG_SET_ENABLE:
        m->velocity_um_s = 0;
        m->heater_duty[0] = m->heater_duty[1] = 0;
        if (msg->u.enable) {
            m->fault_flags = 0; /* latched faults cleared; nothing commanded yet */
            m->last_feed_us = m->now_us;
        }
        m->enabled = msg->u.enable;
        status(m, seq, 0, out);
        return;
    case RG_SET_WATCHDOG:
        if (msg->u.watchdog_ms < RG_WATCHDOG_MIN_MS || msg->u.watchdog_ms > RG_WATCHDOG_MAX_MS) {
            reject(m, RG_VALUE_OUT_OF_RANGE, seq, type, msg->u.watchdog_ms, out);
            return;
        }
        m->watchdog_ms = msg->u.watchdog_ms;
        m->last_feed_us = m->now_us;
        status(m, seq, 0, out);
        return;
    default: break;
    }
    /* motion and heater commands */
    if (!m->enabled) {
        reject(m, RG_NOT_ENABLED, seq, type, m->fault_flags, out);
        return;
    }
    if (type == RG_SET_MOTOR_VELOCITY || type == RG_COMMAND) {
        int32_t v = type == RG_COMMAND ? msg->u.command.velocity_um_s : msg->u.velocity_um_s;
        int32_t vmax = m->cfg.max_velocity_um_s;
        int32_t c = v > vmax ? vmax : v < -vmax ? -vmax : v;
        set_flag(m, RG_FAULT_VELOCITY_CLAMPED, (uint8_t)(c != v));
        m->velocity_um_s = c;
    }
    if (type == RG_SET_HEATER_DUTY || type == RG_COMMAND) {
        const uint16_t *d = type == RG_COMMAND ? msg->u.command.heater_duty : msg->u.heater_duty;
        uint16_t limit = m->cfg.heater_duty_limit;
        uint8_t clamped = 0;
        for (uint8_t k = 0; k < 2; k++) {
            m->heater_duty[k] = d[k] > limit ? limit : d[k];
            clamped |= (uint8_t)(d[k] > limit);
        }
        set_flag(m, RG_FAULT_DUTY_CLAMPED, clamped);
    }
    m->last_feed_us = m->now_us;
    status(m, seq, 0, out);
}

void rg_mcu_receive(rg_mcu_t *m, uint8_t code, const rg_msg_t *msg, const rg_frame_error_t *err,
                    uint32_t now_us, rg_replies_t *out)
{
    rg_mcu_tick(m, now_us, out);
    if (code != RG_OK) {
        /* Only a frame whose CRC passed has a trustworthy seq and type (§8). */
        reject(m, code, err->has_header ? err->seq : 0, err->has_header ? err->type : 0,
               err->detail, out);
        return;
    }
    handle(m, msg, out);
}
