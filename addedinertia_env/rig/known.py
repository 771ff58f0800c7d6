"""What the experimenter knows about the rig: the run record's ``rig`` block, typed.

:class:`KnownRig` is the one typed form of the constants that estimators, controllers,
the task and the experiment may use (data sheet, test in air, static calibration; never
the simulated truth). It is built one way from each source:

* a run record's ``rig`` block: :meth:`KnownRig.from_block` (``RunRecord.known``),
* a simulated rig's :class:`~addedinertia_env.rig.params.RigParams`: :meth:`KnownRig.from_params`
  (``RigParams.known()``; a preset goes through :func:`~addedinertia_env.rig.presets.rig_from_mapping`),
* a lab file joined with the board's CAPS: ``hw_adapter.lab.known_rig``,

and written back with :meth:`KnownRig.to_block` (the keys of ``spec/run-record.md``; keys
it does not know, such as a bench's ``board`` and ``lab``, are kept in ``extra``).

``L`` may be unknown (absent, ``None``) or neglected (0): a method that needs it calls
:meth:`KnownRig.require_L`, which says so, instead of the record being refused.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Mapping

# The spec keys of the ``rig`` block this class reads; every other key goes to ``extra``.
BLOCK_KEYS = ("J_hull", "J_flywheel", "c_torsion", "phi_neutral", "k_t", "R", "L", "i_max", "u_max",
              "motor_friction", "encoder_counts", "sample_rate", "gear_ratio")


class KnownRigError(ValueError):
    """A known-rig constant that is missing or unusable for what was asked."""


@dataclass(frozen=True)
class KnownRig:
    """The experimenter's constants of one rig, SI units (the run record's ``rig`` block)."""

    J_hull: float
    """kg m^2, yaw inertia of hull + rod + frame + motor stator, from a test in air."""
    J_flywheel: float
    """kg m^2, flywheel + rotor inertia about the yaw axis."""
    c_torsion: float
    """N m/rad, torsion rod stiffness from static calibration."""
    k_t: float
    """N m/A, torque per ampere at the flywheel (= back-EMF constant per flywheel rad/s, SI): the motor's
    data-sheet constant times :attr:`gear_ratio` (the block's ``k_t`` is the motor's own)."""
    R: float
    """ohm, winding resistance."""
    sample_rate: float
    """Hz, sampling (and control) rate."""
    phi_neutral: float = 0.0
    """rad, calibrated neutral angle of the rod, encoder frame."""
    L: float | None = None
    """H, winding inductance; ``None``: unknown, 0: neglected (see :meth:`require_L`)."""
    i_max: float | None = None
    """A, drive current limit; ``None``: not stated."""
    u_max: float | None = None
    """V, supply voltage; ``None``: not stated."""
    friction_viscous: float = 0.0
    """N m s, rotor bearing viscous friction (``motor_friction.viscous``; 0 if absent)."""
    friction_coulomb: float = 0.0
    """N m, rotor bearing dry friction (``motor_friction.coulomb``; 0 if absent)."""
    phi_counts: int = 0
    """Hull encoder counts per turn (``encoder_counts.phi``); 0: not quantised / not stated."""
    psi_counts: int = 0
    """Motor encoder counts per turn (``encoder_counts.psi``); 0: not quantised / not stated."""
    gear_ratio: float = 1.0
    """Motor turns per flywheel turn (the block's ``gear_ratio``; absent: 1, direct drive)."""
    motor_k_t: float | None = field(default=None, compare=False)
    """N m/A, the motor's own data-sheet constant as the block states it (``None``: ``k_t / gear_ratio``)."""
    extra: dict[str, Any] = field(default_factory=dict, compare=False)
    """Other keys of the block (a bench's ``board``, ``lab``, a lab's own notes), kept on round trip."""

    def __post_init__(self) -> None:
        for name in ("J_hull", "J_flywheel", "c_torsion", "k_t", "R", "sample_rate"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise KnownRigError(f"KnownRig.{name} = {value!r}: expected a finite number > 0 (SI units)")
        g = self.gear_ratio
        if isinstance(g, bool) or not (isinstance(g, (int, float)) and math.isfinite(g) and g >= 1):
            raise KnownRigError(f"KnownRig.gear_ratio = {g!r}: expected a finite number >= 1 (motor turns per "
                                "flywheel turn)")

    # --- derived -------------------------------------------------------------------
    @property
    def dt(self) -> float:
        """Sample period, s."""
        return 1.0 / self.sample_rate

    @property
    def current_limit(self) -> float:
        """``i_max`` in A, or infinity when the block does not state it."""
        return math.inf if self.i_max is None else self.i_max

    def require_L(self, method: str) -> float:
        """The winding inductance in H for ``method``; raises :class:`KnownRigError` naming the
        method when the record does not give it (absent). 0 (neglected) is returned as 0."""
        if self.L is None:
            raise KnownRigError(f"{method} needs rig.L (winding inductance, H); the record does not give it")
        return self.L

    # --- building ------------------------------------------------------------------
    @classmethod
    def from_block(cls, block: Mapping[str, Any]) -> "KnownRig":
        """From a run record's ``rig`` block (assumed checked by the record reader)."""
        fric = block.get("motor_friction") or {}
        counts = block.get("encoder_counts") or {}

        def opt(key: str) -> float | None:
            value = block.get(key)
            return None if value is None else float(value)

        gear = float(block.get("gear_ratio", 1.0))
        k_t = float(block["k_t"])
        return cls(J_hull=float(block["J_hull"]), J_flywheel=float(block["J_flywheel"]),
                   c_torsion=float(block["c_torsion"]), phi_neutral=float(block.get("phi_neutral", 0.0)),
                   k_t=k_t * gear, gear_ratio=gear, motor_k_t=k_t if "gear_ratio" in block else None,
                   R=float(block["R"]), L=opt("L"), i_max=opt("i_max"),
                   u_max=opt("u_max"), friction_viscous=float(fric.get("viscous", 0.0)),
                   friction_coulomb=float(fric.get("coulomb", 0.0)), phi_counts=int(counts.get("phi", 0) or 0),
                   psi_counts=int(counts.get("psi", 0) or 0), sample_rate=float(block["sample_rate"]),
                   extra={k: v for k, v in block.items() if k not in BLOCK_KEYS})

    @classmethod
    def from_params(cls, params: Any) -> "KnownRig":
        """From a simulated rig's :class:`~addedinertia_env.rig.params.RigParams` (no truth)."""
        m, s = params.motor, params.sensors
        gear = float(params.drive.gear_ratio)
        return cls(J_hull=params.hull.J_hull, J_flywheel=m.J_flywheel, c_torsion=params.spring.c,
                   phi_neutral=params.spring.phi_neutral, k_t=m.k_t * gear, gear_ratio=gear,
                   motor_k_t=m.k_t if gear != 1.0 else None, R=m.R, L=m.L, i_max=m.i_max, u_max=m.u_max,
                   friction_viscous=m.friction_viscous, friction_coulomb=m.friction_coulomb,
                   phi_counts=s.phi_counts, psi_counts=s.psi_counts, sample_rate=s.sample_rate)

    # --- writing -------------------------------------------------------------------
    def to_block(self) -> dict[str, Any]:
        """The run record's ``rig`` block (spec key names; unstated optional keys left out)."""
        geared = self.gear_ratio != 1.0 or self.motor_k_t is not None  # the motor's own constant and the ratio
        k_t = (self.motor_k_t if self.motor_k_t is not None else self.k_t / self.gear_ratio) if geared else self.k_t
        block: dict[str, Any] = {"J_hull": self.J_hull, "J_flywheel": self.J_flywheel, "c_torsion": self.c_torsion,
                                 "phi_neutral": self.phi_neutral, "k_t": k_t, "R": self.R}
        for key in ("L", "i_max", "u_max"):
            if getattr(self, key) is not None:
                block[key] = getattr(self, key)
        block["motor_friction"] = {"viscous": self.friction_viscous, "coulomb": self.friction_coulomb}
        block["encoder_counts"] = {"phi": self.phi_counts, "psi": self.psi_counts}
        block["sample_rate"] = self.sample_rate
        if geared:
            block["gear_ratio"] = self.gear_ratio
        block.update(self.extra)
        return block
