"""Sweeps: local processes by default, Ray on request; results in order, errors with the item."""

from __future__ import annotations

import math
import os

import pytest

from addedinertia_env.apps.sweeps import SweepError, run_tasks


def square_and_pid(x: float) -> tuple[float, int]:
    return x * x, os.getpid()


def fail_on_three(x: int) -> int:
    if x == 3:
        raise ValueError("three is not allowed")
    return x


def short_simulation(seed: int) -> float:
    """A little physics per item: the batched rig's free swing, hull angle after 0.2 s."""
    from addedinertia_env.sim.batched import PASSIVE, BatchedRig
    from addedinertia_env.sim.params import RigParams

    rig = BatchedRig(RigParams(), n_envs=2, seed=seed)
    rig.reset(phi0=-0.05 * (1 + seed), brake=False)
    for _ in range(200):
        rig.physics_step(PASSIVE)
    return float(rig.phi[0])


def test_local_processes_keep_input_order():
    items = [3.0, 1.0, 2.0, 0.5, 4.0]
    out = run_tasks(square_and_pid, items, workers=2, progress=False)
    assert [v for v, _ in out] == [x * x for x in items]
    assert any(pid != os.getpid() for _, pid in out), "ran in worker processes"


def test_local_error_names_the_item():
    with pytest.raises(SweepError) as info:
        run_tasks(fail_on_three, [1, 2, 3, 4], workers=2, progress=False)
    assert info.value.item == 3 and info.value.index == 2
    assert "three is not allowed" in str(info.value)


def test_in_process_and_bad_arguments():
    assert run_tasks(square_and_pid, [2.0], workers=1, progress=False)[0] == (4.0, os.getpid())
    assert run_tasks(square_and_pid, [], progress=False) == []
    with pytest.raises(ValueError, match="executor"):
        run_tasks(square_and_pid, [1.0], executor="dask")
    with pytest.raises(ValueError, match="address"):
        run_tasks(square_and_pid, [1.0], address="auto")


def test_local_sweep_of_simulations_matches_a_serial_loop():
    parallel = run_tasks(short_simulation, [0, 1, 2], workers=2, progress=False)
    assert parallel == [short_simulation(s) for s in [0, 1, 2]]
    assert all(math.isfinite(v) for v in parallel)


@pytest.mark.slow
@pytest.mark.ray
def test_ray_sweep_on_a_local_instance():
    pytest.importorskip("ray")
    out = run_tasks(short_simulation, [0, 1, 2, 3], executor="ray", workers=2, progress=False)
    assert out == [short_simulation(s) for s in [0, 1, 2, 3]]
    with pytest.raises(SweepError) as info:
        run_tasks(fail_on_three, [1, 3], executor="ray", workers=2, progress=False)
    assert info.value.item == 3
