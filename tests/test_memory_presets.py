"""Memory-on rig presets (configs/rigs/*-memory.yaml, issue 26 item 6): the memory-free preset
with radiation memory on, through ``extends:``; the single env, the vector env and the bench
emulator run on them, and every truth they write is lambda66 = A66(0)."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest
import yaml

import addedinertia_env  # noqa: F401 - registers the ids
from conftest import single_and_vector_episode
from addedinertia_env.envs.reverse_stroke import ReverseStrokeEnv
from addedinertia_env.sim.batched_single import BatchedSingleRig
from addedinertia_env.sim.forces import true_lambda66
from addedinertia_env.sim.motor import MotorCommand
from addedinertia_env.sim.mujoco_rig import MujocoRig
from addedinertia_env.sim.presets import RIG_DIR, ConfigError, load_preset, load_rig
from addedinertia_env.vector.env import ReverseStrokeVectorEnv

ENV_ID = "AddedInertia/ReverseStroke-v0"
MEMORY = {"wigley-2m-memory": "wigley-2m", "spheroid-7-memory": "spheroid-7"}
SHORT = dict(hold_s=0.5, fixed={"period_s": 3.0}, action_repeat=10)


@pytest.mark.parametrize("name", sorted(MEMORY))
def test_a_memory_preset_is_its_base_with_the_bem_caches_memory(name):
    base, mem = load_preset(MEMORY[name]), load_preset(name)
    assert mem["extends"] == MEMORY[name] and mem["name"] == name
    for block in set(base) | set(mem):  # every block the base's, but the name, the path and the water
        if block not in ("name", "_path", "extends", "hydrodynamics"):
            assert mem.get(block) == base.get(block), block
    rig, plain = load_rig(name), load_rig(MEMORY[name])
    assert plain.hydrodynamics is None and rig.hydrodynamics is not None
    assert rig.hydrodynamics.source.endswith(f"{MEMORY[name]}.bem.json")
    assert rig.hull.lambda66 == plain.hull.lambda66 and rig.spring == plain.spring and rig.motor == plain.motor
    # the truth: lambda66 = A66(0); the swing sees more, an impact less (physics.md s6)
    truth = MujocoRig(rig, seed=0).truth()
    assert truth["lambda66"] == true_lambda66(rig) == plain.hull.lambda66
    assert truth["A66_inf"] < truth["lambda66"] < truth["A66_swing"] < 1.03 * truth["lambda66"]


def test_extends_is_validated(tmp_path):
    def preset(text: str) -> str:
        path = tmp_path / "p.yaml"
        path.write_text(text)
        return str(path)

    with pytest.raises(ConfigError, match=r"p\.yaml: extends = 'nosuch'.*unknown rig 'nosuch'"):
        load_preset(preset("name: x\nextends: nosuch\n"))
    with pytest.raises(ConfigError, match=r"p\.yaml: extends = 3: expected the name of a rig preset"):
        load_preset(preset("name: x\nextends: 3\n"))
    with pytest.raises(ConfigError, match=r"extends = 'wigley-2m-memory', which itself extends 'wigley-2m'"):
        load_preset(preset("name: x\nextends: wigley-2m-memory\n"))
    with pytest.raises(ConfigError, match=r"unknown key\(s\) \['colour'\]"):
        load_preset(preset("name: x\nextends: wigley-2m\ncolour: red\n"))
    # a block of its own replaces the base's whole block; a relative .yaml base is read beside the file
    (tmp_path / "base.yaml").write_text(yaml.safe_dump({k: v for k, v in load_preset("wigley-2m").items()
                                                        if k != "_path"}))
    rig = load_rig(preset("name: stiff\nextends: base.yaml\nspring: {c: 50.0}\n"))
    assert rig.spring.c == 50.0 and rig.spring.phi_neutral == 0.0 and rig.hull.name == "stiff"
    assert rig.hull.lambda66 == load_rig("wigley-2m").hull.lambda66


def _run_out(venv, singles, seed):
    """Zero-ish actions until every first episode ends; batched and single envs compared step by step."""
    n = len(singles)
    obs, _ = venv.reset(seed=seed)
    for k, env in enumerate(singles):
        so, _ = env.reset(seed=seed + k)
        np.testing.assert_allclose(obs[k], so, rtol=1e-6, atol=1e-6)
    rng = np.random.default_rng(3)
    live, ends = [True] * n, [None] * n
    for _ in range(400):
        a = rng.uniform(-0.3, 0.3, size=(n, 1)).astype(np.float32)
        obs, reward, term, _, info = venv.step(a)
        for k, env in enumerate(singles):
            if not live[k]:
                continue
            so, sr, st, _, sinfo = env.step(a[k])
            assert term[k] == st and reward[k] == pytest.approx(sr, rel=1e-9, abs=1e-12)
            if st:
                live[k] = False
                ends[k] = ({key: info[key][k] for key in ("lambda66_est", "lambda66_true", "rel_error")}, sinfo,
                           venv.record(k))  # before the slot's next episode replaces it
            else:
                np.testing.assert_allclose(obs[k], so, rtol=1e-6, atol=1e-6)
        if not any(live):
            return ends
    raise AssertionError("every episode should end within 400 agent steps")


@pytest.mark.parametrize("name", sorted(MEMORY))
def test_vector_env_on_a_memory_preset_equals_the_single_env(name):
    venv = gym.make_vec(ENV_ID, num_envs=2, preset=name, **SHORT)
    assert isinstance(venv, ReverseStrokeVectorEnv)
    singles = [ReverseStrokeEnv(rig_factory=lambda sc: BatchedSingleRig(sc.rig, seed=sc.sensor_seed),
                                preset=name, **SHORT) for _ in range(2)]
    for batched, single, rec in _run_out(venv, singles, seed=11):
        for key, value in batched.items():
            assert value == pytest.approx(single[key], rel=1e-9), key
        # scored against A66(0): the scenario's hull lambda66, not A66 at the swing frequency
        assert rec.meta["truth"]["hydrodynamics"]["model"] == "cummins"
        assert batched["lambda66_true"] == rec.meta["truth"]["lambda66"] == rec.meta["truth"]["hydrodynamics"]["A66_zero"]
        assert math.isfinite(batched["lambda66_est"]) and not single["failed"]
    venv.close()


def test_mujoco_single_env_and_vector_env_identify_alike_with_memory():
    """The default single env (MuJoCo, memory in its own step) against the batched one: the same
    lambda66 within the engines' difference, far below the memory's own bias (percent)."""
    info, sinfo = single_and_vector_episode(preset="wigley-2m-memory", **SHORT)
    assert info["lambda66_true"][0] == sinfo["lambda66_true"]
    assert info["lambda66_est"][0] == pytest.approx(sinfo["lambda66_est"], rel=1e-3)


def test_the_bench_emulator_serves_a_memory_preset():
    """`bench-server --rig wigley-2m-memory`'s board: the memory-on rig behind the wire (the same
    samples as a MuJoCo rig with memory, not those of the memory-free preset)."""
    from hw_adapter.bench_rig import BenchRig
    from hw_adapter.lab import load_lab
    from hw_adapter.loopback import start_emulator

    server = start_emulator(rig="wigley-2m-memory", fast=True, seed=3)
    bench = BenchRig(server.url, load_lab("wigley-2m-memory"))
    sims = {name: MujocoRig(load_rig(name), seed=3) for name in ("wigley-2m-memory", "wigley-2m")}
    try:
        bench.connect()
        assert bench.truth() is None  # a bench hands no truth to the host
        bench.arm()
        bench.reset(phi0=-0.1)
        bench.set_brake(False)
        for sim in sims.values():
            sim.reset(phi0=-0.1, brake=True)
            sim.set_brake(False)
        gap = {name: 0.0 for name in sims}
        for _ in range(1500):
            r = bench.step(MotorCommand("passive", 0.0))
            for name, sim in sims.items():
                gap[name] = max(gap[name], abs(sim.step(MotorCommand("passive", 0.0)).phi - r.phi))
        assert server.board.rig.truth()["hydrodynamics"]["model"] == "cummins"
        assert gap["wigley-2m-memory"] < 1e-9 < 1e-4 < gap["wigley-2m"], gap
        bench.disarm()
        assert bench.confirm_safe()["confirmed"]
    finally:
        bench.close()
        server.stop()


def test_hull_stability_from_a_memory_record_takes_identifys_a66_zero(tmp_path, capsys):
    """`hull wigley-2m-memory --stability --from-record RUN.csv`: the memory preset's hull is its base's
    (the same BEM cache), and the lambda66 it hands the ship is identify()'s, which is A66(0)."""
    import json

    from addedinertia_env.cli import main
    from addedinertia_env.experiment.protocol import plan_from_preset
    from addedinertia_env.identify import identify
    from addedinertia_env.records.record import write_record
    from addedinertia_env.apps.simulate import simulate_run

    rec = simulate_run(load_rig("wigley-2m-memory"), "lqr", plan_from_preset(load_preset("wigley-2m-memory")),
                       seed=1, run_id="memory-hull")
    path = write_record(rec, tmp_path / "run-0000.csv")
    assert main(["hull", "wigley-2m-memory", "--stability", "--from-record", str(path), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["source"].endswith("wigley-2m.bem.json")
    fr = out["stability"]["from_record"]
    res = identify([rec], "energy")
    assert fr["lambda66_used"] == pytest.approx(res.lambda66, rel=1e-12)
    assert out["stability"]["lambda66_range"]["lambda66"] == pytest.approx(list(res.ci95), rel=1e-12)
    assert rec.meta["truth"]["lambda66"] == load_rig("wigley-2m").hull.lambda66  # the truth it estimates: A66(0)
