"""Issue 12: reference rows, paired control errors, the tie rule, the verdict, hard-v0's loop,
repeated cycles, outside submissions and the HTML page."""

from __future__ import annotations

import html
import json
import math
import os
import re
import shutil
import struct
import subprocess
from html.parser import HTMLParser

import numpy as np
import pytest

from addedinertia_env.bench import paired
from addedinertia_env.bench.leaderboard import summarise
from addedinertia_env.bench.render import render_html
from addedinertia_env.bench.submission import SubmissionError, declared_entry, parse_train_cost
from addedinertia_env.bench.suites import load_suite
from addedinertia_env.bench.verdict import discrimination, verdict
from addedinertia_env.cli import main
from addedinertia_env.loop.control_loop import ControlLoop, LoopRig
from addedinertia_env.sim.motor import MotorCommand
from addedinertia_env.sim.mujoco_rig import MujocoRig
from addedinertia_env.sim.params import RigParams, SensorParams
from addedinertia_env.experiment.scenarios import make_scenario


def _rows(controller, errors, energy=1.0, kind=None):
    return [{"controller": controller, "suite": "synthetic", "split": "test", "scenario": f"s{k}", "seed": k,
             "lambda66_true": 1.0, "lambda66_est": None if e is None else 1.0 + e, "rel_error": e,
             "energy_J": energy, "tracking_rms_rad": 1e-4, "saturated_frac": 0.0, "wall_s": 1.0,
             "version": "0.1.0", "commit": "abc1234", "entry_kind": kind} for k, e in enumerate(errors)]


def _bias(n, seed=1):
    """A large error common to every controller on a scenario (e.g. an off data-sheet k_t)."""
    return np.random.default_rng(seed).normal(0.0, 0.05, n)


def test_control_error_cancels_what_is_common_to_entry_and_oracle():
    n = 30
    bias = _bias(n)
    own = np.random.default_rng(2).normal(0.0, 0.002, n)
    rows = _rows("oracle", bias, kind="reference") + _rows("a", bias + own, kind="classical")
    a = next(e for e in summarise(rows, n_boot=300) if e["controller"] == "a")
    # The 5 % common bias is gone: what is left is the controller's own 0.2 % part.
    assert a["median_abs_control_error"] == pytest.approx(np.median(np.abs(own)), rel=1e-9)
    assert a["median_abs_error"] > 5 * a["median_abs_control_error"]
    lo, hi = a["ci95_control_error"]
    assert lo <= a["median_abs_control_error"] <= hi and a["n_paired"] == n


def test_failures_and_oracle_failures_are_counted_not_dropped():
    oracle = [0.0, 0.01, None, 0.0]
    entry = [0.001, None, 0.02, 0.003]
    rows = _rows("oracle", oracle, kind="reference") + _rows("a", entry, kind="classical")
    a = next(e for e in summarise(rows, n_boot=200) if e["controller"] == "a")
    c = a["control_errors"]
    assert a["n_paired"] == 3 and a["oracle_failed"] == 1  # the scenario without an oracle is counted
    assert math.isinf(c[("synthetic", "test", 1)]) and c[("synthetic", "test", 0)] == pytest.approx(0.001)


def test_paired_difference_sees_what_unpaired_intervals_miss():
    n = 30
    bias = _bias(n, seed=3)
    rng = np.random.default_rng(4)
    a = bias + rng.normal(0, 0.001, n)
    b = bias + rng.normal(0, 0.004, n)
    rows = (_rows("oracle", bias, kind="reference") + _rows("a", a, kind="classical")
            + _rows("b", b, kind="classical"))
    entries = {e["controller"]: e for e in summarise(rows, n_boot=500)}
    lo_a, hi_a = entries["a"]["ci95_median"]
    lo_b, hi_b = entries["b"]["ci95_median"]
    assert not (hi_a < lo_b or hi_b < lo_a)  # unpaired |e| intervals overlap: the bias swamps them
    d = paired.difference(entries["b"]["control_errors"], entries["a"]["control_errors"], n_boot=500)
    assert paired.clearly(d) == 1 and d["p_wilcoxon"] < 0.01  # paired: b clearly worse
    # Ranked on the published error (bench/score.py), the common 5 % bias dominates both: b's extra
    # noise moves |e| up as often as down, so the two are tied; the control error beside it tells them apart.
    assert entries["a"]["rank"] == entries["b"]["rank"] == 1


