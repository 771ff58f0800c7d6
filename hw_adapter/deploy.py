"""One reverse-symmetric experiment on a bench: what ``addedinertia deploy`` does.

Sequence (docs/BENCH.md): connect (HELLO -> CAPS) -> arming checks -> ARM -> warm-up
(drive passive, brake on, sensors and loop timing watched) -> [``dry_run``: DISARM, stop
here] -> record opened -> :class:`~addedinertia_env.experiment.protocol.Experiment` with
the controller, every command through the safety envelope -> DISARM -> safe state
confirmed -> record finalised -> lambda66 identified with the energy method.

A trip of the envelope, a board fault, a link fault or an error in the controller
stops the run in the safe state; the record is kept with ``experiment.status =
"aborted: <reason>"`` and the exit status is :data:`EXIT_ABORTED`.
"""

from __future__ import annotations

import gc
import math
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from addedinertia_env.experiment.controller import Controller
from addedinertia_env.experiment.protocol import Experiment, ExperimentError
from addedinertia_env.experiment.runner import drive, needs_stated_link
from addedinertia_env.experiment.two_rate import MAX_STATED_ROUND_TRIP_S
from addedinertia_env.identify import IdentificationError, identify
from addedinertia_env.records.record import read_record
from addedinertia_env.sim.motor import MotorCommand

from hw_adapter import messages as m
from hw_adapter.bench_rig import BenchRig
from hw_adapter.lab import LabConfig
from hw_adapter.link import LinkError
from hw_adapter.recorder import IncrementalRecord
from hw_adapter.safety import SafetyTrip

EXIT_OK = 0
EXIT_IDENTIFY_FAILED = 1  # the run completed but lambda66 could not be identified
EXIT_BAD_INPUT = 2  # refused before arming: a policy whose rate or board mode the bench does not match
EXIT_ABORTED = 3  # stopped in the safe state: fault, trip, failed arming check
EXIT_NO_BENCH = 4  # the bench did not answer; nothing was moved
PASSIVE = MotorCommand("passive", 0.0)


@dataclass(frozen=True)
class DeployOptions:
    """What ``addedinertia deploy`` was asked to do: the bench URL, the controller, the lab, where to write.

    Times in s (``warmup_s``, ``watchdog_s``, ``hold_s``, ``reset_timeout_s``), ``alpha`` in rad,
    ``host_rate_hz`` in Hz (two-rate mode); ``rtt_pings`` link echoes timed before arming (0: none);
    ``link_round_trip_s``: the link's round trip the lab states to the controllers (s; ``"ping"``: the
    median of the arming check's echoes, measured by this deploy; None: none stated), as
    ``ControllerContext.link_round_trip_s`` (:func:`stated_link`).
    """

    bench: str  # pyserial URL: /dev/ttyUSB0, socket://127.0.0.1:5555, loop://
    controller: str  # a registry name: feedforward-pd, pid, ..., onnx:PATH
    lab: LabConfig
    out: Path = Path("out/deploy")
    run_id: str = "deploy"
    dry_run: bool = False
    warmup_s: float = 0.2  # s of passive, braked samples before the experiment
    watchdog_s: float | None = None  # None: 20 ms on a free-running board, 1 s lock-step
    hold_s: float | None = None
    alpha: float | None = None
    reset_timeout_s: float = 120.0
    rtt_pings: int = 20
    host_rate_hz: float | None = None  # two-rate mode: the host acts (sends segments) at this rate
    board_mode: str | None = None  # two-rate: "zoh" or "pd" (None: the controller's own, else zoh)
    link_round_trip_s: float | str | None = None  # s, stated to the controllers; "ping": the arming pings' median


