"""Run many independent tasks (benchmark episodes, training seeds, hyper-parameters).

:func:`run_tasks` maps a function over items on local processes (default:
:class:`concurrent.futures.ProcessPoolExecutor`) or on a Ray cluster
(``executor="ray"``, ``address`` of a running cluster, or a local Ray instance when no
address is given). Results come back in the order of the items; a failing item raises
:class:`SweepError` naming the item and the original error. ``fn`` and the items must be
picklable (a module-level function, plain data).
"""

from __future__ import annotations

import os
import sys
import traceback
from concurrent.futures import ProcessPoolExecutor, as_completed
from typing import Any, Callable, Iterable, Sequence

EXECUTORS = ("local", "ray")


class SweepError(RuntimeError):
    """One item of a sweep failed; ``item`` and ``index`` say which, ``cause`` what."""

    def __init__(self, index: int, item: Any, cause: str):
        super().__init__(f"sweep item {index} ({item!r}) failed: {cause}")
        self.index, self.item, self.cause = index, item, cause


def default_workers() -> int:
    """CPUs this process may use (``sched_getaffinity``), at least 1."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not Linux
        return max(1, os.cpu_count() or 1)


def _call(fn: Callable[[Any], Any], index: int, item: Any) -> tuple[int, bool, Any]:
    """Run one item; errors come back as text (a traceback pickles badly across processes)."""
    try:
        return index, True, fn(item)
    except Exception as e:  # noqa: BLE001 - reported with the item by the caller
        return index, False, f"{type(e).__name__}: {e}\n{traceback.format_exc(limit=5)}"


def _progress(total: int, enabled: bool):
    if not enabled:
        return None
    from tqdm import tqdm  # noqa: PLC0415

    return tqdm(total=total, file=sys.stderr, desc="sweep", leave=False)


def run_tasks(fn: Callable[[Any], Any], items: Iterable[Any], executor: str = "local", address: str | None = None,
              workers: int | None = None, progress: bool = True) -> list[Any]:
    """``[fn(item) for item in items]``, run in parallel; results in input order.

    ``executor``: ``"local"`` (processes on this machine; ``workers=1`` runs in this
    process, which is easiest to debug) or ``"ray"`` (``address``: ``"auto"``,
    ``"ray://host:10001"``...; none: start a local Ray instance with ``workers`` CPUs).
    """
    if executor not in EXECUTORS:
        raise ValueError(f"executor {executor!r}: expected one of {EXECUTORS}")
    if workers is not None and workers < 1:
        raise ValueError(f"workers = {workers!r}: expected an integer >= 1")
    items = list(items)
    if not items:
        return []
    if executor == "ray":
        return _run_ray(fn, items, address, workers, progress)
    if address is not None:
        raise ValueError("address is for executor='ray'; the local executor runs on this machine")
    workers = min(workers or default_workers(), len(items))
    results: list[Any] = [None] * len(items)
    bar = _progress(len(items), progress)
    try:
        if workers == 1:
            for k, item in enumerate(items):
                _store(results, items, _call(fn, k, item), bar)
            return results
        with ProcessPoolExecutor(max_workers=workers) as pool:
            futures = [pool.submit(_call, fn, k, item) for k, item in enumerate(items)]
            try:
                for fut in as_completed(futures):
                    _store(results, items, fut.result(), bar)
            except BaseException:
                for f in futures:
                    f.cancel()
                raise
        return results
    finally:
        if bar is not None:
            bar.close()


def _store(results: list, items: Sequence, outcome: tuple[int, bool, Any], bar) -> None:
    index, ok, value = outcome
    if not ok:
        raise SweepError(index, items[index], value.strip())
    results[index] = value
    if bar is not None:
        bar.update(1)


def _run_ray(fn, items: list, address: str | None, workers: int | None, progress: bool) -> list[Any]:
    try:
        import ray  # noqa: PLC0415
    except ImportError:
        raise ValueError("executor='ray' needs Ray: pip install 'addedinertia[ray]'") from None
    started = False
    if not ray.is_initialized():
        if address:
            ray.init(address=address, log_to_driver=False)
        else:
            # Workers see the driver's import path, so functions defined in scripts and test
            # modules (pickled by reference) import there too.
            ray.init(num_cpus=workers or default_workers(), include_dashboard=False, log_to_driver=False,
                     runtime_env={"env_vars": {"PYTHONPATH": os.pathsep.join(p for p in sys.path if p)}})
        started = True
    try:
        remote = ray.remote(_call)
        refs = [remote.remote(fn, k, item) for k, item in enumerate(items)]
        results: list[Any] = [None] * len(items)
        bar = _progress(len(items), progress)
        pending = list(refs)
        try:
            while pending:
                done, pending = ray.wait(pending, num_returns=1)
                for ref in done:
                    _store(results, items, ray.get(ref), bar)
        except BaseException:
            for ref in pending:
                ray.cancel(ref)
            raise
        finally:
            if bar is not None:
                bar.close()
        return results
    finally:
        if started:
            ray.shutdown()