def test_tie_rule_orders_tied_entries_by_energy():
    n = 30
    bias = _bias(n, seed=5)
    rng = np.random.default_rng(6)
    frugal, spender = rng.normal(0, 0.003, n), rng.normal(0, 0.003, n)
    frugal, spender = sorted((frugal, spender), key=lambda x: -np.mean(np.minimum(np.abs(bias + x), 0.1)))
    rows = (_rows("oracle", bias, kind="reference") + _rows("frugal", bias + frugal, energy=2.0)
            + _rows("spender", bias + spender, energy=9.0))
    entries = summarise(rows, n_boot=500)
    by = {e["controller"]: e for e in entries}
    assert by["spender"]["score"] < by["frugal"]["score"] and by["spender"]["rank"] == by["frugal"]["rank"] == 1
    # spender's ranked score is lower, but the two cannot be told apart: the cheaper one ranks first
    assert [e["controller"] for e in entries if e["rank"] is not None] == ["frugal", "spender"]
    # the oracle is a reference (no rank), listed by its own score: not the floor of the published error
    assert next(e for e in entries if e["controller"] == "oracle")["rank"] is None


def test_verdict_says_non_discriminating_with_numbers_when_zero_is_as_good():
    n = 20
    bias = _bias(n, seed=7)
    rng = np.random.default_rng(8)
    noise = lambda s: rng.normal(0, s, n)  # noqa: E731
    flat = (_rows("oracle", bias, kind="reference") + _rows("zero", bias + noise(0.003), energy=0.0,
                                                              kind="reference")
            + _rows("lqr", bias + noise(0.003), energy=8.0, kind="classical"))
    said = " ".join(verdict(summarise(flat, n_boot=500)))
    assert "NON-DISCRIMINATING" in said and "%" in said and "CI" in said
    clear = (_rows("oracle", bias, kind="reference") + _rows("zero", bias + noise(0.03), energy=0.0,
                                                               kind="reference")
             + _rows("lqr", bias + noise(0.004), energy=8.0, kind="classical"))
    entries = summarise(clear, n_boot=500)
    disc = discrimination(entries)
    assert disc["discriminating"] and disc["zero_worse"] and disc["above_oracle"]
    assert "**Discriminating**" in " ".join(verdict(entries))


def test_zero_that_reads_closer_to_the_truth_than_tracking_is_not_beaten_by_control_error():
    """Where the method is biased (memory water: the oracle reads +4 %), `zero` can sit far from the
    oracle (large control error) yet nearer the truth: the suite does not discriminate, whatever
    the control errors say (memory-v1's board, 2026-11-27)."""
    n = 30
    rng = np.random.default_rng(11)
    bias = 0.04 + rng.normal(0, 0.002, n)  # the method's bias, common to every tracking entry
    flat = (_rows("oracle", bias, kind="reference") + _rows("zero", rng.normal(0, 0.005, n), energy=0.0,
                                                              kind="reference")
            + _rows("pd", bias + rng.normal(0, 0.003, n), energy=8.0, kind="classical"))
    entries = summarise(flat, n_boot=500)
    disc = discrimination(entries)
    assert paired.clearly(disc["zero_vs_best"]) > 0  # on control error zero looks clearly worse
    assert not disc["zero_worse"] and not disc["discriminating"]  # on the ranked score it is not
    said = " ".join(verdict(entries))
    assert "NON-DISCRIMINATING" in said and "NOT clearly worse" in said and "ranked score" in said


