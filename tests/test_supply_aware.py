"""supply-aware (agents/supply_aware.py): its pre-spin keeps the voltage the planned stroke asks for,
``R i(t) + k_t Omega(t)``, within the supply where the symmetric pre-spin of feedforward-pd would not;
the flywheel rate is integrated here independently of the module (explicit Euler on ``J_f Omega' = k_t i``)."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from addedinertia_env.experiment.reference import MirroredReference
from agents import make_controller
from agents.supply_aware import plan_prespin, stroke_plan

K_T, R, J_F, J, C = 0.5, 0.5, 0.05, 1.0, 0.0  # N m/A at the flywheel, Ohm, kg m^2, kg m^2, N m/rad
W = 2.0 * math.pi / 4.0  # rad/s: a 4 s oscillation


def _context(u_max: float, t_stop: float = 3.0):
    """A stroke that swings the flywheel one way, then back past its start: phi = 0.1 cos(W t), 0..t_stop s."""
    law = SimpleNamespace(t_start=0.0, t_stop=t_stop, duration=t_stop, phi=lambda s: 0.1 * np.cos(W * s),
                          accel=lambda s: -0.1 * W**2 * np.cos(W * s), rate=lambda s: -0.1 * W * np.sin(W * s))
    rig = SimpleNamespace(u_max=u_max, R=R, c_torsion=C, phi_neutral=0.0, J_flywheel=J_F, current_limit=15.0)
    return SimpleNamespace(rig=rig, reference=MirroredReference(law=law, t_begin=5.0), i_max=15.0, k_t=K_T)


def _peak_voltage(ctx, omega0: float, n: int = 20000) -> float:
    """Peak |R i + k_t Omega| over the reverse stroke, the reference read as the controller reads it (the
    task's MirroredReference, in the stroke's own time) and the flywheel integrated by explicit Euler."""
    ref = ctx.reference
    t = np.linspace(ref.t_begin, ref.t_end, n)
    i = -2.0 * (J * ref.accel(t) + C * ref.phi(t)) / K_T
    omega = omega0 + np.concatenate([[0.0], np.cumsum(K_T * i[:-1] * np.diff(t) / J_F)])
    return float(max(abs(K_T * omega0), np.max(np.abs(R * i + K_T * omega))))


def _symmetric(ctx) -> float:
    """feedforward-pd's pre-spin: the flywheel ends the stroke at minus its start rate."""
    i, h = stroke_plan(ctx, J)
    return -h[-1] / 2.0


def test_the_plan_stays_within_a_weak_supply_where_the_symmetric_prespin_does_not():
    ctx = _context(u_max=4.0)
    sym = _symmetric(ctx)
    assert _peak_voltage(ctx, sym) > 4.0  # the plain pre-spin runs out of voltage on this supply
    i, h = stroke_plan(ctx, J)
    omega0 = plan_prespin(i, h, R, K_T, 0.85 * 4.0, sym)
    assert _peak_voltage(ctx, omega0) <= 0.85 * 4.0 * 1.01
    assert abs(omega0 - sym) > 0.5  # it moved the pre-spin, not the loop


def test_on_a_wide_supply_the_plan_is_feedforward_pds_prespin():
    ctx = _context(u_max=48.0)
    sym = _symmetric(ctx)
    i, h = stroke_plan(ctx, J)
    assert plan_prespin(i, h, R, K_T, 0.85 * 48.0, sym) == pytest.approx(sym)


def test_where_no_prespin_fits_it_takes_the_one_with_the_least_peak_voltage():
    ctx = _context(u_max=2.0)
    i, h = stroke_plan(ctx, J)
    omega0 = plan_prespin(i, h, R, K_T, 0.85 * 2.0, _symmetric(ctx))
    best = _peak_voltage(ctx, omega0)
    assert best > 0.85 * 2.0  # no pre-spin fits here
    for other in np.linspace(-20.0, 20.0, 81):
        assert best <= _peak_voltage(ctx, other) + 0.02, other
    assert best < _peak_voltage(ctx, 0.0) and best < _peak_voltage(ctx, _symmetric(ctx))


@pytest.mark.parametrize("kw, words", [({"margin": 1.5}, "margin = 1.5"), ({"margin": 0.0}, "margin = 0.0"),
                                       ({"prespin_fraction": -1.0}, "prespin_fraction = -1.0"),
                                       ({"prespin_fraction": float("nan")}, "prespin_fraction = nan")])
def test_a_bad_parameter_is_refused_by_name(kw, words):
    with pytest.raises(ValueError) as err:
        make_controller("supply-aware", tuned=False, **kw)
    assert words in str(err.value) and "supply-aware" in str(err.value)


def test_an_unknown_parameter_is_refused():
    with pytest.raises(TypeError, match="headroom"):
        make_controller("supply-aware", tuned=False, headroom=0.9)
