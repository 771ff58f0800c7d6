"""Options of the reverse-stroke environment, validated in one place.

Every option is checked when the environment is built and again when ``reset(options=)``
changes it; a bad value raises ``ValueError`` naming the option, the value that came and
what was expected. Scenario options (what the next episode's rig and experiment are) may
change at each reset; the others fix the meaning of actions and rewards and may not.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from addedinertia_env.sim.presets import SENSOR_QUALITY, ConfigError, available_rigs, rig_path
from addedinertia_env.experiment.scenarios import RANGE_KEYS, Scenario, load_ranges, make_scenario
from addedinertia_env.experiment.task import CONTROL_MODES, RewardWeights

MAX_HOLD_S = 10.0  # s, longest hold the environment accepts (keeps episodes under the step limit)
MAX_ACTION_REPEAT = 1000  # samples per action: one second at 1 kHz

# Scenario quantities that may be randomised or pinned: check, what is expected.
_DOMAINS: dict[str, tuple[Any, str]] = {
    "lambda_ratio": (lambda v: v > 0, "a ratio lambda66 / J_hull > 0"),
    "drag_coefficient": (lambda v: v > 0, "a cross-flow drag coefficient > 0"),
    "b1": (lambda v: v >= 0, "a linear damping >= 0 N m s"),
    "period_s": (lambda v: v > 0, "a natural period > 0 s"),
    "J_flywheel": (lambda v: v > 0, "a flywheel inertia > 0 kg m^2"),
    "k_t": (lambda v: v > 0, "a torque constant > 0 N m/A"),
    "alpha": (lambda v: 0 < abs(v) < 1, "a twist 0 < |alpha| < 1 rad"),
    "hold_s": (lambda v: 0 <= v <= MAX_HOLD_S, f"a hold time in [0, {MAX_HOLD_S}] s"),
}
SCENARIO_OPTIONS = ("preset", "randomize", "ranges", "fixed", "sensor_quality", "hold_s", "alpha", "scenario_seed")


def _bad(option: str, value: Any, expected: str) -> ValueError:
    return ValueError(f"ReverseStrokeEnv option {option}={value!r}: expected {expected}")


def _is_number(v: Any) -> bool:
    return not isinstance(v, bool) and isinstance(v, (int, float)) and math.isfinite(v)


def _check_value(option: str, key: str, value: Any) -> None:
    if key == "sensor_quality":
        if value not in SENSOR_QUALITY:
            raise _bad(option, value, f"a sensor quality, one of {SENSOR_QUALITY}")
        return
    check, expected = _DOMAINS[key]
    if not (_is_number(value) and check(value)):
        raise _bad(option, value, expected)


def _check_keys(option: str, mapping: Any) -> None:
    if not isinstance(mapping, Mapping):
        raise _bad(option, mapping, f"a mapping with keys among {sorted(RANGE_KEYS)}")
    unknown = sorted(set(mapping) - RANGE_KEYS)
    if unknown:
        raise _bad(option, dict(mapping), f"keys among {sorted(RANGE_KEYS)}; unknown: {unknown}")


def check_ranges(ranges: Any) -> dict[str, Any]:
    """``ranges``: key -> [low, high] (``sensor_quality``: a non-empty list of qualities)."""
    _check_keys("ranges", ranges)
    out: dict[str, Any] = {}
    for key, value in ranges.items():
        opt = f"ranges[{key!r}]"
        if key == "sensor_quality":
            if not (isinstance(value, (list, tuple)) and value):
                raise _bad(opt, value, f"a non-empty list of sensor qualities among {SENSOR_QUALITY}")
            for q in value:
                _check_value(opt, key, q)
            out[key] = list(value)
            continue
        if not (isinstance(value, (list, tuple)) and len(value) == 2 and all(_is_number(v) for v in value)
                and value[0] <= value[1]):
            raise _bad(opt, value, "[low, high], two finite numbers with low <= high")
        for v in value:
            _check_value(opt, key, v)
        if key == "alpha" and value[0] * value[1] <= 0:
            raise _bad(opt, value, "both ends of one sign (the twist's direction)")
        out[key] = [float(value[0]), float(value[1])]
    return out


@dataclass(frozen=True)
class EnvConfig:
    """What the environment does; see :class:`~addedinertia_env.envs.ReverseStrokeEnv`."""

    preset: str = "wigley-2m"  # rig preset name (configs/rigs/) or a path to a .yaml
    randomize: bool = True  # draw the scenario from configs/randomization.yaml (+ ``ranges``)
    ranges: Mapping[str, Any] = field(default_factory=dict)  # overrides of randomization.yaml
    fixed: Mapping[str, Any] = field(default_factory=dict)  # scenario values pinned
    sensor_quality: str | None = None  # pins the sensor set (ideal, good, realistic, poor)
    hold_s: float | None = None  # s, pins the brake hold
    alpha: float | None = None  # rad, pins the twist (amplitude) before release
    scenario_seed: int | None = None  # runs scenario number ``scenario_seed`` (else drawn from np_random)
    action_repeat: int = 1  # rig samples per action (1 = 1 kHz control)
    control_mode: str = "current"  # the action is a current ("current") or voltage ("voltage") command
    reward_weights: RewardWeights = field(default_factory=RewardWeights)

    def __post_init__(self) -> None:
        if not isinstance(self.preset, str) or not self.preset:
            raise _bad("preset", self.preset, f"a rig preset name, one of {available_rigs()}, or a .yaml path")
        try:
            rig_path(self.preset)
        except ConfigError:
            raise _bad("preset", self.preset, f"a rig preset name, one of {available_rigs()}, or a .yaml path") from None
        if not isinstance(self.randomize, bool):
            raise _bad("randomize", self.randomize, "True or False")
        object.__setattr__(self, "ranges", check_ranges(self.ranges))
        if self.ranges and not self.randomize:
            raise _bad("ranges", dict(self.ranges), "no ranges when randomize=False (or set randomize=True)")
        _check_keys("fixed", self.fixed)
        for key, value in self.fixed.items():
            _check_value(f"fixed[{key!r}]", key, value)
        object.__setattr__(self, "fixed", dict(self.fixed))
        for key in ("sensor_quality", "hold_s", "alpha"):
            value = getattr(self, key)
            if value is not None:
                _check_value(key, key, value)
        seed = self.scenario_seed
        if seed is not None and not (isinstance(seed, int) and not isinstance(seed, bool) and seed >= 0):
            raise _bad("scenario_seed", seed, "None or an integer >= 0")
        r = self.action_repeat
        if not (isinstance(r, int) and not isinstance(r, bool) and 1 <= r <= MAX_ACTION_REPEAT):
            raise _bad("action_repeat", r, f"an integer number of samples per action in [1, {MAX_ACTION_REPEAT}]")
        if self.control_mode not in CONTROL_MODES:
            raise _bad("control_mode", self.control_mode, f"one of {CONTROL_MODES}")
        w = self.reward_weights
        if isinstance(w, Mapping):
            try:
                w = RewardWeights.from_mapping(dict(w))
            except (TypeError, ValueError) as e:
                raise _bad("reward_weights", dict(self.reward_weights), f"weights of the terms ({e})") from None
        if not isinstance(w, RewardWeights):
            raise _bad("reward_weights", w, "a RewardWeights or a mapping term -> weight")
        object.__setattr__(self, "reward_weights", w)

    def with_options(self, options: Mapping[str, Any] | None) -> "EnvConfig":
        """This config with reset ``options`` applied (scenario options only), validated."""
        if not options:
            return self
        if not isinstance(options, Mapping):
            raise _bad("options", options, f"None or a mapping with keys among {SCENARIO_OPTIONS}")
        unknown = sorted(set(options) - set(SCENARIO_OPTIONS))
        if unknown:
            raise _bad("options", dict(options), f"reset options among {SCENARIO_OPTIONS} "
                       f"(the others are fixed when the environment is made); unknown: {unknown}")
        return dataclasses.replace(self, **options)

    def pinned(self) -> dict[str, Any]:
        """Scenario values pinned by ``fixed`` and the shortcut options."""
        out = dict(self.fixed)
        for key in ("sensor_quality", "hold_s", "alpha"):
            if getattr(self, key) is not None:
                out[key] = getattr(self, key)
        return out

    def scenario(self, seed: int, default_ranges: Mapping[str, Any] | None = None) -> Scenario:
        """Scenario number ``seed`` under this config (``default_ranges``: randomization.yaml)."""
        if self.randomize:
            base = load_ranges() if default_ranges is None else default_ranges
            ranges = {**base, **self.ranges}
        else:
            ranges = {}
        return make_scenario(seed, preset=self.preset, ranges=ranges, fixed=self.pinned())
