"""A DAQ-quirk layer for simulated records: what another lab's data acquisition does to a run.

The simulator logs every sample on a perfect 1 kHz clock, the current at its instant,
and the full rig block. Real DAQs differ in every way the spec allows
(``docs/RUN_RECORD.md``); this layer turns a simulated record into one with
those habits, so that tests and hidden-effect checks draw quirks as well as effects:

==================  ==================================================================
quirk               what it does (SI units)
==================  ==================================================================
``drop``            removes samples at random (fraction), and the release sample itself
``jitter``          takes each sample at ``t + N(0, sigma)`` (s): angles re-read there
``decimate``        keeps every ``k``-th sample (1 kHz -> 250 Hz for ``k = 4``); the
                    current as an instantaneous sample (``instant``) or its mean over
                    the interval before the sample (``held-previous``)
``held_current``    logs the current as its mean over the previous interval
``braked_tail``     sets the brake for the last ``s`` seconds: the hull is held there
``L_unknown``       removes ``rig.L`` (or, with ``L_unknown=0``, logs it as 0)
``release_moving``  logs the release sample itself as moving (brake 0, the stroke's
                    phase), the other DAQ convention for when the brake let go
``shuffle_columns`` writes the columns in another order, with an extra DAQ channel
==================  ==================================================================

Whether the rig block states how the current was logged is a choice
(``declare_current``): a lab may not say. Nothing here reads ``truth``; the truth
block is carried over unchanged for scoring.
"""

from __future__ import annotations

import copy
from dataclasses import asdict, dataclass

import numpy as np

from addedinertia_env.records.record import RunRecord


@dataclass(frozen=True)
class Quirks:
    """One DAQ's habits; every field off by default (a perfect DAQ)."""

    drop: float = 0.0  # fraction of samples removed at random (s^0)
    drop_release: bool = False  # remove the release sample of every stroke
    jitter: float = 0.0  # s, standard deviation of the sampling instants
    decimate: int = 1  # keep every k-th sample
    decimate_current: str = "instant"  # "instant" or "held-previous" (mean over the interval)
    held_current: bool = False  # current logged as its mean over the previous interval
    declare_current: bool = False  # write rig.current_sampling for the current's convention
    braked_tail: float = 0.0  # s, brake set for the last seconds of the record
    L_unknown: str = ""  # "" keep rig.L, "absent" remove it, "zero" log it as 0
    shuffle_columns: bool = False
    release_moving: bool = False  # the release sample logged as moving, not as braked

    def to_dict(self) -> dict:
        """The quirks that differ from a perfect DAQ, as ``{field: value}`` (units as the fields')."""
        return {k: v for k, v in asdict(self).items() if v != getattr(Quirks(), k)}


QUIRK_NAMES = ("drop", "jitter", "decimate", "held_current", "braked_tail", "L_unknown", "shuffle_columns",
               "release_moving")


def draw_quirks(rng: np.random.Generator, n: int = 2) -> Quirks:
    """``n`` quirks drawn at random with plausible sizes (for hidden-effect tests)."""
    chosen = rng.choice(QUIRK_NAMES, size=n, replace=False)
    kw: dict = {}
    for q in chosen:
        if q == "drop":
            kw.update(drop=float(rng.uniform(0.0005, 0.003)), drop_release=True)
        elif q == "jitter":
            kw.update(jitter=float(rng.uniform(0.01, 0.05)) * 1e-3)
        elif q == "decimate":
            # A DAQ logging slower than the controller runs averages (anti-aliases) its current
            # channel: an instantaneous 250 Hz sample of a 1 kHz controller's chattering current
            # loses the input outright (tests/test_daq_quirks.py shows the interval widening).
            kw.update(decimate=int(rng.choice([2, 4])), decimate_current="held-previous")
        elif q == "held_current":
            kw.update(held_current=True, declare_current=bool(rng.integers(2)))
        elif q == "braked_tail":
            kw.update(braked_tail=float(rng.uniform(0.2, 1.0)))
        elif q == "L_unknown":
            kw.update(L_unknown=str(rng.choice(["absent", "zero"])))
        elif q == "shuffle_columns":
            kw.update(shuffle_columns=True)
        elif q == "release_moving":
            kw.update(release_moving=True)
    return Quirks(**kw)