def rate_mismatch(controller: Controller, caps: m.Caps, host_rate_hz: float | None, board_mode: str | None) -> str | None:
    """Why ``controller`` cannot run on this bench at this host rate (None if it can).

    A controller that declares a policy rate (an exported policy: ``policy_rate_hz``,
    ``board_mode``, ``sample_rate_hz`` from its card) must run at exactly that rate with
    the board doing what it did in training; the classical controllers adapt to any rate.
    """
    rate = getattr(controller, "policy_rate_hz", None)
    name = getattr(controller, "name", type(controller).__name__)
    if host_rate_hz is not None and not caps.two_rate:
        return f"--host-rate-hz {host_rate_hz:g}: the board has no two-rate mode (protocol version 1)"
    mode = board_mode or getattr(controller, "board_mode", None) or "zoh"
    if host_rate_hz is not None and not caps.supports(mode):
        return f"board mode {mode!r}: the board runs only {[k for k, b in m.BOARD_MODE_BITS.items() if caps.board_modes & b]}"
    if host_rate_hz is not None and not 2e3 / caps.watchdog_ms <= host_rate_hz <= caps.sample_rate:
        return (f"--host-rate-hz {host_rate_hz:g}: expected {2e3 / caps.watchdog_ms:g} .. {caps.sample_rate:g} Hz "
                f"(a segment at least every half board watchdog, {caps.watchdog_ms} ms; at most the sample rate)")
    if rate is None:
        return None
    trained_fs = getattr(controller, "sample_rate_hz", None)
    if trained_fs is not None and abs(trained_fs - caps.sample_rate) > 1e-6 * trained_fs:
        return (f"policy {name} was trained on a board sampling at {trained_fs:g} Hz; this bench samples at "
                f"{caps.sample_rate:g} Hz")
    bench_rate = host_rate_hz if host_rate_hz is not None else caps.sample_rate
    if host_rate_hz is None and rate < caps.sample_rate:
        return None  # single-rate host at the board's rate: the policy holds its own action (as in training)
    declared = getattr(controller, "board_mode", "zoh")
    if abs(rate - bench_rate) > 1e-6 * rate or (board_mode is not None and board_mode != declared):
        return (f"policy {name} acts at {rate:g} Hz with board mode {declared!r} (its card); the bench would run "
                f"it at {bench_rate:g} Hz with board mode {mode!r}: "
                + (f"run with --host-rate-hz {rate:g}" if rate < caps.sample_rate else
                   "omit --host-rate-hz (a policy at the sample rate needs the single-rate host)"))
    return None


def check_link_round_trip(value: Any) -> float | str | None:
    """``value`` as :attr:`DeployOptions.link_round_trip_s` accepts it (None, ``"ping"`` or seconds in
    [0, MAX_STATED_ROUND_TRIP_S]); ValueError naming the field and the value otherwise."""
    if value is None or value == "ping":
        return value
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) \
            or not 0.0 <= value <= MAX_STATED_ROUND_TRIP_S:
        raise ValueError(f"link_round_trip_s = {value!r}: expected 'ping' or a finite number of seconds in "
                         f"[0, {MAX_STATED_ROUND_TRIP_S:g}] (the link's round trip as the lab measured it)")
    return float(value)


def stated_link(opts: DeployOptions, checks: list[dict[str, Any]]) -> tuple[float | None, str | None]:
    """The round trip stated to the controllers (s) and where it comes from (``"stated"``: the lab's value,
    ``"ping"``: the median of this deploy's arming echoes; None: not stated)."""
    value = check_link_round_trip(opts.link_round_trip_s)
    if value is None:
        return None, None
    if value != "ping":
        return value, "stated"
    ping = next((c for c in checks if c["check"] == "link_round_trip"), None)
    if ping is None or ping.get("median_ms") is None:
        raise ValueError("link_round_trip_s = 'ping': no echo of the arming check's pings was timed (rtt_pings = "
                         f"{opts.rtt_pings}); expected at least one")
    return 1e-3 * float(ping["median_ms"]), "ping"


def loop_stats(intervals: list[float], dt: float, lockstep: bool) -> dict[str, float | None]:
    """Control-loop period and jitter in ms. Jitter is ``|period - nominal|``; the nominal
    is the sample period on a free-running board and the median period in lock-step."""
    if len(intervals) < 2:
        return {"loop_period_p50_ms": None, "loop_jitter_p50_ms": None, "loop_jitter_p99_ms": None,
                "loop_jitter_max_ms": None, "loop_samples": len(intervals)}
    x = np.asarray(intervals)
    nominal = float(np.median(x)) if lockstep else dt
    dev = np.abs(x - nominal)
    return {"loop_period_p50_ms": 1e3 * float(np.median(x)), "loop_jitter_p50_ms": 1e3 * float(np.percentile(dev, 50)),
            "loop_jitter_p99_ms": 1e3 * float(np.percentile(dev, 99)), "loop_jitter_max_ms": 1e3 * float(dev.max()),
            "loop_samples": int(x.size)}


