"""The gray-box model of the rig that discovery fits, nominal and extended by one effect.

Hull (physics.md section 2, first row of the mass matrix minus the second)::

    (J_h + lambda66) phi'' = -c (phi - phi_n) + Q_hull(phi, phi', r_w) - (k_t i + Q_fly(Omega))

with the *measured* motor current ``i`` as input (offset removed) and ``Q_hull`` from
:func:`addedinertia_env.rig.forces.hull_extra_torque`, the same function the simulator
uses (one source of truth): linear + quadratic damping, and when a candidate asks for
it dry friction, fluid memory (water state ``r_w``), spring stiffening. The spring's
linear part uses :func:`~addedinertia_env.rig.forces.true_neutral`, so a neutral offset is
a parameter like any other. The brake fixes ``phi`` during the hold, while the water
state decays as ``exp(-hold / tau)``.

Flywheel (second row)::

    J_f theta'' = k_t i(t + delay) + Q_fly(Omega),     theta = phi + psi

Its residual is shot from a fitted state every :data:`~.prepare.FLYWHEEL_CHUNK_S`
(variable projection: the state is linear and solved exactly).

Integration: classic RK4 at ``STEP_SAMPLES`` samples per step, the input torque averaged
over the step (exact for its impulse), vectorised over segments and parameter sets, so
that a finite-difference Jacobian is one batched integration.
"""

from __future__ import annotations

from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np

from ..rig import forces
from ..rig.effects import registry
from .prepare import STEP_SAMPLES, Prepared, double_integral

NOMINAL_PARAMS = registry.NOMINAL_PARAM_NAMES


@dataclass(frozen=True)
class ParamSpec:
    """One fitted parameter: name, unit, start value, bounds and typical size (same unit)."""

    name: str
    unit: str
    start: float
    low: float
    high: float
    scale: float  # typical size, for the optimiser's scaling and finite differences


NOMINAL_SPECS = (
    ParamSpec("lambda66", "kg m^2", 10.0, 0.0, 1e3, 1.0),
    ParamSpec("b1", "N m s", 0.2, -5.0, 50.0, 0.1),
    ParamSpec("b2", "N m s^2", 50.0, -50.0, 1e4, 10.0),
)



def candidate_specs(effect: str) -> tuple[ParamSpec, ...]:
    """The fitted parameters of a candidate effect, from the effect registry."""
    return tuple(ParamSpec(p.name, p.unit, p.fit.start, p.fit.low, p.fit.high, p.fit.scale)
                 for p in registry.get(effect).params)


def candidates() -> tuple[str, ...]:
    """Every registered effect is a discovery candidate (registry order)."""
    return registry.effect_names()


def no_effect_value(name: str) -> float:
    """The fixed value of an effect parameter in a model without that effect (its ``neutral``)."""
    for spec in registry.specs():
        if name in spec.param_names:
            return spec.param(name).neutral
    raise KeyError(name)


