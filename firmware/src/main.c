/*
 * relaxgrip MCU firmware for the ATmega328P (Arduino Uno / Nano, 16 MHz).
 *
 * The hardware side of docs/protocol.md: the UART carries COBS frames (rg_proto),
 * the protocol's state machine (rg_mcu) decides, and this file drives the pins:
 *
 *   PD0/PD1  UART RX/TX               PD2/PD3  encoder A/B (INT0/INT1, x4 decoding)
 *   PD6      motor PWM (OC0A, L298N ENA)   PD7/PB0  motor direction (L298N IN1/IN2)
 *   PB1      heater 0 PWM (OC1A)      PB2      heater 1 PWM (OC1B)
 *   PC0      HX711 SCK                PC1      HX711 DOUT        PB5  LED: enabled
 *
 * Timer0: motor PWM, 8 bit, 7.8 kHz.  Timer1: heater PWM, TOP 9999 (ICR1), 200 Hz, so
 * a duty in permyriad is its compare value exactly.  Timer2: the 1 kHz time base.
 * Duty 0 and full duty disconnect the compare output and hold the pin low or high
 * (no one-count glitch at either end).
 *
 * The velocity loop tracks a reference position, the integral of the commanded
 * velocity, with a feed-forward duty and a PI on the position error, every
 * RG_CONTROL_PERIOD_MS: an encoder count of 5 µm is far too coarse to measure a
 * 0.1 mm/s velocity over 2 ms, but the position error it measures exactly.
 */
#include <avr/interrupt.h>
#include <avr/io.h>
#include <avr/sleep.h>
#include <string.h>
#include <util/delay.h>

#include "config.h"
#include "rg_mcu.h"
#include "rg_proto.h"

/* ------------------------------------------------------------------ time base */

static volatile uint32_t g_ms;
static volatile uint8_t g_control_due;

ISR(TIMER2_COMPA_vect)
{
    static uint8_t div;
    g_ms++;
    if (++div >= RG_CONTROL_PERIOD_MS) {
        div = 0;
        g_control_due = 1;
    }
}

static uint32_t micros(void)
{
    uint8_t sreg = SREG;
    cli();
    uint32_t ms = g_ms;
    uint8_t t = TCNT2;
    if ((TIFR2 & _BV(OCF2A)) && t < 249) /* the millisecond ended, its interrupt pending */
        ms++;
    SREG = sreg;
    return ms * 1000ul + (uint32_t)t * 4u; /* prescaler 64: 4 µs per count */
}

/* ------------------------------------------------------------------ UART */

#define RX_SIZE 128u
#define TX_SIZE 128u
static volatile uint8_t rx_buf[RX_SIZE], tx_buf[TX_SIZE];
static volatile uint8_t rx_head, rx_tail, tx_head, tx_tail;
static volatile uint16_t rx_overflows;
static uint16_t tx_dropped;

ISR(USART_RX_vect)
{
    uint8_t b = UDR0;
    uint8_t next = (uint8_t)((rx_head + 1u) & (RX_SIZE - 1u));
    if (next != rx_tail) {
        rx_buf[rx_head] = b;
        rx_head = next;
    } else {
        rx_overflows++;
    }
}

ISR(USART_UDRE_vect)
{
    if (tx_tail != tx_head) {
        UDR0 = tx_buf[tx_tail];
        tx_tail = (uint8_t)((tx_tail + 1u) & (TX_SIZE - 1u));
    } else {
        UCSR0B &= (uint8_t)~_BV(UDRIE0);
    }
}

static void uart_init(void)
{
    UCSR0A = _BV(U2X0);
    UBRR0 = (uint16_t)((F_CPU / 8ul + RG_BAUD / 2ul) / RG_BAUD - 1ul);
    UCSR0C = _BV(UCSZ01) | _BV(UCSZ00); /* 8N1 */
    UCSR0B = _BV(RXEN0) | _BV(TXEN0) | _BV(RXCIE0);
}

