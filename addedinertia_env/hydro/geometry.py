"""Analytic hull shapes as panel meshes (pure numpy; no BEM solver needed).

Two shapes, the ones the rig presets use:

* **Wigley hull** ``y = B/2 (1 - (2x/L)^2)(1 - (z/T)^2)``, ``|x| <= L/2``, ``-T <= z <= 0``
  (physics.md section 6). Floating at its waterline, or as the *double body* (mirrored
  above the waterline, ``-T <= z <= T``) deeply submerged.
* **Prolate spheroid** with semi-axes ``a = L/2`` along x and ``b = B/2`` across: floating
  with its axis in the waterline (the lower half), or whole and deeply submerged.

Each mesh is made as the *quarter* ``x >= 0, y >= 0`` (both port-starboard and fore-aft
symmetry), with outward normals (pointing into the water), and no panel on a symmetry
plane or on the waterline plane: the quarter is mirrored by the solver, so a panel lying
in the plane ``x = 0`` or ``y = 0`` would be an internal lid (see :mod:`.mesh_checks`).

Resolution is given as ``panels``, the approximate number of panels on the whole
(wetted) hull; the quarter gets ``nx * nz ~ panels / 4`` with the split chosen so that
panels are about as long as they are high. Lengths in metres.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

from addedinertia_env.foundation.config_io import ConfigError, check_keys

SHAPES = ("wigley", "spheroid")
SUBMERGENCE = ("floating", "deep")


@dataclasses.dataclass(frozen=True)
class HullShape:
    """An analytic hull: ``shape`` in :data:`SHAPES`, length/beam/draft in m.

    ``draft`` is the Wigley draft ``T``; for a spheroid floating with its axis in the
    waterline the draft is ``beam / 2`` and is derived (a given value must match).
    """

    shape: str
    length: float
    beam: float
    draft: float | None = None

    def __post_init__(self) -> None:
        if self.shape not in SHAPES:
            raise ValueError(f"hull shape {self.shape!r}: expected one of {', '.join(SHAPES)}")
        for name in ("length", "beam"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"hull {name} = {v!r}: expected a finite number > 0 (m)")
        if self.shape == "wigley":
            if not (isinstance(self.draft, (int, float)) and math.isfinite(self.draft) and self.draft > 0):
                raise ValueError(f"hull draft = {self.draft!r}: expected a finite number > 0 (m) for a Wigley hull")
        else:
            if self.length <= self.beam:
                raise ValueError(f"spheroid length {self.length} <= beam {self.beam}: expected a prolate spheroid (L > B)")
            if self.draft is not None and abs(self.draft - 0.5 * self.beam) > 1e-6 * self.beam:
                raise ValueError(f"spheroid draft = {self.draft!r}: expected beam/2 = {0.5 * self.beam} (axis in the waterline)")
            object.__setattr__(self, "draft", 0.5 * self.beam)

    def displaced_volume(self, submergence: str = "floating") -> float:
        """Exact displaced volume, m^3 (double for ``'deep'``)."""
        L, B, T = self.length, self.beam, float(self.draft)
        if self.shape == "wigley":
            v = 4.0 / 9.0 * L * B * T  # integral of 2y over x and z: B L T (2/3)(2/3)
        else:
            v = 2.0 / 3.0 * math.pi * (L / 2) * (B / 2) ** 2
        return 2.0 * v if submergence == "deep" else v

    def block_coefficient(self) -> float:
        """``C_B = volume / (L B T)`` of the floating hull (Wigley 4/9, spheroid pi/6)."""
        return self.displaced_volume("floating") / (self.length * self.beam * float(self.draft))

    def as_dict(self) -> dict:
        """The shape as the ``geometry`` mapping of a preset: ``shape`` and ``length``, ``beam``, ``draft`` in m."""
        return {"shape": self.shape, "length": self.length, "beam": self.beam, "draft": self.draft}


@dataclasses.dataclass(frozen=True)
class QuarterMesh:
    """The quarter ``x >= 0, y >= 0`` of a hull mesh: vertices (n, 3) m, faces (m, 4) indices.

    Triangles repeat their last index (``[i, j, k, k]``). Mirror about ``y = 0`` then
    ``x = 0`` for the whole hull (:func:`full_mesh`).
    """

    vertices: np.ndarray
    faces: np.ndarray
    nx: int
    nz: int
    shape: HullShape
    submergence: str

    @property
    def nb_faces_full(self) -> int:
        """Number of panels on the whole hull (the quarter mirrored twice)."""
        return 4 * len(self.faces)


def _grid_faces(nu: int, nv: int) -> np.ndarray:
    """Quad faces of an (nu+1) x (nv+1) vertex grid, vertex index ``i * (nv+1) + j``."""
    i, j = np.meshgrid(np.arange(nu), np.arange(nv), indexing="ij")
    a = i * (nv + 1) + j
    return np.stack([a, a + (nv + 1), a + (nv + 1) + 1, a + 1], axis=-1).reshape(-1, 4)


def _split(panels: int, aspect: float) -> tuple[int, int]:
    """(nx, nz) with ``nx * nz ~ panels / 4`` and ``nx / nz ~ aspect``."""
    if not isinstance(panels, (int, np.integer)) or panels < 16:
        raise ValueError(f"panels = {panels!r}: expected an integer >= 16")
    quarter = panels / 4.0
    nz = max(2, int(round(math.sqrt(quarter / aspect))))
    nx = max(2, int(round(quarter / nz)))
    return nx, nz


def reversed_faces(faces: np.ndarray) -> np.ndarray:
    """Faces with their vertex order reversed; triangles ``[i, j, k, k]`` become ``[k, j, i, i]``."""
    out = faces[:, ::-1].copy()
    tri = faces[:, 2] == faces[:, 3]
    out[tri] = faces[tri][:, [2, 1, 0, 0]]
    return out


def _orient_outward(vertices: np.ndarray, faces: np.ndarray, outward_hint: np.ndarray) -> np.ndarray:
    """Flip faces whose normal points against ``outward_hint`` (per face)."""
    p = vertices[faces]
    n = np.cross(p[:, 2] - p[:, 0], p[:, 3] - p[:, 1])
    # triangles [i, j, k, k]: diagonal formula still gives the right direction
    flip = np.einsum("ij,ij->i", n, outward_hint) < 0
    out = faces.copy()
    out[flip] = reversed_faces(out[flip])
    return out


def wigley_quarter(shape: HullShape, panels: int, submergence: str = "floating") -> QuarterMesh:
    """Quarter mesh of a Wigley hull, cosine-spaced towards bow and keel."""
    L, B, T = shape.length, shape.beam, float(shape.draft)
    depth = 2.0 * T if submergence == "deep" else T
    # nearly square index grid: with cosine spacing towards bow and keel this converges
    # fastest (A66(0) within 1 % of the extrapolated value at 1,600 panels, docs/HYDRODYNAMICS.md)
    nx, nz = _split(panels, aspect=1.2)
    # cosine spacing: finer near the bow (x = L/2) and the keel / waterline
    s = np.sin(0.5 * np.pi * np.linspace(0.0, 1.0, nx + 1))
    x = 0.5 * L * s
    if submergence == "deep":
        t = np.linspace(-1.0, 1.0, nz + 1)
        z = T * np.sin(0.5 * np.pi * t)
    else:
        t = np.linspace(0.0, 1.0, nz + 1)
        z = -T * np.sin(0.5 * np.pi * t)  # 0 at the waterline down to -T at the keel
    X, Z = np.meshgrid(x, z, indexing="ij")
    Y = 0.5 * B * (1.0 - (2.0 * X / L) ** 2) * (1.0 - (Z / T) ** 2)
    vertices = np.stack([X, Y, Z], axis=-1).reshape(-1, 3)
    faces = _grid_faces(nx, nz)
    centres = vertices[faces].mean(axis=1)
    hint = np.zeros_like(centres)
    hint[:, 1] = 1.0  # the hull surface faces +y on the starboard quarter
    faces = _orient_outward(vertices, faces, hint)
    return QuarterMesh(vertices, faces, nx, nz, shape, submergence)


def spheroid_quarter(shape: HullShape, panels: int, submergence: str = "floating") -> QuarterMesh:
    """Quarter mesh of a prolate spheroid, with triangles at the tip (x = a)."""
    a, b = 0.5 * shape.length, 0.5 * shape.beam
    arc = math.pi * b if submergence == "deep" else 0.5 * math.pi * b
    nx, nz = _split(panels, aspect=max(1.0, 1.2 * a / arc))
    theta = 0.5 * np.pi * np.linspace(0.0, 1.0, nx + 1)  # 0 at the tip, pi/2 amidships
    x = a * np.cos(theta)
    r = b * np.sin(theta)
    # azimuth psi: y = r sin(psi), z = -r cos(psi); psi in [0, pi] (deep) or [0, pi/2] (floating)
    psi_end = np.pi if submergence == "deep" else 0.5 * np.pi
    psi = psi_end * np.linspace(0.0, 1.0, nz + 1)
    TH, PS = np.meshgrid(np.arange(nx + 1), psi, indexing="ij")
    X = x[TH]
    R = r[TH]
    Y = R * np.sin(PS)
    Z = -R * np.cos(PS)
    vertices = np.stack([X, Y, Z], axis=-1).reshape(-1, 3)
    faces = _grid_faces(nx, nz)
    # row 0 is the tip (all vertices at one point): make those faces triangles onto one tip vertex
    tip = 0
    first = faces[: nz].copy()  # faces between row 0 and row 1
    # [a, a+(nz+1), a+(nz+1)+1, a+1] -> [tip, a+(nz+1), a+(nz+1)+1, a+(nz+1)+1]
    first[:, 0] = tip
    first[:, 3] = first[:, 2]
    faces = np.vstack([first, faces[nz:]])
    centres = vertices[faces].mean(axis=1)
    hint = centres / np.array([a * a, b * b, b * b])  # gradient of the spheroid function
    faces = _orient_outward(vertices, faces, hint)
    # keep only the tip vertex of row 0 (others duplicate it)
    used = np.unique(faces)
    remap = -np.ones(len(vertices), dtype=int)
    remap[used] = np.arange(len(used))
    return QuarterMesh(vertices[used], remap[faces], nx, nz, shape, submergence)


def quarter_mesh(shape: HullShape, panels: int, submergence: str = "floating") -> QuarterMesh:
    """The quarter mesh of ``shape`` with about ``panels`` panels on the whole hull."""
    if submergence not in SUBMERGENCE:
        raise ValueError(f"submergence {submergence!r}: expected one of {', '.join(SUBMERGENCE)}")
    if shape.shape == "wigley":
        return wigley_quarter(shape, panels, submergence)
    return spheroid_quarter(shape, panels, submergence)


def full_mesh(q: QuarterMesh) -> tuple[np.ndarray, np.ndarray]:
    """The whole hull (mirror about y = 0, then x = 0): vertices, faces (m, 4).

    Mirrored faces have their vertex order reversed so normals stay outward.
    """
    v, f = q.vertices, q.faces
    vs, fs = [v], [f]
    for axis in (1, 0):
        V = np.vstack(vs)
        F = np.vstack(fs)
        m = V.copy()
        m[:, axis] *= -1.0
        vs = [V, m]
        fs = [F, reversed_faces(F) + len(V)]
    return np.vstack(vs), np.vstack(fs)


def gdf_text(q: QuarterMesh, title: str = "addedinertia hull mesh") -> str:
    """The quarter mesh in WAMIT's GDF format (both symmetry flags set), m, g = 9.81.

    Capytaine, WAMIT and most panel codes read it; every panel is written as 4 vertices
    (triangles repeat their last one).
    """
    lines = [title, "1.0 9.81", "1 1", f"{len(q.faces)}"]
    for face in q.faces:
        for v in q.vertices[face]:
            lines.append(f"{v[0]:.9f} {v[1]:.9f} {v[2]:.9f}")
    return "\n".join(lines) + "\n"


GEOMETRY_KEYS = ("shape", "length", "beam", "draft")


def shape_from_mapping(block: Any, where: str) -> HullShape:
    """A :class:`HullShape` from a preset's ``hull.geometry`` mapping (lengths in m).

    ``where`` names the block in messages (file and key). Raises :class:`ConfigError`
    naming the field when the block is not a mapping, has unknown keys or bad values.
    """
    check_keys(block, GEOMETRY_KEYS, where)
    try:
        return HullShape(**block)
    except (TypeError, ValueError) as e:
        raise ConfigError(f"{where}: {e}") from None
