/*
 * rgsim: the relaxgrip firmware in simavr, as a small C library for the host.
 *
 * relaxgrip.hardware.firmware_sim loads it with ctypes.  It runs the unmodified
 * firmware ELF on simavr's ATmega328P and wires the board around it:
 *
 *   UART0        host bytes in at the line rate (simavr paces them), bytes out kept
 *   PD6 PD7 PB0  motor enable (PWM) and direction: levels integrated in cycles
 *   PB1 PB2      heater PWM: levels integrated in cycles
 *   PD2 PD3      quadrature encoder: edges at the cycles the host asks for
 *   PC0 PC1      an HX711: conversions pushed by the host, shifted out on SCK
 *
 * A pin's level is what the hardware drives: the timer's waveform while the compare
 * output is connected (TCCRnA COMnx1), else the PORT bit; it is re-evaluated whenever
 * the waveform, TCCR0A, TCCR1A or a PORT register changes, so every edge is exact to
 * the cycle.  simavr's sleep callback, which would usleep() to keep wall-clock pace,
 * is replaced: a sleeping AVR jumps straight to its next timer event.
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <simavr/avr_ioport.h>
#include <simavr/avr_timer.h>
#include <simavr/avr_uart.h>
#include <simavr/sim_avr.h>
#include <simavr/sim_elf.h>
#include <simavr/sim_io.h>
#include <simavr/sim_irq.h>

/* ATmega328P data addresses */
#define A_PORTB 0x25
#define A_PORTC 0x28
#define A_PORTD 0x2B
#define A_TCCR0A 0x44
#define A_TCCR1A 0x80

enum { PIN_MOTOR_EN, PIN_MOTOR_IN1, PIN_MOTOR_IN2, PIN_HEATER0, PIN_HEATER1, N_PINS };

DEFINE_FIFO(uint16_t, uart_fifo); /* the accessors of the UART's input FIFO */

#define IN_CAP (1u << 16)
#define OUT_CAP (1u << 16)
#define HX_QUEUE 16

typedef struct {
    avr_t *avr;
    /* UART */
    avr_irq_t *uart_in;
    avr_uart_t *uart; /* its input FIFO shows what the firmware has not read yet */
    uint8_t in_buf[IN_CAP];
    uint32_t in_head, in_tail; /* host -> AVR, not yet in the UART's FIFO */
    int xoff;
    uint8_t out_buf[OUT_CAP];
    uint32_t out_n;
    uint64_t out_last_cycle;
    uint64_t out_total;
    /* PWM and direction pins */
    avr_irq_t *w_motor, *w_heater0, *w_heater1;
    uint8_t w[3]; /* waveform outputs OC0A, OC1A, OC1B (an IRQ's value is updated only
                     after its hooks run, so they are kept here) */
    uint8_t level[N_PINS];
    uint64_t since[N_PINS];  /* cycle of the last change */
    uint64_t high[N_PINS];   /* high cycles since the last take */
    uint64_t taken_at;       /* cycle of the last take */
    uint64_t edges[N_PINS];  /* level changes since power-up */
    /* encoder */
    avr_irq_t *enc_a, *enc_b;
    int64_t enc_pos, enc_target;
    uint64_t enc_interval;
    /* HX711 */
    avr_irq_t *hx_dout;
    int32_t hx_queue[HX_QUEUE];
    uint64_t hx_ready_at[HX_QUEUE];
    uint32_t hx_qhead, hx_qtail;
    uint32_t hx_data;
    int hx_bit;       /* -1: no conversion to shift out; 0..24 */
    int hx_sck;
    uint32_t hx_reads, hx_overwritten;
    uint8_t ext_mask[2], ext_value[2]; /* inputs this board drives on ports C and D */
    uint64_t target;  /* run_until's */
} rgsim_t;

static char last_log[256];

static void logger(avr_t *avr, const int level, const char *fmt, va_list ap)
{
    (void)avr;
    if (level <= LOG_ERROR)
        vsnprintf(last_log, sizeof last_log, fmt, ap);
}

/* simavr 1.6 lists Timer1's waveform mode 14 as phase-correct PWM, whose compare value
 * it reads only when the timer is configured.  The ATmega328P's mode 14 is fast PWM with
 * TOP = ICR1 (datasheet table 15-5), the firmware's heater PWM: put that right. */
