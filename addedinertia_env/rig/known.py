"""What the experimenter knows about the rig: the run record's ``rig`` block, typed.

:class:`KnownRig` is the one typed form of the constants that estimators, controllers,
the task and the experiment may use (data sheet, test in air, static calibration; never
the simulated truth). It is built one way from each source:

* a run record's ``rig`` block: :meth:`KnownRig.from_block` (``RunRecord.known``),
* a simulated rig's :class:`~addedinertia_env.sim.params.RigParams`: :meth:`KnownRig.from_params`
  (``RigParams.known()``; a preset goes through :func:`~addedinertia_env.sim.presets.rig_from_mapping`),
* a lab file joined with the board's CAPS: ``hw_adapter.lab.known_rig``,

and written back with :meth:`KnownRig.to_block` (the keys of ``spec/run-record.md``; keys
it does not know, such as a bench's ``board`` and ``lab``, are kept in ``extra``).

``L`` may be unknown (absent, ``None``) or neglected (0): a method that needs it calls
:meth:`KnownRig.require_L`, which says so, instead of the record being refused.

The block's keys are declared once, in :data:`RIG_BLOCK` (name, meaning and unit, required or
not, the bound a value must keep, who states it): the record reader
(:mod:`addedinertia_env.records.record`), :class:`KnownRig` and the bench's lab file
(``hw_adapter.lab``) all read that one table (``spec/run-record.md``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Mapping



@dataclass(frozen=True)
class BlockKey:
    """One key of the run record's ``rig`` block (``spec/run-record.md``)."""

    name: str
    meaning: str
    """What it holds, with its unit (for messages)."""
    required: bool
    bound: str
    """What a stated value must be: ``positive`` (a finite number > 0), ``nonnegative`` (>= 0),
    ``angle`` (a finite number, |value| <= 2 pi), ``friction`` (a mapping of ``viscous`` and
    ``coulomb``, each >= 0), ``choice`` (one of ``choices``), ``as-stated`` (read as given: a
    value that is not a positive number counts as not stated)."""
    source: str
    """Who states it: ``lab`` (calibration, data sheet: a bench's lab file), ``board`` (its CAPS
    message), ``daq`` (how the recording was made)."""
    choices: tuple[str, ...] = ()
    """The values a ``choice`` key may take."""
    note: str = ""
    """What 0 or absence means, where that matters (shown in messages)."""


# How a logged current sample relates to the true current (``rig.current_sampling``):
#   "instant"       - the value at the sample instant (a sampled analogue channel): the
#                     current between samples is interpolated linearly;
#   "held-previous" - the value held over the interval before the sample (an averaging
#                     or integrating converter, or a controller logging what it applied);
#   "held-next"     - the value held from the sample to the next (a controller logging the
#                     command it is about to apply, with no inductance to smooth it).
# Absent: "instant" (the documented default).
CURRENT_SAMPLING = ("instant", "held-previous", "held-next")
DEFAULT_CURRENT_SAMPLING = "instant"

# The ``rig`` block, key by key, in the spec's order: the one declaration of its keys.
RIG_BLOCK = (
    BlockKey("J_hull", "hull + rod + frame + stator yaw inertia, kg m^2", True, "positive", "lab"),
    BlockKey("J_flywheel", "flywheel + rotor inertia, kg m^2", True, "positive", "lab"),
    BlockKey("c_torsion", "torsion rod stiffness, N m/rad", True, "positive", "lab"),
    BlockKey("phi_neutral", "calibrated neutral angle, rad", True, "angle", "lab"),
    BlockKey("k_t", "motor torque constant, N m/A", True, "positive", "lab"),
    BlockKey("R", "winding resistance, ohm", True, "positive", "lab"),
    BlockKey("L", "winding inductance, H", False, "nonnegative", "lab", note="0 or absent: neglected or unknown"),
    BlockKey("gear_ratio", "motor turns per flywheel turn (absent: 1)", False, "positive", "lab"),
    BlockKey("motor_friction", "rotor bearing friction: viscous, N m s, and coulomb, N m (absent: 0)", False,
             "friction", "lab"),
    BlockKey("i_max", "drive current limit, A", False, "as-stated", "board"),
    BlockKey("u_max", "supply voltage, V", False, "as-stated", "board"),
    BlockKey("encoder_counts", "encoder counts per turn: phi (hull), psi (motor)", False, "as-stated", "board"),
    BlockKey("sample_rate", "sampling rate, Hz", True, "positive", "board"),
    BlockKey("current_sampling", "how the DAQ logged the current (absent: instant)", False, "choice", "daq",
             CURRENT_SAMPLING),
    # not in the spec's example block; a lab that knows its current sensor's gain better states it
    BlockKey("current_gain_uncertainty", "relative uncertainty of the current sensor's gain (absent: 0.005, "
             "physics.md section 7)", False, "nonnegative", "lab"),
)
RIG_KEYS = {key.name: key for key in RIG_BLOCK}
# The spec keys of the ``rig`` block this class reads; every other key goes to ``extra``.
BLOCK_KEYS = tuple(key.name for key in RIG_BLOCK)
FRICTION_KEYS = ("viscous", "coulomb")


def _finite_number(value: Any) -> bool:
    return not isinstance(value, bool) and isinstance(value, (int, float)) and math.isfinite(value)