def apply_quirks(record: RunRecord, quirks: Quirks, rng: np.random.Generator) -> RunRecord:
    """A copy of ``record`` as a DAQ with ``quirks`` would have logged it."""
    s = {k: np.asarray(v).copy() for k, v in record.samples.items()}
    meta = copy.deepcopy(record.meta)
    rig = meta["rig"]  # the copy's block, rewritten below as the DAQ would have stated it
    known = record.known
    rate = known.sample_rate
    counts = {"phi": known.phi_counts, "psi": known.psi_counts}  # 0: not quantised
    if quirks.braked_tail > 0:
        _brake_tail(s, quirks.braked_tail, counts)
    if quirks.release_moving:
        _release_logged_moving(s)
    if quirks.held_current:
        s["i"] = _held(s["i"])
    if quirks.jitter > 0:
        _jitter(s, quirks.jitter, rng, counts)
    if quirks.decimate > 1:
        k = quirks.decimate
        if quirks.decimate_current == "held-previous":
            s["i"] = _block_mean(s["i"], k)
        keep = np.arange(0, len(s["t"]), k)
        s = {c: v[keep] for c, v in s.items()}
        rate /= k
        rig["sample_rate"] = rate
    if quirks.drop > 0 or quirks.drop_release:
        n = len(s["t"])
        keep = rng.random(n) >= quirks.drop
        if quirks.drop_release:
            ph = s["phase"]
            moving = np.isin(ph, ("free", "reverse"))
            if "brake" in s:
                moving &= s["brake"] == 0
            starts = np.nonzero(moving[1:] & ~moving[:-1])[0]  # last held sample before each release
            keep[starts] = False
        keep[0] = keep[-1] = True
        s = {c: v[keep] for c, v in s.items()}
    held_mode = quirks.held_current or (quirks.decimate > 1 and quirks.decimate_current == "held-previous")
    if quirks.declare_current:
        rig["current_sampling"] = "held-previous" if held_mode else "instant"
    if quirks.L_unknown == "absent":
        rig.pop("L", None)
    elif quirks.L_unknown == "zero":
        rig["L"] = 0.0
    if quirks.shuffle_columns:
        s["daq_temperature"] = 21.0 + 0.001 * np.arange(len(s["t"]))
        order = list(s)[::-1]
        s = {c: s[c] for c in order}
    meta.setdefault("experiment", {})["daq_quirks"] = quirks.to_dict()
    return RunRecord(samples=s, meta=meta, path=None, gaps=[])


def _quantise(x: np.ndarray, counts: int | None) -> np.ndarray:
    if not counts:
        return x
    q = 2 * np.pi / counts
    return np.round(x / q) * q


def _held(i: np.ndarray) -> np.ndarray:
    """Mean over the previous interval of a current sampled at its instants (trapezoid)."""
    out = i.copy()
    out[1:] = 0.5 * (i[1:] + i[:-1])
    return out


def _block_mean(i: np.ndarray, k: int) -> np.ndarray:
    """At every k-th sample, the mean current over the k intervals before it (trapezoid)."""
    trap = np.concatenate([[i[0]], 0.5 * (i[1:] + i[:-1])])
    csum = np.cumsum(trap)
    out = i.copy()
    idx = np.arange(k, len(i))
    out[idx] = (csum[idx] - csum[idx - k]) / k
    return out


def _jitter(s: dict, sigma: float, rng: np.random.Generator, counts: dict) -> None:
    """Sample instants moved by N(0, sigma) (kept increasing); every channel re-read there."""
    t = s["t"]
    dt = float(np.median(np.diff(t)))
    shift = np.clip(rng.normal(0.0, sigma, t.size), -0.4 * dt, 0.4 * dt)
    shift[0] = shift[-1] = 0.0
    tj = t + shift
    for c in ("phi", "psi"):
        if c in s:
            s[c] = _quantise(np.interp(tj, t, s[c]), counts.get(c))
    for c in ("u", "i", "u_cmd", "i_cmd"):
        if c in s:
            s[c] = np.interp(tj, t, s[c])
    s["t"] = tj


def _brake_tail(s: dict, seconds: float, counts: dict) -> None:
    """Brake the hull for the last ``seconds``: phase idle, brake 1, hull angle frozen.

    The flywheel's absolute angle ``phi + psi`` is kept (the brake holds the hull, not
    the flywheel), so ``psi`` takes up what the hull no longer does.
    """
    t = s["t"]
    start = int(np.searchsorted(t, t[-1] - seconds))
    if start <= 0 or start >= len(t):
        return
    held_phi = s["phi"][start]
    theta = s["phi"][start:] + s["psi"][start:]
    s["phi"][start:] = held_phi
    s["psi"][start:] = _quantise(theta - held_phi, counts.get("psi"))
    s["phase"] = s["phase"].astype(object)
    s["phase"][start:] = "idle"
    s["phase"] = s["phase"].astype(str)
    if "brake" not in s:
        s["brake"] = np.zeros(len(t))
    s["brake"][start:] = 1.0


def _release_logged_moving(s: dict) -> None:
    """Log the last held sample before each stroke (the release instant) as moving."""
    ph = s["phase"].astype(object)
    moving = np.isin(ph, ("free", "reverse"))
    if "brake" in s:
        moving &= s["brake"] == 0
    starts = np.nonzero(moving[1:] & ~moving[:-1])[0]  # the held sample before each stroke
    for k in starts:
        ph[k] = ph[k + 1]
        if "brake" in s:
            s["brake"][k] = 0.0
    s["phase"] = ph.astype(str)
