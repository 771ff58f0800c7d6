"""Examples that run (issue 31): every ``sh`` and ``python`` block of README.md and docs/*.md,
and every indented command line, is either run here as written or listed in ``NOT_RUN``
with the reason. A new block that is neither fails :func:`test_every_example_is_run_or_excused`.

The commands run in a temporary folder laid out like a clone (the package folders linked,
an empty ``docs/figures`` so that what they write stays out of the repository), with
``addedinertia`` and ``python`` from the interpreter running the tests. Where a document
shows a command's output, the numbers shown are checked against the run's:

* a ``# {...}`` line under a command (README's worked example): each key shown with a
  number must be in the command's JSON, integers equal, other numbers within 1e-3
  relative;
* SUBMITTING.md's example: the ``json`` block after it: ``rows`` and ``failures`` equal,
  ``median_abs_error`` within 1e-4 absolute (the estimate's last digits differ between
  CPUs' floating-point kernels; the doc says so).
"""

from __future__ import annotations

import json
import os
import re
import shlex
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
LINKED = ("addedinertia_env", "agents", "configs", "hw_adapter", "firmware")


@dataclass
class Example:
    doc: str  # README.md or docs/NAME.md
    line: int  # first line of the block in the document
    lang: str  # sh or python
    text: str
    marker: str = ""  # an <!-- example-...: ... --> comment on the line before the fence

    @property
    def key(self) -> str:
        """What identifies the block across edits: its document and its first command line."""
        first = next(ln for ln in self.text.splitlines() if ln.strip() and not ln.lstrip().startswith("#"))
        return f"{self.doc}: {first.strip()}"


FENCE = re.compile(r"^(\s*)```(\w*)\s*$")


def extract(path: Path) -> tuple[list[Example], dict[str, str]]:
    """The sh/python blocks (fenced, or indented lines starting with a command) of ``path``,
    and the fenced files it names with ``<!-- example-file: NAME -->``; json blocks following an
    ``example-output`` marker are kept under the key ``output:MARKER``."""
    doc = str(path.relative_to(ROOT))
    lines = path.read_text().splitlines()
    examples, files = [], {}
    k = 0
    pending_output = None
    while k < len(lines):
        m = FENCE.match(lines[k])
        if m:
            lang, start = m.group(2), k
            marker = lines[k - 1].strip() if k and lines[k - 1].strip().startswith("<!-- example-") else ""
            k += 1
            body = []
            while k < len(lines) and not FENCE.match(lines[k]):
                body.append(lines[k][len(m.group(1)):])
                k += 1
            text = "\n".join(body) + "\n"
            if marker.startswith("<!-- example-file:"):
                files[marker.split(":", 1)[1].strip(" ->")] = text
            elif lang in ("sh", "python"):
                examples.append(Example(doc, start + 1, lang, text, marker))
                if marker.startswith("<!-- example-output:"):
                    pending_output = marker.split(":", 1)[1].strip(" ->")
            elif lang == "json" and pending_output:
                files[f"output:{pending_output}"] = text
                pending_output = None
        elif re.match(r"^    (mkdir -p \S+ && )?(addedinertia|python -m) ", lines[k]) and (k == 0 or not lines[k - 1].startswith("    ")):
            examples.append(Example(doc, k + 1, "sh", lines[k].strip() + "\n"))
        k += 1
    return examples, files


EXAMPLES: list[Example] = []
FILES: dict[str, str] = {}
for _doc in DOCS:
    _ex, _files = extract(_doc)
    EXAMPLES += _ex
    FILES.update(_files)

