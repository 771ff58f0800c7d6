"""Run records turned into what the gray-box model needs; records it cannot use reported and skipped.

Every record the spec allows is taken as the DAQ logged it (issue 11):

* **segments by what the record says**: ``phase`` and ``brake`` together
  (:func:`addedinertia_env.records.record.motion_phase`): a braked sample is never motion. A
  reverse-symmetric run gives a **free stroke** (release to the brake) and a **reverse
  stroke** (release after the hold to the next braked sample, an unbraked passive tail
  included); with no braked sample between them the two are one continuous **stroke**.
  A free-decay run gives one free stroke. Forced-oscillation runs are skipped (reported).
* **the recorded times**: no uniform grid is assumed. The model steps over groups of
  samples (about :data:`STEP_S`); each step's length comes from ``t``, so dropped samples,
  jitter and any rate from 250 Hz to 10 kHz are integrated on the times they were taken.
* **the release instant**: the brake lets go at the last braked sample, or, when that
  sample was dropped, one nominal period before the first moving sample
  (:func:`release_instant`).
* the **flywheel** segment (hold + reverse + tail of a reverse-symmetric run): the
  absolute flywheel angle ``theta = phi + psi`` obeys ``J_f theta'' = k_t i + Q_fly(Omega)``
  (physics.md section 2), which separates a current delay from a torque-constant error;
* the **current as the DAQ logged it**: offset removed (the motor is open-circuit on the
  free stroke, so the true current is zero there); whether a sample is the value at its
  instant or held over an interval (``rig.current_sampling``, :data:`~addedinertia_env.records.record.CURRENT_SAMPLING`)
  is read from the rig block, or, when absent, estimated from the flywheel channel and
  reported;
* noise floors measured from the record itself.

Only the samples and the ``rig`` block are read; never ``truth``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from types import SimpleNamespace

import numpy as np

from addedinertia_env.records.record import CURRENT_SAMPLING, RunRecord, current_sampling, motion_phase, sampling
from addedinertia_env.sim import forces

STEP_S = 0.02  # s, target length of one integrator step (the input is integrated exactly within it)
FLYWHEEL_CHUNK_S = 0.5  # s, flywheel residuals are shot from a fresh state every chunk
MIN_FREE_S = 0.5  # s, shortest free stroke worth fitting
MIN_REVERSE_S = 0.3  # s
# With no braked sample between the strokes (hold 0), the reverse stroke still starts from
# rest at the stop phi2 where the phase switches (physics.md section 3: the hull "slows to a
# stop at phi2"; a lab's controller may clamp it there for an instant). False: each stroke
# is integrated from rest at its first sample (measured to fit another lab's no-hold runs
# to the noise floor, 1.0 x, where one continuous stroke left 1.7 x); True: one
# continuous stroke through the reversal.
CONTINUOUS_NO_HOLD = False
RIG_KEYS = ("J_hull", "J_flywheel", "c_torsion", "phi_neutral", "k_t")


class DiscoveryInputError(ValueError):
    """No record the discovery can use; the message names the runs and what was expected."""


@dataclass
class HullSegment:
    """One stroke the hull model integrates from rest, in steps of ``step_samples`` samples."""

    run: int  # index of the run
    kind: str  # "free", "reverse" or "stroke" (free continuing into reverse with no hold)
    t: np.ndarray  # s, sample times from the initial (rest) instant on; t[0] is the release instant
    phi: np.ndarray  # rad, hull angle at those samples (phi[0]: the braked angle)
    current: np.ndarray  # A, offset-free measured current, same samples
    flywheel_friction: np.ndarray  # N m, Q_fly(Omega) per interval (len - 1), from the rig block
    steps: int  # number of integrator steps
    step_samples: int
    t_start: float  # s, release instant
    hold_before: float  # s, braked time before this segment started (reverse only)
    carry_from: int | None = None  # index (in the model's segment list) whose water state flows in

    @property
    def phi_steps(self) -> np.ndarray:
        """Measured angle at the step boundaries (index 0 is the initial condition)."""
        return self.phi[:: self.step_samples][: self.steps + 1]

    @property
    def t_steps(self) -> np.ndarray:
        """Times of the integrator step boundaries, s."""
        return self.t[:: self.step_samples][: self.steps + 1]


@dataclass
class FlywheelSegment:
    """The flywheel channel of one run: absolute angle, current and rotor friction per interval."""

    run: int
    t: np.ndarray
    theta: np.ndarray  # rad, absolute flywheel angle phi + psi
    current: np.ndarray  # A, offset free
    flywheel_friction: np.ndarray  # N m per interval
    step_samples: int = 1
    chunks: list[slice] = field(default_factory=list)  # of the (sub-sampled) residual points


@dataclass
class RunData:
    """One run cut into hull segments (free, reverse) and its flywheel channel, with its offsets and noise."""

    name: str
    kind: str  # experiment kind: "reverse-symmetric" or "free-decay"
    alpha: float  # rad, twist at release measured from the calibrated neutral
    hold_s: float  # s, measured braked time at the reversal (0 for a free decay)
    segments: list[HullSegment]
    flywheel: FlywheelSegment | None
    current_offset: float  # A
    current_noise: float  # A rms on the free stroke
    phase: np.ndarray  # motion phase of every sample (phase and brake together)
    sampling: dict = field(default_factory=dict)

    @property
    def free(self) -> HullSegment:
        """The free stroke's hull segment."""
        return self.segments[0]

    @property
    def reverse(self) -> HullSegment | None:
        """The reverse (or driven) stroke's hull segment, if the run has one."""
        return next((s for s in self.segments if s.kind in ("reverse", "stroke")), None)


