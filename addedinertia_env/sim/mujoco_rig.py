"""The simulated rig, with MuJoCo as the rigid-body engine.

Model (physics.md section 2): a ``hull`` body on a vertical ``hull_yaw`` hinge carrying the
torsion spring (``stiffness``, ``springref``), with the hull's yaw inertia as its body
inertia and ``lambda66`` as the joint's armature (exact for a constant added inertia;
``A66(inf)`` with radiation memory, :func:`.forces.hull_armature`);
a ``flywheel`` child body on a coaxial ``flywheel_spin`` hinge (angle ``psi`` relative to
the hull) driven by a ``motor`` actuator. Because the flywheel is the hull's child, the
motor's reaction on the hull comes out of the mass matrix; it is never added by hand.
The hull brake is a joint equality constraint, switched on where the hull stands.

Everything else comes from :mod:`.forces` as applied generalised forces, and the motor
current from :mod:`.motor`'s exact update.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np

from addedinertia_env.sim import forces
from addedinertia_env.sim.drive import backlash_scalar
from addedinertia_env.sim.motor import MotorCommand, current_step, terminal_voltage
from addedinertia_env.sim.params import RigParams
from addedinertia_env.sim.sensors import Reading, Sensors
from addedinertia_env.sim.simulated import SimulatedRigBase

HULL_JOINT = "hull_yaw"
FLYWHEEL_JOINT = "flywheel_spin"
MOTOR = "motor"
BRAKE = "brake"


def build_mjcf(p: RigParams) -> str:
    """MJCF text of the rig. Geoms are for rendering only (no mass, no contacts)."""
    J_h, J_f = p.hull.J_hull, p.motor.J_flywheel
    # Flywheel: a steel disc drawn with the radius that gives J_f for a 5 cm thick disc.
    disc_radius = (2.0 * J_f / (7850.0 * math.pi * 0.05)) ** 0.25
    return f"""
<mujoco model="addedinertia-rig">
  <compiler angle="radian" autolimits="true"/>
  <option timestep="{p.physics_dt!r}" integrator="RK4" gravity="0 0 0">
    <flag contact="disable"/>
  </option>
  <visual><global offwidth="640" offheight="480"/></visual>
  <worldbody>
    <light pos="0 0 3" dir="0 0 -1"/>
    <geom name="tank_floor" type="plane" size="2 1 0.01" pos="0 0 -0.3" rgba="0.2 0.4 0.6 1"/>
    <body name="hull">
      <joint name="{HULL_JOINT}" type="hinge" axis="0 0 1"
             stiffness="{p.spring.c!r}" springref="{forces.true_neutral(p)!r}"
             armature="{float(forces.hull_armature(p))!r}"/>
      <inertial pos="0 0 0" mass="1" diaginertia="{J_h!r} {J_h!r} {J_h!r}"/>
      <geom type="ellipsoid" size="1.0 0.1 0.125" mass="0" rgba="0.85 0.85 0.8 1"/>
      <body name="flywheel" pos="0 0 0.2">
        <joint name="{FLYWHEEL_JOINT}" type="hinge" axis="0 0 1"/>
        <inertial pos="0 0 0" mass="1" diaginertia="{J_f!r} {J_f!r} {J_f!r}"/>
        <geom type="cylinder" size="{disc_radius:.4f} 0.025" mass="0" rgba="0.6 0.1 0.1 1"/>
        <geom type="box" pos="{disc_radius * 0.7:.4f} 0 0.03" size="0.02 0.01 0.01" mass="0" rgba="1 1 0 1"/>
      </body>
    </body>
  </worldbody>
  <actuator>
    <motor name="{MOTOR}" joint="{FLYWHEEL_JOINT}" gear="1"/>
  </actuator>
  <equality>
    <joint name="{BRAKE}" joint1="{HULL_JOINT}" active="false" solref="{2 * p.physics_dt!r} 1"
           solimp="0.999 0.9999 0.001"/>
  </equality>
