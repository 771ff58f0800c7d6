"""Radiation memory (the ``cummins`` hydrodynamic model): the fit, the config, the engines, the energy.

Physics checked against physics: the fit is passive (Re Kh >= 0) and exact at zero and at the
swing frequency; the simulated swing period is the root of the Cummins equation
``c = w^2 (J_h + A66(w))``; mechanical energy + work into the water is conserved and the
water's radiated energy (work in minus stored) never decreases; the MuJoCo and the batched
engines agree. Every model comes from the shipped BEM caches (no BEM solve).
"""

from __future__ import annotations

import dataclasses
import json
import math
import shutil

import numpy as np
import pytest

from addedinertia_env.foundation.config_io import ConfigError
from addedinertia_env.sim import forces
from addedinertia_env.sim.batched import BatchedRig
from addedinertia_env.sim.batched_single import BatchedSingleRig
from addedinertia_env.sim.motor import MotorCommand
from addedinertia_env.sim.mujoco_rig import MujocoRig
from addedinertia_env.sim.params import SensorParams
from addedinertia_env.sim.presets import RIG_DIR, load_rig

PRESETS = ("wigley-2m", "spheroid-7")
PASSIVE = MotorCommand("passive")


def memory_rig(preset: str = "wigley-2m", lossless: bool = False):
    p = load_rig(preset, sensors=SensorParams.ideal(), hydrodynamics="cummins")
    if lossless:  # no viscous damping, no rotor friction: only the water's radiation can take energy
        p = p.replace(hull=dataclasses.replace(p.hull, b1=0.0, b2=0.0),
                      motor=dataclasses.replace(p.motor, friction_viscous=0.0, friction_coulomb=0.0))
    return p


def run(rig, seconds: float, command=lambda t: PASSIVE, phi0: float = -0.1):
    rig.reset(phi0=phi0, brake=False)
    states = [rig.true_state()]
    for k in range(int(round(seconds / rig.dt))):
        rig.step(command(k * rig.dt))
        states.append(rig.true_state())
    return states


# --- the fit -----------------------------------------------------------------------------

@pytest.mark.parametrize("preset", PRESETS)
def test_cached_fit_is_passive_and_exact_where_the_rig_swings(preset):
    p = memory_rig(preset)
    m = p.hydrodynamics
    cache = json.loads((RIG_DIR / f"{preset}.bem.json").read_text())
    fine = cache["resolutions"]["fine"]
    grid = np.geomspace(1e-3, 1e4, 3000)
    B = m.transfer(grid).real
    # passivity: Re Kh >= 0 everywhere (a negative value would let the water feed the hull)
    assert B.min() >= -1e-9 * np.abs(B).max(), B.min()
    # zero frequency: A66(w)/A66(0) -> 1; swing frequency: the BEM's own ratio
    assert abs(m.added_inertia_ratio(1e-3)[0] - 1.0) < 1e-5
    dep = fine["at_depth_omega"]
    ratio_bem = dep["A66_deep_water"] / fine["zero_frequency"]["A66"]
    assert abs(m.added_inertia_ratio(dep["omega"])[0] - ratio_bem) < 1e-6
    assert abs(m.a_inf_ratio - fine["infinite_frequency"]["A66"] / fine["zero_frequency"]["A66"]) < 1e-12
    # overall fit error against the whole sweep (what chose the order)
    K = np.asarray(fine["B66"]).clip(0) + 1j * np.asarray(fine["omega"]) * (
        np.asarray(fine["A66"]) - fine["infinite_frequency"]["A66"])
    err = np.linalg.norm(m.transfer(fine["omega"]) * fine["zero_frequency"]["A66"] - K) / np.linalg.norm(K)
    assert err < 0.05 and abs(err - m.fit_error) < 1e-6  # (the stored error is before the 1e-7 feedthrough)
    # the storage function certifies passivity: P > 0, A'P + PA <= 0 (to the fit's tiny feedthrough)
    A, P = np.asarray(m.A), np.asarray(m.P)
    assert np.linalg.eigvalsh(P).min() > 0
    assert np.linalg.eigvalsh(A.T @ P + P @ A).max() < 1e-3 * np.abs(np.linalg.eigvalsh(A.T @ P + P @ A)).max()


