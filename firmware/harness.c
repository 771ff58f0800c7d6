/* Test harness: drives board_loop.c from text on stdin, prints what it decided.
 *   I dt_us i_max grace_us rate_filter_hz      init
 *   S id flags n t0 duration deadline switch knot kp kd c[0..n-1] [p[0..n-1] if flags & PD]
 *   C now_us phi                                command  -> O passive current brake hold starved seg_id
 *   R                                           restart
 * Offers print "A 1" (kept) or "A 0" (late, dropped). Used by tests/test_board_loop_c.py. */
#include <stdio.h>
#include "board_loop.h"

int main(void) {
    bl_loop l;
    char op;
    bl_init(&l, 1000, 15.0, 20000, 40.0);
    while (scanf(" %c", &op) == 1) {
        if (op == 'I') {
            unsigned dt, grace;
            double i_max, fc;
            if (scanf("%u %lf %u %lf", &dt, &i_max, &grace, &fc) != 4) return 2;
            bl_init(&l, dt, i_max, grace, fc);
        } else if (op == 'S') {
            bl_segment s;
            unsigned id, flags, n, t0, dur, dl, sw, knot, k;
            unsigned now;
            if (scanf("%u %u %u %u %u %u %u %u %lf %lf", &id, &flags, &n, &t0, &dur, &dl, &sw, &knot, &s.kp,
                      &s.kd) != 10 || n < 1 || n > BL_MAX_KNOTS) return 2;
            s.seg_id = (uint16_t)id; s.flags = (uint8_t)flags; s.n = (uint8_t)n;
            s.t0_us = t0; s.duration_us = dur; s.deadline_us = dl; s.brake_switch_us = sw; s.knot_us = knot;
            for (k = 0; k < n; k++) if (scanf("%lf", &s.currents[k]) != 1) return 2;
            if (flags & BL_PD) for (k = 0; k < n; k++) if (scanf("%lf", &s.phi_refs[k]) != 1) return 2;
            if (scanf("%u", &now) != 1) return 2;
            printf("A %d\n", bl_offer(&l, &s, now));
        } else if (op == 'C') {
            unsigned now;
            double phi;
            bl_output o;
            if (scanf("%u %lf", &now, &phi) != 2) return 2;
            o = bl_command(&l, now, phi);
            printf("O %d %.17g %d %d %d %u\n", o.passive, o.current, o.brake, o.hold, o.starved, o.seg_id);
        } else if (op == 'R') {
            bl_restart(&l);
        } else {
            return 2;
        }
    }
    return 0;
}
