"""``addedinertia dataset export``: episodes written as a Minari dataset, loaded back with Minari,
and one episode's score replayed from the loaded data (docs/DATASETS.md)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from addedinertia_env.cli import main

minari = pytest.importorskip("minari", reason="Minari (optional extra [data]) not installed")
pytest.importorskip("h5py", reason="h5py (Minari's HDF5 storage, extra [data]) not installed")


@pytest.fixture
def datasets(tmp_path, monkeypatch):
    """A private Minari root for the test."""
    root = tmp_path / "minari"
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(root))
    return root


def _episode_meta(ds, k: int) -> dict:
    return next(iter(ds.storage.get_episode_metadata([k])))


def test_run_records_round_trip_and_score_replayed(datasets, realistic_record_path, capsys):
    from addedinertia_env.records.record import read_record
    from addedinertia_env.evaluation.scoring import RANKED, score_episode

    assert main(["dataset", "export", str(realistic_record_path), "--minari", "ai/records-v0"]) == 0
    ds = minari.load_dataset("ai/records-v0")
    assert ds.total_episodes == 1
    ep = ds[0]
    record = read_record(realistic_record_path)
    n = len(record.t)
    # the data are the record's samples: observations [t, phi, psi, u, i], actions the command
    assert ep.observations.shape == (n, 5) and ep.actions.shape == (n - 1, 1)
    np.testing.assert_array_equal(ep.observations[:, 1], record["phi"])
    np.testing.assert_array_equal(ep.observations[:, 4], record["i"])
    assert ep.terminations[-1] and not ep.terminations[:-1].any() and not ep.truncations.any()
    # replay the score from the original record and compare with what came back from the dataset
    replayed = score_episode([record], RANKED)
    assert math.isfinite(replayed.rel_error)
    assert ep.rewards[-1] == pytest.approx(-abs(replayed.rel_error), rel=1e-12)
    assert ep.rewards.sum() == pytest.approx(-abs(replayed.rel_error), rel=1e-12)
    meta = _episode_meta(ds, 0)
    assert meta["lambda66_est"] == pytest.approx(replayed.info()["lambda66_est"], rel=1e-12)
    assert meta["return"] == pytest.approx(ep.rewards.sum(), rel=1e-12)
    scoring = ds.storage.metadata["addedinertia"]
    assert scoring["score"] == RANKED and scoring["source"] == "run records"


def test_simulated_episode_replays_to_the_same_return(datasets):
    from addedinertia_env.learning.minari_export import make_env, _run_env_episode

    assert main(["dataset", "export", "--simulate", "1", "--seed", "3", "--no-references",
                 "--minari", "ai/sim-v0"]) == 0
    ds = minari.load_dataset("ai/sim-v0")
    ep = ds[0]
    meta = _episode_meta(ds, 0)
    env = ds.recover_environment()  # the stored spec rebuilds the environment
    assert env.spec.id == "AddedInertia/ReverseStroke-v0" and env.spec.kwargs["action_repeat"] == 10
    assert ep.observations.shape[1:] == env.observation_space.shape
    assert ep.actions.shape == (len(ep.rewards), 1) and ep.terminations[-1]
    # replay: the same seed and controller in a fresh environment give the stored return and score
    again = _run_env_episode(make_env(None, 10), "feedforward-pd", int(meta["seed"]))
    assert ep.rewards.sum() == pytest.approx(again.meta["return"], rel=1e-9)
    np.testing.assert_allclose(ep.actions, again.actions, rtol=0, atol=1e-6)
    assert meta["rel_error"] == pytest.approx(again.meta["rel_error"], rel=1e-9)
    scoring = ds.storage.metadata["addedinertia"]
    assert scoring["score"] == "corrected" and scoring["seeds"] == [3]


@pytest.mark.slow
def test_reference_scores_normalise_the_return(datasets):
    assert main(["dataset", "export", "--simulate", "1", "--suite", "standard-v0", "--minari", "ai/ref-v0"]) == 0
    ds = minari.load_dataset("ai/ref-v0")
    scoring = ds.storage.metadata["addedinertia"]
    refs = scoring["reference_scores"]
    assert scoring["suite_version"]["name"] == "standard-v0" and len(scoring["suite_version"]["sha256"]) == 64
    assert ds.storage.metadata["ref_min_score"] == refs["zero"]
    assert ds.storage.metadata["ref_max_score"] == refs["feedforward-pd"]
    ret = float(ds[0].rewards.sum())
    # the reference max is the same controller on the same seed: normalised score 1
    assert minari.get_normalized_score(ds, np.array([ret]))[0] == pytest.approx(1.0, rel=1e-9)


def test_bad_inputs_exit_2(datasets, realistic_record_path, tmp_path, capsys):
    missing = tmp_path / "run-9999.csv"
    assert main(["dataset", "export", str(missing), "--minari", "ai/x-v0"]) == 2
    assert str(missing) in capsys.readouterr().err
    assert not (datasets / "ai" / "x-v0").exists()
    assert main(["dataset", "export", str(realistic_record_path), "--minari", "no-version"]) == 2
    assert "no-version" in capsys.readouterr().err
    assert main(["dataset", "export", str(realistic_record_path), "--simulate", "1", "--minari", "ai/y-v0"]) == 2
    assert "not both" in capsys.readouterr().err
    assert main(["dataset", "export", str(realistic_record_path), "--minari", "ai/z-v0"]) == 0
    capsys.readouterr()
    assert main(["dataset", "export", str(realistic_record_path), "--minari", "ai/z-v0"]) == 2
    assert "already exists" in capsys.readouterr().err
    leftovers = [p.name for p in datasets.iterdir() if p.name.startswith(".export-")]
    assert leftovers == []


def test_one_record_named_twice_is_refused(datasets, realistic_record_path, capsys):
    json_path = realistic_record_path.with_suffix(".json")
    assert main(["dataset", "export", str(realistic_record_path), str(json_path), "--minari", "ai/twice-v0"]) == 2
    err = capsys.readouterr().err
    assert str(json_path) in err and "same run record" in err
