"""The whole-record gray-box model with the water's radiation memory as a state.

With memory (physics.md section 6, docs/RADIATION_MEMORY.md) the hull's equation is

    (J_h + A66(inf)) phi'' = -c (phi - phi_n) + Q_hull - (k_t i + Q_fly) - mu,
    mu = K(s) phi',   x' = A x + b phi',   mu = c.x + d phi'

The kernel is the one :func:`~addedinertia_env.identify.memory.identify_memory` identified from
the same records (its family, poles and coefficients), normalised to A66(0) = 1 like the
simulator's own model: the fit's ``lambda66`` is A66(0), the armature is ``lambda66 x
A66(inf)/A66(0)`` and ``mu`` scales with ``lambda66``. So the kernel's *shape* comes from the
memory identification and its *size* from the whole-record fit, which reads lambda66 from the
motor's known torque and the free swing like the memory-free model. The state starts at zero
at each run's first release (the water calm after the idle), carries from the free stroke through
the hold (``x -> exp(A hold) x``, the hull held still) into the reverse stroke.

Integration as :mod:`~addedinertia_env.discover.model` does (RK4 over steps of about 20 ms, the
input as a straight line per step); the state's fastest pole (at most 60 rad/s, the memory
search's bound) stays well inside RK4's stability at that step (h |p| < 2.8).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from addedinertia_env.discover.model import GrayBoxModel, ParamSpec
from addedinertia_env.identify.memory import FamilyFit, MemoryIdentification
from addedinertia_env.sim import forces
from addedinertia_env.sim.integrator import rk4_step


FREE_INF = True  # the whole-record fit reads A66(inf) itself (see MemoryGrayBoxModel)


@dataclass(frozen=True)
class MemoryKernel:
    """A passive memory kernel in state space, per kg m^2 of the memory's size A66(0) - A66(inf):
    ``x' = A x + b w``, ``mu / (A66(0) - A66(inf)) = c.x + d w``; ``a_inf_ratio`` = A66(inf)/A66(0) as identified."""

    A: np.ndarray
    b: np.ndarray
    c: np.ndarray
    d: float
    a_inf_ratio: float
    family: str

    @property
    def order(self) -> int:
        """Number of states."""
        return len(self.b)

    @classmethod
    def from_fit(cls, fit: FamilyFit) -> "MemoryKernel":
        """The state space of ``K(s) = s sum theta_i G_i(s)`` (identify/memory.py), normalised to A66(0)."""
        n = sum(1 if sec[0] == "r" else 2 for sec in fit.sections)
        A, b, c, d = np.zeros((n, n)), np.zeros(n), np.zeros(n), 0.0
        i = k = 0
        for sec in fit.sections:
            if sec[0] == "r":  # x' = -a x + w; s/(s + a) w = w - a x
                a = sec[1]
                A[i, i], b[i] = -a, 1.0
                c[i] += -a * fit.theta[k]
                d += fit.theta[k]
                i, k = i + 1, k + 1
            else:  # x1' = x2, x2' = -wn^2 x1 - 2 z wn x2 + w; s/D w = x2, s^2/D w = x2'
                wn, z = sec[1], sec[2]
                A[i, i + 1] = 1.0
                A[i + 1, i], A[i + 1, i + 1], b[i + 1] = -wn * wn, -2.0 * z * wn, 1.0
                c[i + 1] += fit.theta[k]
                c[i] += -wn * wn * fit.theta[k + 1]
                c[i + 1] += -2.0 * z * wn * fit.theta[k + 1]
                d += fit.theta[k + 1]
                i, k = i + 2, k + 2
        size = fit.A_zero - fit.A_inf  # the memory's share of A66(0), > 0 for a passive family
        return cls(A, b, c / size, d / size, fit.A_inf / fit.A_zero, fit.family)

    def after_rest(self, x: np.ndarray, seconds: np.ndarray) -> np.ndarray:
        """The state after ``seconds`` (per segment) with the hull held still: ``exp(A t) x``; ``x`` (n, P, S)."""
        from scipy.linalg import expm  # noqa: PLC0415

        out = np.empty_like(x)
        for s, t in enumerate(np.atleast_1d(seconds)):
            out[:, :, s] = expm(self.A * float(t)) @ x[:, :, s]
        return out


def kernel_of(memory: MemoryIdentification | None) -> MemoryKernel | None:
    """The identified memory's kernel, or None when the records show none (or it is not identifiable)."""
    if memory is None or not memory.identified or memory.best is None:
        return None
    return MemoryKernel.from_fit(memory.best)


