"""Pictures of an episode: the rig drawn by MuJoCo, and a plot of the run so far.

``rgb_array`` needs an OpenGL backend chosen *before* MuJoCo is first imported, through
the ``MUJOCO_GL`` environment variable (MuJoCo's own rule): on a headless machine use
``MUJOCO_GL=egl`` (add ``EGL_PLATFORM=surfaceless`` where no GPU is present) or
``MUJOCO_GL=osmesa`` (Debian package ``libosmesa6``). ``plot`` needs only matplotlib.
"""

from __future__ import annotations

import atexit
import os
import weakref
from typing import Any

import numpy as np

from addedinertia_env.records.record import RunRecord

GL_HELP = ("MuJoCo could not open an OpenGL context for render_mode='rgb_array'. Set MUJOCO_GL before "
           "Python imports mujoco: MUJOCO_GL=egl (with EGL_PLATFORM=surfaceless on a machine without a GPU) "
           "or MUJOCO_GL=osmesa (apt-get install libosmesa6). MUJOCO_GL is now {gl!r}.")


# Renderers still open when the interpreter exits (an env nobody closed): closed by an atexit
# hook while the OpenGL context and its library are still alive. Left to the garbage collector
# at teardown, MuJoCo's EGL context is freed after EGL itself is gone and prints tracebacks.
# The hook is registered after MuJoCo's first renderer exists, hence after mujoco.egl's own
# atexit eglTerminate, so it runs before it (atexit runs last-registered first).
_OPEN: "weakref.WeakSet[RigRenderer]" = weakref.WeakSet()
_HOOKED = False


def _close_open_renderers() -> None:
    for renderer in list(_OPEN):
        try:
            renderer.close()
        except Exception:  # noqa: BLE001, S110 - at exit a failed free has no one left to tell
            pass


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
        global _HOOKED
        if not _HOOKED:
            atexit.register(_close_open_renderers)
            _HOOKED = True
        _OPEN.add(self)
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
            renderer, self._renderer = self._renderer, None
            _OPEN.discard(self)
            renderer.close()


def plot_frame(record: RunRecord, title: str = "", dpi: int = 80) -> np.ndarray:
    """The run so far (:func:`addedinertia_env.records.plots.run_figure`) as an RGB uint8 array."""
    import matplotlib  # noqa: PLC0415

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415

    from addedinertia_env.records.plots import run_figure  # noqa: PLC0415

    fig = run_figure(record, title=title)
    try:
        fig.set_dpi(dpi)
        fig.canvas.draw()
        return np.asarray(fig.canvas.buffer_rgba())[..., :3].copy()
    finally:
        plt.close(fig)


