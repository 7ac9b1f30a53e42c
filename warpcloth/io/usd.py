"""USD export of an animated cloth mesh (and the colliders it meets, :class:`ColliderPrims`).

One ``UsdGeomMesh`` ``/World/Cloth``, or for a model of several cloths (:class:`~warpcloth.sim.builder.ClothBuilder`)
one per piece, ``/World/Cloth/<name>`` (topology written once; points and extent time-sampled per frame), pinned
particles marked by a ``pinned`` vertex primvar and a ``UsdGeomPoints`` prim, the stage's
``timeCodesPerSecond`` equal to the frame rate, Y up, metres. The file is written to a temporary
beside the target (:mod:`warpcloth.io.files`) and renamed over it when closed, so a reader never
sees half a file; on any failure the temporary is removed and the target is left as it was.

**Bounded memory.** A USD layer keeps every time sample in memory until it is saved, so a long or
large run writes its frames in chunks of ``clip_frames`` frames (by default as many as fit in
:data:`CLIP_BYTES`, ~64 MiB of samples) to *value clips* under ``<target>.clips/`` with clip
metadata on ``/World``, so any USD reader sees one animated stage; a run shorter than one chunk
stays a single file.

Pipeline extras: the run's provenance in ``customLayerData`` (:mod:`warpcloth.io.provenance`);
``/World/Pins`` only where the cloth has pins (an empty point cloud crashed Blender 5.0's Cycles),
``purpose = "guide"`` (markers, not rendered), written once while they do not move; colliders under ``/World/Colliders`` with ``purpose =
"guide"`` by default (``colliders_purpose="render"`` draws them); ``color="strain"`` writes a vertex
``primvars:displayColor`` per frame from blue (0) to red (``strain_scale``, default 10 %); a
``.usdz`` target is a ``.usdc`` stage packaged with ``UsdUtils.CreateNewUsdzPackage`` (no value
clips: its samples stay in memory until it is written). docs/colliders.md, "USD".
"""

from __future__ import annotations

import errno
import os
import shutil

import numpy as np

from warpcloth.errors import WarpclothError, require_int
from warpcloth.io.files import (
    OutputError,
    check_output_path,
    describe_write_error,
    fsync_dir,
    remove_temporary,
    temp_path,
)
from warpcloth.io.frames import spring_arrays, strain_colors, vertex_strain
from warpcloth.sim.colliders import matrix_quat

USD_EXTENSIONS = (".usd", ".usda", ".usdc", ".usdz")
#: Colourings of ``primvars:displayColor`` (``--usd-color``).
USD_COLORS = ("none", "strain")
#: Strain at the red end of the displayColor ramp by default (10 %).
DEFAULT_STRAIN_SCALE = 0.1
#: ``purpose`` of the collider prims (``--usd-colliders``): "guide" (viewports and tools only) or "render".
COLLIDER_PURPOSES = ("guide", "render")
#: Bytes of time samples a writer keeps in memory before it moves them to a value clip.
CLIP_BYTES = 64 * 2**20
#: Bytes per point per frame in memory (points, pins, extent, colours, and the layer's overhead).
_BYTES_PER_POINT_FRAME = 32


def check_usd_path(path: str) -> str:
    """Validate an output path before a run starts: a USD extension, a name the file system
    takes, a folder where a file can be created, not an immutable file
    (:func:`~warpcloth.io.files.check_output_path`)."""
    return check_output_path(path, "USD", extensions=USD_EXTENSIONS)


def clip_folder_of(path: str) -> tuple[str | None, int]:
    """(the value-clip folder ``PATH.clips`` a closed writer left beside ``path``, its clip count),
    or (None, 0) for a one-file stage."""
    folder = path + ".clips"
    if not os.path.isdir(folder):
        return None, 0
    return folder, sum(1 for name in os.listdir(folder) if name.startswith("clip_") and name.endswith(".usdc"))


def _usd_failure(exc: BaseException, target: str, tmp: str) -> OutputError:
    """One line for a failed USD write (pxr's error text can be thousands of lines)."""
    text = str(exc)
    written = os.path.getsize(tmp) if os.path.exists(tmp) else None
    if "No space left" in text or (isinstance(exc, OSError) and exc.errno == errno.ENOSPC):
        return OutputError(
            describe_write_error(OSError(errno.ENOSPC, "No space left on device"), target, "USD file", written=written)
        )
    if isinstance(exc, OSError):
        return OutputError(describe_write_error(exc, target, "USD file"))
    first = next((line.strip() for line in text.splitlines() if line.strip()), type(exc).__name__)
    return OutputError(f"cannot write the USD file {target}: {first[:200]}; {target} is unchanged")


