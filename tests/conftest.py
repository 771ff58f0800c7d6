"""Shared fixtures: simulated run records, made once per test session.

One simulated reverse-symmetric experiment costs about 1.5 s of CPU, so the records
that several test files read are built here, session-scoped, and shared:

* ``oracle_record(name)``: noise-free sensors, the ideal tracking controller
  (:class:`~addedinertia_env.experiment.oracle.OracleController`), preset ``name``;
* ``realistic_record``: the wigley-2m preset as it stands (realistic sensors, physics.md
  section 7) with the default controller ``feedforward-pd``;
* ``realistic_record_path``: that record written to a session folder (CSV + JSON);
* ``unpack_shared(name)``: a developers' archive (``shared/data/<name>``, e.g. the
  foreign-lab sets) unpacked into a fresh temporary folder; the test skips when it is absent.

Tests that change a record must copy it first (the ``clone`` fixture is
:func:`copy_record`).
"""

from __future__ import annotations

import copy
import tarfile
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

from addedinertia_env.experiment.oracle import OracleController
from addedinertia_env.experiment.runner import run_experiment
from addedinertia_env.records.record import RunRecord, write_record
from addedinertia_env.sim.batched import BatchedRig
from addedinertia_env.sim.motor import MODES, MotorCommand
from addedinertia_env.sim.mujoco_rig import MujocoRig
from addedinertia_env.sim.params import RigParams, SensorParams
from addedinertia_env.sim.presets import load_preset, rig_from_mapping
from addedinertia_env.experiment.protocol import plan_from_preset
from addedinertia_env.apps.simulate import simulate_run
from addedinertia_env.vector.env import ReverseStrokeVectorEnv

REALISTIC_SEED = 1
ENV_ID = "AddedInertia/ReverseStroke-v0"
_REPO = Path(__file__).resolve().parents[1]


def copy_record(record: RunRecord) -> RunRecord:
    """A deep copy, so that a test may change samples or metadata freely."""
    return RunRecord(samples={k: v.copy() for k, v in record.samples.items()}, meta=copy.deepcopy(record.meta),
                     path=record.path, gaps=list(record.gaps))


def preset_rig(name: str, ideal_sensors: bool = False) -> tuple[RigParams, object]:
    """The preset's rig (optionally with ideal sensors) and its experiment plan."""
    data = load_preset(name)
    rig = rig_from_mapping(data, sensors=SensorParams.ideal() if ideal_sensors else None)
    return rig, plan_from_preset(data)


@pytest.fixture(scope="session")
def clone():
    """:func:`copy_record`, for tests that change a shared record."""
    return copy_record


@pytest.fixture(scope="session")
def oracle_record():
    """``oracle_record(name)``: ideal sensors + ideal tracking on preset ``name`` (cached)."""
    cache: dict[str, tuple[RunRecord, RigParams]] = {}

    def make(name: str) -> tuple[RunRecord, RigParams]:
        if name not in cache:
            params, plan = preset_rig(name, ideal_sensors=True)
            rig = MujocoRig(params, seed=0)
            cache[name] = (run_experiment(rig, OracleController(rig), plan, run_id=f"oracle-{name}"), params)
        return cache[name]

    return make


@pytest.fixture(scope="session")
def realistic_record() -> tuple[RunRecord, RigParams]:
    """wigley-2m with realistic sensors and the default controller, seed 1, held 2 s at the reversal
    (the long hold of the first protocol: room for a gap in the hold, a gentle pre-spin)."""
    import dataclasses  # noqa: PLC0415

    params, plan = preset_rig("wigley-2m")
    plan = dataclasses.replace(plan, hold_s=2.0)
    return simulate_run(params, "feedforward-pd", plan, seed=REALISTIC_SEED, run_id="realistic"), params


@pytest.fixture(scope="session")
def realistic_record_path(realistic_record, tmp_path_factory) -> Path:
    """The realistic record written as ``run-0000.csv`` + ``.json`` (read-only by convention)."""
    record, _ = realistic_record
    return write_record(copy_record(record), tmp_path_factory.mktemp("realistic") / "run-0000.csv")


def both_engines(params: RigParams, command, n: int = 600, omega0: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """(MuJoCo, batched) histories of [phi, w, psi, omega, i, read u, read i] over ``n`` steps of
    ``command(k) -> MotorCommand``, same seed (4) and start (phi0 = -0.08 rad, ``omega0``, brake off)."""
    mj, batch = MujocoRig(params, seed=4), BatchedRig([params], seed=[4])
    mj.reset(phi0=-0.08, omega0=omega0, brake=False)
    batch.reset(phi0=-0.08, omega0=omega0, brake=False)
    a, b = [], []
    for k in range(n):
        cmd: MotorCommand = command(k)
        ra = mj.step(cmd)
        rb = batch.step([MODES.index(cmd.mode)], [cmd.value])
        s = mj.true_state()
        a.append([s.phi, s.w, s.psi, s.omega, s.i, ra.u, ra.i])
        b.append([batch.phi[0], batch.w[0], batch.psi[0], batch.omega[0], batch.i[0], rb.u[0], rb.i[0]])
    return np.array(a), np.array(b, dtype=float)


def single_and_vector_episode(seed: int = 8, **env_kwargs) -> tuple[dict, dict]:
    """One episode at a constant action 0.05 in the default single env (MuJoCo) and in the batched
    env of one, both made with ``env_kwargs`` and reset with ``seed``: their last step's infos
    ``(vector info, single info)``; asserts both episodes ended within 400 steps."""
    venv = ReverseStrokeVectorEnv(1, **env_kwargs)
    venv.reset(seed=seed)
    env = gym.make(ENV_ID, **env_kwargs)
    env.reset(seed=seed)
    a = np.full((1, 1), 0.05, np.float32)
    try:
        for _ in range(400):
            _, _, term, _, info = venv.step(a)
            if term[0]:
                break
        for _ in range(400):
            _, _, st, _, sinfo = env.step(a[0])
            if st:
                break
        assert term[0] and st
        return info, sinfo
    finally:
        env.close()
        venv.close()


def shared_archive(name: str) -> Path | None:
    """``shared/data/<name>``: ../shared beside the repository (as in run-record.md's links),
    beside a worktree's parent, or /work/shared; None when none of them holds it."""
    paths = (base / "shared" / "data" / name for base in (_REPO.parent, _REPO.parent.parent, Path("/work")))
    return next((p for p in paths if p.exists()), None)


@pytest.fixture(scope="session")
def unpack_shared(tmp_path_factory):
    """``unpack_shared(name)``: the shared archive ``name`` unpacked into a fresh temporary
    folder, returned as the folder that holds its ``answers.json``; skips when it is absent."""

    def unpack(name: str) -> Path:
        archive = shared_archive(name)
        if archive is None:
            pytest.skip(f"shared {name} data not present")
        out = tmp_path_factory.mktemp(name.split(".")[0])
        with tarfile.open(archive) as tar:
            tar.extractall(out, filter="data")
        return next(p.parent for p in out.rglob("answers.json"))

    return unpack
