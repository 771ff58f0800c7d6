"""Checks on a hull mesh before a BEM solve (pure numpy).

A panel method gives silently wrong numbers on a bad mesh, so a mesh is checked first:

* **closed**: every edge is shared by exactly two panels, except edges on the waterline
  (``z = 0``) of a floating hull and edges on a declared symmetry plane (where the mirror
  image closes the hull). Any other free edge is a hole.
* **orientation**: normals point out of the hull into the water (Capytaine's convention).
  Checked by the divergence theorem, ``V = sum(z_c n_z A)`` over the panels, which is the
  displaced volume and positive for outward normals (the waterplane adds nothing since
  ``z = 0`` there); and edge by edge, the two panels on an edge must run it in opposite
  directions (a consistently oriented surface).
* **no internal lid**: no panel lies *in* a symmetry plane (the mirror would double it
  into a wall inside the fluid) nor in the waterplane of a floating hull (a lid there is
  the irregular-frequency device, added by the solver, never part of the hull mesh).
* **immersion**: a floating hull has no panel above ``z = 0``.

All lengths in metres; ``faces`` is an (m, 4) index array, triangles repeating their last
vertex.
"""

from __future__ import annotations

import dataclasses

import numpy as np


class MeshError(ValueError):
    """A hull mesh that would give wrong BEM results; the message says what and where."""


@dataclasses.dataclass(frozen=True)
class MeshReport:
    """What the checks found: counts and the displaced volume (m^3, outward normals)."""

    panels: int
    free_edges: int
    inconsistent_edges: int
    lid_panels: int
    panels_above_surface: int
    volume: float
    area: float

    def as_dict(self) -> dict:
        """The report as a JSON-ready dict (``volume`` in m^3, ``area`` in m^2)."""
        return dataclasses.asdict(self)


