"""The mirrored reference of many environments at once (:mod:`~addedinertia_env.experiment.reference` on arrays).

Each environment's fitted stroke law (a :class:`~addedinertia_env.experiment.reference.StrokeLaw`
from :func:`~addedinertia_env.experiment.reference.fit_stroke`, the single experiment's own
fit) is stored as a column of coefficient arrays; the series are evaluated by the same
Clenshaw recursion, in the same order of operations, as ``numpy.polynomial.chebyshev.chebval``,
so each column equals the scalar :class:`MirroredReference` bit for bit.
"""

from __future__ import annotations

import numpy as np

from ..experiment.reference import DEFAULT_DEGREE, StrokeLaw


def clenshaw(c: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Chebyshev series with per-column coefficients ``c`` (terms x envs) at ``x`` (envs)."""
    if len(c) == 1:
        return c[0] + 0 * x
    if len(c) == 2:
        return c[0] + c[1] * x
    x2 = 2 * x
    c0 = c[-2]
    c1 = c[-1]
    for i in range(3, len(c) + 1):
        tmp = c0
        c0 = c[-i] - c1
        c1 = tmp + c1 * x2
    return c0 + c1 * x


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

    def _x(self, t: np.ndarray, sel) -> tuple[np.ndarray, np.ndarray]:
        """The law's mapped variable at the mirrored time of ``t``, and its scale 2 / (t_stop - t_start)."""
        t_begin, t_stop, t_start = self.t_begin[sel], self.t_stop[sel], self.t_start[sel]
        mirrored = t_stop - (np.minimum(np.maximum(t, t_begin), self.t_end[sel]) - t_begin)
        x = (2.0 * mirrored - (t_start + t_stop)) / (t_stop - t_start)
        return x, 2.0 / (t_stop - t_start)

    def phi(self, t: np.ndarray, sel=slice(None)) -> np.ndarray:
        """phi_ref(t), rad, of slots ``sel``."""
        x, _ = self._x(t, sel)
        return clenshaw(self.coef[:, sel], x)

    def phi_rate_accel(self, t: np.ndarray, sel=slice(None)):
        """phi_ref, its rate and acceleration at ``t`` (rad, rad/s, rad/s^2)."""
        x, scale = self._x(t, sel)
        phi = clenshaw(self.coef[:, sel], x)
        rate = -(clenshaw(self.d1[:, sel], x) * scale)
        accel = clenshaw(self.d2[:, sel], x) * scale**2
        return phi, rate, accel