</mujoco>
"""


@dataclass(frozen=True)
class TrueState:
    """The simulator's state, for scoring and physics tests only."""

    t: float
    phi: float  # rad
    w: float  # rad/s, hull yaw rate
    psi: float  # rad, flywheel relative to hull
    omega: float  # rad/s, flywheel rate relative to hull
    i: float  # A, motor current
    u: float  # V, terminal voltage held over the last sample
    water_rate: float  # rad/s, fluid-memory state
    energy: float  # J, mechanical energy T + Pi
    motor_work: float  # J, cumulative integral of k_t i Omega dt
    dissipated_hull: float  # J, cumulative work of non-spring hull torques (<= 0 for damping)
    dissipated_flywheel: float  # J, cumulative work of rotor friction
    electric_energy: float  # J, cumulative integral of u i dt
    ohmic_loss: float  # J, cumulative integral of R i^2 dt
    reaction_work_hull: float = 0.0  # J, cumulative work of the motor's reaction -(k_t i - M_f) on the hull
    current_angle: float = 0.0  # A rad, cumulative integral of i dphi (the current's share of that work)
    radiation_state: tuple = ()  # rad, the radiation-memory state x (empty without memory)
    radiation_work: float = 0.0  # J, cumulative work of the hull on the water through the memory, integral mu dphi
    radiation_energy: float = 0.0  # J, energy the memory holds now (its storage function)
    radiation_torque: float = 0.0  # N m, the memory moment -mu on the hull over the last physics step
    gap: float = 0.0  # rad, the rotor's angle (at the flywheel) minus the flywheel's in the gearbox's backlash
    gap_rate: float = 0.0  # rad/s, its rate
    backlash_work: float = 0.0  # J, cumulative work of the motor on the rotor's motion in the gap, k_t i dgap
    impact_loss: float = 0.0  # J, cumulative kinetic energy lost when the rotor hits a flank
    gap_torque_work: float = 0.0  # J, cumulative work on the flywheel of what the gap withholds and delivers late


