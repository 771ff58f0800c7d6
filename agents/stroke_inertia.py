"""The hull's inertia from the whole free stroke: the least-squares undamped fit of the recorded law.

The task's prior (``ControllerContext.inertia_prior``, ``StrokeLaw.inertia_prior``) reads the inertia at
the stroke's stop, ``J = -c (phi_2 - phi_n) / f''(t_2)``, where rate-dependent damping vanishes but dry
friction does not: a geared drive's drag and cogging, reflected to the hull by the ratio, bias it. On
drive-v2's 32 train seeds it reads 0.75-2.27 times the true ``J_hull + lambda66`` (docs/DRIVE.md
"drive-v3 and smith-pd"); where it reads twice too much, the loop's gains and the feed-forward are
twice too large, and every observer-based entry drives the stroke into the current limit.

Over the whole fitted stroke the hull obeys ``J f'' + c (f - phi_n) = Q(f')`` (``Q`` the damping). The
inertia that makes the stroke closest to an undamped one, the least-squares solution of
``J f'' + c (f - phi_n) = 0`` over the stroke::

    J_fit = -c  sum f''(t) (f(t) - phi_n)  /  sum f''(t)^2

is biased low by the damping (exact on an undamped oscillator, 0.6-1 of it with 5 % viscous damping:
tests/test_smith_pd.py), but it rests on every sample of the stroke rather than on the fitted law's last
one, where the fit is least constrained and a dry friction torque is largest against the spring's.
Measured on those 32 seeds it reads 0.71-0.96 times the truth. Sensor data and the known stiffness only; never the truth.
"""

from __future__ import annotations

import math

import numpy as np

from agents.base import ControllerContext


def stroke_fit_inertia(context: ControllerContext, n: int = 400) -> float:
    """``J_fit`` (kg m^2) over the recorded law's stroke (module doc); ValueError where the law gives none."""
    law, rig = context.reference.law, context.rig
    s = np.linspace(law.t_start, law.t_stop, n)
    a = np.asarray(law.accel(s), float)
    phi = np.asarray(law.phi(s), float) - rig.phi_neutral
    den = float(np.sum(a * a))
    J = -rig.c_torsion * float(np.sum(a * phi)) / den if den > 0 else math.nan
    if not (math.isfinite(J) and J > 0):
        raise ValueError(f"stroke_fit_inertia: the free stroke's law gives J = {J!r} kg m^2 (c = {rig.c_torsion} N m/rad); "
                         "expected a positive inertia: the stroke must decelerate towards its stop")
    return J
