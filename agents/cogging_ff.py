"""Feed-forward + PD with the motor's cogging mapped in the hold and fed forward (issue 28).

A motor's cogging (sim/drive.py) is a torque periodic in the rotor's angle, ``T(psi) = A
sin(m psi) + B cos(m psi)`` at the flywheel with ``m = n N`` cycles per flywheel radian (``n``
per motor turn, the lcm of slots and poles; ``N`` the gear ratio), that the current does not
show. The classical answer is to map it and feed its opposite forward. This entry:

* **observes the rotor's angle without a new sensor**: the controller sees the flywheel's
  rate, the slope of a quadratic fitted to the motor encoder's last samples
  (experiment/filters.py). Summed over the control periods (trapezoid rule) that rate is the encoder's angle
  smoothed by a kernel of unit gain that is exact for a quadratic, so it does not drift
  (``psi_hat``, up to a constant that the map's phase absorbs);
* **maps the cogging in the hold** (the hull is braked, so nothing of the stroke is spent):
  over its first ``sweep_s`` seconds (at most the hold less ``spinup_reserve_s``) a rate
  loop turns the flywheel slowly, at ``sweep_rate`` rad/s, where the cogging is a slow
  torque the encoder and the current both see. The flywheel's balance ``J_f psi'' = k_t i +
  T(psi) - c - d sgn(psi')`` twice integrated is fitted by least squares for every ``n`` of
  :attr:`periods`; the best ``n`` is kept where its fit stands out of every other period's
  (``min_ratio`` times the median one's) and its amplitude is clear of ``min_z`` standard errors;
  otherwise nothing is fed forward (the entry is then ``feedforward-pd`` with a later
  spin-up);
* **feeds it forward**: ``-T/k_t``, averaged over the coming control period at the angle the
  flywheel will sweep through at its present rate (a held command cancels what it can of a
  faster ripple; at the stroke's rates the average goes to zero), in the rest of the hold
  and the stroke.

Everything it uses is known or observed (``k_t``, ``J_flywheel``, ``gear_ratio`` of the record's
rig block, the flywheel rate and the current); it never reads the hidden cogging. Where the
cogging goes in the energy method's books, and what the feed-forward changes there, is
measured in docs/DRIVE.md ("Cogging feed-forward").
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from agents.base import ControllerContext
from agents.feedforward_pd import FeedforwardPD


def twice_integrated(x: np.ndarray, dt: float) -> np.ndarray:
    """``x`` (columns along axis 0) integrated twice from zero by the trapezoid rule, step ``dt``."""
    x = np.asarray(x, float)
    once = np.concatenate([np.zeros((1,) + x.shape[1:]), np.cumsum(0.5 * (x[1:] + x[:-1]), axis=0) * dt])
    return np.concatenate([np.zeros((1,) + x.shape[1:]), np.cumsum(0.5 * (once[1:] + once[:-1]), axis=0) * dt])


def fit_cogging(psi: np.ndarray, rate: np.ndarray, current: np.ndarray, dt: float, J_f: float, k_t: float,
                gear_ratio: float, periods: range, min_ratio: float = 10.0, min_z: float = 4.0,
                min_cycles: float = 2.0) -> dict[str, Any]:
    """The cogging map from a slow sweep: ``psi`` (rad, the flywheel's angle), ``rate`` (rad/s),
    ``current`` (A), sampled every ``dt`` s. Returns ``{"found": bool, "n", "m", "A", "B",
    "amplitude", "se", "ratio", "why"}`` with the torque at the flywheel ``A sin(m psi) + B cos(m psi)``
    N m, ``m = n gear_ratio``. The balance ``J_f psi'' = s k_t i + T(psi) - c - d sgn(psi')``
    twice integrated (columns: offset, ramp, current, constant, sign, and the cogging pair)."""
    psi, rate, current = (np.asarray(x, float) for x in (psi, rate, current))
    n_s = len(psi)
    t = np.arange(n_s) * dt
    y = psi - psi[0]
    sg = np.tanh(rate / 0.02)
    base = np.column_stack([np.ones(n_s), t, twice_integrated(np.column_stack([k_t * current, np.ones(n_s), sg]), dt)
                            / J_f])
    q0, _ = np.linalg.qr(base)
    r0 = y - q0 @ (q0.T @ y)
    span = float(np.ptp(psi))
    drops: dict[int, float] = {}
    best = None
    for n in periods:
        m = n * gear_ratio
        if span * m / (2 * math.pi) < min_cycles:
            continue
        # a cycle must span 8 control periods at the sweep's fastest rate to be seen
        if m * float(np.max(np.abs(rate))) * dt * 8 > 2 * math.pi:
            continue
        cog = twice_integrated(np.column_stack([np.sin(m * psi), np.cos(m * psi)]), dt) / J_f
        cog = cog - q0 @ (q0.T @ cog)
        c, *_ = np.linalg.lstsq(cog, r0, rcond=None)
        fitted = cog @ c
        drops[n] = float(fitted @ fitted)
        if best is None or drops[n] > drops[best[0]]:
            best = (n, m)
    if best is None or len(drops) < 5:
        return {"found": False, "why": "the sweep turned through too few cycles of the periods searched"}
    n, m = best
    cog = twice_integrated(np.column_stack([np.sin(m * psi), np.cos(m * psi)]), dt) / J_f
    A = np.column_stack([base, cog])
    c, *_ = np.linalg.lstsq(A, y, rcond=None)
    r = y - A @ c
    dof = n_s - A.shape[1]
    # the twice-integrated residuals are strongly correlated: the standard errors are inflated by
    # sqrt((1 + rho) / (1 - rho)) (rho the lag-one correlation, capped at 0.999)
    rho = float(np.clip((r[1:] @ r[:-1]) / max(float(r @ r), 1e-300), 0.0, 0.999))
    cov = np.linalg.pinv(A.T @ A) * float(r @ r) / dof * (1 + rho) / (1 - rho)
    a, b = float(c[-2]), float(c[-1])
    amp = math.hypot(a, b)
    se = math.sqrt(max(0.5 * (cov[-1, -1] + cov[-2, -2]), 0.0))
    # the best period must stand out of every other one searched: its drop of the residual over
    # the median drop (a chi-square with 2 degrees of freedom has median 2 ln 2, its largest of 60
    # about 2 ln 60: a ratio near 6 without cogging)
    others = [v for k, v in drops.items() if k != n]
    ratio = drops[n] / max(float(np.median(others)), 1e-300)
    found = bool(ratio >= min_ratio and amp >= min_z * se)
    why = (f"{n} cycles per motor turn, {amp * 1e3:.1f} +- {se * 1e3:.1f} mN m at the flywheel (its fit "
           f"{ratio:.0f} times the median period's)" + ("" if found else ": not clear of the noise, nothing fed forward"))
    return {"found": found, "n": int(n), "m": float(m), "A": a, "B": b, "amplitude": amp, "se": se, "ratio": ratio,
            "torque_scale": float(c[2]), "why": why}


class CoggingFeedforwardPD(FeedforwardPD):
    """:class:`~agents.feedforward_pd.FeedforwardPD` with the cogging mapped in the hold and fed forward (module doc)."""

    name = "cogging-ff"
    tuned_as = "feedforward-pd"  # the loop's gains are feedforward-pd's (the map adds no loop knob)
    DEFAULTS: dict[str, Any] = {**FeedforwardPD.DEFAULTS, "sweep_rate": 0.15, "sweep_s": 1.5,
                                "spinup_reserve_s": 1.0, "min_sweep_s": 0.4, "sweep_bandwidth": 20.0,
                                "min_ratio": 10.0, "min_z": 4.0, "periods_low": 4, "periods_high": 72,
                                "compensate": True}

    def reset(self, context: ControllerContext) -> None:
        """As :class:`FeedforwardPD`; then the sweep's length from the hold and an empty map."""
        super().reset(context)
        self.sweep_len = min(float(self.sweep_s), context.hold_s - float(self.spinup_reserve_s))
        if self.sweep_len < float(self.min_sweep_s):
            self.sweep_len = 0.0
        self.psi_hat = 0.0
        self.rate_prev: float | None = None
        self.t_hold = 0.0
        self.log: list[tuple[float, float, float]] = []  # (psi_hat, rate, current) over the sweep
        self.sweep_int = 0.0
        self.cogging: dict[str, Any] | None = None
        self.direction = 1.0 if self.omega_start >= 0 else -1.0  # sweep the way the pre-spin goes

    @property
    def periods(self) -> range:
        """Cycles per motor turn searched."""
        return range(int(self.periods_low), int(self.periods_high) + 1)

    def cogging_current(self, rate: float) -> float:
        """The current (A) that cancels the mapped cogging over the coming control period, 0 without a map."""
        cg = self.cogging
        if not cg or not cg["found"] or not self.compensate:
            return 0.0
        m, dt = cg["m"], self.ctx.dt
        th = m * self.psi_hat
        d = m * rate * dt  # the phase swept over the period
        if abs(d) < 1e-6:
            s_avg, c_avg = math.sin(th), math.cos(th)
        else:  # means of sin, cos(th + x) for x in [0, d]
            s_avg = (math.cos(th) - math.cos(th + d)) / d
            c_avg = (math.sin(th + d) - math.sin(th)) / d
        return -(cg["A"] * s_avg + cg["B"] * c_avg) / self.ctx.k_t

    def _finish_map(self) -> None:
        rows = np.array(self.log) if self.log else np.zeros((0, 3))
        if len(rows) < 50:
            self.cogging = {"found": False, "why": "no sweep (the hold is too short)"}
            return
        self.cogging = fit_cogging(rows[:, 0], rows[:, 1], rows[:, 2], self.ctx.dt, self.ctx.rig.J_flywheel,
                                   self.ctx.k_t, float(self.ctx.rig.gear_ratio), self.periods,
                                   float(self.min_ratio), float(self.min_z))

    def current(self, obs: dict[str, float]) -> float:
        """The command, A: the sweep (hold start), then feedforward-pd's plus the cogging's cancellation."""
        ctx = self.ctx
        rate = obs["flywheel_rate"]
        if self.rate_prev is not None:  # the trapezoid rule: exact for a quadratic angle, no drift
            self.psi_hat += 0.5 * (rate + self.rate_prev) * ctx.dt
        self.rate_prev = rate
        if obs["is_hold"] > 0.5 and self.cogging is None and self.t_hold < self.sweep_len:
            self.t_hold += ctx.dt
            self.log.append((self.psi_hat, rate, obs["current"]))
            # a PI rate loop at sweep_bandwidth rad/s on the flywheel's inertia
            J_f, w = ctx.rig.J_flywheel, float(self.sweep_bandwidth)
            ramp = min(1.0, self.t_hold / 0.1)  # start gently
            err = self.direction * float(self.sweep_rate) * ramp - rate
            self.sweep_int += err * ctx.dt
            i = J_f * (2.0 * w * err + w * w * self.sweep_int) / ctx.k_t
            i = float(np.clip(i, -ctx.i_max, ctx.i_max))
            self.i_prev = i
            return i
        if self.cogging is None:
            self._finish_map()
        i = super().current(obs)  # sets i_prev, the hull observer's current: without the cancellation,
        if obs["is_hold"] > 0.5 or obs["is_reverse"] > 0.5:  # which the cogging itself undoes
            i = float(np.clip(i + self.cogging_current(rate), -ctx.i_max, ctx.i_max))
        return i