class MujocoRig(SimulatedRigBase):
    """One simulated rig; see :class:`addedinertia_env.rig.interface.Rig` for the protocol."""

    source = "sim"

    def __init__(self, params: RigParams, seed: int | np.random.SeedSequence | None = None):
        self.params = params
        self.model = mujoco.MjModel.from_xml_string(build_mjcf(params))
        self.data = mujoco.MjData(self.model)
        self._hull_dof = self.model.jnt_dofadr[self.model.joint(HULL_JOINT).id]
        self._fly_dof = self.model.jnt_dofadr[self.model.joint(FLYWHEEL_JOINT).id]
        self._hull_qpos = self.model.jnt_qposadr[self.model.joint(HULL_JOINT).id]
        self._fly_qpos = self.model.jnt_qposadr[self.model.joint(FLYWHEEL_JOINT).id]
        self._motor = self.model.actuator(MOTOR).id
        self._brake = self.model.equality(BRAKE).id
        self.k_t = forces.true_torque_constant(params)
        self._driver_lag = forces.driver_lag(params)
        self.sensors = Sensors(params, seed)
        self.reset()

    # --- protocol -------------------------------------------------------------------
    @property
    def time(self) -> float:
        """Simulation time, s."""
        return float(self.data.time)

    def reset(self, phi0: float = 0.0, psi0: float = 0.0, omega0: float = 0.0, brake: bool = True) -> Reading:
        """Place the hull at ``phi0`` (rod twisted), motor passive, brake as given."""
        mujoco.mj_resetData(self.model, self.data)
        self.data.qpos[self._hull_qpos] = phi0
        self.data.qpos[self._fly_qpos] = psi0
        self.data.qvel[self._fly_dof] = omega0
        mujoco.mj_forward(self.model, self.data)
        self.i = 0.0
        self.u = self.k_t * omega0  # open circuit: the terminals show the back-EMF
        self.water_rate = 0.0
        self.motor_work = self.dissipated_hull = self.dissipated_flywheel = 0.0
        self.electric_energy = self.ohmic_loss = 0.0
        self.reaction_work_hull = self.current_angle = 0.0
        self.radiation_x = np.zeros(forces.radiation_state_size(self.params))  # rad, memory state
        self.radiation_work = self.radiation_torque = 0.0
        self._w_prev = 0.0  # hull rate one physics step ago (forces.centred_rate)
        self.gap = self.gap_rate = 0.0  # rad, rad/s: the rotor mid-gap at rest (drive.backlash_step)
        self.backlash_work = self.impact_loss = self.gap_torque_work = 0.0
        self.sensors.reset()
        self.set_brake(brake)
        return self._read()

    def set_brake(self, on: bool) -> None:
        """Engage the brake (the hull held where it stands, by an equality constraint) or release it."""
        self.brake = bool(on)
        if on:  # hold the hull where it stands: phi = polycoef[0]
            self.model.eq_data[self._brake, :5] = 0.0
            self.model.eq_data[self._brake, 0] = self.data.qpos[self._hull_qpos]
        self.data.eq_active[self._brake] = 1 if on else 0

    def step(self, cmd: MotorCommand) -> Reading:
        """Advance one sample period under ``cmd`` and return the new reading."""
        p, m = self.params, self.params.motor
        d = self.data
        h = p.physics_dt
        omega = d.qvel[self._fly_dof]
        passive = cmd.mode == "passive"
        memory = forces.has_radiation_memory(p)
        u = terminal_voltage(cmd, self.i, omega, R=m.R, L=m.L, k_e=self.k_t, u_max=m.u_max,
                             i_max=m.i_max, sample_dt=p.sensors.dt, lag=self._driver_lag)
        drive = forces.has_drive_torque(p)
        backlash = forces.has_backlash(p)
        j_rotor = float(forces.backlash_inertia(p)) if backlash else 0.0  # kg m^2 at the flywheel
        for _ in range(p.physics_substeps):
            phi, w = d.qpos[self._hull_qpos], d.qvel[self._hull_dof]
            psi0, omega = d.qpos[self._fly_qpos], d.qvel[self._fly_dof]
            w_mid = forces.centred_rate(w, self._w_prev)
            self._w_prev = float(w)
            q_hull = float(forces.hull_extra_torque(phi, w_mid, self.water_rate, p))
            q_fly = float(forces.flywheel_friction_torque(omega, p))
            if drive:  # the drive's own torque (cogging, gear friction), with the current held over the step
                q_fly += float(forces.drive_torque(psi0, omega, 0.0 if passive else self.i, self.k_t, p))
            q_gap = 0.0  # N m, what the gap withholds from (and delivers late to) the flywheel
            gap_rate = 0.0  # rad/s, the rotor's mean rate in the gap over the step (adds to the back-EMF)
            if backlash:  # the rotor crosses the gap on the held torque; the flywheel feels what gets through
                t_m = self.k_t * (0.0 if passive else self.i)
                g1, v1, engaged, impulse, loss = backlash_scalar(self.gap, self.gap_rate, t_m, j_rotor,
                                                                 p.drive.backlash, h)
                q_gap = t_m * (engaged - 1.0) + impulse / h
                gap_rate = (g1 - self.gap) / h
                self.gap, self.gap_rate = g1, v1
                self.impact_loss += loss
            q_rad = 0.0
            if memory:
                self.radiation_x, mu = forces.radiation_memory_step(self.radiation_x, w_mid, p)
                q_rad = -float(mu)
            d.qfrc_applied[self._hull_dof] = q_hull + q_rad
            d.qfrc_applied[self._fly_dof] = q_fly + q_gap
            if passive:
                i1 = i_mean = 0.0
                u = self.k_t * omega
            else:
                omega = self._mean_flywheel_rate(omega, i_guess=current_step(
                    self.i, u, omega + gap_rate, h, R=m.R, L=m.L, k_e=self.k_t)[1], h=h) + gap_rate
                i1, i_mean = current_step(self.i, u, omega, h, R=m.R, L=m.L, k_e=self.k_t)
                self.backlash_work += self.k_t * i_mean * gap_rate * h
            torque = self.k_t * i_mean
            d.ctrl[self._motor] = torque
            self.water_rate += h * float(forces.water_rate_derivative(w, self.water_rate, p))
            mujoco.mj_step(self.model, self.data)
            dphi = d.qpos[self._hull_qpos] - phi
            dpsi = d.qpos[self._fly_qpos] - psi0
            self.motor_work += torque * dpsi
            self.dissipated_hull += q_hull * dphi
            self.radiation_work -= q_rad * dphi
            self.radiation_torque = q_rad
            self.dissipated_flywheel += q_fly * dpsi
            self.gap_torque_work += q_gap * dpsi
            self.reaction_work_hull -= (torque + q_fly + q_gap) * dphi
            self.current_angle += i_mean * dphi
            if not passive:
                # Exact integrals over the step with u held: int(u i) = u * mean(i);
                # int(R i^2) from the exponential solution.
                self.electric_energy += u * i_mean * h
                self.ohmic_loss += m.R * _mean_square_current(self.i, i1, u, omega, h, m.R, m.L, self.k_t) * h
            self.i = float(i1)
        self.u = float(u)
        return self._read()

    def truth(self) -> dict:
        """The run record's ``truth`` block (scoring only)."""
        return forces.truth(self.params, self.k_t)

    def true_state(self) -> TrueState:
        """Simulator truth: for scoring and tests, never for estimators or controllers."""
        d, p = self.data, self.params
        phi, w = float(d.qpos[self._hull_qpos]), float(d.qvel[self._hull_dof])
        omega = float(d.qvel[self._fly_dof])
        energy = float(forces.kinetic_energy(w, omega, p) + forces.potential_energy(phi, p))
        return TrueState(t=float(d.time), phi=phi, w=w, psi=float(d.qpos[self._fly_qpos]), omega=omega,
                         i=self.i, u=self.u, water_rate=self.water_rate, energy=energy,
                         motor_work=self.motor_work, dissipated_hull=self.dissipated_hull,
                         dissipated_flywheel=self.dissipated_flywheel,
                         electric_energy=self.electric_energy, ohmic_loss=self.ohmic_loss,
                         reaction_work_hull=self.reaction_work_hull, current_angle=self.current_angle,
                         radiation_state=tuple(float(v) for v in self.radiation_x),
                         radiation_work=self.radiation_work,
                         radiation_energy=float(forces.radiation_energy(self.radiation_x, p)),
                         radiation_torque=self.radiation_torque, gap=self.gap, gap_rate=self.gap_rate,
                         backlash_work=self.backlash_work, impact_loss=self.impact_loss,
                         gap_torque_work=self.gap_torque_work)

    # --- internals ------------------------------------------------------------------
    def _mean_flywheel_rate(self, omega0: float, i_guess: float, h: float) -> float:
        """The flywheel's mean relative rate over the coming physics step, rad/s.

        The back-EMF must see the same ``Omega`` the motor torque works against, or the
        power balance ``u i = R i^2 + d(L i^2/2)/dt + k_t i Omega`` fails by about
        ``k_t i Omega' h / 2`` (an O(h) error of 2-3 % of the motor work in a few seconds
        of driving). With the torque of ``i_guess`` applied, MuJoCo's accelerations (brake
        constraint included) give ``Omega_mean = Omega0 + Omega' h / 2`` to O(h^2).
        """
        self.data.ctrl[self._motor] = self.k_t * i_guess
        mujoco.mj_forward(self.model, self.data)
        return float(omega0 + 0.5 * h * self.data.qacc[self._fly_dof])

    def _read(self) -> Reading:
        d = self.data
        return self.sensors.read(float(d.time), float(d.qpos[self._hull_qpos]), float(d.qpos[self._fly_qpos]),
                                 self.u, self.i, self.brake)


def _mean_square_current(i0, i1, u, omega, h, R, L, k_e) -> float:
    """Mean of i(t)^2 over a step of the exact exponential solution."""
    tau = L / R
    i_ss = (u - k_e * omega) / R
    a = i0 - i_ss
    e1 = math.exp(-h / tau)
    e2 = e1 * e1
    return i_ss**2 + 2 * i_ss * a * tau / h * (1 - e1) + a**2 * tau / (2 * h) * (1 - e2)
