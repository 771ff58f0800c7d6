"""Reading configuration files (YAML) with one kind of refusal: :class:`ConfigError` naming the file.

A rig preset, suite, randomisation range, lab or training config that is missing,
unreadable, not UTF-8 or not valid YAML gives a one-line message with the file and what
was expected, never a ``UnicodeDecodeError`` or ``yaml`` traceback.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Iterable

import yaml

import addedinertia_env as _package

# The repository's configs/ folder: presets (rigs/), suites, ranges, algorithms, tuned gains.
# Found from the package's root so that it holds wherever this module sits in the package.
CONFIG_DIR = Path(_package.__file__).resolve().parents[1] / "configs"
RIG_DIR = CONFIG_DIR / "rigs"  # the rig presets, each with its BEM cache PRESET.bem.json


class ConfigError(ValueError):
    """A configuration file or override that cannot be used; the message says how to fix it."""


def check_keys(block: Any, allowed: Iterable[str], where: str) -> dict[str, Any]:
    """``block`` itself if it is a mapping whose keys are all in ``allowed``; else ConfigError.

    ``where`` names the file and the block in the message (``"configs/rigs/x.yaml: hull"``);
    the message lists the unknown keys and the allowed ones. The loader's own ``_path``
    key is always allowed.
    """
    allowed = set(allowed)
    if not isinstance(block, dict):
        raise ConfigError(f"{where} = {block!r}: expected a mapping with keys from {sorted(allowed)}")
    unknown = sorted(map(str, set(block) - allowed - {"_path"}))
    if unknown:
        raise ConfigError(f"{where}: unknown key(s) {unknown}; allowed keys are {sorted(allowed)}")
    return block


MAX_CONFIG_BYTES = 1_000_000  # a configuration file is a few kB; beyond this it is not one


def read_yaml(path: str | Path, what: str = "configuration") -> Any:
    """The parsed YAML document of ``path`` (a ``what`` file); raises ConfigError naming the file."""

    path = Path(path)
    try:
        size = path.stat().st_size
        if size > MAX_CONFIG_BYTES:
            raise ConfigError(f"{path}: {size} bytes; expected a {what} YAML file of at most {MAX_CONFIG_BYTES} bytes")
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError as e:
        raise ConfigError(f"{path}: not UTF-8 text (byte {e.start}); expected a {what} YAML file") from None
    except IsADirectoryError:
        raise ConfigError(f"{path}: is a folder; expected a {what} YAML file") from None
    except OSError as e:
        raise ConfigError(f"{path}: cannot read ({e.strerror}); expected a readable {what} YAML file") from None
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError as e:
        where = getattr(e, "problem_mark", None)
        at = f"line {where.line + 1}: " if where is not None else ""
        raise ConfigError(f"{path}: {at}not valid YAML ({getattr(e, 'problem', None) or e}); "
                          f"expected a {what} YAML file") from None