def arm_checks(rig: BenchRig, plan, pings: int) -> list[dict[str, Any]]:
    """Checks before anything moves; each ``{"check", "ok", "detail"}``."""
    caps, lim = rig.caps, rig.limits
    checks = []

    def add(name: str, ok: bool, detail: str, **extra: Any) -> None:
        checks.append({"check": name, "ok": bool(ok), "detail": detail, **extra})

    add("sample_rate", 100.0 <= caps.sample_rate <= 20_000.0, f"{caps.sample_rate:g} Hz (expected 100..20000)")
    add("twist_inside_envelope", abs(plan.alpha) <= 0.8 * lim.phi_max,
        f"|alpha| = {abs(plan.alpha):g} rad, angle limit {lim.phi_max:g} rad (alpha must be <= 80 % of it)")
    add("board_watchdog", 0 < caps.watchdog_ms <= 200, f"{caps.watchdog_ms} ms (expected 1..200)")
    sample, reading = rig.query()
    add("no_latched_faults", sample.faults == 0, f"board faults {m.fault_names(sample.faults) or 'none'}")
    add("brake_engaged", sample.brake, "brake sensed engaged" if sample.brake else "brake sensed released")
    add("current_near_zero", abs(sample.current) <= max(0.2, 0.05 * caps.i_max), f"{sample.current:+.3f} A")
    phi_rel = reading.phi - rig.known.phi_neutral
    add("angle_inside_envelope", abs(phi_rel) <= lim.phi_max, f"{phi_rel:+.4f} rad from neutral")
    rtts = []
    for k in range(pings):
        t0 = time.perf_counter()
        rig.link.send(m.Empty(m.HEARTBEAT, 1000 + k))
        deadline = t0 + 0.5
        while (left := deadline - time.perf_counter()) > 0:
            got = rig.link.recv(left)
            if got is not None and isinstance(got[1], m.Empty) and got[1].type == m.HEARTBEAT \
                    and got[1].reason == 1000 + k:
                rtts.append(time.perf_counter() - t0)
                break
    if pings:
        rtt_p99 = float(np.percentile(rtts, 99)) if rtts else math.inf
        # Single-rate: a command per sample must beat half the watchdog. Two-rate: a segment
        # must reach the board within one host period (its deadline).
        bound, what = ((1.0 / rig.host_rate_hz, "one host period") if rig.two_rate and not rig.lockstep
                       else (rig.watchdog_s / 2, "half the watchdog"))
        add("link_round_trip", len(rtts) == pings and rtt_p99 < bound,
            f"{len(rtts)}/{pings} echoes, p99 {1e3 * rtt_p99:.2f} ms (must be < {what}, {1e3 * bound:.1f} ms)",
            median_ms=1e3 * float(np.median(rtts)) if rtts else None)
    return checks


def warm_up(rig: BenchRig, seconds: float) -> dict[str, Any]:
    """Passive, braked samples: the loop runs at its rate and the sensors are checked."""
    n = max(3, int(round(seconds / rig.dt)))
    currents, phis = [], []
    for _ in range(n):
        r = rig.step(PASSIVE)
        currents.append(r.i)
        phis.append(r.phi)
    i = np.asarray(currents)
    phi = np.asarray(phis)
    stats = {"samples": n, "current_mean_A": float(i.mean()), "current_std_A": float(i.std()),
             "phi_span_rad": float(phi.max() - phi.min())}
    problems = []
    if abs(stats["current_mean_A"]) > max(0.2, 0.05 * rig.caps.i_max):
        problems.append(f"current offset {stats['current_mean_A']:+.3f} A with the drive passive")
    if stats["phi_span_rad"] > 0.01:
        problems.append(f"hull moved {stats['phi_span_rad']:.4f} rad while braked")
    if problems:
        raise rig.stop("sensor", "warm-up: " + "; ".join(problems))
    return stats


