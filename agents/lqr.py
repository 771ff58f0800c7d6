"""Tracking LQR on the hull's error dynamics, plus the recorded-law feedforward and pre-spin.

With the feedforward the reference satisfies ``J a_ref = -c phi_ref - k_t i_ff + d_exp``,
so the error ``e = phi_ref - phi`` obeys ``e'' = -(c / J) e + u + (residual torque) / J``
with ``u = k_t di / J`` (rad/s^2). The state is ``z = [e, e', integral(e)]``; the
discrete infinite-horizon LQR (``scipy.linalg.solve_discrete_are``) weighs
``(e / e_scale)^2 + (e' / rate_scale)^2 + integral_weight (integral / e_scale)^2``
against ``(u / u_scale)^2``. The observer's residual torque ``d`` can be cancelled
directly (``disturbance_gain`` in [0, 1]): ``di += disturbance_gain * d / k_t``.

Knobs (tuning: addedinertia_env/bench/tuning.py): ``e_scale`` (rad, the error the loop is sized for),
``rate_ratio`` (``rate_scale = e_scale * rate_ratio``), ``integral_weight``,
``disturbance_gain``, ``observer_bandwidth``; ``u_scale`` is 1 rad/s^2.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import solve_discrete_are

from agents.feedforward_pd import StrokeController


def lqr_gain(c_over_J: float, dt: float, q: np.ndarray, r: float) -> np.ndarray:
    """Discrete LQR gain ``K`` (u = -K z) for ``z = [e, e', integral e]`` over one period."""
    A = np.array([[1.0, dt, 0.0], [-c_over_J * dt, 1.0, 0.0], [dt, 0.0, 1.0]])
    B = np.array([[0.5 * dt * dt], [dt], [0.0]])
    Q = np.diag(q)
    R = np.array([[r]])
    P = solve_discrete_are(A, B, Q, R)
    return np.linalg.solve(R + B.T @ P @ B, B.T @ P @ A).reshape(-1)


class LQR(StrokeController):
    """Tracking LQR on ``[e, e', integral(e)]`` plus the recorded-law feed-forward and pre-spin.

    Knobs (see the module docstring): ``e_scale`` (rad), ``rate_ratio``, ``integral_weight``,
    ``disturbance_gain`` (0..1), ``observer_bandwidth`` (rad/s).
    """

    name = "lqr"
    DEFAULTS = {**StrokeController.DEFAULTS, "e_scale": 2e-4, "rate_ratio": 10.0, "integral_weight": 1.0,
                "disturbance_gain": 0.5}
    KNOBS = {"e_scale": (2e-5, 3e-3, "log"), "rate_ratio": (2.0, 60.0, "log"),
             "integral_weight": (0.01, 30.0, "log"), "disturbance_gain": (0.0, 1.0, "lin"),
             "observer_bandwidth": (2.0, 80.0, "log")}

    def reset(self, context) -> None:
        """Start a stroke as :class:`StrokeController` does and compute the discrete LQR gain for this period ``context.dt`` (s)."""
        super().reset(context)
        q = np.array([1.0 / self.e_scale**2, 1.0 / (self.e_scale * self.rate_ratio) ** 2,
                      self.integral_weight / self.e_scale**2])
        self.K = lqr_gain(self.c / self.J, context.dt, q, 1.0)
        self.integral = 0.0
        self._K_board = None

    def board_pd(self, obs: dict[str, float]) -> tuple[float, float, float]:
        """Two-rate, board mode "pd": the LQR's error and rate gains run on the board at its
        sample period; the integral term stays on the host (updated each host period from
        the encoder's tracking error) and rides on the feed-forward knots."""
        if getattr(self, "_K_board", None) is None:
            q = np.array([1.0 / self.e_scale**2, 1.0 / (self.e_scale * self.rate_ratio) ** 2,
                          self.integral_weight / self.e_scale**2])
            self._K_board = lqr_gain(self.c / self.J, self.ctx.board_dt, q, 1.0)
        K = self._K_board
        scale = -self.J / self.ctx.k_t
        if obs["is_reverse"] > 0.5:
            self.integral += obs["tracking_error"] * self.ctx.dt
        return scale * K[0], scale * K[1], scale * K[2] * self.integral

    def feedback(self, obs: dict[str, float], e: float, e_rate: float) -> float:
        """LQR feedback current, A: ``J u / k_t`` with ``u = -K [e, e', integral(e)]`` (rad/s^2), plus the observer's residual torque cancelled by ``disturbance_gain``."""
        self.integral += e * self.ctx.dt
        # The error's acceleration is +u: more hull torque (negative current) lowers it.
        u = -float(self.K @ np.array([e, e_rate, self.integral]))  # rad/s^2 on the error
        i = self.J * u / self.ctx.k_t
        if self.observer:
            i += self.disturbance_gain * self.obs_filter.disturbance / self.ctx.k_t
        return i