static void fix_timer1_mode14(avr_t *avr)
{
    for (avr_io_t *io = avr->io_port; io; io = io->next) {
        if (io->kind && strcmp(io->kind, "timer") == 0 && ((avr_timer_t *)io)->name == '1') {
            avr_timer_wgm_t fast = AVR_TIMER_WGM_ICFASTPWM();
            ((avr_timer_t *)io)->wgm_op[14] = fast;
        }
    }
}

static void no_sleep(avr_t *avr, avr_cycle_count_t how_long)
{
    (void)avr;
    (void)how_long;
}

/* ------------------------------------------------------------------ pins */

static uint8_t bit(rgsim_t *s, uint16_t addr, int b) { return (s->avr->data[addr] >> b) & 1u; }

static uint8_t pwm_level(rgsim_t *s, uint16_t tccr, int com_bit, uint8_t w, uint16_t port, int b)
{
    return bit(s, tccr, com_bit) ? w : bit(s, port, b);
}

static void evaluate(rgsim_t *s)
{
    uint8_t now[N_PINS];
    now[PIN_MOTOR_EN] = pwm_level(s, A_TCCR0A, 7, s->w[0], A_PORTD, 6);
    now[PIN_MOTOR_IN1] = bit(s, A_PORTD, 7);
    now[PIN_MOTOR_IN2] = bit(s, A_PORTB, 0);
    now[PIN_HEATER0] = pwm_level(s, A_TCCR1A, 7, s->w[1], A_PORTB, 1);
    now[PIN_HEATER1] = pwm_level(s, A_TCCR1A, 5, s->w[2], A_PORTB, 2);
    uint64_t c = s->avr->cycle;
    for (int i = 0; i < N_PINS; i++) {
        if (now[i] == s->level[i])
            continue;
        if (s->level[i])
            s->high[i] += c - (s->since[i] > s->taken_at ? s->since[i] : s->taken_at);
        s->level[i] = now[i];
        s->since[i] = c;
        s->edges[i]++;
    }
}

static void on_change(struct avr_irq_t *irq, uint32_t value, void *param)
{
    (void)irq;
    (void)value;
    evaluate((rgsim_t *)param);
}

static void on_waveform(struct avr_irq_t *irq, uint32_t value, void *param)
{
    rgsim_t *s = param;
    int i = irq == s->w_motor ? 0 : irq == s->w_heater0 ? 1 : 2;
    s->w[i] = (uint8_t)(value & 1u); /* toggle mode sends AVR_IOPORT_OUTPUT | level */
    evaluate(s);
}

/* Drive an input pin from outside.  simavr raises every input pin whose PORT bit is set
 * (the firmware's pull-up) to 1 on each write to its PORT, unless the pin is declared
 * externally driven: so each level is also given as the port's external value. */
static void drive_input(rgsim_t *s, char port, avr_irq_t *irq, int b, uint8_t level)
{
    int k = port == 'C' ? 0 : 1;
    s->ext_mask[k] |= (uint8_t)(1u << b);
    s->ext_value[k] = (uint8_t)((s->ext_value[k] & ~(1u << b)) | ((level & 1u) << b));
    avr_ioport_external_t ext = {.name = (unsigned)port, .mask = s->ext_mask[k],
                                 .value = s->ext_value[k]};
    avr_ioctl(s->avr, AVR_IOCTL_IOPORT_SET_EXTERNAL(port), &ext);
    avr_raise_irq(irq, level & 1u);
}

/* ------------------------------------------------------------------ UART */

static void feed_uart(rgsim_t *s)
{
    while (!s->xoff && s->in_tail != s->in_head) {
        uint8_t b = s->in_buf[s->in_tail % IN_CAP];
        s->in_tail++;
        avr_raise_irq(s->uart_in, b); /* may call on_xoff from inside */
    }
}

static void on_uart_out(struct avr_irq_t *irq, uint32_t value, void *param)
{
    (void)irq;
    rgsim_t *s = param;
    if (s->out_n < OUT_CAP)
        s->out_buf[s->out_n++] = (uint8_t)value;
    s->out_last_cycle = s->avr->cycle;
    s->out_total++;
}

static void on_xon(struct avr_irq_t *irq, uint32_t value, void *param)
{
    (void)irq;
    (void)value;
    rgsim_t *s = param;
    s->xoff = 0;
    feed_uart(s);
}

static void on_xoff(struct avr_irq_t *irq, uint32_t value, void *param)
{
    (void)irq;
    (void)value;
    ((rgsim_t *)param)->xoff = 1;
}

/* ------------------------------------------------------------------ encoder */

