"""The rig for many environments at once: the MuJoCo model's dynamics on numpy arrays.

One source of truth with :mod:`.mujoco_rig`:

* every generalised force except inertia and the linear spring comes from :mod:`.forces`
  (the same functions, run on per-environment parameter arrays, :mod:`.batched_params`);
* the motor current comes from :mod:`.motor` (the same exact exponential update
  :func:`~.motor.current_step`, the same drive modes :func:`~.motor.terminal_voltage`),
  with the back-EMF taken at the flywheel's mean rate over the step as
  :meth:`MujocoRig._mean_flywheel_rate` does, and the torque ``k_t`` x the mean current;
* the mechanics are integrated with the classic four-stage Runge-Kutta method (MuJoCo's
  ``RK4``) at ``physics_dt = sample_dt / physics_substeps``, the linear spring and the
  2x2 mass matrix ``[[J_h + lambda66 + J_f, J_f], [J_f, J_f]]`` (solved in closed form,
  :func:`mass_matrix_solve`) inside the stages, the extra forces and the motor torque
  held over each physics step.

:func:`reference_substep` is that physics step written out plainly. With the extra
torques held, every operation in it is *linear* in ``x = (phi, w, psi, omega, i, u, F1,
F2)`` (``F1`` the held hull torque plus ``c phi_n``, ``F2`` the held rotor friction): the
exact current update is linear in ``(i0, u, Omega)`` for a fixed step, the mean-rate
correction is an acceleration, and RK4 applied to a linear system is a fixed linear map.
So the whole step is a matrix ``G`` (5 x 8 per environment and kind of step), obtained
by running :func:`reference_substep` on the unit vectors once (:func:`substep_matrix`).
A physics step is then: the nonlinear torques from :mod:`.forces`, and one product
``G x`` per environment, in compiled loops (:mod:`.kernels`; they also apply the
open-circuit rule and pause inactive environments). A batch whose only extra torques are
the damping and the rotor friction (no hull-torque effect, no water or radiation memory)
runs a whole sample in one :func:`~.kernels.rig_sample` call, with the laws of
:mod:`.forces` and :func:`~.motor.drive_voltage` compiled from their one definition;
any other batch computes the torques with :mod:`.forces` on arrays and steps with
:func:`~.kernels.linear_substep` (tests/test_kernels.py holds the two paths equal). It
equals stage-by-stage evaluation to rounding (about 1e-15; tests/test_batched.py checks it).

Kinds of step: motor passive (open circuit: no current, ``u`` shows the back-EMF) or
driven (current or voltage mode; the drive's voltage is set once per sample by
:func:`~.motor.terminal_voltage`), hull free or braked.

The brake: MuJoCo holds the hull with a stiff (soft) equality constraint; here a braked
hull is held exactly: ``phi`` fixed and ``w = 0`` from the moment the brake is set
(the flywheel keeping its absolute rate ``w + Omega`` through that instant, as under an
impulse on the hull alone), and then ``J_f Omega' = k_t i + M_f``. Braked, the two agree
to about 1e-9 rad; a brake set while the hull still moves at rate ``w0`` lets MuJoCo's
hull slide on for about the constraint's time constant (``2 physics_dt``), so the
trajectories then differ by about ``w0 x physics_dt`` in ``phi`` (docs/PERFORMANCE.md).

One "step" (:meth:`BatchedRig.step`) is one sample period (``physics_substeps`` physics
steps), as for :meth:`MujocoRig.step`.
"""

from __future__ import annotations

from types import SimpleNamespace
from typing import Sequence

import numpy as np

from addedinertia_env.sim import forces
from addedinertia_env.sim.drive import backlash_step
from addedinertia_env.sim.integrator import rk4_step
from addedinertia_env.sim.kernels import CONSTANTS, linear_substep, rig_sample
from addedinertia_env.sim.batched_params import BatchedParams
from addedinertia_env.sim.effects.registry import active_params
from addedinertia_env.sim.motor import MODES, current_step, terminal_voltage
from addedinertia_env.sim.noise import batch_keys
from addedinertia_env.sim.params import RigParams
from addedinertia_env.sim.sensors import BatchedReading, SensorModel

