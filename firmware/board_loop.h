/* The bench board's inner loop (protocol version 2): the C reference for firmware.
 *
 * Port of addedinertia_env/loop/board_loop.py, step for step (its module docstring and
 * docs/PROTOCOL.md section 9 explain each step); tests/test_board_loop_c.py compiles this
 * file with gcc and holds its outputs equal to the Python loop's on the same inputs.
 * Doubles throughout, as in the Python reference; a firmware on a single-precision FPU
 * may use float where the drive's resolution allows. Times: u32 board microseconds.
 */
#ifndef BOARD_LOOP_H
#define BOARD_LOOP_H

#include <stdint.h>

#define BL_MAX_KNOTS 8

/* segment flags, as on the wire (SEGMENT.flags) */
#define BL_BRAKE 0x01        /* brake requested at t0 */
#define BL_SWITCH_VALID 0x02 /* brake_switch_us is used */
#define BL_PD 0x04           /* reference knots present: board-side PD */
#define BL_END_PASSIVE 0x08  /* drive passive after the end (instead of holding) */
#define BL_PASSIVE 0x10      /* drive passive throughout */

typedef struct {
    uint16_t seg_id;
    uint8_t flags;
    uint8_t n;               /* knots, 1..BL_MAX_KNOTS */
    uint32_t t0_us, duration_us, deadline_us, brake_switch_us, knot_us;
    double kp, kd;           /* A/rad, A/(rad/s) */
    double currents[BL_MAX_KNOTS];  /* A */
    double phi_refs[BL_MAX_KNOTS];  /* rad (BL_PD only) */
} bl_segment;

typedef struct {
    uint32_t dt_us;          /* sample period */
    double i_max;            /* A */
    uint32_t grace_us;
    double alpha, beta;      /* alpha-beta rate filter gains */
    int has_segment, started;
    bl_segment seg;
    double phi_hat, w_hat;   /* rad, rad/s */
    uint32_t late_segments, accepted_segments;
} bl_loop;

typedef struct {
    int passive;             /* 1: terminals open (no current) */
    double current;          /* A, when not passive */
    int brake;               /* brake request */
    int hold;                /* the segment ran out, holding within the grace */
    int starved;             /* grace over: go to the safe state (fault SEGMENTS) */
    uint16_t seg_id;
} bl_output;

int32_t bl_elapsed_us(uint32_t now, uint32_t then);
void bl_init(bl_loop *l, uint32_t dt_us, double i_max, uint32_t grace_us, double rate_filter_hz);
void bl_restart(bl_loop *l);
int bl_offer(bl_loop *l, const bl_segment *s, uint32_t now_us);   /* 1 kept, 0 late (dropped) */
bl_output bl_command(bl_loop *l, uint32_t now_us, double phi);

#endif
