"""The radiation memory the simulator integrates: a passive state-space fit of Cummins' kernel.

:mod:`.radiation_ss` fits ``Kh(j omega) = B66 + j omega (A66 - A66(inf))`` by the smallest
order whose *overall* relative error is under 5 %. That error is dominated by the wave
radiation peak (5 to 15 rad/s), so such a fit can be wrong where the rig lives (0.5 to
3 rad/s) and can radiate negative energy (order 3 on wigley-2m: A66(0) 9 % low,
``Re Kh < 0`` near 2.7 rad/s). A simulator needs more, and this module adds it:

* **exact where the experiment lives**: ``Kh(0) = 0`` (no static memory moment),
  ``Kh'(0) = A66(0) - A66(inf)`` (the zero-frequency added inertia) and
  ``Im Kh(j w_s) / w_s = A66(w_s) - A66(inf)`` at the swing frequency ``w_s``, all as
  equality constraints (linear in the residues);
* **passive**: ``Re Kh(j omega) >= 0`` on a dense logarithmic grid, with the two asymptotic
  conditions (``Kh''(0) <= 0``: B66 grows from zero as ``omega^2`` or faster; ``K'(0) <= 0``:
  B66 falls as ``omega^-2`` or faster at high frequency), and a storage function
  (Kalman-Yakubovich-Popov, :func:`storage_matrix`) that certifies it;
* poles by Sanathanan-Koerner (:func:`.radiation_ss._fit_order`), then moved by a small
  Nelder-Mead search with the residues refitted (constrained least squares) at every trial:
  variable projection. The order is the smallest whose relative error over the sweep is
  below ``tolerance``.

The realisation is block diagonal (one block per real pole or complex pair) with
``b`` the unit input of each block: ``x' = A x + b w``, ``mu = c . x + d w`` (N m) for the
hull rate ``w`` (rad/s), ``d`` a feedthrough of rounding size that makes it strictly passive; the model is stored *normalised* to ``A66(0) = 1`` so that the
simulator scales it by the hull's own lambda66 (:mod:`addedinertia_env.hydro.radiation`).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from addedinertia_env.hydro.radiation_ss import _fit_order, kernel_transform

FORMAT = "addedinertia-memory-model/1"
PASSIVITY_GRID = (1e-2, 1e3, 400)  # rad/s: from, to, points (log spaced)


def _basis(poles, s) -> tuple[np.ndarray, list[tuple]]:
    """Columns of Kh(s) for the real coefficients, one or two per pole; and their kinds."""
    cols, kinds = [], []
    for p in poles:
        if abs(p.imag) < 1e-9:
            cols.append(1.0 / (s - p.real))
            kinds.append(("real", p.real))
        elif p.imag > 0:
            m, sig = abs(p) ** 2, p.real
            den = s * s - 2.0 * sig * s + m
            cols += [s / den, 1.0 / den]
            kinds += [("s", sig, m), ("1", sig, m)]
    return np.stack(cols, axis=-1), kinds


def _at_zero(kinds) -> np.ndarray:
    """Rows: Kh(0), Kh'(0), Kh''(0), K(t=0), K'(t=0) of each basis function."""
    out = []
    for k in kinds:
        if k[0] == "real":
            p = k[1]
            out.append((-1.0 / p, -1.0 / p**2, -2.0 / p**3, 1.0, p))
            continue
        sig, m = k[1], k[2]
        d0, d1, d2 = m, -2.0 * sig, 2.0  # den(0), den'(0), den''(0)
        n0, n1 = (0.0, 1.0) if k[0] == "s" else (1.0, 0.0)
        f0 = n0 / d0
        f1 = (n1 - f0 * d1) / d0
        f2 = (-2.0 * f1 * d1 - f0 * d2) / d0
        k0, k1 = (1.0, 2.0 * sig) if k[0] == "s" else (0.0, 1.0)
        out.append((f0, f1, f2, k0, k1))
    return np.array(out).T


def _residues(poles, omega, K, targets, grid):
    """Constrained least-squares coefficients for fixed poles: (theta, relative error, ok)."""
    from scipy.optimize import minimize  # noqa: PLC0415

    a0_minus_inf, ws, as_minus_inf = targets
    Phi, kinds = _basis(poles, 1j * omega)
    Pg, _ = _basis(poles, 1j * grid)
    Ps, _ = _basis(poles, np.array([1j * ws]))
    D = _at_zero(kinds)
    M = np.vstack([Phi.real, Phi.imag])
    y = np.concatenate([K.real, K.imag])
    yy = float(y @ y)
    cons = [{"type": "eq", "fun": lambda th: np.array([D[0] @ th, D[1] @ th - a0_minus_inf,
                                                        (Ps[0] @ th).imag / ws - as_minus_inf])},
            {"type": "ineq", "fun": lambda th: np.concatenate([(Pg @ th).real, [-D[2] @ th, -D[4] @ th]])}]
    th0, *_ = np.linalg.lstsq(M, y, rcond=None)
    res = minimize(lambda th: float(np.sum((M @ th - y) ** 2)) / yy, th0,
                   jac=lambda th: 2.0 * M.T @ (M @ th - y) / yy, constraints=cons, method="SLSQP",
                   options={"maxiter": 300, "ftol": 1e-12})
    err = float(np.linalg.norm(Phi @ res.x - K) / np.linalg.norm(K))
    ok = bool(res.success) and float(np.min((Pg @ res.x).real)) >= -1e-9 * float(np.max(np.abs(K)))
    return res.x, err, ok, kinds


def _pack(poles) -> np.ndarray:
    v = []
    for p in poles:
        if abs(p.imag) < 1e-9:
            v.append(math.log(-p.real))
        elif p.imag > 0:
            v += [math.log(-p.real), math.log(p.imag)]
    return np.array(v)


def _unpack(v, shape) -> np.ndarray:
    out, i = [], 0
    for kind in shape:
        if kind == "real":
            out.append(complex(-math.exp(v[i]), 0.0))
            i += 1
        else:
            z = complex(-math.exp(v[i]), math.exp(v[i + 1]))
            out += [z, z.conjugate()]
            i += 2
    return np.array(out)


def _realise(poles, theta, kinds) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Block-diagonal (A, b, c) of sum(theta_k basis_k)."""
    n = len(kinds)
    A, b, c = np.zeros((n, n)), np.zeros(n), np.zeros(n)
    k = 0
    while k < n:
        kind = kinds[k]
        if kind[0] == "real":
            A[k, k], b[k], c[k] = kind[1], 1.0, theta[k]
            k += 1
            continue
        sig, m = kind[1], kind[2]  # (theta_s s + theta_1) / (s^2 - 2 sig s + m), controllable form
        A[k, k + 1] = 1.0
        A[k + 1, k], A[k + 1, k + 1] = -m, 2.0 * sig
        b[k + 1] = 1.0
        c[k], c[k + 1] = theta[k + 1], theta[k]
        k += 2
    return A, b, c