@dataclass
class Prepared:
    """All usable runs of one discovery, with the rig constants they share."""

    runs: list[RunData]
    rig: object  # KnownRig
    J_hull: float
    J_flywheel: float
    c: float
    phi_neutral: float
    k_t: float
    dt: float  # s, nominal sample period
    phi_noise: float  # rad rms, hull encoder quantisation
    theta_noise: float  # rad rms, flywheel-channel noise floor after chunked shooting
    step_samples: int = 20
    current_mode: str = "instant"
    current_mode_report: dict = field(default_factory=dict)
    skipped: list[dict] = field(default_factory=list)  # {"run", "reason"} of records not used
    release_lag: float = 0.0  # s, added to every release instant (see with_release_lag)

    @property
    def names(self) -> list[str]:
        """Names of the runs."""
        return [r.name for r in self.runs]

    def subset(self, idx) -> "Prepared":
        """The same prepared data with only the runs at positions ``idx``."""
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


def _rig_namespace(rig) -> SimpleNamespace:
    """The rotor friction constants in the shape :func:`forces.flywheel_friction_torque` reads."""
    return SimpleNamespace(motor=SimpleNamespace(friction_viscous=rig.friction_viscous,
                                                 friction_coulomb=rig.friction_coulomb))


def step_samples_for(rate: float) -> int:
    """Samples per integrator step at ``rate`` Hz (about :data:`STEP_S`)."""
    return max(1, int(round(STEP_S * rate)))


def release_instant(t: np.ndarray, rest: int, first: int, period: float, lag: float = 0.0) -> float:
    """When the brake let go, s: one nominal period before the first moving sample, not before the
    last braked one (plus ``lag``, s).

    A DAQ logs the brake state at a sample and acts on it after: the last braked sample is
    the release instant, and when that sample is missing (a dropped sample at release) the
    release still lies one period before the first moving sample, not at the braked
    sample seen before the drop (an error of one period there biases lambda66 by about
    0.1 %).
    """
    return max(float(t[rest]), float(t[first]) - period) + lag