def block_problem(name: str, value: Any) -> tuple[str, str, str] | None:
    """What is wrong with a stated ``value`` of the ``rig`` block's key ``name``: ``(where, shown,
    expected)``, the key's path in the block (``motor_friction.viscous``), the value as a message
    shows it and what was expected; None when the value keeps the key's bound (:data:`RIG_BLOCK`)."""
    key = RIG_KEYS[name]
    if key.bound in ("positive", "angle") and not _finite_number(value):
        return name, repr(value), "a finite number"
    if key.bound == "positive" and value <= 0:
        return name, repr(value), "a number > 0 (SI units)"
    if key.bound == "nonnegative" and (not _finite_number(value) or value < 0):
        return name, repr(value), "a finite number >= 0" + (f" ({key.note})" if key.note else "")
    if key.bound == "angle" and abs(value) > 2 * math.pi:
        return name, f"{value!r} rad", "|value| <= 2 pi"
    if key.bound == "choice" and value not in key.choices:
        return name, repr(value), f"one of {key.choices}"
    if key.bound == "friction":
        if not isinstance(value, dict):
            return name, repr(value), "an object with 'viscous' and 'coulomb'"
        for part, number in value.items():
            if not _finite_number(number) or number < 0:
                return f"{name}.{part}", repr(number), "a finite number >= 0"
    return None


def block_problems(block: Mapping[str, Any], keys: tuple[str, ...] = BLOCK_KEYS):
    """Every problem of a ``rig`` block (or a lab file's part of it, ``keys``), in the schema's order: a
    missing required key is ``(name, None, "missing")``, else :func:`block_problem`'s triple. Required
    keys come first (missing, then not a number), then each stated key's bound (None is not stated)."""
    wanted = [RIG_KEYS[k] for k in keys]
    for key in wanted:
        if key.required and key.name not in block:
            yield key.name, None, "missing"
        elif key.required and not _finite_number(block[key.name]):
            yield block_problem(key.name, block[key.name])
    for key in wanted:
        value = block.get(key.name)
        if value is not None and not (key.required and not _finite_number(value)):
            problem = block_problem(key.name, value)
            if problem is not None:
                yield problem


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
    """Motor turns per flywheel turn (``gear_ratio``; 1 if absent: no gearbox). ``psi`` is the
    flywheel's angle either way (run-record.md)."""
    current_sampling: str | None = None
    """How the DAQ logged the current, one of :data:`CURRENT_SAMPLING`; ``None``: not stated
    (:attr:`current_sampling_used` is then the default, ``instant``)."""
    current_gain_uncertainty: float | None = None
    """Relative uncertainty of the current sensor's gain; ``None``: not stated."""
    motor_k_t: float | None = field(default=None, compare=False)
    """N m/A, the motor's own data-sheet constant as the block states it (``None``: ``k_t / gear_ratio``)."""
    extra: dict[str, Any] = field(default_factory=dict, compare=False)
    """Other keys of the block (a bench's ``board``, ``lab``, a lab's own notes), kept on round trip."""

    def __post_init__(self) -> None:
        for name in (key.name for key in RIG_BLOCK if key.bound == "positive"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise KnownRigError(f"KnownRig.{name} = {value!r}: expected a finite number > 0 (SI units)")
        if self.gear_ratio < 1:
            raise KnownRigError(f"KnownRig.gear_ratio = {self.gear_ratio!r}: expected a finite number >= 1 (motor "
                                "turns per flywheel turn)")

    # --- derived -------------------------------------------------------------------
    @property
    def dt(self) -> float:
        """Sample period, s."""
        return 1.0 / self.sample_rate

    @property
    def current_sampling_used(self) -> str:
        """How the logged current is read: the stated ``current_sampling``, else ``instant``."""
        return DEFAULT_CURRENT_SAMPLING if self.current_sampling is None else self.current_sampling

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

        mode = block.get("current_sampling")
        gear = float(block.get("gear_ratio") or 1.0)
        k_t = float(block["k_t"])  # the motor's own; at the flywheel it is k_t * gear_ratio
        return cls(J_hull=float(block["J_hull"]), J_flywheel=float(block["J_flywheel"]),
                   c_torsion=float(block["c_torsion"]), phi_neutral=float(block.get("phi_neutral", 0.0)),
                   k_t=k_t * gear, motor_k_t=k_t if "gear_ratio" in block else None,
                   R=float(block["R"]), L=opt("L"), i_max=opt("i_max"),
                   u_max=opt("u_max"), friction_viscous=float(fric.get("viscous", 0.0)),
                   friction_coulomb=float(fric.get("coulomb", 0.0)), phi_counts=int(counts.get("phi", 0) or 0),
                   psi_counts=int(counts.get("psi", 0) or 0), sample_rate=float(block["sample_rate"]),
                   gear_ratio=gear,
                   current_sampling=None if mode is None else str(mode),
                   current_gain_uncertainty=opt("current_gain_uncertainty"),
                   extra={k: v for k, v in block.items() if k not in BLOCK_KEYS})

    @classmethod
    def from_params(cls, params: Any) -> "KnownRig":
        """From a simulated rig's :class:`~addedinertia_env.sim.params.RigParams` (no truth)."""
        m, s = params.motor, params.sensors
        gear = float(params.drive.gear_ratio)
        return cls(J_hull=params.hull.J_hull, J_flywheel=m.J_flywheel, c_torsion=params.spring.c,
                   phi_neutral=params.spring.phi_neutral, k_t=m.k_t * gear,
                   motor_k_t=m.k_t if gear != 1.0 else None, R=m.R, L=m.L, i_max=m.i_max, u_max=m.u_max,
                   friction_viscous=m.friction_viscous, friction_coulomb=m.friction_coulomb,
                   phi_counts=s.phi_counts, psi_counts=s.psi_counts, sample_rate=s.sample_rate,
                   gear_ratio=gear)

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
        for key in ("current_sampling", "current_gain_uncertainty"):
            if getattr(self, key) is not None:
                block[key] = getattr(self, key)
        block.update(self.extra)
        return block
