"""Pictures of an episode: the rig drawn by MuJoCo, and a plot of the run so far.

``rgb_array`` needs an OpenGL backend chosen *before* MuJoCo is first imported, through
the ``MUJOCO_GL`` environment variable (MuJoCo's own rule): on a headless machine use
``MUJOCO_GL=egl`` (add ``EGL_PLATFORM=surfaceless`` where no GPU is present) or
``MUJOCO_GL=osmesa`` (Debian package ``libosmesa6``). ``plot`` needs only matplotlib.
"""

from __future__ import annotations

import os
from typing import Any

import numpy as np

from ..record import RunRecord

GL_HELP = ("MuJoCo could not open an OpenGL context for render_mode='rgb_array'. Set MUJOCO_GL before "
           "Python imports mujoco: MUJOCO_GL=egl (with EGL_PLATFORM=surfaceless on a machine without a GPU) "
           "or MUJOCO_GL=osmesa (apt-get install libosmesa6). MUJOCO_GL is now {gl!r}.")


class RigRenderer:
    """Offscreen MuJoCo view of the hull (white), the flywheel (red, yellow marker) and the reference (green).

    One renderer per MuJoCo model: the environment builds a new model at each reset,
    so it calls :meth:`close` and makes a new one then.
    """

    def __init__(self, model: Any, width: int = 480, height: int = 360):
        import mujoco  # noqa: PLC0415

        try:
            self._renderer = mujoco.Renderer(model, height=height, width=width)
        except Exception as e:  # noqa: BLE001 - every backend fails differently; all mean "no GL"
            raise RuntimeError(GL_HELP.format(gl=os.environ.get("MUJOCO_GL", "")) + f" ({type(e).__name__}: {e})") from e
        self.model = model
        self.camera = mujoco.MjvCamera()
        self.camera.lookat[:] = (0.0, 0.0, 0.0)
        self.camera.distance = 2.8  # m
        self.camera.elevation = -50.0  # degrees: from above and aside
        self.camera.azimuth = 90.0

    def render(self, data: Any, reference_angle: float | None = None) -> np.ndarray:
        """An RGB frame (height, width, 3), uint8, of the rig in the state ``data``; with
        ``reference_angle`` (rad, encoder frame), a green bar shows where the hull should point."""
        import mujoco  # noqa: PLC0415

        self._renderer.update_scene(data, camera=self.camera)
        scene = self._renderer.scene
        if reference_angle is not None and scene.ngeom < scene.maxgeom:
            c, s = np.cos(reference_angle), np.sin(reference_angle)
            rotation = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]).reshape(-1)
            mujoco.mjv_initGeom(scene.geoms[scene.ngeom], int(mujoco.mjtGeom.mjGEOM_BOX),
                                np.array([1.1, 0.008, 0.008]), np.array([0.0, 0.0, 0.14]), rotation,
                                np.array([0.1, 0.8, 0.2, 1.0], dtype=np.float32))
            scene.ngeom += 1
        return self._renderer.render().copy()

    def close(self) -> None:
        """Free the MuJoCo renderer (safe to call twice)."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None


def plot_frame(record: RunRecord, title: str = "", dpi: int = 80) -> np.ndarray:
    """The run so far (:func:`addedinertia_env.plots.run_figure`) as an RGB uint8 array."""
    import matplotlib  # noqa: PLC0415

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415

    from ..plots import run_figure  # noqa: PLC0415

    fig = run_figure(record, title=title)
    try:
        fig.set_dpi(dpi)
        fig.canvas.draw()
        return np.asarray(fig.canvas.buffer_rgba())[..., :3].copy()
    finally:
        plt.close(fig)