def _usd_dict(value):
    """A JSON-able value as USD dictionary data: None (no USD value) becomes the string "none",
    lists of mixed types become strings."""
    if isinstance(value, dict):
        return {str(k): _usd_dict(v) for k, v in value.items()}
    if value is None:
        return "none"
    if isinstance(value, bool):
        return value
    if isinstance(value, int):
        return int(value)
    if isinstance(value, float):
        return float(value)
    if isinstance(value, (list, tuple)):
        return [str(v) for v in value]
    return str(value)


def _quat_between(u, v):
    """The unit quaternion (w, x, y, z) turning unit vector u onto unit vector v."""
    u, v = np.asarray(u, dtype=np.float64), np.asarray(v, dtype=np.float64)
    c = float(np.dot(u, v))
    if c < -1.0 + 1e-12:  # opposite: half a turn about any axis perpendicular to u
        axis = np.cross(u, [1.0, 0.0, 0.0] if abs(u[0]) < 0.9 else [0.0, 1.0, 0.0])
        axis /= np.linalg.norm(axis)
        return (0.0, *axis)
    q = np.array([1.0 + c, *np.cross(u, v)])
    return tuple(q / np.linalg.norm(q))


class ColliderPrims:
    """Colliders as USD prims under ``root``, one per collider (``Sphere_0``, ``Box_1``, ...), each
    with ``xformOp:translate`` and ``xformOp:orient`` (and ``xformOp:scale`` for a box):

    * sphere: ``UsdGeom.Sphere`` (radius);
    * capsule: ``UsdGeom.Capsule`` along its local Z (radius, height = |b - a|), oriented a -> b;
    * box: ``UsdGeom.Cube`` of size 2 scaled by the half extents, oriented by its rotation;
    * mesh: ``UsdGeom.Mesh`` of its triangles as given, in world coordinates (identity transform,
      or its track's rigid transform when it moves; a deforming mesh's points and extent get a time
      sample at every frame written);
    * plane: ``UsdGeom.Mesh``, a square quad ``plane_size`` across in its local XZ plane (normal +Y
      turned onto the plane's normal), centred on its point.

    Static colliders hold default values (no time samples); a collider on a track gets a time
    sample of its transform at every frame written. Each prim and the scope carry ``purpose``
    (``"guide"`` by default: collision proxies that renderers skip; ``"render"``: drawn). Thickness and friction go to
    the prim's
    ``customData`` (``warpcloth:thickness``, ``warpcloth:friction``); the prim is the surface itself,
    so a resting cloth floats ``thickness`` above it.
    """

    def __init__(self, stage, root: str, colliders, plane_size: float = 10.0, purpose: str = "guide"):
        from pxr import Gf, UsdGeom, Vt  # noqa: PLC0415 (usd-core loads only where USD is read or written)

        if purpose not in COLLIDER_PURPOSES:
            raise WarpclothError(f"collider purpose must be one of {', '.join(COLLIDER_PURPOSES)}, got {purpose!r}")
        self._Gf, self._Vt = Gf, Vt
        self.items = []
        self.deforming = []  # (collider, its UsdGeom.Mesh) of the meshes on a MeshTrack: points sampled per frame
        colliders = tuple(colliders or ())
        if not colliders:
            return
        token = UsdGeom.Tokens.guide if purpose == "guide" else UsdGeom.Tokens.render
        UsdGeom.Scope.Define(stage, root).CreatePurposeAttr(token)
        for k, c in enumerate(colliders):
            path = f"{root}/{c.kind.capitalize()}_{k}"
            if c.kind == "sphere":
                prim = UsdGeom.Sphere.Define(stage, path)
                prim.CreateRadiusAttr(float(c.radius))
                r = float(c.radius)
                prim.CreateExtentAttr(Vt.Vec3fArray([Gf.Vec3f(-r), Gf.Vec3f(r)]))
            elif c.kind == "capsule":
                prim = UsdGeom.Capsule.Define(stage, path)
                prim.CreateAxisAttr(UsdGeom.Tokens.z)
                prim.CreateRadiusAttr(float(c.radius))
                height = float(np.linalg.norm(np.subtract(c.b, c.a)))
                prim.CreateHeightAttr(height)
                r, h = float(c.radius), 0.5 * height + float(c.radius)
                prim.CreateExtentAttr(Vt.Vec3fArray([Gf.Vec3f(-r, -r, -h), Gf.Vec3f(r, r, h)]))
            elif c.kind == "mesh":
                prim = UsdGeom.Mesh.Define(stage, path)
                v = np.ascontiguousarray(c.vertices, dtype=np.float32)
                prim.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(v))
                prim.CreateFaceVertexCountsAttr(Vt.IntArray([3] * len(c.triangles)))
                prim.CreateFaceVertexIndicesAttr(Vt.IntArray(c.triangles.reshape(-1).tolist()))
                prim.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
                prim.CreateExtentAttr(
                    Vt.Vec3fArray([Gf.Vec3f(*map(float, v.min(axis=0))), Gf.Vec3f(*map(float, v.max(axis=0)))])
                )
                if c.deforming:
                    self.deforming.append((c, prim))
            elif c.kind == "box":
                prim = UsdGeom.Cube.Define(stage, path)
                prim.CreateSizeAttr(2.0)
                prim.CreateExtentAttr(Vt.Vec3fArray([Gf.Vec3f(-1.0), Gf.Vec3f(1.0)]))
            else:
                prim = UsdGeom.Mesh.Define(stage, path)
                h = 0.5 * float(plane_size)
                prim.CreatePointsAttr(
                    Vt.Vec3fArray([Gf.Vec3f(-h, 0, -h), Gf.Vec3f(-h, 0, h), Gf.Vec3f(h, 0, h), Gf.Vec3f(h, 0, -h)])
                )
                prim.CreateFaceVertexCountsAttr(Vt.IntArray([4]))
                prim.CreateFaceVertexIndicesAttr(Vt.IntArray([0, 1, 2, 3]))  # counter-clockwise seen from +Y
                prim.CreateNormalsAttr(Vt.Vec3fArray([Gf.Vec3f(0, 1, 0)] * 4))
                prim.SetNormalsInterpolation(UsdGeom.Tokens.vertex)
                prim.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
                prim.CreateDoubleSidedAttr(True)
                prim.CreateExtentAttr(Vt.Vec3fArray([Gf.Vec3f(-h, 0, -h), Gf.Vec3f(h, 0, h)]))
            prim.CreatePurposeAttr(token)  # as the scope's: a reader that does not inherit purpose sees it too
            p = prim.GetPrim()
            p.SetCustomDataByKey("warpcloth:thickness", float(c.thickness))
            p.SetCustomDataByKey("warpcloth:friction", float(c.friction))
            xf = UsdGeom.Xformable(prim)
            ops = [xf.AddTranslateOp(), xf.AddOrientOp()]
            if c.kind == "box":
                ops.append(xf.AddScaleOp())
                ops[2].Set(Gf.Vec3f(*map(float, c.half_extents)))
            self.items.append((c, ops))
            if c.track is None or (c.kind == "mesh" and c.deforming):  # a deforming mesh's points move, not it
                self._set(c, ops, None)

    def _pose(self, c):
        """(translate, orient (w, x, y, z)) of a static collider."""
        if c.kind == "sphere":
            return c.center, (1.0, 0.0, 0.0, 0.0)
        if c.kind == "capsule":
            a, b = np.asarray(c.a), np.asarray(c.b)
            d = b - a
            length = np.linalg.norm(d)
            return 0.5 * (a + b), _quat_between((0.0, 0.0, 1.0), d / length) if length > 0 else (1.0, 0.0, 0.0, 0.0)
        if c.kind == "box":
            x, y, z, w = c.rotation
            return c.center, (w, x, y, z)
        if c.kind == "mesh":
            return (0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0)
        return c.point, _quat_between((0.0, 1.0, 0.0), c.normal)

    @staticmethod
    def _mesh_pose(c, sim_time: float):
        """(translate, orient (w, x, y, z)) of a mesh on a track at ``sim_time``: its points stay as
        given and the track's transform y -> R y + T moves them."""
        r, shift = c.track.pose(float(sim_time))
        x, y, z, w = matrix_quat(r)
        return shift, (w, x, y, z)

    def _set(self, c, ops, code, pose=None) -> None:
        from pxr import Usd  # noqa: PLC0415 (usd-core loads only where USD is read or written)

        Gf = self._Gf
        t, q = self._pose(c) if pose is None else pose
        time = Usd.TimeCode.Default() if code is None else code
        ops[0].Set(Gf.Vec3d(*map(float, t)), time)
        ops[1].Set(Gf.Quatf(float(q[0]), Gf.Vec3f(*map(float, q[1:]))), time)

    def write(self, sim_time: float, code: float) -> None:
        """A time sample of every moving collider's transform, posed at ``sim_time`` [s]."""
        for c, prim in self.deforming:  # the points and their extent, a time sample each
            v = np.ascontiguousarray(c.at(sim_time).vertices, dtype=np.float32)
            prim.GetPointsAttr().Set(self._Vt.Vec3fArray.FromNumpy(v), code)
            lo, hi = v.min(axis=0), v.max(axis=0)
            prim.GetExtentAttr().Set(
                self._Vt.Vec3fArray([self._Gf.Vec3f(*map(float, lo)), self._Gf.Vec3f(*map(float, hi))]), code
            )
        for c, ops in self.items:
            if c.track is not None and not (c.kind == "mesh" and c.deforming):
                if c.kind == "mesh":
                    self._set(c, ops, code, self._mesh_pose(c, sim_time))
                else:
                    self._set(c.at(sim_time), ops, code)


