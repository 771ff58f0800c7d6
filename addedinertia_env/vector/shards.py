"""The batched task over several processes: ``num_envs`` split into shards, one per CPU core.

``gym.make_vec("AddedInertia/ReverseStroke-v0", num_envs=N, workers=W)`` with ``W`` > 1
gives :class:`ShardedVectorEnv`: ``W`` shards, each a
:class:`~addedinertia_env.vector.env.ReverseStrokeVectorEnv` of about ``N / W``
environments, stepped at the same time: shard 0 in this process, the others in ``W - 1``
worker processes (the actions go out to the workers, this process steps its own shard
meanwhile, then every shard's results are joined in environment order). Each shard is the
one-process vector env, so its episodes, rewards and records are exactly that env's; the
shard holding environments ``a..b`` is reset with ``seed + a``, so environment ``e``'s first
episode after ``reset(seed=s)`` is still the single environment's ``reset(seed=s + e)``.
What differs from one process: the spare episodes (those after an autoreset) are drawn
per shard, so they are other scenarios than one process would draw (each reports its
``scenario_seed``, as always).

The end-of-episode identification is shared: a step runs in two halves. First every shard
samples its environments (:meth:`~.env.ReverseStrokeVectorEnv.advance`) and says how long the
records of its ended episodes are; then :func:`balance_plan` moves records from the shard with
the most identification work to the one with the least, each shard identifies what it holds
(:func:`~.env.estimate_lambda66`), the estimates of moved records go back to their shard, and
every shard finishes its step (:meth:`~.env.ReverseStrokeVectorEnv.finish`). The numbers are the
same wherever a record is identified; only the wall time changes (the step waits for the
slowest shard, so without this the shard that happens to have more episodes ending sets it).
A shard starts its step's spare episodes (:meth:`~.env.ReverseStrokeVectorEnv.start_spares`, a
few ms every few steps) while it waits for the others, not in its sampling half: the same
episodes, and the halves are more even (measured: 715k -> 735k samples/s, 6 alternating runs).
So does it with the stroke fits of the spares that reached their stop
(:meth:`~.env.ReverseStrokeVectorEnv.fit_spare_stops`, one fit at a time while nobody has answered; an
environment taking a slot whose fit is not done does it then): 900k -> 933k samples/s, 3
alternating runs each.

Shard 0 is a little smaller than the others (:func:`shard_sizes`), since this process also relays
the records and joins the shards' results.

Why shard 0 lives in this process rather than in a worker of its own: this process would
otherwise sit idle while the workers step and then relay their results with the workers idle,
and on a machine with as many cores as shards a third process only takes turns with them.

Use it when the machine has idle cores: on one busy core it only adds the transfers.
"""

from __future__ import annotations

import multiprocessing as mp
import time
import traceback
from collections import Counter
from typing import Any

import numpy as np
from gymnasium.vector import VectorEnv

from addedinertia_env.vector.env import ReverseStrokeVectorEnv, estimate_lambda66

# Shard 0 (this process) holds this fraction fewer environments than an even split: besides its
# shard it relays the records, joins the shards' results and runs the caller's code, and with an
# even split the workers waited for it more than it for them. 2 processes, N = 1024, 5 alternating
# runs: shards of 499 and 525 environments 949k samples/s (median), 512 each 942k; faster in every pair.
LIGHTER_SHARD_0 = 0.025
MOVE_MARGIN = 0.15  # a record moves only if the busiest shard's load drops by more than this fraction of it (the transfer's cost)


def shard_sizes(num_envs: int, workers: int) -> list[int]:
    """Environments per shard: an even split, then shard 0 gives :data:`LIGHTER_SHARD_0` of its
    share (rounded; none for small shards) to the others in turn."""
    base, extra = divmod(num_envs, workers)
    sizes = [base + (k < extra) for k in range(workers)]
    give = int(round(LIGHTER_SHARD_0 * sizes[0])) if workers > 1 else 0
    sizes[0] -= give
    for j in range(give):
        sizes[1 + j % (workers - 1)] += 1
    return sizes


