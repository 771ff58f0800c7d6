/* The bench board's inner loop: see board_loop.h and addedinertia_env/loop/board_loop.py. */
#include "board_loop.h"

#include <math.h>

int32_t bl_elapsed_us(uint32_t now, uint32_t then) {
    return (int32_t)(now - then);  /* wrap-safe, valid within +-35 min */
}

void bl_init(bl_loop *l, uint32_t dt_us, double i_max, uint32_t grace_us, double rate_filter_hz) {
    const double pi = 3.14159265358979323846;
    double theta = exp(-2.0 * pi * rate_filter_hz * (double)dt_us * 1e-6);
    l->dt_us = dt_us;
    l->i_max = i_max;
    l->grace_us = grace_us;
    l->alpha = 1.0 - theta * theta;
    l->beta = (1.0 - theta) * (1.0 - theta);
    l->late_segments = l->accepted_segments = 0;
    l->phi_hat = l->w_hat = 0.0;
    bl_restart(l);
}

void bl_restart(bl_loop *l) {
    l->has_segment = 0;
    l->started = 0;
}

int bl_offer(bl_loop *l, const bl_segment *s, uint32_t now_us) {
    if (bl_elapsed_us(now_us, s->deadline_us) > 0) {                     /* rule 1: late */
        l->late_segments++;
        return 0;
    }
    if (l->has_segment && bl_elapsed_us(s->t0_us, l->seg.t0_us) < 0) {  /* older than the one in force */
        l->late_segments++;
        return 0;
    }
    l->seg = *s;
    l->has_segment = 1;
    l->accepted_segments++;
    return 1;
}

static void update_rate(bl_loop *l, double phi) {  /* step 1: alpha-beta filter */
    double dt = (double)l->dt_us * 1e-6;
    double pred, r;
    if (!l->started) {
        l->phi_hat = phi;
        l->w_hat = 0.0;
        l->started = 1;
        return;
    }
    pred = l->phi_hat + dt * l->w_hat;
    r = phi - pred;
    l->phi_hat = pred + l->alpha * r;
    l->w_hat = l->w_hat + (l->beta / dt) * r;
}

static int brake_at(const bl_segment *s, uint32_t now_us) {  /* step 6 */
    int brake = (s->flags & BL_BRAKE) != 0;
    if ((s->flags & BL_SWITCH_VALID) && bl_elapsed_us(now_us, s->brake_switch_us) >= 0)
        return !brake;
    return brake;
}

static bl_output out_passive(int brake, uint16_t id) {
    bl_output o = {1, 0.0, brake, 0, 0, id};
    return o;
}

bl_output bl_command(bl_loop *l, uint32_t now_us, double phi) {
    const bl_segment *s = &l->seg;
    int64_t sd;
    int32_t over;
    int hold = 0, brake, pd = (s->flags & BL_PD) != 0;
    double i_ff, phi_ref = 0.0, rate_ref = 0.0, i;
    bl_output o;

    update_rate(l, phi);
    if (!l->has_segment)                                            /* step 2 */
        return out_passive(1, 0);
    sd = bl_elapsed_us(now_us, s->t0_us);                           /* step 3 */
    if (sd < 0) sd = 0;
    over = bl_elapsed_us(now_us, s->t0_us + s->duration_us);        /* step 4 */
    if (over > 0) {
        if ((s->flags & (BL_END_PASSIVE | BL_PASSIVE)) && brake_at(s, now_us))
            return out_passive(1, s->seg_id);                       /* ends in the safe command */
        if (over > (int32_t)l->grace_us) {
            o = out_passive(1, s->seg_id);
            o.hold = o.starved = 1;
            return o;
        }
        if (s->flags & (BL_END_PASSIVE | BL_PASSIVE))
            return out_passive(brake_at(s, now_us), s->seg_id);
        hold = 1;
        sd = s->duration_us;
    }
    brake = brake_at(s, now_us);
    if (s->flags & BL_PASSIVE)
        return out_passive(brake, s->seg_id);
    if (s->n == 1) {                                                /* step 5 */
        i_ff = s->currents[0];
        if (pd) phi_ref = s->phi_refs[0];
    } else {
        int64_t k = sd / s->knot_us;
        double f;
        if (k > s->n - 2) k = s->n - 2;
        f = (double)(sd - k * (int64_t)s->knot_us) / (double)s->knot_us;
        if (f > 1.0) {
            f = 1.0;
            rate_ref = 0.0;
        } else if (pd) {
            rate_ref = (s->phi_refs[k + 1] - s->phi_refs[k]) / ((double)s->knot_us * 1e-6);
        }
        i_ff = s->currents[k] + f * (s->currents[k + 1] - s->currents[k]);
        if (pd) phi_ref = s->phi_refs[k] + f * (s->phi_refs[k + 1] - s->phi_refs[k]);
    }
    i = i_ff;
    if (pd && !brake)                                               /* step 7 */
        i += s->kp * (phi_ref - phi) + s->kd * (rate_ref - l->w_hat);
    if (i > l->i_max) i = l->i_max;                                 /* step 8 */
    if (i < -l->i_max) i = -l->i_max;
    o.passive = 0;
    o.current = i;
    o.brake = brake;
    o.hold = hold;
    o.starved = 0;
    o.seg_id = s->seg_id;
    return o;
}