PASSIVE, CURRENT, VOLTAGE = (MODES.index(m) for m in ("passive", "current", "voltage"))
# Rows of the state block: the moving state, then the inputs held over a physics step.
PHI, W, PSI, OMEGA, I, U, F1, F2 = range(8)
STATE = ("phi", "w", "psi", "omega", "i", "u", "F1", "F2")
N_OUT = 5  # phi, w, psi, omega, i are updated; u, F1, F2 are inputs
# Kinds of physics step: 2 * braked + driven.
KIND_NAMES = ("free, passive", "free, driven", "braked, passive", "braked, driven")


def mass_matrix_solve(J_hull_added, J_flywheel, f_hull, f_flywheel):
    """Accelerations ``(phi'', psi'')`` from ``[[J + J_f, J_f], [J_f, J_f]] a = f`` in closed form.

    ``J`` = hull + added inertia, ``J_f`` flywheel, kg m^2; ``f`` generalised forces, N m.
    """
    a_hull = (f_hull - f_flywheel) / J_hull_added
    return a_hull, f_flywheel / J_flywheel - a_hull


def free_dynamics(z, c, J, J_f):
    """``z'`` of the unbraked mechanics, ``z = (phi, w, psi, omega, F1, F2)``, torques held.

    The linear spring ``-c phi + F1`` (``F1`` includes ``c phi_n``) and the mass matrix
    are evaluated at every stage, as MuJoCo's RK4 does.
    """
    phi, w, psi, omega, f1, f2 = z
    a_hull, a_fly = mass_matrix_solve(J, J_f, f1 - c * phi, f2)
    zero = 0.0 * phi
    return (w, a_hull, omega, a_fly, zero, zero)


def braked_dynamics(z, c, J, J_f):
    """``z'`` with the hull held: ``phi`` fixed, ``w = 0``, ``J_f Omega' = F2``."""
    phi, w, psi, omega, f1, f2 = z
    zero = 0.0 * phi
    return (zero, zero, omega, f2 / J_f, zero, zero)


def reference_substep(x, h: float, kind: int, c, J, J_f, k_t, R, L):
    """One physics step as :meth:`MujocoRig.step` takes it, on plain arrays.

    ``x``: the 8 entries of :data:`STATE`; ``kind``: 0..3 (:data:`KIND_NAMES`).
    Returns the new ``(phi, w, psi, omega, i)``. The extra torques in ``F1``/``F2`` come
    from :mod:`.forces` and are held, as in MuJoCo. Clear, not fast: the rig uses the
    linear map :func:`substep_matrix` of this function.
    """
    phi, w, psi, omega, i0, u, f1, f2_friction = x
    braked, driven = divmod(kind, 2)
    if driven:
        # Back-EMF at the mean flywheel rate over the step (MujocoRig._mean_flywheel_rate).
        _, i_guess = current_step(i0, u, omega, h, R=R, L=L, k_e=k_t)
        f_fly = f2_friction + k_t * i_guess
        if braked:
            a_fly = f_fly / J_f
        else:
            a_fly = mass_matrix_solve(J, J_f, f1 - c * phi, f_fly)[1]
        i1, i_mean = current_step(i0, u, omega + 0.5 * h * a_fly, h, R=R, L=L, k_e=k_t)
        f2 = f2_friction + k_t * i_mean
    else:  # open circuit: no current
        i1, f2 = 0.0 * i0, f2_friction
    dynamics = braked_dynamics if braked else free_dynamics
    phi1, w1, psi1, omega1, _, _ = rk4_step(dynamics, (phi, w, psi, omega, f1, f2), h, c, J, J_f)
    return phi1, w1, psi1, omega1, i1


def substep_matrix(h: float, kind: int, c, J, J_f, k_t, R, L) -> np.ndarray:
    """The linear map of :func:`reference_substep`: ``new = G @ x``, shape ``(5, 8, n)``.

    Obtained by running :func:`reference_substep` on each unit vector (float64), all
    eight at once (the parameters repeated for each).
    """
    n = np.broadcast(c, J, J_f, k_t, R, L).size
    m = len(STATE)
    args = [np.tile(np.broadcast_to(np.asarray(a, float), (n,)), m) for a in (c, J, J_f, k_t, R, L)]
    unit = tuple(np.repeat(np.eye(m)[j], n) for j in range(m))  # env fastest: block j is unit vector j
    out = reference_substep(unit, h, kind, *args)
    G = np.zeros((N_OUT, m, n))
    for i in range(N_OUT):
        G[i] = np.broadcast_to(out[i], (m * n,)).reshape(m, n)
    return G


