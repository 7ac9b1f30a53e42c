"""Reading triangle meshes: Wavefront OBJ (a small reader here) and USD (``UsdGeom.Mesh``).

OBJ is a 100-line format, so warpcloth reads it itself rather than adding a dependency: ``v``,
``vt``, ``f`` (polygons fan-triangulated; ``v``, ``v/vt``, ``v//vn``, ``v/vt/vn`` corners;
negative indices count back from the last vertex read), ``g`` and ``o`` (the vertices of the
faces that follow belong to that vertex group). Other statements (``vn``, ``s``, ``usemtl``,
``mtllib``, ``l``, ...) are ignored. USD: a ``UsdGeom.Mesh`` by prim path (default: the first
mesh on the stage), its points in world space (the prim's local-to-world transform applied; points
with time samples only, an animated mesh as a DCC exports it, at the first sample),
``faceVertexCounts`` fan-triangulated, ``primvars:st`` kept (vertex or faceVarying), and each
``UsdGeom.Subset`` of faces or points a vertex group named after the subset prim.

Every file read is checked before it is opened (:func:`~warpcloth.io.files.check_input_file`: a
regular file of at most :data:`MAX_MESH_FILE_BYTES`, not a FIFO or a file of /proc, /sys, /dev),
and so is every layer a USD file names (sublayers, references, payloads, value clips and their
manifests, :func:`open_usd_stage`), so no read blocks. The memory a reader needs is estimated
from the file's size and refused up front when the machine lacks it, as a grid's is.
"""

from __future__ import annotations

import io
import os
import re
import sys

import numpy as np

from warpcloth.errors import WarpclothError, require
from warpcloth.io.files import AtomicFolder, check_input_file, check_output_folder, read_input, write_atomic
from warpcloth.sim.colliders import MeshCollider, MeshTrack
from warpcloth.sim.device import require_memory
from warpcloth.sim.mesh import TriangleMesh, check_mesh, drop_loose_vertices

MESH_FORMATS = {".obj": "OBJ", ".usd": "USD", ".usda": "USD", ".usdc": "USD", ".usdz": "USD"}
#: The largest mesh file (and USD layer) read [bytes].
MAX_MESH_FILE_BYTES = 2**31
#: Layers one USD mesh file may name, all told (sublayers, references, payloads, clips).
MAX_USD_LAYERS = 1000
#: Host memory a reader needs per byte of the file, at most (measured: 13 for OBJ; Python lists
#: of floats and the per-face index arrays), so a file too large for the machine is refused
#: before it is read.
READ_BYTES_PER_FILE_BYTE = 16


def load_mesh(path: str, prim: str | None = None) -> TriangleMesh:
    """Read a triangle mesh from an OBJ or USD file (checked with :func:`~warpcloth.sim.mesh.check_mesh`).
    Vertices in no face are dropped with a one-line note on stderr (:attr:`TriangleMesh.loose
    <warpcloth.sim.mesh.TriangleMesh.loose>`; :meth:`~warpcloth.sim.mesh.TriangleMesh.file_indices` maps
    the file's vertex numbers to the mesh's)."""
    try:
        path = os.fspath(path)
    except TypeError:
        raise WarpclothError(f"mesh file must be a file name, got {path!r:.80}") from None
    if not isinstance(path, str) or not path:
        raise WarpclothError(f"mesh file must be a file name, got {path!r:.80}")
    ext = os.path.splitext(path)[1].lower()
    if ext not in MESH_FORMATS:
        raise WarpclothError(
            f"mesh file {path!r} has an unsupported format {ext or '(no extension)'!r}: use {', '.join(MESH_FORMATS)}"
        )
    check_input_file(path, "mesh file", MAX_MESH_FILE_BYTES)
    if prim is not None and not isinstance(prim, str):
        raise WarpclothError(f"prim must be a prim path such as '/World/Cloth', got {prim!r:.80}")
    if prim is not None and MESH_FORMATS[ext] != "USD":
        raise WarpclothError(f"a prim path ({prim!r}) applies to USD files only, not {path!r}")
    size = os.stat(path).st_size
    require_memory(f"reading mesh file {path!r} ({size:,} bytes)", READ_BYTES_PER_FILE_BYTE * size, "cpu")
    mesh = drop_loose_vertices(read_obj(path) if ext == ".obj" else read_usd(path, prim))
    check_mesh(mesh.vertices, mesh.triangles, what=f"mesh {path}")
    if mesh.loose.size:  # faces deleted in a DCC leave their vertices: dropped, said in one line
        first = 1 if ext == ".obj" else 0  # numbered as the file numbers them
        shown = ", ".join(str(int(k) + first) for k in mesh.loose[:5]) + (", ..." if mesh.loose.size > 5 else "")
        count = f"{mesh.loose.size} vertices" if mesh.loose.size > 1 else "1 vertex"
        print(
            f"warpcloth: note: mesh {path}: {count} in no face dropped ({shown}, numbered as in the file); "
            f"warpcloth and its outputs use the other {mesh.vertices.shape[0]}",
            file=sys.stderr,
        )
    return mesh