/* Queue a whole frame, or drop it whole (a flood of garbage outruns the line). */
static void uart_send(const uint8_t *data, uint8_t n)
{
    uint8_t used = (uint8_t)((tx_head - tx_tail) & (TX_SIZE - 1u));
    if ((uint8_t)(TX_SIZE - 1u - used) < n) {
        tx_dropped++;
        return;
    }
    for (uint8_t i = 0; i < n; i++) {
        tx_buf[tx_head] = data[i];
        tx_head = (uint8_t)((tx_head + 1u) & (TX_SIZE - 1u));
    }
    UCSR0B |= _BV(UDRIE0);
}

/* ------------------------------------------------------------------ encoder */

static volatile int32_t enc_count;
static volatile uint8_t enc_state, enc_errors;
/* (previous << 2 | current) of (A << 1 | B): +1 closing, -1 opening, 2 impossible. */
static const int8_t QDEC[16] = {0, -1, 1, 2, 1, 0, 2, -1, -1, 2, 0, 1, 2, 1, -1, 0};

ISR(INT0_vect)
{
    uint8_t s = (uint8_t)((PIND >> 2) & 3u);
    s = (uint8_t)(((s & 1u) << 1) | (s >> 1)); /* A on PD2 is the high bit */
    int8_t d = QDEC[(uint8_t)(enc_state << 2) | s];
    if (d == 2) {
        if (enc_errors < 255)
            enc_errors++;
    } else {
        enc_count += RG_ENCODER_SIGN * d;
    }
    enc_state = s;
}
ISR(INT1_vect, ISR_ALIASOF(INT0_vect));

static int32_t encoder_counts(void)
{
    uint8_t sreg = SREG;
    cli();
    int32_t c = enc_count;
    SREG = sreg;
    return c;
}

static int32_t counts_to_um(int32_t counts)
{
    return (int32_t)((int64_t)counts * RG_ENCODER_NM_PER_COUNT / 1000);
}

/* ------------------------------------------------------------------ PWM outputs */

static void motor_pwm(uint8_t counts, int8_t dir)
{
    /* IN1 high: closing; IN2 high: opening; both low with the enable low: coasting. */
    if (counts == 0 || dir == 0) {
        TCCR0A &= (uint8_t)~_BV(COM0A1);
        PORTD &= (uint8_t)~(_BV(PD6) | _BV(PD7));
        PORTB &= (uint8_t)~_BV(PB0);
        return;
    }
    if (dir > 0) {
        PORTB &= (uint8_t)~_BV(PB0);
        PORTD |= _BV(PD7);
    } else {
        PORTD &= (uint8_t)~_BV(PD7);
        PORTB |= _BV(PB0);
    }
    if (counts == 255) {
        TCCR0A &= (uint8_t)~_BV(COM0A1);
        PORTD |= _BV(PD6);
    } else {
        OCR0A = counts;
        TCCR0A |= _BV(COM0A1);
    }
}

static void heater_pwm(uint8_t k, uint16_t duty)
{
    uint8_t com = k ? _BV(COM1B1) : _BV(COM1A1);
    uint8_t pin = k ? _BV(PB2) : _BV(PB1);
    if (duty == 0 || duty >= RG_DUTY_FULL_SCALE) {
        TCCR1A &= (uint8_t)~com;
        if (duty)
            PORTB |= pin;
        else
            PORTB &= (uint8_t)~pin;
        return;
    }
    if (k)
        OCR1B = (uint16_t)(duty - 1u);
    else
        OCR1A = (uint16_t)(duty - 1u);
    TCCR1A |= com;
}

/* The duty the PWM drives, read back from the timer (docs/protocol.md §4: Status). */
static uint16_t heater_readback(uint8_t k)
{
    uint8_t com = k ? _BV(COM1B1) : _BV(COM1A1);
    uint8_t pin = k ? _BV(PB2) : _BV(PB1);
    if (TCCR1A & com)
        return (uint16_t)((k ? OCR1B : OCR1A) + 1u);
    return (PORTB & pin) ? RG_DUTY_FULL_SCALE : 0;
}

