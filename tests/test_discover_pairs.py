"""Two hidden effects at once: discovery must name both, and nothing else (issue 27).

Pairs come from the effect registry (every pair of the vocabulary; a new word joins by
itself), each effect at a size drawn from its realistic range by the seed
(:func:`addedinertia_env.discover.pairs.hidden_pair`), on the project's engine and under
DAQ quirks drawn from the seed. The diagnosis never sees the truth; only the assertions
read it. The default run holds a small sample of pairs; the slow set every pair at
least once. The pair table in docs/DISCOVERY.md runs the same datasets.
"""

from __future__ import annotations

import numpy as np
import pytest

from addedinertia_env.discover import discover
from addedinertia_env.apps.discovery_dataset import simulate_pair_dataset
from addedinertia_env.discover.pairs import hidden_pair, parse_pair, vocabulary_pairs
from addedinertia_env.sim.effects import EFFECT_NAMES, registry

ALL_PAIRS = vocabulary_pairs()
# The default run: a small sample, drawn once from the vocabulary's pairs with a fixed seed.
FAST_PAIRS = [ALL_PAIRS[k] for k in np.random.default_rng(27).choice(len(ALL_PAIRS), size=2, replace=False)]

_cache: dict = {}


def pair_dataset(pair, seed):
    if (pair, seed) not in _cache:
        _cache[(pair, seed)] = simulate_pair_dataset(pair, seed)
    return _cache[(pair, seed)]


def check_pair(records, pair, seed, quirks=None):
    diag = discover(records)
    hidden = hidden_pair(pair, seed).to_dict()  # scoring only
    truth = records[0].truth_lambda66()
    g = diag.gain()
    detail = (hidden, quirks, [(c.cause, c.against, c.reason) for rnd in diag.rounds for c in rnd])
    assert sorted(diag.causes) == sorted(pair), detail
    assert diag.cause in pair
    # the extended model's lambda66 is good, and closer to the truth than the nominal one's
    assert abs(g["lambda66_extended"] / truth - 1) < 3e-3, detail
    assert abs(g["lambda66_extended"] - truth) <= abs(g["lambda66_nominal"] - truth) + 1e-3 * truth
    # the gain per effect: nominal, each named effect alone, the combination
    rows = diag.effects_gain()
    assert [r["model"] for r in rows] == ["nominal", *diag.causes, "+".join(diag.causes)]
    assert rows[-1]["residual_rms"] <= min(r["residual_rms"] for r in rows[:-1])
    return diag


def test_every_pair_of_the_vocabulary_is_drawn_from_the_registry():
    names = registry.effect_names()
    assert len(ALL_PAIRS) == len(names) * (len(names) - 1) // 2
    assert {e for p in ALL_PAIRS for e in p} == set(names)
    p = ALL_PAIRS[0]
    a, b = hidden_pair(p, 0), hidden_pair(p, 0)
    assert a == b and set(a.active) == set(p)
    # one stream per effect: an effect has the same size in every pair of one seed
    other = next(q for q in ALL_PAIRS if p[0] in q and q != p)
    assert hidden_pair(other, 0).to_dict()[p[0]] == a.to_dict()[p[0]]
    with pytest.raises(ValueError, match="unknown effect"):
        parse_pair("bearing_coulomb+no_such_effect")


@pytest.mark.parametrize("pair", FAST_PAIRS, ids=["+".join(p) for p in FAST_PAIRS])
def test_a_sample_of_pairs_is_named_exactly(pair):
    check_pair(pair_dataset(pair, 0), pair, 0)


@pytest.mark.slow
@pytest.mark.parametrize("pair", ALL_PAIRS, ids=["+".join(p) for p in ALL_PAIRS])
def test_every_pair_is_named_exactly(pair):
    check_pair(pair_dataset(pair, 0), pair, 0)


# Measured misses under quirks (docs/DISCOVERY.md, "The same under DAQ quirks"): fluid memory
# is lost where the release is known to one 4 ms period only (250 Hz, release sample not
# logged: as for fluid memory alone) and, with a sensor delay, where the release sample is
# logged as moving behind a braked tail.
QUIRK_MISSES = {("bearing_coulomb", "fluid_memory"): "250 Hz with the release sample dropped: fluid memory missed",
                ("fluid_memory", "sensor_delay"): "release logged as moving: fluid memory missed beside the delay"}
QUIRK_PAIRS = [pytest.param(p, marks=pytest.mark.xfail(reason=QUIRK_MISSES[p], strict=False))
               if p in QUIRK_MISSES else p for p in ALL_PAIRS]


@pytest.mark.slow
@pytest.mark.parametrize("pair", QUIRK_PAIRS, ids=["+".join(p) for p in ALL_PAIRS])
def test_every_pair_is_named_exactly_under_drawn_daq_quirks(pair):
    from addedinertia_env.reports.pair_table import quirky

    # seed 2: every effect inside the range discovery resolves with holds of 0.5 and 5 s (at
    # seed 1, fluid memory's tau is 26 s: missed even alone, docs/DISCOVERY.md "Limits")
    records, quirks = quirky(pair_dataset(pair, 2), 2, "+".join(pair))
    check_pair(records, pair, 2, quirks)


def test_a_new_word_joins_the_pairs():
    """A toy effect registered at run time is paired with every word of the vocabulary."""
    from dataclasses import dataclass

    @dataclass(frozen=True)
    class ToyDamping:
        d9: float

    spec = registry.EffectSpec(name="toy_pair_word", summary="toy", params_type=ToyDamping,
                               params=(registry.Param("d9", "N m s^3", "toy", (1.0, 2.0), 0.0,
                                                      registry.FitRange(0.0, -10.0, 10.0, 1.0)),),
                               size_param="d9", min_size=0.5, hull_torque=lambda e, d, w, p: -e.d9 * w**3)
    registry.register(spec)
    try:
        pairs = vocabulary_pairs()
        assert {tuple(sorted((e, "toy_pair_word"))) for e in EFFECT_NAMES} <= {tuple(sorted(p)) for p in pairs}
        assert "toy_pair_word" in hidden_pair(("bearing_coulomb", "toy_pair_word"), 3).active
    finally:
        registry.unregister("toy_pair_word")