def balance_plan(loads: list[list[float]], margin: float = MOVE_MARGIN) -> list[tuple[int, int, int]]:
    """Which ended episodes' records to identify in another shard: ``loads[k]`` holds the cost of
    each record shard ``k`` has (its number of samples, say). Greedy: while moving one record from
    the most loaded shard to the least loaded lowers the larger of their two loads by more than
    ``margin`` times that record's cost, move the record that best evens them. Returns the moves
    as ``(from shard, record index in it, to shard)``; the records' own shard does the rest."""
    totals = [float(sum(c)) for c in loads]
    left = [dict(enumerate(c)) for c in loads]  # records not moved yet, by index
    moves: list[tuple[int, int, int]] = []
    while len(totals) > 1:
        src = max(range(len(totals)), key=totals.__getitem__)
        dst = min(range(len(totals)), key=totals.__getitem__)
        best, best_gain = None, 0.0
        for i, c in left[src].items():
            gain = totals[src] - max(totals[src] - c, totals[dst] + c) - margin * c
            if gain > best_gain:
                best, best_gain = i, gain
        if best is None:
            break
        c = left[src].pop(best)
        totals[src] -= c
        totals[dst] += c
        moves.append((src, best, dst))
    return moves


class StepClock:
    """Where one process's wall time goes in the sharded steps, while ``on``: :meth:`lap` gives the
    time since the previous lap to an activity (``sample``: the sampling half, ``spares``: spare
    starts, ``fits``: the spares' stroke fits, ``identify``, ``transfer``: records and results to and from other processes, the plan,
    ``finish``, ``join``: the shards' results put together, ``wait``: blocked until another process
    answers, ``caller``: between two steps, in the caller's code), summed in ``seconds``."""

    def __init__(self):
        self.on = False
        self.seconds: Counter = Counter()
        self._last = 0.0

    def switch(self, on: bool) -> None:
        """Start (from zero) or stop counting."""
        self.on, self.seconds, self._last = on, Counter(), time.perf_counter()

    def lap(self, activity: str) -> None:
        """The time since the previous lap goes to ``activity``."""
        if self.on:
            now = time.perf_counter()
            self.seconds[activity] += now - self._last
            self._last = now


def _expect(conn, kind: str):
    command, args = conn.recv()
    if command != kind:
        raise RuntimeError(f"shard protocol: expected {kind!r} from the parent, got {command!r}")
    return args


def _settle(conn, env: ReverseStrokeVectorEnv, pending, export: list[int], n_import: int, clock: StepClock):
    """The second half of a sharded step in a worker (module docstring): send the ``export``
    records, take ``n_import`` records of other shards, identify those and its own others, send
    the foreign estimates back, take the estimates of the exported records, finish the step.
    Foreign records are read before any identification, so the shard sending them never waits."""
    records = pending.records
    if export:
        conn.send(("ok", [records[i] for i in export]))
        clock.lap("transfer")
    if n_import:
        env.fit_spare_stops(conn.poll)
        clock.lap("fits")
    foreign = _expect(conn, "foreign") if n_import else []
    clock.lap("wait")
    moved = set(export)
    estimates: list = [None] * len(records)
    for i, record in enumerate(records):
        if i not in moved:
            estimates[i] = estimate_lambda66(record, env.score_method)
    clock.lap("identify")
    if n_import:
        results = [estimate_lambda66(r, env.score_method) for r in foreign]
        clock.lap("identify")
        conn.send(("ok", results))
        clock.lap("transfer")
    if export:
        env.fit_spare_stops(conn.poll)
        clock.lap("fits")
        for i, estimate in zip(export, _expect(conn, "estimates")):
            estimates[i] = estimate
        clock.lap("wait")
    out = env.finish(pending, estimates)
    clock.lap("finish")
    return out


