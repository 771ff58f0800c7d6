"""Two hidden effects at once: every pair of the vocabulary, drawn at realistic sizes from a seed.

The pairs come from the effect registry (``sim/effects/``), so a word added there joins
the pair tests and the pair table without a change here. Each effect of a pair is drawn
from its own realistic range (its file's ``draw`` or ``Param.realistic``) with a stream
of its own, so the same seed gives an effect the same size in every pair it is in.
The records of a pair: :func:`.dataset.simulate_pair_dataset`.
"""

from __future__ import annotations

import itertools
import numpy as np

from addedinertia_env.sim.effects import Effects, registry


def vocabulary_pairs() -> list[tuple[str, str]]:
    """Every unordered pair of registered effects (registry order)."""
    return list(itertools.combinations(registry.effect_names(), 2))


def parse_pair(text: str) -> tuple[str, str]:
    """``"a+b"`` -> ``("a", "b")``; ``ValueError`` naming the known effects otherwise."""
    parts = tuple(text.split("+"))
    if len(parts) != 2 or parts[0] == parts[1]:
        raise ValueError(f"pair {text!r}: expected two different effects joined by '+'")
    for p in parts:
        registry.get(p)
    return parts


def hidden_pair(pair: tuple[str, str], seed: int) -> Effects:
    """The two effects of ``pair`` at sizes drawn from ``seed`` (one stream per effect)."""
    on = {}
    for name in pair:
        spec = registry.get(name)
        index = registry.effect_names().index(name)
        rng = np.random.default_rng(np.random.SeedSequence([seed, 27, index]))
        on[name] = spec.params_type(**spec.draw_values(rng))
    return Effects(**on)