def usd_frames(path: str, color: str = "none", provenance=None, colliders: str = "guide"):
    """The one way a run's USD writer is made: checks ``path`` now (before any work) and returns
    the factory ``(sim, config) -> UsdWriter`` that a scenario run calls once its simulator is
    built. ``provenance``: None, or a function ``(sim, config) -> dict`` (the layer's record);
    ``colliders``: the collider prims' purpose (:data:`COLLIDER_PURPOSES`)."""
    check_usd_path(path)
    if colliders not in COLLIDER_PURPOSES:
        raise WarpclothError(f"--usd-colliders must be one of {', '.join(COLLIDER_PURPOSES)}, got {colliders!r}")
    return lambda sim, cfg: UsdWriter(
        path,
        sim.model,
        cfg.fps,
        provenance=provenance(sim, cfg) if provenance else None,
        color=color,
        colliders=sim.control.colliders,
        colliders_purpose=colliders,
    )


class ClothPrim:
    """One cloth mesh prim of a :class:`UsdWriter`: the prim, its time-sampled points and extent
    attributes, its strain colours (or None) and its particles' slice of the model's."""

    def __init__(self, mesh, particles: slice):
        self.mesh = mesh
        self.particles = particles
        self.points_attr = mesh.CreatePointsAttr()
        self.extent_attr = mesh.CreateExtentAttr()
        self.color_attr = None

    def write_points(self, points: np.ndarray, code: float | None, Vt, Gf) -> None:
        """Points (n, 3) float32 and their extent at time ``code`` (None: the default value)."""
        lo, hi = points.min(axis=0), points.max(axis=0)
        extent = Vt.Vec3fArray([Gf.Vec3f(*map(float, lo)), Gf.Vec3f(*map(float, hi))])
        if code is None:
            self.points_attr.Set(Vt.Vec3fArray.FromNumpy(points))
            self.extent_attr.Set(extent)
        else:
            self.points_attr.Set(Vt.Vec3fArray.FromNumpy(points), code)
            self.extent_attr.Set(extent, code)


