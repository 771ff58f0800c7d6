"""Reverse-symmetric experiments in many slots of one batched rig: the protocol on arrays.

:class:`ExperimentPool` runs :class:`~addedinertia_env.experiment.protocol.Experiment`'s
state machine for every slot of a :class:`~addedinertia_env.sim.batched.BatchedRig` at
once, one rig sample per :meth:`ExperimentPool.sample`:

``settle`` (braked, passive) -> ``free`` (released; the hull swings through neutral; the
stop is predicted by the same quadratic over the last ``stop_window_s`` of encoder
samples, and the brake set there) -> ``ready`` (braked at the stop, paused until an
environment takes the slot) -> ``hold`` (the agent's commands; brake on) -> ``reverse``
(brake off, the agent tracks the mirrored reference) -> ``ended`` (paused; the record
is identified and the slot recycled).

What is shared with the single experiment, not copied: the rig's forces, motor and
sensor model (the batched rig), the causal rate filter's weights
(:func:`~addedinertia_env.experiment.filters.endpoint_slope_weights`), the stroke fit
(:func:`~addedinertia_env.experiment.reference.fit_stroke`, called per slot on its own
encoder record), the reference law (evaluated by :mod:`.reference` as ``chebval``
does), the run record's assembly (:func:`~addedinertia_env.experiment.sample_log.make_record`)
and the identification (:func:`~addedinertia_env.identify.identify`).

One difference, by design: the passive tail after the reverse stroke (``tail_s``) is
not simulated; a slot's record ends with its last reverse-stroke sample. The tail
carries no reward and no term of the energy balance (tests/test_vector_env.py checks
that the identified lambda66 equals the single environment's).

A scenario's control loop (a benchmark suite's: reading delay, a 100 Hz drive with
zero-order hold, quantised set-points; hard-v0) runs on the pool's
:class:`~addedinertia_env.loop.control_loop.LoopState`, the class the single environment's
:class:`~addedinertia_env.loop.control_loop.LoopRig` runs with one environment: commands
pass through it to the rig, readings through its delay lines to everything here.

Paused slots (``empty``, ``ready``, ``ended``) keep their state, clock, noise counter
and delay lines: the rig's ``active`` mask. Every slot's samples go to a staging block
(``STAGE`` samples x columns, in tiles of ``LANES`` slots) and from there to the slot's own
log arrays. A sample's bookkeeping in every slot (the log, energy, tracking error, stage
changes, free-stroke detection, settling) is one compiled pass, :mod:`.pool_kernels`; what
needs Python (the stroke fit at a stop, brakes) comes back from it as lists of slots.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, Sequence

import numpy as np
from numba.typed import List

from addedinertia_env.experiment.filters import endpoint_slope_weights
from addedinertia_env.experiment.reference import MirroredReference, fit_stroke
from addedinertia_env.experiment.sample_log import make_record
from addedinertia_env.sim import forces
from addedinertia_env.sim.batched import CURRENT, VOLTAGE, BatchedRig
from addedinertia_env.loop.control_loop import LoopState
from addedinertia_env.sim.simulated import SimulatedRigBase
from addedinertia_env.sim.sensors import BatchedReading
from addedinertia_env.experiment.scenarios import Scenario
from addedinertia_env.vector.pool_kernels import (
    BROKEN,
    ENDED_NOW,
    EVENTS,
    OVER,
    RELEASE,
    STOP,
    TO_REVERSE,
    flush_staged,
    restore_rings,
    slot_bookkeeping,
    slot_masks,
    slot_rates,
)
from addedinertia_env.vector.reference import MirroredReferences

EMPTY, SETTLE, FREE, READY, HOLD, REVERSE, ENDED = range(7)
STAGE_NAMES = ("empty", "settle", "free", "ready", "hold", "reverse", "ended")
RING = 64  # samples of encoder history kept for the rate filters and the stop fit
STAGE = 256  # samples staged before they are copied to the slots' logs
PAD = 8  # extra positions per ring row (cache sets; see __init__)
LANES = 8  # slots side by side in the staging block (one 64-byte cache line of float64)
COLUMNS = ("phi", "psi", "u", "i", "i_cmd", "u_cmd")
RATE_WINDOW_S = 0.04  # s, as RateEstimator's default


def _plan_block(plan) -> dict[str, Any]:
    """``dataclasses.asdict(plan)``: a plain copy when every field is a number, text or None (no
    deep copies to make), else asdict itself."""
    out = {f.name: getattr(plan, f.name) for f in dataclasses.fields(plan)}
    if all(v is None or type(v) in (int, float, str, bool) for v in out.values()):
        return out
    return dataclasses.asdict(plan)


class SlotRig(SimulatedRigBase):
    """What a slot's run record says about its rig: known constants and (simulator) truth."""

    source = "sim"

    def __init__(self, params, loop=None):
        self.params = params
        self.loop = loop  # the scenario's ControlLoop (None: ideal)

    def truth(self) -> dict:
        """The slot's ``truth`` block as :meth:`MujocoRig.truth` writes it (:func:`forces.truth`: lambda66 kg m^2, effects, damping, true k_t N m/A, neutral rad, the hydrodynamic model if not constant; the control loop if not ideal). Scoring only."""
        truth = forces.truth(self.params, float(forces.true_torque_constant(self.params)))
        if self.loop is not None and not self.loop.ideal:  # as LoopRig.truth
            truth["control_loop"] = self.loop.to_dict()
        return truth


