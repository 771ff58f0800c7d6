"""addedinertia decay: the textbook's nu reproduced, damping laws recovered, bad input refused."""

from __future__ import annotations

import contextlib
import io
import json
import math
from pathlib import Path

import numpy as np
import pytest

from addedinertia_env.cli import main
from addedinertia_env.decay import READING_RESOLUTION_DEG, analyse, envelope, law_nu

# The measured record ships with the package (addedinertia_env/data/textbook/README.md cites it).
DATA = Path(__file__).resolve().parents[1] / "addedinertia_env" / "data" / "textbook"
TEXTBOOK = DATA / "textbook_roll_decay.csv"
SHARED = next((p for p in (Path(__file__).resolve().parents[2] / "shared" / "data", Path("/work/shared/data"))
               if (p / "textbook_roll_decay.csv").exists()), None)


def run_json(args):
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        rc = main(args)
    return rc, (json.loads(out.getvalue()) if rc == 0 else None)


def test_textbook_columns_reproduced():
    rc, res = run_json(["decay", str(TEXTBOOK), "--json"])
    assert rc == 0
    pr = res["textbook"]["printed"]
    # printed to 3-4 significant digits: agreement to rounding of the printed values
    assert pr["check_nu_6_17"]["max_abs_diff"] < 5e-4
    assert pr["check_nu_6_18"]["max_abs_diff"] < 5e-4
    assert pr["check_dtheta_raw"]["max_abs_diff"] < 1e-9  # raw decrements are exact multiples of 0.1025
    assert pr["check_theta_mean"]["max_abs_diff"] < 5e-3
    assert res["law"] in {m["law"] for m in res["models"]}
    assert len(pr["nu_6_17_reproduced"]) == 18


def _series(law, theta0, params, n=19, noise=0.0, seed=0):
    """Amplitudes from an envelope law, read off to the trace's 0.1025 deg steps."""
    rng = np.random.default_rng(seed)
    th = envelope(law, theta0, params, np.arange(n)) + noise * rng.standard_normal(n)
    return np.round(th / READING_RESOLUTION_DEG) * READING_RESOLUTION_DEG


def _write(tmp_path, theta, swing=None, name="amp.csv"):
    swing = np.arange(1, len(theta) + 1) if swing is None else swing
    p = tmp_path / name
    p.write_text("swing,theta_deg\n" + "".join(f"{s},{float(t)!r}\n" for s, t in zip(swing, theta)))
    return p


@pytest.mark.parametrize("law,params", [
    ("linear", {"a": 0.06}),
    ("linear+quadratic", {"a": 0.02, "b": 0.004}),
    ("linear+coulomb", {"a": 0.03, "c": 0.25}),
])
def test_known_law_recovered(tmp_path, law, params):
    """30 amplitudes from 20 deg read to the trace resolution: the law and its coefficients come back."""
    theta = _series(law, 20.0, params, n=30)
    res = analyse(_write(tmp_path, theta))
    assert res["law"] == law
    best = res["models"][0]
    for k, v in params.items():
        lo, hi = best["ci95"][k]
        assert lo <= v <= hi, (k, v, best["ci95"][k])
    # nu implied by the law is the textbook's definition: 2/pi f(theta)/theta
    assert law_nu(law, params, 10.0) == pytest.approx(2 / math.pi * (params.get("a", 0) + params.get("b", 0) * 10
                                                                        + params.get("c", 0) / 10))


@pytest.mark.parametrize("text,expected", [
    ("swing,amplitude\n1,10\n2,9\n", "missing column"),
    ("swing,theta_deg\n1,10\n2,abc\n3,8\n4,7\n5,6\n", "'abc' is not a number"),
    ("swing,theta_deg\n1,10\n3,9\n4,8\n5,7\n6,6\n", "successive half swings"),
    ("swing,theta_deg\n1,10\n2,9\n2,8\n3,7\n4,6\n", "successive half swings"),
    ("swing,theta_deg\n1,10\n2,-9\n3,8\n4,7\n5,6\n", "amplitude > 0"),
    ("swing,theta_deg\n1,10\n2,9\n3,nan\n4,7\n5,6\n", "finite"),
    ("swing,theta_deg\n1,10\n2,9\n", "at least 5"),
    ("swing,theta_deg\n1,5\n2,6\n3,7\n4,8\n5,9\n", "decaying"),
])
def test_bad_input_exit_2(tmp_path, capsys, text, expected):
    p = tmp_path / "bad.csv"
    p.write_text(text)
    rc = main(["decay", str(p), "--json"])
    err = capsys.readouterr()
    assert rc == 2 and err.out == ""
    assert expected in err.err and str(p) in err.err


def test_missing_file_exit_2(tmp_path, capsys):
    assert main(["decay", str(tmp_path / "nope.csv")]) == 2
    assert "no such file" in capsys.readouterr().err


@pytest.mark.parametrize("content, expected", [
    (b"\xff\xfe\x00binary", "not UTF-8 text; expected the textbook's processing table"),
    (b"", "no rows; expected the textbook's processing table"),
])
def test_an_unreadable_processing_table_exit_2(tmp_path, capsys, content, expected):
    """The processing table is read as carefully as the amplitudes: one line naming the file, exit 2."""
    amplitudes = _write(tmp_path, _series("linear", 20.0, {"a": 0.02}, n=10))
    table = tmp_path / "table.csv"
    table.write_bytes(content)
    assert main(["decay", str(amplitudes), "--processing", str(table)]) == 2
    err = capsys.readouterr().err
    assert expected in err and str(table) in err and len(err.strip().splitlines()) == 1


def test_decay_textbook_option_reads_the_shipped_record():
    rc, res = run_json(["decay", "--textbook", "--json"])
    assert rc == 0 and res["n_amplitudes"] == 19
    assert res["textbook"]["printed"]["check_nu_6_17"]["max_abs_diff"] < 5e-4  # its processing table found beside it


@pytest.mark.skipif(SHARED is None, reason="the developers' shared data folder is not beside the project")
def test_shipped_textbook_files_are_the_developers_copy():
    for name in ("textbook_roll_decay.csv", "textbook_roll_decay_processing.csv"):
        assert (DATA / name).read_bytes() == (SHARED / name).read_bytes(), name
