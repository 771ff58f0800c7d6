"""Physical parameters of the rig, as frozen dataclasses with SI units.

Every number here has a unit in its comment and a source in ``configs/rigs/*.yaml`` or
in ``docs/PHYSICS.md`` section 7 (the realistic default rig). Derived
quantities are properties, never stored copies.

Two views of a rig exist:

* :class:`RigParams` is the *simulated truth*: it includes the true ``lambda66``, the true
  damping law and any hidden :class:`~addedinertia_env.sim.effects.Effects`.
* :meth:`RigParams.known` is what an experimenter knows (data sheet, test in air, static
  calibration), a :class:`~addedinertia_env.rig.known.KnownRig`; it is what goes into a run
  record's ``rig`` block and all that estimators and controllers may use.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

from addedinertia_env.sim.drive import DriveParams
from addedinertia_env.sim.effects import Effects
from addedinertia_env.rig.known import KnownRig
from addedinertia_env.hydro.radiation import CumminsModel


@dataclass(frozen=True)
class HullParams:
    """The floating hull on its yaw axis."""

    name: str = "wigley-2m"
    J_hull: float = 5.8  # kg m^2, yaw inertia of hull + rod + frame + motor stator (in air)
    lambda66: float = 11.7  # kg m^2, true added moment of inertia in yaw
    b1: float = 0.2  # N m s, linear (skin-friction) damping
    b2: float = 31.0  # N m s^2, quadratic cross-flow damping, torque = -b2 w |w|

    def __post_init__(self) -> None:
        _positive(self, "J_hull", "lambda66")
        _non_negative(self, "b1", "b2")


@dataclass(frozen=True)
class SpringParams:
    """The torsion rod (main drive)."""

    c: float = 43.4  # N m / rad, torsional stiffness from static calibration
    phi_neutral: float = 0.0  # rad, neutral angle as calibrated (encoder frame)

    def __post_init__(self) -> None:
        _positive(self, "c")


@dataclass(frozen=True)
class MotorParams:
    """DC motor + flywheel (corrective drive). Stator on the hull, rotor carries the flywheel."""

    J_flywheel: float = 0.1  # kg m^2, flywheel + rotor about the yaw axis
    k_t: float = 0.25  # N m / A, torque constant (= back-EMF constant k_e in SI)
    R: float = 0.5  # ohm, winding resistance
    L: float = 0.0005  # H, winding inductance (L/R = 1 ms)
    i_max: float = 15.0  # A, drive current limit
    u_max: float = 48.0  # V, supply voltage
    friction_viscous: float = 1e-4  # N m s, rotor bearing viscous friction
    friction_coulomb: float = 2e-3  # N m, rotor bearing dry friction

    def __post_init__(self) -> None:
        _positive(self, "J_flywheel", "k_t", "R", "L", "i_max", "u_max")
        _non_negative(self, "friction_viscous", "friction_coulomb")

    @property
    def electrical_time_constant(self) -> float:
        """L / R in seconds."""
        return self.L / self.R


# Documented limits of simulated work (docs/RELIABILITY.md): beyond them a config is refused up front.
SAMPLE_RATE_LIMITS = (100.0, 20_000.0)  # Hz; the spec's DAQs log at 250 Hz to 10 kHz
MAX_PHYSICS_SUBSTEPS = 100  # integrator steps per sample


@dataclass(frozen=True)
class SensorParams:
    """Sampling and sensor imperfections (physics.md section 7)."""

    sample_rate: float = 1000.0  # Hz
    phi_counts: int = 131072  # hull encoder counts per turn (17 bit); 0 = no quantisation
    psi_counts: int = 16384  # motor encoder counts per turn (14 bit); 0 = no quantisation
    current_noise: float = 0.010  # A rms
    current_offset: float = 0.003  # A
    current_gain_error: float = 0.005  # relative
    voltage_noise: float = 0.02  # V rms
    voltage_offset: float = 0.01  # V
    voltage_gain_error: float = 0.005  # relative

    def __post_init__(self) -> None:
        _positive(self, "sample_rate")
        _non_negative(self, "phi_counts", "psi_counts", "current_noise", "voltage_noise")
        if not SAMPLE_RATE_LIMITS[0] <= self.sample_rate <= SAMPLE_RATE_LIMITS[1]:
            raise ValueError(f"SensorParams.sample_rate = {self.sample_rate!r} Hz: expected {SAMPLE_RATE_LIMITS[0]:g} "
                             f"to {SAMPLE_RATE_LIMITS[1]:g} Hz (a DAQ logs at 250 Hz to 10 kHz; docs/RELIABILITY.md)")

    @property
    def dt(self) -> float:
        """Sample period in seconds."""
        return 1.0 / self.sample_rate

    @classmethod
    def ideal(cls, sample_rate: float = 1000.0) -> "SensorParams":
        """Noise-free, unquantised, unbiased sensors."""
        return cls(sample_rate=sample_rate, phi_counts=0, psi_counts=0, current_noise=0.0,
                   current_offset=0.0, current_gain_error=0.0, voltage_noise=0.0,
                   voltage_offset=0.0, voltage_gain_error=0.0)


@dataclass(frozen=True)
class RigParams:
    """The whole simulated rig: truth for the simulator."""

    hull: HullParams = field(default_factory=HullParams)
    spring: SpringParams = field(default_factory=SpringParams)
    motor: MotorParams = field(default_factory=MotorParams)
    sensors: SensorParams = field(default_factory=SensorParams)
    effects: Effects = field(default_factory=Effects)
    brake_torque: float = 60.0  # N m, holding torque of the hull brake
    physics_substeps: int = 2  # integrator steps per sample
    # Radiation memory (hydro/radiation.py): None = constant added inertia lambda66 (the default);
    # a CumminsModel = Cummins' convolution, lambda66 then being A66(0). Not a hidden effect.
    hydrodynamics: CumminsModel | None = None
    # The drive's flaws (sim/drive.py: gearbox, cogging, driver bandwidth); the default is the ideal drive.
    drive: DriveParams = field(default_factory=DriveParams)

    def __post_init__(self) -> None:
        _positive(self, "brake_torque", "physics_substeps")
        if not isinstance(self.drive, DriveParams):
            raise ValueError(f"RigParams.drive = {self.drive!r}: expected a DriveParams (sim/drive.py)")
        if self.physics_substeps > MAX_PHYSICS_SUBSTEPS:
            raise ValueError(f"RigParams.physics_substeps = {self.physics_substeps!r}: expected at most "
                             f"{MAX_PHYSICS_SUBSTEPS} integrator steps per sample")
        if isinstance(self.physics_substeps, bool) or int(self.physics_substeps) != self.physics_substeps:
            raise ValueError(f"RigParams.physics_substeps = {self.physics_substeps!r}: expected a whole number >= 1")
        object.__setattr__(self, "physics_substeps", int(self.physics_substeps))
        if self.hydrodynamics is not None and not isinstance(self.hydrodynamics, CumminsModel):
            raise ValueError(f"RigParams.hydrodynamics = {self.hydrodynamics!r}: expected None (constant added "
                             "inertia) or a CumminsModel (hydro/radiation.py)")

    @property
    def J_total(self) -> float:
        """Hull + added + flywheel yaw inertia with the flywheel locked, kg m^2."""
        return self.hull.J_hull + self.hull.lambda66 + self.motor.J_flywheel

    @property
    def natural_period(self) -> float:
        """Undamped yaw period with a free-spinning (frictionless) flywheel, s.

        A free flywheel keeps its inertial orientation, so only hull + added inertia
        swings: T = 2 pi sqrt((J_h + lambda66) / c).
        """
        return 2.0 * math.pi * math.sqrt((self.hull.J_hull + self.hull.lambda66) / self.spring.c)

    @property
    def physics_dt(self) -> float:
        """Physics integration step, s: the sample period over ``physics_substeps``."""
        return self.sensors.dt / self.physics_substeps

    def replace(self, **changes) -> "RigParams":
        """A copy with the given fields replaced (``dataclasses.replace``; validated again)."""
        return replace(self, **changes)

    def known(self) -> "KnownRig":
        """What the experimenter knows (no truth): the typed run record ``rig`` block."""
        return KnownRig.from_params(self)


def _positive(obj, *names: str) -> None:
    for name in names:
        value = getattr(obj, name)
        if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
            raise ValueError(f"{type(obj).__name__}.{name} = {value!r}: expected a finite number > 0")


def _non_negative(obj, *names: str) -> None:
    for name in names:
        value = getattr(obj, name)
        if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
            raise ValueError(f"{type(obj).__name__}.{name} = {value!r}: expected a finite number >= 0")
