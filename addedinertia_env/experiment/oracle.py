"""An ideal tracking controller for the simulated rig only: computed torque on the truth.

It reads the simulator's true state and true parameters, so it exists to test the
identification methods (physics.md section 4: with ideal tracking the energy method must
return the true lambda66 to 0.05 %), never to be benchmarked or deployed.
"""

from __future__ import annotations

import numpy as np

from addedinertia_env.sim import forces
from addedinertia_env.sim.mujoco_rig import MujocoRig


class OracleController:
    """Computed-torque tracking of the reverse stroke on the simulator's true state and parameters.

    The floor of the benchmark (row ``oracle``): no real controller can know the truth.
    ``omega_c`` (rad/s) sets the tracking bandwidth: ``kp = omega_c^2``, ``kd = 2 omega_c``.
    """

    name = "oracle"

    def __init__(self, rig: MujocoRig, omega_c: float = 40.0):
        self.rig = rig
        self.kp, self.kd = omega_c**2, 2.0 * omega_c

    def reset(self, context) -> None:
        """Keep the episode's controller context (reference, sample period)."""
        self.ctx = context

    def predict(self, observation, state=None, episode_start=None, deterministic=True):
        """The motor current (fraction of ``i_max``, clipped to [-1, 1]) whose reaction makes the true
        hull follow the reference; 0 before the reverse stroke begins. Returns ``(action, state)``.
        """
        p, s, ctx = self.rig.params, self.rig.true_state(), self.ctx
        ref = ctx.reference
        t = s.t + 0.5 * ctx.dt  # the torque acts over the coming sample
        if t < ref.t_begin:
            return np.zeros(1, dtype=np.float32), state
        J = p.hull.J_hull + forces.hull_armature(p)  # A66(inf) with radiation memory
        acc = float(ref.accel(t)) + self.kp * (float(ref.phi(t)) - s.phi) + self.kd * (float(ref.rate(t)) - s.w)
        hull_torque = J * acc + p.spring.c * (s.phi - forces.true_neutral(p)) \
            - float(forces.hull_extra_torque(s.phi, s.w, s.water_rate, p)) - s.radiation_torque
        i = -hull_torque / self.rig.k_t  # reaction of the motor torque on the hull
        if forces.has_drive_torque(p):  # it knows the drive: the reaction of cogging and gear friction too
            for _ in range(2):  # the mesh friction grows with |i|: two fixed-point passes
                i = -(hull_torque + float(forces.drive_torque(s.psi, s.omega, i, self.rig.k_t, p))) / self.rig.k_t
        lag = forces.driver_lag(p) if forces.has_driver_lag(p) else 0.0
        if lag:  # and its current loop: the command whose first-order response is i after this sample
            i = (i - s.i * lag) / (1.0 - lag)
        return np.array([np.clip(i / p.motor.i_max, -1, 1)], dtype=np.float32), state