class PlotRenderer:
    """The ``plot`` render mode: one matplotlib figure per environment, kept between frames.

    The figure is :func:`addedinertia_env.records.plots.run_figure`'s (three panels over time, the
    phases shaded). Its axes, ticks and labels are drawn once and kept as a bitmap (blitting);
    a frame restores that bitmap and draws only the curves, the phase shading and the title.
    The axis limits grow in steps (the time axis by half again, a value axis by a quarter of
    its range each side) when the run leaves them, and only then is the whole figure redrawn.
    Rebuilding the figure every frame (:func:`plot_frame`) made a
    :class:`gymnasium.wrappers.RecordVideo` episode of about 200 frames take minutes.
    """

    PANELS = (("hull yaw phi [rad]", "phi"), ("motor current i [A]", "i"), ("flywheel rate Omega [rad/s]", "omega"))

    def __init__(self, dpi: int = 80):
        self.dpi = dpi
        self.fig = None

    def _build(self) -> None:
        import matplotlib  # noqa: PLC0415

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt  # noqa: PLC0415

        from addedinertia_env.records.plots import PHASE_COLOURS  # noqa: PLC0415

        self.fig, self.axes = plt.subplots(3, 1, figsize=(9, 7), sharex=True, dpi=self.dpi)
        self.lines = []
        for ax, (label, _) in zip(self.axes, self.PANELS):
            (line,) = ax.plot([], [], lw=0.8, color="k", animated=True)
            self.lines.append(line)
            ax.set_ylabel(label)
            ax.grid(alpha=0.3)
        self.axes[-1].set_xlabel("time [s]")
        handles = [plt.Rectangle((0, 0), 1, 1, color=c) for c in PHASE_COLOURS.values()]
        self.legend = self.axes[0].legend(handles, list(PHASE_COLOURS), loc="upper right", ncol=4, fontsize=8)
        self.legend.set_animated(True)  # drawn over the shading
        self.title = self.axes[0].set_title(" ", animated=True)
        self.fig.tight_layout()  # once: the layout does not change between frames
        self.spans: list[tuple[int, list]] = []  # (first sample of the block, its patches)
        self.colours = PHASE_COLOURS
        self.xlim: tuple[float, float] | None = None
        self.ylims: list[tuple[float, float] | None] = [None] * len(self.axes)
        self.background = None

    def _grow_limits(self, t: np.ndarray, series: list[np.ndarray]) -> bool:
        """Widen the axes where the data left them; True when they changed (a full redraw)."""
        changed = False
        t0, t1 = float(t[0]), float(t[-1])
        if self.xlim is None or t1 > self.xlim[1] or t0 < self.xlim[0]:
            self.xlim = (t0, t0 + max(1.5 * (t1 - t0), 1.0))
            self.axes[0].set_xlim(*self.xlim)
            changed = True
        for k, (ax, y) in enumerate(zip(self.axes, series)):
            lo, hi = float(np.min(y)), float(np.max(y))
            old = self.ylims[k]
            if old is None or lo < old[0] or hi > old[1]:
                span = max(hi - lo, 1e-3 * max(abs(hi), abs(lo)), 1e-9)
                self.ylims[k] = (lo - 0.25 * span, hi + 0.25 * span)
                ax.set_ylim(*self.ylims[k])
                changed = True
        return changed

    def render(self, record: RunRecord, title: str = "") -> np.ndarray:
        """The run so far as an RGB uint8 frame (the panels of :func:`plot_frame`)."""
        if self.fig is None:
            self._build()
        t, phase = record.t, record.phase
        series = [record["phi"], record["i"], np.gradient(record["psi"], t) if len(t) > 1 else np.zeros(len(t))]
        canvas = self.fig.canvas
        if len(t) and self._grow_limits(t, series):
            self.background = None
        if self.background is None:
            canvas.draw()  # everything but the animated artists: the curves, the shading, the title
            self.background = canvas.copy_from_bbox(self.fig.bbox)
        else:
            canvas.restore_region(self.background)
        self._shade(t, phase)
        for line, y in zip(self.lines, series):
            line.set_data(t, y)
        for k, ax in enumerate(self.axes):
            for _, patches in self.spans:
                ax.draw_artist(patches[k])
            ax.draw_artist(self.lines[k])
        self.axes[0].draw_artist(self.legend)
        self.title.set_text(title or f"run {record.run_id}")
        self.axes[0].draw_artist(self.title)
        return np.asarray(canvas.buffer_rgba())[..., :3].copy()

    def _shade(self, t: np.ndarray, phase: np.ndarray) -> None:
        """Phase blocks shaded; blocks finished at an earlier frame are kept, the rest made anew."""
        if not len(t):
            return
        starts = np.concatenate([[0], np.nonzero(phase[1:] != phase[:-1])[0] + 1])
        ends = np.concatenate([starts[1:], [len(t) - 1]])
        if self.spans:  # the block that was last at the previous frame may have grown (or ended)
            for patch in self.spans.pop()[1]:
                patch.remove()
        for a, b in zip(starts, ends):
            if self.spans and a <= self.spans[-1][0]:
                continue
            colour = self.colours.get(str(phase[a]), "white")
            self.spans.append((int(a), [ax.axvspan(t[a], t[b], color=colour, lw=0, alpha=0.8, animated=True)
                                        for ax in self.axes]))

    def close(self) -> None:
        """Close the figure (safe to call twice)."""
        if self.fig is not None:
            import matplotlib.pyplot as plt  # noqa: PLC0415

            plt.close(self.fig)
            self.fig = None
