"""Discovery: an effect hidden in simulated records must be found blind, with a positive gain.

Each dataset is the standard one (addedinertia_env.apps.discovery_dataset: twists 0.05 and
0.10 rad x holds 0.5 and 5 s) with one effect drawn from its realistic range (sim/effects/) by the seed.
The diagnosis never sees the truth; only the assertions read the simulator's effect.
Every effect and `none` runs by default on one seed; more seeds are marked slow. The
detection table in docs/DISCOVERY.md covers 10 seeds per effect.
"""

from __future__ import annotations

import copy
import json

import numpy as np
import pytest

from addedinertia_env.cli import main
from addedinertia_env.discover import DiscoveryInputError, discover
from addedinertia_env.apps.discovery_dataset import hidden_effect, simulate_dataset
from addedinertia_env.records.record import RunRecord, write_record
from addedinertia_env.sim.effects import EFFECT_NAMES

# Every effect and `none` in the default run (seed 10); more seeds in `make test-slow`.
FAST_CASES = [(e, 10) for e in ("none",) + EFFECT_NAMES]
SLOW_CASES = [(e, s) for s in (11,) for e in ("none",) + EFFECT_NAMES] + \
    [("none", 3), ("spring_stiffening", 3), ("sensor_delay", 3)]

_cache: dict[tuple[str, int], list[RunRecord]] = {}


def dataset(effect: str, seed: int) -> list[RunRecord]:
    if (effect, seed) not in _cache:
        _cache[(effect, seed)] = simulate_dataset(effect, seed)
    return _cache[(effect, seed)]


def check_found(effect: str, seed: int) -> None:
    records = dataset(effect, seed)
    diag = discover(records)
    truth = records[0].truth_lambda66()  # scoring only
    g = diag.gain()
    hidden = hidden_effect(effect, seed).to_dict()
    assert diag.cause == effect, f"hidden {hidden}, named {diag.cause}: {[c.to_json()['reason'] for c in diag.candidates]}"
    if effect == "none":
        assert g["residual_rms_extended"] == g["residual_rms_nominal"]
        # the nominal model explains the data to near the encoder's quantisation floor
        assert g["residual_rms_nominal"] < 2.0 * diag.data.phi_noise
        assert abs(g["lambda66_nominal"] / truth - 1) < 2e-3
        return
    assert g["residual_rms_extended"] < g["residual_rms_nominal"]
    assert g["heldout_gain"] > 0.0
    # the extended model's lambda66 is closer to the truth than the nominal one, and good
    assert abs(g["lambda66_extended"] - truth) < abs(g["lambda66_nominal"] - truth) + 2e-3 * truth
    assert abs(g["lambda66_extended"] / truth - 1) < 3e-3
    # the fitted size of the effect matches the hidden one (the parameter that measures it)
    best = diag.best.fit.params
    (name, params), = hidden.items()
    key = "beta" if name == "fluid_memory" else next(iter(params))
    assert best[key] == pytest.approx(params[key], rel=0.35, abs=0.02 if key == "beta" else 0.0)


@pytest.mark.parametrize("effect,seed", FAST_CASES)
def test_hidden_effect_found_fast(effect, seed):
    check_found(effect, seed)


@pytest.mark.slow
@pytest.mark.parametrize("effect,seed", SLOW_CASES)
def test_hidden_effect_found_every_effect(effect, seed):
    check_found(effect, seed)


def test_unmodelled_disturbance_is_unexplained():
    """A structure no candidate can produce (a 1.3 Hz wobble of the encoder mount) is not named as an effect."""
    records = []
    for rec in dataset("none", 3):
        r = RunRecord(samples={k: v.copy() for k, v in rec.samples.items()}, meta=copy.deepcopy(rec.meta))
        r.samples["phi"] = r.samples["phi"] + 4e-4 * np.sin(2 * np.pi * 1.3 * r.t)
        records.append(r)
    diag = discover(records)
    assert diag.cause == "unexplained"


def quirky_dataset(effect: str, seed: int) -> list[RunRecord]:
    """The dataset of (effect, seed) as a DAQ with two quirks drawn from the seed would log it."""
    from addedinertia_env.records.daq import apply_quirks, draw_quirks

    rng = np.random.default_rng(np.random.SeedSequence([seed, 11]))
    quirks = draw_quirks(rng)
    return [apply_quirks(r, quirks, rng) for r in dataset(effect, seed)], quirks


# fluid_memory at seed 10 draws 250 Hz decimation with the release sample not logged: the
# release is then known to one 4 ms period only, and the misfit is named bearing_coulomb.
QUIRK_CASES = [pytest.param(e, 10, marks=pytest.mark.xfail(reason="release known to 4 ms only at 250 Hz"))
               if e == "fluid_memory" else (e, 10) for e in ("none",) + EFFECT_NAMES]


