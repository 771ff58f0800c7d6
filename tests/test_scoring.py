"""One scoring of an episode (addedinertia_env/evaluation/scoring.py, issue 29 item 3).

The environment's reward, the vector env, the benchmark, the trainers and the demo must all
score an episode through :func:`addedinertia_env.evaluation.scoring.score_episode`. The scan below fails
if one of them calls ``identify()`` or divides by a true lambda66 itself; the functional tests
hold each caller's numbers equal to an independent computation on the same records
(``identify()`` here, the record's truth block read by key here).
"""

from __future__ import annotations

import ast
import math
from pathlib import Path

import numpy as np
import pytest

import addedinertia_env  # noqa: F401 - registers the id
from addedinertia_env.evaluation import scoring
from addedinertia_env.identify import identify

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("addedinertia_env", "agents", "hw_adapter")
SCORING = ROOT / "addedinertia_env" / "scoring.py"
# the callers that score an episode: each must go through scoring.py
CALLERS = ["addedinertia_env/envs/reverse_stroke.py", "addedinertia_env/vector/env.py", "addedinertia_env/vector/shards.py",
           "addedinertia_env/bench/runner.py", "addedinertia_env/learning/paired_batch.py",
           "addedinertia_env/learning/ars_residual.py", "addedinertia_env/learning/dagger.py",
           "addedinertia_env/learning/train.py", "addedinertia_env/cli/demo.py"]
TRUTHY = ("lambda66", "truth", "true")


def _calls(tree: ast.AST, name: str):
    for node in ast.walk(tree):
        if isinstance(node, ast.Call):
            f = node.func
            if (isinstance(f, ast.Name) and f.id == name) or (isinstance(f, ast.Attribute) and f.attr == name):
                yield node


def _names(node: ast.AST) -> list[str]:
    return [n.id if isinstance(n, ast.Name) else n.attr for n in ast.walk(node) if isinstance(n, (ast.Name, ast.Attribute))]


def test_only_the_scoring_module_chooses_the_energy_methods_correction():
    offenders = []
    for pkg in PACKAGES:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            if path == SCORING:
                continue
            for call in _calls(ast.parse(path.read_text()), "identify"):
                if any(k.arg == "asymmetry_correction" for k in call.keywords):
                    offenders.append(f"{path.relative_to(ROOT)}:{call.lineno}")
    assert not offenders, f"identify(..., asymmetry_correction=...) outside scoring.py: {offenders}"


@pytest.mark.parametrize("caller", CALLERS)
def test_the_callers_neither_identify_nor_divide_by_a_truth_themselves(caller):
    path = ROOT / caller
    tree = ast.parse(path.read_text())
    problems = [f"identify() at line {c.lineno}" for c in _calls(tree, "identify")]
    for node in ast.walk(tree):
        if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Div):
            if any(t in name.lower() for name in _names(node.right) for t in TRUTHY):
                problems.append(f"divides by {ast.unparse(node.right)} at line {node.lineno}")
        if isinstance(node, ast.Attribute) and node.attr == "lambda66" and "hull" in _names(node.value):
            problems.append(f"reads {ast.unparse(node)} at line {node.lineno}")
    assert not problems, f"{caller} scores an episode itself: {problems}"
    if caller.endswith(("ars_residual.py", "dagger.py", "train.py", "shards.py")):
        return  # they score through paired_batch / the envs, checked above
    assert "score_episode" in path.read_text() or "scoring" in path.read_text(), f"{caller} does not use scoring.py"


# --- functional: every caller's numbers equal an independent computation ------------------
def _independent(records, correction: bool):
    est = identify(records, "energy", asymmetry_correction=correction).lambda66
    true = records[0].meta["truth"]["lambda66"]  # the truth block, read here by key
    return est, true, (est - true) / true


def test_the_two_scores_are_named_and_each_is_its_identification():
    from addedinertia_env.experiment.protocol import plan_from_preset
    from addedinertia_env.sim.presets import load_preset, rig_from_mapping
    from addedinertia_env.apps.simulate import simulate_run

    data = load_preset("wigley-2m")
    rec = simulate_run(rig_from_mapping(data), "lqr", plan_from_preset(data), seed=1)
    for name, correction in ((scoring.AS_WRITTEN, False), (scoring.CORRECTED, True)):
        s = scoring.score_episode([rec], name)
        est, true, rel = _independent([rec], correction)
        assert s.score == name and s.lambda66_est == est and s.lambda66_true == true and s.rel_error == rel
        assert s.energy_J > 0 and math.isfinite(s.tracking_rms_rad)
    a, c = (scoring.score_episode([rec], n).lambda66_est for n in (scoring.AS_WRITTEN, scoring.CORRECTED))
    assert a != c  # two different estimates, not one under two names
    assert scoring.RANKED == scoring.AS_WRITTEN and scoring.REWARD == scoring.CORRECTED
    with pytest.raises(ValueError, match="expected one of"):
        scoring.score_episode([rec], "energy")


