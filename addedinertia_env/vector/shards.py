"""The batched task over several processes: ``num_envs`` split into shards, one per CPU core.

``gym.make_vec("AddedInertia/ReverseStroke-v0", num_envs=N, workers=W)`` with ``W`` > 1
gives :class:`ShardedVectorEnv`: ``W`` worker processes, each running a
:class:`~addedinertia_env.vector.env.ReverseStrokeVectorEnv` of about ``N / W``
environments, stepped at the same time (the actions go out to every shard, then every
shard's results come back and are joined in environment order). Each shard is the
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

Use it when the machine has idle cores: on one busy core it only adds the transfers.
"""

from __future__ import annotations

import multiprocessing as mp
import time
import traceback
from typing import Any

import numpy as np
from gymnasium.vector import VectorEnv

from .env import ReverseStrokeVectorEnv, estimate_lambda66

MOVE_MARGIN = 0.15  # a record moves only if the busiest shard's load drops by more than this fraction of it (the transfer's cost)


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


def _expect(conn, kind: str):
    command, args = conn.recv()
    if command != kind:
        raise RuntimeError(f"shard protocol: expected {kind!r} from the parent, got {command!r}")
    return args


def _settle(conn, env: ReverseStrokeVectorEnv, pending, export: list[int], n_import: int):
    """The second half of a sharded step in a worker (module docstring): send the ``export``
    records, identify the rest, identify ``n_import`` records of other shards and send their
    estimates back, take the estimates of the exported records, finish the step."""
    records = pending.records
    if export:
        conn.send(("ok", [records[i] for i in export]))
    moved = set(export)
    estimates: list = [None] * len(records)
    for i, record in enumerate(records):
        if i not in moved:
            estimates[i] = estimate_lambda66(record)
    if n_import:
        foreign = _expect(conn, "foreign")
        conn.send(("ok", [estimate_lambda66(r) for r in foreign]))
    if export:
        for i, estimate in zip(export, _expect(conn, "estimates")):
            estimates[i] = estimate
    return env.finish(pending, estimates)