/* (A, B) of count n: counts up through 11 -> 01 -> 00 -> 10 (A leads when closing);
 * 11 at count 0, the level the inputs' pull-ups give before the first edge. */
static void enc_drive(rgsim_t *s)
{
    static const uint8_t phase[4] = {3, 1, 0, 2}; /* (A << 1) | B */
    uint8_t p = phase[(uint64_t)s->enc_pos & 3u];
    drive_input(s, 'D', s->enc_a, 2, (p >> 1) & 1u);
    drive_input(s, 'D', s->enc_b, 3, p & 1u);
}

static avr_cycle_count_t enc_edge(avr_t *avr, avr_cycle_count_t when, void *param)
{
    (void)avr;
    rgsim_t *s = param;
    if (s->enc_pos == s->enc_target)
        return 0;
    s->enc_pos += s->enc_target > s->enc_pos ? 1 : -1;
    enc_drive(s);
    return s->enc_pos == s->enc_target ? 0 : when + s->enc_interval;
}

/* ------------------------------------------------------------------ HX711 */

/* Take the conversions that are ready by now; the newest is shifted out. */
static void hx_load(rgsim_t *s)
{
    while (s->hx_qhead != s->hx_qtail) {
        uint32_t i = s->hx_qtail % HX_QUEUE;
        if (s->hx_ready_at[i] > s->avr->cycle)
            return;
        s->hx_qtail++;
        if (s->hx_bit > 0) { /* a read in progress: this conversion is lost, as on the chip */
            s->hx_overwritten++;
            continue;
        }
        if (s->hx_bit == 0)
            s->hx_overwritten++; /* the previous one was never read */
        s->hx_data = (uint32_t)s->hx_queue[i] & 0xFFFFFFu;
        s->hx_bit = 0;
        drive_input(s, 'C', s->hx_dout, 1, 0); /* DOUT low: ready */
    }
}

/* simavr keeps one timer per callback and parameter: this one re-arms for the next. */
static avr_cycle_count_t hx_ready(avr_t *avr, avr_cycle_count_t when, void *param)
{
    (void)avr;
    rgsim_t *s = param;
    hx_load(s);
    if (s->hx_qhead == s->hx_qtail)
        return 0;
    uint64_t next = s->hx_ready_at[s->hx_qtail % HX_QUEUE];
    return next > when ? next : when + 1;
}

static void on_sck(struct avr_irq_t *irq, uint32_t value, void *param)
{
    (void)irq;
    rgsim_t *s = param;
    int rising = value && !s->hx_sck;
    s->hx_sck = value ? 1 : 0;
    if (!rising || s->hx_bit < 0)
        return;
    s->hx_bit++;
    if (s->hx_bit <= 24) {
        drive_input(s, 'C', s->hx_dout, 1, (s->hx_data >> (24 - s->hx_bit)) & 1u);
    } else { /* the 25th pulse: gain 128 for the next; DOUT high until it is ready */
        drive_input(s, 'C', s->hx_dout, 1, 1);
        s->hx_bit = -1;
        s->hx_reads++;
        hx_load(s);
    }
}

/* ------------------------------------------------------------------ API */

rgsim_t *rgsim_open(const char *elf_path, uint32_t frequency, char *err, int err_len);
void rgsim_close(rgsim_t *s);