@pytest.mark.slow
@pytest.mark.parametrize("effect,seed", QUIRK_CASES)
def test_hidden_effect_found_under_drawn_daq_quirks(effect, seed):
    records, quirks = quirky_dataset(effect, seed)
    diag = discover(records)
    assert diag.data.skipped == []
    assert diag.cause == effect, (quirks.to_dict(), [c.to_json()["reason"] for c in diag.candidates])
    truth = records[0].truth_lambda66()  # scoring only
    assert abs(diag.gain()["lambda66_extended"] / truth - 1) < 3e-3


@pytest.mark.slow
def test_two_effects_at_once_are_both_named():
    """Dry bearing friction and a stiffening spring together: the model selection names both."""
    from addedinertia_env.sim.effects import BearingCoulomb, Effects, SpringStiffening

    hidden = Effects(bearing_coulomb=BearingCoulomb(torque=0.06), spring_stiffening=SpringStiffening(k3=6.0))
    records = simulate_dataset("pair", 31, effects=hidden)
    diag = discover(records)
    assert set(diag.causes) == set(hidden.active), [(c.cause, c.against, c.reason) for r in diag.rounds for c in r]
    assert diag.best is not None and set(diag.best.effects) == set(hidden.active)
    truth = records[0].truth_lambda66()
    assert abs(diag.gain()["lambda66_extended"] / truth - 1) < 3e-3


def test_discover_cli_json_and_report(tmp_path):
    paths = [write_record(r, tmp_path / f"{r.run_id}.csv") for r in dataset("spring_stiffening", 3)]
    report = tmp_path / "report"
    import contextlib
    import io

    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        rc = main(["discover", *map(str, paths), "--json", "--no-heldout", "--report", str(report)])
    assert rc == 0
    obj = json.loads(out.getvalue())
    assert obj["cause"] == "spring_stiffening"
    assert {"residual_rms_nominal", "residual_rms_extended", "lambda66_nominal", "lambda66_extended"} <= set(obj["gain"])
    assert all({"cause", "score"} <= set(c) for c in obj["candidates"])
    assert (report / "report.md").exists() and (report / "residuals_time.png").stat().st_size > 0


def _write(tmp_path, rec: RunRecord, name: str):
    return write_record(rec, tmp_path / f"{name}.csv")


def _copy(rec: RunRecord) -> RunRecord:
    return RunRecord(samples={k: v.copy() for k, v in rec.samples.items()}, meta=copy.deepcopy(rec.meta))


@pytest.mark.parametrize("damage,expected", [
    ("no_reverse", "blocks of reverse motion"),
    ("forced_kind", "forced-oscillation"),
    ("two_rigs", "differs from"),
])
def test_an_unusable_record_is_skipped_and_reported(tmp_path, capsys, damage, expected):
    good = dataset("none", 3)
    a, b = _copy(good[0]), _copy(good[1])
    if damage == "no_reverse":
        b.samples["phase"] = np.where(b.phase == "reverse", "idle", b.phase)
    elif damage == "forced_kind":
        b.meta["experiment"]["kind"] = "forced-oscillation"
    elif damage == "two_rigs":
        b.meta["rig"]["c_torsion"] = 40.0
    paths = [_write(tmp_path, a, "a"), _write(tmp_path, b, "b")]
    rc = main(["discover", *map(str, paths), "--json", "--no-heldout"])
    out = capsys.readouterr()
    assert rc == 0
    obj = json.loads(out.out)
    assert [s["run"] for s in obj["skipped"]] == [str(paths[1])]
    assert expected in obj["skipped"][0]["reason"]
    assert [r["run"] for r in obj["runs"]] == [str(paths[0])]


def test_no_usable_record_is_refused_with_a_clear_message(tmp_path, capsys):
    a = _copy(dataset("none", 3)[0])
    a.meta["experiment"]["kind"] = "forced-oscillation"
    path = _write(tmp_path, a, "a")
    rc = main(["discover", str(path), "--json"])
    err = capsys.readouterr()
    assert rc == 2
    assert err.out == ""  # nothing half-analysed on stdout
    assert "no usable record" in err.err and "forced-oscillation" in err.err
    assert len(err.err.strip().splitlines()) == 1
    from addedinertia_env.records.record import read_record
    with pytest.raises(DiscoveryInputError):
        discover([read_record(path)])


def test_uneven_sampling_is_integrated_on_the_recorded_times(tmp_path):
    """A long interval (not a gap) and a dropped sample: read, fitted, not refused."""
    good = dataset("none", 3)
    a = _copy(good[0])
    t = a.samples["t"].copy()
    t[2000:] += 0.0004
    a.samples["t"] = t
    keep = np.ones(len(t), bool)
    keep[3000] = False
    a.samples = {k: v[keep] for k, v in a.samples.items()}
    diag = discover([a, *[_copy(r) for r in good[1:]]], heldout=False, pairs=False)
    assert diag.data.skipped == []
    assert diag.data.runs[0].sampling["dropped_samples"] == 1
