"""One environment of the batched model behind the :class:`~addedinertia_env.rig.interface.Rig` protocol.

:class:`BatchedSingleRig` is a :class:`~addedinertia_env.sim.batched.BatchedRig` of one
environment with the protocol's scalar methods, so that
:class:`~addedinertia_env.experiment.protocol.Experiment` (and anything else written for
:class:`~addedinertia_env.sim.mujoco_rig.MujocoRig`) drives the batched dynamics
unchanged. With the same parameters and seed it gives the MuJoCo rig's readings (same
noise stream) and trajectories within the tolerance stated in :mod:`.batched`.
"""

from __future__ import annotations

import numpy as np

from addedinertia_env.sim import forces
from addedinertia_env.sim.batched import BatchedRig
from addedinertia_env.sim.motor import MODES, MotorCommand
from addedinertia_env.sim.params import RigParams
from addedinertia_env.sim.sensors import Reading
from addedinertia_env.sim.simulated import SimulatedRigBase


class BatchedSingleRig(SimulatedRigBase):
    """A single simulated rig on the batched (numpy) dynamics."""

    source = "sim"

    def __init__(self, params: RigParams, seed: int | np.random.SeedSequence | None = None, dtype=np.float64):
        self.params = params
        self.batch = BatchedRig(params, n_envs=1, seed=[seed], dtype=dtype)
        self.k_t = float(forces.true_torque_constant(params))

    @property
    def time(self) -> float:
        """Simulated time, s."""
        return float(self.batch.t[0])

    @property
    def brake(self) -> bool:
        """Whether the hull brake is engaged."""
        return bool(self.batch.brake[0])

    def reset(self, phi0: float = 0.0, psi0: float = 0.0, omega0: float = 0.0, brake: bool = True) -> Reading:
        """Bring the hull to ``phi0`` (rad), motor passive, brake as given; the first reading."""
        return self.batch.reset(phi0=phi0, psi0=psi0, omega0=omega0, brake=brake).single(0)

    def set_brake(self, on: bool) -> None:
        """Engage or release the hull brake."""
        self.batch.set_brake(bool(on))

    def step(self, cmd: MotorCommand) -> Reading:
        """Apply ``cmd`` for one sample period; the new reading."""
        return self.batch.step(MODES.index(cmd.mode), cmd.value).single(0)

    def truth(self) -> dict:
        """The run record's ``truth`` block (scoring only); same content as MujocoRig.truth()."""
        return forces.truth(self.params, self.k_t)

    def true_state(self) -> dict:
        """Simulator truth (t, phi, w, psi, omega, i, u, water_rate, energy): scoring and tests only."""
        return self.batch.true_state(0)
