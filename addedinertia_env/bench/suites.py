"""Benchmark suites: named, seeded scenario sets in ``configs/suites/*.yaml``.

A suite file::

    name: standard-v0
    description: free text
    presets: [wigley-2m, spheroid-7]     # scenario seed s uses presets[s % len(presets)]
    ranges: randomization.yaml           # a file in configs/ or an inline mapping (scenarios.py keys)
    fixed: {}                            # keys of ranges pinned to one value
    splits:
      tuning: {first_seed: 100000, count: 24}   # used by `bench tune` only
      test:   {first_seed: 200000, count: 30}   # held out: never used for tuning

The split seed ranges must not overlap: the test seeds are never seen by tuning. Seeds
outside every split belong to the pseudo-split ``train`` (for learned controllers: the
same distribution, never a tuning or test scenario).

Optional keys: ``effects``, ``loop``, ``motor``, ``link`` (hidden effects, the control loop, motor
overrides, the loop's round trip stated to the controllers, drawn per seed: :mod:`.scenario_draws`) and ``cycles: N`` (each episode runs N
reverse-symmetric cycles, each with fresh sensor noise, identified jointly), ``tuned:
FILE`` (the suite's own tuned gains, a file in configs/controllers/ written by
``bench tune --suite NAME``; without it controllers use configs/controllers/tuned.yaml), ``ranked:
as-written | memory-corrected`` (the estimate the leaderboard ranks, default the method as written;
``memory-corrected``: the same with the water's memory identified from the records and corrected for,
its own score version, bench/versions.py).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from agents.classical import CLASSICAL, controller_class
from agents.tuned import load_tuned

from addedinertia_env.foundation.config_io import check_keys, read_yaml

from addedinertia_env.sim.presets import CONFIG_DIR, ConfigError, config_path
from addedinertia_env.experiment.scenarios import RANGE_KEYS, Scenario, load_ranges, make_scenario
from addedinertia_env.bench.scenario_draws import apply_extras, validate_extras
from addedinertia_env.bench.drive_draws import check_supply_floor

SUITE_DIR = CONFIG_DIR / "suites"
SUITE_KEYS = {"name", "description", "presets", "ranges", "fixed", "splits", "effects", "loop", "motor", "cycles",
              "tuned", "drive", "ranked", "link"}
RANKED_SCORES = ("as-written", "memory-corrected")  # evaluation/scoring.py's scores a suite may rank
TUNED_DIR = CONFIG_DIR / "controllers"
TRAIN_FIRST_SEED = 10**9  # declared splits lie below; seeds from here on are the "train" pseudo-split
SPLITS = ("tuning", "test")


def available_suites() -> list[str]:
    """Names of the suites in configs/suites/."""
    return sorted(p.stem for p in SUITE_DIR.glob("*.yaml"))


@dataclass(frozen=True)
class EpisodeTask:
    """One benchmark episode, independent of every other (picklable)."""

    suite: str
    split: str
    scenario: Scenario
    preset: str
    controller: str
    controller_kwargs: dict[str, Any] = field(default_factory=dict)
    cycles: int = 1  # scored reverse-symmetric cycles, identified jointly
    ranked: str = "as-written"  # the score the leaderboard ranks (evaluation/scoring.py), the suite's ``ranked``
    entry: dict[str, Any] = field(default_factory=dict)  # declared by a submission: entry_kind, train cost


@dataclass(frozen=True)
class Suite:
    """A benchmark suite: presets, randomisation ranges, fixed values and seeded splits."""

    name: str
    description: str
    presets: tuple[str, ...]
    ranges: dict[str, Any]
    fixed: dict[str, Any]
    splits: dict[str, tuple[int, int]]  # split -> (first_seed, count)
    extras: dict[str, Any] = field(default_factory=dict)  # effects, loop, motor (scenario_draws)
    cycles: int = 1
    tuned_path: Path | None = None  # the suite's own tuned gains (None: configs/controllers/tuned.yaml)
    source: str = ""  # the suite file, for messages
    ranked: str = "as-written"  # the score the leaderboard ranks (``ranked:``; RANKED_SCORES)

    def seeds(self, split: str) -> list[int]:
        """The scenario seeds of ``split`` (``tuning``, ``test`` or ``all``)."""
        if split == "all":
            return [s for name in SPLITS for s in self.seeds(name)]
        if split not in self.splits:
            raise ConfigError(f"suite {self.name!r}: no split {split!r}; expected one of "
                              f"{', '.join([*self.splits, 'all'])}")
        first, count = self.splits[split]
        return list(range(first, first + count))

    def split_seed(self, split: str, k: int) -> int:
        """Scenario seed number ``k`` of ``split``: cycles through a declared split's seeds;
        for ``train``, ``TRAIN_FIRST_SEED + k mod 10**9`` (outside every declared split)."""
        if split == "train":
            return TRAIN_FIRST_SEED + int(k) % 10**9
        seeds = self.seeds(split)
        return seeds[int(k) % len(seeds)]

    def split_of(self, seed: int) -> str:
        """``tuning``, ``test``, or ``train`` for a seed outside both."""
        for name, (first, count) in self.splits.items():
            if first <= seed < first + count:
                return name
        return "train"

    def preset_for(self, seed: int) -> str:
        """The rig preset of scenario ``seed`` (presets taken in turn)."""
        return self.presets[seed % len(self.presets)]

    def scenario(self, seed: int) -> Scenario:
        """The seeded scenario ``seed`` of this suite."""
        preset = self.preset_for(seed)
        try:
            sc = make_scenario(seed, preset=preset, ranges=self.ranges, fixed=self.fixed,
                               name=f"{self.name}/{self.split_of(seed)}/{seed}")
            return apply_extras(sc, self.extras) if self.extras else sc
        except (ConfigError, ValueError) as e:  # a value the suite drew or fixed: the suite file is to blame
            raise ConfigError(f"{self.source or self.name}: scenario seed {seed} on preset {preset!r}, with the "
                              f"suite's fixed values {self.fixed} and ranges: {e}") from None

    def scenarios(self, split: str = "test") -> list[Scenario]:
        """The scenarios of ``split``."""
        return [self.scenario(s) for s in self.seeds(split)]

    def task(self, scenario: Scenario, controller: str, controller_kwargs: dict[str, Any] | None = None,
             tuned: bool = True, entry: dict[str, Any] | None = None) -> EpisodeTask:
        """One benchmark episode of ``controller`` on ``scenario`` (the suite's tuned gains unless ``tuned`` is false)."""
        kwargs = dict(controller_kwargs or {})
        if tuned and self.tuned_path is not None:
            params = load_tuned(controller, self.tuned_path)
            shared = getattr(controller_class(controller), "tuned_as", None) if controller in CLASSICAL else None
            if not params and shared:  # an entry that adds no loop knob (cogging-ff) runs its loop's tuned gains
                params = load_tuned(shared, self.tuned_path)
            if params:  # gains tuned on this suite's tuning split, passed explicitly
                kwargs = {**params, **kwargs}
                tuned = False
        if not tuned:
            kwargs["tuned"] = False
        return EpisodeTask(suite=self.name, split=self.split_of(scenario.seed), scenario=scenario,
                           preset=self.preset_for(scenario.seed), controller=controller, controller_kwargs=kwargs,
                           cycles=self.cycles, ranked=self.ranked, entry=dict(entry or {}))


def suite_path(name: str) -> Path:
    """The YAML file of suite ``name`` (a name in configs/suites/ or a path); ConfigError if none."""
    return config_path("suite", name, SUITE_DIR)


def load_suite(name: str) -> Suite:
    """The suite ``name`` (a file in configs/suites/ or a path), validated."""
    path = suite_path(name)
    data = check_keys(read_yaml(path, "suite") or {}, SUITE_KEYS, str(path))
    presets = data.get("presets") or ["wigley-2m"]
    if not (isinstance(presets, list) and all(isinstance(p, str) for p in presets)):
        raise ConfigError(f"{path}: presets = {presets!r}; expected a list of rig preset names")
    ranges_spec = data.get("ranges", "randomization.yaml")
    if isinstance(ranges_spec, str):
        ranges = load_ranges(CONFIG_DIR / ranges_spec)
    elif isinstance(ranges_spec, dict):
        ranges = _validate_inline_ranges(ranges_spec, path)
    else:
        raise ConfigError(f"{path}: ranges = {ranges_spec!r}; expected a file name in configs/ or a mapping")
    fixed = check_keys(data.get("fixed") or {}, RANGE_KEYS, f"{path}: fixed")
    splits_raw = data.get("splits") or {}
    splits: dict[str, tuple[int, int]] = {}
    for split, spec in splits_raw.items():
        if split not in SPLITS:
            raise ConfigError(f"{path}: split {split!r}; expected {' and/or '.join(SPLITS)}")
        if not (isinstance(spec, dict) and isinstance(spec.get("first_seed"), int)
                and isinstance(spec.get("count"), int) and spec["count"] > 0 and spec["first_seed"] >= 0):
            raise ConfigError(f"{path}: splits.{split} = {spec!r}; expected {{first_seed: int >= 0, count: int > 0}}")
        splits[split] = (spec["first_seed"], spec["count"])
        if spec["first_seed"] + spec["count"] > TRAIN_FIRST_SEED:
            raise ConfigError(f"{path}: splits.{split} = {spec!r}; seeds from {TRAIN_FIRST_SEED} on are kept for "
                              "training (split 'train')")
    if not splits:
        raise ConfigError(f"{path}: no splits; expected splits.test (and splits.tuning)")
    ranges_list = sorted(splits.values())
    for (a0, n0), (a1, _) in zip(ranges_list, ranges_list[1:]):
        if a0 + n0 > a1:
            raise ConfigError(f"{path}: split seed ranges overlap; the test seeds must never be used for tuning")
    from addedinertia_env.sim.presets import rig_path  # noqa: PLC0415

    for p in presets:
        rig_path(p)
    cycles = data.get("cycles", 1)
    if isinstance(cycles, bool) or not isinstance(cycles, int) or not 1 <= cycles <= 20:
        raise ConfigError(f"{path}: cycles = {cycles!r}; expected a whole number of cycles in [1, 20]")
    tuned = data.get("tuned")
    if tuned is not None and not (isinstance(tuned, str) and tuned.endswith((".yaml", ".yml"))
                                  and "/" not in tuned):
        raise ConfigError(f"{path}: tuned = {tuned!r}; expected a .yaml file name in configs/controllers/")
    ranked = data.get("ranked", "as-written")
    if ranked not in RANKED_SCORES:
        raise ConfigError(f"{path}: ranked = {ranked!r}; expected one of {', '.join(RANKED_SCORES)}")
    extras = validate_extras(data, path)
    check_supply_floor(extras["drive"], extras["motor"], presets, path)
    extras = {k: v for k, v in extras.items() if v}
    suite = Suite(name=str(data.get("name", path.stem)), description=str(data.get("description", "")),
                  presets=tuple(presets), ranges=ranges, fixed=dict(fixed), splits=splits, extras=extras,
                  cycles=cycles, tuned_path=TUNED_DIR / tuned if tuned else None, source=str(path), ranked=ranked)
    for first, _ in splits.values():  # a bad fixed value or range refused up front, naming the suite file
        suite.scenario(first)
    return suite


def _validate_inline_ranges(ranges: dict[str, Any], path: Path) -> dict[str, Any]:
    check_keys(ranges, RANGE_KEYS, f"{path}: ranges")
    for key, value in ranges.items():
        if key == "sensor_quality":
            if not (isinstance(value, list) and value):
                raise ConfigError(f"{path}: ranges.sensor_quality = {value!r}; expected a list of quality names")
            continue
        if not (isinstance(value, list) and len(value) == 2 and all(isinstance(v, (int, float)) for v in value)
                and value[0] <= value[1]):
            raise ConfigError(f"{path}: ranges.{key} = {value!r}; expected [low, high] with low <= high")
    return dict(ranges)
