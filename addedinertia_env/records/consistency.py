"""Do a record's angles and its current tell the same story? The flywheel's momentum in the reverse stroke.

:mod:`addedinertia_env.records.plausibility` bounds each channel against the rig; this check ties the
angles to the current by Newton's second law for the flywheel. The motor's torque
``G k_t i`` (``G``: ``rig.gear_ratio``, 1 without a gearbox) and the rotor's bearing friction
are the only torques on the flywheel, so from the last held sample ``a`` before the reverse
stroke to any sample ``k`` of it, its absolute rate ``theta' = phi' + psi'`` can change by no more
than their impulse allows (up to the first gap in ``t`` over five nominal periods, where the
current is unknown):

    J_f |theta'(k) - theta'(a)| <= int_a^k (G k_t |i| + |M_f(Omega)|) dt,
    M_f(Omega) = f_visc Omega + f_coul (from the rig block; Omega = psi').

In the reverse stroke the current drives the flywheel hard (tens of rad/s of change), so the
bound is tested where it matters. A record whose angles are in degrees while its rig block
and current are in SI units breaks it by a factor of about 57: the logged current could not
have spun the flywheel (and so pushed the hull round against the spring) that much. The check
refuses where the change exceeds :data:`IMPULSE_MARGIN` x the impulse plus what the encoders can
misread: rates are centred differences over +-:data:`RATE_HALF_S` whose ends may be off by a few
counts and the channel's noise (the plausibility check's allowances), plus
:data:`MOMENTUM_FLOOR`; only changes over :data:`SIGNAL_FACTOR` times that misreading are judged
(a stroke that barely drives the flywheel cannot tell units apart). The margin allows a torque constant or a current gain 50 % off (a data
sheet's ``k_t`` is good to a few per cent); the measured ratios on the shared dev sets and on
simulated records with every hidden effect are in docs/RELIABILITY.md. A hull angle in
degrees with the flywheel's in radians moves ``theta`` by the hull's swing only (56 x a few
0.1 rad/s) and is not always caught here. Never reads ``truth``.
"""

from __future__ import annotations

import numpy as np

from addedinertia_env.records.plausibility import NOISE_SIGMAS, QUANT_STEPS, _count_step, _noise
from addedinertia_env.records.record import MAX_GAP_PERIODS
from addedinertia_env.records.run_record import RecordError, RunRecord

IMPULSE_MARGIN = 1.5  # the flywheel's momentum change may reach this many times the torques' impulse
MOMENTUM_FLOOR = 1e-4  # N m s, plus this much (a tiny stroke: offsets of the current channel)
RATE_HALF_S = 0.01  # s, half-width of the centred differences that give the flywheel's rate
SIGNAL_FACTOR = 10.0  # a momentum change is judged only where it is this many times what the encoders may misread


