"""The one Runge-Kutta integrator of the project's own models (MuJoCo integrates its model itself).

:func:`rk4_step` is the classic four-stage method on a state given as a tuple of arrays
(or floats); the batched rig (:mod:`.batched`) and the discovery model's hull
(:mod:`addedinertia_env.discover.model`) both step with it.
"""

from __future__ import annotations


def rk4_step(f, z, h, *args, inputs=None):
    """One classic four-stage Runge-Kutta step of ``z' = f(z, *args)`` over ``h`` (s).

    ``z`` and the value of ``f`` are tuples of equal length (arrays or floats); the
    arguments are held over the step. ``inputs``: an input that varies over the step, as
    its values (at the start, at the half step, at the end); it is passed to ``f`` as its
    last argument (the first stage sees the start value, the middle two the half-step
    value, the last the end value). Returns the new state tuple.
    """
    if inputs is None:
        u0 = um = u1 = ()
    else:
        u0, um, u1 = ((u,) for u in inputs)
    k1 = f(z, *args, *u0)
    k2 = f(tuple(a + 0.5 * h * b for a, b in zip(z, k1)), *args, *um)
    k3 = f(tuple(a + 0.5 * h * b for a, b in zip(z, k2)), *args, *um)
    k4 = f(tuple(a + h * b for a, b in zip(z, k3)), *args, *u1)
    return tuple(a + h / 6.0 * (b1 + 2.0 * b2 + 2.0 * b3 + b4) for a, b1, b2, b3, b4 in zip(z, k1, k2, k3, k4))