def _usable(rec: RunRecord, mp: np.ndarray) -> str | None:
    """Why ``rec`` cannot be used (None: usable)."""
    kind = rec.experiment.get("kind")
    if kind not in ("reverse-symmetric", "free-decay"):
        return f"experiment.kind = {kind!r}; discovery uses reverse-symmetric and free-decay runs"
    free = _contiguous(mp == "free")
    if len(free) != 1:
        return f"{len(free)} blocks of free motion (phase 'free', brake off); expected exactly one"
    if free[0][0] == 0:
        return "the record starts in free motion; expected at least one braked sample before release"
    if kind == "reverse-symmetric":
        rev = _contiguous(mp == "reverse")
        if len(rev) != 1:
            return f"{len(rev)} blocks of reverse motion (phase 'reverse', brake off); expected exactly one"
        if rev[0][0] < free[0][0]:
            return "the reverse stroke comes before the free one; expected idle > free > hold > reverse"
    return None


def _hull_segment(run: int, kind: str, rec: RunRecord, rest: int, first: int, stop: int, current: np.ndarray,
                  q_fly: np.ndarray, hold_before: float, n: int) -> HullSegment | None:
    """Samples ``rest``..``stop``-1 (``rest``: the braked sample before motion), cut to whole steps."""
    tr = release_instant(rec.t, rest, first, rec.known.dt)
    steps = (stop - 1 - rest) // n
    if steps < 2:
        return None
    end = rest + steps * n + 1
    t = rec.t[rest:end].astype(float).copy()
    t[0] = tr
    return HullSegment(run=run, kind=kind, t=t, phi=rec["phi"][rest:end], current=current[rest:end],
                       flywheel_friction=q_fly[rest:end - 1], steps=steps, step_samples=n, t_start=tr,
                       hold_before=hold_before)


def _held_mask(rec: RunRecord, mp: np.ndarray) -> np.ndarray:
    held = mp == "hold"
    if "brake" in rec.samples:
        held = held | (np.asarray(rec["brake"]) == 1.0)
    return held


def _prepare_run(k: int, rec: RunRecord, rig0, n: int, dt: float) -> RunData | str:
    mp = motion_phase(rec)
    why = _usable(rec, mp)
    if why:
        return why
    t, phi, psi = rec.t, rec["phi"], rec["psi"]
    held = _held_mask(rec, mp)
    f0, f1 = _contiguous(mp == "free")[0]
    i_free = rec["i"][f0:f1]
    offset = float(np.mean(i_free))
    noise = float(np.std(i_free))
    current = rec["i"] - offset
    omega = np.diff(psi) / np.diff(t)  # mean flywheel rate per interval
    q_fly = np.asarray(forces.flywheel_friction_torque(omega, _rig_namespace(rig0)), dtype=float)
    alpha = rig0.phi_neutral - float(phi[f0 - 1])
    kind = rec.experiment["kind"]

    def motion_stop(start: int) -> int:
        """End of the motion from ``start``: the next held sample, or a gap no step can bridge."""
        after = np.nonzero(held[start:])[0]
        stop = start + int(after[0]) if after.size else len(rec)
        return min(stop, _before_gap(t, start, dt))

    segments: list[HullSegment] = []
    flywheel = None
    hold = 0.0
    free_stop = motion_stop(f0)
    if (t[min(free_stop, len(t) - 1)] - t[f0]) < MIN_FREE_S:
        return f"free motion of {t[min(free_stop, len(t) - 1)] - t[f0]:.3f} s; expected at least {MIN_FREE_S} s"
    if kind == "free-decay":
        seg = _hull_segment(k, "free", rec, f0 - 1, f0, free_stop, current, q_fly, 0.0, n)
        segments.append(seg)
    else:
        r0, _ = _contiguous(mp == "reverse")[0]
        rev_stop = motion_stop(r0)
        if t[rev_stop - 1] - t[r0] < MIN_REVERSE_S:
            return f"reverse motion of {t[rev_stop - 1] - t[r0]:.3f} s; expected at least {MIN_REVERSE_S} s"
        if free_stop >= r0 and CONTINUOUS_NO_HOLD:  # no braked sample between the strokes: one continuous stroke
            segments.append(_hull_segment(k, "stroke", rec, f0 - 1, f0, rev_stop, current, q_fly, 0.0, n))
        else:
            free_stop = min(free_stop, r0)
            hold = float(t[r0 - 1] - t[free_stop - 1])
            segments.append(_hull_segment(k, "free", rec, f0 - 1, f0, free_stop, current, q_fly, 0.0, n))
            segments.append(_hull_segment(k, "reverse", rec, r0 - 1, r0, rev_stop, current, q_fly, hold, n))
        # The flywheel's balance holds through the hold and the reverse stroke whatever cut the free
        # stroke short (a gap): it starts at the last sample before the hull is held.
        held_after = np.nonzero(held[f0:r0])[0]
        free_end = f0 + int(held_after[0]) if held_after.size else r0
        flywheel = _flywheel_segment(k, rec, min(free_end, r0) - 1, current, q_fly, n)
    if any(s is None for s in segments):
        return "a stroke shorter than two integrator steps"
    return RunData(name=rec.name, kind=kind, alpha=alpha, hold_s=hold, segments=segments, flywheel=flywheel,
                   current_offset=offset, current_noise=noise, phase=mp, sampling=sampling(rec).to_json())


