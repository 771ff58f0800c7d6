"""The experiment pool's compiled loops (vector/pool_kernels.py) against the numpy code they replaced."""

from __future__ import annotations

import numpy as np

from addedinertia_env.experiment.filters import endpoint_slope_weights
from addedinertia_env.experiment.metrics import current_at_limit
from addedinertia_env.vector.pool_kernels import (ENDED_NOW, EVENTS, OVER, RELEASE, STOP, TO_REVERSE,
                                                  slot_bookkeeping, slot_rates)

RING, DT, N_RATE = 64, 1e-3, 40


def numpy_rate(history: np.ndarray, count: int) -> float:
    """The former ExperimentPool._rate on one slot's samples (oldest first, newest last)."""
    if count < N_RATE:
        return 0.0 if count < 2 else (history[-1] - history[-count]) / ((count - 1) * DT)
    return float(endpoint_slope_weights(N_RATE, DT) @ history[-N_RATE:])


def ring_of(histories: list[np.ndarray], g: int) -> np.ndarray:
    """Slots' histories (newest last) in the pool's ring layout, newest at position ``g``."""
    ring = np.full((len(histories), 2, RING), np.nan)
    for k, h in enumerate(histories):
        m = min(len(h), RING)
        ring[k, 0, (g - m + 1 + np.arange(m)) % RING] = h[-m:]
        ring[k, 1, (g - m + 1 + np.arange(m)) % RING] = 2.0 * h[-m:]
    return ring


def test_slot_rates_equal_the_fir_and_the_short_window_rule():
    rng = np.random.default_rng(1)
    counts = np.array([1, 2, 7, 39, 40, 41, 300])
    histories = [np.cumsum(rng.normal(size=min(c, RING))) * 1e-3 for c in counts]
    w = endpoint_slope_weights(N_RATE, DT)
    for g in (0, 5, 63):
        ring = ring_of(histories, g)
        out = np.empty(len(counts))
        slot_rates(ring, 0, g, np.arange(len(counts)), counts, N_RATE, w, DT, out)
        want = [numpy_rate(h, c) for h, c in zip(histories, counts)]
        assert np.allclose(out, want, rtol=1e-12, atol=1e-12)
        slot_rates(ring, 1, g, np.arange(len(counts)), counts, N_RATE, w, DT, out)
        assert np.allclose(out, 2.0 * np.array(want), rtol=1e-12, atol=1e-12)


