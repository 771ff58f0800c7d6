"""The part of the rig protocol every simulated rig shares: ``dt`` and ``known`` read from its
:class:`~.params.RigParams` (the MuJoCo rig, a batched rig's single view, a vector env's slot)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from addedinertia_env.rig.known import KnownRig

if TYPE_CHECKING:
    from addedinertia_env.sim.params import RigParams


class SimulatedRigBase:
    """``dt`` and ``known`` of a simulated rig, read from its :class:`RigParams` ``self.params``."""

    params: RigParams

    @property
    def dt(self) -> float:
        """Sample (and control) period, s."""
        return self.params.sensors.dt

    @property
    def known(self) -> KnownRig:
        """What the experimenter knows (the run record's ``rig`` block, typed)."""
        return self.params.known()
