"""The gray-box model of the rig that discovery fits, nominal and extended by one effect.

Hull (physics.md section 2, first row of the mass matrix minus the second)::

    (J_h + lambda66) phi'' = -c (phi - phi_n) + Q_hull(phi, phi', r_w) - (k_t i + Q_fly(Omega))

with the *measured* motor current ``i`` as input (offset removed) and ``Q_hull`` from
:func:`addedinertia_env.sim.forces.hull_extra_torque`, the same function the simulator
uses (one source of truth): linear + quadratic damping, and when a candidate asks for
it dry friction, fluid memory (water state ``r_w``), spring stiffening. The spring's
linear part uses :func:`~addedinertia_env.sim.forces.true_neutral`, so a neutral offset is
a parameter like any other. The brake fixes ``phi`` during the hold, while the water
state decays as ``exp(-hold / tau)``.

Flywheel (second row)::

    J_f theta'' = k_t i(t + delay) + Q_fly(Omega),     theta = phi + psi

Its residual is shot from a fitted state every :data:`~.prepare.FLYWHEEL_CHUNK_S`
(variable projection: the state is linear and solved exactly).

Integration: classic RK4 over steps of about 20 ms of *recorded* samples (each step's
length from ``t``: dropped samples and jitter included). The input is integrated on the
sample grid, not on the step: within a step the motor torque is replaced by the straight
line with the same impulse and the same first moment (both summed over the sample
intervals, the current read as the DAQ logged it), which RK4 integrates exactly; so a
controller whose current chatters within a step is not smeared into a lag. Vectorised
over segments and parameter sets, so that a finite-difference Jacobian is one batched
integration.

A model is the nominal one extended by any number of candidate effects (``effects``),
so that pairs can be fitted as well as singles.
"""

from __future__ import annotations

from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np

