"""Compiled per-slot loops of the experiment pool (numba): one sample's bookkeeping, and the rate filter.

:func:`slot_bookkeeping` is what :meth:`~.pool.ExperimentPool.sample` does with a sample's
readings in every slot, in one pass: the encoder ring and the staging block, the electric
energy, the slot's last reading, the tracking error against the tabulated reference, the
stage changes that are due (hold -> reverse, reverse -> ended), the free strokes' rate,
peak, crossing and stop prediction, and the settle countdown. What needs Python (the
stroke fit at a stop, releasing a brake, flushing staged samples to the logs) comes back
as lists of slots (:data:`EVENTS`), which the pool handles in the order of the numpy code
it replaced.

The laws come from their one definition: the saturation rule is
:func:`~addedinertia_env.experiment.metrics.current_at_limit` / :func:`~addedinertia_env.experiment.metrics.voltage_at_limit`
compiled as they are; the rate filter's weights are
:func:`~addedinertia_env.experiment.filters.endpoint_slope_weights` and the stop fit's the
pseudo-inverse rows the pool builds (``np.polyfit``'s quadratic), passed in.
tests/test_pool_kernels.py holds the loops equal to the numpy code they replaced.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from addedinertia_env.experiment import metrics

# Event lists that slot_bookkeeping returns (rows of its ``events`` array).
EVENTS = ("broken", "to_reverse", "ended", "stop", "over", "release")
BROKEN, TO_REVERSE, ENDED_NOW, STOP, OVER, RELEASE = range(len(EVENTS))
# Stages (pool.STAGE_NAMES)
_SETTLE, _FREE, _HOLD, _REVERSE = 1, 2, 4, 5

current_at_limit = njit(metrics.current_at_limit, cache=True)
voltage_at_limit = njit(metrics.voltage_at_limit, cache=True)


@njit(cache=True, inline="always")
def slot_rate(ring, j, g, k, count, n_rate, w_rate, dt):  # pragma: no cover - compiled
    """The rate estimate (rad/s) of encoder ``j`` (0 hull, 1 motor) of slot ``k`` whose newest
    sample is at ring position ``g`` (``ring``: slot x encoder x position): the FIR ``w_rate``
    over the last ``n_rate`` samples (summed oldest first), or before ``count`` reaches
    ``n_rate`` the end-point difference (0 for one sample)."""
    size = ring.shape[2]
    if count < n_rate:
        if count < 2:
            return 0.0
        return (ring[k, j, g] - ring[k, j, (g - count + 1 + size) % size]) / ((count - 1) * dt)
    rate = 0.0
    pos = (g - n_rate + 1 + size) % size
    for m in range(n_rate):
        rate += w_rate[m] * ring[k, j, pos]
        pos = pos + 1 if pos + 1 < size else 0
    return rate


@njit(cache=True)
def slot_rates(ring, j, g, cols, counts, n_rate, w_rate, dt, out):  # pragma: no cover - compiled
    """:func:`slot_rate` of encoder ``j`` for slots ``cols`` (their sample counts ``counts``) into ``out``."""
    for m in range(len(cols)):
        out[m] = slot_rate(ring, j, g, cols[m], counts[m], n_rate, w_rate, dt)


@njit(cache=True)
def flush_staged(block, logs, slots, stage_cnt, stage_from, flushed):  # pragma: no cover - compiled
    """Copy the staged samples of ``slots`` from ``block`` (tile x row x column x lane, slot ``k`` in
    tile ``k // lanes``, lane ``k % lanes``) to their logs ``logs[k]`` (column x sample; long enough)
    after their ``flushed[k]`` samples; ``flushed`` grows by ``stage_cnt``, which becomes 0."""
    lanes = block.shape[3]
    for s in range(len(slots)):
        k = slots[s]
        cnt, start, n0 = stage_cnt[k], stage_from[k], flushed[k]
        log = logs[k]
        tile, lane = k // lanes, k % lanes
        for c in range(block.shape[2]):
            for r in range(cnt):
                log[c, n0 + r] = block[tile, start + r, c, lane]
        flushed[k] = n0 + cnt
        stage_cnt[k] = 0


@njit(cache=True)
def restore_rings(ring, logs, slots, flushed, g):  # pragma: no cover - compiled
    """The encoder history (phi, psi: rows 0 and 1 of ``logs[k]``) of slots ``k = slots[s]`` back into
    their ``ring`` rows: the last ``min(flushed[k], size - 1)`` logged samples, the newest at ring
    position ``g - 1``, the ones before it at the positions before (modulo the ring's size); positions
    before a slot's first sample are left as they are."""
    size = ring.shape[2]
    for s in range(len(slots)):
        k = slots[s]
        nk = flushed[k]
        mk = min(nk, size - 1)
        log = logs[k]
        for m in range(mk):
            pos = (g - mk + m + size) % size
            ring[k, 0, pos] = log[0, nk - mk + m]
            ring[k, 1, pos] = log[1, nk - mk + m]


@njit(cache=True)
def slot_masks(stage, controlled, was_active, mode_code, value, settling, freeing, active, mode, command,
               resumed):  # pragma: no cover - compiled
    """Which slots take this sample: ``settling`` (stage settle), ``freeing`` (stage free), ``active``
    (those or ``controlled``); the rig's ``mode`` (``mode_code`` where controlled, else 0: passive)
    and ``command`` (``value`` where controlled, else 0); the slots active again after a pause
    into ``resumed``. Returns how many resumed."""
    m = 0
    for k in range(len(stage)):
        settling[k] = stage[k] == _SETTLE
        freeing[k] = stage[k] == _FREE
        active[k] = settling[k] or freeing[k] or controlled[k]
        mode[k] = mode_code if controlled[k] else 0
        command[k] = value[k] if controlled[k] else 0.0
        if active[k] and not was_active[k]:
            resumed[m] = k
            m += 1
    return m


@njit(cache=True)
def slot_bookkeeping(g, row, ring, block, stage_from, stage_cnt, flushed,
                     active, controlled, settling, freeing, value, current_mode,
                     phi, psi, u, i, t,
                     energy, last_t, s_phi, s_psi, s_u, s_i, s_t,
                     i_max, u_max, ref_table, ref_first, ref_len, stage, t_begin, t_end, dt,
                     free_n, free_max, hull_rate, sign, peak, t_cross, phi_n,
                     n_rate, w_rate, window, stop_c2, stop_c1, settle_left,
                     e_sq, d_energy, limit, events, n_events):  # pragma: no cover - compiled
    """One sample's bookkeeping in every slot ``k`` (module docstring); readings ``phi, psi`` (rad),
    ``u`` (V), ``i`` (A), ``t`` (s) of this sample; ``g`` the ring position it goes to (``ring``:
    slot x encoder x position), ``row`` the staging block's row (``block``: tile x row x column x
    lane, slot ``k`` in tile ``k // lanes``, lane ``k % lanes``). Outputs per slot: ``e_sq`` (rad^2, tracking error squared inside
    the reverse stroke), ``d_energy`` (J), ``limit`` (at the drive's limit), and the event
    lists ``events[e, :n_events[e]]`` (:data:`EVENTS`).

    If any active slot's staged samples do not end at the row before ``row`` (``broken``),
    nothing is done and only those slots come back: flush them, then call again.
    """
    n = len(active)
    n_events[:] = 0
    for k in range(n):  # a slot that takes this row must have its staged samples just before it
        if active[k] and stage_cnt[k] > 0 and stage_from[k] + stage_cnt[k] != row:
            events[BROKEN, n_events[BROKEN]] = k
            n_events[BROKEN] += 1
    if n_events[BROKEN]:
        return
    size = ring.shape[2]
    lanes = block.shape[3]
    half = 0.5 * dt
    n_ref = ref_table.shape[1]
    for k in range(n):
        # the log: encoder ring and staging block (every slot; paused ones are restored on resume)
        ring[k, 0, g] = phi[k]
        ring[k, 1, g] = psi[k]
        tile, lane = k // lanes, k % lanes
        block[tile, row, 0, lane] = phi[k]
        block[tile, row, 1, lane] = psi[k]
        block[tile, row, 2, lane] = u[k]
        block[tile, row, 3, lane] = i[k]
        cmd = value[k] if controlled[k] else 0.0
        block[tile, row, 4, lane] = cmd if current_mode else 0.0
        block[tile, row, 5, lane] = 0.0 if current_mode else cmd
        e_sq[k] = 0.0
        d_energy[k] = 0.0
        limit[k] = False
        if not active[k]:
            continue
        if stage_cnt[k] == 0:
            stage_from[k] = row
        stage_cnt[k] += 1
        # electric energy over hold and reverse (Experiment._log_reading), then the last reading
        if controlled[k]:
            before = energy[k]
            energy[k] = before + abs(u[k] * i[k]) * (t[k] - last_t[k])
            d_energy[k] = energy[k] - before
        last_t[k] = t[k]
        s_phi[k], s_psi[k], s_u[k], s_i[k], s_t[k] = phi[k], psi[k], u[k], i[k], t[k]
        count = flushed[k] + stage_cnt[k]
        if controlled[k]:
            if current_mode:
                limit[k] = current_at_limit(value[k], i_max[k])
            else:
                limit[k] = voltage_at_limit(value[k], i[k], u_max[k], i_max[k])
            idx = count - 1 - ref_first[k]
            e = ref_table[k, min(max(idx, 0), n_ref - 1)] - phi[k]
            if 0 <= idx < ref_len[k]:
                e_sq[k] = e * e
            if stage[k] == _HOLD and t[k] >= t_begin[k] - half:
                events[TO_REVERSE, n_events[TO_REVERSE]] = k
                n_events[TO_REVERSE] += 1
            elif stage[k] == _REVERSE and t[k] >= t_end[k] - half:
                events[ENDED_NOW, n_events[ENDED_NOW]] = k
                n_events[ENDED_NOW] += 1
        elif freeing[k]:  # crossing, peak and stop prediction of the free stroke (Experiment.start)
            free_n[k] += 1
            rate = slot_rate(ring, 0, g, k, count, n_rate, w_rate, dt)
            hull_rate[k] = rate
            w = sign[k] * rate
            peak[k] = max(peak[k], w)
            if math.isnan(t_cross[k]) and sign[k] * (phi[k] - phi_n[k]) >= 0:
                t_cross[k] = t[k]
            stop = False
            if not math.isnan(t_cross[k]) and w < 0.3 * peak[k]:  # the quadratic predicts the stop
                c2 = 0.0
                c1 = 0.0
                pos = (g - window + 1 + size) % size
                for m in range(window):
                    c2 += stop_c2[m] * ring[k, 0, pos]
                    c1 += stop_c1[m] * ring[k, 0, pos]
                    pos = pos + 1 if pos + 1 < size else 0
                stop = c2 != 0.0 and -c1 / (2.0 * c2) <= half
            if stop:
                events[STOP, n_events[STOP]] = k
                n_events[STOP] += 1
            elif free_n[k] >= free_max[k]:
                events[OVER, n_events[OVER]] = k
                n_events[OVER] += 1
        elif settling[k]:
            settle_left[k] -= 1
            if settle_left[k] <= 0:
                events[RELEASE, n_events[RELEASE]] = k
                n_events[RELEASE] += 1