class MemoryGrayBoxModel(GrayBoxModel):
    """:class:`~addedinertia_env.discover.model.GrayBoxModel` with the radiation memory's state (module doc)."""

    def __init__(self, data, effect=None, kernel: MemoryKernel | None = None, free_inf: bool = FREE_INF):
        super().__init__(data, effect)
        if kernel is None:
            raise ValueError("MemoryGrayBoxModel needs a memory kernel (kernel_of(identify_memory(records)))")
        self.kernel = kernel
        self.free_inf = free_inf
        if free_inf:  # A66(inf) a parameter too: the kernel's shape from the memory fit, its size from this fit
            self.specs = self.specs + (ParamSpec("A66_inf", "kg m^2", 10.0 * kernel.a_inf_ratio, 0.0, 1e3, 0.5),)
            self.names = tuple(sp.name for sp in self.specs)

    def extend(self, theta: np.ndarray) -> np.ndarray:
        """A memory-free model's parameters with this model's own appended (A66(inf) from the identified ratio)."""
        theta = np.asarray(theta, float)
        if not self.free_inf or len(theta) == len(self.names):
            return theta
        return np.r_[theta, theta[0] * self.kernel.a_inf_ratio]

    def with_effects(self, effects: tuple[str, ...]) -> "MemoryGrayBoxModel":
        """The same model (data and kernel) with other effects (their parameters before ``A66_inf``)."""
        return MemoryGrayBoxModel(self.data, effects or None, self.kernel, self.free_inf)

    def _a_inf(self, thetas: np.ndarray) -> np.ndarray:
        if self.free_inf:
            return thetas[:, self.names.index("A66_inf")][:, None]
        return thetas[:, 0][:, None] * self.kernel.a_inf_ratio

    def hull_prediction(self, thetas: np.ndarray) -> np.ndarray:
        """Model hull angle at every step boundary of every segment, (P, n_hull), with the memory state."""
        P = len(thetas)
        ns, mean, slope, phi0, ends, carried = self._segment_inputs(thetas)
        lam = thetas[:, 0][:, None]
        a_inf = self._a_inf(thetas)
        segs = self.segments
        n = self.kernel.order
        phi = np.zeros((P, len(segs), mean.shape[2] + 1))
        first = ~carried
        idx_f, idx_c = np.nonzero(first)[0], np.nonzero(carried)[0]
        zeros_f = np.zeros((P, len(idx_f)))
        phi_f, r_end, x_end = self._integrate(phi0[:, idx_f], zeros_f, np.zeros((n, P, len(idx_f))),
                                              mean[:, idx_f], slope[:, idx_f], self._h[idx_f], lam, a_inf, ns,
                                              ends[idx_f])
        phi[:, idx_f] = phi_f
        if len(idx_c):
            src = np.array([int(np.nonzero(idx_f == segs[i].carry_from)[0][0]) for i in idx_c])
            hold = self._hold[idx_c]
            r0 = forces.water_rate_after_rest(r_end[:, src], hold[None, :], ns)
            x0 = self.kernel.after_rest(x_end[:, :, src], hold)
            phi_c, _, _ = self._integrate(phi0[:, idx_c], r0, x0, mean[:, idx_c], slope[:, idx_c], self._h[idx_c],
                                          lam, a_inf, ns, ends[idx_c])
            phi[:, idx_c] = phi_c
        parts = [phi[:, k, 1: s.steps + 1] for k, s in enumerate(segs)]
        return np.concatenate(parts, axis=1)

    def _integrate(self, phi0, r0, x0, mean, slope, h_steps, lam, a_inf, ns, ends):
        """RK4 of the hull with the memory state; phi at every step boundary (P, S, N + 1) and the water and
        memory states at each segment's end."""
        data, k = self.data, self.kernel
        c = data.c
        neutral = forces.true_neutral(ns)
        water = forces.has_water_memory(ns)
        J = data.J_hull + a_inf  # (P, 1)
        size = lam - a_inf  # the memory's share of A66(0)
        A, b, cv, d = k.A, k.b[:, None, None], k.c, k.d

        def deriv(z, torque):  # the memory state is (n, P, S): its trailing axes broadcast with the step lengths
            phi, w, r, x = z
            mu = size * (np.tensordot(cv, x, axes=1) + d * w)
            acc = (-c * (phi - neutral) + forces.hull_extra_torque(phi, w, r, ns) + torque - mu) / J
            dr = forces.water_rate_derivative(w, r, ns) if water else 0.0 * r
            return w, acc, dr, np.tensordot(A, x, axes=1) + b * w

        P, S, N = mean.shape
        phi, w, r, x = phi0.astype(float), np.zeros((P, S)), r0.astype(float), x0.astype(float)
        out = np.empty((P, S, N + 1))
        out[:, :, 0] = phi
        r_end, x_end = np.zeros((P, S)), np.zeros((k.order, P, S))
        for j in range(N):
            h = h_steps[None, :, j]
            u_mid = mean[:, :, j]
            du = 0.5 * slope[:, :, j] * h
            # a segment past its end has h = 0: it stays as it was
            phi, w, r_new, x = rk4_step(deriv, (phi, w, r, x), h, inputs=(u_mid - du, u_mid, u_mid + du))
            r = r_new if water else r
            done = ends == j + 1
            if done.any():
                r_end[:, done] = r[:, done]
                x_end[:, :, done] = x[:, :, done]
            out[:, :, j + 1] = phi
        return out, r_end, x_end
