"""A still or animated preview of a run, drawn with matplotlib (``warpcloth[plot]``).

``--preview out.png``: the last frame. ``--preview out.gif``: the animation, every k-th frame so
that at most :data:`MAX_GIF_FRAMES` frames are drawn (each shown for k / fps seconds, so it
plays at the simulation's speed). Both are lit by face normals and framed on the whole run's
bounding box and its colliders' (the camera does not move); the colliders are drawn translucent,
posed at each frame's time (a plane as a square around the cloth). Written atomically like every
output.
"""

from __future__ import annotations

import math
import os

import numpy as np

from warpcloth.errors import WarpclothError
from warpcloth.io.files import AtomicFile, OutputError, check_output_path, describe_write_error
from warpcloth.io.player import check_frame_memory
from warpcloth.sim.colliders import quat_matrix

PREVIEW_EXTENSIONS = (".png", ".gif")
#: Most frames in a GIF preview (a 640 x 480 frame is 30-80 kB: a few MB in all).
MAX_GIF_FRAMES = 90
#: Pixel size of a preview.
SIZE_PX = (640, 480)
PLOT_HINT = "pip install 'warpcloth[plot]' (from a clone: pip install -e '.[plot]')"


def require_matplotlib(what: str = "--preview") -> None:
    """One line naming the extra to install when matplotlib is missing (checked before a run)."""
    try:
        import matplotlib  # noqa: F401, PLC0415
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


