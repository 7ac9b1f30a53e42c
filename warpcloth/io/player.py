"""A self-contained HTML player of a run (``warpcloth run ... --html out.html``).

One HTML file, nothing fetched when it opens: the page (``player.html`` beside this module, a
small WebGL 1 program written for warpcloth) and the animation as JSON inside it. Frames are
stored compactly: every position quantised to uint16 within the animation's bounding box
(3 x 2 bytes a vertex, base64: 8 bytes a vertex a frame; the step is the box's size / 65535),
the frames' simulated times, the triangles, the springs and their rest lengths (the player
computes normals and, on request, spring strain per frame), the pinned particles and the run's
colliders (:func:`collider_records`), drawn shaded in a neutral grey: a plane as a square patch
around the cloth (:data:`PLANE_PATCH` x the animation's bounding-box diagonal across, centred where
the box's centre projects onto the plane, ruled with a grid fixed to the plane), spheres, capsules, oriented
boxes and triangle meshes (vertices uint16 in the mesh's own box, like the frames). A collider
on a track gets its rigid pose at every frame's simulated time (:class:`ColliderPoses`): the
translation uint16 within the range it covers and, only if it turns, the rotation quaternion as
int16 (14 bytes a frame, 6 if it only translates); a static collider has no per-frame data.

Open ``out.html#t=0.5`` to seek to t = 0.5 s and pause; ``#t=0.5&strain=1`` also colours the
cloth by strain (a fixed scale, blue 0 to red :data:`~warpcloth.io.usd.DEFAULT_STRAIN_SCALE`, 10 %,
as the USD output's colours, so that two pages compare; the run's largest strain is printed under
it); ``&colliders=0`` hides the colliders. A model of several cloths draws each in its own colour.
The camera starts framing the whole animation's bounding box (every frame's cloth, above the
control bar), seen from the side the cloth faces.
"""

from __future__ import annotations

import base64
import html
import json
import os

import numpy as np

from warpcloth.errors import WarpclothError
from warpcloth.io.files import check_output_path, write_atomic
from warpcloth.io.frames import spring_arrays, vertex_strain
from warpcloth.io.usd import DEFAULT_STRAIN_SCALE
from warpcloth.sim.colliders import matrix_quat

HTML_EXTENSIONS = (".html", ".htm")
#: Where the page template lives (package data).
TEMPLATE = os.path.join(os.path.dirname(os.path.abspath(__file__)), "player.html")
#: A plane's patch in the player is this many times the animation's bounding-box diagonal across
#: (at least :data:`PLANE_PATCH_MIN` m).
PLANE_PATCH = 3.0
PLANE_PATCH_MIN = 0.3
#: Bytes of float32 positions held in memory before the run is refused (about 2 GB).
MAX_BUFFER_BYTES = 2 * 1024**3


def check_frame_memory(model, frames: int | None, what: str) -> None:
    """Refuse, before the run, a writer that would hold more than :data:`MAX_BUFFER_BYTES` of frames."""
    if frames is None:
        return
    need = int(frames) * int(model.particle_count) * 12
    if need > MAX_BUFFER_BYTES:
        raise WarpclothError(
            f"{what} would hold {frames} frames of {model.particle_count} particles, {need / 2**30:.1f} GiB "
            f"(at most {MAX_BUFFER_BYTES / 2**30:.0f} GiB); use fewer frames (--fps, --duration) or a smaller cloth"
        )


def check_html_path(path: str) -> str:
    """Validate an HTML output path before a run (see :func:`~warpcloth.io.files.check_output_path`)."""
    return check_output_path(path, "HTML", extensions=HTML_EXTENSIONS)


def _b64(array: np.ndarray) -> str:
    return base64.b64encode(np.ascontiguousarray(array).tobytes()).decode("ascii")