static void pwm_init(void)
{
    DDRD |= _BV(PD6) | _BV(PD7);
    DDRB |= _BV(PB0) | _BV(PB1) | _BV(PB2) | _BV(PB5);
    TCCR0A = _BV(WGM01) | _BV(WGM00); /* fast PWM, TOP 0xFF */
    TCCR0B = _BV(CS01);               /* /8: 7.8 kHz */
    ICR1 = RG_DUTY_FULL_SCALE - 1u;   /* fast PWM, TOP ICR1: 200 Hz at /8 */
    TCCR1A = _BV(WGM11);
    TCCR1B = _BV(WGM13) | _BV(WGM12) | _BV(CS11);
    TCCR2A = _BV(WGM21); /* CTC, 1 kHz */
    OCR2A = 249;
    TCCR2B = _BV(CS22);
    TIMSK2 = _BV(OCIE2A);
    motor_pwm(0, 0);
    heater_pwm(0, 0);
    heater_pwm(1, 0);
}

/* ------------------------------------------------------------------ velocity loop */

#define ERR_MAX_UM 2000l /* the reference waits for a motor this far behind */

/* The reference model's step: 1 - exp(-T/tau) to 1e-5 as T / (tau + T/2), Q16. */
#if RG_MOTOR_LAG_MS > 0
#define REF_ALPHA_Q16                                                                  \
    ((65536l * 2l * RG_CONTROL_PERIOD_MS + RG_MOTOR_LAG_MS + RG_CONTROL_PERIOD_MS / 2) / \
     (2l * RG_MOTOR_LAG_MS + RG_CONTROL_PERIOD_MS))
#else
#define REF_ALPHA_Q16 65536l
#endif

static struct {
    int32_t v_ref_q8;  /* reference velocity (µm/s, Q8): the command through the motor's lag */
    int32_t ref_nm;    /* reference position: the reference velocity integrated */
    int32_t i_um_ms;   /* integrated position error */
    uint32_t acc;      /* sigma-delta remainder of the 8-bit duty */
    uint8_t running;
} loop;

static void loop_reset(void)
{
    loop.ref_nm = counts_to_um(encoder_counts()) * 1000l;
    loop.v_ref_q8 = 0;
    loop.i_um_ms = 0;
    loop.acc = 0;
    loop.running = 0;
}