def prepare(records: list[RunRecord], current_mode: str | None = None) -> Prepared:
    """Cut the usable records into model segments; the others are listed in ``skipped``.

    ``current_mode``: force how the logged current is read (one of CURRENT_SAMPLING);
    default: the rig block's ``current_sampling``, else estimated from the flywheel channel.
    Raises :class:`DiscoveryInputError` when no record is usable.
    """
    if not records:
        raise DiscoveryInputError("no records given; expected reverse-symmetric or free-decay run records")
    rig0 = records[0].known
    n = step_samples_for(rig0.sample_rate)
    runs: list[RunData] = []
    skipped: list[dict] = []
    for rec in records:
        rig = rec.known
        differs = [key for key in RIG_KEYS
                   if not math.isclose(getattr(rig, key), getattr(rig0, key), rel_tol=1e-9, abs_tol=1e-12)]
        if differs:
            skipped.append({"run": rec.name, "reason": f"rig.{differs[0]} = {getattr(rig, differs[0])!r} differs from "
                                                        f"{records[0].name}'s {getattr(rig0, differs[0])!r}; "
                                                        "one discovery is one rig"})
            continue
        rec_n = step_samples_for(rig.sample_rate)
        out = _prepare_run(len(runs), rec, rig0, rec_n, rig.dt)
        if isinstance(out, str):
            skipped.append({"run": rec.name, "reason": out})
            continue
        runs.append(out)
    if not runs:
        raise DiscoveryInputError("no usable record: " + "; ".join(f"{s['run']}: {s['reason']}" for s in skipped))
    q_phi = 2 * math.pi / rig0.phi_counts if rig0.phi_counts else _scatter(runs[0].free.phi)
    q_psi = 2 * math.pi / rig0.psi_counts if rig0.psi_counts else q_phi
    J_f, k_t = rig0.J_flywheel, rig0.k_t
    dt = rig0.dt
    flying = [r for r in runs if r.flywheel is not None]
    noise_i = float(np.median([r.current_noise for r in (flying or runs)]))
    theta_noise = _flywheel_noise_floor(q_psi / math.sqrt(12), noise_i, k_t, J_f, dt)
    data = Prepared(runs=runs, rig=rig0, J_hull=rig0.J_hull, J_flywheel=J_f, c=rig0.c_torsion,
                    phi_neutral=rig0.phi_neutral, k_t=k_t, dt=dt, phi_noise=q_phi / math.sqrt(12),
                    theta_noise=theta_noise, step_samples=n, skipped=skipped)
    stated, said = current_sampling(records[0].known)
    if current_mode is not None:
        if current_mode not in CURRENT_SAMPLING:
            raise ValueError(f"current_mode {current_mode!r}; expected one of {CURRENT_SAMPLING}")
        data.current_mode, data.current_mode_report = current_mode, {"used": current_mode, "source": "caller"}
    elif said:
        data.current_mode, data.current_mode_report = stated, {"used": stated, "source": "rig.current_sampling"}
    else:
        scores = {m: flywheel_rms(data, m) for m in CURRENT_SAMPLING}
        finite = {m: v for m, v in scores.items() if math.isfinite(v)}
        used = min(finite, key=finite.get) if finite else stated
        data.current_mode = used
        data.current_mode_report = {"used": used, "source": "estimated from the flywheel channel" if finite
                                    else "default (no current flowed)", "flywheel_rms_rad": scores}
    return data