# Blocks not run, each with why. Keyed as Example.key (the document and the block's first command line).
MEASURED = "reproduces the doc's measured figures (minutes on the wall clock, busy processes or real-time priority)"
NOT_RUN = {
    "README.md: make demo   # creates .venv, installs everything (CPU torch), runs the main job":
        "creates a virtual environment and installs from PyPI; its job, `addedinertia demo`, is "
        "test_make_demo_job_runs, and the test suite is what runs here",
    "docs/SUBMITTING.md: class MyController:":
        "a skeleton (bodies are `...`); the complete example below it is run",
    "docs/SUBMITTING.md: export PYTHONPATH=/path/to/your/package:$PYTHONPATH":
        "a template (my_pkg.my_module is the reader's); the complete example is run",
    "docs/BENCH.md: addedinertia bench-server --port 5555 --rig wigley-2m --realtime":
        "needs a bench on a serial port (/dev/ttyUSB0) or a server left running; tests/test_deploy.py "
        "runs deploy through the emulator",
    "docs/BENCH.md: .venv/bin/python -m hw_adapter.measure --watchdog-ms 100 --board-watchdog-ms 200 "
    "--out out/bench-figures.json": MEASURED,
    "docs/BENCH.md: python -m hw_adapter.measure --host-rate-hz 100 --controller lqr --repeat 3 --only nominal "
    "--out out/bench-two-rate-idle.json": MEASURED,
    "docs/BENCH.md: python -m hw_adapter.measure --host-rate-hz 100 --policy agents/policies/reverse_stroke_100hz.onnx "
    "--repeat 3 --only nominal --out out/bench-policy-100hz-shared.json": MEASURED,
    "docs/BENCH.md: python -m hw_adapter.measure --host-rate-hz 100 --policy agents/policies/reverse_stroke_100hz.onnx "
    "--repeat 3 --only nominal --out out/bench-policy-100hz-idle.json": MEASURED,
    "docs/BENCH.md: python -m hw_adapter.measure --host-rate-hz 100 --controller lqr --repeat 3 --only nominal "
    "--out out/bench-two-rate.json": MEASURED,
    "docs/INSTALL.md: python3.11 -m venv .venv": "a GPU install: needs CUDA and PyPI",
    "docs/INSTALL.md: .venv/bin/pip install -e '.[hull]'": "installs optional packages from PyPI",
    "docs/LEARNING.md: addedinertia train --algo ppo|sac|td3|recurrent-ppo [--config FILE] [--timesteps N] [--seed N]":
        "a usage synopsis, not a command; tests/test_learning.py runs short trainings",
    "docs/LEARNING.md: addedinertia export out/train/ppo-residual --onnx agents/policies/reverse_stroke.onnx [--json]":
        "a synopsis that needs the run of `make policy` (20 min) and overwrites the shipped policy; "
        "tests/test_export.py exports a trained model",
    "docs/LEARNING.md: addedinertia bench run --suite standard-v0 --split test --controller "
    "onnx:agents/policies/reverse_stroke.onnx \\":
        "the leaderboard's rows (the whole test split, minutes); SUBMITTING.md's example runs bench run",
    "docs/DATASETS.md: import minari":
        "loads the dataset the `--simulate 100` block above writes (each block runs in its own folder); "
        "tests/test_minari_export.py writes one and loads it back with Minari, replaying its score",
    "docs/DATASETS.md: import xarray as xr":
        "reads the file the `hull --netcdf` block above writes (each block runs in its own folder); "
        "tests/test_hull_netcdf.py writes such a file and loads it with xarray",
    "docs/CONTROLLERS.md: addedinertia bench tune --suite standard-v0 --controller NAME --candidates 6 --scenarios 6 "
    "--seed 0": "NAME is the reader's; tests/test_controllers.py runs the tuning",
}
# Blocks run only with the slow tests (seconds of CPU each command, minutes in all).
SLOW = {
    "README.md: source .venv/bin/activate",
    "docs/BENCH.md: .venv/bin/python -m hw_adapter.measure --out out/bench-figures.json          # 25 s",
    "docs/RADIATION_MEMORY.md: addedinertia hull wigley-2m --fit-memory      # fits the cached sweep; no BEM solve, ~2 s",
    "docs/DATASETS.md: addedinertia dataset export --simulate 100 --controller feedforward-pd --minari "
    "addedinertia/ffpd-sim-v0",
}


def _clone(tmp_path: Path) -> Path:
    """A folder laid out like a clone: the package folders linked, docs/figures empty."""
    for name in LINKED:
        if (ROOT / name).exists():
            (tmp_path / name).symlink_to(ROOT / name)
    (tmp_path / "docs" / "figures").mkdir(parents=True)
    return tmp_path


