"""Radiation memory of the hull (Cummins 1962) as the simulator integrates it: an optional
hydrodynamic model of a rig, not a hidden effect.

With the default (``constant``) model the water's inertia is one number, ``lambda66``, the
hull joint's armature. With the ``cummins`` model the radiation moment is

    -A66(inf) phi'' - mu(t),   mu = integral_0^t K(t - s) phi'(s) ds

realised by the passive state-space fit stored in the hull's BEM cache
(:mod:`addedinertia_env.hydro.memory_fit`): ``x' = A x + b w``, ``mu = lambda66 (c . x + d w)``
(``w = phi'`` rad/s, ``x`` rad, ``mu`` N m). The armature becomes ``A66(inf)``.

How the preset's lambda66 enters: the cached model is *normalised* to ``A66(0) = 1``; the
simulator multiplies ``c`` and ``A66(inf)`` by the hull's lambda66, so **lambda66 is the
zero-frequency (rigid-lid) added inertia A66(0)**, which is what the presets state
(``added_inertia.source``: panel-method A66(0)), and the BEM's frequency *shape*
``A66(omega)/A66(0)`` (computed for this hull) is kept. A scenario that draws another
lambda66 scales the whole curve with it.

What lambda66 means with memory on (the truth for scoring, :func:`truth_block`,
``docs/RUN_RECORD.md``): **lambda66 is A66(0)**, the value manoeuvring models use,
in every truth block the simulator writes. Beside it the truth gives ``A66_swing``, A66 at the
natural swing frequency ``w_n`` (the root of ``c = w^2 (J_h + A66(w))``, a free flywheel:
physics.md s3; what a free decay measures, 1.7-2.0 % above A66(0) on the shipped hulls), and
``A66_inf``, the infinite-frequency limit, kg m^2; the ``hydrodynamics`` block repeats them with
``w_n`` and the model. Memory-free water: ``lambda66`` is the hull's one added inertia.
"""

from __future__ import annotations

import functools
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

MODELS = ("constant", "cummins")
SOURCES = ("bem-cache",)
MEMORY_FORMAT = "addedinertia-memory-model/1"


class HydrodynamicsError(ValueError):
    """A hydrodynamic model that cannot be built (bad config, missing or stale cache)."""


@dataclass(frozen=True)
class CumminsModel:
    """Normalised radiation memory (A66(0) = 1 kg m^2); hashable, so engines cache its step maps.

    ``A`` 1/s, ``b`` -, ``c`` 1/s^2 (per kg m^2 of A66(0)), ``P`` the storage matrix (same
    units as ``c``); ``a_inf_ratio`` = A66(inf)/A66(0); ``source`` the cache file.
    """

    A: tuple[tuple[float, ...], ...]
    b: tuple[float, ...]
    c: tuple[float, ...]
    P: tuple[tuple[float, ...], ...]
    a_inf_ratio: float
    order: int
    fit_error: float
    source: str = ""
    d: float = 0.0  # 1/s per kg m^2 of A66(0): feedthrough (strict passivity; ~1e-7)

    @classmethod
    def from_block(cls, block: dict[str, Any], source: str = "") -> "CumminsModel":
        """From a BEM cache's ``memory_model`` block (:func:`addedinertia_env.hydro.memory_fit.fit_memory_model`)."""
        if block.get("format") != MEMORY_FORMAT:
            raise HydrodynamicsError(f"{source}: memory_model.format = {block.get('format')!r}; expected "
                                     f"{MEMORY_FORMAT!r} (refit with 'addedinertia hull PRESET --fit-memory')")
        try:
            A = np.asarray(block["A"], dtype=float)
            b, c = np.asarray(block["b"], dtype=float), np.asarray(block["c"], dtype=float)
            P = np.asarray(block["P"], dtype=float)
            ratio = float(block["a_inf_ratio"])
            d = float(block.get("d", 0.0))
        except (KeyError, TypeError, ValueError) as e:
            raise HydrodynamicsError(f"{source}: memory_model: {e!r}; expected A, b, c, P and a_inf_ratio") from None
        n = len(b)
        if A.shape != (n, n) or c.shape != (n,) or P.shape != (n, n) or n < 1:
            raise HydrodynamicsError(f"{source}: memory_model: shapes A {A.shape}, b {b.shape}, c {c.shape}, "
                                     f"P {P.shape}; expected n x n, n, n, n x n")
        if not np.all(np.isfinite(A)) or np.max(np.linalg.eigvals(A).real) >= 0:
            raise HydrodynamicsError(f"{source}: memory_model.A is not stable (poles must have Re < 0)")
        if not (math.isfinite(d) and d >= 0.0):
            raise HydrodynamicsError(f"{source}: memory_model.d = {d!r}; expected a finite feedthrough >= 0 (1/s)")
        if not 0.0 < ratio < 1.0:
            raise HydrodynamicsError(f"{source}: memory_model.a_inf_ratio = {ratio!r}; expected 0 < A66(inf)/A66(0) < 1")
        return cls(A=tuple(map(tuple, A.tolist())), b=tuple(b.tolist()), c=tuple(c.tolist()),
                   P=tuple(map(tuple, P.tolist())), a_inf_ratio=ratio, order=n, d=d,
                   fit_error=float(block.get("fit_error", math.nan)), source=source)

    # --- frequency domain -------------------------------------------------------------
    def transfer(self, omega) -> np.ndarray:
        """Kh(j omega) per kg m^2 of A66(0) (N m s): Re = B66/A66(0), Im/omega = (A66 - A66(inf))/A66(0)."""
        A, b, c = (np.asarray(v) for v in (self.A, self.b, self.c))
        n = self.order
        return np.array([c @ np.linalg.solve(1j * w * np.eye(n) - A, b) + self.d for w in np.atleast_1d(omega)])

    def added_inertia_ratio(self, omega) -> np.ndarray:
        """A66(omega)/A66(0) of the model (omega > 0, rad/s)."""
        omega = np.atleast_1d(np.asarray(omega, dtype=float))
        return self.a_inf_ratio + self.transfer(omega).imag / omega

    def natural_frequency(self, J_hull: float, lambda66: float, c_spring: float) -> float:
        """The undamped swing frequency, rad/s: the root of ``c = w^2 (J_h + lambda66 A66(w)/A66(0))``."""
        w = math.sqrt(c_spring / (J_hull + lambda66))
        for _ in range(50):
            new = math.sqrt(c_spring / (J_hull + lambda66 * float(self.added_inertia_ratio(w)[0])))
            if abs(new - w) < 1e-13 * w:
                break
            w = new
        return new


