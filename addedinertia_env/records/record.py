"""Run records, format ``addedinertia-run/1`` (``docs/RUN_RECORD.md``).

One experiment is a CSV of samples plus a JSON of metadata with the same stem. Readers
refuse bad input with the file, the line or column, the value and what was expected;
they never drop rows. Writers are atomic: a temporary file in the same folder, then an
``os.replace`` to the final name.

Estimators read ``record.known`` (the typed ``rig`` block) and ``record.experiment``; only scoring reads
``record.truth_lambda66`` (simulated runs).
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from addedinertia_env.foundation.atomic import atomic_write_texts
from addedinertia_env.rig.known import CURRENT_SAMPLING, DEFAULT_CURRENT_SAMPLING, RIG_BLOCK, KnownRig, block_problems  # noqa: F401
from addedinertia_env.records.run_record import SAMPLE_RATE_RANGE, RecordError, RunRecord, Sampling, measure_sampling  # noqa: F401 - re-exported: most  # callers import them from here

FORMAT = "addedinertia-run/1"
PHASES = ("free", "hold", "reverse", "idle")
REQUIRED_COLUMNS = ("t", "phase", "phi", "psi", "u", "i")
OPTIONAL_NUMERIC_COLUMNS = ("u_cmd", "i_cmd", "brake")
# The ``rig`` block's keys are declared once, in :data:`~addedinertia_env.rig.known.RIG_BLOCK`
# (shared with KnownRig and the bench's lab file); these names are views of that table.
REQUIRED_RIG_KEYS = tuple(key.name for key in RIG_BLOCK if key.required)
POSITIVE_RIG_KEYS = tuple(key.name for key in RIG_BLOCK if key.required and key.bound == "positive")
# What each required ``rig`` key holds, for error messages.
RIG_KEY_MEANING = {key.name: key.meaning for key in RIG_BLOCK if key.required}
# ``rig.current_sampling``: how a logged current sample relates to the true current
# (CURRENT_SAMPLING, documented at RIG_BLOCK); absent: DEFAULT_CURRENT_SAMPLING. Discovery
# also estimates it from the flywheel channel and reports what it used.

EXPERIMENT_KINDS = ("reverse-symmetric", "free-decay", "forced-oscillation")
SOURCES = ("sim", "emulator", "bench")
MAX_GAP_PERIODS = 5.0


# --- writing -----------------------------------------------------------------------

_atomic_write_texts = atomic_write_texts  # the CSV and the JSON are replaced together


def _atomic_write_text(path: Path, text: str) -> None:
    _atomic_write_texts([(path, text)])


def write_record(record: RunRecord, csv_path: str | os.PathLike) -> Path:
    """Write ``record`` as ``STEM.csv`` + ``STEM.json``; returns the CSV path."""
    csv_path = Path(csv_path)
    if csv_path.suffix != ".csv":
        raise RecordError(f"{csv_path}: expected a run record's sample file name ending in .csv")
    cols = list(record.samples)
    missing = [c for c in REQUIRED_COLUMNS if c not in cols]
    if missing:
        raise RecordError(f"{csv_path}: cannot write a record without columns {missing}; "
                          f"expected at least {list(REQUIRED_COLUMNS)}")
    n = len(record.samples["t"])
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(cols)
    columns = [record.samples[c] for c in cols]
    for k in range(n):
        w.writerow([_fmt(col[k]) for col in columns])
    meta = dict(record.meta)
    meta.setdefault("format", FORMAT)
    meta.setdefault("run_id", csv_path.stem)
    # Both files are written in full before either final name changes (JSON renamed
    # first, then CSV): a crash while writing leaves an older record whole.
    _atomic_write_texts([(csv_path.with_suffix(".json"), json.dumps(meta, indent=2, sort_keys=False) + "\n"),
                         (csv_path, buf.getvalue())])
    record.path = csv_path
    return csv_path


def _fmt(v: Any) -> str:
    if isinstance(v, (str, np.str_)):
        return str(v)
    if isinstance(v, (bool, np.bool_)):
        return "1" if v else "0"
    return repr(float(v))


# --- reading -----------------------------------------------------------------------

def read_record(path: str | os.PathLike) -> RunRecord:
    """Read and validate a record from its CSV path (or its JSON path)."""
    path = Path(path)
    if path.suffix == ".json":
        csv_path, json_path = path.with_suffix(".csv"), path
    elif path.suffix == ".csv":
        csv_path, json_path = path, path.with_suffix(".json")
    else:
        raise RecordError(f"{path}: expected a run record's .csv (or .json) file")
    if not csv_path.exists() and not json_path.exists():
        raise RecordError(f"{path}: no such file; "
                          f"expected a run record {csv_path.name} with {json_path.name} beside it")
    if not json_path.exists():
        raise RecordError(f"{csv_path}: no matching metadata file {json_path.name} beside it; "
                          "expected a CSV and a JSON file with the same stem")
    if not csv_path.exists():
        raise RecordError(f"{json_path}: no matching sample file {csv_path.name} beside it; "
                          "expected a CSV and a JSON file with the same stem")
    meta = _read_meta(json_path)
    samples = _read_samples(csv_path)
    gaps = _check_samples(csv_path, samples, meta)
    record = RunRecord(samples=samples, meta=meta, path=csv_path, gaps=gaps)
    # Physically possible for its own rig block (docs/RELIABILITY.md): the plausibility check, whose
    # limits stay in the record's views beside its typed rig and phase blocks.
    record.views.limits  # noqa: B018
    return record


def _read_meta(json_path: Path) -> dict[str, Any]:
    try:
        meta = json.loads(json_path.read_text(encoding="utf-8-sig"))
    except json.JSONDecodeError as e:
        raise RecordError(f"{json_path}: line {e.lineno} column {e.colno}: not valid JSON ({e.msg})") from None
    except UnicodeDecodeError:
        raise RecordError(f"{json_path}: not UTF-8 text; expected a JSON file") from None
    except OSError as e:
        raise RecordError(f"{json_path}: cannot read ({e.strerror}); expected a readable JSON file") from None
    if not isinstance(meta, dict):
        raise RecordError(f"{json_path}: expected a JSON object at the top level, got {type(meta).__name__}")
    expected_top = {"format": f"{FORMAT!r}", "rig": "an object of rig constants",
                    "experiment": "an object with 'kind'"}
    for key, what in expected_top.items():
        if key not in meta:
            raise RecordError(f"{json_path}: missing key '{key}'; expected {what}")
    if meta["format"] != FORMAT:
        raise RecordError(f"{json_path}: key 'format' is {meta['format']!r}; expected {FORMAT!r}, "
                          "the only format this reader knows")
    if "source" in meta and meta["source"] not in SOURCES:
        raise RecordError(f"{json_path}: key 'source' is {meta['source']!r}; expected one of {SOURCES}")
    rig = meta["rig"]
    if not isinstance(rig, dict):
        raise RecordError(f"{json_path}: key 'rig' must be an object, got {rig!r}; expected an object of rig constants")
    for where, shown, expected in block_problems(rig):  # the first, as the schema orders them
        if expected == "missing":
            raise RecordError(f"{json_path}: missing key 'rig.{where}'; expected a number ({RIG_KEY_MEANING[where]})")
        raise RecordError(f"{json_path}: key 'rig.{where}' is {shown}; expected {expected}")
    exp = meta["experiment"]
    if not isinstance(exp, dict):
        raise RecordError(f"{json_path}: key 'experiment' must be an object, got {exp!r}; "
                          "expected an object with 'kind'")
    if "kind" not in exp:
        raise RecordError(f"{json_path}: missing key 'experiment.kind'; expected one of {EXPERIMENT_KINDS}")
    if exp["kind"] not in EXPERIMENT_KINDS:
        raise RecordError(f"{json_path}: key 'experiment.kind' is {exp['kind']!r}; expected one of {EXPERIMENT_KINDS}")
    phi1 = exp.get("phi1")
    if phi1 is not None and (not isinstance(phi1, list) or not all(
            isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) and abs(x) <= 2 * math.pi
            for x in phi1)):
        raise RecordError(f"{json_path}: key 'experiment.phi1' is {phi1!r}; expected a list of angles in rad, |angle| <= 2 pi")
    return meta


def _read_samples(csv_path: Path) -> dict[str, np.ndarray]:
    try:
        text = csv_path.read_text(encoding="utf-8-sig")  # a DAQ's byte-order mark is not part of the header
    except UnicodeDecodeError:
        raise RecordError(f"{csv_path}: not UTF-8 text; expected a CSV file") from None
    except OSError as e:
        raise RecordError(f"{csv_path}: cannot read ({e.strerror}); expected a readable CSV file") from None
    rows = list(csv.reader(io.StringIO(text)))
    if not rows:
        raise RecordError(f"{csv_path}: empty file; expected a header row with {list(REQUIRED_COLUMNS)}")
    header = [h.strip() for h in rows[0]]
    if len(set(header)) != len(header):
        dup = sorted({h for h in header if header.count(h) > 1})
        raise RecordError(f"{csv_path}: line 1: duplicate column(s) {dup}; expected each column once")
    missing = [c for c in REQUIRED_COLUMNS if c not in header]
    if missing:
        raise RecordError(f"{csv_path}: line 1: missing required column(s) {missing}; "
                          f"expected at least {list(REQUIRED_COLUMNS)}, header is {header}")
    body = rows[1:]
    while body and not any(c.strip() for c in body[-1]):  # blank lines at the end of the file
        body.pop()
    if not body:
        raise RecordError(f"{csv_path}: header only; expected at least one sample row")
    for k, row in enumerate(body):
        if len(row) != len(header):
            raise RecordError(f"{csv_path}: line {k + 2}: {len(row)} fields, expected {len(header)} as in the header")
    columns = list(zip(*body))
    samples: dict[str, np.ndarray] = {}
    for name, col in zip(header, columns):
        if name == "phase":
            arr = np.array([c.strip() for c in col], dtype=object).astype(str)
            bad = ~np.isin(arr, PHASES)
            if bad.any():
                k = int(np.argmax(bad))
                raise RecordError(f"{csv_path}: line {k + 2}, column 'phase': {arr[k]!r}; expected one of {PHASES}")
            samples[name] = arr
            continue
        numeric = name in REQUIRED_COLUMNS or name in OPTIONAL_NUMERIC_COLUMNS
        try:
            arr = np.array(col, dtype=float)
        except ValueError:
            if not numeric:
                samples[name] = np.array(col, dtype=object).astype(str)  # kept, unused
                continue
            for k, c in enumerate(col):
                try:
                    float(c)
                except ValueError:
                    raise RecordError(f"{csv_path}: line {k + 2}, column '{name}': {c!r} is not a number; "
                                      "expected a finite number") from None
            raise
        if numeric and not np.all(np.isfinite(arr)):
            k = int(np.argmax(~np.isfinite(arr)))
            raise RecordError(f"{csv_path}: line {k + 2}, column '{name}': {col[k]!r}; expected a finite number")
        samples[name] = arr
    return samples


def _check_samples(csv_path: Path, s: dict[str, np.ndarray], meta: dict) -> list[tuple[float, float]]:
    t = s["t"]
    dt = np.diff(t)
    if np.any(dt <= 0):
        k = int(np.argmax(dt <= 0))
        raise RecordError(f"{csv_path}: line {k + 3}, column 't': {t[k + 1]!r} after {t[k]!r}; "
                          "expected strictly increasing sample times")
    for name in ("phi",):
        big = np.abs(s[name]) > 2 * math.pi
        if big.any():
            k = int(np.argmax(big))
            raise RecordError(f"{csv_path}: line {k + 2}, column '{name}': {s[name][k]!r} rad; expected |phi| <= 2 pi "
                              "(hull yaw in radians, not degrees or counts?)")
    if "brake" in s:
        bad = ~np.isin(s["brake"], (0.0, 1.0))
        if bad.any():
            k = int(np.argmax(bad))
            raise RecordError(f"{csv_path}: line {k + 2}, column 'brake': {s['brake'][k]!r}; expected 0 or 1")
    period = KnownRig.from_block(meta["rig"]).dt
    # A relative 1e-6 keeps rounding in stored times (0.013 - 0.008 > 0.005) from flagging
    # a step of exactly five periods.
    gaps = [(float(t[k]), float(dt[k])) for k in np.nonzero(dt > MAX_GAP_PERIODS * period * (1 + 1e-6))[0]]
    return gaps


# --- sampling and segmentation (what every method reads instead of assuming) ----------

def sampling(record: RunRecord) -> Sampling:
    """How ``record`` was sampled: jitter, dropped samples, gaps (never assumed uniform); the record's
    ``views.sampling``, measured once."""
    return record.views.sampling


def braked(record: RunRecord) -> np.ndarray:
    """Boolean per sample: the hull is held (``brake`` = 1, or phase ``hold``)."""
    held = record.phase == "hold"
    if "brake" in record.samples:
        held = held | (np.asarray(record["brake"]) == 1.0)
    return held


def motion_phase(record: RunRecord) -> np.ndarray:
    """The phase of each sample as the hull experienced it: ``phase`` and ``brake`` together.

    A braked sample is never free or controlled motion, whatever its ``phase`` says
    (run-record.md): braked ``free``/``reverse`` samples become ``hold`` when they lie
    between the first free-motion sample and the last reverse-motion sample (the hull
    held at the reversal), else ``idle`` (set-up before release, a braked tail after the
    reverse stroke). Where there is no ``brake`` column the ``phase`` column is taken as is.
    """
    phase = np.asarray(record.phase).astype(object).copy()
    if "brake" not in record.samples:
        return phase.astype(str)
    held = np.asarray(record["brake"]) == 1.0
    moving = ~held & np.isin(phase, ("free", "reverse"))
    idx = np.nonzero(moving)[0]
    relabel = held & np.isin(phase, ("free", "reverse"))
    if idx.size:
        inside = (np.arange(len(phase)) > idx[0]) & (np.arange(len(phase)) < idx[-1])
        phase[relabel & inside] = "hold"
        phase[relabel & ~inside] = "idle"
    else:
        phase[relabel] = "idle"
    return phase.astype(str)


def rig_inductance(rig: dict[str, Any] | KnownRig) -> float | None:
    """Winding inductance ``L`` (H) from a rig block: 0.0 when neglected, None when unknown (absent)."""
    return _typed(rig).L


def current_sampling(rig: dict[str, Any] | KnownRig) -> tuple[str, bool]:
    """How the current was logged (one of :data:`CURRENT_SAMPLING`) and whether the rig block said so."""
    known = _typed(rig)
    return known.current_sampling_used, known.current_sampling is not None


def _typed(rig: dict[str, Any] | KnownRig) -> KnownRig:
    return rig if isinstance(rig, KnownRig) else KnownRig.from_block(rig)
