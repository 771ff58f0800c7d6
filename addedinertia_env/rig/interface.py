"""The rig protocol: what the experiment, the task and the environment need of a rig.

The MuJoCo model (:class:`~addedinertia_env.sim.mujoco_rig.MujocoRig`), a single view of
the batched model and the real bench (``hw_adapter``) all implement it. Nothing above
this interface knows which one it drives.
"""

from __future__ import annotations

from typing import Any, Protocol, runtime_checkable

from addedinertia_env.rig.known import KnownRig
from addedinertia_env.rig.signals import MotorCommand, Reading


@runtime_checkable
class Rig(Protocol):
    """What a rig offers the experiment and the task: the sim, the emulator and the bench alike.

    ``dt`` is the sample (control) period in s, ``known`` the experimenter's constants; the
    methods move the hull, set the brake and the motor command, and step one period,
    returning each time a :class:`~addedinertia_env.rig.signals.Reading` (SI units).
    """

    source: str  # "sim", "emulator" or "bench": the run record's ``source``

    @property
    def dt(self) -> float:
        """Sample (and control) period, s."""

    @property
    def known(self) -> KnownRig:
        """What the experimenter knows (the run record's ``rig`` block, typed)."""

    def reset(self, phi0: float = 0.0, psi0: float = 0.0, omega0: float = 0.0, brake: bool = True) -> Reading:
        """Bring the hull to ``phi0`` (rod twisted), motor passive, brake as given."""

    def set_brake(self, on: bool) -> None:
        """Engage or release the hull brake (engaging holds the hull where it stands)."""

    def step(self, cmd: MotorCommand) -> Reading:
        """Apply ``cmd`` for one sample period and return the new reading."""

    def truth(self) -> dict[str, Any] | None:
        """The run record's ``truth`` block for a simulated rig; ``None`` on a real bench."""