def test_bookkeeping_equals_the_numpy_protocol_step():
    """Energy, tracking error, saturation, stage changes, free-stroke detection and settling of
    one sample, against the numpy code of the former ExperimentPool.sample."""
    n, window, g, row = 8, 30, 17, 3
    rng = np.random.default_rng(2)
    stage = np.array([1, 1, 2, 2, 2, 4, 5, 3], dtype=np.int8)  # settle, free, hold, reverse, ready
    controlled = (stage == 4) | (stage == 5)
    settling, freeing = stage == 1, stage == 2
    active = settling | freeing | controlled
    # free strokes: a decelerating swing (stop due), one still fast, one past max_free
    t_hist = (np.arange(200) - 199) * DT
    swings = [0.1 * np.sin(8.0 * (t_hist + np.pi / 16 - 2e-4)), 0.1 * np.sin(8.0 * t_hist), 0.1 * np.sin(8.0 * (t_hist + 0.1))]
    histories = [np.zeros(200), np.zeros(200)] + swings + [np.zeros(200)] * 3
    ring = ring_of([h[:-1] for h in histories], g - 1)  # this sample's reading goes to position g
    phi = np.array([h[-1] for h in histories])
    psi, u, i = rng.normal(size=n), rng.normal(size=n), rng.normal(size=n)
    t = np.full(n, 2.0)
    value = np.where(controlled, np.array([0, 0, 0, 0, 0, 1.0, 5.0, 0]), 0.0)
    i_max, u_max = np.full(n, 5.0), np.full(n, 24.0)
    energy, last_t = rng.uniform(0, 1, n), np.full(n, 2.0 - DT)
    flushed = np.full(n, 150, dtype=np.int64)
    stage_cnt = np.full(n, 40, dtype=np.int64)
    stage_from = np.full(n, row - 40, dtype=np.int64)
    ref_table = rng.normal(size=(n, 100))
    ref_first = np.full(n, 170, dtype=np.int64)
    ref_len = np.full(n, 100, dtype=np.int64)
    t_begin, t_end = np.full(n, 1.5), np.full(n, 2.0)
    free_n = np.array([0, 0, 10, 10, 500, 0, 0, 0], dtype=np.int64)
    free_max = np.full(n, 400, dtype=np.int64)
    sign, peak = np.ones(n), np.full(n, 0.8)
    t_cross = np.array([np.nan, np.nan, 1.9, 1.9, np.nan, np.nan, np.nan, np.nan])
    phi_n = np.zeros(n)
    settle_left = np.array([1, 5, 0, 0, 0, 0, 0, 0], dtype=np.int64)
    w_rate = endpoint_slope_weights(N_RATE, DT)
    tt = (np.arange(window) - (window - 1)) * DT
    stop_fit = np.linalg.pinv(np.vander(tt, 3))
    block = np.zeros((1, 64, 6, 8))
    state = [np.zeros(n) for _ in range(5)]
    e_sq, d_energy, limit = np.empty(n), np.empty(n), np.empty(n, dtype=bool)
    events, counts = np.zeros((len(EVENTS), n), dtype=np.int64), np.zeros(len(EVENTS), dtype=np.int64)
    energy0, peak0, free_n0 = energy.copy(), peak.copy(), free_n.copy()
    slot_bookkeeping(g, row, ring, block, stage_from, stage_cnt, flushed, active, controlled, settling, freeing,
                     value, True, phi, psi, u, i, t, energy, last_t, *state, i_max, u_max, ref_table, ref_first,
                     ref_len, stage, t_begin, t_end, DT, free_n, free_max, np.zeros(n), sign, peak, t_cross,
                     phi_n, N_RATE, w_rate, window, stop_fit[0], stop_fit[1], settle_left,
                     e_sq, d_energy, limit, events, counts)
    # the log
    assert np.array_equal(ring[:, 0, g], phi) and np.array_equal(block[0, row, 2], u)
    assert np.array_equal(stage_cnt, 40 + active)
    # energy and tracking (ExperimentPool._controlled_sample)
    new_energy = np.where(controlled, energy0 + np.abs(u * i) * (t - (2.0 - DT)), energy0)
    assert np.array_equal(energy, new_energy) and np.array_equal(d_energy, new_energy - energy0)
    idx = flushed + stage_cnt - 1 - ref_first
    in_stroke = controlled & (idx >= 0) & (idx < ref_len)
    e = ref_table[np.arange(n), np.clip(idx, 0, 99)] - phi
    assert np.array_equal(e_sq, np.where(in_stroke, e * e, 0.0))
    assert np.array_equal(limit, current_at_limit(value, i_max) & controlled)
    lists = {name: sorted(events[j, :counts[j]].tolist()) for j, name in enumerate(EVENTS)}
    assert lists["to_reverse"] == [5] and lists["ended"] == [6]  # t >= t_begin - dt/2, t >= t_end - dt/2
    # free strokes (ExperimentPool._free_sample, _stop_due)
    for k in (2, 3, 4):
        h = histories[k]
        rate = numpy_rate(h, int(flushed[k] + stage_cnt[k]))
        assert free_n[k] == free_n0[k] + 1 and np.isclose(peak[k], max(peak0[k], rate), rtol=1e-12)
        c2, c1, _ = np.polyfit(tt, h[-window:], 2)
        due = not np.isnan(t_cross[k]) and rate < 0.3 * peak[k] and c2 != 0 and -c1 / (2 * c2) <= 0.5 * DT
        assert (k in lists["stop"]) == due, k
    assert lists["stop"] == [2] and lists["over"] == [4]
    assert lists["release"] == [0] and np.array_equal(settle_left[:2], [0, 4])
    assert counts[STOP] + counts[OVER] + counts[RELEASE] + counts[TO_REVERSE] + counts[ENDED_NOW] == 5


def test_reference_kernel_equals_chebval_column_by_column():
    """reference_one (compiled; what the observation and the tabulation call) against numpy's chebval of
    each slot's law and the scalar MirroredReference."""
    from numpy.polynomial import chebyshev as C

    from addedinertia_env.experiment.reference import MirroredReference, fit_stroke
    from addedinertia_env.vector.reference import MirroredReferences, reference_one

    refs = MirroredReferences(3)
    singles = []
    for k, (amp, w) in enumerate(((0.1, 6.0), (0.05, 9.0), (0.2, 4.0))):
        t = np.arange(0.0, 0.5, DT)
        law = fit_stroke(t, amp * np.cos(w * t), 0.02, 0.45)
        refs.set(k, law, 1.0 + k)
        singles.append(MirroredReference(law, t_begin=1.0 + k))
    columns = (refs.coef, refs.d1, refs.d2, refs.t_start, refs.t_stop, refs.t_begin, refs.t_end)
    t = np.array([1.1, 2.05, 3.3])
    for k, single in enumerate(singles):
        phi, rate, accel = reference_one(t[k], k, *columns, True)
        assert phi == single.phi(t[k])
        law = single.law
        x = (2.0 * (law.t_stop - (min(max(t[k], refs.t_begin[k]), refs.t_end[k]) - refs.t_begin[k]))
             - (law.t_start + law.t_stop)) / (law.t_stop - law.t_start)
        scale = 2.0 / (law.t_stop - law.t_start)
        assert phi == C.chebval(x, law.coef)
        assert rate == -(C.chebval(x, law._d1) * scale) and accel == C.chebval(x, law._d2) * scale**2
        assert reference_one(t[k], k, *columns, False) == (phi, 0.0, 0.0)
    times = np.linspace(1.9, 2.6, 7)  # one slot at many times
    assert [reference_one(x, 1, *columns, False)[0] for x in times] == [singles[1].phi(x) for x in times]


