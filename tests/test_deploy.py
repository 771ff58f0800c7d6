"""``addedinertia deploy`` over loopback: full experiments through the emulator, compared
with the same scenario in simulation, and one test per injected fault."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from addedinertia_env.cli import main
from addedinertia_env.identify import identify
from addedinertia_env.records.record import read_record
from addedinertia_env.sim.presets import load_preset, rig_from_mapping
from addedinertia_env.experiment.protocol import plan_from_preset
from addedinertia_env.apps.simulate import simulate_run
from agents import make_controller
from hw_adapter.deploy import EXIT_ABORTED, DeployOptions, deploy
from hw_adapter.lab import load_lab
from hw_adapter.loopback import spawn_bench_server, start_emulator

RIG_NAME = "wigley-2m"
SEED = 4
HOLD_S = 0.3  # s: a short hold keeps the test fast; the estimate does not depend on it
REL_TOL = 0.03  # energy method on the realistic rig: within 3 % of the truth (docs/ACCURACY.md)
POLICY = Path(__file__).resolve().parents[1] / "agents" / "policies" / "reverse_stroke.onnx"


def run_deploy(capsys, *args: str) -> tuple[int, dict]:
    status = main(["deploy", *args, "--json"])
    out = capsys.readouterr().out
    return status, json.loads(out)


def simulated_lambda66(controller: str) -> tuple[float, tuple[float, float]]:
    data = load_preset(RIG_NAME)
    rec = simulate_run(rig_from_mapping(data), controller, plan_from_preset(data, hold_s=HOLD_S), seed=SEED)
    res = identify([rec], "energy")
    return res.lambda66, res.ci95


def check_full_run(summary: dict, status: int, controller: str) -> None:
    truth = rig_from_mapping(load_preset(RIG_NAME)).hull.lambda66  # scoring only
    assert status == 0, summary["status"]
    assert summary["status"] == "complete" and summary["safe_stop"] and summary["source"] == "emulator"
    rec = read_record(summary["record"])
    assert rec.experiment["status"] == "complete" and rec.meta["source"] == "emulator"
    assert "truth" not in rec.meta  # the emulator keeps its truth in its own process
    assert set(rec.phase) >= {"idle", "free", "hold", "reverse"}
    assert rec.experiment["controller"] == controller
    assert summary["max_abs_current_sent_A"] <= rec.known.i_max
    assert summary["loop_jitter_p99_ms"] is not None and summary["loop_jitter_p99_ms"] >= 0
    sim, sim_ci = simulated_lambda66(controller)
    emu = summary["lambda66"]
    # The same tolerance holds for both, and the two agree within their intervals.
    assert abs(sim / truth - 1) < REL_TOL, f"simulation {sim:.3f} vs truth {truth}"
    assert abs(emu / truth - 1) < REL_TOL, f"emulator {emu:.3f} vs truth {truth}"
    lo, hi = summary["ci95"]
    assert lo <= hi and max(lo, sim_ci[0]) <= min(hi, sim_ci[1]), (summary["ci95"], sim_ci)


def test_full_experiment_through_the_emulator_with_a_classical_controller(tmp_path, capsys):
    proc, url = spawn_bench_server("--fast", "--rig", RIG_NAME, "--seed", str(SEED), "--once")
    try:
        status, summary = run_deploy(capsys, "--bench", url, "--controller", "feedforward-pd", "--lab", RIG_NAME,
                                     "--hold", str(HOLD_S), "--out", str(tmp_path))
    finally:
        proc.wait(timeout=30)
    check_full_run(summary, status, "feedforward-pd")


def test_full_experiment_through_the_emulator_with_the_shipped_policy(tmp_path, capsys):
    if not POLICY.exists():
        pytest.skip(f"the shipped policy {POLICY} does not exist yet (agents/policies/reverse_stroke.onnx)")
    proc, url = spawn_bench_server("--fast", "--rig", RIG_NAME, "--seed", str(SEED), "--once")
    try:
        status, summary = run_deploy(capsys, "--bench", url, "--policy", str(POLICY), "--lab", RIG_NAME,
                                     "--hold", str(HOLD_S), "--out", str(tmp_path))
    finally:
        proc.wait(timeout=30)
    check_full_run(summary, status, f"onnx:{POLICY}")


def test_dry_run_arms_and_warms_up_without_motion(capsys):
    server = start_emulator(fast=True)
    try:
        status, summary = run_deploy(capsys, "--bench", server.url, "--controller", "pd", "--dry-run")
    finally:
        server.stop()
    assert status == 0 and summary["status"] == "dry-run" and summary["record"] is None
    assert all(c["ok"] for c in summary["arm_checks"])
    assert summary["warmup"]["samples"] == 200 and summary["safe_stop"]
    board = server.board
    assert all(c.mode == "passive" and c.brake for c in board.commands)  # zero current, brake held
    assert board.rig.brake and board.is_safe


# fault spec, expected trip kinds. Faults start 0.3 s after RESET, in the free stroke;
# the stuck brake at 0.05 s, so the release at 0.1 s fails.
FAULTS = {
    "drop": ("drop=0.5@0.3", {"link"}),
    "corrupt": ("corrupt=0.5@0.3", {"link"}),
    "latency": ("latency=1500@0.3", {"link", "watchdog"}),  # beyond the 1 s lock-step watchdog
    "disconnect": ("disconnect@0.3", {"link"}),
    "glitch": ("glitch=0.2@0.3", {"rate", "board_fault"}),  # the board's encoder check or the host's rate check
    "stuck_brake": ("stuck_brake@0.05", {"brake", "board_fault"}),
}


@pytest.mark.parametrize("name", list(FAULTS))
def test_each_injected_fault_ends_safe_with_a_flagged_partial_record(name, tmp_path, capsys):
    spec, kinds = FAULTS[name]
    server = start_emulator(fast=True, faults=spec, seed=SEED)
    try:
        status, summary = run_deploy(capsys, "--bench", server.url, "--controller", "feedforward-pd",
                                     "--hold", str(HOLD_S), "--warmup", "0.05", "--out", str(tmp_path))
    finally:
        server.stop()
    board = server.board
    # 1. safe state: the board is disarmed, drive passive, brake requested (and held),
    #    and the host confirmed it (after reconnecting, for the pulled cable).
    assert status == EXIT_ABORTED != 0
    assert summary["trip"]["kind"] in kinds, summary["trip"]
    assert board.is_safe and board.rig.brake
    assert summary["safe_stop"], summary["safe_state"]
    assert board.log.first("fault_onset")["fault"] == name and board.log.first("safe") is not None
    # 2. no command beyond the limits reached the board, and none but the safe state after the trip
    i_max = board.params.motor.i_max
    assert max(abs(c.value) for c in board.commands) <= i_max
    assert summary["max_abs_current_sent_A"] <= i_max
    # 3. the partial record is kept, readable and flagged
    rec = read_record(summary["record"])
    assert rec.experiment["status"].startswith("aborted: ")
    assert summary["trip"]["kind"] in rec.experiment["status"]
    assert rec.meta["deploy"]["trip"]["kind"] == summary["trip"]["kind"]
    assert len(rec) > 50 and summary["lambda66"] is None


class CommandsTooMuchThenCrashes:
    """A controller gone wrong: asks for the full current, then raises."""

    def __init__(self):
        self.calls = 0

    def predict(self, obs, state=None, episode_start=None, deterministic=True):
        self.calls += 1
        if self.calls > 30:
            raise RuntimeError("controller bug")
        return np.array([1.0], dtype=np.float32), state


def test_envelope_clamps_to_the_lab_limit_and_a_crashing_controller_stops_safely(tmp_path):
    lab_file = tmp_path / "lab.yaml"
    lab_file.write_text(Path("hw_adapter/labs/example.yaml").read_text().replace("phi_max: 0.35",
                                                                                "phi_max: 0.35\n  i_max: 4.0"))
    lab = load_lab(str(lab_file))
    assert lab.limits["i_max"] == 4.0
    server = start_emulator(fast=True, seed=SEED)
    try:
        summary, status = deploy(DeployOptions(bench=server.url, controller="test", lab=lab, out=tmp_path,
                                               hold_s=HOLD_S, warmup_s=0.05, rtt_pings=3),
                                 CommandsTooMuchThenCrashes())
    finally:
        server.stop()
    assert status == EXIT_ABORTED and summary["trip"]["kind"] == "controller", summary["status"]
    assert "controller bug" in summary["status"]
    currents = [c.value for c in server.board.commands if c.mode == "current"]
    assert len(currents) == 30 and max(currents) == pytest.approx(4.0)  # asked 15 A, got 4 A
    assert server.board.is_safe and summary["safe_stop"]
    assert read_record(summary["record"]).experiment["status"].startswith("aborted: controller")


def test_deploy_bad_input_and_an_absent_bench(tmp_path, capsys):
    assert main(["deploy", "--bench", "loop://", "--controller", "no-such", "--json"]) == 2
    assert "no-such" in capsys.readouterr().err
    assert main(["deploy", "--bench", "loop://", "--policy", str(tmp_path / "none.onnx"), "--json"]) == 2
    assert "no such file" in capsys.readouterr().err
    assert main(["deploy", "--bench", "loop://", "--controller", "pd", "--lab", "nowhere", "--json"]) == 2
    capsys.readouterr()
    # loop:// echoes our own frames back: no board answers HELLO -> exit 4, nothing moved
    status, summary = run_deploy(capsys, "--bench", "loop://", "--controller", "pd")
    assert status == 4 and summary["status"].startswith("aborted: link") and summary["record"] is None


def test_a_link_slower_than_half_the_watchdog_fails_the_arming_check(tmp_path):
    """The round-trip check before arming, made deterministic: the emulator delays every frame
    it sends by 60 ms, the host's watchdog is 40 ms (lock-step), so every echo takes longer than
    the 20 ms bound whatever the machine's load (a loaded machine is only slower). deploy stops
    before arming; the board never moved. (The passing side is every other deploy test.)"""
    server = start_emulator(fast=True, seed=SEED, faults="latency=60")
    try:
        summary, status = deploy(DeployOptions(bench=server.url, controller="lqr", lab=load_lab("wigley-2m"),
                                               out=tmp_path, hold_s=HOLD_S, watchdog_s=0.04, rtt_pings=3),
                                 make_controller("lqr"))
    finally:
        server.stop()
    assert status == EXIT_ABORTED, summary["status"]
    check = next(c for c in summary["arm_checks"] if c["check"] == "link_round_trip")
    assert not check["ok"] and "3/3 echoes" in check["detail"] and "half the watchdog" in check["detail"]
    assert all(c["ok"] for c in summary["arm_checks"] if c["check"] != "link_round_trip")
    assert "arming check failed: link_round_trip" in summary["status"]
    assert all(c.mode == "passive" and c.brake and not c.armed for c in server.board.commands)  # only safe stops
    assert not server.board.armed and summary["safe_stop"]