def test_the_truth_is_the_records_truth_block_and_none_on_a_bench():
    from addedinertia_env.experiment.protocol import plan_from_preset
    from addedinertia_env.sim.presets import load_preset, rig_from_mapping
    from addedinertia_env.apps.simulate import simulate_run

    data = load_preset("wigley-2m")
    rec = simulate_run(rig_from_mapping(data), "lqr", plan_from_preset(data), seed=2)
    rec.meta["truth"] = {**rec.meta["truth"], "lambda66": 12.345}  # a truth block that is not the hull's parameter
    s = scoring.score_episode([rec], scoring.CORRECTED, metrics=False)
    assert s.lambda66_true == 12.345 and s.rel_error == (s.lambda66_est - 12.345) / 12.345
    bench = rec.without_truth()
    s = scoring.score_episode([bench], scoring.CORRECTED, metrics=False)
    assert math.isnan(s.lambda66_true) and math.isnan(s.rel_error) and not s.failed and s.lambda66_est > 0
    other = simulate_run(rig_from_mapping(data), "lqr", plan_from_preset(data), seed=3)
    with pytest.raises(ValueError, match="truth lambda66"):
        scoring.truth_lambda66([rec, other])


def test_env_reward_vector_env_bench_row_and_trainer_score_through_the_one_scorer(monkeypatch):
    import gymnasium as gym

    from addedinertia_env.bench import runner
    from addedinertia_env.bench.suites import load_suite
    from addedinertia_env.envs import ReverseStrokeEnv
    from addedinertia_env.learning import paired_batch
    from addedinertia_env.experiment.task import RewardWeights, ReverseStrokeTask
    from agents import make_controller

    # the single env: its last info and its accuracy term
    env = ReverseStrokeEnv(action_repeat=10, hold_s=0.5, randomize=False, scenario_seed=4)
    obs, _ = env.reset(seed=0)
    controller = make_controller("lqr")
    controller.reset(env.controller_context())
    while True:
        obs, reward, terminated, truncated, info = env.step(controller.predict(obs, deterministic=True)[0])
        if terminated or truncated:
            break
    est, true, rel = _independent([env.record()], True)
    assert (info["lambda66_est"], info["lambda66_true"], info["rel_error"]) == (est, true, rel)
    task = ReverseStrokeTask(env.scenario.rig.motor.i_max, RewardWeights())
    assert info["reward_terms"]["accuracy"] == task.accuracy_term(rel, failed=False)

    # the vector env: an ended episode's info, against its record
    venv = gym.make_vec("AddedInertia/ReverseStroke-v0", num_envs=1, vectorization_mode="vector_entry_point",
                        action_repeat=10, hold_s=0.5, randomize=False)
    venv.reset(seed=1)
    for _ in range(2000):
        _, _, term, trunc, vinfo = venv.step(np.full((1, 1), 0.05, np.float32))
        if term[0] or trunc[0]:
            break
    est, true, rel = _independent([venv.unwrapped.record(0)], True)
    assert (vinfo["lambda66_est"][0], vinfo["lambda66_true"][0], vinfo["rel_error"][0]) == (est, true, rel)

    # the benchmark: the ranked (as written) and corrected numbers of its row, against its records
    made = []
    real = runner.run_experiment
    monkeypatch.setattr(runner, "run_experiment", lambda *a, **k: made.append(real(*a, **k)) or made[-1])
    suite = load_suite("smoke")
    row = runner.run_episode(suite.task(suite.scenarios("test")[0], "pid"))
    assert row["failure"] is None
    est, true, rel = _independent(made, False)
    assert (row["lambda66_est"], row["lambda66_true"], row["rel_error"]) == (est, true, rel)
    est_c, _, rel_c = _independent(made, True)
    assert (row["lambda66_est_corrected"], row["rel_error_corrected"]) == (est_c, rel_c)

    # the trainers' batched episodes (ars_residual, dagger): the ranked score of each slot's record
    pools = []

    class Recording(paired_batch.ExperimentPool):
        def __init__(self, *a, **k):
            super().__init__(*a, **k)
            pools.append(self)

    monkeypatch.setattr(paired_batch, "ExperimentPool", Recording)
    hard = load_suite("hard-v0")
    from addedinertia_env.learning.ars_residual import base_factory, base_params

    result = paired_batch.run_batch(hard, [0, 1], base_factory("pid", base_params(hard, "pid")))
    for k in range(2):
        est, true, rel = _independent([pools[0].record(k)], False)
        assert result.rel_error[k] == rel