def collider_triangles(c, lo, hi, resolution: int = 16) -> np.ndarray:
    """(T, 3, 3) triangles [m] that draw collider ``c`` (as it is, static): a sphere or capsule
    of ``resolution`` segments round, a box's 12, a mesh's own (at most 4,000), a plane as a
    square around the box ``lo``..``hi`` (the cloth's bounds)."""
    if c.kind == "box":
        corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=np.float64)
        points = np.asarray(c.center) + (corners * np.asarray(c.half_extents)) @ quat_matrix(c.rotation).T
        faces = [
            (0, 1, 3),
            (0, 3, 2),
            (4, 6, 7),
            (4, 7, 5),
            (0, 4, 5),
            (0, 5, 1),
            (2, 3, 7),
            (2, 7, 6),
            (0, 2, 6),
            (0, 6, 4),
            (1, 5, 7),
            (1, 7, 3),
        ]
        return points[np.array(faces)]
    if c.kind == "mesh":
        tris = np.asarray(c.vertices)[np.asarray(c.triangles)]
        return tris[:: max(1, len(tris) // 4000)]
    if c.kind == "plane":
        n = np.asarray(c.normal, dtype=np.float64)
        u = np.cross(n, [1.0, 0.0, 0.0] if abs(n[0]) < 0.9 else [0.0, 1.0, 0.0])
        u /= np.linalg.norm(u)
        v = np.cross(n, u)
        centre = np.asarray(c.point) + ((lo + hi) / 2 - np.asarray(c.point)) @ (np.eye(3) - np.outer(n, n))
        r = 0.5 * float(np.max(hi - lo))  # the plot's box: the square stays inside it
        q = [centre + r * (a * u + b * v) for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
        return np.array([[q[0], q[1], q[2]], [q[0], q[2], q[3]]])
    # sphere, capsule: a UV sphere, its halves pulled apart along the capsule's axis
    th, ph = np.meshgrid(np.linspace(0, 2 * np.pi, resolution + 1), np.linspace(0, np.pi, resolution // 2 + 1))
    unit = np.stack([np.sin(ph) * np.cos(th), np.sin(ph) * np.sin(th), np.cos(ph)], axis=-1)
    if c.kind == "sphere":
        grid = np.asarray(c.center) + c.radius * unit
    else:
        a, b = np.asarray(c.a, dtype=np.float64), np.asarray(c.b, dtype=np.float64)
        axis = b - a
        length = float(np.linalg.norm(axis))
        w = axis / length if length > 0 else np.array([0.0, 0.0, 1.0])
        e = np.cross(w, [1.0, 0.0, 0.0] if abs(w[0]) < 0.9 else [0.0, 1.0, 0.0])
        e /= np.linalg.norm(e)
        frame = np.stack([e, np.cross(w, e), w])  # local x, y, z (z along the axis)
        local = c.radius * unit + np.where(unit[..., 2:] >= 0, 0.5 * length, -0.5 * length) * np.array([0.0, 0.0, 1.0])
        grid = 0.5 * (a + b) + local @ frame
    p00, p01, p10, p11 = grid[:-1, :-1], grid[:-1, 1:], grid[1:, :-1], grid[1:, 1:]
    return np.concatenate(
        [np.stack([p00, p10, p11], axis=-2).reshape(-1, 3, 3), np.stack([p00, p11, p01], axis=-2).reshape(-1, 3, 3)]
    )


class PreviewWriter:
    """Collects frames; on :meth:`close` draws the PNG (last frame) or GIF (every k-th)."""

    def __init__(
        self, path: str, model, fps: float = 60.0, title: str = "", expected_frames: int | None = None, colliders=()
    ):
        self.path = check_preview_path(path)
        self.gif = os.path.splitext(self.path)[1].lower() == ".gif"
        if self.gif:
            check_frame_memory(model, expected_frames, "the GIF preview")
        self.fps = float(fps)
        self.title = title
        self.tris = np.asarray(model.host.tris, dtype=np.int64).reshape(-1, 3)
        self.pins = np.asarray(model.pinned, dtype=np.int64).reshape(-1)
        self.colliders = tuple(colliders or ())
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
        import matplotlib  # noqa: PLC0415 (the optional [plot] extra)

        matplotlib.use("Agg", force=True)
        import matplotlib.pyplot as plt  # noqa: PLC0415 (the optional [plot] extra)
        from mpl_toolkits.mplot3d.art3d import Poly3DCollection  # noqa: PLC0415 (the optional [plot] extra)

        dpi = 100
        fig = plt.figure(figsize=(SIZE_PX[0] / dpi, SIZE_PX[1] / dpi), dpi=dpi)
        ax = fig.add_subplot(projection="3d")
        allp = np.concatenate(self.frames)
        lo, hi = allp.min(axis=0), allp.max(axis=0)
        solid = [c for c in self.colliders if c.kind not in ("plane", "mesh")]
        for t in (self.times[0], self.times[-1]) if solid else ():
            for c in solid:
                tri = collider_triangles(c.at(t) if c.track is not None else c, lo, hi)
                lo, hi = np.minimum(lo, tri.reshape(-1, 3).min(axis=0)), np.maximum(hi, tri.reshape(-1, 3).max(axis=0))
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
        self._bounds = (c - r, c + r)  # the axes' cube (a plane is drawn across it)
        from matplotlib.ticker import MaxNLocator  # noqa: PLC0415 (the optional [plot] extra)

        for axis in (ax.xaxis, ax.yaxis, ax.zaxis):
            axis.set_major_locator(MaxNLocator(5))  # tick labels that do not run into each other
        self._solids = []
        for _ in self.colliders:
            shape = Poly3DCollection([], linewidths=0.2, alpha=0.35)
            ax.add_collection3d(shape)
            self._solids.append(shape)
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
        for c, shape in zip(self.colliders, self._solids):
            posed = c.at(self.times[k]) if c.track is not None else c
            tri = collider_triangles(posed, *self._bounds)[:, :, [0, 2, 1]]
            shape.set_verts(tri)
            shape.set_facecolor((0.55, 0.65, 0.80))
            shape.set_edgecolor((0.45, 0.55, 0.70))
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
                from matplotlib.animation import FuncAnimation, PillowWriter  # noqa: PLC0415 (the optional [plot] extra)

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