static void loop_step(int32_t v_um_s)
{
    int32_t pos_um = counts_to_um(encoder_counts());
    if (!loop.running) {
        loop_reset();
        loop.running = 1;
    }
    /* Model following: the reference moves as the motor answers the command (a first-order
     * lag of RG_MOTOR_LAG_MS) while the feed-forward is the command itself, so a motor
     * that behaves as modelled tracks the reference with no error, and a stop brings no
     * overshoot; the PI corrects what the model does not explain. */
    loop.v_ref_q8 += (int32_t)(((int64_t)v_um_s * 256 - loop.v_ref_q8) * REF_ALPHA_Q16 / 65536);
    loop.ref_nm += (loop.v_ref_q8 / 256) * RG_CONTROL_PERIOD_MS; /* µm/s · ms = nm */
    int32_t err_um = loop.ref_nm / 1000l - pos_um;
    if (err_um > ERR_MAX_UM || err_um < -ERR_MAX_UM) {
        err_um = err_um > 0 ? ERR_MAX_UM : -ERR_MAX_UM;
        loop.ref_nm = (pos_um + err_um) * 1000l;
        loop.v_ref_q8 = v_um_s * 256; /* a stalled motor: the model starts again from here */
    }
    int32_t i_lim = (int32_t)((int64_t)RG_I_MAX_PERMYRIAD * 1000000l / RG_KI_PERMYRIAD_PER_MM_S);
    /* The integral only learns while the motor holds or creeps: the error of a fast move
     * is the motor's lag, which the move's end takes back, and integrating it would
     * overshoot there. */
    if (v_um_s <= RG_I_VMAX_UM_S && v_um_s >= -RG_I_VMAX_UM_S)
        loop.i_um_ms += err_um * RG_CONTROL_PERIOD_MS;
    if (loop.i_um_ms > i_lim)
        loop.i_um_ms = i_lim;
    if (loop.i_um_ms < -i_lim)
        loop.i_um_ms = -i_lim;
    int32_t duty = (int32_t)((int64_t)v_um_s * RG_DUTY_FULL_SCALE / RG_MOTOR_FULL_SPEED_UM_S) +
                   err_um * RG_KP_PERMYRIAD_PER_MM / 1000l +
                   (int32_t)((int64_t)loop.i_um_ms * RG_KI_PERMYRIAD_PER_MM_S / 1000000l);
    if (duty > (int32_t)RG_DUTY_FULL_SCALE)
        duty = RG_DUTY_FULL_SCALE;
    if (duty < -(int32_t)RG_DUTY_FULL_SCALE)
        duty = -(int32_t)RG_DUTY_FULL_SCALE;
    /* 8-bit PWM, dithered so that the mean duty keeps 1e-4 resolution. */
    uint32_t mag = (uint32_t)(duty < 0 ? -duty : duty);
    loop.acc += mag * 255u;
    uint8_t counts = (uint8_t)(loop.acc / RG_DUTY_FULL_SCALE);
    loop.acc %= RG_DUTY_FULL_SCALE;
    motor_pwm(counts, (int8_t)(duty > 0 ? 1 : duty < 0 ? -1 : 0));
}

/* ------------------------------------------------------------------ HX711 */

#if RG_LOAD_CELL
static uint8_t hx711_ready(void) { return !(PINC & _BV(PC1)); }

/* 24 bits MSB first, then a 25th pulse: channel A, gain 128, for the next conversion.
 * Interrupts are held off while SCK is high: above 60 µs the HX711 powers down. */
static int32_t hx711_read(void)
{
    uint32_t v = 0;
    for (uint8_t i = 0; i < 25; i++) {
        uint8_t sreg = SREG;
        cli();
        PORTC |= _BV(PC0);
        _delay_us(1);
        uint8_t bit = (uint8_t)((PINC >> PC1) & 1u);
        PORTC &= (uint8_t)~_BV(PC0);
        SREG = sreg;
        if (i < 24)
            v = (v << 1) | bit;
        _delay_us(1);
    }
    if (v & 0x800000ul)
        v |= 0xFF000000ul; /* sign-extend */
    return (int32_t)v;
}
#endif

/* ------------------------------------------------------------------ protocol */

static rg_mcu_t mcu;
static rg_rx_t rx;
static uint16_t tx_seq;

static void send_replies(rg_replies_t *r)
{
    uint8_t frame[48]; /* the longest: Status of minor 1, 41 raw bytes */
    for (uint8_t i = 0; i < r->n; i++) {
        rg_msg_t *m = &r->msg[i];
        m->seq = tx_seq++;
        if (m->type == RG_STATUS) {
            m->u.status.heater_duty[0] = heater_readback(0);
            m->u.status.heater_duty[1] = heater_readback(1);
        }
        size_t n = rg_encode_frame(m, frame, sizeof frame);
        if (n)
            uart_send(frame, (uint8_t)n);
    }
    r->n = 0;
}

static void apply_outputs(void)
{
    heater_pwm(0, rg_mcu_duty(&mcu, 0));
    heater_pwm(1, rg_mcu_duty(&mcu, 1));
    if (!mcu.enabled) {
        motor_pwm(0, 0);
        loop.running = 0;
        PORTB &= (uint8_t)~_BV(PB5);
    } else {
        PORTB |= _BV(PB5);
    }
}