def test_fit_recovers_a_known_passive_kernel():
    from addedinertia_env.hydro.memory_fit import fit_memory_model

    # a two-pair passive kernel with known A66(w) (Re >= 0: each pair is k s / (s^2 + 2 z s + m)):
    # the fit must recover it at order 4, passive, exact at zero and at the swing frequency
    def kernel(s):
        return 40.0 * s / (s * s + 4.0 * s + 50.0) + 300.0 * s / (s * s + 10.0 * s + 200.0)

    w = np.geomspace(0.2, 40, 45)
    H = kernel(1j * w)
    a_inf = 5.0
    a_zero = a_inf + 40.0 / 50.0 + 300.0 / 200.0
    a_swing = a_inf + float(kernel(1.5j).imag) / 1.5
    block = fit_memory_model(w, a_inf + H.imag / w, H.real, a_zero, a_inf, 1.5, a_swing, tolerance=1e-3)
    assert block["order"] == 4 and block["fit_error"] < 1e-3, block["fit_error"]
    assert block["min_B_on_grid"] >= 0 and all(z["re"] < 0 for z in block["poles"])
    assert block["a_swing_ratio"] == pytest.approx(a_swing / a_zero, rel=1e-12)


# --- the config ----------------------------------------------------------------------------

def _preset_copy(tmp_path, preset: str = "wigley-2m", cache: dict | None = None, hydro: str = ""):
    text = (RIG_DIR / f"{preset}.yaml").read_text() + hydro
    (tmp_path / f"{preset}.yaml").write_text(text)
    data = json.loads((RIG_DIR / f"{preset}.bem.json").read_text())
    if cache is not None:
        data.update(cache)
    (tmp_path / f"{preset}.bem.json").write_text(json.dumps(data))
    return tmp_path / f"{preset}.yaml"


def test_preset_block_turns_memory_on_and_constant_is_the_default(tmp_path):
    assert load_rig("wigley-2m").hydrodynamics is None  # the default: constant added inertia
    path = _preset_copy(tmp_path, hydro="hydrodynamics: {model: cummins, source: bem-cache}\n")
    p = load_rig(str(path))
    assert p.hydrodynamics is not None and p.hydrodynamics.order >= 2
    assert forces.hull_armature(p) == pytest.approx(p.hull.lambda66 * p.hydrodynamics.a_inf_ratio)
    assert load_rig(str(path), hydrodynamics="constant").hydrodynamics is None  # an override wins


@pytest.mark.parametrize("hydro, words", [
    ("hydrodynamics: {model: potential}\n", ["hydrodynamics.model", "'potential'", "constant, cummins"]),
    ("hydrodynamics: {model: cummins, source: strip}\n", ["hydrodynamics.source", "'strip'", "bem-cache"]),
    ("hydrodynamics: {model: cummins, order: 3}\n", ["hydrodynamics", "unknown key", "order"]),
    ("hydrodynamics: {model: constant, source: bem-cache}\n", ["'source'", "'cummins' only"]),
])
def test_bad_hydrodynamics_block_is_named(tmp_path, hydro, words):
    path = _preset_copy(tmp_path, hydro=hydro)
    with pytest.raises(ConfigError) as err:
        load_rig(str(path))
    msg = str(err.value)
    assert str(path) in msg and all(w in msg for w in words), msg


def test_cache_without_the_fit_says_which_command_writes_it(tmp_path):
    path = _preset_copy(tmp_path, cache={"memory_model": None},
                        hydro="hydrodynamics: {model: cummins, source: bem-cache}\n")
    with pytest.raises(ConfigError) as err:
        load_rig(str(path))
    msg = str(err.value)
    assert "wigley-2m.bem.json" in msg and "memory_model" in msg and "--fit-memory" in msg, msg
    (tmp_path / "wigley-2m.bem.json").unlink()
    with pytest.raises(ConfigError, match="no BEM cache"):
        load_rig(str(path))


def test_batch_refuses_mixed_hydrodynamic_models():
    with pytest.raises(ValueError, match="hydrodynamic model differs"):
        BatchedRig([memory_rig(), load_rig("wigley-2m", sensors=SensorParams.ideal())])


# --- the engines and the physics -------------------------------------------------------------

def test_mujoco_and_batched_engines_agree_with_memory_on():
    p = memory_rig()
    drive = lambda t: MotorCommand("current", 4.0 * math.sin(2 * math.pi * 0.7 * t)) if t < 2.0 else PASSIVE  # noqa: E731
    a = run(MujocoRig(p, seed=0), 4.0, drive)
    b = run(BatchedSingleRig(p, seed=0), 4.0, drive)
    dphi = max(abs(x.phi - y["phi"]) for x, y in zip(a, b))
    dw = max(abs(x.w - y["w"]) for x, y in zip(a, b))
    dx = max(np.max(np.abs(np.subtract(x.radiation_state, y["radiation_state"]))) for x, y in zip(a, b))
    # same forces, same exact memory update, same RK4 (batched: as a linear map): rounding only
    assert dphi < 1e-9 and dw < 1e-9 and dx < 1e-9, (dphi, dw, dx)
    assert max(abs(x.radiation_torque) for x in a) > 0.1  # the memory did act (N m)