def deploy(opts: DeployOptions, controller: Controller) -> tuple[dict[str, Any], int]:
    """Run one experiment on ``opts.bench``; returns (summary, exit status)."""
    t_start = time.perf_counter()
    plan = opts.lab.plan(hold_s=opts.hold_s, alpha=opts.alpha)
    summary: dict[str, Any] = {"bench": opts.bench, "controller": opts.controller, "dry_run": opts.dry_run,
                               "lambda66": None, "ci95": None, "record": None, "safe_stop": False}
    if opts.host_rate_hz is not None:
        summary["host_rate_hz"] = opts.host_rate_hz
    check_link_round_trip(opts.link_round_trip_s)
    if opts.link_round_trip_s is None and needs_stated_link(controller):  # before anything is connected
        refusal = (f"{opts.controller} needs the link's round trip stated to it (ControllerContext.link_round_trip_s): "
                   "give link_round_trip_s (deploy --link-round-trip-ms MS, or 'ping' to state the arming pings' median)")
        summary.update(status=f"refused: {refusal}", exit_status=EXIT_BAD_INPUT, refused=refusal)
        return summary, EXIT_BAD_INPUT
    try:
        rig = BenchRig(opts.bench, opts.lab, watchdog_s=opts.watchdog_s, reset_timeout_s=opts.reset_timeout_s,
                       host_rate_hz=opts.host_rate_hz)
        rig.connect()
    except LinkError as e:
        summary.update(status=f"aborted: link: {e}", exit_status=EXIT_NO_BENCH)
        return summary, EXIT_NO_BENCH
    refusal = rate_mismatch(controller, rig.caps, opts.host_rate_hz, opts.board_mode)
    if refusal is not None:  # before anything is armed: nothing moved
        rig.close()
        summary.update(status=f"refused: {refusal}", exit_status=EXIT_BAD_INPUT, refused=refusal)
        return summary, EXIT_BAD_INPUT
    if opts.host_rate_hz is not None:
        from addedinertia_env.experiment.two_rate import default_board_mode  # noqa: PLC0415

        summary["board_mode"] = opts.board_mode or default_board_mode(controller)
    summary.update(source=rig.source, watchdog_ms=1e3 * rig.watchdog_s, limits=asdict(rig.limits))
    recorder: IncrementalRecord | None = None
    exp: Experiment | None = None
    status = "complete"
    try:
        checks = arm_checks(rig, plan, opts.rtt_pings)
        summary["arm_checks"] = checks
        failed = [c for c in checks if not c["ok"]]
        if failed:
            hint = (f"; inspect and clear latched faults with `addedinertia bench-faults --bench {opts.bench} --clear`"
                    if any(c["check"] == "no_latched_faults" for c in failed) else "")
            raise rig.stop("arming", "arming check failed: " + "; ".join(f"{c['check']} ({c['detail']})"
                                                                             for c in failed) + hint)
        try:
            rtt, rtt_from = stated_link(opts, checks)
        except ValueError as e:
            raise rig.stop("arming", str(e)) from None
        rig.stated_round_trip_s = rtt  # what the controllers are told (experiment/runner.py: stated_round_trip)
        link = {} if rtt is None else {"link_round_trip_s": rtt, "link_round_trip_from": rtt_from}
        summary.update(link)
        rig.arm()
        summary["warmup"] = warm_up(rig, opts.warmup_s)
        if opts.dry_run:
            status = "dry-run"
        else:
            recorder = IncrementalRecord(opts.out, opts.run_id)
            exp = Experiment(rig, plan)
            recorder.phase = lambda: exp.phase
            recorder.start({"source": rig.source, "rig": rig.known.to_block(),
                            "experiment": {"kind": "reverse-symmetric", **asdict(plan), "controller": opts.controller,
                                           "bench": opts.bench, **link}})
            rig.on_sample = recorder.append
            gc.collect()
            gc.disable()  # no collector pauses in the control loop (re-enabled below)
            try:
                _run(exp, rig, controller, opts.host_rate_hz, summary.get("board_mode"))
            finally:
                gc.enable()
    except SafetyTrip as trip:
        status = f"aborted: {trip.reason}"
    except ExperimentError as e:
        status = f"aborted: {rig.stop('experiment', str(e)).reason}"
    except LinkError as e:
        status = f"aborted: {rig.stop('link', str(e)).reason}"
    except KeyboardInterrupt:
        status = f"aborted: {rig.stop('operator', 'interrupted by the operator').reason}"
    except Exception as e:  # a controller that raises must still leave the bench safe
        status = f"aborted: {rig.stop('controller', f'{type(e).__name__}: {e}').reason}"
    finally:
        if rig.trip is None:
            rig.disarm()
    summary["safe_state"] = rig.confirm_safe(timeout_s=1.0 + 2 * rig.watchdog_s)
    summary["safe_stop"] = bool(summary["safe_state"]["confirmed"])
    rig.close()
    summary.update(_timing(rig))
    summary["status"] = status
    if recorder is not None:
        meta = exp.record(opts.run_id).meta
        meta["experiment"]["controller"] = opts.controller
        meta["experiment"]["bench"] = opts.bench
        if summary.get("link_round_trip_s") is not None:  # what the controllers were told, s, and from where
            meta["experiment"].update(link_round_trip_s=summary["link_round_trip_s"],
                                      link_round_trip_from=summary["link_round_trip_from"])
        meta["deploy"] = {k: summary.get(k) for k in ("safe_stop", "safe_state", "watchdog_ms", "limits",
                                                      "arm_checks", "warmup")}
        meta["deploy"].update(_timing(rig), trip=_trip_info(rig))
        summary["record"] = str(recorder.finish(meta, status))
    summary["trip"] = _trip_info(rig)
    exit_status = EXIT_OK
    if status.startswith("aborted"):
        exit_status = EXIT_ABORTED
    elif status == "complete":
        try:
            result = identify([read_record(summary["record"])], "energy")
            summary.update(lambda66=result.lambda66, ci95=list(result.ci95), n_intervals=result.n_intervals)
            if result.lambda66 is None or not np.isfinite(result.lambda66):
                summary["lambda66"] = None
                summary["identify_error"] = f"the energy method gave no finite lambda66 ({result.lambda66!r})"
                exit_status = EXIT_IDENTIFY_FAILED
        except (IdentificationError, ValueError) as e:  # a record the estimator cannot use: not a crash
            summary["identify_error"] = f"{type(e).__name__}: {e}" if not isinstance(e, IdentificationError) else str(e)
            exit_status = EXIT_IDENTIFY_FAILED
    summary["wall_s"] = time.perf_counter() - t_start
    summary["exit_status"] = exit_status
    return summary, exit_status