def quantise(frames: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Positions (F, N, 3) -> (uint16 (F, N, 3), box min (3,), box max (3,)); the error is at
    most half a step, (max - min) / 65535 / 2 per axis."""
    f = np.asarray(frames, dtype=np.float64)
    lo, hi = f.min(axis=(0, 1)), f.max(axis=(0, 1))
    span = np.where(hi > lo, hi - lo, 1.0)
    q = np.rint((f - lo) / span * 65535.0).clip(0, 65535).astype("<u2")
    hi = np.where(hi > lo, hi, lo + 1.0)
    return q, lo, hi


def _floats(values) -> list:
    return [float(v) for v in np.asarray(values, dtype=np.float64).reshape(-1)]


class ColliderPoses:
    """The rigid pose of a collider on a track at each frame written: y -> R y + T, so that
    ``collider.at(t)`` is the collider as given moved by it (``track.pose(t)``). Stored as
    :meth:`record` says."""

    def __init__(self, collider):
        self.collider = collider
        self.translations: list[np.ndarray] = []
        self.rotations: list[tuple] = []

    def add(self, t: float) -> None:
        r, shift = self.collider.track.pose(float(t))
        self.translations.append(shift)
        self.rotations.append(matrix_quat(r))

    def record(self) -> dict:
        """``translation``: uint16 x y z a frame within [``translationMin``, ``translationMax``]
        (base64, as the frames); ``rotation`` (only if some frame turns): the quaternion x y z w,
        w >= 0, as int16 / 32767 a frame (base64)."""
        q, lo, hi = quantise(np.asarray(self.translations, dtype=np.float64)[:, None, :])
        out = {"translation": _b64(q), "translationMin": _floats(lo), "translationMax": _floats(hi)}
        rot = np.asarray(self.rotations, dtype=np.float64).reshape(-1, 4)
        if rot.size and np.abs(rot[:, :3]).max() > 1e-12:
            rot = rot * np.where(rot[:, 3:] < 0.0, -1.0, 1.0)
            out["rotation"] = _b64(np.rint(rot * 32767.0).clip(-32767, 32767).astype("<i2"))
        return out


class MeshFrames:
    """A deforming mesh collider's vertices at each frame written (``collider.at(t)``), stored as
    :meth:`record` says."""

    def __init__(self, collider):
        self.collider = collider
        self.frames: list[np.ndarray] = []

    def add(self, t: float) -> None:
        self.frames.append(np.asarray(self.collider.at(float(t)).vertices, dtype=np.float32))

    def record(self) -> dict:
        """``frames``: uint16 x y z per vertex, frames one after another, within [``min``, ``max``] (base64)."""
        q, lo, hi = quantise(np.stack(self.frames))
        return {"frames": _b64(q), "min": _floats(lo), "max": _floats(hi)}


def collider_records(colliders, lo, hi, poses: dict | None = None) -> list[dict]:
    """The player's JSON record of each collider (as given, i.e. at its track's time-0 offset):
    ``kind`` (plane, sphere, capsule, box, mesh), ``thickness``, ``friction`` and

    * plane: ``point``, ``normal``, ``halfSize`` (the patch drawn: :data:`PLANE_PATCH` x the
      diagonal of the animation's box ``lo``..``hi`` across);
    * sphere: ``center``, ``radius``; capsule: ``a``, ``b``, ``radius``;
    * box: ``center``, ``halfExtents``, ``rotation`` (quaternion x y z w);
    * mesh: ``vertexCount``, ``triangleCount``, ``vertices`` (uint16 x y z within
      [``verticesMin``, ``verticesMax``], base64) and ``triangles`` (uint32, base64);

    and, for a collider with an entry in ``poses`` (index -> :class:`ColliderPoses`), ``motion``:
    its pose at every frame (:meth:`ColliderPoses.record`); a deforming mesh's (a :class:`MeshFrames`)
    ``deform``: its vertices at every frame (:meth:`MeshFrames.record`)."""
    poses = poses or {}
    diagonal = float(np.linalg.norm(np.asarray(hi, dtype=np.float64) - np.asarray(lo, dtype=np.float64)))
    records = []
    for k, c in enumerate(colliders):
        rec = {"kind": c.kind}
        if c.kind == "plane":
            rec.update(
                point=_floats(c.point),
                normal=_floats(c.normal),
                halfSize=0.5 * max(PLANE_PATCH * diagonal, PLANE_PATCH_MIN),
            )
        elif c.kind == "sphere":
            rec.update(center=_floats(c.center), radius=float(c.radius))
        elif c.kind == "capsule":
            rec.update(a=_floats(c.a), b=_floats(c.b), radius=float(c.radius))
        elif c.kind == "box":
            rec.update(center=_floats(c.center), halfExtents=_floats(c.half_extents), rotation=_floats(c.rotation))
        elif c.kind == "mesh":
            q, vlo, vhi = quantise(np.asarray(c.vertices, dtype=np.float64)[None])
            tris = np.asarray(c.triangles).reshape(-1, 3)
            rec.update(
                vertexCount=int(q.shape[1]),
                triangleCount=int(len(tris)),
                vertices=_b64(q),
                verticesMin=_floats(vlo),
                verticesMax=_floats(vhi),
                triangles=_b64(tris.astype("<u4")),
            )
        else:
            raise WarpclothError(f"the HTML player cannot draw a collider of kind {c.kind!r}")
        rec.update(thickness=float(c.thickness), friction=float(c.friction))
        if k in poses:
            rec["deform" if isinstance(poses[k], MeshFrames) else "motion"] = poses[k].record()
        records.append(rec)
    return records


class HtmlWriter:
    """Collects a run's frames and writes the player page on :meth:`close` (atomically).

    Args:
        path: output file (.html or .htm), checked here.
        model: the :class:`~warpcloth.sim.model.ClothModel` (triangles, springs, pins).
        fps: the frame rate of the run (the page plays at the frames' simulated times).
        title: a line shown in the page's corner and its title.
        info: extra JSON-able facts stored in the page (provenance).
        colliders: the run's colliders (``Control.colliders``), drawn with the cloth; a moving
            one's pose is stored at every frame's simulated time (see :func:`collider_records`).
    """

    def __init__(
        self,
        path: str,
        model,
        fps: float = 60.0,
        title: str = "warpcloth",
        info: dict | None = None,
        expected_frames: int | None = None,
        colliders=(),
    ):
        self.path = check_html_path(path)
        check_frame_memory(model, expected_frames, "the HTML player")
        self.fps = float(fps)
        self.title = str(title)
        self.info = dict(info or {})
        self.tris = np.asarray(model.host.tris, dtype="<u4").reshape(-1, 3)
        self.pairs, self.rest = spring_arrays(model)
        self.pins = [int(i) for i in np.asarray(model.pinned).reshape(-1)]
        self.vertex_count = int(model.particle_count)
        #: a model of several cloths: each one's name and particle and triangle ranges (the page colours each)
        self.pieces = [
            {"name": c.name, "first": c.particle_offset, "count": c.particle_count}
            | {"firstTri": c.tri_offset, "triCount": c.tri_count}
            for c in model.pieces
        ]
        self.frames: list[np.ndarray] = []
        self.times: list[float] = []
        self.max_strain = 0.0
        self.colliders = tuple(colliders or ())
        for c in self.colliders:
            if getattr(c, "kind", None) not in ("plane", "sphere", "capsule", "box", "mesh"):
                raise WarpclothError(
                    f"the HTML player's colliders must be warpcloth.sim.colliders objects, got {c!r:.80}"
                )
        self.poses = {
            k: MeshFrames(c) if c.kind == "mesh" and c.deforming else ColliderPoses(c)
            for k, c in enumerate(self.colliders)
            if getattr(c, "track", None) is not None
        }
        self._closed = False

    def write_frame(self, points: np.ndarray, sim_time: float | None = None) -> None:
        p = np.array(points, dtype=np.float32).reshape(-1, 3)
        if (len(self.frames) + 1) * p.nbytes > MAX_BUFFER_BYTES:
            raise WarpclothError(
                f"the HTML player would hold more than {MAX_BUFFER_BYTES >> 20} MiB of frames; "
                "use fewer frames (--fps, --duration) or a smaller cloth"
            )
        t = float(sim_time) if sim_time is not None else (self.times[-1] + 1.0 / self.fps if self.times else 0.0)
        if not np.all(np.isfinite(p)):
            return  # an unstable frame has nothing to show
        self.frames.append(p)
        self.times.append(t)
        for poses in self.poses.values():
            poses.add(t)
        strain = vertex_strain(p, self.pairs, self.rest)
        self.max_strain = max(self.max_strain, float(strain.max(initial=0.0)))

    def document(self) -> str:
        """The page as text."""
        if not self.frames:
            raise WarpclothError("the HTML player has no frames to show")
        q, lo, hi = quantise(np.stack(self.frames))
        data = {
            "format": "warpcloth-player/1",
            "title": self.title,
            "fps": self.fps,
            "vertexCount": self.vertex_count,
            "frameCount": len(self.frames),
            "times": [round(t, 9) for t in self.times],
            "bboxMin": [float(v) for v in lo],
            "bboxMax": [float(v) for v in hi],
            "quantisation": "uint16 in the bounding box, little-endian, x y z per vertex, frames one after another",
            "frames": _b64(q),
            "tris": _b64(self.tris),
            "springs": _b64(self.pairs.astype("<u4")),
            "rest": _b64(self.rest.astype("<f4")),
            "pins": self.pins,
            **({"pieces": self.pieces} if self.pieces else {}),
            "colliders": collider_records(self.colliders, lo, hi, self.poses),
            "view": default_view(self.frames, self.tris),
            # fixed (it was the run's own 99th percentile, so one colour meant another strain on each page)
            "strainScale": DEFAULT_STRAIN_SCALE,
            "maxStrain": self.max_strain,
            "info": self.info,
        }
        text = json.dumps(data, separators=(",", ":")).replace("</", "<\\/")  # never closes the script element
        with open(TEMPLATE, encoding="utf-8") as fh:
            page = fh.read()
        return page.replace("__TITLE__", html.escape(self.title)).replace("__DATA__", text)

    def close(self) -> str:
        if self._closed:
            return self.path
        text = self.document()
        self._closed = True
        self.frames = []
        return write_atomic(self.path, text, "HTML player")

    def abort(self) -> None:
        self.frames = []
        self._closed = True


def default_view(frames, tris) -> dict:
    """The camera's start (``yaw``, ``pitch`` [rad] of the eye about the cloth's centre, Y up):
    from the side the cloth faces over the run (its area-weighted normal, averaged over up to 16
    frames, each turned to agree with the first frame's), turned 0.4 rad for depth (a hanging
    flag seen face-on, not edge-on); a horizontal cloth from above at 0.6 rad. ``frames``: one
    (N, 3) array or a list of them."""
    frames = [frames] if isinstance(frames, np.ndarray) and frames.ndim == 2 else list(frames)
    t = np.asarray(tris, dtype=np.int64).reshape(-1, 3)
    total, first = np.zeros(3), None
    for frame in frames[:: max(1, len(frames) // 16)]:
        p = np.asarray(frame, dtype=np.float64).reshape(-1, 3)
        n = np.cross(p[t[:, 1]] - p[t[:, 0]], p[t[:, 2]] - p[t[:, 0]]).sum(axis=0) if t.size else np.zeros(3)
        first = n if first is None else first
        total += n if n @ first >= 0 else -n
    length = float(np.linalg.norm(total))
    if length == 0.0 or abs(total[1]) > 0.9 * length:  # no net normal, or a horizontal cloth
        return {"yaw": 0.55, "pitch": 0.6}
    return {"yaw": round(float(np.arctan2(total[0], total[2])) + 0.4, 4), "pitch": 0.25}


def read_player_data(path: str) -> dict:
    """The JSON data of a player page written by :class:`HtmlWriter`, with the frames decoded
    to float32 (F, N, 3) under ``"positions"`` (for tests and tools); a mesh collider's record
    gains ``"vertexPositions"`` (V, 3) and ``"triangleIndices"`` (T, 3) (a deforming one's ``"deform"``
    ``"vertexFrames"`` (F, V, 3)), a moving collider's
    ``"motion"`` gains ``"translations"`` (F, 3) and ``"rotations"`` (F, 4; x y z w, normalised;
    the identity when it only translates), decoded."""
    with open(path, encoding="utf-8") as fh:
        page = fh.read()
    start_tag = '<script id="warpcloth-data" type="application/json">'
    a = page.find(start_tag)
    b = page.find("</script>", a)
    if a < 0 or b < 0:
        raise WarpclothError(f"{path} is not a warpcloth player page")
    data = json.loads(page[a + len(start_tag) : b])
    q = np.frombuffer(base64.b64decode(data["frames"]), dtype="<u2").reshape(data["frameCount"], data["vertexCount"], 3)
    lo, hi = np.array(data["bboxMin"]), np.array(data["bboxMax"])
    data["positions"] = (lo + q * ((hi - lo) / 65535.0)).astype(np.float32)
    for c in data["colliders"]:
        if c["kind"] == "mesh":
            v = np.frombuffer(base64.b64decode(c["vertices"]), dtype="<u2").reshape(c["vertexCount"], 3)
            vlo, vhi = np.array(c["verticesMin"]), np.array(c["verticesMax"])
            c["vertexPositions"] = vlo + v * ((vhi - vlo) / 65535.0)
            c["triangleIndices"] = np.frombuffer(base64.b64decode(c["triangles"]), dtype="<u4").reshape(
                c["triangleCount"], 3
            )
        d = c.get("deform")
        if d:
            v = np.frombuffer(base64.b64decode(d["frames"]), dtype="<u2").reshape(-1, c["vertexCount"], 3)
            d["vertexFrames"] = np.array(d["min"]) + v * ((np.array(d["max"]) - np.array(d["min"])) / 65535.0)
        m = c.get("motion")
        if m:
            t = np.frombuffer(base64.b64decode(m["translation"]), dtype="<u2").reshape(-1, 3)
            tlo, thi = np.array(m["translationMin"]), np.array(m["translationMax"])
            m["translations"] = tlo + t * ((thi - tlo) / 65535.0)
            if "rotation" in m:
                r = np.frombuffer(base64.b64decode(m["rotation"]), dtype="<i2").reshape(-1, 4) / 32767.0
                m["rotations"] = r / np.linalg.norm(r, axis=1, keepdims=True)
            else:
                m["rotations"] = np.tile([0.0, 0.0, 0.0, 1.0], (len(t), 1))
    return data