def test_slot_masks_equal_the_numpy_masks():
    from addedinertia_env.vector.pool_kernels import slot_masks

    rng = np.random.default_rng(4)
    n = 50
    stage = rng.integers(0, 7, n).astype(np.int8)
    controlled = ((stage == 4) | (stage == 5)) & (rng.random(n) < 0.8)
    was_active = rng.random(n) < 0.5
    value = rng.normal(size=n)
    out = [np.empty(n, dtype=bool) for _ in range(3)] + [np.empty(n, dtype=np.int64), np.empty(n),
                                                         np.empty(n, dtype=np.int64)]
    m = slot_masks(stage, controlled, was_active, 2, value, *out)
    settling, freeing = stage == 1, stage == 2
    active = settling | freeing | controlled
    assert np.array_equal(out[0], settling) and np.array_equal(out[1], freeing) and np.array_equal(out[2], active)
    assert np.array_equal(out[3], np.where(controlled, 2, 0)) and np.array_equal(out[4], np.where(controlled, value, 0.0))
    assert np.array_equal(out[5][:m], np.nonzero(active & ~was_active)[0])


def test_flush_staged_copies_each_slots_rows_to_its_log():
    from numba.typed import List

    from addedinertia_env.vector.pool_kernels import flush_staged

    rng = np.random.default_rng(6)
    n, lanes, stage = 20, 8, 16
    block = rng.normal(size=(-(-n // lanes), stage + 1, 6, lanes))
    logs = List([np.zeros((6, 40)) for _ in range(n)])
    flushed = rng.integers(0, 20, n)
    stage_cnt = rng.integers(0, 10, n)
    stage_from = rng.integers(0, stage - 10, n)
    slots = np.array([0, 3, 9, 17, 19])
    want = [logs[k].copy() for k in range(n)]
    for k in slots:
        c, s, f = stage_cnt[k], stage_from[k], flushed[k]
        want[k][:, f:f + c] = block[k // lanes, s:s + c, :, k % lanes].T
    n0, cnt0 = flushed.copy(), stage_cnt.copy()
    flush_staged(block, logs, slots, stage_cnt, stage_from, flushed)
    for k in range(n):
        assert np.array_equal(logs[k], want[k])
    assert np.array_equal(flushed[slots], n0[slots] + cnt0[slots]) and not stage_cnt[slots].any()


def test_restore_rings_puts_each_slots_last_samples_before_the_current_position():
    """restore_rings against the numpy code it replaced (the newest logged sample at g - 1)."""
    from numba.typed import List

    from addedinertia_env.vector.pool_kernels import restore_rings

    rng = np.random.default_rng(3)
    flushed = np.array([0, 1, 5, 63, 64, 200])
    logs = [rng.normal(size=(6, max(int(n), 1) + 3)) for n in flushed]
    slots = np.array([5, 0, 2, 3, 1, 4])
    for g in (0, 1, 40, 63):
        ring = rng.normal(size=(len(flushed), 2, RING))
        expected = ring.copy()
        for k in slots.tolist():
            nk = int(flushed[k])
            mk = min(nk, RING - 1)
            if mk:
                expected[k, :, (g - mk + np.arange(mk)) % RING] = logs[k][:2, nk - mk:nk].T
        restore_rings(ring, List(logs), slots, flushed, g)
        assert np.array_equal(ring, expected)


def test_tabulated_reference_equals_phi_on_the_reverse_strokes_samples():
    """MirroredReferences.tabulate against the numpy selection and MirroredReference.phi."""
    from addedinertia_env.experiment.reference import MirroredReference, fit_stroke
    from addedinertia_env.vector.reference import MirroredReferences

    refs = MirroredReferences(2)
    t_fit = np.arange(0.0, 0.5, DT)
    law = fit_stroke(t_fit, 0.1 * np.cos(6.0 * t_fit), 0.02, 0.45)
    refs.set(1, law, 2.0)
    single = MirroredReference(law, t_begin=2.0)
    until = refs.t_end[1] + 0.5 * DT
    for t in (np.arange(1.5, 3.0, DT), np.arange(2.1, 2.2, DT), np.arange(3.0, 3.1, DT)):
        row = np.full(4096, np.nan)
        a, b = refs.tabulate(1, t, until, row)
        inside = np.nonzero((refs.t_begin[1] < t) & (t <= until))[0]
        if not len(inside):
            assert a == b and np.isnan(row).all()
            continue
        assert (a, b) == (inside[0], inside[-1] + 1)
        assert np.array_equal(row[:b - a], single.phi(t[a:b])) and np.isnan(row[b - a:]).all()
        short = np.full(b - a - 1, np.nan)
        assert refs.tabulate(1, t, until, short) == (a, b) and np.isnan(short).all()  # too short: untouched