def storage_matrix(A, b, c, eps: float | None = None) -> np.ndarray:
    """P of a storage function ``S = 1/2 x' P x`` (Kalman-Yakubovich-Popov) of ``c (sI - A)^-1 b``.

    Solved as the Riccati equation of ``H(s) + eps`` (``eps`` a tiny feedthrough,
    default 1e-9 of ``K(0)`` times a second): ``A'P + PA + (Pb - c')(2 eps)^-1 (b'P - c) = 0``;
    as ``eps -> 0``, ``Pb -> c'`` and ``A'P + PA <= 0``. Raises ValueError when the system is not
    passive (no positive definite solution).
    """
    from scipy.linalg import solve_continuous_are  # noqa: PLC0415

    A, b, c = np.asarray(A, float), np.asarray(b, float).reshape(-1, 1), np.asarray(c, float).reshape(1, -1)
    if eps is None:
        eps = 1e-9 * abs(float((c @ b).item()))
    X = solve_continuous_are(A, b, np.zeros_like(A), np.array([[2.0 * eps]]), s=c.T)
    P = -0.5 * (X + X.T)
    if np.min(np.linalg.eigvalsh(P)) <= 0:
        raise ValueError("the memory model is not passive: its storage function is not positive definite")
    return P


def fit_memory_model(omega, a66, b66, a_zero: float, a_inf: float, swing_omega: float, a_swing: float, *,
                     tolerance: float = 0.05, max_order: int = 6, max_evaluations: int = 400) -> dict[str, Any]:
    """The simulator's memory model from a BEM sweep, JSON-ready (normalised to A66(0) = 1).

    ``omega`` rad/s; ``a66`` kg m^2; ``b66`` N m s; ``a_zero``, ``a_inf``, ``a_swing``: A66 at
    zero, infinite and the swing frequency ``swing_omega`` (kg m^2). Returns the block the
    BEM cache stores under ``memory_model`` (see the module docstring).
    """
    from scipy.optimize import minimize  # noqa: PLC0415

    omega = np.asarray(omega, dtype=float)
    K = kernel_transform(omega, a66, np.maximum(np.asarray(b66, dtype=float), 0.0), a_inf)
    grid = np.geomspace(*PASSIVITY_GRID[:2], PASSIVITY_GRID[2])
    targets = (a_zero - a_inf, swing_omega, a_swing - a_inf)
    best = None
    for n in range(3, max_order + 1):
        p, q, scale = _fit_order(omega, K, n)
        poles = np.roots(np.concatenate([[1.0], q[::-1]])) * scale
        poles = np.where(poles.real > 0, -poles.real + 1j * poles.imag, poles)
        poles = np.where(np.abs(poles.real) < 1e-3, poles - 1e-3, poles)
        shape = ["real" if abs(z.imag) < 1e-9 else "pair" for z in poles if z.imag >= -1e-9]

        def error(v):
            _, err, ok, _ = _residues(_unpack(v, shape), omega, K, targets, grid)
            return err if ok else 10.0 + err

        search = minimize(error, _pack(poles), method="Nelder-Mead",
                          options={"maxfev": max_evaluations, "xatol": 1e-4, "fatol": 1e-7})
        poles = _unpack(search.x, shape)
        theta, err, ok, kinds = _residues(poles, omega, K, targets, grid)
        if not ok:
            continue
        cand = (n, err, poles, theta, kinds)
        if best is None or err < best[1]:
            best = cand
        if err < tolerance:
            break
    if best is None:
        raise ValueError("no passive state-space fit of the radiation memory was found up to order "
                         f"{max_order}; check the sweep (B66 >= 0, A66(inf) below A66(0))")
    n, err, poles, theta, kinds = best
    A, b, c = _realise(poles, theta, kinds)
    # The grid constraint leaves at most rounding-sized dips of Re Kh between its points; a
    # feedthrough d (a damping of ~1e-6 N m s, nothing physically) makes the model strictly
    # passive, and the storage function is then that of the model itself (no regularisation).
    dense = np.geomspace(1e-3, 1e4, 4000)
    H = np.array([c @ np.linalg.solve(1j * w * np.eye(n) - A, b) for w in dense])
    d = max(1e-9 * abs(float(c @ b)), -1.01 * float(np.min(H.real)))
    P = storage_matrix(A, b, c, eps=d)
    return {
        "format": FORMAT,
        "normalised_to": "A66(0) = 1: the simulator multiplies c and A66(inf) by the hull's lambda66 (kg m^2)",
        "order": int(n), "fit_error": float(err), "tolerance": float(tolerance),
        "A": A.tolist(), "b": b.tolist(), "c": (c / a_zero).tolist(), "d": d / a_zero, "P": (P / a_zero).tolist(),
        "a_inf_ratio": float(a_inf / a_zero), "a_swing_ratio": float(a_swing / a_zero),
        "swing_omega": float(swing_omega),
        "bem": {"A66_zero": float(a_zero), "A66_inf": float(a_inf), "A66_swing": float(a_swing)},
        "poles": [{"re": float(z.real), "im": float(z.imag)} for z in np.linalg.eigvals(A)],
        "K0_ratio": float(c @ b / a_zero), "min_B_on_grid": float(np.min(H.real) + d),
        "units": {"A": "1/s", "b": "-", "c": "1/s^2 per kg m^2 of A66(0) (mu = lambda66 (c.x + d w), N m; x in rad)",
                  "d": "1/s per kg m^2 of A66(0) (a feedthrough of ~1e-7: strict passivity)",
                  "P": "1/s^2 per kg m^2 of A66(0) (stored energy lambda66 x'Px/2, J)"},
        "how": "Kh(j w) = B66 + j w (A66 - A66(inf)) fitted with Kh(0) = 0, Kh'(0) = A66(0) - A66(inf) and "
               "A66(swing) exact, Re Kh >= 0 on 0.01..1000 rad/s; poles by Sanathanan-Koerner then Nelder-Mead "
               "(variable projection); smallest order with relative error < tolerance",
    }


def memory_model_from_cache(data: dict[str, Any]) -> dict[str, Any]:
    """:func:`fit_memory_model` on a BEM cache's fine sweep (floating hull, ``addedinertia hull --write-cache``)."""
    fine = data["resolutions"]["fine"]
    dep = fine.get("at_depth_omega") or {}
    swing = float(dep.get("omega") or data["swing_omega"])
    a_swing = dep.get("A66_deep_water")
    if a_swing is None:
        a_swing = float(np.interp(swing, fine["omega"], fine["A66"]))
    return fit_memory_model(fine["omega"], fine["A66"], fine["B66"], fine["zero_frequency"]["A66"],
                            fine["infinite_frequency"]["A66"], swing, float(a_swing))
