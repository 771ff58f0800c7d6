"""identify --method whole-record: lambda66 from the whole record, its 95 % interval and the Cramer-Rao bound."""

from __future__ import annotations

import contextlib
import io
import json

import pytest

from addedinertia_env.cli import main
from addedinertia_env.identify import IdentificationError, identify
from addedinertia_env.records.record import write_record

from test_discover import dataset  # same module object under pytest: the dataset cache is shared


def test_one_run_nominal_rig(tmp_path):
    rec = dataset("none", 3)[0]
    path = write_record(rec, tmp_path / "run.csv")
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert main(["identify", str(path), "--method", "whole-record", "--json"]) == 0
    obj = json.loads(out.getvalue())
    truth = rec.truth_lambda66()
    lo, hi = obj["ci95"]
    assert obj["method"] == "whole-record" and lo < obj["lambda66"] < hi
    assert abs(obj["lambda66"] / truth - 1) < 2e-3
    # the interval is never narrower than what the data allow, and the bound is a bound
    assert obj["crb"] > 0 and obj["sigma"] >= obj["crb"]
    assert obj["per_run_crb"][0]["crb"] == pytest.approx(obj["crb"])
    # the encoder noise floor is small: the bound is far below 0.1 % of lambda66
    assert obj["crb"] < 1e-3 * truth


def test_more_runs_tighten_the_bound():
    recs = dataset("none", 3)
    one = identify(recs[:1], "whole-record")
    four = identify(recs, "whole-record")
    assert four.details["crb"] < one.details["crb"]
    assert abs(four.lambda66 / recs[0].truth_lambda66() - 1) < 2e-3


def test_unmodelled_effect_biases_nominal_and_extended_model_recovers():
    """Spring stiffening (period depends on amplitude) biases the nominal fit by percents."""
    recs = dataset("spring_stiffening", 3)
    truth = recs[0].truth_lambda66()
    nominal = identify(recs, "whole-record")
    extended = identify(recs, "whole-record", effect="spring_stiffening")
    assert abs(nominal.lambda66 / truth - 1) > 5e-3
    assert abs(extended.lambda66 / truth - 1) < 2e-3
    assert extended.details["residual_rms"] < nominal.details["residual_rms"]


def test_wrong_kind_refused():
    rec = dataset("none", 3)[0]
    bad = type(rec)(samples=rec.samples, meta={**rec.meta, "experiment": {**rec.experiment, "kind": "free-decay"}})
    from addedinertia_env.discover.whole_record import identify_whole_record
    from addedinertia_env.records.record import RecordError

    forced = type(rec)(samples=rec.samples,
                       meta={**rec.meta, "experiment": {**rec.experiment, "kind": "forced-oscillation"}})
    with pytest.raises(IdentificationError, match="forced-oscillation"):  # the method itself refuses the kind
        identify_whole_record([forced])
    with pytest.raises(RecordError, match="phase"):  # identify() refuses first: phases out of a free decay's order
        identify([bad], "whole-record")