static void handle_byte(uint8_t b, rg_replies_t *r)
{
    uint8_t ev = rg_rx_byte(&rx, b);
    if (ev == RG_RX_NONE)
        return;
    rg_msg_t msg;
    rg_frame_error_t err;
    uint8_t code;
    if (ev == RG_RX_OVERSIZE) {
        memset(&err, 0, sizeof err);
        code = err.code = RG_OVERSIZE;
    } else {
        code = rg_decode_frame(rx.buf, rx.len, RG_PROTOCOL_VERSION, RG_PROTOCOL_MINOR, &msg, &err);
    }
    mcu.encoder_position_um = counts_to_um(encoder_counts());
    uint16_t errors_before = mcu.rx_error_count;
    rg_mcu_receive(&mcu, code, &msg, &err, micros(), r);
    if (code == RG_OK && msg.type == RG_SET_ENABLE && mcu.rx_error_count == errors_before) {
        /* An accepted SetEnable starts afresh: the loop from where the motor is, the
         * encoder's error count from zero (its fault was cleared). */
        loop.running = 0;
        enc_errors = 0;
    }
    apply_outputs(); /* a Command's duties and a trip's zeros take effect now */
    send_replies(r);
}

int main(void)
{
    static const rg_mcu_config_t cfg = {
        .firmware_id = RG_FIRMWARE_ID,
        .max_velocity_um_s = RG_MAX_VELOCITY_UM_S,
        .watchdog_default_ms = RG_WATCHDOG_DEFAULT_MS_CFG,
        .heater_duty_limit = RG_HEATER_DUTY_LIMIT,
        .features = RG_LOAD_CELL ? RG_FEATURE_LOAD_CELL : 0,
    };
    rg_replies_t replies = {0};

    pwm_init();
    uart_init();
    PORTD |= _BV(PD2) | _BV(PD3); /* encoder inputs with pull-ups */
    enc_state = (uint8_t)((((PIND >> 2) & 1u) << 1) | ((PIND >> 3) & 1u));
    EICRA = _BV(ISC10) | _BV(ISC00); /* any change */
    EIMSK = _BV(INT1) | _BV(INT0);
#if RG_LOAD_CELL
    DDRC |= _BV(PC0);
    PORTC &= (uint8_t)~_BV(PC0);
    PORTC |= _BV(PC1); /* DOUT pulled up: no HX711 reads as never ready */
#endif
    rg_mcu_init(&mcu, &cfg, 0);
    rg_rx_init(&rx);
    set_sleep_mode(SLEEP_MODE_IDLE);
    sei();

    for (;;) {
        while (rx_tail != rx_head) {
            uint8_t b = rx_buf[rx_tail];
            rx_tail = (uint8_t)((rx_tail + 1u) & (RX_SIZE - 1u));
            handle_byte(b, &replies);
        }
        uint32_t now = micros();
        if (enc_errors >= RG_ENCODER_MAX_ERRORS && mcu.enabled)
            rg_mcu_fault(&mcu, RG_FAULT_ENCODER, now, &replies);
        rg_mcu_tick(&mcu, now, &replies);
        if (replies.n) { /* a trip: outputs off at once, then the unsolicited Status */
            apply_outputs();
            mcu.encoder_position_um = counts_to_um(encoder_counts());
            send_replies(&replies);
        }
        if (g_control_due) {
            g_control_due = 0;
            if (mcu.enabled)
                loop_step(rg_mcu_velocity(&mcu));
        }
#if RG_LOAD_CELL
        if (hx711_ready())
            rg_mcu_load_cell(&mcu, hx711_read(), micros());
#endif
        cli();
        if (rx_tail == rx_head && !g_control_due) {
            sleep_enable();
            sei(); /* the instruction after sei runs first: no wake-up lost */
            sleep_cpu();
            sleep_disable();
        }
        sei();
    }
}