def test_swing_period_is_the_root_of_the_cummins_equation():
    p = memory_rig(lossless=True)
    s = run(MujocoRig(p, seed=0), 13.0)
    t, phi = np.array([x.t for x in s]), np.array([x.phi for x in s])
    k = np.nonzero(np.signbit(phi[:-1]) != np.signbit(phi[1:]))[0]
    crossings = t[k] - phi[k] * (t[k + 1] - t[k]) / (phi[k + 1] - phi[k])
    period = 2.0 * float(np.mean(np.diff(crossings)[2:]))  # after the release transient (poles decay in ~1 s)
    w_n = p.hydrodynamics.natural_frequency(p.hull.J_hull, p.hull.lambda66, p.spring.c)
    period_a0 = 2 * math.pi * math.sqrt((p.hull.J_hull + p.hull.lambda66) / p.spring.c)
    # the memory makes the water heavier at the swing (A66(w_n) > A66(0)): the period grows by
    # about half the relative inertia change, 0.5 x 0.2/17.5 ~ 0.6 %; the root predicts it to 1e-6
    assert abs(period / (2 * math.pi / w_n) - 1.0) < 1e-6
    assert period / period_a0 - 1.0 > 3e-3
    # the swing measures A66(w_n), which the truth block states beside lambda66 = A66(0)
    assert MujocoRig(p, seed=0).truth()["A66_swing"] == pytest.approx(p.spring.c / w_n**2 - p.hull.J_hull, rel=1e-12)


def test_energy_closes_with_the_water_stored_and_radiated():
    p = memory_rig(lossless=True)
    s = run(MujocoRig(p, seed=0), 8.0, lambda t: MotorCommand("current", 3.0) if 3.0 < t < 3.5 else PASSIVE)
    E = np.array([x.energy for x in s])
    W_in = np.array([x.radiation_work for x in s])  # work of the hull on the water (memory moment)
    A = np.array([x.motor_work for x in s])
    S = np.array([x.radiation_energy for x in s])  # energy the memory holds (storage function)
    # mechanics: T(A66(inf)) + spring changes by the motor's work minus the work into the water.
    # Held torques x exact displacements: rounding only (the release stores ~70 mJ, E0 = 0.22 J).
    assert np.max(np.abs(E - E[0] - A + W_in)) < 1e-9 * E[0]
    assert W_in.max() > 0.05 * E[0]
    # the water: work in = stored + radiated, radiated never decreases (passivity). The storage
    # function is exact to the fit's 1e-9 feedthrough: a step may show -1e-10 J.
    radiated = W_in - S
    assert np.min(np.diff(radiated)) > -1e-9
    assert 0.0 < radiated[-1] < W_in.max()
    assert np.all(S >= 0)


def test_report_renders_every_reference_and_verdict():
    from addedinertia_env.reports.radiation_memory import BEGIN, END, render

    refs_on = {"A66_zero": 10.0, "A66_swing": 10.2, "A66_inf": 5.0}
    runs = [{"alpha": 0.1, "hold": 5.0, "energy": 10.5, "failure": ""},
            {"alpha": 0.05, "hold": 0.5, "energy": float("nan"), "failure": "refused"}]
    cases = [{"preset": "wigley-2m", "seed": 1, "memory": True, "refs": refs_on, "runs": runs, "free_decay": 10.2,
              "discover": {"cause": "unexplained", "causes": [], "lambda66_nominal": 10.1, "best_candidate": None,
                           "best_delta_bic": None}},
             {"preset": "wigley-2m", "seed": 1, "memory": False, "refs": dict.fromkeys(refs_on, 10.0),
              "runs": [dict(r, energy=10.01) for r in runs], "free_decay": float("nan")}]
    text = render(cases, [1], 1.0, 1.0, [{"preset": "wigley-2m", "hold": 5.0, "fwd_mJ": -1.0, "rev_mJ": 1.2,
                                          "quasi_static_mJ": 1.0, "implied": 10.4, "A66_swing": 10.2}])
    assert text.startswith(BEGIN) and text.rstrip().endswith(END)
    assert "| wigley-2m | on | 1/2 | +5.000 % (max +5.000 %) | +2.941 % (max +2.941 %) | +110.000 %" in text
    assert "| wigley-2m | on | 1/1 | +2.000 % | +0.000 % | +104.000 % |" in text  # free decay
    assert "| wigley-2m | off | 0/1 | failed | failed | failed |" in text
    assert "| wigley-2m | 1 | on | unexplained | 10.1000 | -0.980 % | - |" in text
    assert "+1.961 %" in text  # implied lambda66 against A66(swing)