class _Command(SimpleNamespace):
    """Duck-typed :class:`MotorCommand` carrying arrays (for :func:`motor.terminal_voltage`)."""


def mode_codes(mode, n: int) -> np.ndarray | int:
    """Mode names or codes (scalar or per environment) -> :data:`PASSIVE`/:data:`CURRENT`/:data:`VOLTAGE`."""
    if isinstance(mode, str):
        if mode not in MODES:
            raise ValueError(f"motor mode {mode!r}: expected one of {MODES}")
        return MODES.index(mode)
    if np.isscalar(mode):
        code = int(mode)
        if code not in (PASSIVE, CURRENT, VOLTAGE):
            raise ValueError(f"motor mode code {mode!r}: expected 0 (passive), 1 (current) or 2 (voltage)")
        return code
    codes = np.asarray(mode)
    if codes.dtype.kind in "US":
        codes = np.array([MODES.index(m) for m in codes])
    codes = codes.astype(np.int64).reshape(-1)
    if codes.shape != (n,) or codes.min() < 0 or codes.max() > 2:
        raise ValueError(f"motor modes: expected {n} codes in 0..2, got shape {codes.shape}")
    if (codes == codes[0]).all():
        return int(codes[0])
    return codes


class BatchedRig:
    """``n`` simulated rigs stepped together; each may have its own parameters.

    ``params``: one :class:`RigParams` (repeated ``n_envs`` times), a list of them, or a
    :class:`BatchedParams`. ``seed``: one seed (per-environment noise keys derived from
    it) or a list of per-environment seeds (each environment then reproduces the sensor
    readings of a :class:`MujocoRig` with that seed; :mod:`.noise`).
    ``dtype``: float64 (default) or float32. ``initial_reading``: reset and read once on
    construction, as :class:`MujocoRig` does (False: take no reading).
    """

    source = "sim"

    def __init__(self, params: RigParams | Sequence[RigParams] | BatchedParams, n_envs: int | None = None,
                 seed=None, dtype=np.float64, initial_reading: bool = True):
        if isinstance(params, RigParams):
            params = BatchedParams.repeat(params, n_envs or 1, dtype=dtype)
        elif not isinstance(params, BatchedParams):
            params = BatchedParams.stack(params, dtype=dtype)
        if n_envs is not None and n_envs != params.n:
            raise ValueError(f"BatchedRig: n_envs = {n_envs} but {params.n} parameter sets were given")
        self.n = n = params.n
        self.dtype = dtype = params.dtype
        self.sensors = SensorModel(params, keys=batch_keys(seed, n))
        self._build(params)
        self._X = np.zeros((len(STATE), n), dtype=dtype)  # the state block (rows: STATE)
        self.water_rate = np.zeros(n, dtype=dtype)
        # radiation-memory state (rad), one column per environment (no rows without memory)
        self.radiation_x = np.zeros((forces.radiation_state_size(params), n), dtype=dtype)
        self._w_prev = np.zeros(n, dtype=dtype)  # hull rate one physics step ago (forces.centred_rate)
        self.t = np.zeros(n)  # s, float64 always (phase timing)
        self.brake = np.zeros(n, dtype=bool)
        self._all = np.ones(n, dtype=bool)  # every environment (driven / running)
        self._none = np.zeros(n, dtype=bool)
        # the rotor in the gearbox's backlash (drive.backlash_step): gap (rad), its rate (rad/s), float64
        self.gap = np.zeros(n)
        self.gap_rate = np.zeros(n)
        self.backlash_work = np.zeros(n)  # J, k_t i dgap
        self.impact_loss = np.zeros(n)  # J
        if initial_reading:  # as MujocoRig: reset and read (takes the first noise sample)
            self.reset()
        else:
            self.set_brake(True)

    def _build(self, p: BatchedParams) -> None:
        """Everything that follows from the parameters: true constants, step maps, sensor delays."""
        self.params = p
        self.physics_dt = h = p.physics_dt
        self.k_t = forces.true_torque_constant(p)  # N m/A, true (scalar when shared)
        self._k_t_env = p.per_env(self.k_t)
        self._spring_offset = p.per_env(p.spring.c * forces.true_neutral(p))  # c phi_n, N m
        self._drive_decay = np.exp(-p.sample_dt * p.motor.R / p.motor.L)  # motor.terminal_voltage's, per sample
        self._constants = self._constant_table(p)
        self._drive_flaws = (forces.has_drive_torque(p) or forces.has_driver_lag(p)
                             or forces.has_backlash(p))  # step-by-step path (kept per batch)
        table = np.stack([substep_matrix(h, kind, *self._map_args(p)) for kind in range(4)])
        # (n, kind, out, in) in float64, then cast: one environment's maps contiguous (one
        # environment, index 0, when the physics is shared).
        self._G_table = np.ascontiguousarray(np.moveaxis(table, -1, 0)).astype(self.dtype)
        self._shared = table.shape[-1] == 1  # one map for the whole batch
        # each environment's map of its current kind (kernels.rig_sample copies it from the table
        # when the kind changes; -1: none yet): 5 x 8 numbers per environment stay in cache
        self._G_now = np.zeros((p.n, N_OUT, len(STATE)), dtype=self.dtype)
        self._kind_now = np.full(p.n, -1, dtype=np.int64)
        self.sensors.p = p
        self.sensors._update_params()

    def _constant_table(self, p: BatchedParams) -> np.ndarray:
        """The per-environment constants of :func:`~.kernels.rig_sample` (columns :data:`~.kernels.CONSTANTS`), float64."""
        m, h = p.motor, p.hull
        values = {"k_t": self._k_t_env, "spring_offset": self._spring_offset, "b1": h.b1, "b2": h.b2,
                  "friction_viscous": m.friction_viscous, "friction_coulomb": m.friction_coulomb, "R": m.R,
                  "u_max": m.u_max, "i_max": m.i_max, "decay": self._drive_decay}
        return np.ascontiguousarray(np.stack([np.broadcast_to(np.asarray(values[name], dtype=float), (p.n,))
                                              for name in CONSTANTS], axis=1))

    def _plain(self) -> bool:
        """Whether the only extra torques are the damping and the rotor friction (no hull-torque effect,
        no radiation or water memory): then a whole sample runs in :func:`~.kernels.rig_sample`."""
        p = self.params
        return not (active_params(p.effects, "hull_torque") or forces.has_radiation_memory(p) or forces.has_water_memory(p)
                    or self._drive_flaws)

    @staticmethod
    def _map_args(p: BatchedParams, idx=None):
        """(c, J, J_f, k_t, R, L) for :func:`substep_matrix`, of environments ``idx`` (all: None)."""
        m = p.motor
        sel = slice(None) if idx is None else idx
        J = np.asarray(p.hull.J_hull, float) + np.asarray(forces.hull_armature(p), float)
        values = (p.spring.c, J, m.J_flywheel, forces.true_torque_constant(p), m.R, m.L)
        out = []
        for v in values:
            v = np.asarray(v, float)
            out.append(v if v.ndim == 0 or idx is None else v[sel])
        return out

    def set_envs(self, envs, rigs: Sequence[RigParams], seeds) -> None:
        """Environments ``envs`` get new parameters ``rigs`` and sensor seeds ``seeds`` (a new
        episode's rig): step maps updated for those columns only; the state is left as it is
        (call :meth:`reset` next)."""
        idx = self._envs(envs)
        p = self.params
        p.set_envs(idx, rigs)
        if self._shared or self._G_table.shape[0] != self.n:  # from now on one map per environment
            # a copy (writeable) even for one environment, where broadcast_to changes no shape
            self._G_table = np.broadcast_to(self._G_table, (self.n,) + self._G_table.shape[1:]).copy()
            self._shared = False
        h = self.physics_dt
        args = self._map_args(p, idx)
        for kind in range(4):
            self._G_table[idx, kind] = np.moveaxis(substep_matrix(h, kind, *args), -1, 0)
        self._kind_now[idx] = -1  # their current maps are taken anew from the table
        self.k_t = forces.true_torque_constant(p)
        self._k_t_env = p.per_env(self.k_t)
        self._spring_offset = p.per_env(p.spring.c * forces.true_neutral(p))
        self._drive_decay = np.exp(-p.sample_dt * p.motor.R / p.motor.L)
        self._constants = self._constant_table(p)
        self._drive_flaws = forces.has_drive_torque(p) or forces.has_driver_lag(p) or forces.has_backlash(p)
        self.sensors.set_envs(idx, batch_keys(list(seeds), len(idx)))

    # --- the state, by name -----------------------------------------------------------
    phi = property(lambda self: self._X[PHI], doc="rad, hull angle")
    w = property(lambda self: self._X[W], doc="rad/s, hull rate")
    psi = property(lambda self: self._X[PSI], doc="rad, flywheel angle relative to the hull")
    omega = property(lambda self: self._X[OMEGA], doc="rad/s, flywheel rate relative to the hull")
    i = property(lambda self: self._X[I], doc="A, motor current")
    u = property(lambda self: self._X[U], doc="V, terminal voltage held over the last sample")

    @property
    def dt(self) -> float:
        """Sample period, s."""
        return self.params.sample_dt

    def _envs(self, envs) -> np.ndarray | None:
        if envs is None:
            return None
        envs = np.asarray(envs)
        if envs.dtype == bool:
            envs = np.nonzero(envs)[0]
        return envs.astype(np.int64).reshape(-1)

    # --- protocol-like API over the batch ---------------------------------------------
    def reset(self, phi0=0.0, psi0=0.0, omega0=0.0, brake=True, envs=None) -> BatchedReading:
        """Reset environments ``envs`` (all by default) as :meth:`MujocoRig.reset` does."""
        idx = self._envs(envs)
        sel = slice(None) if idx is None else idx
        X = self._X
        X[PHI, sel] = phi0
        X[PSI, sel] = psi0
        X[W, sel] = 0.0
        X[OMEGA, sel] = omega0
        X[I, sel] = 0.0
        X[U, sel] = self._k_t_env[sel] * X[OMEGA, sel]  # open circuit shows the back-EMF
        self.water_rate[sel] = 0.0
        self.radiation_x[:, sel] = 0.0
        self._w_prev[sel] = 0.0
        self.t[sel] = 0.0
        for a in (self.gap, self.gap_rate, self.backlash_work, self.impact_loss):
            a[sel] = 0.0
        self.sensors.reset(idx)
        self.brake[sel] = False
        self.set_brake(brake, envs=idx)
        return self.read(envs=idx)

    def set_brake(self, on, envs=None) -> None:
        """Engage (hold where it stands) or release the hull brake of ``envs`` (all by default).

        Engaging stops the hull at once; the flywheel keeps its absolute rate
        ``w + Omega`` through that instant (the brake's impulse acts on the hull only).
        """
        idx = self._envs(envs)
        if idx is None:
            idx = np.arange(self.n)
        on = np.broadcast_to(np.asarray(on, dtype=bool), idx.shape)
        where = idx[on & ~self.brake[idx]]  # engaging now
        if len(where):
            self._X[OMEGA, where] += self._X[W, where]
            self._X[W, where] = 0.0
        self.brake[idx] = on

    def read(self, envs=None) -> BatchedReading:
        """Sensor readings of ``envs`` (all by default); advances their noise and delay line."""
        idx = self._envs(envs)
        X = self._X
        if idx is None:
            return self.sensors.read(self.t, X[PHI], X[PSI], X[U], X[I], self.brake)
        return self.sensors.read(self.t[idx], X[PHI, idx], X[PSI, idx], X[U, idx], X[I, idx],
                                 self.brake[idx], envs=idx)

    def step(self, mode, value=0.0, active=None) -> BatchedReading:
        """Advance one sample period under per-environment commands; returns the readings
        (``active``: see :meth:`physics_step`; inactive environments take no reading)."""
        if self._plain():
            return self._sample(mode, value, active, read=True)
        self.physics_step(mode, value, active=active)
        X = self._X
        return self.sensors.read(self.t, X[PHI], X[PSI], X[U], X[I], self.brake, active=active)

    def _sample(self, mode, value, active, read: bool) -> BatchedReading | None:
        """:meth:`step` (``read``) or :meth:`physics_step` with the physics in one call of
        :func:`~.kernels.rig_sample` (a batch without hull-torque effects or water memory, :meth:`_plain`)."""
        if isinstance(mode, np.ndarray) and mode.dtype == np.int64 and mode.shape == (self.n,):  # codes already
            if mode.min() < 0 or mode.max() > 2:
                raise ValueError(f"motor modes: expected codes in 0..2, got {mode.min()}..{mode.max()}")
            modes = mode
        else:
            code = mode_codes(mode, self.n)
            modes = np.full(self.n, code, dtype=np.int64) if np.isscalar(code) else code
        running = self._all if active is None else np.asarray(active, dtype=bool)
        rig_sample(self._X, self._G_table, self._G_now, self._kind_now, self.brake, modes, self._per_env(value), running, self._constants,
                   self._w_prev, self.water_rate, self.t, self.physics_dt, self.params.physics_substeps)
        if not read:
            return None
        X = self._X
        return self.sensors.read(self.t, X[PHI], X[PSI], X[U], X[I], self.brake, active=active)

    # --- physics ------------------------------------------------------------------------
    def physics_step(self, mode, value=0.0, active=None) -> None:
        """Advance every environment one sample period (no sensor reading).

        ``mode``: ``"passive"``/``"current"``/``"voltage"`` or codes 0/1/2, scalar or per
        environment; ``value``: A (current mode) or V (voltage mode), scalar or array.
        ``active``: bool per environment, or None (all); the others stay exactly as they
        are (paused; give them ``passive``).
        """
        if self._plain():
            self._sample(mode, value, active, read=False)
            return
        p = self.params
        code = mode_codes(mode, self.n)
        X = self._X
        if np.isscalar(code):
            driven = self._none if code == PASSIVE else self._all
        else:
            driven = code != PASSIVE
        running = self._all if active is None else np.asarray(active, dtype=bool)
        paused = None if active is None or running.all() else ~running
        if code != PASSIVE if np.isscalar(code) else driven.any():
            self._set_terminal_voltage(code, np.asarray(value, dtype=self.dtype), paused)
        h = self.physics_dt
        memory = forces.has_radiation_memory(p)
        water = forces.has_water_memory(p)
        drive = forces.has_drive_torque(p)
        backlash = forces.has_backlash(p)
        for _ in range(p.physics_substeps):
            # the held torques (forces.py, on arrays), then the linear step (kernels.linear_substep)
            w_mid = forces.centred_rate(X[W], self._w_prev)
            q_hull = forces.hull_extra_torque(X[PHI], w_mid, self.water_rate, p)
            if memory:  # radiation memory: the hull feels -mu over the step
                x_new, mu = forces.radiation_memory_step(self.radiation_x, w_mid, p)
                q_hull = q_hull - mu
                if paused is not None:
                    x_new = np.where(paused, self.radiation_x, x_new)
                self.radiation_x[...] = x_new
            f2 = forces.flywheel_friction_torque(X[OMEGA], p)
            if drive:  # the drive's own torque (cogging, gear friction), the current held over the step
                f2 = f2 + forces.drive_torque(X[PSI], X[OMEGA], np.where(driven, X[I], 0.0), self._k_t_env, p)
            if backlash:  # the rotor crosses the gap on the held torque; the flywheel feels what gets through
                t_m = self._k_t_env * np.where(driven, X[I], 0.0)
                g1, v1, engaged, impulse, loss = backlash_step(self.gap, self.gap_rate, t_m, forces.backlash_inertia(p),
                                                               p.drive.backlash, h)
                if paused is not None:
                    g1, v1 = np.where(paused, self.gap, g1), np.where(paused, self.gap_rate, v1)
                    engaged, impulse, loss = np.where(paused, 1.0, engaged), np.where(paused, 0.0, impulse), \
                        np.where(paused, 0.0, loss)
                f2 = f2 + t_m * (engaged - 1.0) + impulse / h
                gap_rate = (g1 - self.gap) / h
                self.gap[...], self.gap_rate[...] = g1, v1
                self.impact_loss += loss
                u_held = X[U].copy()
                X[U] -= self._k_t_env * gap_rate  # the rotor's rate in the gap adds to the back-EMF
                i_start = X[I].copy()
            if water:
                dw = h * forces.water_rate_derivative(X[W], self.water_rate, p)
                if paused is not None:
                    dw = np.where(paused, 0.0, dw)
                self.water_rate += dw
            linear_substep(X, self._G_table, self.brake, driven, running, self._k_t_env, self._per_env(q_hull),
                           self._spring_offset, self._per_env(f2), self._w_prev, self.t, h)
            if backlash:
                on = driven & running
                # the current's mean over the step from the exact exponential solution (motor.current_step)
                m = p.motor
                tau = np.asarray(m.L, float) / np.asarray(m.R, float)
                e = np.exp(-h / tau)
                i_ss = (X[I] - i_start * e) / (1.0 - e)
                i_mean = i_ss + (i_start - i_ss) * tau / h * (1.0 - e)
                self.backlash_work += np.where(on, self._k_t_env * i_mean * gap_rate * h, 0.0)
                np.copyto(X[U], u_held, where=on)

    def _per_env(self, value) -> np.ndarray:
        """``value`` as a contiguous array of the batch's dtype and length ``n`` (no copy if it is one)."""
        if isinstance(value, np.ndarray) and value.shape == (self.n,) and value.dtype == self.dtype:
            return value
        return np.ascontiguousarray(np.broadcast_to(np.asarray(value, dtype=self.dtype), (self.n,)))

    def _set_terminal_voltage(self, code, value, paused=None) -> None:
        """The drive's voltage for the coming sample (motor.terminal_voltage), into row U (not where ``paused``)."""
        m = self.params.motor
        X = self._X
        kw = dict(R=m.R, L=m.L, k_e=self.k_t, u_max=m.u_max, i_max=m.i_max, sample_dt=self.dt,
                  decay=self._drive_decay, lag=forces.driver_lag(self.params) if forces.has_driver_lag(self.params) else 0.0)
        if np.isscalar(code) and paused is None:
            X[U] = terminal_voltage(_Command(mode=MODES[code], value=value), X[I], X[OMEGA], **kw)
            return
        for c in (CURRENT, VOLTAGE):
            mask = code == c
            if paused is not None:
                mask = mask & ~paused
            if mask.any():
                u = terminal_voltage(_Command(mode=MODES[c], value=value), X[I], X[OMEGA], **kw)
                np.copyto(X[U], u, where=mask, casting="unsafe")  # u broadcasts to the batch

    # --- bookkeeping ----------------------------------------------------------------------
    def state_nbytes(self) -> int:
        """Bytes of the per-environment state and work arrays (maps included)."""
        arrays = [self._X, self.water_rate, self.radiation_x, self._w_prev, self.t, self.brake, self._all, self._none,
                  self._k_t_env, self._spring_offset]
        total = sum(a.nbytes for a in arrays) + self._G_table.nbytes + self._G_now.nbytes + self._kind_now.nbytes
        if self.sensors.delay_samples is not None:
            total += self.sensors._hist.nbytes + self.sensors._pos.nbytes + self.sensors._count.nbytes
        return total

    def nbytes_per_env(self) -> float:
        """State + work + parameter bytes per environment."""
        return (self.state_nbytes() + self.params.nbytes()) / self.n

    def true_state(self, k: int = 0) -> dict:
        """Simulator truth of environment ``k`` (scoring and tests only)."""
        rig = self.params.rigs[k]
        X = self._X
        phi, w, omega = float(X[PHI, k]), float(X[W, k]), float(X[OMEGA, k])
        energy = float(forces.kinetic_energy(w, omega, rig) + forces.potential_energy(phi, rig))
        return {"t": float(self.t[k]), "phi": phi, "w": w, "psi": float(X[PSI, k]), "omega": omega,
                "i": float(X[I, k]), "u": float(X[U, k]), "water_rate": float(self.water_rate[k]),
                "energy": energy, "radiation_state": tuple(float(v) for v in self.radiation_x[:, k]),
                "radiation_energy": float(forces.radiation_energy(self.radiation_x[:, k].astype(float), rig)),
                "gap": float(self.gap[k]), "gap_rate": float(self.gap_rate[k]),
                "backlash_work": float(self.backlash_work[k]), "impact_loss": float(self.impact_loss[k])}
