"""A steady-state Kalman filter on the hull's yaw, with the motor torque as a known input.

Why: a rate from quantised encoder differences is coarse (one 17-bit count per ms is
0.05 rad/s, physics.md section 7), and a derivative gain on it makes the current chatter
by amperes. The chatter is correlated with the quantisation error, which biases the
measured motor work (identify/common.py ``smooth_angle``), so it costs lambda66 accuracy.
The observer predicts the hull from its model and corrects with the encoder.

Model over one control period ``dt`` (sensor data and known constants only)::

    J phi'' = -c phi - k_t i + d_expected(t) + d

``phi`` is measured from the spring's neutral, ``J`` the inertia prior from the free
stroke, ``i`` the motor current (its reaction on the hull is ``-k_t i``),
``d_expected`` the damping torque the mirrored stroke should meet
(``-(J accel_ref + c phi_ref)``, from the recorded law) and ``d`` an unknown residual
torque, N m, modelled as a random walk. State ``x = [phi, w, d]``; measurement ``phi``
with the encoder's quantisation variance ``q^2 / 12``.

The gain is the steady-state Kalman gain (``scipy.linalg.solve_discrete_are`` on the
dual problem), so one step costs a few multiplications.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.linalg import solve_discrete_are


class HullObserver:
    """Estimates ``phi`` (rad), ``w`` (rad/s) and a residual torque ``d`` (N m).

    ``disturbance_bandwidth`` (rad/s) sets how fast ``d`` may wander: the process noise
    of ``d`` is chosen so that the filter tracks a torque step in about
    ``1 / disturbance_bandwidth`` seconds. Higher: faster, noisier.
    """

    def __init__(self, J: float, c: float, k_t: float, dt: float, encoder_counts: int,
                 disturbance_bandwidth: float = 20.0, torque_noise: float = 0.02):
        self.J, self.c, self.k_t, self.dt = float(J), float(c), float(k_t), float(dt)
        q = 2.0 * math.pi / encoder_counts if encoder_counts > 0 else 1e-6
        r = max(q * q / 12.0, 1e-14)  # rad^2, quantisation variance
        A = np.array([[1.0 - c * dt * dt / (2 * J), dt, dt * dt / (2 * J)],
                      [-c * dt / J, 1.0, dt / J],
                      [0.0, 0.0, 1.0]])
        B = np.array([dt * dt / (2 * J), dt / J, 0.0])  # per N m of known torque
        # Process noise: unmodelled torque on the hull (white) and the drift of d.
        s_d = disturbance_bandwidth * torque_noise * math.sqrt(dt)
        Q = np.diag([1e-14, (torque_noise * dt / J) ** 2, s_d**2])
        H = np.array([[1.0, 0.0, 0.0]])
        P = solve_discrete_are(A.T, H.T, Q, np.array([[r]]))
        S = H @ P @ H.T + r
        self.K = (P @ H.T / S).reshape(3)
        self.A, self.B = A, B
        self.x = np.zeros(3)

    def start(self, phi: float, w: float = 0.0, d: float = 0.0) -> None:
        """Start at a known state (the hull is braked at the reversal: ``w = 0``)."""
        self.x = np.array([phi, w, d], dtype=float)

    def predict(self, current: float, d_expected: float) -> None:
        """Advance one period with the mean motor current (A) and expected damping (N m)."""
        torque = -self.k_t * current + d_expected
        self.x = self.A @ self.x + self.B * torque

    def correct(self, phi_measured: float) -> None:
        """Update the estimate with a measured hull angle (rad)."""
        self.x = self.x + self.K * (phi_measured - self.x[0])

    @property
    def phi(self) -> float:
        """Estimated hull angle, rad."""
        return float(self.x[0])

    @property
    def rate(self) -> float:
        """Estimated hull rate, rad/s."""
        return float(self.x[1])

    @property
    def disturbance(self) -> float:
        """Estimated disturbance torque on the hull, N m."""
        return float(self.x[2])