def test_few_episodes_are_warned():
    rows = _rows("oracle", [0.0] * 5, kind="reference") + _rows("a", [0.01, 0.02, 0.0, 0.03, 0.01])
    assert "fewer than 10 episodes" in " ".join(verdict(summarise(rows, n_boot=100)))


def test_loop_rig_delays_readings_holds_and_quantises_commands():
    p = RigParams(sensors=SensorParams.ideal())
    loop = ControlLoop(obs_delay_s=0.005, command_period_s=0.01, current_step_A=0.5)
    plain, wrapped = MujocoRig(p, seed=0), LoopRig(MujocoRig(p, seed=0), loop)
    assert wrapped.command_every == 10
    plain.reset(phi0=-0.1, brake=False)
    wrapped.reset(phi0=-0.1, brake=False)
    direct = [plain.step(MotorCommand("passive", 0.0)) for _ in range(30)]
    late = [wrapped.step(MotorCommand("passive", 0.0)) for _ in range(30)]
    for k in range(5, 30):  # values 5 samples old, time stamps of now
        assert late[k].phi == direct[k - 5].phi and late[k].t == direct[k].t
    wrapped.reset(phi0=-0.1, brake=True)
    sent = [1.26 + 0.1 * k for k in range(20)]
    for v in sent:
        wrapped.step(MotorCommand("current", v))
    # the drive acted on the 1st and 11th set-points only, rounded to 0.5 A
    assert wrapped._held.value == pytest.approx(0.5 * round(sent[10] / 0.5))
    assert wrapped.truth()["control_loop"]["command_period_s"] == 0.01


def test_hard_suite_draws_its_extras_without_moving_the_base_scenario():
    s = load_suite("hard-v0")
    assert s.tuned_path is not None and s.tuned_path.name == "tuned-hard-v0.yaml"
    seed = s.seeds("test")[0]
    sc = s.scenario(seed)
    base = make_scenario(seed, preset=s.preset_for(seed), ranges=s.ranges, fixed=s.fixed)
    assert sc.rig.hull == base.rig.hull and sc.plan == base.plan  # extras come from their own streams
    assert {"bearing_coulomb", "torque_constant"} <= set(sc.rig.effects.active)
    assert sc.loop.command_period_s == 0.01 and 0.004 <= sc.loop.obs_delay_s <= 0.012
    assert 9.0 <= sc.rig.motor.i_max <= 13.0
    assert s.split_of(s.split_seed("train", 5)) == "train"
    assert not set(s.seeds("tuning")) & set(s.seeds("test"))


def test_references_run_on_a_suite_and_are_refused_elsewhere(tmp_path, capsys):
    suite = tmp_path / "two.yaml"
    suite.write_text("name: two-cycles\npresets: [wigley-2m]\nfixed: {hold_s: 0.5, sensor_quality: realistic}\n"
                     "cycles: 2\nsplits:\n  test: {first_seed: 1000, count: 1}\n")
    rows = {}
    for name in ("oracle", "zero"):
        out = tmp_path / f"{name}.jsonl"
        assert main(["bench", "run", "--suite", str(suite), "--controller", name, "--jobs", "1", "--no-progress",
                     "--out", str(out)]) == 0
        rows[name] = json.loads(out.read_text().splitlines()[0])
    o, z = rows["oracle"], rows["zero"]
    assert o["entry_kind"] == z["entry_kind"] == "reference" and o["cycles"] == 2
    assert o["command"].startswith("addedinertia bench run")
    assert abs(o["rel_error"]) < 0.01 and o["rel_error_corrected"] is not None
    assert z["energy_J"] < 0.01 * o["energy_J"]  # no control: no energy
    assert abs(z["rel_error"] - o["rel_error"]) > abs(o["rel_error"])  # doing nothing is worse
    capsys.readouterr()
    assert main(["deploy", "--bench", "socket://127.0.0.1:1", "--controller", "oracle", "--json"]) == 2
    assert "reference row" in capsys.readouterr().err


