"""Energy-aware model-predictive control over a short horizon on the linearised hull model.

Every control period, over ``N`` future steps of ``step_s`` seconds (horizon
``N * step_s``), the controller chooses current corrections ``di_k`` to the
recorded-law feedforward ``i_ff(t_k)`` minimising::

    sum_k  (e_k / e_scale)^2 + (e'_k / (e_scale * rate_ratio))^2
         + energy_weight * ((i_ff(t_k) + di_k) / i_max)^2

The last term is the energy awareness: the ohmic loss ``R i^2`` and the work through
the motor both grow with the current, and every joule through the motor is measurement
error in lambda66 (physics.md section 4). The error model is the LQR's
(``e'' = -(c/J) e + k_t di / J``, residual torque ``d`` from the observer held over the
horizon). Without constraints the minimiser is linear, so it is solved in closed form
(one matrix set up per stroke, one matrix-vector product per step); the current limit is
then applied by clipping. Only the first correction is used (receding horizon).

Knobs (tuning: addedinertia_env/bench/tuning.py): ``e_scale``, ``rate_ratio``, ``energy_weight``,
``horizon_s``, ``observer_bandwidth``; ``step_s`` is fixed at 10 ms.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import expm

from agents.base import stroke_feedforward_current
from agents.feedforward_pd import StrokeController


class MPC(StrokeController):
    """Energy-aware receding-horizon control on the linearised error model (see the module docstring).

    Knobs: ``e_scale`` (rad), ``rate_ratio``, ``energy_weight`` (on ``(i / i_max)^2``),
    ``horizon_s`` (s), ``observer_bandwidth`` (rad/s); ``step_s`` (s) is the prediction step.
    """

    name = "mpc"
    DEFAULTS = {**StrokeController.DEFAULTS, "e_scale": 2e-4, "rate_ratio": 10.0, "energy_weight": 1e-3,
                "horizon_s": 0.1, "step_s": 0.01}
    KNOBS = {"e_scale": (2e-5, 3e-3, "log"), "rate_ratio": (2.0, 60.0, "log"),
             "energy_weight": (1e-6, 1.0, "log"), "horizon_s": (0.03, 0.3, "log"),
             "observer_bandwidth": (2.0, 80.0, "log")}

    def reset(self, context) -> None:
        """Start a stroke as :class:`StrokeController` does and set up the closed-form minimiser's gains for the horizon (once per stroke)."""
        super().reset(context)
        n = max(2, int(round(self.horizon_s / self.step_s)))
        h = self.step_s
        a = self.c / self.J
        # Exact discretisation of x' = [[0, 1], [-a, 0]] x + [0, 1] (u + dist), zero-order hold.
        M = np.zeros((3, 3))
        M[0, 1], M[1, 0], M[1, 2] = 1.0, -a, 1.0
        E = expm(M * h)
        A, B = E[:2, :2], E[:2, 2]
        # Stacked predictions x_k = A^k x0 + sum_j A^(k-1-j) B (u_j + dist), k = 1..n.
        F = np.zeros((2 * n, 2))
        G = np.zeros((2 * n, n))
        Ak = np.eye(2)
        powers = [np.eye(2)]
        for k in range(1, n + 1):
            Ak = A @ Ak
            powers.append(Ak)
            F[2 * (k - 1):2 * k] = Ak
        for k in range(1, n + 1):
            for j in range(k):
                G[2 * (k - 1):2 * k, j] = powers[k - 1 - j] @ B
        q = np.tile([1.0 / self.e_scale**2, 1.0 / (self.e_scale * self.rate_ratio) ** 2], n)
        gain_u = context.k_t / self.J  # rad/s^2 per ampere
        rho = self.energy_weight / context.i_max**2  # per A^2
        Gi = G * gain_u  # prediction per ampere of correction
        H = Gi.T @ (q[:, None] * Gi) + rho * np.eye(n)
        Hinv_row = np.linalg.solve(H, np.eye(n))[0]  # first row of H^-1: only di_0 is applied
        self._kx = Hinv_row @ (Gi.T @ (q[:, None] * F))  # di_0 = -kx x0 - kd dist - kff i_ff
        self._kd = Hinv_row @ (Gi.T @ (q * G.sum(axis=1)))
        self._kff = rho * Hinv_row
        self._n = n

    def feedback(self, obs: dict[str, float], e: float, e_rate: float) -> float:
        """The first current correction, A, of the horizon's optimum given the errors, the observer's residual torque and the feed-forward ahead."""
        ctx, h, n = self.ctx, self.step_s, self._n
        # The error state x = [e, e']; its model input is -(residual torque)/J.
        dist = -(self.obs_filter.disturbance / self.J) if self.observer else 0.0
        t_now = ctx.reference.t_begin + obs["phase_progress"] * ctx.reference.law.duration
        tk = t_now + h * np.arange(n)
        ref = ctx.reference
        phi_n = ctx.rig.phi_neutral
        i_ff = (stroke_feedforward_current(ctx, ref.phi(tk) - phi_n, ref.accel(tk), self.J)
                if self.feedforward else np.zeros(n))
        x0 = np.array([e, e_rate])
        return float(-(self._kx @ x0) - self._kd * dist - self._kff @ i_ff)