def momentum_account(rec: RunRecord) -> dict | None:
    """The flywheel's momentum account over the reverse stroke at its worst sample, or None where the
    record has no reverse stroke: ``change`` (N m s, ``J_f |theta'(k) - theta'(a)|``), ``impulse`` (N m s,
    the bound's integral), ``allowed`` (N m s, :data:`IMPULSE_MARGIN` x ``impulse`` + the encoders'
    allowance + :data:`MOMENTUM_FLOOR`), ``used`` (``change / allowed``, the largest over the stroke:
    over 1 is refused), ``line`` and ``t`` (the CSV line and time of that sample)."""
    if rec.experiment.get("kind") != "reverse-symmetric":
        return None
    # the reverse stroke as the hull experienced it (record.motion_phase's 'reverse': a braked sample is
    # never motion), without relabelling the other phases
    moving = np.asarray(rec.phase) == "reverse"
    if "brake" in rec.samples:
        moving &= np.asarray(rec["brake"]) != 1.0
    idx = np.nonzero(moving)[0]
    if idx.size < 2:
        return None
    breaks = np.nonzero(np.diff(idx) > 1)[0]
    r0 = int(idx[0])
    r1 = int(idx[breaks[0]] + 1) if breaks.size else int(idx[-1] + 1)
    known = rec.known
    gear = known.gear_ratio
    t = np.asarray(rec.t, dtype=float)
    psi = np.asarray(rec["psi"], dtype=float)
    theta = np.asarray(rec["phi"], dtype=float) + psi
    i = np.asarray(rec["i"], dtype=float)
    a = max(r0 - 1, 0)  # the last held sample: the stroke starts from it
    # The balance is followed up to the first gap over five periods (the current over it is unknown),
    # with every rate's window before it.
    dt = np.diff(t[a:r1])
    gaps = np.nonzero(dt > MAX_GAP_PERIODS / known.sample_rate * (1 + 1e-6))[0]
    if gaps.size:
        end_t = t[a + int(gaps[0])]
        r1 = a + int(np.searchsorted(t[a:r1], end_t - RATE_HALF_S, side="right"))
        if r1 - a < 2:
            return None
    tt = t[a:r1]

    def rate(x, at):
        return (np.interp(at + RATE_HALF_S, t, x) - np.interp(at - RATE_HALF_S, t, x)) / (2 * RATE_HALF_S)

    w_fly = rate(theta, tt)
    change = known.J_flywheel * np.abs(w_fly - w_fly[0])
    # Each rate is the mean of theta' over +-RATE_HALF_S, so the change between two of them is bounded by the
    # impulse from RATE_HALF_S before the first to RATE_HALF_S after the second (a current that steps up at
    # the stroke's start already shows in the rate of the samples just before it).
    lo = int(np.searchsorted(t, tt[0] - RATE_HALF_S, side="right")) - 1
    hi = int(np.searchsorted(t, tt[-1] + RATE_HALF_S, side="left")) + 1
    lo, hi = max(lo, 0), min(hi, len(t))
    tg = t[lo:hi]
    torque = gear * abs(known.k_t) * np.abs(i[lo:hi]) + np.abs(known.friction_viscous * rate(psi, tg)) \
        + abs(known.friction_coulomb)
    cumulative = np.concatenate([[0.0], np.cumsum(0.5 * (torque[1:] + torque[:-1]) * np.diff(tg))])
    impulse = np.interp(tt + RATE_HALF_S, tg, cumulative) - np.interp(tt[0] - RATE_HALF_S, tg, cumulative)
    # what the encoders may misread: each end of each difference a few counts and the noise off
    d_angle = QUANT_STEPS * (_count_step(known.phi_counts) + _count_step(known.psi_counts)) \
        + NOISE_SIGMAS * _noise(theta[a:r1])
    reading = known.J_flywheel * 2.0 * d_angle / RATE_HALF_S
    allowed = IMPULSE_MARGIN * impulse + reading + MOMENTUM_FLOOR
    # A stroke that barely drives the flywheel (random actions of a few tenths of an ampere) changes its
    # momentum by a few encoder misreadings: there the balance cannot tell units apart, and an honest
    # record was seen at twice its impulse. Only changes well clear of the misreading are judged.
    judged = change > SIGNAL_FACTOR * (reading + MOMENTUM_FLOOR)
    used = np.where(judged, change / allowed, 0.0)
    k = int(np.argmax(used))
    return {"change": float(change[k]), "impulse": float(impulse[k]), "allowed": float(allowed[k]),
            "used": float(used[k]), "line": a + k + 2, "t": float(t[a + k])}


def check_momentum_consistent(rec: RunRecord) -> dict | None:
    """Refuse (:class:`RecordError`) a reverse stroke whose flywheel changed its speed by more than the
    logged current can have; returns the account (None without a reverse stroke)."""
    acc = momentum_account(rec)
    if acc is None or acc["used"] <= 1.0:
        return acc
    raise RecordError(
        f"{rec.name}: line {acc['line']} (t = {acc['t']:.4g} s), columns 'phi', 'psi': since the brake let go the "
        f"flywheel's angular momentum J_flywheel (phi' + psi') changed by {acc['change']:.4g} N m s, but the motor's "
        f"current and the rotor's friction can have changed it by at most {acc['allowed']:.4g} N m s "
        f"({IMPULSE_MARGIN:g} x int (k_t |i| + |M_f|) dt = {acc['impulse']:.4g} N m s, plus what the encoders may "
        f"misread): the current that drove the stroke cannot have spun the flywheel, and so moved the hull, that "
        f"far; expected phi and psi in radians (degrees?), i in A and rig.J_flywheel, rig.k_t in SI units")