def _worker(conn, num_envs: int, kwargs: dict) -> None:
    env = None
    pending = None
    try:
        env = ReverseStrokeVectorEnv(num_envs, **kwargs)
        conn.send(("ok", None))
        while True:
            command, args = conn.recv()
            if command == "close":
                break
            if command == "advance":  # first half of a step: the ended episodes' record lengths
                pending = env.advance(args)
                out = [len(r) for r in pending.records]
            elif command == "settle":
                out, pending = _settle(conn, env, pending, *args), None
            elif command == "step":
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
    """``num_envs`` reverse-stroke environments in ``workers`` processes (module docstring);
    the other keyword arguments are those of :class:`~addedinertia_env.vector.env.ReverseStrokeVectorEnv`."""

    def __init__(self, num_envs: int, workers: int = 2, **kwargs: Any):
        if not (isinstance(workers, int) and 2 <= workers <= num_envs):
            raise ValueError(f"ShardedVectorEnv option workers={workers!r}: expected an integer in 2..num_envs "
                             f"({num_envs})")
        base, extra = divmod(num_envs, workers)
        self.sizes = [base + (k < extra) for k in range(workers)]
        self.offsets = np.concatenate([[0], np.cumsum(self.sizes)])
        self.num_envs = num_envs
        ctx = mp.get_context()
        self._conns, self._procs = [], []
        for n in self.sizes:
            parent, child = ctx.Pipe()
            proc = ctx.Process(target=_worker, args=(child, n, kwargs), daemon=True)
            proc.start()
            child.close()
            self._conns.append(parent)
            self._procs.append(proc)
        self._closed = False
        self._gather()
        (self.single_observation_space, self.single_action_space, self.observation_space, self.action_space,
         self.metadata) = ReverseStrokeVectorEnv.spaces(num_envs, **kwargs)

    def _gather(self) -> list:
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

    def _all(self, command: str, args_per_shard: list) -> list:
        for conn, args in zip(self._conns, args_per_shard):
            conn.send((command, args))
        return self._gather()

    def reset(self, *, seed: int | list | None = None, options: dict | None = None):
        """Reset every shard (``seed`` an int: the shard holding environments ``a..b`` gets ``seed + a``; or a list, one per environment); returns the joined ``(obs, info)``."""
        if seed is None or isinstance(seed, (int, np.integer)):
            seeds = [None if seed is None else int(seed) + int(a) for a in self.offsets[:-1]]
        else:
            seeds = [list(seed)[a:b] for a, b in zip(self.offsets[:-1], self.offsets[1:])]
        out = self._all("reset", [{"seed": s, "options": options} for s in seeds])
        return np.concatenate([o for o, _ in out]), _join([i for _, i in out], self.sizes)

    def step(self, actions):
        """Step every shard with its rows of ``actions`` at the same time; returns ``(obs, rewards, terminated, truncated, info)`` joined in environment order."""
        a = np.asarray(actions).reshape(self.num_envs, -1)
        loads = self._all("advance", [a[lo:hi] for lo, hi in zip(self.offsets[:-1], self.offsets[1:])])
        moves = self._plan(loads)
        exports: dict[int, list[int]] = {}
        imports: dict[int, list[tuple[int, int]]] = {}  # importer -> (exporter, position in its export list)
        for src, i, dst in moves:
            exports.setdefault(src, []).append(i)
            imports.setdefault(dst, []).append((src, len(exports[src]) - 1))
        for k, conn in enumerate(self._conns):
            conn.send(("settle", (exports.get(k, []), len(imports.get(k, [])))))
        sent = {k: self._gather_one(k) for k in exports}
        for dst, items in imports.items():
            self._conns[dst].send(("foreign", [sent[src][pos] for src, pos in items]))
        back = {k: [None] * len(v) for k, v in exports.items()}
        for dst, items in imports.items():
            for (src, pos), estimate in zip(items, self._gather_one(dst)):
                back[src][pos] = estimate
        for k, estimates in back.items():
            self._conns[k].send(("estimates", estimates))
        out = self._gather()
        obs, rew, term, trunc, infos = zip(*out)
        return (np.concatenate(obs), np.concatenate(rew), np.concatenate(term), np.concatenate(trunc),
                _join(list(infos), self.sizes))

    def _plan(self, loads: list[list[int]]) -> list[tuple[int, int, int]]:
        """The records to identify in another shard this step (:func:`balance_plan`)."""
        return balance_plan(loads)

    def record(self, env: int = 0, run_id: str = "run"):
        """Environment ``env``'s current (or just finished) episode as a run record (no tail)."""
        k = int(np.searchsorted(self.offsets, env, side="right") - 1)
        self._conns[k].send(("record", (env - int(self.offsets[k]), run_id)))
        return self._gather_one(k)

    def _gather_one(self, k: int):
        status, value = self._conns[k].recv()
        if status == "error":
            raise RuntimeError(f"a shard of the vector env failed: {value[0]}: {value[1]}\n{value[2]}")
        return value

    def worker_cpu_s(self) -> float:
        """CPU time used so far by the worker processes together, s (``time.process_time`` in each)."""
        return float(sum(self._all("cpu", [None] * len(self._conns))))

    @property
    def episodes_ended(self) -> int:
        """Episodes ended so far, summed over the shards."""
        return int(sum(self._all("get", ["episodes_ended"] * len(self._conns))))

    @property
    def score_episodes(self) -> bool:
        """Whether ended episodes are identified and scored (set on every shard at once)."""
        return bool(self._all("get", ["score_episodes"] * len(self._conns))[0])

    @score_episodes.setter
    def score_episodes(self, value: bool) -> None:
        if hasattr(self, "_conns"):
            self._all("set", [("score_episodes", value)] * len(self._conns))

    def close_extras(self, **kwargs: Any) -> None:
        """Tell every worker to stop and wait for it (10 s, then terminate); safe to call twice."""
        if self._closed:
            return
        self._closed = True
        for conn in self._conns:
            try:
                conn.send(("close", None))
            except (BrokenPipeError, OSError):
                pass
        for proc in self._procs:
            proc.join(timeout=10)
            if proc.is_alive():
                proc.terminate()
