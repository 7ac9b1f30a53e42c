"""A still or animated preview of a run, drawn with matplotlib (``warpcloth[plot]``).

``--preview out.png``: the last frame. ``--preview out.gif``: the animation, every k-th frame so
that at most :data:`MAX_GIF_FRAMES` frames are drawn (each shown for k / fps seconds, so it
plays at the simulation's speed). Both are lit by face normals and framed on the whole run's
bounding box (the camera does not move). Written atomically like every output.
"""

from __future__ import annotations

import math
import os

import numpy as np

from warpcloth.errors import WarpclothError
from warpcloth.io.files import AtomicFile, OutputError, check_output_path, describe_write_error

PREVIEW_EXTENSIONS = (".png", ".gif")
#: Most frames in a GIF preview (a 640 x 480 frame is 30-80 kB: a few MB in all).
MAX_GIF_FRAMES = 90
#: Pixel size of a preview.
SIZE_PX = (640, 480)
PLOT_HINT = "pip install 'warpcloth[plot]' (from a clone: pip install -e '.[plot]')"


def require_matplotlib(what: str = "--preview") -> None:
    """One line naming the extra to install when matplotlib is missing (checked before a run)."""
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        raise WarpclothError(f"{what} needs matplotlib: {PLOT_HINT}") from None


def check_preview_path(path: str) -> str:
    """A .png or .gif path that can be written, and matplotlib importable; before any work."""
    p = check_output_path(path, "preview", extensions=PREVIEW_EXTENSIONS)
    require_matplotlib()
    return p


def gif_stride(frames: int, max_frames: int = MAX_GIF_FRAMES) -> int:
    """Keep every k-th frame so that at most ``max_frames`` remain."""
    return max(1, math.ceil(frames / max(1, max_frames)))


class PreviewWriter:
    """Collects frames; on :meth:`close` draws the PNG (last frame) or GIF (every k-th)."""

    def __init__(self, path: str, model, fps: float = 60.0, title: str = "", expected_frames: int | None = None):
        self.path = check_preview_path(path)
        self.gif = os.path.splitext(self.path)[1].lower() == ".gif"
        if self.gif:
            from warpcloth.io.player import check_frame_memory

            check_frame_memory(model, expected_frames, "the GIF preview")
        self.fps = float(fps)
        self.title = title
        self.tris = np.asarray(model.host["tris"], dtype=np.int64).reshape(-1, 3)
        self.pins = np.asarray(model.pinned, dtype=np.int64).reshape(-1)
        self.frames: list[np.ndarray] = []
        self.times: list[float] = []
        self._closed = False

    def write_frame(self, points, sim_time: float | None = None) -> None:
        p = np.array(points, dtype=np.float32).reshape(-1, 3)
        if not np.all(np.isfinite(p)):
            return
        t = float(sim_time) if sim_time is not None else len(self.times) / self.fps
        if self.gif:
            self.frames.append(p)
            self.times.append(t)
        else:
            self.frames, self.times = [p], [t]

    def _figure(self):
        import matplotlib

        matplotlib.use("Agg", force=True)
        import matplotlib.pyplot as plt
        from mpl_toolkits.mplot3d.art3d import Poly3DCollection

        dpi = 100
        fig = plt.figure(figsize=(SIZE_PX[0] / dpi, SIZE_PX[1] / dpi), dpi=dpi)
        ax = fig.add_subplot(projection="3d")
        allp = np.concatenate(self.frames)
        lo, hi = allp.min(axis=0), allp.max(axis=0)
        c, r = (lo + hi) / 2, max(float((hi - lo).max()) / 2, 0.05)
        # warpcloth is Y up; matplotlib's 3-D axes are Z up: plot (x, z, y)
        ax.set_xlim(c[0] - r, c[0] + r)
        ax.set_ylim(c[2] - r, c[2] + r)
        ax.set_zlim(c[1] - r, c[1] + r)
        ax.set_box_aspect((1, 1, 1))
        ax.set_xlabel("x [m]")
        ax.set_ylabel("z [m]")
        ax.set_zlabel("y [m]")
        ax.view_init(elev=18, azim=-60)
        poly = Poly3DCollection([], linewidths=0.0)
        ax.add_collection3d(poly)
        pins = ax.scatter([], [], [], color=(0.9, 0.2, 0.3), s=8, depthshade=False)
        label = ax.set_title("")
        return fig, plt, poly, pins, label

    def _draw(self, poly, pins, label, k: int) -> None:
        p = self.frames[k][:, [0, 2, 1]]
        tri = p[self.tris]
        n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-20)
        light = np.array([0.3, -0.5, 0.8])
        light /= np.linalg.norm(light)
        shade = 0.25 + 0.75 * np.abs(n @ light)  # two-sided
        base = np.array([0.80, 0.70, 0.55])
        poly.set_verts(tri)
        rgb = np.clip(shade[:, None] * base, 0, 1)
        poly.set_facecolor(rgb)
        poly.set_edgecolor(rgb)  # no seams between the triangles
        if self.pins.size:
            q = p[self.pins]
            pins._offsets3d = (q[:, 0], q[:, 1], q[:, 2])
        label.set_text(f"{self.title}  t = {self.times[k]:.2f} s".strip())

    def close(self) -> str:
        if self._closed:
            return self.path
        if not self.frames:
            raise WarpclothError("the preview has no frames to draw")
        self._closed = True
        fig, plt, poly, pins, label = self._figure()
        try:
            f = AtomicFile(self.path, "preview", mode="wb")
        except OSError as exc:
            plt.close(fig)
            raise OutputError(describe_write_error(exc, self.path, "preview")) from None
        try:
            if self.gif:
                from matplotlib.animation import FuncAnimation, PillowWriter

                stride = gif_stride(len(self.frames))
                keep = list(range(0, len(self.frames), stride))
                if keep[-1] != len(self.frames) - 1:
                    keep.append(len(self.frames) - 1)
                anim = FuncAnimation(fig, lambda k: self._draw(poly, pins, label, k), frames=keep, blit=False)
                f.fh.close()  # Pillow writes by name
                anim.save(f.tmp, writer=PillowWriter(fps=self.fps / stride))
                f.fh = open(f.tmp, "ab")
            else:
                self._draw(poly, pins, label, len(self.frames) - 1)
                fig.savefig(f.fh, format="png", dpi=100)
        except OSError as exc:
            f.abort()
            raise OutputError(describe_write_error(exc, self.path, "preview")) from None
        except BaseException:
            f.abort()
            raise
        finally:
            plt.close(fig)
            self.frames = []
        return f.commit()

    def abort(self) -> None:
        self.frames = []
        self._closed = True
