"""Cummins' radiation convolution as a small state-space system, fitted in the frequency domain.

The radiation moment of yaw is ``-A66(inf) phi'' - mu(t)`` with ``mu = integral K(t - s) phi'(s) ds``.
The kernel's transform is known from the BEM on the sweep:

    Kh(j omega) = integral_0^inf K(t) exp(-j omega t) dt = B66(omega) + j omega (A66(omega) - A66(inf))

and is fitted by a strictly proper rational function ``P(s) / Q(s)`` of order n with
``P(0) = 0`` (``Kh(0) = integral K dt = B66(0) = 0``) and relative degree 1 (``K(0)`` finite),
by linearised least squares with Sanathanan-Koerner reweighting (Perez & Fossen 2008 use
the same frequency-domain identification). Unstable poles are reflected into the left half
plane. The order is the smallest whose relative fit error is below ``tolerance``.

The realisation (controllable canonical form) ``x' = A x + b phi'``, ``mu = c . x`` is what a
simulator integrates alongside the rig (N m; x in the units that make ``c . x`` N m).
"""

from __future__ import annotations

import dataclasses

import numpy as np


@dataclasses.dataclass(frozen=True)
class RadiationSS:
    """``x' = A x + b u``, ``y = c . x``; u the yaw rate (rad/s), y the memory moment (N m)."""

    A: np.ndarray
    b: np.ndarray
    c: np.ndarray
    order: int
    fit_error: float  # relative L2 error of the fit on the sweep

    def response(self, omega) -> np.ndarray:
        """Kh(j omega) of the realisation."""
        omega = np.atleast_1d(np.asarray(omega, dtype=float))
        n = self.order
        out = np.empty(len(omega), dtype=complex)
        for k, w in enumerate(omega):
            out[k] = self.c @ np.linalg.solve(1j * w * np.eye(n) - self.A, self.b)
        return out

    def kernel(self, t) -> np.ndarray:
        """K(t) = c exp(A t) b (N m)."""
        from scipy.linalg import expm  # noqa: PLC0415

        return np.array([self.c @ expm(self.A * tt) @ self.b for tt in np.atleast_1d(t)])

    def as_dict(self) -> dict:
        """The fitted state-space system as a JSON-ready dict: matrices ``A``, ``b``, ``c``, its order and the fit error."""
        return {"A": self.A.tolist(), "b": self.b.tolist(), "c": self.c.tolist(), "order": self.order,
                "fit_error": self.fit_error}


def kernel_transform(omega, a66, b66, a_inf: float) -> np.ndarray:
    """Kh(j omega) = B66 + j omega (A66 - A66(inf)) on the sweep (N m s)."""
    omega = np.asarray(omega, dtype=float)
    return np.asarray(b66, dtype=float) + 1j * omega * (np.asarray(a66, dtype=float) - a_inf)


def _fit_order(omega: np.ndarray, K: np.ndarray, n: int, iterations: int = 20) -> tuple[np.ndarray, np.ndarray]:
    """Coefficients (p, q) of P(s) = sum_{k=1}^{n-1} p_k s^k, Q(s) = s^n + sum_{k<n} q_k s^k."""
    s = 1j * omega
    weight = np.ones(len(omega))
    scale = np.max(omega)  # work in s / scale for conditioning
    z = s / scale
    p = q = None
    for _ in range(iterations):
        cols = [z**k for k in range(1, n)]  # P's unknowns
        cols += [-K * z**k for k in range(n)]  # Q's unknowns
        M = np.stack(cols, axis=1) * weight[:, None]
        rhs = K * z**n * weight
        Mr = np.vstack([M.real, M.imag])
        rr = np.concatenate([rhs.real, rhs.imag])
        sol, *_ = np.linalg.lstsq(Mr, rr, rcond=None)
        p, q = sol[: n - 1], sol[n - 1:]
        Q = z**n + sum(q[k] * z**k for k in range(n))
        new = 1.0 / np.maximum(np.abs(Q), 1e-12)
        if np.allclose(new, weight, rtol=1e-6):
            break
        weight = new
    return p, q, scale


def _realise(p, q, scale, n) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """State space of P(z)/Q(z), z = s / scale, with unstable poles reflected."""
    # polynomial coefficients in z, highest power first
    Qz = np.concatenate([[1.0], q[::-1]])
    roots = np.roots(Qz)
    roots = np.where(roots.real > 0, -roots.real + 1j * roots.imag, roots)
    roots = np.where(np.abs(roots.real) < 1e-9, roots - 1e-6, roots)
    Qz = np.real(np.poly(roots))
    # in s: z = s/scale -> Q(s) = Qz(s/scale) * scale^n; P likewise
    qs = Qz[1:][::-1] * scale ** (n - np.arange(n))  # q_k (s^k), monic
    ps = np.zeros(n)
    for k in range(1, n):
        ps[k] = p[k - 1] * scale ** (n - k)  # P(s)/Q(s) = (sum p_k z^k)/(...) scaled to monic s^n
    A = np.zeros((n, n))
    A[:-1, 1:] = np.eye(n - 1)
    A[-1, :] = -qs
    b = np.zeros(n)
    b[-1] = 1.0
    return A, b, ps


def fit_radiation_ss(omega, a66, b66, a_inf: float, *, max_order: int = 10, tolerance: float = 0.05) -> RadiationSS:
    """The smallest-order stable realisation with relative fit error below ``tolerance``
    (or the best up to ``max_order``). ``omega`` rad/s, A66 kg m^2, B66 N m s."""
    omega = np.asarray(omega, dtype=float)
    K = kernel_transform(omega, a66, np.maximum(np.asarray(b66, dtype=float), 0.0), a_inf)
    norm = np.linalg.norm(K)
    best = None
    for n in range(2, max_order + 1):
        p, q, scale = _fit_order(omega, K, n)
        A, b, c = _realise(p, q, scale, n)
        ss = RadiationSS(A, b, c, n, 0.0)
        err = float(np.linalg.norm(ss.response(omega) - K) / norm)
        ss = dataclasses.replace(ss, fit_error=err)
        if best is None or err < best.fit_error:
            best = ss
        if err < tolerance:
            return ss
    return best