def _worker(conn, num_envs: int, kwargs: dict) -> None:
    env = None
    pending = None
    clock = StepClock()
    try:
        env = ReverseStrokeVectorEnv(num_envs, **kwargs)
        conn.send(("ok", None))
        while True:
            command, args = conn.recv()
            clock.lap("wait")
            if command == "close":
                break
            if command == "advance":  # first half of a step: the ended episodes' record lengths
                pending = env.advance(args, defer_spares=True)
                clock.lap("sample")
                conn.send(("ok", [len(r) for r in pending.records]))
                if not conn.poll():  # the step's spare starts while the other shards still sample
                    env.start_spares()
                    clock.lap("spares")
                env.fit_spare_stops(conn.poll)
                clock.lap("fits")
                continue
            if command == "settle":
                out, pending = _settle(conn, env, pending, *args, clock), None
                conn.send(("ok", out))
                clock.lap("transfer")
                env.start_spares()  # if still due: while the parent joins the shards' results
                clock.lap("spares")
                env.fit_spare_stops(conn.poll)  # until the next command
                clock.lap("fits")
                continue
            if command == "clock":  # switch the step clock on or off; its seconds so far
                out = dict(clock.seconds)
                clock.switch(args)
                conn.send(("ok", out))
                continue
            if command == "step":
                out = env.step(args)
            elif command == "reset":
                out = env.reset(**args)
            elif command == "get":
                out = getattr(env, args)
            elif command == "set":
                setattr(env, *args)
                out = None
            elif command == "cpu":
                out = time.process_time()
            elif command == "record":
                out = env.record(*args)
            else:
                raise ValueError(f"unknown command {command!r}")
            conn.send(("ok", out))
    except Exception as e:  # noqa: BLE001 - sent to the parent, which raises it
        conn.send(("error", (type(e).__name__, str(e), traceback.format_exc())))
    finally:
        if env is not None:
            env.close()
        conn.close()


def _join(parts: list, sizes: list[int]) -> Any:
    """Shards' info values joined in environment order; a key that a shard lacks is filled
    (zeros, None or False) with its mask False, as Gymnasium's vector infos do."""
    present = [p for p in parts if p is not None]
    if isinstance(present[0], dict):
        keys = list(dict.fromkeys(k for p in present for k in p))
        return {k: _join([None if p is None else p.get(k) for p in parts], sizes) for k in keys}
    ref = np.asarray(present[0])
    filled = []
    for p, n in zip(parts, sizes):
        if p is None:
            fill = None if ref.dtype == object else 0
            p = np.full((n,) + ref.shape[1:], fill, dtype=ref.dtype)
        filled.append(np.asarray(p))
    return np.concatenate(filled, axis=0)