def panel_geometry(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Centres (m, 3), unit normals (m, 3) and areas (m,) of quad/triangle panels."""
    p = vertices[faces]
    n = 0.5 * np.cross(p[:, 2] - p[:, 0], p[:, 3] - p[:, 1])  # exact area vector of a planar quad
    area = np.linalg.norm(n, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        unit = n / area[:, None]
    tri = faces[:, 2] == faces[:, 3]
    centres = np.where(tri[:, None], p[:, :3].mean(axis=1), p.mean(axis=1))
    return centres, unit, area


def _edges(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Directed edges (k, 2) of all panels (degenerate triangle edges dropped) and their face index."""
    e = np.stack([faces, np.roll(faces, -1, axis=1)], axis=-1).reshape(-1, 2)
    owner = np.repeat(np.arange(len(faces)), 4)
    keep = e[:, 0] != e[:, 1]
    return e[keep], owner[keep]


def check_mesh(vertices: np.ndarray, faces: np.ndarray, *, floating: bool,
               symmetry_planes: tuple[str, ...] = (), where: str = "mesh", tol: float = 1e-6) -> MeshReport:
    """Check a hull mesh; return a :class:`MeshReport` or raise :class:`MeshError`.

    ``symmetry_planes``: ``'xOz'`` (y = 0) and/or ``'yOz'`` (x = 0) when ``vertices``/``faces``
    are the half (or quarter) a solver will mirror. ``tol`` is in metres, relative to the
    hull size.
    """
    vertices = np.asarray(vertices, dtype=float)
    faces = np.asarray(faces, dtype=int)
    if faces.ndim != 2 or faces.shape[1] != 4 or len(faces) == 0:
        raise MeshError(f"{where}: expected panels as an (m, 4) index array with m > 0, got shape {faces.shape}")
    size = float(np.ptp(vertices, axis=0).max())
    eps = tol * max(size, 1e-9)
    # merge coincident vertices so that edges can be matched
    key = np.round(vertices / eps).astype(np.int64)
    _, inverse = np.unique(key, axis=0, return_inverse=True)
    f = inverse.reshape(-1)[faces]
    centres, normals, area = panel_geometry(vertices, faces)
    if np.any(~np.isfinite(normals)) or np.any(area <= 0):
        bad = int(np.count_nonzero(~(area > 0)))
        raise MeshError(f"{where}: {bad} panel(s) with zero area; expected non-degenerate panels")

    # internal lids: panels lying in a symmetry plane or in the waterplane. The tolerance is
    # much tighter than the merge tolerance: a fine hull mesh has real panels that come within
    # microns of the centreplane (a Wigley hull is tangent to it at the bow-keel corner)
    lid_eps = 1e-3 * eps
    pv = vertices[faces]
    lid = np.zeros(len(faces), dtype=bool)
    plane_axis = {"xOz": 1, "yOz": 0}
    for plane in symmetry_planes:
        if plane not in plane_axis:
            raise MeshError(f"{where}: symmetry plane {plane!r}: expected 'xOz' or 'yOz'")
        lid |= np.all(np.abs(pv[:, :, plane_axis[plane]]) < lid_eps, axis=1)
    if floating:
        lid |= np.all(np.abs(pv[:, :, 2]) < lid_eps, axis=1)
    above = int(np.count_nonzero(centres[:, 2] > eps)) if floating else 0

    # free and inconsistently oriented edges
    e, _ = _edges(f)
    und = np.sort(e, axis=1)
    uniq, idx, counts = np.unique(und, axis=0, return_inverse=True, return_counts=True)
    idx = idx.reshape(-1)
    free = uniq[counts == 1]
    vx = np.zeros(len(free), dtype=bool)
    if len(free):
        rep = np.zeros(inverse.max() + 1, dtype=int)
        rep[inverse.reshape(-1)] = np.arange(len(vertices))
        a, b = vertices[rep[free[:, 0]]], vertices[rep[free[:, 1]]]
        on = lambda ax: (np.abs(a[:, ax]) < eps) & (np.abs(b[:, ax]) < eps)  # noqa: E731
        if floating:
            vx |= on(2)
        for plane in symmetry_planes:
            vx |= on(plane_axis[plane])
    holes = int(np.count_nonzero(~vx))
    # orientation consistency: an edge shared by two panels is run once each way
    forward = e[:, 0] < e[:, 1]
    fwd_count = np.bincount(idx, weights=forward.astype(float), minlength=len(uniq))
    shared = counts == 2
    inconsistent = int(np.count_nonzero(shared & (fwd_count != 1)))

    volume = float(np.sum(centres[:, 2] * normals[:, 2] * area)) * (2 ** len(symmetry_planes))
    report = MeshReport(panels=len(faces) * 2 ** len(symmetry_planes), free_edges=holes,
                        inconsistent_edges=inconsistent, lid_panels=int(np.count_nonzero(lid)),
                        panels_above_surface=above, volume=volume,
                        area=float(area.sum()) * 2 ** len(symmetry_planes))
    if report.lid_panels:
        raise MeshError(f"{where}: {report.lid_panels} panel(s) lie in a symmetry plane or the waterplane "
                        "(an internal lid); expected the wetted hull surface only")
    if above:
        raise MeshError(f"{where}: {above} panel(s) above the waterline z = 0; expected the wetted part only "
                        "(clip the mesh at z = 0, or use --deep for a submerged body)")
    if holes:
        raise MeshError(f"{where}: {holes} free edge(s) off the waterline and symmetry planes; "
                        "expected a closed hull (holes give wrong BEM results)")
    if inconsistent:
        raise MeshError(f"{where}: {inconsistent} edge(s) where neighbouring panels disagree on orientation; "
                        "expected consistently ordered panels")
    if volume <= 0:
        raise MeshError(f"{where}: displaced volume {volume:.4g} m^3 from the panel normals; expected > 0 "
                        "(normals must point out of the hull into the water; reverse the panel order)")
    return report