class GrayBoxModel:
    """Nominal model (``effect=None``) or nominal + one candidate effect, on prepared data."""

    def __init__(self, data: Prepared, effect: str | None = None):
        if effect is not None and effect not in candidates():
            raise ValueError(f"unknown candidate {effect!r}; expected one of {', '.join(candidates())}")
        self.data = data
        self.effect = effect
        self.specs = NOMINAL_SPECS + (candidate_specs(effect) if effect else ())
        self.names = tuple(s.name for s in self.specs)
        self._free = [r.free for r in data.runs]
        self._rev = [r.reverse for r in data.runs]
        self._hold = np.array([r.hold_s for r in data.runs])
        self._hull_obs = np.concatenate([s.phi_steps[1:] for s in self._free + self._rev])
        self._fly_proj = [_chunk_projections(r.flywheel) for r in data.runs]
        self._fly_obs = [r.flywheel.theta[::STEP_SAMPLES][: _n_points(r.flywheel)] for r in data.runs]
        self._input_cache: dict[tuple[float, float], tuple] = {}

    # --- parameters -----------------------------------------------------------------
    def start(self) -> np.ndarray:
        return np.array([s.start for s in self.specs], dtype=float)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        return np.array([s.low for s in self.specs]), np.array([s.high for s in self.specs])

    def scales(self) -> np.ndarray:
        return np.array([s.scale for s in self.specs])

    def as_dict(self, theta: np.ndarray) -> dict[str, float]:
        return {n: float(v) for n, v in zip(self.names, theta)}

    def _column(self, thetas: np.ndarray, name: str) -> np.ndarray:
        if name in self.names:
            return thetas[:, self.names.index(name)]
        return np.full(len(thetas), no_effect_value(name))

    def _namespace(self, thetas: np.ndarray) -> SimpleNamespace:
        """A parameter object :mod:`..rig.forces` understands, with one row per parameter set."""
        col = lambda n: self._column(thetas, n)[:, None]  # noqa: E731 - (P, 1) broadcasts over segments
        d = self.data
        effects = SimpleNamespace()
        if self.effect is not None:
            names = registry.get(self.effect).param_names
            setattr(effects, self.effect, SimpleNamespace(**{n: col(n) for n in names}))
        effects._hooked = registry.hook_table(effects)
        return SimpleNamespace(hull=SimpleNamespace(b1=col("b1"), b2=col("b2")),
                               spring=SimpleNamespace(c=d.c, phi_neutral=d.phi_neutral), effects=effects)

    # --- inputs -------------------------------------------------------------------------
    @staticmethod
    def _motor_input_params(ns: SimpleNamespace, P: int) -> tuple[np.ndarray, np.ndarray]:
        """Per parameter set: the current channel's lag (s) and the torque-constant ratio (-)."""
        delays = np.broadcast_to(np.ravel(forces.channel_delay(ns)), (P,))
        ratios = np.broadcast_to(np.ravel(forces.torque_constant_ratio(ns)), (P,))
        return delays, ratios

    def _inputs(self, delay: float, ratio: float):
        """Hull input torque per step for every segment, and flywheel accelerations, cached."""
        key = (float(delay), float(ratio))
        hit = self._input_cache.get(key)
        if hit is not None:
            return hit
        d = self.data
        k_t = d.k_t * ratio

        def motor_torque(t, current, q_fly):
            i = _shifted(t, current, delay)
            return k_t * 0.5 * (i[1:] + i[:-1]) + q_fly  # on the flywheel, per interval

        hull = []
        for seg in self._free + self._rev:
            per_interval = -motor_torque(seg.t, seg.current, seg.flywheel_friction)  # reaction on the hull
            hull.append(per_interval[: seg.steps * STEP_SAMPLES].reshape(seg.steps, STEP_SAMPLES).mean(axis=1))
        fly = []
        for run in d.runs:
            fw = run.flywheel
            acc = motor_torque(fw.t, fw.current, fw.flywheel_friction) / d.J_flywheel
            fly.append(double_integral(fw.t, acc)[::STEP_SAMPLES][: _n_points(fw)])
        out = (hull, fly)
        if len(self._input_cache) > 64:
            self._input_cache.clear()
        self._input_cache[key] = out
        return out

    # --- simulation ---------------------------------------------------------------------
    def residuals(self, thetas: np.ndarray) -> np.ndarray:
        """Scaled residuals, one row per parameter set: hull (rad / phi_noise) then flywheel."""
        thetas = np.atleast_2d(np.asarray(thetas, dtype=float))
        hull = self.hull_prediction(thetas) - self._hull_obs[None, :]
        fly = self.flywheel_residuals(thetas)
        return np.concatenate([hull / self.data.phi_noise, fly / self.data.theta_noise], axis=1)

    @property
    def n_hull(self) -> int:
        return int(self._hull_obs.size)

    def hull_prediction(self, thetas: np.ndarray) -> np.ndarray:
        """Model hull angle at every step boundary of every segment, (P, n_hull)."""
        P = len(thetas)
        ns = self._namespace(thetas)
        delays, ratios = self._motor_input_params(ns, P)
        inputs = [self._inputs(delays[p], ratios[p])[0] for p in range(P)]
        J = (self.data.J_hull + thetas[:, 0])[:, None]
        nf = len(self._free)
        segs = self._free + self._rev
        u = _stack([inp for inp in inputs])
        phi0 = np.array([s.phi[0] for s in segs])[None, :].repeat(P, 0)
        ends = np.array([s.steps for s in segs])
        if not forces.has_water_memory(ns):  # strokes independent: one pass over all of them
            phi, _ = _integrate(phi0, np.zeros_like(phi0), u, J, ns, self.data, ends)
        else:  # the water state carries from the free stroke, through the hold, to the reverse
            phi = np.empty((P, len(segs), u.shape[2] + 1))
            free_phi, water_end = _integrate(phi0[:, :nf], np.zeros((P, nf)), u[:, :nf], J, ns, self.data, ends[:nf])
            water0 = forces.water_rate_after_rest(water_end, self._hold[None, :], ns)
            n_rev = int(ends[nf:].max())
            rev_phi, _ = _integrate(phi0[:, nf:], water0, u[:, nf:, :n_rev], J, ns, self.data, ends[nf:])
            phi[:, :nf] = free_phi
            phi[:, nf:, : n_rev + 1] = rev_phi
        parts = [phi[:, k, 1: s.steps + 1] for k, s in enumerate(segs)]
        return np.concatenate(parts, axis=1)

    def flywheel_residuals(self, thetas: np.ndarray) -> np.ndarray:
        delays, ratios = self._motor_input_params(self._namespace(thetas), len(thetas))
        rows = []
        for p in range(len(thetas)):
            fly = self._inputs(delays[p], ratios[p])[1]
            parts = []
            for obs, pred, proj in zip(self._fly_obs, fly, self._fly_proj):
                y = obs - pred
                parts += [M @ y[sl] for sl, M in proj]
            rows.append(np.concatenate(parts))
        return np.array(rows)

    def split(self, scaled: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Unscaled (hull rad, flywheel rad) residuals from a row of :meth:`residuals`."""
        return scaled[: self.n_hull] * self.data.phi_noise, scaled[self.n_hull:] * self.data.theta_noise

    def hull_index(self) -> list[tuple[int, str, slice]]:
        """(run, stroke kind, slice of the hull residuals) for every segment."""
        out, k = [], 0
        for seg in self._free + self._rev:
            out.append((seg.run, seg.kind, slice(k, k + seg.steps)))
            k += seg.steps
        return out


def _n_points(fw) -> int:
    return fw.chunks[-1].stop if fw.chunks else 0


def _chunk_projections(fw) -> list[tuple[slice, np.ndarray]]:
    """Per chunk, the matrix that removes the best straight line (a fresh angle and rate)."""
    t = fw.t[::STEP_SAMPLES]
    out = []
    for sl in fw.chunks:
        tt = t[sl] - t[sl][0]
        X = np.column_stack([np.ones_like(tt), tt])
        out.append((sl, np.eye(len(tt)) - X @ np.linalg.pinv(X)))
    return out


def _shifted(t: np.ndarray, x: np.ndarray, delay: float) -> np.ndarray:
    """``x(t + delay)`` by linear interpolation (a channel that lags by ``delay`` read forward)."""
    if delay == 0.0:
        return x
    return np.interp(t + delay, t, x)


def _stack(rows: list[list[np.ndarray]]) -> np.ndarray:
    """(P, S, N) zero-padded array of per-step inputs."""
    n = max(len(u) for row in rows for u in row)
    out = np.zeros((len(rows), len(rows[0]), n))
    for p, row in enumerate(rows):
        for s, u in enumerate(row):
            out[p, s, : len(u)] = u
    return out


def _integrate(phi0, water0, u, J, ns, data: Prepared, ends: np.ndarray):
    """RK4 of the hull from rest; phi at every step boundary (P, S, N + 1), and the water state at each segment's end."""
    h = STEP_SAMPLES * data.dt
    c = data.c
    neutral = forces.true_neutral(ns)
    memory = forces.has_water_memory(ns)

    def deriv(phi, w, r, torque):
        acc = (-c * (phi - neutral) + forces.hull_extra_torque(phi, w, r, ns) + torque) / J
        dr = forces.water_rate_derivative(w, r, ns) if memory else 0.0
        return w, acc, dr

    P, S, N = u.shape
    phi, w, r = phi0.astype(float), np.zeros((P, S)), water0.astype(float)
    out = np.empty((P, S, N + 1))
    out[:, :, 0] = phi
    water_end = np.zeros((P, S))
    for j in range(N):
        torque = u[:, :, j]
        k1p, k1w, k1r = deriv(phi, w, r, torque)
        k2p, k2w, k2r = deriv(phi + 0.5 * h * k1p, w + 0.5 * h * k1w, r + 0.5 * h * k1r, torque)
        k3p, k3w, k3r = deriv(phi + 0.5 * h * k2p, w + 0.5 * h * k2w, r + 0.5 * h * k2r, torque)
        k4p, k4w, k4r = deriv(phi + h * k3p, w + h * k3w, r + h * k3r, torque)
        phi = phi + h / 6.0 * (k1p + 2 * k2p + 2 * k3p + k4p)
        w = w + h / 6.0 * (k1w + 2 * k2w + 2 * k3w + k4w)
        if memory:
            r = r + h / 6.0 * (k1r + 2 * k2r + 2 * k3r + k4r)
            done = ends == j + 1
            if done.any():
                water_end[:, done] = r[:, done]
        out[:, :, j + 1] = phi
    return out, water_end
