"""Rig parameters for a batch of environments: one array per parameter (struct of arrays).

:class:`BatchedParams` mirrors :class:`~addedinertia_env.sim.params.RigParams` field by
field (``p.hull.b1``, ``p.motor.k_t``, ``p.effects.fluid_memory.tau``...), except that
each number is a numpy array with one entry per environment. Because the attribute paths
are the same, the functions of :mod:`.forces` and :mod:`.motor` run unchanged on a batch
(numpy broadcasting): the batched rig and the MuJoCo rig share one source of truth.

Domain randomisation in a batch is simply a list of different :class:`RigParams`.

A physical parameter that is the same in every environment is stored as a scalar of the
batch's dtype (cheaper arithmetic); :attr:`BatchedParams.uniform` says whether all of the
physics (hull, spring, motor, effects) is shared, which lets the rig use one propagator
matrix for the whole batch. Sensor parameters are always arrays.

An effect that is on in some environments and off in others is stored with a *neutral*
value in the environments where it is off (each parameter's ``neutral`` in the effect
registry: a value for which the effect's force is exactly zero, such as no bearing torque,
``k3 = 0``, water memory with ``beta = 0``, ``k_t`` ratio 1). An effect off everywhere is
``None``, as in :class:`~addedinertia_env.sim.effects.Effects`, so it costs nothing.
"""

from __future__ import annotations

import dataclasses
from types import SimpleNamespace
from typing import Sequence

import numpy as np

from addedinertia_env.sim.effects import registry
from addedinertia_env.sim.params import RigParams

_GROUPS = ("hull", "spring", "motor", "sensors", "drive")
# Parameters that must be equal across a batch (they set the common clock).
_COMMON = ("sample_rate",)


def _shared_hydrodynamics(rigs: Sequence[RigParams]):
    """The batch's one hydrodynamic model (None: constant added inertia); a ValueError if rigs differ.

    The radiation-memory state has the model's order in every environment, so a batch shares
    the model (the hull's lambda66, which scales it, may differ per environment).
    """
    models = {r.hydrodynamics for r in rigs}
    if len(models) > 1:
        names = sorted("constant" if m is None else f"cummins ({m.source or 'unnamed'})" for m in models)
        raise ValueError(f"BatchedParams: the hydrodynamic model differs across the batch ({', '.join(names)}); "
                         "one batch shares one model (batch rigs of one hull together)")
    return next(iter(models))


def _numeric_fields(obj) -> list[str]:
    return [f.name for f in dataclasses.fields(obj) if isinstance(getattr(obj, f.name), (int, float))
            and not isinstance(getattr(obj, f.name), bool)]