def load_mesh_collider(path: str, prim: str | None = None, **settings) -> MeshCollider:
    """The mesh of an OBJ or USD file (:func:`load_mesh`) as a :class:`~warpcloth.sim.colliders.MeshCollider`
    with ``settings`` (thickness, friction, reach, track). A USD mesh whose points are time-sampled
    (a skinned or baked body) deforms: its track is a :class:`~warpcloth.sim.colliders.MeshTrack`
    of those samples (:func:`read_usd_points_samples`), unless ``settings`` give a track."""
    path = os.path.expanduser(os.fspath(path))
    mesh = load_mesh(path, prim)
    if "track" not in settings and MESH_FORMATS.get(os.path.splitext(path)[1].lower()) == "USD":
        samples = read_usd_points_samples(path, prim)
        if samples is not None:
            times, points = samples
            keep = np.setdiff1d(np.arange(points.shape[1]), mesh.loose)  # as load_mesh dropped the loose ones
            settings = {**settings, "track": MeshTrack.keyframes(times, points[:, keep])}
    return MeshCollider(vertices=mesh.vertices, triangles=mesh.triangles, source=str(path), **settings)


def read_usd_points_samples(path: str, prim: str | None = None):
    """(times [s] (K,), world points (K, V, 3) [m]) of a USD mesh's time-sampled points (the prim
    :func:`load_mesh` reads: ``prim``, or the first ``UsdGeom.Mesh``), each sample in its prim's
    world transform at that time and times from the stage's ``timeCodesPerSecond``; None where the
    points hold fewer than two samples. The file and every layer it names are checked before they
    are opened (:func:`open_usd_stage`); a sample of another vertex count is an error."""
    from pxr import Usd, UsdGeom  # noqa: PLC0415 (usd-core loads only where USD is read or written)

    stage, layers = open_usd_stage(path)
    try:
        if prim is None:
            p = next((m for m in stage.Traverse() if m.IsA(UsdGeom.Mesh)), None)
        else:
            p = stage.GetPrimAtPath(prim)
        if p is None or not p.IsValid() or not p.IsA(UsdGeom.Mesh):
            return None
        attr = UsdGeom.Mesh(p).GetPointsAttr()
        codes = attr.GetTimeSamples()
        if len(codes) < 2:
            return None
        per_second = stage.GetTimeCodesPerSecond() or 24.0
        frames = []
        for code in codes:
            local = np.asarray(attr.Get(Usd.TimeCode(code)), dtype=np.float64).reshape(-1, 3)
            xf = np.asarray(UsdGeom.Xformable(p).ComputeLocalToWorldTransform(Usd.TimeCode(code)), dtype=np.float64)
            if frames and local.shape != frames[0].shape:
                raise WarpclothError(
                    f"USD mesh {p.GetPath()} in {path!r}: its points at time code {code:g} are {len(local)}, "
                    f"not {len(frames[0])}: a deforming collider keeps its vertices"
                )
            frames.append(local @ xf[:3, :3] + xf[3, :3])
        return np.asarray(codes, dtype=np.float64) / float(per_second), np.stack(frames)
    finally:
        del layers