rgsim_t *rgsim_open(const char *elf_path, uint32_t frequency, char *err, int err_len)
{
    elf_firmware_t fw;
    memset(&fw, 0, sizeof fw);
    avr_global_logger_set(logger);
    if (elf_read_firmware(elf_path, &fw) != 0) {
        snprintf(err, (size_t)err_len, "cannot read the firmware ELF %s", elf_path);
        return NULL;
    }
    rgsim_t *s = calloc(1, sizeof *s);
    if (!s) {
        snprintf(err, (size_t)err_len, "out of memory");
        return NULL;
    }
    s->avr = avr_make_mcu_by_name("atmega328p");
    if (!s->avr) {
        snprintf(err, (size_t)err_len, "simavr has no atmega328p");
        free(s);
        return NULL;
    }
    avr_init(s->avr);
    s->avr->log = LOG_ERROR;
    fix_timer1_mode14(s->avr);
    fw.frequency = frequency;
    avr_load_firmware(s->avr, &fw);
    s->avr->frequency = frequency;
    s->avr->sleep = no_sleep;
    /* Paint the SRAM above the registers so that the host can find the stack's depth. */
    memset(s->avr->data + 0x100, 0xA5, 0x800);

    uint32_t flags = 0; /* no stdio echo, no usleep() on polled reads */
    avr_ioctl(s->avr, AVR_IOCTL_UART_SET_FLAGS('0'), &flags);
    s->uart_in = avr_io_getirq(s->avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_INPUT);
    for (avr_io_t *io = s->avr->io_port; io; io = io->next)
        if (io->kind && strcmp(io->kind, "uart") == 0 && ((avr_uart_t *)io)->name == '0')
            s->uart = (avr_uart_t *)io;
    avr_irq_register_notify(avr_io_getirq(s->avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUTPUT),
                            on_uart_out, s);
    avr_irq_register_notify(avr_io_getirq(s->avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUT_XON),
                            on_xon, s);
    avr_irq_register_notify(avr_io_getirq(s->avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUT_XOFF),
                            on_xoff, s);

    s->w_motor = avr_io_getirq(s->avr, AVR_IOCTL_TIMER_GETIRQ('0'), TIMER_IRQ_OUT_COMP + 0);
    s->w_heater0 = avr_io_getirq(s->avr, AVR_IOCTL_TIMER_GETIRQ('1'), TIMER_IRQ_OUT_COMP + 0);
    s->w_heater1 = avr_io_getirq(s->avr, AVR_IOCTL_TIMER_GETIRQ('1'), TIMER_IRQ_OUT_COMP + 1);
    avr_irq_register_notify(s->w_motor, on_waveform, s);
    avr_irq_register_notify(s->w_heater0, on_waveform, s);
    avr_irq_register_notify(s->w_heater1, on_waveform, s);
    static const uint16_t watched[] = {A_PORTB, A_PORTD, A_TCCR0A, A_TCCR1A};
    for (size_t i = 0; i < sizeof watched / sizeof watched[0]; i++)
        avr_irq_register_notify(avr_iomem_getirq(s->avr, watched[i], NULL, AVR_IOMEM_IRQ_ALL),
                                on_change, s);

    s->enc_a = avr_io_getirq(s->avr, AVR_IOCTL_IOPORT_GETIRQ('D'), 2);
    s->enc_b = avr_io_getirq(s->avr, AVR_IOCTL_IOPORT_GETIRQ('D'), 3);
    enc_drive(s);

    s->hx_dout = avr_io_getirq(s->avr, AVR_IOCTL_IOPORT_GETIRQ('C'), 1);
    avr_irq_register_notify(avr_io_getirq(s->avr, AVR_IOCTL_IOPORT_GETIRQ('C'), 0), on_sck, s);
    s->hx_bit = -1;
    drive_input(s, 'C', s->hx_dout, 1, 1);

    if (!s->uart_in || !s->uart || !s->w_motor || !s->w_heater0 || !s->enc_a || !s->hx_dout) {
        snprintf(err, (size_t)err_len, "simavr did not give the UART, timer or port IRQs");
        rgsim_close(s);
        return NULL;
    }
    return s;
}

void rgsim_close(rgsim_t *s)
{
    if (!s)
        return;
    avr_terminate(s->avr);
    free(s->avr);
    free(s);
}

uint64_t rgsim_cycle(rgsim_t *s) { return s->avr->cycle; }

static avr_cycle_count_t wake(avr_t *avr, avr_cycle_count_t when, void *param)
{
    (void)avr;
    (void)when;
    (void)param;
    return 0; /* only there to end a sleep at the target cycle */
}

/* Run until `cycle`; 0, or -1 if the AVR stopped or crashed (rgsim_error says why). */
int rgsim_run_until(rgsim_t *s, uint64_t cycle)
{
    avr_t *avr = s->avr;
    if (cycle > avr->cycle)
        avr_cycle_timer_register(avr, cycle - avr->cycle, wake, s);
    while (avr->cycle < cycle) {
        int state = avr_run(avr);
        if (state == cpu_Done || state == cpu_Crashed)
            return -1;
    }
    avr_cycle_timer_cancel(avr, wake, s);
    return 0;
}

const char *rgsim_error(void) { return last_log; }

void rgsim_uart_write(rgsim_t *s, const uint8_t *data, uint32_t n)
{
    for (uint32_t i = 0; i < n && s->in_head - s->in_tail < IN_CAP; i++)
        s->in_buf[(s->in_head++) % IN_CAP] = data[i];
    feed_uart(s);
}