def _cloth_prims(stage, model) -> list[ClothPrim]:
    """The cloth's mesh prims, topology written once: ``/World/Cloth`` for a model of one cloth; for a
    model of pieces (:class:`~warpcloth.sim.builder.ClothBuilder`) an Xform ``/World/Cloth`` with one mesh
    ``/World/Cloth/<piece name>`` per piece, its own triangles, pins and texture coordinates."""
    from pxr import Sdf, UsdGeom, Vt  # noqa: PLC0415 (usd-core loads only where USD is read or written)

    pinned_all = np.zeros(model.particle_count, dtype=np.int32)
    pinned_all[model.pinned] = 1
    uv_all = model.host.uv
    if model.pieces:
        UsdGeom.Xform.Define(stage, "/World/Cloth")
    prims = []
    for piece in model.cloth_pieces:
        path = f"/World/Cloth/{piece.name}" if model.pieces else "/World/Cloth"
        tris = model.host.tris[piece.triangles] - piece.particle_offset
        mesh = UsdGeom.Mesh.Define(stage, path)
        mesh.CreateFaceVertexCountsAttr(Vt.IntArray([3] * len(tris)))
        mesh.CreateFaceVertexIndicesAttr(Vt.IntArray(tris.reshape(-1).tolist()))
        mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
        mesh.CreateDoubleSidedAttr(True)
        cloth = ClothPrim(mesh, piece.particles)
        primvar = UsdGeom.PrimvarsAPI(mesh).CreatePrimvar("pinned", Sdf.ValueTypeNames.IntArray, UsdGeom.Tokens.vertex)
        primvar.Set(Vt.IntArray(pinned_all[piece.particles].tolist()))
        if uv_all is not None:  # texture coordinates per triangle corner (grids, meshes read with UVs)
            uv = np.asarray(uv_all, dtype=np.float32).reshape(-1, 2)[3 * piece.tri_offset : 3 * piece.triangles.stop]
            st = UsdGeom.PrimvarsAPI(mesh).CreatePrimvar(
                "st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.faceVarying
            )
            st.Set(Vt.Vec2fArray.FromNumpy(np.ascontiguousarray(uv)))
        if model.pieces and piece.material is not None:
            mesh.GetPrim().SetCustomDataByKey("warpcloth:material", str(getattr(piece.material, "name", "")))
        prims.append(cloth)
    return prims