@functools.lru_cache(maxsize=32)
def step_maps(model: CumminsModel, h: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """Exact maps of ``x' = A x + b w`` over a step ``h`` (s) with ``w`` held:
    ``x(h) = Phi x + Gam w``, and the step's mean of ``c . x``, ``cbar . x + dbar w``
    (per kg m^2 of A66(0)). Returns ``(Phi, Gam, cbar, dbar)``."""
    from scipy.linalg import expm  # noqa: PLC0415

    A, b = np.asarray(model.A), np.asarray(model.b)
    n = model.order
    # [[A, b, 0], [0, 0, 1], [0, 0, 0]] h: its exponential holds Phi, Gam and the integrals.
    M = np.zeros((n + 2, n + 2))
    M[:n, :n], M[:n, n], M[n, n + 1] = A, b, 1.0
    E = expm(M * h)
    Phi, Gam = E[:n, :n], E[:n, n]
    Ainv = np.linalg.inv(A)
    Phibar = Ainv @ (Phi - np.eye(n)) / h
    Gambar = Ainv @ (Phibar - np.eye(n)) @ b
    c = np.asarray(model.c)
    return Phi, Gam, c @ Phibar, float(c @ Gambar) + model.d


def model_from_cache(path: str | Path) -> CumminsModel:
    """The memory model stored in a BEM cache file; a HydrodynamicsError naming what is missing."""
    path = Path(path)
    preset = path.name.removesuffix(".bem.json")
    if not path.exists():
        raise HydrodynamicsError(f"{path}: no BEM cache for the cummins model; expected one written by "
                                 f"'addedinertia hull {preset} --solve --write-cache' (needs the [hull] extra)")
    try:
        data = json.loads(path.read_text())
    except json.JSONDecodeError as e:
        raise HydrodynamicsError(f"{path}: not valid JSON ({e}); expected a BEM cache") from None
    block = data.get("memory_model")
    if not isinstance(block, dict):
        raise HydrodynamicsError(f"{path}: no 'memory_model' block (the state-space fit of the radiation memory); "
                                 f"expected one written by 'addedinertia hull {preset} --fit-memory' (no BEM solve)")
    return CumminsModel.from_block(block, source=_display(path))


def _display(path: Path) -> str:
    """``path`` relative to the project root when inside it (records carry no machine paths)."""
    root = Path(__file__).resolve().parents[2]
    try:
        return str(path.resolve().relative_to(root))
    except ValueError:
        return str(path)


def truth_block(J_hull: float, lambda66: float, c_spring: float, model: CumminsModel) -> dict[str, Any]:
    """The record's truth about the water with memory on: ``lambda66`` = A66(0) (the spec's
    definition), ``A66_swing`` (A66 at the natural swing frequency) and ``A66_inf``, kg m^2, and
    the ``hydrodynamics`` block (the model, A66(0), A66(w_n), A66(inf), ``swing_omega`` rad/s)."""
    w = model.natural_frequency(J_hull, lambda66, c_spring)
    a_swing = lambda66 * float(model.added_inertia_ratio(w)[0])
    a_inf = lambda66 * model.a_inf_ratio
    return {"lambda66": float(lambda66), "A66_swing": a_swing, "A66_inf": a_inf,
            "hydrodynamics": {"model": "cummins", "source": model.source, "order": model.order,
                              "fit_error": model.fit_error, "A66_zero": float(lambda66), "A66_swing": a_swing,
                              "A66_inf": a_inf, "swing_omega": w,
                              "lambda66_is": "A66(0), the zero-frequency added inertia (spec/run-record.md)"}}