def _env(cwd: Path | None = None) -> dict[str, str]:
    """The environment of an example: this interpreter's bin first, the checkout importable, no screen, and
    Minari's datasets (docs/DATASETS.md) in the example's own folder, never the user's ``~/.minari``."""
    bindir = str(Path(sys.executable).parent)
    env = {**os.environ, "PATH": bindir + os.pathsep + os.environ.get("PATH", ""),
           "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""), "MPLBACKEND": "Agg"}
    if cwd is not None:
        env["MINARI_DATASETS_PATH"] = str(cwd / ".minari")
    return env


def _commands(text: str) -> list[tuple[str, str | None]]:
    """(command, the ``# {...}`` output shown under it or None), continuation lines joined."""
    out: list[tuple[str, str | None]] = []
    for line in text.replace("\\\n", " ").splitlines():
        s = line.strip()
        if not s:
            continue
        if s.startswith("# {"):
            if out:
                out[-1] = (out[-1][0], s[2:])
            continue
        if s.startswith("#") or s.startswith("source .venv/bin/activate"):
            continue
        s = re.sub(r"^\.venv/bin/", "", s)
        out.append((s, None))
    return out


def _check_shown(shown: str, stdout: str, command: str) -> None:
    """The numbers a doc shows under a command against what it printed."""
    got = json.loads(stdout)
    for key, value in re.findall(r'"(\w+)": (-?\d[\d.eE+-]*)', shown):
        assert key in got, f"{command}: the doc shows {key!r}, the output has none"
        if re.fullmatch(r"-?\d+", value):
            assert got[key] == int(value), f"{command}: the doc shows {key} = {value}, the run gave {got[key]}"
        else:
            assert got[key] == pytest.approx(float(value), rel=1e-3), (command, key, value, got[key])


def _run_sh(example: Example, cwd: Path) -> list[subprocess.CompletedProcess]:
    done = []
    for command, shown in _commands(example.text):
        proc = subprocess.run(["bash", "-c", command], cwd=cwd, env=_env(cwd), capture_output=True, text=True,
                              timeout=900)
        assert proc.returncode == 0, (f"{example.doc} line {example.line}: `{command}` exited {proc.returncode}\n"
                                      f"{proc.stderr[-2000:]}")
        if shown is not None:
            _check_shown(shown, proc.stdout, command)
        done.append(proc)
    return done


def _run(example: Example, tmp_path: Path) -> list[subprocess.CompletedProcess]:
    cwd = _clone(tmp_path)
    for name, text in FILES.items():
        if not name.startswith("output:"):
            (cwd / name).write_text(text)
    if example.lang == "python":
        proc = subprocess.run([sys.executable, "-c", example.text], cwd=cwd, env=_env(cwd), capture_output=True,
                              text=True, timeout=900)
        assert proc.returncode == 0, f"{example.doc} line {example.line}:\n{proc.stderr[-2000:]}"
        assert "Traceback" not in proc.stderr, proc.stderr[-2000:]  # nothing at interpreter exit either
        return [proc]
    return _run_sh(example, cwd)


def _to_run(slow: bool) -> list[Example]:
    return [e for e in EXAMPLES if e.key not in NOT_RUN and (e.key in SLOW) == slow]


def test_every_example_is_run_or_excused():
    keys = {e.key for e in EXAMPLES}
    assert len(EXAMPLES) >= 20, [e.key for e in EXAMPLES]  # the extraction finds the documents' blocks
    assert not (set(NOT_RUN) | SLOW) - keys, f"stale entries (no such block any more): {(set(NOT_RUN) | SLOW) - keys}"
    assert "my_controller.py" in FILES and "output:my_controller" in FILES


def test_extraction_finds_commands_and_shown_output():
    ex, files = extract(ROOT / "docs" / "SUBMITTING.md")
    assert any("my_controller:make" in e.text and e.marker for e in ex)
    assert json.loads(files["output:my_controller"])["rows"] == 3
    cmds = _commands("a --x \\\n  --y\n# {\"n\": 15, \"m\": ...}\n# note\nb\n")
    assert cmds == [("a --x    --y", '{"n": 15, "m": ...}'), ("b", None)]
    with pytest.raises(AssertionError, match="shows n = 15"):
        _check_shown('{"n": 15}', '{"n": 123}', "cmd")


@pytest.mark.parametrize("example", _to_run(slow=False), ids=lambda e: f"{e.doc}:{e.line}")
def test_example_runs(example, tmp_path):
    procs = _run(example, tmp_path)
    if example.marker.startswith("<!-- example-output:"):
        name = example.marker.split(":", 1)[1].strip(" ->")
        shown, got = json.loads(FILES[f"output:{name}"]), json.loads(procs[-1].stdout)
        assert got["rows"] == shown["rows"] and got["failures"] == shown["failures"], (got, shown)
        assert abs(got["median_abs_error"] - shown["median_abs_error"]) <= 1e-4, (got, shown)


@pytest.mark.slow
@pytest.mark.parametrize("example", _to_run(slow=True), ids=lambda e: f"{e.doc}:{e.line}")
def test_slow_example_runs(example, tmp_path):
    _run(example, tmp_path)


@pytest.mark.slow
def test_make_demo_job_runs(tmp_path):
    """What `make demo` runs once the environment is installed (the Makefile's demo target)."""
    text = (ROOT / "Makefile").read_text()
    job = re.search(r"^demo:.*\n\t\$\(BIN\)/(addedinertia .*)$", text, re.M).group(1)
    proc = subprocess.run(shlex.split(job), cwd=_clone(tmp_path), env=_env(), capture_output=True, text=True,
                          timeout=900)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert (tmp_path / "out" / "demo" / "demo.png").exists()