class UsdWriter:
    """Writes a cloth model's frames to a USD stage.

    Args:
        path: output file (.usd, .usda, .usdc or .usdz).
        model: the :class:`~warpcloth.sim.model.ClothModel` (topology, pins).
        fps: frames per second; frame k is written at time code k.
        provenance: stored in the layer's ``customLayerData["warpcloth"]`` (None values as "none").
        color: ``"strain"`` for a per-frame vertex ``primvars:displayColor`` of spring strain.
        strain_scale: the strain at the red end of the colour ramp.
        clip_frames: frames kept in memory before they move to a value clip (see the module
            doc); default: as many as fit in :data:`CLIP_BYTES` (a .usdz: all, one package).
        colliders: the run's colliders (``Control.colliders``), written as prims under
            ``/World/Colliders`` (see :class:`ColliderPrims`); moving ones get a time sample per frame.
        colliders_purpose: ``"guide"`` (default: not rendered) or ``"render"``.

    After :meth:`close`, :attr:`clip_folder` names the value-clip folder of a long run (None for
    one file): the stage reads its samples from there, so the two travel together.
    """

    def __init__(
        self,
        path: str,
        model,
        fps: float = 60.0,
        provenance: dict | None = None,
        color: str | None = None,
        strain_scale: float = DEFAULT_STRAIN_SCALE,
        clip_frames: int | None = None,
        colliders=(),
        colliders_purpose: str = "guide",
    ):
        from pxr import Gf, Sdf, Usd, UsdGeom, Vt  # noqa: PLC0415 (usd-core loads only where USD is read or written)

        self._Gf, self._Vt = Gf, Vt
        self.path = check_usd_path(path)
        self.fps = float(fps)
        color = color or "none"
        if color not in USD_COLORS:
            raise WarpclothError(f"USD colour must be one of {', '.join(USD_COLORS)}, got {color!r}")
        self.color = color
        self.strain_scale = float(strain_scale)
        self.usdz = os.path.splitext(self.path)[1].lower() == ".usdz"
        self._tmp = temp_path(self.path, ".usdc" if self.usdz else None)
        self._package = temp_path(self.path) if self.usdz else None
        self._closed = False
        try:
            self.stage = Usd.Stage.CreateNew(self._tmp)
        except Exception as exc:
            remove_temporary(self._tmp)
            self._closed = True
            raise _usd_failure(exc, self.path, self._tmp) from None
        if self.stage is None:  # pragma: no cover - pxr raises before this
            remove_temporary(self._tmp)
            raise WarpclothError(f"cannot create USD stage at {self.path!r}")
        UsdGeom.SetStageUpAxis(self.stage, UsdGeom.Tokens.y)
        UsdGeom.SetStageMetersPerUnit(self.stage, 1.0)
        self.stage.SetTimeCodesPerSecond(self.fps)
        self.stage.SetFramesPerSecond(self.fps)
        if provenance:
            self.stage.GetRootLayer().customLayerData = {"warpcloth": _usd_dict(provenance)}
        root = UsdGeom.Xform.Define(self.stage, "/World")
        self.stage.SetDefaultPrim(root.GetPrim())

        #: the cloth's mesh prims: /World/Cloth, or for a model of pieces (ClothBuilder) /World/Cloth/<name> each
        self.cloth_prims = _cloth_prims(self.stage, model)
        self.mesh = self.cloth_prims[0].mesh  # the first (the only one of a one-cloth model)
        self.points_attr, self.extent_attr = self.cloth_prims[0].points_attr, self.cloth_prims[0].extent_attr
        self._pin_idx = np.asarray(model.pinned, dtype=np.int64)
        self.pins = self.pins_attr = self.pins_extent_attr = None
        if self._pin_idx.size:  # no empty point cloud (Blender 5.0's Cycles crashed rendering one)
            self.pins = UsdGeom.Points.Define(self.stage, "/World/Pins")
            # guide: a marker for viewports and tools, not geometry to render (Cycles drew them as white balls)
            self.pins.CreatePurposeAttr(UsdGeom.Tokens.guide)
            self.pins.CreateWidthsAttr(Vt.FloatArray([0.02] * len(model.pinned)))
            self.pins_attr = self.pins.CreatePointsAttr()
            self.pins_extent_attr = self.pins.CreateExtentAttr()
        self._pins_first: np.ndarray | None = None  # the pins' first positions, written once while they stay
        self._pins_moving = False
        self.color_attr = None
        if self.color == "strain":
            self._springs = spring_arrays(model)
            for cloth in self.cloth_prims:
                pv = UsdGeom.PrimvarsAPI(cloth.mesh).CreatePrimvar(
                    "displayColor", Sdf.ValueTypeNames.Color3fArray, UsdGeom.Tokens.vertex
                )
                cloth.color_attr = pv.GetAttr()
                cloth.mesh.GetPrim().SetCustomDataByKey(
                    "warpcloth:displayColor", f"spring strain, blue 0 to red {self.strain_scale:g}"
                )
            self.color_attr = self.cloth_prims[0].color_attr
        rest = model.host.q
        size = float(np.max(rest.max(axis=0) - rest.min(axis=0))) if len(rest) else 1.0
        self.colliders = ColliderPrims(
            self.stage, "/World/Colliders", colliders, plane_size=max(4.0, 10.0 * size), purpose=colliders_purpose
        )
        self.frames = 0
        self._first_points = None
        self.last_code = -1.0
        if self.usdz:  # one package: no clip files beside it
            clip_frames = 2**62
        elif clip_frames is None:
            clip_frames = max(60, CLIP_BYTES // (_BYTES_PER_POINT_FRAME * max(1, model.particle_count)))
        self.clip_frames = require_int("clip_frames", clip_frames, 1)
        self.frames_in_memory = 0  # frames whose samples are still in the stage's layer
        self._clips: list[tuple[str, float]] = []  # (file name, first time code)
        self._clip_first = 0.0
        self._clip_dir_tmp = self._tmp + ".clips"
        self._clip_dir = self.path + ".clips"
        self.clip_folder: str | None = None

    def write_frame(self, points: np.ndarray, sim_time: float | None = None) -> None:
        """Write one frame of particle positions (N, 3) at time code ``round(sim_time * fps)``
        (the next time code when ``sim_time`` is None), so playback runs at simulated speed even
        when a step is longer than a frame."""
        Vt, Gf = self._Vt, self._Gf
        code = float(round(sim_time * self.fps)) if sim_time is not None else float(self.last_code + 1)
        self._prev_code, self.last_code = self.last_code, code
        p = np.ascontiguousarray(points, dtype=np.float32).reshape(-1, 3)
        if self.frames == 0:
            self._first_points = p.copy()  # the default value of a one-file stage (close)
        for cloth in self.cloth_prims:
            cloth.write_points(np.ascontiguousarray(p[cloth.particles]), code, Vt, Gf)
        if self._pin_idx.size:
            self._write_pins(np.ascontiguousarray(p[self._pin_idx]), code)
        self.colliders.write(code / self.fps if sim_time is None else float(sim_time), code)
        if self.color_attr is not None:
            rgb = strain_colors(vertex_strain(p, *self._springs), self.strain_scale)
            for cloth in self.cloth_prims:
                cloth.color_attr.Set(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(rgb[cloth.particles])), code)
        self.frames += 1
        if self.frames_in_memory == 0:
            self._clip_first = code
        self.frames_in_memory += 1
        if self.frames_in_memory >= self.clip_frames:
            failure = None
            try:
                self._flush_clip()
            except (
                Exception
            ) as exc:  # a full disk while a clip is saved: one line (OutputError, exit 74), not pxr's text
                failure = _usd_failure(exc, self.path, self._tmp)
            if (
                failure is not None
            ):  # raised outside the handler: pxr's exception (and the clip layer its frames hold) is freed
                self.abort()
                raise failure

    def _flush_clip(self) -> None:
        """Move every time sample of the stage's layer into a new value-clip layer on disk."""
        from pxr import Sdf  # noqa: PLC0415 (usd-core loads only where USD is read or written)

        if self.frames_in_memory == 0:
            return
        if self._pins_first is not None and not self._pins_moving:
            # every clip holds the pins: if they move later, the clips (not the default, which
            # would win over them) give their value in the chunks before
            self.pins_attr.Set(self._Vt.Vec3fArray.FromNumpy(self._pins_first), self._clip_first)
            self.pins_extent_attr.Set(self._pin_extent(self._pins_first), self._clip_first)
        layer = self.stage.GetRootLayer()
        sampled = []
        layer.Traverse(
            Sdf.Path.absoluteRootPath,
            lambda path: (
                sampled.append(path) if path.IsPropertyPath() and layer.GetNumTimeSamplesForPath(path) else None
            ),
        )
        os.makedirs(self._clip_dir_tmp, exist_ok=True)
        name = f"clip_{len(self._clips):05d}.usdc"
        clip = Sdf.Layer.CreateNew(os.path.join(self._clip_dir_tmp, name))
        for path in sampled:
            prim = Sdf.CreatePrimInLayer(clip, path.GetPrimPath())
            spec = layer.GetAttributeAtPath(path)
            Sdf.AttributeSpec(prim, path.name, spec.typeName)
            for t in layer.ListTimeSamplesForPath(path):
                clip.SetTimeSample(path, t, layer.QueryTimeSample(path, t))
                layer.EraseTimeSample(path, t)
        if not clip.Save():
            raise OSError(f"USD could not save the value clip {name}")
        del clip
        self._clips.append((name, self._clip_first))
        self.frames_in_memory = 0

    def _finish_clips(self) -> None:
        """Write the last chunk and the clip metadata on /World (when any chunk left memory)."""
        from pxr import Sdf, Usd  # noqa: PLC0415 (usd-core loads only where USD is read or written)

        if not self._clips:
            return  # a short run: one file, as before
        self._flush_clip()
        if self._pins_moving:  # a default is stronger than clips: the clips alone hold the pins
            self.pins_attr.ClearDefault()
            self.pins_extent_attr.ClearDefault()
        folder = os.path.basename(self._clip_dir)
        api = Usd.ClipsAPI(self.stage.GetPrimAtPath("/World"))
        api.SetClipAssetPaths(Sdf.AssetPathArray([f"./{folder}/{name}" for name, _ in self._clips]))
        api.SetClipPrimPath("/World")
        api.SetClipActive([(first, float(k)) for k, (_, first) in enumerate(self._clips)])
        api.SetClipTimes([(0.0, 0.0), (max(1.0, self.last_code), max(1.0, self.last_code))])  # identity
        layers = [Sdf.Layer.FindOrOpen(os.path.join(self._clip_dir_tmp, name)) for name, _ in self._clips]
        manifest = Usd.ClipsAPI.GenerateClipManifestFromLayers(layers, "/World")  # the final folder does not exist yet
        manifest.Export(os.path.join(self._clip_dir_tmp, "manifest.usda"))
        del layers, manifest
        api.SetClipManifestAssetPath(Sdf.AssetPath(f"./{folder}/manifest.usda"))

    def _pin_extent(self, pins: np.ndarray):
        Gf, Vt = self._Gf, self._Vt
        r = 0.01  # half the pins' width
        lo, hi = pins.min(axis=0) - r, pins.max(axis=0) + r
        return Vt.Vec3fArray([Gf.Vec3f(*map(float, lo)), Gf.Vec3f(*map(float, hi))])

    def _write_pins(self, pins: np.ndarray, code: float) -> None:
        """Pins as one default value (no time samples) while they stay where they were; time
        samples from the first frame they move (the first frame's sample added then)."""
        Vt = self._Vt
        if self._pins_first is None:
            self._pins_first, self._pins_first_code = pins.copy(), code
            self.pins_attr.Set(Vt.Vec3fArray.FromNumpy(pins))
            self.pins_extent_attr.Set(self._pin_extent(pins))
            return
        if not self._pins_moving and np.array_equal(pins, self._pins_first):
            return
        if not self._pins_moving:
            self._pins_moving = True
            first = self._pins_first  # held from the first frame to the frame before this one
            for held in sorted({self._pins_first_code, self._prev_code}):
                self.pins_attr.Set(Vt.Vec3fArray.FromNumpy(first), held)
                self.pins_extent_attr.Set(self._pin_extent(first), held)
        self.pins_attr.Set(Vt.Vec3fArray.FromNumpy(pins), code)
        self.pins_extent_attr.Set(self._pin_extent(pins), code)

    def close(self) -> str:
        """Save and move the file into place; returns the path."""
        if self._closed:
            return self.path
        try:
            self._finish_clips()
            if not self._clips and self.frames:  # the first frame as the default too: a reader that asks for no
                first = self._first_points  # time (a mesh input, a DCC's rest pose) gets the cloth, not nothing
                for cloth in self.cloth_prims:
                    cloth.write_points(np.ascontiguousarray(first[cloth.particles]), None, self._Vt, self._Gf)
            self.stage.SetStartTimeCode(0.0)
            self.stage.SetEndTimeCode(max(0.0, self.last_code))
            if not self.stage.GetRootLayer().Save():
                raise OSError(f"USD could not save {self._tmp}")
            del self.stage
            if self._clips:  # the clip folder first, then the stage that names it
                old = None
                if os.path.lexists(self._clip_dir):
                    old = self._tmp + ".old-clips"
                    os.replace(self._clip_dir, old)
                os.replace(self._clip_dir_tmp, self._clip_dir)
                if old is not None:
                    shutil.rmtree(old, ignore_errors=True)
            if self.usdz:
                from pxr import UsdUtils  # noqa: PLC0415 (usd-core loads only where USD is read or written)

                if not UsdUtils.CreateNewUsdzPackage(self._tmp, self._package):
                    raise OSError(f"USD could not package {self._tmp} as .usdz")
                remove_temporary(self._tmp)
                os.replace(self._package, self.path)
            else:
                os.replace(self._tmp, self.path)
            if not self._clips and os.path.isdir(self._clip_dir):  # an older long run's clips
                shutil.rmtree(self._clip_dir, ignore_errors=True)
        except BaseException as exc:
            failure = _usd_failure(exc, self.path, self._tmp) if isinstance(exc, Exception) else None
            self.abort()
            if failure is not None:
                raise failure from None
            raise
        self._closed = True
        self.clip_folder = self._clip_dir if self._clips else None
        fsync_dir(os.path.dirname(os.path.abspath(self.path)))
        return self.path

    def describe(self) -> str:
        """What :meth:`close` wrote, for a run's output line: the file's size and frames, and for
        a long run the clip folder it reads its samples from (copy both; the file alone opens
        with no time samples)."""
        text = f"{self.path} ({os.path.getsize(self.path):,} bytes, {self.frames} frames)"
        if self.clip_folder:
            count = len(self._clips)
            text += (
                f", samples in {self.clip_folder}{os.sep} ({count} clip{'s' * (count != 1)}: "
                f"keep the folder beside the file)"
            )
        return text

    def abort(self) -> None:
        """Drop the temporary file (and USD's own safe-save file) without touching the target."""
        if not self._closed:
            if hasattr(self, "stage"):
                try:
                    del self.stage  # release the layer so a later writer may reuse nothing of it
                except AttributeError:
                    pass
            remove_temporary(self._tmp)
            if self._package:
                remove_temporary(self._package)
        self._closed = True

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb):
        if exc_type is None:
            self.close()
        else:
            self.abort()
