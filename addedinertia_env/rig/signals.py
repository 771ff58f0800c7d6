"""The signals of the rig contract: what a controller asks of the drive (:class:`MotorCommand`,
one of :data:`MODES`) and what the data acquisition reports each sample (:class:`Reading`).

The simulator (:mod:`.motor`, :mod:`.sensors`), the board loop and the bench speak these
types; they hold no physics.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

MODES = ("passive", "current", "voltage")


@dataclass(frozen=True)
class MotorCommand:
    """What the motor driver is asked to do: ``mode`` in :data:`MODES` and its ``value``.

    ``value`` is a current in A (``current`` mode) or a voltage in V (``voltage`` mode);
    ``passive`` leaves the winding open. Raises ValueError for an unknown mode or a value
    that is not finite.
    """

    mode: str = "passive"  # one of MODES
    value: float = 0.0  # A in current mode, V in voltage mode

    def __post_init__(self) -> None:
        if self.mode not in MODES:
            raise ValueError(f"motor mode {self.mode!r}: expected one of {MODES}")
        if not np.isfinite(self.value):
            raise ValueError(f"motor command {self.value!r}: expected a finite number")


@dataclass(frozen=True)
class Reading:
    """One sample as the data acquisition sees it (SI units)."""

    t: float
    phi: float  # rad, hull encoder
    psi: float  # rad, motor encoder (flywheel relative to hull), unwrapped
    u: float  # V, terminal voltage
    i: float  # A, motor current
    brake: bool
