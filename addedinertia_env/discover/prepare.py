"""Run records turned into what the gray-box model needs, and bad records refused.

For every reverse-symmetric run this keeps, per sample (SI units):

* the hull segments the model integrates: the **free stroke** (from the last braked
  sample before release to the brake) and the **reverse stroke** (from the last braked
  sample of the hold to the end of the record, the passive tail included); the hold
  itself is trivial (the brake fixes ``phi``);
* the **flywheel** segment (hold + reverse + tail): the absolute flywheel angle
  ``theta = phi + psi`` obeys ``J_f theta'' = k_t i + Q_fly(Omega)`` (physics.md section 2,
  second row of the mass matrix), which separates a current delay from a torque-constant
  error (physics.md section 8);
* the motor current with the sensor offset removed: on the free stroke the motor is
  open-circuit, so the true current is zero and the mean reading is the offset;
* noise floors measured from the record itself (encoder quantisation; the current's
  scatter on the free stroke).

Only the samples and the ``rig`` block are read; never ``truth``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from types import SimpleNamespace

import numpy as np

from ..record import RunRecord
from ..rig import forces
from ..rig.known import KnownRig

STEP_SAMPLES = 20  # samples per integrator step (20 ms at 1 kHz); the input is averaged over it
FLYWHEEL_CHUNK_S = 0.5  # s, flywheel residuals are shot from a fresh state every chunk
MIN_FREE_S = 0.5  # s, shortest free stroke worth fitting
MIN_REVERSE_S = 0.3  # s


class DiscoveryInputError(ValueError):
    """A record the discovery cannot use; the message names the run and what was expected."""


@dataclass
class HullSegment:
    """One stroke the hull model integrates, sampled every ``STEP_SAMPLES``."""

    run: int  # index of the run
    kind: str  # "free" or "reverse"
    t: np.ndarray  # s, raw sample times from the initial (braked) sample on
    phi: np.ndarray  # rad, raw hull angle, same samples
    current: np.ndarray  # A, offset-free measured current, same samples
    flywheel_friction: np.ndarray  # N m, Q_fly(Omega) per interval (len - 1), from the rig block
    steps: int  # number of integrator steps
    t_start: float  # s
    hold_before: float  # s, braked time before this segment started (reverse only)

    @property
    def phi_steps(self) -> np.ndarray:
        """Measured angle at the step boundaries (index 0 is the initial condition)."""
        return self.phi[:: STEP_SAMPLES][: self.steps + 1]


@dataclass
class FlywheelSegment:
    run: int
    t: np.ndarray
    theta: np.ndarray  # rad, absolute flywheel angle phi + psi
    current: np.ndarray  # A, offset free
    flywheel_friction: np.ndarray  # N m per interval
    chunks: list[slice] = field(default_factory=list)  # of the (sub-sampled) residual points


@dataclass
class RunData:
    name: str
    alpha: float  # rad, twist at release measured from the calibrated neutral
    hold_s: float  # s, measured braked time at the reversal
    free: HullSegment
    reverse: HullSegment
    flywheel: FlywheelSegment
    current_offset: float  # A
    current_noise: float  # A rms on the free stroke
    phase: np.ndarray  # phase labels of the record (for the report)


@dataclass
class Prepared:
    """All runs of one discovery, with the rig constants they share."""

    runs: list[RunData]
    rig: KnownRig
    J_hull: float
    J_flywheel: float
    c: float
    phi_neutral: float
    k_t: float
    dt: float
    phi_noise: float  # rad rms, hull encoder quantisation
    theta_noise: float  # rad rms, flywheel-channel noise floor after chunked shooting

    @property
    def names(self) -> list[str]:
        return [r.name for r in self.runs]

    def subset(self, idx) -> "Prepared":
        keep = [self.runs[k] for k in idx]
        return Prepared(**{**self.__dict__, "runs": keep})


def _contiguous(mask: np.ndarray) -> list[tuple[int, int]]:
    """(start, stop) of each block of True."""
    idx = np.nonzero(mask)[0]
    if not len(idx):
        return []
    breaks = np.nonzero(np.diff(idx) > 1)[0]
    starts = np.r_[idx[0], idx[breaks + 1]]
    stops = np.r_[idx[breaks] + 1, idx[-1] + 1]
    return list(zip(starts.tolist(), stops.tolist()))


def _rig_namespace(rig: KnownRig) -> SimpleNamespace:
    """The rotor friction constants in the shape :func:`forces.flywheel_friction_torque` reads."""
    return SimpleNamespace(motor=SimpleNamespace(friction_viscous=rig.friction_viscous,
                                                 friction_coulomb=rig.friction_coulomb))


def _check_record(rec: RunRecord) -> None:
    name = rec.name
    if rec.experiment.get("kind") != "reverse-symmetric":
        raise DiscoveryInputError(f"{name}: discovery needs reverse-symmetric runs (free, hold, reverse phases); "
                                  f"this is experiment.kind = {rec.experiment.get('kind')!r}")
    order = [p for k, p in enumerate(rec.phase) if k == 0 or p != rec.phase[k - 1]]
    for needed in ("free", "reverse"):
        blocks = _contiguous(rec.phase == needed)
        if len(blocks) != 1:
            raise DiscoveryInputError(f"{name}: column 'phase' has {len(blocks)} '{needed}' block(s); expected "
                                      f"exactly one (phase order seen: {' > '.join(order)})")
    if not order.index("free") < order.index("reverse"):
        raise DiscoveryInputError(f"{name}: the 'reverse' phase comes before 'free'; expected idle > free > hold > reverse")
    if rec.gaps:
        t0, gap = rec.gaps[0]
        raise DiscoveryInputError(f"{name}: gap of {gap:.4f} s in 't' after t = {t0:.4f} s; the whole-record fit "
                                  "needs uninterrupted sampling (cut the record or fill the gap)")
    dt = np.diff(rec.t)
    nominal = rec.known.dt
    if np.max(np.abs(dt - nominal)) > 0.05 * nominal:
        k = int(np.argmax(np.abs(dt - nominal)))
        raise DiscoveryInputError(f"{name}: sample interval {dt[k]:.6f} s at t = {rec.t[k]:.4f} s; expected uniform "
                                  f"sampling at 1/rig.sample_rate = {nominal:.6f} s (resample first)")
    free = _contiguous(rec.phase == "free")[0]
    if free[0] == 0:
        raise DiscoveryInputError(f"{name}: the record starts in 'free'; expected at least one braked 'idle' sample "
                                  "before release (the initial condition)")
    if (free[1] - free[0]) * nominal < MIN_FREE_S:
        raise DiscoveryInputError(f"{name}: free stroke of {(free[1] - free[0]) * nominal:.3f} s; expected at least "
                                  f"{MIN_FREE_S} s")
    rev = _contiguous(rec.phase == "reverse")[0]
    if (len(rec) - rev[0]) * nominal < MIN_REVERSE_S:
        raise DiscoveryInputError(f"{name}: reverse stroke of {(len(rec) - rev[0]) * nominal:.3f} s; expected at "
                                  f"least {MIN_REVERSE_S} s")


def _hull_segment(run: int, kind: str, rec: RunRecord, a: int, b: int, current: np.ndarray, q_fly: np.ndarray,
                  hold_before: float) -> HullSegment:
    """Samples a..b-1 (a: the braked initial sample), cut to whole integrator steps."""
    steps = (b - 1 - a) // STEP_SAMPLES
    stop = a + steps * STEP_SAMPLES + 1
    return HullSegment(run=run, kind=kind, t=rec.t[a:stop], phi=rec["phi"][a:stop], current=current[a:stop],
                       flywheel_friction=q_fly[a:stop - 1], steps=steps, t_start=float(rec.t[a]),
                       hold_before=hold_before)


def prepare(records: list[RunRecord]) -> Prepared:
    """Check the records and cut them into model segments; raises :class:`DiscoveryInputError`."""
    if not records:
        raise DiscoveryInputError("no records given; expected one or more reverse-symmetric run records")
    keys = ("J_hull", "J_flywheel", "c_torsion", "phi_neutral", "k_t", "sample_rate")
    rig0 = records[0].known
    for rec in records:
        _check_record(rec)
        rig = rec.known
        for key in keys:
            if not math.isclose(getattr(rig, key), getattr(rig0, key), rel_tol=1e-9, abs_tol=1e-12):
                raise DiscoveryInputError(f"{rec.name}: rig.{key} = {rec.rig[key]!r} differs from "
                                          f"{records[0].name}'s {records[0].rig[key]!r}; discover runs of one rig "
                                          "together")
    fric = _rig_namespace(rig0)
    dt = rig0.dt
    runs = []
    for k, rec in enumerate(records):
        t, phi, psi = rec.t, rec["phi"], rec["psi"]
        f0, f1 = _contiguous(rec.phase == "free")[0]
        r0, _ = _contiguous(rec.phase == "reverse")[0]
        i_free = rec["i"][f0:f1]
        offset = float(np.mean(i_free))
        noise = float(np.std(i_free))
        current = rec["i"] - offset
        omega = np.diff(psi) / np.diff(t)  # mean flywheel rate per interval
        q_fly = np.asarray(forces.flywheel_friction_torque(omega, fric), dtype=float)
        hold = float(t[r0 - 1] - t[f1 - 1])
        free = _hull_segment(k, "free", rec, f0 - 1, f1, current, q_fly, 0.0)
        rev = _hull_segment(k, "reverse", rec, r0 - 1, len(rec), current, q_fly, hold)
        fw = _flywheel_segment(k, rec, f1 - 1, current, q_fly, dt)
        alpha = rig0.phi_neutral - float(phi[f0 - 1])
        runs.append(RunData(name=rec.name, alpha=alpha, hold_s=hold, free=free, reverse=rev, flywheel=fw,
                            current_offset=offset, current_noise=noise, phase=rec.phase))
    q_phi = 2 * math.pi / rig0.phi_counts if rig0.phi_counts else _scatter(runs[0].free.phi)
    q_psi = 2 * math.pi / rig0.psi_counts if rig0.psi_counts else q_phi
    J_f, k_t = rig0.J_flywheel, rig0.k_t
    theta_noise = _flywheel_noise_floor(q_psi / math.sqrt(12), float(np.median([r.current_noise for r in runs])),
                                        k_t, J_f, dt)
    return Prepared(runs=runs, rig=rig0, J_hull=rig0.J_hull, J_flywheel=J_f,
                    c=rig0.c_torsion, phi_neutral=rig0.phi_neutral, k_t=k_t, dt=dt,
                    phi_noise=q_phi / math.sqrt(12), theta_noise=theta_noise)


def _scatter(x: np.ndarray) -> float:
    """Noise of a smooth signal from its third differences (for encoders of unknown resolution)."""
    d3 = np.diff(x, 3)
    return float(np.std(d3) / math.sqrt(20.0))


def _flywheel_segment(run: int, rec: RunRecord, a: int, current: np.ndarray, q_fly: np.ndarray,
                      dt: float) -> FlywheelSegment:
    t = rec.t[a:]
    theta = rec["phi"][a:] + rec["psi"][a:]
    n_points = (len(t) - 1) // STEP_SAMPLES
    per_chunk = max(4, int(round(FLYWHEEL_CHUNK_S / (STEP_SAMPLES * dt))))
    chunks = [slice(s, min(s + per_chunk, n_points)) for s in range(0, n_points, per_chunk)]
    if chunks and chunks[-1].stop - chunks[-1].start < 4:  # too short to fit a state: merge
        last = chunks.pop()
        chunks[-1] = slice(chunks[-1].start, last.stop)
    return FlywheelSegment(run=run, t=t, theta=theta, current=current[a:], flywheel_friction=q_fly[a:],
                           chunks=chunks)


def double_integral(t: np.ndarray, accel_per_interval: np.ndarray) -> np.ndarray:
    """Angle from an acceleration held over each interval, starting at rest at 0."""
    h = np.diff(t)
    vel = np.concatenate([[0.0], np.cumsum(accel_per_interval * h)])
    # exact for a piecewise-constant acceleration: dtheta = v0 h + a h^2 / 2
    dtheta = vel[:-1] * h + 0.5 * accel_per_interval * h * h
    return np.concatenate([[0.0], np.cumsum(dtheta)])


def _flywheel_noise_floor(q_sigma: float, current_noise: float, k_t: float, J_f: float, dt: float) -> float:
    """RMS flywheel residual expected from quantisation plus the current's white noise.

    Current noise double-integrated is a wandering angle; each chunk of the flywheel
    residual is shot from its own fitted state (angle and rate), which removes most of it.
    The remainder is computed by a small seeded Monte Carlo of exactly that procedure.
    """
    rng = np.random.default_rng(0)
    n = int(round(FLYWHEEL_CHUNK_S / dt))
    t = np.arange(n + 1) * dt
    sq = []
    for _ in range(20):
        noise = rng.standard_normal(n + 1) * current_noise
        acc = k_t * 0.5 * (noise[1:] + noise[:-1]) / J_f
        ang = double_integral(t, acc)[::STEP_SAMPLES]
        tt = t[::STEP_SAMPLES]
        X = np.column_stack([np.ones_like(tt), tt])
        res = ang - X @ np.linalg.lstsq(X, ang, rcond=None)[0]
        sq.append(np.mean(res**2))
    return float(math.sqrt(q_sigma**2 + float(np.mean(sq))))