def test_submission_declarations(tmp_path, monkeypatch):
    assert parse_train_cost("40960,6.5") == {"train_env_steps": 40960, "train_cpu_minutes": 6.5}
    for bad in ("40960", "x,1", "-1,2"):
        with pytest.raises(SubmissionError):
            parse_train_cost(bad)
    (tmp_path / "my_ctrl.py").write_text("from agents.zero import ZeroCurrent as make\n")
    (tmp_path / "my_ctrl.card.yaml").write_text("entry_kind: learned\ntrain_env_steps: 1000\ntrain_cpu_minutes: 2\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    entry = declared_entry("my_ctrl:make")
    assert entry["entry_kind"] == "learned" and entry["train_env_steps"] == 1000 and entry["card"].endswith(".yaml")
    assert declared_entry("my_ctrl:make", kind="learned", train_cost="5,1")["train_env_steps"] == 5
    with pytest.raises(SubmissionError):
        declared_entry("my_ctrl:make", kind="classical")  # a cost from the card, but declared classical
    with pytest.raises(SubmissionError):
        declared_entry("oracle", kind="learned")


class _Page(HTMLParser):
    def __init__(self):
        super().__init__()
        self.tags, self.ref_rows, self.rows, self.json_blocks, self._in_json = [], 0, 0, [], False
        self.external = []

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        self.tags.append(tag)
        if tag == "tr":
            self.rows += 1
            self.ref_rows += a.get("class") == "ref"
        if tag == "script" and a.get("type") == "application/json":
            self._in_json = True
        for key in ("src", "href"):
            if a.get(key, "").startswith(("http:", "https:", "//")):
                self.external.append(a[key])

    def handle_endtag(self, tag):
        if tag == "script":
            self._in_json = False

    def handle_data(self, data):
        if self._in_json:
            self.json_blocks.append(data)


def _html_rows():
    bias = _bias(12, seed=9)
    rng = np.random.default_rng(10)
    return (_rows("oracle", bias, kind="reference") + _rows("zero", bias + rng.normal(0, 0.03, 12), 0.0, "reference")
            + _rows("lqr", bias + rng.normal(0, 0.002, 12), 8.0, "classical")
            + _rows("onnx:p.onnx", bias + rng.normal(0, 0.003, 12), 6.0, "learned"))


def test_html_page_is_self_contained_and_complete():
    rows = _html_rows()
    page = render_html(summarise(rows, n_boot=200), rows, "t", "made by `addedinertia bench leaderboard x`")
    p = _Page()
    p.feed(page)
    assert p.rows == 1 + 4 and p.ref_rows == 2  # header + 4 rows, the two references marked
    assert "svg" in p.tags and "select" in p.tags and not p.external
    episodes = json.loads("".join(p.json_blocks))
    assert len(episodes) == len(rows) and {"control_error", "rel_error"} <= set(episodes[-1])
    assert "Verdict" in page and "addedinertia bench leaderboard" in page


def _chromium():
    return next((shutil.which(n) for n in ("chromium", "chromium-browser", "google-chrome", "chrome")
                 if shutil.which(n)), None)


# What a reader sees once the page has loaded, written into the page by a probe script (Chromium's
# --dump-dom gives the DOM after the load event): the table's rows as laid out, each image's pixels,
# the Pareto figure's size and marks, the drill-down, and the order after a click on "controller".
_PROBE = """<script>window.addEventListener('load', () => {
  const names = () => [...document.querySelectorAll('#leaderboard tbody tr')].map(tr => tr.cells[1].innerText);
  const rows = [...document.querySelectorAll('#leaderboard tbody tr')].map(tr => {
    const r = tr.getBoundingClientRect(); return {name: tr.cells[1].innerText, w: r.width, h: r.height}; });
  const imgs = [...document.images].map(i => ({complete: i.complete, w: i.naturalWidth, h: i.naturalHeight,
                                                shown: i.getBoundingClientRect().height}));
  const svgs = [...document.querySelectorAll('svg')].map(s => { const b = s.getBoundingClientRect();
    return {w: b.width, h: b.height, marks: s.querySelectorAll('circle').length}; });
  const drill = document.getElementById('drill').innerText;
  [...document.querySelectorAll('#leaderboard th')].find(th => th.innerText.trim() === 'controller').click();
  const sorted = names();
  const p = document.createElement('pre'); p.id = 'probe';
  p.textContent = JSON.stringify({rows, imgs, svgs, drill, sorted}); document.body.appendChild(p);
});</script>"""


@pytest.mark.skipif(_chromium() is None and not os.environ.get("ADDEDINERTIA_REQUIRE_CHROMIUM"),
                    reason="no Chromium installed (CI installs it: .ci/run)")
def test_html_page_renders_in_headless_chromium(tmp_path):
    """The page as a reader sees it in a browser (CI installs Debian's chromium and sets
    ADDEDINERTIA_REQUIRE_CHROMIUM, so there it runs or fails, never skips)."""
    from addedinertia_env.bench.plots import plot_error_vs_energy

    assert _chromium() is not None, "ADDEDINERTIA_REQUIRE_CHROMIUM is set but no Chromium is installed"
    rows = _html_rows()
    entries = summarise(rows, n_boot=200)
    figure = plot_error_vs_energy(rows, [e["controller"] for e in entries], tmp_path / "fig.png")
    page = render_html(entries, rows, "t", "x", figures={"|error| against energy": figure})
    path = tmp_path / "lb.html"
    path.write_text(page.replace("</body>", _PROBE + "</body>"))
    out = subprocess.run([_chromium(), "--headless", "--no-sandbox", "--disable-gpu", "--virtual-time-budget=5000",
                          "--dump-dom", path.as_uri()], capture_output=True, text=True, timeout=120)
    found = re.search(r'<pre id="probe">(.*?)</pre>', out.stdout, re.S)
    assert found, (out.returncode, out.stderr[-2000:])
    seen = json.loads(html.unescape(found.group(1)))
    # the table: one laid-out row per entry, in the ranked order
    assert [r["name"] for r in seen["rows"]] == [e["controller"] for e in entries]
    assert all(r["h"] > 5 and r["w"] > 100 for r in seen["rows"])
    # the figures: the PNG decoded to its own pixels and shown; the Pareto SVG drawn with a mark per entry
    size = struct.unpack(">II", figure.read_bytes()[16:24])  # the PNG's IHDR: width, height
    assert [(i["complete"], i["w"], i["h"]) for i in seen["imgs"]] == [(True, *size)] and seen["imgs"][0]["shown"] > 50
    assert seen["svgs"] and seen["svgs"][0]["w"] > 100 and seen["svgs"][0]["h"] > 100
    assert seen["svgs"][0]["marks"] >= len(entries)
    # the drill-down built by the script, and sorting by a click on the heading
    assert "control error" in seen["drill"]
    assert sorted(seen["sorted"]) in (seen["sorted"], seen["sorted"][::-1]) and seen["sorted"] != []


def test_env_draws_a_suites_training_scenarios_never_its_test_split():
    import gymnasium as gym

    env = gym.make("AddedInertia/ReverseStroke-v0", suite="hard-v0", action_repeat=10)
    _, info = env.reset(seed=3)
    assert info["scenario"].startswith("hard-v0/train/") and isinstance(env.unwrapped.rig, LoopRig)
    env.close()
    with pytest.raises(ValueError, match="held out"):
        gym.make("AddedInertia/ReverseStroke-v0", suite="hard-v0", suite_split="test")