def test_simulate_command_writes_the_memory_truth(tmp_path, capsys):
    from addedinertia_env.cli import main
    from addedinertia_env.records.record import read_record

    assert main(["simulate", "--rig", "spheroid-7", "--hydrodynamics", "cummins", "--out", str(tmp_path),
                 "--kind", "free-decay", "--alpha", "0.05"]) == 0
    truth = read_record(tmp_path / "run-0000.csv").meta["truth"]
    hydro = truth["hydrodynamics"]
    assert hydro["model"] == "cummins" and hydro["source"] == "configs/rigs/spheroid-7.bem.json"
    # lambda66 is A66(0) (spec/run-record.md); A66(swing) and A66(inf) beside it
    assert hydro["A66_inf"] == truth["A66_inf"] < hydro["A66_zero"] == truth["lambda66"] < truth["A66_swing"]
    capsys.readouterr()
    # an unknown model: a one-line error naming it, exit 2
    assert main(["simulate", "--rig", "spheroid-7", "--hydrodynamics", "potential", "--out", str(tmp_path)]) == 2
    assert "potential" in capsys.readouterr().err


def test_batch_with_memory_scales_per_environment_and_pauses():
    # one model, three hulls of different lambda66 (the memory scales with each), mixed commands,
    # an environment paused half the time: every column must equal its own MuJoCo rig
    base = memory_rig("spheroid-7")
    rigs = [base.replace(hull=dataclasses.replace(base.hull, lambda66=lam)) for lam in (7.0, 4.0, 11.0)]
    mj = [MujocoRig(p, seed=k) for k, p in enumerate(rigs)]
    batch = BatchedRig(rigs, seed=list(range(3)))
    for r in mj:
        r.reset(phi0=-0.1, brake=False)
    batch.reset(phi0=-0.1, brake=False)
    worst = 0.0
    for k in range(1500):
        active = np.array([True, True, k % 2 == 0])
        cmds = [MotorCommand("current", 2.0 * math.sin(5.0 * k * 1e-3)), PASSIVE, PASSIVE]
        for r, c, on in zip(mj, cmds, active):
            if on:
                r.step(c)
        batch.step([1, 0, 0], [cmds[0].value, 0.0, 0.0], active=active)
        for j, r in enumerate(mj):
            worst = max(worst, abs(r.true_state().phi - batch.phi[j]), abs(r.true_state().w - batch.w[j]))
    assert worst < 1e-9, worst
    assert batch.true_state(2)["t"] == pytest.approx(0.75, abs=1e-9)  # the paused one ran half the samples


def test_two_rate_board_sim_carries_the_memory():
    from addedinertia_env.loop.board_loop import TwoRateSimRig

    p = memory_rig()
    board = TwoRateSimRig(MujocoRig(p, seed=0), host_rate_hz=100.0)
    plain = MujocoRig(p, seed=0)
    board.reset(phi0=-0.1, brake=False)
    plain.reset(phi0=-0.1, brake=False)
    for _ in range(800):
        a, b = board.step(PASSIVE), plain.step(PASSIVE)
    assert a.phi == b.phi  # the board's loop passes a passive command through: the same memory-on rig
    assert board.truth()["hydrodynamics"]["model"] == "cummins"
    assert abs(board.rig.true_state().radiation_torque) > 0.1


@pytest.mark.parametrize("preset", PRESETS)
def test_every_truth_writer_gives_lambda66_as_a66_zero(preset):
    # the MuJoCo rig, the batched single rig, the vector pool's slot truth and the scoring
    # helper all read one function: lambda66 = A66(0) = the hull's lambda66, with A66(swing)
    # (the Cummins root's) above it and A66(inf) below it; memory-free water unchanged
    p = memory_rig(preset)
    model = p.hydrodynamics
    w_n = model.natural_frequency(p.hull.J_hull, p.hull.lambda66, p.spring.c)
    for rig in (MujocoRig(p, seed=0), BatchedSingleRig(p, seed=0)):
        truth = rig.truth()
        assert truth["lambda66"] == p.hull.lambda66
        assert truth["A66_swing"] == pytest.approx(p.hull.lambda66 * float(model.added_inertia_ratio(w_n)[0]), rel=1e-12)
        assert truth["A66_inf"] == pytest.approx(p.hull.lambda66 * model.a_inf_ratio, rel=1e-12)
        assert truth["A66_inf"] < truth["lambda66"] < truth["A66_swing"]
    assert forces.true_lambda66(p) == p.hull.lambda66
    plain = load_rig(preset, sensors=SensorParams.ideal())
    truth = MujocoRig(plain, seed=0).truth()
    assert truth["lambda66"] == plain.hull.lambda66 and "A66_swing" not in truth
