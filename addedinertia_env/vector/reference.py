"""The mirrored reference of many environments at once (:mod:`~addedinertia_env.experiment.reference` on arrays).

Each environment's fitted stroke law (a :class:`~addedinertia_env.experiment.reference.StrokeLaw`
from :func:`~addedinertia_env.experiment.reference.fit_stroke`, the single experiment's own
fit) is stored as a column of coefficient arrays; the series are evaluated by the same
Clenshaw recursion, in the same order of operations, as ``numpy.polynomial.chebyshev.chebval``,
so each column equals the scalar :class:`MirroredReference` bit for bit. A slot's reference at
one time is :func:`reference_one` (the mirrored time mapped onto the law's interval, and
:func:`~addedinertia_env.experiment.stroke_kernels.clenshaw_one`, the same operations in the
same order, no gathers of coefficient columns), called from the compiled loops of the
observation (:mod:`.observe`) and of :meth:`MirroredReferences.tabulate`.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from addedinertia_env.experiment.reference import DEFAULT_DEGREE, StrokeLaw
from addedinertia_env.experiment.stroke_kernels import clenshaw_one


@njit(cache=True, inline="always")
def reference_one(t, k, coef, d1, d2, t_start, t_stop, t_begin, t_end, derivatives):  # pragma: no cover - compiled
    """phi_ref (rad) of slot ``k`` at ``t`` (s), and with ``derivatives`` its rate (rad/s) and
    acceleration (rad/s^2) (else 0.0 for both): the scalar :class:`MirroredReference` of the slot."""
    tb, ts, t0 = t_begin[k], t_stop[k], t_start[k]
    mirrored = ts - (min(max(t, tb), t_end[k]) - tb)
    x = (2.0 * mirrored - (t0 + ts)) / (ts - t0)
    phi = clenshaw_one(coef, k, x)
    if not derivatives:
        return phi, 0.0, 0.0
    scale = 2.0 / (ts - t0)
    return phi, -(clenshaw_one(d1, k, x) * scale), clenshaw_one(d2, k, x) * scale**2


@njit(cache=True)
def tabulate_one(t, k, after, until, coef, d1, d2, t_start, t_stop, t_begin, t_end, row):  # pragma: no cover - compiled
    """Slot ``k``'s phi_ref (rad) at the times ``t[a:b]`` (s) into ``row[:b - a]``, where ``a`` and ``b - 1``
    are the first and last index with ``after < t <= until``; returns ``(a, b)``, ``(0, 0)`` when no
    time qualifies, and writes nothing when ``row`` is shorter than ``b - a`` (the caller grows it)."""
    a, b = -1, -1
    for j in range(len(t)):
        if after < t[j] and t[j] <= until:
            if a < 0:
                a = j
            b = j + 1
    if a < 0:
        return 0, 0
    if b - a <= len(row):
        for j in range(a, b):
            row[j - a] = reference_one(t[j], k, coef, d1, d2, t_start, t_stop, t_begin, t_end, False)[0]
    return a, b


class MirroredReferences:
    """The reverse-stroke references of ``n`` slots; a slot is set by :meth:`set` once its free stroke is fitted."""

    def __init__(self, n: int, degree: int = DEFAULT_DEGREE):
        self.coef = np.zeros((degree + 1, n))
        self.d1 = np.zeros((degree, n))
        self.d2 = np.zeros((degree - 1, n))
        self.t_start = np.zeros(n)
        self.t_stop = np.ones(n)
        self.t_begin = np.zeros(n)  # s, start of the reverse stroke (end of the hold)
        self.t_end = np.zeros(n)
        self.duration = np.ones(n)

    def set(self, k: int, law: StrokeLaw, t_begin: float) -> None:
        """Store slot ``k``'s stroke law and the time its mirrored reverse stroke begins, ``t_begin`` (s); ValueError for a law of another degree than the batch's."""
        if len(law.coef) != len(self.coef):
            raise ValueError(f"stroke law of degree {len(law.coef) - 1}; this batch holds degree {len(self.coef) - 1}")
        self.coef[:, k] = law.coef
        self.d1[:, k] = law._d1
        self.d2[:, k] = law._d2
        self.t_start[k], self.t_stop[k] = law.t_start, law.t_stop
        self.duration[k] = law.duration
        self.t_begin[k] = t_begin
        self.t_end[k] = t_begin + law.duration

    def tabulate(self, k: int, t: np.ndarray, until: float, row: np.ndarray) -> tuple[int, int]:
        """Slot ``k``'s phi_ref (rad) at the times ``t`` (s) after its ``t_begin`` and up to ``until``
        (s) into ``row`` (:func:`tabulate_one`): returns ``(a, b)``, the span of ``t`` tabulated."""
        return tabulate_one(t, k, self.t_begin[k], until, self.coef, self.d1, self.d2, self.t_start, self.t_stop,
                            self.t_begin, self.t_end, row)