class BatchedParams:
    """Per-environment parameter arrays, attribute-compatible with :class:`RigParams`.

    Build with :meth:`stack` (a list of rigs) or :meth:`repeat` (one rig, ``n`` times).
    ``dtype`` is the float type of the physical parameters (float64 by default); encoder
    counts stay integer.
    """

    def __init__(self, rigs: Sequence[RigParams], dtype=np.float64):
        rigs = list(rigs)
        if not rigs:
            raise ValueError("BatchedParams: expected at least one RigParams, got an empty list")
        for r in rigs:
            if not isinstance(r, RigParams):
                raise TypeError(f"BatchedParams: expected RigParams, got {type(r).__name__}")
        self.rigs = tuple(rigs)
        self.dtype = np.dtype(dtype)
        first = rigs[0]
        for name in ("physics_substeps",):
            values = {getattr(r, name) for r in rigs}
            if len(values) > 1:
                raise ValueError(f"BatchedParams: {name} differs across the batch ({sorted(values)}); "
                                 "all environments of one batch share the clock")
        values = {r.sensors.sample_rate for r in rigs}
        if len(values) > 1:
            raise ValueError(f"BatchedParams: sensors.sample_rate differs across the batch ({sorted(values)}); "
                             "all environments of one batch share the clock")
        self.n = len(rigs)
        self.physics_substeps = int(first.physics_substeps)
        self.sample_rate = float(first.sensors.sample_rate)
        self.uniform = True
        for group in _GROUPS:
            ns = SimpleNamespace()
            proto = getattr(first, group)
            for name in _numeric_fields(proto):
                column = [getattr(getattr(r, group), name) for r in rigs]
                if name in ("phi_counts", "psi_counts"):
                    setattr(ns, name, np.asarray(column, dtype=np.int64))
                elif name in _COMMON:
                    setattr(ns, name, float(column[0]))
                else:
                    setattr(ns, name, self._column(column, shared_ok=group != "sensors"))
            setattr(self, group, ns)
        self.brake_torque = np.asarray([r.brake_torque for r in rigs], dtype=self.dtype)
        self.effects = SimpleNamespace()
        for spec in registry.specs():
            present = [getattr(r.effects, spec.name) for r in rigs]
            if all(e is None for e in present):
                setattr(self.effects, spec.name, None)
                continue
            ns = SimpleNamespace(**{k: self._column([v if e is None else getattr(e, k) for e in present])
                                    for k, v in spec.neutral_values().items()})
            setattr(self.effects, spec.name, ns)
        self.effects._hooked = registry.hook_table(self.effects)  # read every physics step
        self.hydrodynamics = _shared_hydrodynamics(rigs)

    def _column(self, values: list, shared_ok: bool = True):
        """A dtype scalar if all values are equal (and sharing is allowed), else an array."""
        if shared_ok and all(v == values[0] for v in values):
            return self.dtype.type(values[0])
        if shared_ok:
            self.uniform = False
        return np.asarray(values, dtype=self.dtype)

    def per_env(self, value) -> np.ndarray:
        """``value`` (a scalar or per-environment array) as an array of length ``n``."""
        return np.broadcast_to(np.asarray(value, dtype=self.dtype), (self.n,)).copy()

    @classmethod
    def stack(cls, rigs: Sequence[RigParams], dtype=np.float64) -> "BatchedParams":
        """The parameters of ``rigs``, one environment each, as arrays (SI units)."""
        return cls(rigs, dtype=dtype)

    @classmethod
    def repeat(cls, rig: RigParams, n: int, dtype=np.float64) -> "BatchedParams":
        """``n`` environments with the parameters of ``rig``; ValueError for ``n`` < 1."""
        if n < 1:
            raise ValueError(f"BatchedParams.repeat: n = {n}; expected at least 1 environment")
        return cls([rig] * n, dtype=dtype)

    def set_envs(self, envs: np.ndarray, rigs: Sequence[RigParams]) -> None:
        """Environments ``envs`` take the parameters ``rigs`` (every column becomes per-environment)."""
        envs = np.asarray(envs, dtype=np.int64)
        rigs = list(rigs)
        if len(rigs) != len(envs):
            raise ValueError(f"BatchedParams.set_envs: {len(rigs)} rigs for {len(envs)} environments")
        for r in rigs:
            if r.physics_substeps != self.physics_substeps or float(r.sensors.sample_rate) != self.sample_rate:
                raise ValueError("BatchedParams.set_envs: a rig with another clock (sample rate or physics "
                                 "substeps) than the batch's")
        all_rigs = list(self.rigs)
        for k, r in zip(envs, rigs):
            all_rigs[int(k)] = r
        if _shared_hydrodynamics(all_rigs) != self.hydrodynamics:  # the memory state's size is the batch's
            raise ValueError("BatchedParams.set_envs: new rigs with another hydrodynamic model than the batch's")
        self.rigs = tuple(all_rigs)
        self.uniform = False
        for group in _GROUPS:
            ns = getattr(self, group)
            for name in _numeric_fields(getattr(rigs[0], group)):
                if name in _COMMON:
                    continue
                column = getattr(ns, name)
                if np.ndim(column) == 0:
                    column = np.full(self.n, column, dtype=np.asarray(column).dtype)
                    setattr(ns, name, column)
                column[envs] = [getattr(getattr(r, group), name) for r in rigs]
        self.brake_torque[envs] = [r.brake_torque for r in rigs]
        for spec in registry.specs():
            present = [getattr(r.effects, spec.name) for r in rigs]
            ns = getattr(self.effects, spec.name, None)
            neutral_values = spec.neutral_values()
            if ns is None:
                if all(e is None for e in present):
                    continue
                ns = SimpleNamespace(**{k: np.full(self.n, v, dtype=self.dtype) for k, v in neutral_values.items()})
                setattr(self.effects, spec.name, ns)
            for key, neutral in neutral_values.items():
                column = getattr(ns, key)
                if np.ndim(column) == 0:
                    column = np.full(self.n, column, dtype=self.dtype)
                    setattr(ns, key, column)
                column[envs] = [neutral if e is None else getattr(e, key) for e in present]
        self.effects._hooked = registry.hook_table(self.effects)  # read every physics step

    # Derived quantities with the same names as RigParams ---------------------------------
    @property
    def physics_dt(self) -> float:
        """Physics step, s (common to the batch)."""
        return 1.0 / self.sample_rate / self.physics_substeps

    @property
    def sample_dt(self) -> float:
        """Sample period, s."""
        return 1.0 / self.sample_rate

    def nbytes(self) -> int:
        """Bytes held by the per-environment parameter arrays."""
        total = self.brake_torque.nbytes
        for group in _GROUPS:
            total += sum(np.asarray(v).nbytes for v in vars(getattr(self, group)).values())
        for spec in registry.specs():
            ns = getattr(self.effects, spec.name, None)
            if ns is not None:
                total += sum(np.asarray(v).nbytes for v in vars(ns).values())
        return total
