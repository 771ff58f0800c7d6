"""The energy method's motor work: how the logged current is averaged over a sample interval, the
angles smoothed phase by phase for the work sums, and the patent's electric form of the work.

Part of the energy method (:mod:`addedinertia_env.identify.energy`); :class:`~.energy_balance.RunBalance`
sums these into its cumulative work.
"""

from __future__ import annotations

import numpy as np

from addedinertia_env.records.record import RunRecord
from addedinertia_env.records.scan_kernels import negative_step_ratios, relaxed_interval_means, value_change_starts
from addedinertia_env.identify.common import smooth_angle, smooth_angles


WORK_SMOOTHING_S = 0.2  # s, window of the quintic smoothing of the angles in the work sums


def interval_mean_current(t: np.ndarray, i: np.ndarray, R: float, L: float,
                          sampling: str = "instant") -> np.ndarray:
    """Mean current over each sample interval, A, from the logged current samples.

    ``sampling`` is the record's ``rig.current_sampling``: ``held-previous`` (a sample is the
    value over the interval before it) and ``held-next`` (over the interval after it) say
    it outright. For ``instant`` samples (the default), a drive holds its voltage over a sample, so inside it the current relaxes exponentially
    with ``tau = L / R`` (physics.md section 2). Its mean is then
    ``i_ss + (i0 - i1) tau / h`` with ``i_ss = (i1 - a i0) / (1 - a)``, ``a = exp(-h / tau)``:
    0.42 i0 + 0.58 i1 for ``tau = h``, not the trapezoid's 0.5 / 0.5 (the trapezoid leaves
    about 0.01 % of lambda66 in the reaction work). With ``L`` unknown (0) the trapezoid
    is used: it assumes nothing about the drive.
    """
    if sampling == "held-previous":
        return i[1:].astype(float)
    if sampling == "held-next":
        return i[:-1].astype(float)
    if not L > 0.0:
        return 0.5 * (i[1:] + i[:-1])
    tau = L / R
    t, i = np.asarray(t, dtype=float), np.asarray(i, dtype=float)
    if t.ndim != 1 or i.shape != t.shape:  # numpy's broadcasting (and errors) for anything but two series
        h = np.diff(t)
        a = np.exp(-h / tau)
        i_ss = (i[1:] - a * i[:-1]) / (1.0 - a)
        return i_ss + (i[:-1] - i[1:]) * tau / h
    decay = negative_step_ratios(t, tau)  # -h / tau, then exp(-h / tau) in place (numpy's exp)
    np.exp(decay, out=decay)
    return relaxed_interval_means(t, i, decay, tau)


def smooth_by_phase(rec: RunRecord, *angles: np.ndarray, cuts: np.ndarray | None = None) -> list[np.ndarray]:
    """Encoder angles smoothed within each contiguous block of one phase and brake state.

    The work sum ``sum(torque_k * dphi_k)`` is biased where the torque reacts to the same
    quantisation errors as the increments (a controller's feedback does): the smoothing
    must reject the quantisation's high frequencies well. A quintic over 0.2 s leaves
    about 1e-6 J of that correlation on the reverse stroke (a cubic over 40 ms: 3e-5 J,
    0.03 % of lambda66), while following the stroke itself (period 3-6 s) exactly. ``cuts``: the
    record's :func:`phase_blocks` when already known.
    """
    if cuts is None:
        cuts = phase_blocks(rec)
    out = [np.empty(len(angle), dtype=float) for angle in angles]
    for a, b in zip(cuts[:-1], cuts[1:]):
        smoothed = smooth_angles(rec.t[a:b], [angle[a:b] for angle in angles], window_s=WORK_SMOOTHING_S, degree=5)
        for o, x in zip(out, smoothed):
            o[a:b] = x
    return out


def phase_blocks(rec: RunRecord) -> np.ndarray:
    """Boundaries of the record's contiguous blocks of one phase and one brake state: sample
    indices ``[0, ..., len]`` (block ``j`` is ``cuts[j]:cuts[j + 1]``), from the record's phase
    blocks (``rec.views.phase_blocks``) and its ``brake`` column."""
    n = len(rec.phase)
    starts = rec.views.phase_blocks.starts
    inner = np.asarray(starts, dtype=np.int64)[1:]
    if "brake" in rec.samples:
        b = np.asarray(rec["brake"], dtype=float)
        if b.ndim != 1 or len(b) != n:  # numpy's broadcasting (and its error) as the masks compared it
            change = np.zeros(max(n - 1, 0), dtype=bool)
            change[inner - 1] = True
            change |= (b[1:] != b[:-1]) & ~(np.isnan(b[1:]) & np.isnan(b[:-1]))
            inner = np.nonzero(change)[0] + 1
        else:
            inner = np.union1d(inner, value_change_starts(b))
    return np.concatenate([[0], inner, [n]]).astype(np.int64)


def voltage_offset(t: np.ndarray, psi: np.ndarray, u: np.ndarray) -> float:
    """Intercept of the terminal voltage against the flywheel rate on an open-circuit stroke, V."""
    omega = np.gradient(smooth_angle(t, psi), t)
    X = np.column_stack([np.ones_like(omega), omega])
    coef, *_ = np.linalg.lstsq(X, u, rcond=None)
    return float(coef[0])


def electric_work_steps(t: np.ndarray, u: np.ndarray, i: np.ndarray, R: float, L: float) -> np.ndarray:
    """Electric energy minus ohmic loss and the change of magnetic energy per sample, J (the patent's form).

    A drive holds its terminal voltage over each sample, so the current inside a sample is
    the exponential ``L di/dt = u - R i - k_e Omega`` with ``tau = L / R``; trapezoids on
    ``u i`` and ``R i^2`` are off by percents when ``tau`` is near the sample period. Here each
    sample's exponential is rebuilt from its two end currents, and the voltage recorded at
    a sample's end is taken as the one held over it.
    """
    h = np.diff(t)
    tau = L / R
    a = np.exp(-h / tau)
    i0, i1 = i[:-1], i[1:]
    i_ss = (i1 - a * i0) / (1.0 - a)
    d = i0 - i_ss
    mean = i_ss + d * tau / h * (1.0 - a)
    mean_sq = i_ss**2 + 2.0 * i_ss * d * tau / h * (1.0 - a) + d**2 * tau / (2.0 * h) * (1.0 - a * a)
    return u[1:] * mean * h - R * mean_sq * h - 0.5 * L * (i1**2 - i0**2)