def with_release_lag(data: Prepared, lag: float) -> Prepared:
    """A copy of ``data`` with every stroke released ``lag`` s after :func:`release_instant`'s
    instant (kept before the stroke's first moving sample).

    ``lag`` = one period: the DAQ's convention is the other one (release at the first
    moving sample). :func:`choose_release_lag` picks between them by the fit.
    """
    import dataclasses  # noqa: PLC0415

    runs = []
    for run in data.runs:
        segs = []
        for seg in run.segments:
            t = seg.t.copy()
            t0 = seg.t_start - data.release_lag + lag
            t[0] = min(t0, t[1] - 1e-9 * (t[1] - t[0] + 1.0))
            segs.append(dataclasses.replace(seg, t=t, t_start=float(t[0])))
        runs.append(dataclasses.replace(run, segments=segs))
    return dataclasses.replace(data, runs=runs, release_lag=lag)


def _scatter(x: np.ndarray) -> float:
    """Noise of a smooth signal from its third differences (for encoders of unknown resolution)."""
    d3 = np.diff(x, 3)
    return float(np.std(d3) / math.sqrt(20.0))


def _before_gap(t: np.ndarray, start: int, dt: float) -> int:
    """Index after the last sample before the first gap from ``start`` that is longer than an
    integrator step and five periods (the input over it is unknown; the stroke ends there)."""
    limit = max(STEP_S, 5.0 * dt)
    big = np.nonzero(np.diff(t[start:]) > limit)[0]
    return start + int(big[0]) + 1 if big.size else len(t)


def _flywheel_segment(run: int, rec: RunRecord, a: int, current: np.ndarray, q_fly: np.ndarray,
                      n: int) -> FlywheelSegment:
    b = _before_gap(rec.t, a, rec.known.dt)
    t = rec.t[a:b]
    theta = rec["phi"][a:b] + rec["psi"][a:b]
    n_points = (len(t) - 1) // n + 1
    step_s = float(np.median(np.diff(t))) * n
    per_chunk = max(4, int(round(FLYWHEEL_CHUNK_S / step_s)))
    chunks = [slice(s, min(s + per_chunk, n_points)) for s in range(0, n_points, per_chunk)]
    if len(chunks) > 1 and chunks[-1].stop - chunks[-1].start < 4:  # too short to fit a state: merge
        last = chunks.pop()
        chunks[-1] = slice(chunks[-1].start, last.stop)
    return FlywheelSegment(run=run, t=t, theta=theta, current=current[a:b], flywheel_friction=q_fly[a:b - 1],
                           step_samples=n, chunks=chunks)


def interval_current(t: np.ndarray, current: np.ndarray, mode: str, delay: float = 0.0
                     ) -> tuple[np.ndarray, np.ndarray]:
    """The current at the start and at the end of every sample interval, A (two arrays of ``len(t) - 1``).

    ``mode`` (see :data:`~addedinertia_env.records.record.CURRENT_SAMPLING`): ``instant`` - linear
    between samples; ``held-previous`` - sample ``k + 1`` held over interval ``k``;
    ``held-next`` - sample ``k`` held over interval ``k``. ``delay`` (s): the channel lags
    the encoders, so the true current at ``t`` is the logged one at ``t + delay``.
    """
    if mode == "instant":
        x = current if delay == 0.0 else np.interp(t + delay, t, current)
        return x[:-1], x[1:]
    level = current[1:] if mode == "held-previous" else current[:-1]
    if delay != 0.0:
        mid = 0.5 * (t[1:] + t[:-1])
        level = np.interp(mid + delay, mid, level)
    return level, level