def _run(exp: Experiment, rig: BenchRig, controller: Controller, host_rate_hz: float | None = None,
         board_mode: str | None = None) -> None:
    """The loop of ``run_experiment``, on the bench (two-rate: ``drive_two_rate``)."""
    exp.start()
    if host_rate_hz is None:
        drive(exp, controller)
    else:
        from addedinertia_env.experiment.two_rate import drive_two_rate  # noqa: PLC0415

        drive_two_rate(exp, controller, host_rate_hz, board_mode)
    rig.disarm()


def _timing(rig: BenchRig) -> dict[str, Any]:
    t = rig.timing
    out = loop_stats(t.intervals, rig.dt if rig.caps else 0.0, rig.lockstep)
    compute = np.asarray(t.compute_s) if t.compute_s else np.zeros(1)
    sent_current = [abs(c.value) for c in rig.sent if c.mode == "current"]
    sent_voltage = [abs(c.value) for c in rig.sent if c.mode == "voltage"]
    if rig.two_rate:
        periods = np.asarray(t.segment_intervals) if t.segment_intervals else np.full(1, np.nan)
        slack = np.asarray(t.segment_slack_ms) if t.segment_slack_ms else np.full(1, np.nan)
        out.update(host_rate_hz=rig.host_rate_hz, segments_sent=t.segments_sent,
                   host_period_p50_ms=1e3 * float(np.median(periods)),
                   host_period_p99_ms=1e3 * float(np.percentile(periods, 99)),
                   segment_slack_p1_ms=float(np.percentile(slack, 1)),
                   deadline_misses=int(np.sum(slack < 0)), late_segments=t.late_segments,
                   board_hold_samples=t.hold_samples, samples_lost=t.samples_lost)
    out.update(overruns=t.overruns, skipped_samples=t.skipped_samples, lockstep_retries=t.lockstep_retries,
               host_compute_p99_ms=1e3 * float(np.percentile(compute, 99)),
               commands_sent=len(rig.sent), commands_clamped=rig.envelope.clamped if rig.envelope else 0,
               max_abs_current_sent_A=max(sent_current, default=0.0),
               max_abs_voltage_sent_V=max(sent_voltage, default=0.0),
               link_errors={"bad_crc": rig.link.parser.stats.bad_crc, "seq_gaps": rig.link.stats.seq_gaps,
                            "bad_messages": rig.link.stats.bad_messages,
                            "skipped_bytes": rig.link.parser.stats.skipped_bytes})
    return out


def _trip_info(rig: BenchRig) -> dict[str, Any] | None:
    if rig.trip is None:
        return None
    info = {"kind": rig.trip.kind, "message": str(rig.trip)}
    if rig.safe_command_wall is not None and rig.trip_wall is not None:
        info["detect_to_safe_command_ms"] = 1e3 * (rig.safe_command_wall - rig.trip_wall)
    return info