def _fan(count: int) -> np.ndarray:
    """Corner indices (k, 3) of a fan over a polygon of ``count`` corners: (0, i, i + 1)."""
    i = np.arange(1, count - 1)
    return np.stack([np.zeros_like(i), i, i + 1], axis=1)


def read_obj(path: str) -> TriangleMesh:
    """Read an OBJ file (see the module docstring)."""
    verts, tex, tris, tri_uv = [], [], [], []
    groups: dict[str, set] = {}
    current: list[str] = []
    has_uv = True
    text = read_input(path, "mesh file", MAX_MESH_FILE_BYTES).decode("utf-8", errors="replace")
    lines = io.StringIO(text, newline=None).readlines()  # as open() in text mode splits them
    del text
    for lineno, raw in enumerate(lines, 1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        parts = line.split()
        tag, args = parts[0], parts[1:]
        where = f"{path}:{lineno}"
        if tag == "v":
            try:
                verts.append([float(a) for a in args[:3]])
            except ValueError:
                raise WarpclothError(f"{where}: vertex coordinates must be numbers, got {' '.join(args)!r}") from None
            require(len(args) >= 3, f"{where}: a vertex needs x y z, got {' '.join(args)!r}")
            require(
                all(abs(x) <= sys.float_info.max for x in verts[-1]),
                f"{where}: vertex coordinates must be finite, got {' '.join(args)!r}",
            )
        elif tag == "vt":
            try:
                uv = [float(a) for a in args[:2]]
            except ValueError:
                raise WarpclothError(f"{where}: texture coordinates must be numbers, got {' '.join(args)!r}") from None
            require(
                all(abs(x) <= sys.float_info.max for x in uv),
                f"{where}: texture coordinates must be finite, got {' '.join(args)!r}",
            )
            tex.append(uv + [0.0] * (2 - len(uv)))
        elif tag in ("g", "o"):
            current = args or ["default"]
        elif tag == "f":
            require(len(args) >= 3, f"{where}: a face needs at least 3 corners, got {len(args)}")
            vi, ti = [], []
            for corner in args:
                fields = corner.split("/")
                vi.append(_obj_index(fields[0], len(verts), where, "vertex"))
                if len(fields) > 1 and fields[1]:
                    ti.append(_obj_index(fields[1], len(tex), where, "texture coordinate"))
            if len(ti) != len(vi):
                has_uv = False
            fan = _fan(len(vi))
            vi = np.asarray(vi)
            tris.append(vi[fan])
            if has_uv:
                tri_uv.append(np.asarray(ti)[fan])
            for name in current:
                groups.setdefault(name, set()).update(vi.tolist())
    require(len(verts) > 0, f"mesh file {path!r} is empty: no vertices ('v' lines)")
    require(len(tris) > 0, f"mesh file {path!r} is empty: no faces ('f' lines)")
    triangles = np.concatenate(tris).astype(np.int64)
    uv = None
    if has_uv and tri_uv and tex:
        uv = np.asarray(tex, dtype=np.float32)[np.concatenate(tri_uv)]
    return TriangleMesh(
        vertices=np.asarray(verts, dtype=np.float64),
        triangles=triangles,
        uv=uv,
        groups={k: np.asarray(sorted(g), dtype=np.int64) for k, g in groups.items()},
        source=path,
    )


def _obj_index(text: str, count: int, where: str, what: str) -> int:
    """A 0-based index from an OBJ 1-based index (negative: relative to the last one read)."""
    try:
        k = int(text)
    except ValueError:
        raise WarpclothError(f"{where}: {what} index must be an integer, got {text!r}") from None
    if k > 0 and k <= count:
        return k - 1
    if k < 0 and -k <= count:
        return count + k
    raise WarpclothError(
        f"{where}: {what} index {k} is out of range: {count} read so far (1..{count}, or -1..-{count})"
    )


def read_usd(path: str, prim: str | None = None) -> TriangleMesh:
    """Read a ``UsdGeom.Mesh`` (see the module docstring)."""
    try:
        import pxr  # noqa: F401, PLC0415  (usd-core present?)
    except ImportError:  # pragma: no cover - usd-core is a dependency
        raise WarpclothError("reading USD meshes needs usd-core (pip install usd-core)") from None
    stage, layers = open_usd_stage(path)
    try:
        return _read_usd_mesh(stage, path, prim)
    finally:
        del stage, layers


#: pxr's error text starts with where in its C++ sources it was raised: ``Error in 'Sdf...' at line
#: 323 in file .../usdaFileFormat.cpp : 'the message'``; the user needs only the message.
_PXR_WHERE = re.compile(r"^Error in '.*?' at line \d+ in file \S+ : '(.*?)'?$")


def _usd_error(exc: BaseException) -> str:
    """The first line of pxr's error text (which can run to many lines) without the C++ source
    location it starts with, at most 200 characters."""
    first = next((ln.strip() for ln in str(exc).splitlines() if ln.strip()), type(exc).__name__)
    m = _PXR_WHERE.match(first)
    return (m.group(1) if m else first)[:200]


def _clip_assets(layer) -> list:
    """(asset path, what) of the value clips and clip manifests a layer's prims name."""
    from pxr import Sdf  # noqa: PLC0415 (usd-core loads only where USD is read or written)

    out = []

    def clip_set(info: dict) -> None:
        for key in ("assetPaths", "clipAssetPaths"):
            for a in info.get(key) or ():
                out.append((a.path, "value clip"))
        for key in ("manifestAssetPath", "clipManifestAssetPath"):
            if info.get(key) is not None and info[key].path:
                out.append((info[key].path, "value-clip manifest"))
        if info.get("templateAssetPath") or info.get("clipTemplateAssetPath"):
            out.append((None, "template value clips"))

    def visit(path) -> None:
        if not (path.IsPrimPath() or path.IsPrimVariantSelectionPath()):
            return
        spec = layer.GetPrimAtPath(path)
        if spec is None:
            return
        if spec.HasInfo("clips"):
            for info in dict(spec.GetInfo("clips")).values():
                clip_set(dict(info))
        old = {
            key: spec.GetInfo(key)
            for key in ("clipAssetPaths", "clipManifestAssetPath", "clipTemplateAssetPath")
            if spec.HasInfo(key)
        }
        if old:
            clip_set(old)

    layer.Traverse(Sdf.Path.absoluteRootPath, visit)
    return out


def open_usd_stage(path: str, max_bytes: int = MAX_MESH_FILE_BYTES, max_layers: int = MAX_USD_LAYERS):
    """``(stage, layers)``: the USD stage of ``path`` composed from layers that were each checked
    before they were opened: the file itself and every sublayer, reference, payload, value clip
    and clip manifest it names, transitively (:func:`~warpcloth.io.files.check_input_file`: a
    regular file, not a FIFO or a file of /proc, /sys, /dev, at most ``max_bytes``; a missing
    one, one USD cannot read, and a sublayer that is the layer itself or one it is a sublayer of
    (a cycle) are errors, where USD would only warn and compose without it). ``layers`` holds the
    opened layers: keep it while the stage is used (the stage then finds them open, and opens no
    file itself). At most ``max_layers`` layers in all.
    """
    from pxr import Ar, Sdf, Usd  # noqa: PLC0415 (usd-core loads only where USD is read or written)

    resolver = Ar.GetResolver()
    top = os.path.abspath(path)
    check_input_file(path, "USD file", max_bytes)
    layers, seen = [], set()
    todo = [(top, None, "the file", ())]  # (asset path, the layer naming it, what it is, sublayer chain)
    while todo:
        asset, anchor, what, chain = todo.pop()
        name = top if anchor is None else f"{asset!r} ({what} in {os.path.basename(anchor.identifier)})"
        if asset is None:
            raise WarpclothError(
                f"USD file {path!r} uses {what}, which warpcloth does not read (name each clip in assetPaths)"
            )
        identifier = (
            asset if anchor is None else resolver.CreateIdentifier(asset, Ar.ResolvedPath(str(anchor.resolvedPath)))
        )
        outer = Ar.SplitPackageRelativePathOuter(identifier)[0] if Ar.IsPackageRelativePath(identifier) else identifier
        resolved = str(resolver.Resolve(outer)) if anchor is not None else outer
        if not resolved:
            raise WarpclothError(f"USD file {path!r} names {name}, which does not exist")
        real = os.path.realpath(resolved)
        if real in chain:
            whose = "the layer itself" if real == chain[-1] else "a layer it is a sublayer of"
            raise WarpclothError(f"USD file {path!r} names {name}, which is {whose} (a cycle of sublayers)")
        if identifier in seen:
            continue
        seen.add(identifier)
        if len(seen) > max_layers:
            raise WarpclothError(f"USD file {path!r} names more than {max_layers} layers")
        try:
            what_file = "layer" if anchor is not None else "USD file"
            check_input_file(resolved if anchor is not None else path, what_file, max_bytes)
        except WarpclothError as exc:
            raise WarpclothError(f"USD file {path!r} names {name}: {exc}" if anchor is not None else str(exc)) from None
        try:
            layer = Sdf.Layer.FindOrOpen(identifier)
            error = None if layer is not None else "not a USD layer"
        except Exception as exc:
            layer, error = None, _usd_error(exc)
        if layer is None:
            where = f"USD file {path!r}" if anchor is None else f"USD file {path!r} names {name}, which"
            raise WarpclothError(f"{where} cannot be read as USD: {error}")
        layers.append(layer)
        subs = set(layer.subLayerPaths)
        for a in layer.GetCompositionAssetDependencies():
            if a in subs:  # a sublayer's layer stack is this one's: a cycle is refused
                todo.append((a, layer, "sublayer", (*chain, real)))
            else:
                todo.append((a, layer, "reference or payload", ()))
        for a, kind in _clip_assets(layer):
            todo.append((a, layer, kind, ()))
    try:
        stage = Usd.Stage.Open(layers[0])
    except Exception as exc:
        raise WarpclothError(f"cannot open USD file {path!r}: {_usd_error(exc)}") from None
    if stage is None:
        raise WarpclothError(f"cannot open USD file {path!r}")
    return stage, layers


def _read_usd_mesh(stage, path: str, prim: str | None) -> TriangleMesh:
    from pxr import Usd, UsdGeom  # noqa: PLC0415 (usd-core loads only where USD is read or written)

    if prim is None:
        meshes = [p for p in stage.Traverse() if p.IsA(UsdGeom.Mesh)]
        require(len(meshes) > 0, f"USD file {path!r} has no UsdGeom.Mesh")
        p = meshes[0]
    else:
        p = stage.GetPrimAtPath(prim) if prim.startswith("/") else None
        if p is None or not p.IsValid():
            have = ", ".join(str(m.GetPath()) for m in stage.Traverse() if m.IsA(UsdGeom.Mesh)) or "none"
            raise WarpclothError(f"USD file {path!r} has no prim {prim!r} (its meshes: {have})")
        require(
            p.IsA(UsdGeom.Mesh),
            f"prim {prim!r} in {path!r} is a {p.GetTypeName() or 'typeless prim'}, not a UsdGeom.Mesh",
        )
    mesh = UsdGeom.Mesh(p)
    time = Usd.TimeCode.Default()
    if mesh.GetPointsAttr().Get(time) is None and mesh.GetPointsAttr().GetNumTimeSamples():
        # points only time-sampled (an animated mesh as a DCC exports it): the mesh at its first sample
        time = Usd.TimeCode.EarliestTime()
    points = mesh.GetPointsAttr().Get(time)
    require(points is not None and len(points) > 0, f"USD mesh {p.GetPath()} in {path!r} is empty: no points")
    local = np.asarray(points, dtype=np.float64)
    xf = np.asarray(
        UsdGeom.Xformable(p).ComputeLocalToWorldTransform(time), dtype=np.float64
    )  # row vectors: p' = [p 1] M
    world = local @ xf[:3, :3] + xf[3, :3]
    counts = np.asarray(mesh.GetFaceVertexCountsAttr().Get(time) or [], dtype=np.int64)
    indices = np.asarray(mesh.GetFaceVertexIndicesAttr().Get(time) or [], dtype=np.int64)
    require(counts.size > 0, f"USD mesh {p.GetPath()} in {path!r} is empty: no faces")
    require(
        int(counts.sum()) == indices.size,
        f"USD mesh {p.GetPath()}: faceVertexCounts sum to {int(counts.sum())} but there are {indices.size} "
        "faceVertexIndices",
    )
    if np.any(counts < 3):
        raise WarpclothError(
            f"USD mesh {p.GetPath()}: face {int(np.flatnonzero(counts < 3)[0])} has fewer than 3 vertices"
        )
    out = np.flatnonzero((indices < 0) | (indices >= local.shape[0]))
    if out.size:  # before they index the points or a vertex primvar
        raise WarpclothError(
            f"USD mesh {p.GetPath()} in {path!r}: faceVertexIndices[{int(out[0])}] = {int(indices[out[0]])} is out of "
            f"range: its points are 0..{local.shape[0] - 1}"
        )
    face_start = np.concatenate([[0], np.cumsum(counts)[:-1]])
    corner_of_tri, face_of_tri = [], []
    for c in np.unique(counts):  # one vectorised fan per polygon size
        faces = np.flatnonzero(counts == c)
        fan = _fan(int(c))
        corner_of_tri.append((face_start[faces][:, None, None] + fan[None, :, :]).reshape(-1, 3))
        face_of_tri.append(np.repeat(faces, fan.shape[0]))
    face_of_tri = np.concatenate(face_of_tri)
    order = np.argsort(face_of_tri, kind="stable")  # triangles in face order
    corners, face_of_tri = np.concatenate(corner_of_tri)[order], face_of_tri[order]
    triangles = indices[corners]
    uv = None
    st = UsdGeom.PrimvarsAPI(p).GetPrimvar("st")
    if st and st.HasValue():
        values = st.ComputeFlattened(time)
        if values is not None and len(values):
            values = np.asarray(values, dtype=np.float32).reshape(-1, 2)
            interp = st.GetInterpolation()
            if interp == UsdGeom.Tokens.faceVarying and values.shape[0] == indices.size:
                uv = values[corners]
            elif interp in (UsdGeom.Tokens.vertex, UsdGeom.Tokens.varying) and values.shape[0] == local.shape[0]:
                uv = values[triangles]
    groups = {}
    for subset in UsdGeom.Subset.GetAllGeomSubsets(UsdGeom.Imageable(p)):
        idx = np.asarray(subset.GetIndicesAttr().Get(time) or [], dtype=np.int64)
        kind = subset.GetElementTypeAttr().Get()
        name = subset.GetPrim().GetName()
        if kind == UsdGeom.Tokens.face:
            bad = idx[(idx < 0) | (idx >= counts.size)]
            if bad.size:
                raise WarpclothError(
                    f"USD subset {subset.GetPath()}: face index {int(bad[0])} out of range 0..{counts.size - 1}"
                )
            groups[name] = np.unique(triangles[np.isin(face_of_tri, idx)].ravel())
        else:
            groups[name] = np.unique(idx)
    return TriangleMesh(vertices=world, triangles=triangles, uv=uv, groups=groups, source=path)


def write_obj(path: str, vertices, triangles, uv=None, groups: dict | None = None) -> None:
    """Write a triangle mesh as OBJ (per-vertex ``vt`` when ``uv`` is (N, 2)); each group gets a
    ``g`` block with the faces whose three vertices are all in it (for example meshes)."""
    v = np.asarray(vertices, dtype=np.float64)
    t = np.asarray(triangles, dtype=np.int64)
    lines = ["# written by warpcloth"]
    lines += [f"v {a:.9g} {b:.9g} {c:.9g}" for a, b, c in v]
    if uv is not None:
        lines += [f"vt {a:.9g} {b:.9g}" for a, b in np.asarray(uv, dtype=np.float64)]
    taken = np.zeros(t.shape[0], dtype=bool)

    def face(row):
        return "f " + " ".join(f"{k + 1}/{k + 1}" if uv is not None else f"{k + 1}" for k in row)

    for name, members in (groups or {}).items():
        inside = np.isin(t, np.asarray(members)).all(axis=1) & ~taken
        taken |= inside
        lines.append(f"g {name}")
        lines += [face(row) for row in t[inside]]
    if not taken.all():
        lines.append("g cloth")
        lines += [face(row) for row in t[~taken]]
    write_atomic(path, "\n".join(lines) + "\n", "OBJ mesh")  # a temporary renamed over path: never through a link


#: File names of an OBJ sequence, frame k: ``frame_0000.obj`` ... (more digits past 9999 frames).
OBJ_FRAME_NAME = "frame_{:04d}.obj"
OBJ_FRAME_NAMES = re.compile(r"^frame_\d{4,}\.obj$")


def check_obj_sequence_path(path: str) -> str:
    """Validate an OBJ-sequence folder before a run (:func:`~warpcloth.io.files.check_output_folder`):
    absent, empty, or an earlier sequence (only ``frame_NNNN.obj`` files), never a link."""
    return check_output_folder(path, "OBJ sequence", OBJ_FRAME_NAMES)


class ObjSequenceWriter:
    """A frame sink writing one OBJ per frame (:func:`write_obj`: the cloth's triangles and its
    mesh groups), ``frame_0000.obj``, ``frame_0001.obj``, ... in the folder ``path``, for tools
    that read mesh sequences rather than USD. The folder is built beside ``path`` and renamed into
    place on :meth:`close` (:class:`~warpcloth.io.files.AtomicFolder`); :meth:`abort` leaves
    ``path`` as it was. A frame with a non-finite position (an unstable run's last) is skipped."""

    def __init__(self, path: str, model):
        self.path = os.fspath(path)
        self.tris = np.asarray(model.host.tris, dtype=np.int64).reshape(-1, 3)
        self.groups = dict(model.host.groups or {})
        self.frames = 0
        self.folder = AtomicFolder(self.path, "OBJ sequence", OBJ_FRAME_NAMES)

    def write_frame(self, points, sim_time: float | None = None) -> None:
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        if not np.all(np.isfinite(p)):
            return
        write_obj(self.folder.file(OBJ_FRAME_NAME.format(self.frames)), p, self.tris, groups=self.groups)
        self.frames += 1

    def close(self) -> str:
        return self.folder.commit()

    def abort(self) -> None:
        self.folder.abort()


__all__ = [
    "MAX_MESH_FILE_BYTES",
    "MESH_FORMATS",
    "OBJ_FRAME_NAME",
    "OBJ_FRAME_NAMES",
    "ObjSequenceWriter",
    "check_obj_sequence_path",
    "load_mesh",
    "load_mesh_collider",
    "open_usd_stage",
    "read_obj",
    "read_usd",
    "read_usd_points_samples",
    "write_obj",
]