from addedinertia_env.sim import forces
from addedinertia_env.sim.integrator import rk4_step
from addedinertia_env.sim.effects import registry
from addedinertia_env.discover.prepare import Prepared, flywheel_prediction, interval_current

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
    """Nominal model (no effect) or nominal + candidate effects, on prepared data.

    ``effect``: None, one effect name, or a tuple of names (a pair search fits two).
    """

    def __init__(self, data: Prepared, effect: str | tuple[str, ...] | None = None):
        effects = () if effect is None else ((effect,) if isinstance(effect, str) else tuple(effect))
        for e in effects:
            if e not in candidates():
                raise ValueError(f"unknown candidate {e!r}; expected one of {', '.join(candidates())}")
        self.data = data
        self.effects = effects
        self.effect = effects[0] if len(effects) == 1 else ("+".join(effects) if effects else None)
        self.specs = NOMINAL_SPECS + tuple(s for e in effects for s in candidate_specs(e))
        self.names = tuple(s.name for s in self.specs)
        self.segments = []
        for run in data.runs:
            first = len(self.segments)
            for seg in run.segments:
                if seg.kind == "reverse":
                    seg.carry_from = first  # the free stroke of the same run
                self.segments.append(seg)
        self._hold = np.array([s.hold_before for s in self.segments])
        self._hull_obs = np.concatenate([s.phi_steps[1:] for s in self.segments])
        self._flywheels = [r.flywheel for r in data.runs if r.flywheel is not None and r.flywheel.chunks]
        self._fly_proj = [_chunk_projections(fw) for fw in self._flywheels]
        self._fly_obs = [fw.theta[:: fw.step_samples][: _n_points(fw)] for fw in self._flywheels]
        n = max(s.steps for s in self.segments)
        self._h = np.zeros((len(self.segments), n))
        for k, s in enumerate(self.segments):
            self._h[k, : s.steps] = np.diff(s.t_steps)
        self._input_cache: dict[tuple[float, float], tuple] = {}

    # --- parameters -----------------------------------------------------------------
    def start(self) -> np.ndarray:
        """Start values of the parameters, in ``names`` order."""
        return np.array([s.start for s in self.specs], dtype=float)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(lower, upper) bounds of the parameters."""
        return np.array([s.low for s in self.specs]), np.array([s.high for s in self.specs])

    def scales(self) -> np.ndarray:
        """Typical sizes of the parameters (optimiser scaling)."""
        return np.array([s.scale for s in self.specs])

    def as_dict(self, theta: np.ndarray) -> dict[str, float]:
        """``{name: value}`` of a parameter vector."""
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
        for e in self.effects:
            setattr(effects, e, SimpleNamespace(**{n: col(n) for n in registry.get(e).param_names}))
        effects._hooked = registry.hook_table(effects)
        return SimpleNamespace(hull=SimpleNamespace(b1=col("b1"), b2=col("b2")),
                               spring=SimpleNamespace(c=d.c, phi_neutral=d.phi_neutral), effects=effects)

    @staticmethod
    def _motor_input_params(ns: SimpleNamespace, P: int) -> tuple[np.ndarray, np.ndarray]:
        """Per parameter set: the current channel's lag (s) and the torque-constant ratio (-)."""
        delays = np.broadcast_to(np.ravel(forces.channel_delay(ns)), (P,))
        ratios = np.broadcast_to(np.ravel(forces.torque_constant_ratio(ns)), (P,))
        return delays, ratios

    # --- inputs -------------------------------------------------------------------------
    def _inputs(self, delay: float, ratio: float):
        """Per segment the hull input torque per step as (mean, slope), and flywheel angles; cached."""
        key = (float(delay), float(ratio))
        hit = self._input_cache.get(key)
        if hit is not None:
            return hit
        d = self.data
        k_t = d.k_t * ratio
        hull = []
        for seg in self.segments:
            ia, ib = interval_current(seg.t, seg.current, d.current_mode, delay)
            q = seg.flywheel_friction
            # reaction on the hull of the motor torque on the flywheel, at each interval's ends
            hull.append(step_input(seg.t, -(k_t * ia + q), -(k_t * ib + q), seg.step_samples, seg.steps))
        fly = [flywheel_prediction(fw, d.k_t, d.J_flywheel, d.current_mode, delay, ratio) for fw in self._flywheels]
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
        """Number of hull residuals."""
        return int(self._hull_obs.size)

    @property
    def n_flywheel(self) -> int:
        """Number of flywheel residuals."""
        return int(sum(sl.stop - sl.start for fw in self._flywheels for sl in fw.chunks))

    def _segment_inputs(self, thetas: np.ndarray):
        """What every segment's integration starts from, for the (P,) parameter sets ``thetas``: the
        parameters' namespace, the motor torque's mean and slope per step (P, segments, steps), the
        start angles (P, segments), the step counts and whether each segment carries a state over."""
        P = len(thetas)
        ns = self._namespace(thetas)
        delays, ratios = self._motor_input_params(ns, P)
        inputs = [self._inputs(delays[p], ratios[p])[0] for p in range(P)]
        segs = self.segments
        mean = _stack([[m for m, _ in row] for row in inputs])
        slope = _stack([[s for _, s in row] for row in inputs])
        phi0 = np.array([s.phi[0] for s in segs])[None, :].repeat(P, 0)
        ends = np.array([s.steps for s in segs])
        carried = np.array([s.carry_from is not None for s in segs])
        return ns, mean, slope, phi0, ends, carried

    def hull_prediction(self, thetas: np.ndarray) -> np.ndarray:
        """Model hull angle at every step boundary of every segment, (P, n_hull)."""
        P = len(thetas)
        ns, mean, slope, phi0, ends, carried = self._segment_inputs(thetas)
        J = (self.data.J_hull + thetas[:, 0])[:, None]
        segs = self.segments
        if not forces.has_water_memory(ns) or not carried.any():  # strokes independent: one pass
            phi, _ = _integrate(phi0, np.zeros_like(phi0), mean, slope, self._h, J, ns, self.data, ends)
        else:  # the water state carries from the free stroke, through the hold, to the reverse
            phi = np.zeros((P, len(segs), mean.shape[2] + 1))
            first = ~carried
            idx_f, idx_c = np.nonzero(first)[0], np.nonzero(carried)[0]
            phi_f, water_end = _integrate(phi0[:, idx_f], np.zeros((P, len(idx_f))), mean[:, idx_f], slope[:, idx_f],
                                          self._h[idx_f], J, ns, self.data, ends[idx_f])
            phi[:, idx_f] = phi_f
            src = np.array([int(np.nonzero(idx_f == segs[i].carry_from)[0][0]) for i in idx_c])
            water0 = forces.water_rate_after_rest(water_end[:, src], self._hold[idx_c][None, :], ns)
            phi_c, _ = _integrate(phi0[:, idx_c], water0, mean[:, idx_c], slope[:, idx_c], self._h[idx_c], J,
                                  ns, self.data, ends[idx_c])
            phi[:, idx_c] = phi_c
        parts = [phi[:, k, 1: s.steps + 1] for k, s in enumerate(segs)]
        return np.concatenate(parts, axis=1)

    def flywheel_residuals(self, thetas: np.ndarray) -> np.ndarray:
        """Flywheel residuals (rad) after removing each chunk's fresh angle and rate, one row per parameter set."""
        delays, ratios = self._motor_input_params(self._namespace(thetas), len(thetas))
        rows = []
        for p in range(len(thetas)):
            fly = self._inputs(delays[p], ratios[p])[1]
            parts = []
            for obs, pred, proj in zip(self._fly_obs, fly, self._fly_proj):
                y = obs - pred
                parts += [M @ y[sl] for sl, M in proj]
            rows.append(np.concatenate(parts) if parts else np.zeros(0))
        return np.array(rows)

    def split(self, scaled: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Unscaled (hull rad, flywheel rad) residuals from a row of :meth:`residuals`."""
        return scaled[: self.n_hull] * self.data.phi_noise, scaled[self.n_hull:] * self.data.theta_noise

    def hull_index(self) -> list[tuple[int, str, slice]]:
        """(run, stroke kind, slice of the hull residuals) for every segment."""
        out, k = [], 0
        for seg in self.segments:
            out.append((seg.run, seg.kind, slice(k, k + seg.steps)))
            k += seg.steps
        return out

    def flywheel_rows(self, run: int) -> np.ndarray:
        """Indices of run ``run``'s flywheel residuals in the stacked residual vector."""
        offset = self.n_hull
        for fw in self._flywheels:
            n = sum(sl.stop - sl.start for sl in fw.chunks)
            if fw.run == run:
                return np.arange(offset, offset + n)
            offset += n
        return np.zeros(0, dtype=int)


def step_input(t: np.ndarray, start: np.ndarray, end: np.ndarray, n: int, steps: int
               ) -> tuple[np.ndarray, np.ndarray]:
    """Per step of ``n`` sample intervals: the straight line ``mean + slope (s - s_mid)`` with the
    same impulse and first moment as the input (linear over each interval, values ``start``,
    ``end``), N m and N m/s. RK4 integrates a linear input exactly."""
    m = steps * n
    h = np.diff(t)[:m].reshape(steps, n)
    a, b = start[:m].reshape(steps, n), end[:m].reshape(steps, n)
    t0 = t[:m].reshape(steps, n)
    t_end = t[n:: n][:steps]
    H = t_end - t[:: n][:steps]
    mid = t0 + 0.5 * h
    avg = 0.5 * (a + b)
    m0 = np.sum(avg * h, axis=1)
    m1 = np.sum(avg * h * (t_end[:, None] - mid) - (b - a) * h * h / 12.0, axis=1)
    mean = m0 / H
    slope = 12.0 * (0.5 * mean * H * H - m1) / H**3
    return mean, slope


def _n_points(fw) -> int:
    return fw.chunks[-1].stop if fw.chunks else 0


def _chunk_projections(fw) -> list[tuple[slice, np.ndarray]]:
    """Per chunk, the matrix that removes the best straight line (a fresh angle and rate)."""
    t = fw.t[:: fw.step_samples]
    out = []
    for sl in fw.chunks:
        tt = t[sl] - t[sl][0]
        X = np.column_stack([np.ones_like(tt), tt])
        out.append((sl, np.eye(len(tt)) - X @ np.linalg.pinv(X)))
    return out


def _stack(rows: list[list[np.ndarray]]) -> np.ndarray:
    """(P, S, N) zero-padded array of per-step inputs."""
    n = max(len(u) for row in rows for u in row)
    out = np.zeros((len(rows), len(rows[0]), n))
    for p, row in enumerate(rows):
        for s, u in enumerate(row):
            out[p, s, : len(u)] = u
    return out


def _integrate(phi0, water0, mean, slope, h_steps, J, ns, data: Prepared, ends: np.ndarray):
    """RK4 of the hull from rest; phi at every step boundary (P, S, N + 1), and the water state at each segment's end.

    ``mean``, ``slope``: (P, S, N) input torque line per step; ``h_steps``: (S, N) step lengths, s
    (0 past a segment's end, which freezes it).
    """
    c = data.c
    neutral = forces.true_neutral(ns)
    memory = forces.has_water_memory(ns)

    def deriv(z, torque):
        phi, w, r = z
        acc = (-c * (phi - neutral) + forces.hull_extra_torque(phi, w, r, ns) + torque) / J
        dr = forces.water_rate_derivative(w, r, ns) if memory else 0.0 * r
        return w, acc, dr

    P, S, N = mean.shape
    phi, w, r = phi0.astype(float), np.zeros((P, S)), water0.astype(float)
    out = np.empty((P, S, N + 1))
    out[:, :, 0] = phi
    water_end = np.zeros((P, S))
    for j in range(N):
        h = h_steps[None, :, j]
        u_mid = mean[:, :, j]
        du = 0.5 * slope[:, :, j] * h
        phi, w, r_new = rk4_step(deriv, (phi, w, r), h, inputs=(u_mid - du, u_mid, u_mid + du))
        if memory:
            r = r_new
            done = ends == j + 1
            if done.any():
                water_end[:, done] = r[:, done]
        out[:, :, j + 1] = phi
    return out, water_end