class ShardedVectorEnv(VectorEnv):
    """``num_envs`` reverse-stroke environments in ``workers`` processes, shard 0 in this one
    (module docstring); the other keyword arguments are those of
    :class:`~addedinertia_env.vector.env.ReverseStrokeVectorEnv`."""

    def __init__(self, num_envs: int, workers: int = 2, **kwargs: Any):
        if not (isinstance(workers, int) and 2 <= workers <= num_envs):
            raise ValueError(f"ShardedVectorEnv option workers={workers!r}: expected an integer in 2..num_envs "
                             f"({num_envs})")
        self.sizes = shard_sizes(num_envs, workers)
        self.offsets = np.concatenate([[0], np.cumsum(self.sizes)])
        self.num_envs = num_envs
        self._closed = False
        self._clock = StepClock()
        ctx = mp.get_context()
        self._conns, self._procs = [], []  # workers: shards 1 .. W-1
        for n in self.sizes[1:]:
            parent, child = ctx.Pipe()
            proc = ctx.Process(target=_worker, args=(child, n, kwargs), daemon=True)
            proc.start()
            child.close()
            self._conns.append(parent)
            self._procs.append(proc)
        try:
            self.local = ReverseStrokeVectorEnv(self.sizes[0], **kwargs)  # shard 0, built while the workers build theirs
        finally:
            self._gather()
        (self.single_observation_space, self.single_action_space, self.observation_space, self.action_space,
         self.metadata) = ReverseStrokeVectorEnv.spaces(num_envs, **kwargs)

    def _gather(self) -> list:
        """Every worker's next answer, in shard order (shard 1 first); the first error is raised after all are read."""
        out = []
        error = None
        for conn in self._conns:
            status, value = conn.recv()
            if status == "error" and error is None:
                error = value
            out.append(value)
        if error is not None:
            name, message, trace = error
            raise RuntimeError(f"a shard of the vector env failed: {name}: {message}\n{trace}")
        return out

    def _send_all(self, command: str, args_per_worker: list) -> None:
        for conn, args in zip(self._conns, args_per_worker):
            conn.send((command, args))

    def _all(self, command: str, args_per_worker: list) -> list:
        self._send_all(command, args_per_worker)
        return self._gather()

    def _rows(self, values) -> list:
        """``values`` (one row per environment) cut into the shards' parts."""
        return [values[lo:hi] for lo, hi in zip(self.offsets[:-1], self.offsets[1:])]

    def reset(self, *, seed: int | list | None = None, options: dict | None = None):
        """Reset every shard (``seed`` an int: the shard holding environments ``a..b`` gets ``seed + a``; or a list, one per environment); returns the joined ``(obs, info)``."""
        if seed is None or isinstance(seed, (int, np.integer)):
            seeds = [None if seed is None else int(seed) + int(a) for a in self.offsets[:-1]]
        else:
            seeds = self._rows(list(seed))
        self._send_all("reset", [{"seed": s, "options": options} for s in seeds[1:]])
        try:
            mine = self.local.reset(seed=seeds[0], options=options)
        finally:
            out = [None] + self._gather()
        out[0] = mine
        return np.concatenate([o for o, _ in out]), _join([i for _, i in out], self.sizes)

    def step(self, actions):
        """Step every shard with its rows of ``actions`` at the same time; returns ``(obs, rewards, terminated, truncated, info)`` joined in environment order."""
        clock = self._clock
        clock.lap("caller")
        parts = self._rows(np.asarray(actions).reshape(self.num_envs, -1))
        self._send_all("advance", parts[1:])
        clock.lap("transfer")
        try:
            pending = self.local.advance(parts[0], defer_spares=True)
            clock.lap("sample")
            if not self._answered():  # the spare starts while the workers still sample
                self.local.start_spares()
                clock.lap("spares")
            self.local.fit_spare_stops(self._answered)
            clock.lap("fits")
        finally:
            loads = [None] + self._gather()
            clock.lap("wait")
        loads[0] = [len(r) for r in pending.records]
        estimates = self._settle(pending, self._plan(loads))
        mine = self.local.finish(pending, estimates)
        clock.lap("finish")
        self.local.start_spares()  # if still due
        clock.lap("spares")
        self.local.fit_spare_stops(self._answered)
        clock.lap("fits")
        outs = [mine] + self._gather()
        clock.lap("wait")
        obs, rew, term, trunc, infos = zip(*outs)
        out = (np.concatenate(obs), np.concatenate(rew), np.concatenate(term), np.concatenate(trunc),
               _join(list(infos), self.sizes))
        clock.lap("join")
        return out

    def step_clock(self, on: bool) -> list[dict[str, float]]:
        """Switch every process's :class:`StepClock` on (from zero) or off; returns the seconds each
        counted so far per activity, shard 0 (this process) first."""
        self._clock.lap("caller")
        mine = dict(self._clock.seconds)
        self._clock.switch(on)
        return [mine] + self._all("clock", [on] * len(self._conns))

    def _settle(self, pending, moves: list[tuple[int, int, int]]) -> list:
        """The identification half of a step (module docstring): tell each worker what it sends and
        takes, relay the moved records, identify shard 0's share here while the workers identify
        theirs, and route the moved records' estimates back. Returns shard 0's estimates, in the
        order of ``pending.records``; the workers then finish their steps on their own."""
        exports: dict[int, list[int]] = {}
        imports: dict[int, list[tuple[int, int]]] = {}  # importer -> (exporter, position in its export list)
        for src, i, dst in moves:
            exports.setdefault(src, []).append(i)
            imports.setdefault(dst, []).append((src, len(exports[src]) - 1))
        clock = self._clock
        clock.lap("transfer")
        self._send_all("settle", [(exports.get(k, []), len(imports.get(k, []))) for k in range(1, len(self.sizes))])
        senders = [self._conns[k - 1] for k in exports if k]
        if senders:
            self.local.fit_spare_stops(lambda: self._answered(senders))
            clock.lap("fits")
        sent = {k: self._gather_one(k) for k in exports if k}
        clock.lap("wait")
        if 0 in exports:
            sent[0] = [pending.records[i] for i in exports[0]]
        for dst, items in imports.items():
            if dst:
                self._conns[dst - 1].send(("foreign", [sent[src][pos] for src, pos in items]))
        clock.lap("transfer")
        moved = set(exports.get(0, []))
        estimates: list = [None] * len(pending.records)
        for i, record in enumerate(pending.records):
            if i not in moved:
                estimates[i] = estimate_lambda66(record, self.local.score_method)
        back = {k: [None] * len(v) for k, v in exports.items()}
        for src, pos in imports.get(0, []):
            back[src][pos] = estimate_lambda66(sent[src][pos], self.local.score_method)
        clock.lap("identify")
        importers = [self._conns[k - 1] for k in imports if k]
        if importers:
            self.local.fit_spare_stops(lambda: self._answered(importers))
            clock.lap("fits")
        for dst, items in imports.items():
            if dst:
                for (src, pos), estimate in zip(items, self._gather_one(dst)):
                    back[src][pos] = estimate
        clock.lap("wait")
        for k, values in back.items():
            if k:
                self._conns[k - 1].send(("estimates", values))
        for i, estimate in zip(exports.get(0, []), back.get(0, [])):
            estimates[i] = estimate
        return estimates

    def _answered(self, conns: list | None = None) -> bool:
        """Whether the next answer of every worker (of ``conns``, or all) is waiting to be read."""
        return all(conn.poll() for conn in (self._conns if conns is None else conns))

    def _plan(self, loads: list[list[int]]) -> list[tuple[int, int, int]]:
        """The records to identify in another shard this step (:func:`balance_plan`)."""
        return balance_plan(loads)

    def _shard_of(self, env: int) -> int:
        return int(np.searchsorted(self.offsets, env, side="right") - 1)

    def record(self, env: int = 0, run_id: str = "run"):
        """Environment ``env``'s current (or just finished) episode as a run record (no tail)."""
        k = self._shard_of(env)
        if k == 0:
            return self.local.record(env, run_id)
        self._conns[k - 1].send(("record", (env - int(self.offsets[k]), run_id)))
        return self._gather_one(k)

    def _gather_one(self, k: int):
        """Worker shard ``k``'s (k >= 1) next answer; raises its error."""
        status, value = self._conns[k - 1].recv()
        if status == "error":
            raise RuntimeError(f"a shard of the vector env failed: {value[0]}: {value[1]}\n{value[2]}")
        return value

    def worker_cpu_s(self) -> float:
        """CPU time used so far by the worker processes together, s (``time.process_time`` in each;
        shard 0's is this process's own)."""
        return float(sum(self._all("cpu", [None] * len(self._conns))))

    @property
    def episodes_ended(self) -> int:
        """Episodes ended so far, summed over the shards."""
        return self.local.episodes_ended + int(sum(self._all("get", ["episodes_ended"] * len(self._conns))))

    @property
    def score_episodes(self) -> bool:
        """Whether ended episodes are identified and scored (set on every shard at once)."""
        return bool(self.local.score_episodes)

    @score_episodes.setter
    def score_episodes(self, value: bool) -> None:
        if hasattr(self, "local"):
            self.local.score_episodes = value
            self._all("set", [("score_episodes", value)] * len(self._conns))

    def close_extras(self, **kwargs: Any) -> None:
        """Close shard 0, tell every worker to stop and wait for it (10 s, then terminate); safe to call twice."""
        if self._closed:
            return
        self._closed = True
        if hasattr(self, "local"):
            self.local.close()
        for conn in self._conns:
            try:
                conn.send(("close", None))
            except (BrokenPipeError, OSError):
                pass
        for proc in self._procs:
            proc.join(timeout=10)
            if proc.is_alive():
                proc.terminate()