def sample_times(n: int, sample_dt: float, substeps: int) -> np.ndarray:
    """The rig clock after 0..n-1 samples, accumulated physics step by physics step as the rigs do, s."""
    steps = np.full(1 + max(n - 1, 0) * substeps, sample_dt / substeps)
    steps[0] = 0.0
    return np.add.accumulate(steps)[::substeps][:n]


class ExperimentPool:
    """``n`` experiment slots on one batched rig (module docstring).

    ``control_mode``: ``"current"`` or ``"voltage"`` (the agent's commands).
    """

    def __init__(self, n: int, first: Scenario, control_mode: str = "current"):
        self.n = n
        self.control_mode = control_mode
        self.mode_code = CURRENT if control_mode == "current" else VOLTAGE
        rig = first.rig
        self.dt = rig.sensors.dt
        self.substeps = rig.physics_substeps
        self.rig = BatchedRig([rig] * n, seed=list(range(n)), initial_reading=False)
        self.loop = LoopState(n, self.dt, size=RING)  # the scenarios' control loops (ideal until begin)
        self.stage = np.full(n, EMPTY, dtype=np.int8)
        self.scenarios: list[Scenario | None] = [None] * n
        self.views: list[SlotRig | None] = [None] * n
        self.refs = MirroredReferences(n)
        self.laws: list = [None] * n  # each slot's fitted stroke law (experiment.reference.StrokeLaw)
        self._ref_table = np.zeros((n, 1024))  # phi_ref at the reverse stroke's samples, per slot
        self._ref_first = np.zeros(n, dtype=np.int64)  # log index of its first entry
        self._ref_len = np.zeros(n, dtype=np.int64)
        self._cols = np.arange(n)
        f = lambda v=0.0: np.full(n, v)  # noqa: E731
        # Known constants and plan, per slot
        self.phi_n, self.c_known, self.k_t_known, self.J_f_known = f(), f(), f(), f()
        self.i_max, self.u_max = f(1.0), f(1.0)
        self.sign, self.hold_s, self.lead_s = f(1.0), f(), f()
        self.settle_left = np.zeros(n, dtype=np.int64)
        self.free_n = np.zeros(n, dtype=np.int64)
        self.free_max = np.zeros(n, dtype=np.int64)
        self.window = 0
        self._stop_fit: np.ndarray | None = None
        # Free-stroke detection
        self.t_cross, self.peak = f(math.nan), f()
        self.t_release, self.t_brake, self.inertia_prior, self.fit_rms = f(math.nan), f(math.nan), f(math.nan), f()
        # Controlled part
        self.energy = f()  # J, integral of |u i| over hold and reverse
        self.last_t = f()
        self.k_release = np.zeros(n, dtype=np.int64)  # log index of the first free sample
        self.k_hold = np.zeros(n, dtype=np.int64)  # first hold sample
        self.k_reverse = np.zeros(n, dtype=np.int64)  # first reverse sample
        # Last reading and rate estimates, per slot
        self.phi, self.psi, self.u, self.i = f(), f(), f(), f()
        self.t = f()
        self.hull_rate, self.fly_rate = f(), f()
        # Encoder history (doubled ring: the last RING samples are one contiguous slice)
        # slot x (phi, psi) x position: a slot's history contiguous (rows padded off a power of two,
        # so that one sample's writes to every slot do not all fall into the same cache sets)
        self._ring = np.zeros((n, 2, RING + PAD))[:, :, :RING]
        self._g = 0  # ring position of the newest sample
        self.n_rate = max(3, int(round(RATE_WINDOW_S / self.dt)))
        if self.n_rate > RING:
            raise ValueError(f"rate window of {self.n_rate} samples exceeds the ring of {RING}")
        self._w_rate = endpoint_slope_weights(self.n_rate, self.dt)
        self._was_active = np.zeros(n, dtype=bool)
        self._unfitted = np.zeros(n, dtype=bool)  # ready slots whose stroke fit is still to do (fit_stops)
        self._events = np.zeros((len(EVENTS), n), dtype=np.int64)  # slot_bookkeeping's event lists
        self._n_events = np.zeros(len(EVENTS), dtype=np.int64)
        self._no_slots = np.zeros(0, dtype=np.int64)
        # Logs
        # tile x row x column x lane, slot k in tile k // LANES, lane k % LANES: one sample's writes
        # fill whole cache lines, and the tiles are one row longer than STAGE (cache sets, as the ring)
        self._stage_block = np.zeros((-(-n // LANES), STAGE + 1, len(COLUMNS), LANES))
        self._stage_row = 0
        self._stage_from = np.zeros(n, dtype=np.int64)
        self._stage_cnt = np.zeros(n, dtype=np.int64)
        self._log_arrays = [np.zeros((len(COLUMNS), 0)) for _ in range(n)]  # column x sample, per slot
        self._logs = List(self._log_arrays)  # the same arrays in numba's list (flush_staged writes them)
        self._log_cap = np.zeros(n, dtype=np.int64)  # samples each log holds
        self._flushed = np.zeros(n, dtype=np.int64)
        self._times = sample_times(1, self.dt, self.substeps)

    # --- slots ----------------------------------------------------------------------------
    def times(self, n: int) -> np.ndarray:
        """The clock of a slot's first ``n`` log entries, s."""
        if len(self._times) < n:
            self._times = sample_times(max(n, 2 * len(self._times)), self.dt, self.substeps)
        return self._times[:n]

    def begin(self, slots: Sequence[int], scenarios: Sequence[Scenario]) -> None:
        """Start experiments ``scenarios`` in ``slots``: new rigs, twist, first reading (settle begins)."""
        slots = np.asarray(slots, dtype=np.int64)
        if not len(slots):
            return
        rigs = [s.rig for s in scenarios]
        for s in scenarios:
            if s.rig.physics_substeps != self.substeps or s.rig.sensors.dt != self.dt:
                raise ValueError(f"scenario {s.name}: its rig's clock differs from the pool's "
                                 f"({s.rig.sensors.dt} s, {s.rig.physics_substeps} substeps)")
        self.rig.set_envs(slots, rigs, [s.sensor_seed for s in scenarios])
        self.rig.sensors.counters[slots] = 1  # a single rig takes one reading when it is built
        for k, s in zip(slots, scenarios):
            k = int(k)
            self.scenarios[k] = s
            self.views[k] = SlotRig(s.rig, s.loop)
            known, plan = s.rig.known(), s.plan
            self.phi_n[k], self.c_known[k] = known.phi_neutral, known.c_torsion
            self.k_t_known[k], self.J_f_known[k] = known.k_t, known.J_flywheel
            self.i_max[k] = known.current_limit
            self.u_max[k] = math.nan if known.u_max is None else known.u_max
            self.sign[k] = 1.0 if plan.alpha > 0 else -1.0
            self.hold_s[k], self.lead_s[k] = plan.hold_s, plan.lead_s
            self.settle_left[k] = int(round(plan.settle_s / self.dt))
            self.free_max[k] = int(round(plan.max_free_s / self.dt))
            window = max(5, int(round(plan.stop_window_s / self.dt)))
            if self.window and window != self.window:
                raise ValueError("all slots of a pool share the stop-fit window (stop_window_s)")
            if window > RING:
                raise ValueError(f"stop_window_s of {plan.stop_window_s} s: at most {RING} samples")
            self.window = window
        phi0 = self.phi_n[slots] - np.array([s.plan.alpha for s in scenarios])
        self.loop.configure(slots, [s.loop for s in scenarios])
        reading = self.rig.reset(phi0=phi0, envs=slots)
        self.loop.reset(slots, [reading.phi, reading.psi, reading.u, reading.i])
        for name in ("t_cross", "t_release", "t_brake", "inertia_prior"):
            getattr(self, name)[slots] = math.nan
        for name in ("peak", "energy", "fit_rms"):
            getattr(self, name)[slots] = 0.0
        self.free_n[slots] = 0
        self.refs.t_begin[slots] = 0.0
        self.refs.t_end[slots] = 0.0
        self._ref_len[slots] = 0
        self.phi[slots], self.psi[slots], self.u[slots], self.i[slots] = reading.phi, reading.psi, reading.u, reading.i
        self.t[slots] = self.last_t[slots] = reading.t
        self.hull_rate[slots] = self.fly_rate[slots] = 0.0
        self._stage_cnt[slots] = 0
        self._flushed[slots] = 1
        for j, k in enumerate(slots):
            if self._log_cap[k] < 4096:
                self._set_log(k, np.zeros((len(COLUMNS), 4096)))
                self._log_cap[k] = 4096
            self._log_arrays[k][:, 0] = (reading.phi[j], reading.psi[j], reading.u[j], reading.i[j], 0.0, 0.0)
        self.stage[slots] = SETTLE
        self._was_active[slots] = False
        self._unfitted[slots] = False
        done = slots[self.settle_left[slots] <= 0]
        if len(done):
            self._release(done)

    def _release(self, slots: np.ndarray) -> None:
        self.rig.set_brake(False, envs=slots)
        self.t_release[slots] = self.t[slots]
        self.k_release[slots] = self._flushed[slots] + self._stage_cnt[slots]
        self.stage[slots] = FREE

    # --- one rig sample ---------------------------------------------------------------------
    def sample(self, value: np.ndarray, controlled: np.ndarray) -> dict[str, np.ndarray]:
        """One rig sample of every slot. ``value``: the agent's command per slot (A or V; used
        where ``controlled``: slots in hold or reverse that an environment drives now).

        Returns the per-slot increments of this sample for the reward (``tracking_sq`` rad^2,
        ``energy`` J, ``limit`` 0/1) and ``ended`` (slots whose reverse stroke ended here).
        """
        stage, n = self.stage, self.n
        value = np.asarray(value, dtype=float)
        settling, freeing, active = np.empty(n, dtype=bool), np.empty(n, dtype=bool), np.empty(n, dtype=bool)
        mode, command, resumed = np.empty(n, dtype=np.int64), np.empty(n), np.empty(n, dtype=np.int64)
        n_resumed = slot_masks(stage, controlled, self._was_active, self.mode_code, value, settling, freeing, active,
                               mode, command, resumed)
        if not self.loop.ideal:  # the drives' set-points through the scenarios' control loops
            applied = self.loop.command(value, controlled, active & ~controlled, self.mode_code == CURRENT)
            command = np.where(controlled, applied, 0.0)
        r = self.rig.step(mode, command, active=active)
        if not self.loop.ideal:  # what the hosts receive: readings through the loops' delay lines
            phi, psi, u, i = self.loop.arrive([r.phi, r.psi, r.u, r.i], active)
            r = BatchedReading(t=r.t, phi=phi, psi=psi, u=u, i=i, brake=r.brake)
        g = self._g = (self._g + 1) % RING
        if n_resumed:
            self._restore_ring(resumed[:n_resumed])
        e_sq, d_energy, limit = np.empty(n), np.empty(n), np.empty(n, dtype=bool)
        events, counts = self._events, self._n_events
        while True:  # the log, energy, tracking, stage changes, free strokes and settling (pool_kernels.py)
            slot_bookkeeping(g, self._stage_row, self._ring, self._stage_block, self._stage_from,
                             self._stage_cnt, self._flushed, active, controlled, settling, freeing,
                             value, self.mode_code == CURRENT, r.phi, r.psi, r.u, r.i, r.t,
                             self.energy, self.last_t, self.phi, self.psi, self.u, self.i, self.t,
                             self.i_max, self.u_max, self._ref_table, self._ref_first, self._ref_len, stage,
                             self.refs.t_begin, self.refs.t_end, self.dt, self.free_n, self.free_max,
                             self.hull_rate, self.sign, self.peak, self.t_cross, self.phi_n, self.n_rate,
                             self._w_rate, self.window, *self._stop_rows(), self.settle_left,
                             e_sq, d_energy, limit, events, counts)
            if not counts[BROKEN]:
                break
            self._flush(events[BROKEN, :counts[BROKEN]].copy())  # staged samples before a pause: to the logs
        lists = [events[e, :c].copy() if c else self._no_slots for e, c in enumerate(counts.tolist())]
        if self._stage_row == STAGE - 1:
            self._flush(self._stage_cnt.nonzero()[0])
            self._stage_row = 0
        else:
            self._stage_row += 1
        self._was_active = active
        out: dict[str, np.ndarray] = {}
        if controlled.any():
            out = {"tracking_sq": e_sq, "energy": d_energy, "limit": limit,
                   "ended": self._phase_changes(lists[TO_REVERSE], lists[ENDED_NOW])}
        over = lists[OVER]
        if len(over):
            raise RuntimeError(f"the hull did not stop within max_free_s in slot(s) {over.tolist()} "
                               f"(scenario {self.scenarios[int(over[0])].name})")
        if len(lists[STOP]):
            self._brake_at_stop(lists[STOP])
        if len(lists[RELEASE]):
            self._release(lists[RELEASE])
        return out

    def _phase_changes(self, to_rev: np.ndarray, ended: np.ndarray) -> np.ndarray:
        """Hold -> reverse (brake off) in ``to_rev``, reverse -> ended in ``ended`` (Experiment.step); returns ``ended``."""
        if len(to_rev):
            self.rig.set_brake(False, envs=to_rev)
            self.stage[to_rev] = REVERSE
            self.k_reverse[to_rev] = self._flushed[to_rev] + self._stage_cnt[to_rev]
        if len(ended):
            self.hull_rate[ended] = self._rate(0, ended)  # the terminal observation's
            self.fly_rate[ended] = self._rate(1, ended)
            self.stage[ended] = ENDED
        return ended

    def _stop_rows(self) -> tuple[np.ndarray, np.ndarray]:
        """The rows of the stop fit's pseudo-inverse giving ``c2`` and ``c1`` of the quadratic over the
        last ``window`` samples (``np.polyfit``'s order), newest at time 0."""
        n = max(self.window, 3)
        if self._stop_fit is None or self._stop_fit.shape[1] != n:
            tt = (np.arange(n) - (n - 1)) * self.dt
            self._stop_fit = np.ascontiguousarray(np.linalg.pinv(np.vander(tt, 3)))  # rows: c2, c1, c0
        return self._stop_fit[0], self._stop_fit[1]

    def _brake_at_stop(self, slots: np.ndarray) -> None:
        """Slots whose free stroke ends here: brake set (released at once if they hold for 0 s),
        ready. Their stroke fits wait for :meth:`fit_stops` (a slot's stroke is fixed from now on)."""
        self.fly_rate[slots] = self._rate(1, slots)  # the first observation's (ring current now)
        self.rig.set_brake(True, envs=slots)
        self.t_brake[slots] = self.t[slots]
        self._flush(slots)
        self.k_hold[slots] = self._flushed[slots]
        no_hold = slots[self.hold_s[slots] <= 0]
        if len(no_hold):
            self.rig.set_brake(False, envs=no_hold)
        self.k_reverse[no_hold] = self._flushed[no_hold]
        self._unfitted[slots] = True
        self.stage[slots] = READY

    def fit_stops(self, slots: np.ndarray | None = None, stop=None) -> int:
        """The stroke fits of ready slots not fitted yet (``slots``, or all), one after another
        until ``stop()`` is true (None: all): the mirrored reference each slot's reverse stroke
        will track, its fit residual and inertia prior (``fit_stroke`` on the slot's logged free
        stroke). :meth:`take` does those of its slots first; a process that would otherwise wait
        does them earlier (the same numbers whenever it runs). Returns how many were done."""
        pending = np.nonzero(self._unfitted)[0] if slots is None else slots[self._unfitted[slots]]
        done = 0
        for k in pending.tolist():
            if stop is not None and stop():
                break
            self._fit_stop(k)
            done += 1
        return done

    def _fit_stop(self, k: int) -> None:
        n = int(self.k_hold[k])  # the log up to the stop
        t, phi = self.times(n), self._log_arrays[k][0, :n]
        law = self.laws[k] = fit_stroke(t, phi, float(self.t_cross[k] - self.lead_s[k]), float(self.t_brake[k]))
        self.fit_rms[k] = law.fit_rms
        self.inertia_prior[k] = law.inertia_prior(float(self.c_known[k]), float(self.phi_n[k]))
        self.refs.set(k, law, float(self.t_brake[k] + self.hold_s[k]))
        self._tabulate_reference(k, n)
        self._unfitted[k] = False

    def _tabulate_reference(self, k: int, first: int) -> None:
        """phi_ref of slot ``k`` at every sample of its reverse stroke (the samples with
        ``t_begin < t <= t_end + dt / 2``, as ReverseStrokeTask.tracking_error), log index from ``first`` on."""
        refs = self.refs
        span = int(math.ceil((self.hold_s[k] + refs.duration[k]) / self.dt)) + 4
        t = self.times(first + span)[first:]
        until = refs.t_end[k] + 0.5 * self.dt
        a, b = refs.tabulate(k, t, until, self._ref_table[k])
        if b == a:  # no sample of the reverse stroke
            self._ref_len[k] = 0
            return
        if b - a > self._ref_table.shape[1]:
            grown = np.zeros((self.n, max(b - a, 2 * self._ref_table.shape[1])))
            grown[:, :self._ref_table.shape[1]] = self._ref_table
            self._ref_table = grown
            refs.tabulate(k, t, until, self._ref_table[k])
        self._ref_first[k], self._ref_len[k] = first + a, b - a

    def take(self, slots: np.ndarray) -> None:
        """Ready slots start their controlled part (hold, or reverse when ``hold_s`` is 0); their
        stroke fits first, if not done yet (:meth:`fit_stops`)."""
        self.fit_stops(np.asarray(slots, dtype=np.int64))
        self.stage[slots] = np.where(self.hold_s[slots] > 0, HOLD, REVERSE)

    # --- rates and logs --------------------------------------------------------------------
    def _rate(self, j: int, cols: np.ndarray) -> np.ndarray:
        """RateEstimator's value for the newest sample of slots ``cols`` (their ring must be current;
        :func:`~.pool_kernels.slot_rates`)."""
        cols = np.asarray(cols, dtype=np.int64)
        out = np.empty(len(cols))
        slot_rates(self._ring, j, self._g, cols, (self._flushed + self._stage_cnt)[cols], self.n_rate,
                   self._w_rate, self.dt, out)
        return out

    def refresh_rates(self, slots: np.ndarray) -> None:
        """Hull and flywheel rate estimates of ``slots`` that took the last sample (others keep theirs)."""
        cols = slots[self._was_active[slots]]
        if len(cols):
            self.hull_rate[cols] = self._rate(0, cols)
            self.fly_rate[cols] = self._rate(1, cols)

    def _restore_ring(self, slots: np.ndarray) -> None:
        """Slots that run again after a pause: their encoder history back into the ring (newest
        at the position before the current one; :func:`~.pool_kernels.restore_rings`)."""
        self._flush(slots)
        restore_rings(self._ring, self._logs, slots, self._flushed, self._g)

    def _set_log(self, k: int, log: np.ndarray) -> None:
        """Slot ``k``'s log array (column x sample) becomes ``log``, in both lists of logs."""
        self._log_arrays[k] = log
        self._logs[k] = log

    def _flush(self, slots) -> None:
        """Copy the staged samples of ``slots`` to their own logs."""
        slots = np.asarray(slots, dtype=np.int64).reshape(-1)
        slots = slots[self._stage_cnt[slots] > 0]
        if not len(slots):
            return
        need = self._flushed[slots] + self._stage_cnt[slots]
        short = slots[need > self._log_cap[slots]]
        for k in short.tolist():  # logs that grow (rare): twice the size, or what is needed
            n0, size = int(self._flushed[k]), max(2 * int(self._log_cap[k]), int(self._flushed[k] + self._stage_cnt[k]))
            grown = np.zeros((len(COLUMNS), size))
            grown[:, :n0] = self._log_arrays[k][:, :n0]
            self._set_log(k, grown)
            self._log_cap[k] = size
        flush_staged(self._stage_block, self._logs, slots, self._stage_cnt, self._stage_from, self._flushed)

    # --- records --------------------------------------------------------------------------
    def record(self, k: int, run_id: str = "run"):
        """Slot ``k``'s run record so far (as the single experiment writes it, without the tail)."""
        self._flush([k])
        n = int(self._flushed[k])
        log = self._log_arrays[k]
        phase = np.empty(n, dtype="<U7")
        phase[:] = "idle"
        kr, kh = int(self.k_release[k]), int(self.k_hold[k])
        stage = self.stage[k]
        past_free = stage in (READY, HOLD, REVERSE, ENDED)
        phase[kr:kh if past_free else n] = "free"
        brake = np.ones(n)
        brake[kr:kh if past_free else n] = 0.0
        if past_free:
            in_reverse = stage in (REVERSE, ENDED)
            kv = int(self.k_reverse[k]) if in_reverse else n
            phase[kh:kv] = "hold"
            phase[kv:n] = "reverse"
            brake[kv:n] = 0.0
        samples = {"t": self.times(n).copy(), "phase": phase, "phi": log[0, :n].copy(), "psi": log[1, :n].copy(),
                   "u": log[2, :n].copy(), "i": log[3, :n].copy(), "i_cmd": log[4, :n].copy(),
                   "u_cmd": log[5, :n].copy(), "brake": brake}
        s = self.scenarios[k]
        experiment = {"kind": "reverse-symmetric", **_plan_block(s.plan),
                      "t_release": float(self.t_release[k]), "t_brake": float(self.t_brake[k])}
        if past_free:
            experiment["stroke_fit_rms_rad"] = float(self.fit_rms[k])
        experiment["scenario"] = s.name
        return make_record(samples, self.views[k], experiment, run_id)

    def reference(self, k: int) -> MirroredReference:
        """The mirrored reference slot ``k``'s episode drives (its free stroke must be fitted)."""
        return MirroredReference(self.laws[k], t_begin=float(self.t_brake[k] + self.hold_s[k]))

    def info(self, k: int) -> dict[str, Any]:
        """What identifies slot ``k``'s episode: scenario name and seed, sensor quality."""
        s = self.scenarios[k]
        return {"scenario": s.name, "scenario_seed": s.seed, "sensor_quality": s.sensor_quality}