/* Host bytes the firmware has not read from UDR yet: queued here or in the UART's FIFO. */
uint32_t rgsim_uart_pending(rgsim_t *s)
{
    return s->in_head - s->in_tail + uart_fifo_get_read_size(&s->uart->input);
}

uint32_t rgsim_uart_read(rgsim_t *s, uint8_t *out, uint32_t cap)
{
    uint32_t n = s->out_n < cap ? s->out_n : cap;
    memcpy(out, s->out_buf, n);
    memmove(s->out_buf, s->out_buf + n, s->out_n - n);
    s->out_n -= n;
    return n;
}

uint64_t rgsim_uart_last_tx_cycle(rgsim_t *s) { return s->out_last_cycle; }
uint64_t rgsim_uart_tx_total(rgsim_t *s) { return s->out_total; }

/* High cycles of each pin since the last take (out: N_PINS each), its level now and the
 * cycle of its last change; returns the cycles the take covers. */
uint64_t rgsim_take_pins(rgsim_t *s, uint64_t *high, uint8_t *level, uint64_t *since,
                         uint64_t *edges)
{
    uint64_t c = s->avr->cycle;
    for (int i = 0; i < N_PINS; i++) {
        uint64_t h = s->high[i];
        if (s->level[i])
            h += c - (s->since[i] > s->taken_at ? s->since[i] : s->taken_at);
        high[i] = h;
        level[i] = s->level[i];
        since[i] = s->since[i];
        edges[i] = s->edges[i];
        s->high[i] = 0;
    }
    uint64_t span = c - s->taken_at;
    s->taken_at = c;
    return span;
}

/* Move the encoder to `counts` by `by_cycle`, its edges evenly spaced. */
void rgsim_encoder_to(rgsim_t *s, int64_t counts, uint64_t by_cycle)
{
    avr_t *avr = s->avr;
    avr_cycle_timer_cancel(avr, enc_edge, s);
    s->enc_target = counts;
    uint64_t n = (uint64_t)(counts > s->enc_pos ? counts - s->enc_pos : s->enc_pos - counts);
    if (n == 0)
        return;
    uint64_t span = by_cycle > avr->cycle ? by_cycle - avr->cycle : 1;
    s->enc_interval = span / n ? span / n : 1;
    avr_cycle_timer_register(avr, s->enc_interval, enc_edge, s);
}

int64_t rgsim_encoder_position(rgsim_t *s) { return s->enc_pos; }

/* A conversion of `counts` (24-bit, two's complement) that the HX711 has ready at `cycle`. */
int rgsim_hx711_push(rgsim_t *s, int32_t counts, uint64_t cycle)
{
    if (s->hx_qhead - s->hx_qtail >= HX_QUEUE)
        return -1;
    uint32_t i = s->hx_qhead % HX_QUEUE;
    s->hx_queue[i] = counts;
    s->hx_ready_at[i] = cycle;
    s->hx_qhead++;
    if (s->hx_qhead - s->hx_qtail == 1) { /* else the timer is armed for an earlier one */
        uint64_t now = s->avr->cycle;
        avr_cycle_timer_register(s->avr, cycle > now ? cycle - now : 1, hx_ready, s);
    }
    return 0;
}

uint32_t rgsim_hx711_reads(rgsim_t *s) { return s->hx_reads; }
uint32_t rgsim_hx711_lost(rgsim_t *s) { return s->hx_overwritten; }

/* Copy n bytes of the AVR's data space from addr (registers, I/O, SRAM). */
int rgsim_read_data(rgsim_t *s, uint16_t addr, uint8_t *out, uint16_t n)
{
    if ((uint32_t)addr + n > 0x900u)
        return -1;
    memcpy(out, s->avr->data + addr, n);
    return 0;
}

/* One co-simulation step: move the encoder to `counts` by `end`, run to `end`, and return
 * each pin's mean level over the step (out: N_PINS).  The same as rgsim_encoder_to,
 * rgsim_run_until and rgsim_take_pins, in one call from the host. */
int rgsim_step(rgsim_t *s, int64_t counts, uint64_t end, double *duty)
{
    rgsim_encoder_to(s, counts, end);
    if (rgsim_run_until(s, end) != 0)
        return -1;
    uint64_t high[N_PINS], since[N_PINS], edges[N_PINS];
    uint8_t level[N_PINS];
    uint64_t span = rgsim_take_pins(s, high, level, since, edges);
    for (int i = 0; i < N_PINS; i++)
        duty[i] = span ? (double)high[i] / (double)span : (double)level[i];
    return 0;
}
