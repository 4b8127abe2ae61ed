/*
 * Build-time constants of the firmware: what belongs to one gripper (motor,
 * encoder, heaters, load cell).  Every one can be set on the make command line,
 * e.g. `make ENCODER_NM_PER_COUNT=2500`; docs/firmware.md lists them.
 */
#ifndef RG_CONFIG_H
#define RG_CONFIG_H

#ifndef F_CPU
#define F_CPU 16000000ul /* Arduino Uno / Nano crystal */
#endif
#ifndef RG_BAUD
#define RG_BAUD 115200ul
#endif
#ifndef RG_FIRMWARE_ID
#define RG_FIRMWARE_ID "relaxgrip-fw 1.1" /* <= 16 printable characters */
#endif

/* Motor and encoder. */
#ifndef RG_MAX_VELOCITY_UM_S
#define RG_MAX_VELOCITY_UM_S 20000l /* commands beyond it are clamped */
#endif
#ifndef RG_MOTOR_FULL_SPEED_UM_S
#define RG_MOTOR_FULL_SPEED_UM_S 25000l /* closing speed at 100 % PWM: the feed-forward */
#endif
#ifndef RG_MOTOR_LAG_MS
#define RG_MOTOR_LAG_MS 50l /* the motor's velocity time constant: the reference model's */
#endif
#ifndef RG_ENCODER_NM_PER_COUNT
#define RG_ENCODER_NM_PER_COUNT 5000l /* travel per quadrature count (x4 decoding) */
#endif
#ifndef RG_ENCODER_SIGN
#define RG_ENCODER_SIGN 1 /* -1 if closing counts down */
#endif
#ifndef RG_ENCODER_MAX_ERRORS
#define RG_ENCODER_MAX_ERRORS 8 /* impossible transitions before the ENCODER fault */
#endif
#ifndef RG_KP_PERMYRIAD_PER_MM
#define RG_KP_PERMYRIAD_PER_MM 4000l /* duty per mm of position error */
#endif
#ifndef RG_KI_PERMYRIAD_PER_MM_S
#define RG_KI_PERMYRIAD_PER_MM_S 8000l /* duty per mm·s of integrated error */
#endif
#ifndef RG_I_MAX_PERMYRIAD
#define RG_I_MAX_PERMYRIAD 1000l /* the integral's share of the duty at most (anti-windup) */
#endif
#ifndef RG_I_VMAX_UM_S
#define RG_I_VMAX_UM_S 1000l /* the integral learns at commanded speeds up to this */
#endif
#ifndef RG_CONTROL_PERIOD_MS
#define RG_CONTROL_PERIOD_MS 2 /* velocity loop period */
#endif

/* Heaters. */
#ifndef RG_HEATER_DUTY_LIMIT
#define RG_HEATER_DUTY_LIMIT 10000u /* permyriad: every duty is clamped to it */
#endif

/* Load cell (HX711 on A0/A1): 1 to read it, 0 to build without. */
#ifndef RG_LOAD_CELL
#define RG_LOAD_CELL 1
#endif

#ifndef RG_WATCHDOG_DEFAULT_MS_CFG
#define RG_WATCHDOG_DEFAULT_MS_CFG 200u
#endif

#endif