def double_integral(t: np.ndarray, acc_start: np.ndarray, acc_end: np.ndarray | None = None) -> np.ndarray:
    """Angle from an acceleration linear over each interval (start, end values), from rest at 0.

    Exact for piecewise-linear (or, with ``acc_end`` None, piecewise-constant) acceleration.
    """
    acc_end = acc_start if acc_end is None else acc_end
    h = np.diff(t)
    vel = np.concatenate([[0.0], np.cumsum(0.5 * (acc_start + acc_end) * h)])
    dtheta = vel[:-1] * h + h * h * (2.0 * acc_start + acc_end) / 6.0
    return np.concatenate([[0.0], np.cumsum(dtheta)])


def flywheel_prediction(fw: FlywheelSegment, k_t: float, J_f: float, mode: str, delay: float = 0.0,
                        ratio: float = 1.0, parts: bool = False):
    """Model flywheel angle (from rest at 0) at every ``step_samples``-th sample, rad.

    With ``parts``: the motor part (per unit ``ratio``) and the friction part separately.
    """
    ia, ib = interval_current(fw.t, fw.current, mode, delay)
    q = fw.flywheel_friction
    motor = double_integral(fw.t, k_t * ia / J_f, k_t * ib / J_f)[:: fw.step_samples]
    fric = double_integral(fw.t, q / J_f)[:: fw.step_samples]
    n = fw.chunks[-1].stop if fw.chunks else 0
    if parts:
        return motor[:n], fric[:n]
    return (ratio * motor + fric)[:n]


def _chunk_residual(fw: FlywheelSegment, y: np.ndarray) -> np.ndarray:
    t = fw.t[:: fw.step_samples]
    out = []
    for sl in fw.chunks:
        tt = t[sl] - t[sl][0]
        X = np.column_stack([np.ones_like(tt), tt])
        coef, *_ = np.linalg.lstsq(X, y[sl], rcond=None)
        out.append(y[sl] - X @ coef)
    return np.concatenate(out) if out else np.zeros(0)


def flywheel_rms(data: Prepared, mode: str) -> float:
    """RMS flywheel residual (rad) reading the current as ``mode``, the torque scale fitted (no delay)."""
    rows_m, rows_y = [], []
    for run in data.runs:
        fw = run.flywheel
        if fw is None or not fw.chunks:
            continue
        motor, fric = flywheel_prediction(fw, data.k_t, data.J_flywheel, mode, parts=True)
        obs = fw.theta[:: fw.step_samples][: len(motor)]
        rows_m.append(_chunk_residual(fw, motor))
        rows_y.append(_chunk_residual(fw, obs - fric))
    if not rows_m:
        return math.nan
    m, y = np.concatenate(rows_m), np.concatenate(rows_y)
    ratio = float(m @ y / (m @ m)) if m @ m > 0 else 1.0
    return float(np.sqrt(np.mean((y - ratio * m) ** 2)))


def _flywheel_noise_floor(q_sigma: float, current_noise: float, k_t: float, J_f: float, dt: float) -> float:
    """RMS flywheel residual expected from quantisation plus the current's white noise.

    Current noise double-integrated is a wandering angle; each chunk of the flywheel
    residual is shot from its own fitted state (angle and rate), which removes most of it.
    The remainder is computed by a small seeded Monte Carlo of exactly that procedure.
    """
    rng = np.random.default_rng(0)
    n = int(round(FLYWHEEL_CHUNK_S / dt))
    step = step_samples_for(1.0 / dt)
    t = np.arange(n + 1) * dt
    sq = []
    for _ in range(20):
        noise = rng.standard_normal(n + 1) * current_noise
        acc = k_t * 0.5 * (noise[1:] + noise[:-1]) / J_f
        ang = double_integral(t, acc)[::step]
        tt = t[::step]
        X = np.column_stack([np.ones_like(tt), tt])
        res = ang - X @ np.linalg.lstsq(X, ang, rcond=None)[0]
        sq.append(np.mean(res**2))
    return float(math.sqrt(q_sigma**2 + float(np.mean(sq))))
