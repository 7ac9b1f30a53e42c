"""Intersection checker in float64 NumPy: does a cloth pass through itself, or a collider's edge
through the cloth? Independent of the simulator's kernels (no Warp), for tests and for frames
written to USD (docs/self-collision.md, "The checker").

* :func:`self_intersections`: the pairs of cloth triangles that intersect, topological
  neighbours (triangles that share a vertex) excluded;
* :func:`collider_edge_crossings`: the (collider edge, cloth triangle) pairs that cross, for box
  colliders (their 12 edges) and triangle-mesh colliders (their unique edges);
* :func:`check_frames` and :func:`check_usd`: both counts at every frame (a USD file as
  :class:`~warpcloth.io.usd.UsdWriter` writes it: ``/World/Cloth`` points, time-sampled, or the
  meshes of a model's pieces under it, checked as one cloth; ``/World/Colliders``, a deforming
  mesh's edges at each frame's points).

The tests are on closed sets: two triangles intersect when they share a point (touching and
coplanar overlap count), a segment crosses a triangle when it has a point in it. A segment's ends'
signed distances to the triangle's plane count as zero within a few float32 ulps of the coordinates,
because a cloth lying on the ground is coplanar only up to float32 rounding; a crossing point is
tested in the triangle, a segment in the plane in 2-D, both along the normal's largest axis
(Moller 1997). Two non-coplanar triangles intersect exactly when an edge of one meets the other,
so the pair test is six segment tests. Broad phase: a uniform grid of cell size the largest box
extent, pairs from sorted cell keys (vectorised), then an exact box test.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field

import numpy as np

from warpcloth.errors import WarpclothError
from warpcloth.io.meshio import open_usd_stage
from warpcloth.sim.colliders import quat_matrix
from warpcloth.sim.mesh import mesh_topology


# -- predicates ---------------------------------------------------------------------------------------
def _orient(a, b, c, d):
    """Signed volume (six times the tetrahedron's) det[b - a, c - a, d - a], row-wise."""
    return np.einsum("ij,ij->i", np.cross(b - a, c - a), d - a)


def _snap(values, tol):
    """Values within ``tol`` of zero are zero: float64 orientations of near-degenerate
    configurations (a coplanar pair a rounding error off its plane) are treated as exact ones."""
    return np.where(np.abs(values) <= tol, 0.0, values)


def _orient2(a, b, c, tol):
    return _snap((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0]), tol)


def _on_segment2(a, b, p):
    """p (collinear with ab) within the box of ab."""
    return (
        (np.minimum(a[:, 0], b[:, 0]) <= p[:, 0])
        & (p[:, 0] <= np.maximum(a[:, 0], b[:, 0]))
        & (np.minimum(a[:, 1], b[:, 1]) <= p[:, 1])
        & (p[:, 1] <= np.maximum(a[:, 1], b[:, 1]))
    )


def _segments_meet2(p, q, a, b, tol):
    """Closed 2-D segments pq and ab share a point."""
    d1, d2 = _orient2(a, b, p, tol), _orient2(a, b, q, tol)
    d3, d4 = _orient2(p, q, a, tol), _orient2(p, q, b, tol)
    proper = (((d1 > 0) & (d2 < 0)) | ((d1 < 0) & (d2 > 0))) & (((d3 > 0) & (d4 < 0)) | ((d3 < 0) & (d4 > 0)))
    touch = ((d1 == 0) & _on_segment2(a, b, p)) | ((d2 == 0) & _on_segment2(a, b, q))
    touch |= ((d3 == 0) & _on_segment2(p, q, a)) | ((d4 == 0) & _on_segment2(p, q, b))
    return proper | touch


def _inside2(a, b, c, p, tol):
    """p in the closed 2-D triangle abc (either winding)."""
    s1, s2, s3 = _orient2(a, b, p, tol), _orient2(b, c, p, tol), _orient2(c, a, p, tol)
    return ((s1 >= 0) & (s2 >= 0) & (s3 >= 0)) | ((s1 <= 0) & (s2 <= 0) & (s3 <= 0))


def _coplanar_segment_meets(p, q, a, b, c, tol):
    """A segment in the plane of triangle abc meets it (tested in 2-D, dropping the normal's
    largest axis)."""
    axis = np.argmax(np.abs(np.cross(b - a, c - a)), axis=1)
    keep = np.array([[1, 2], [0, 2], [0, 1]])[axis]
    rows = np.arange(len(p))[:, None]
    p2, q2, a2, b2, c2 = (m[rows, keep] for m in (p, q, a, b, c))
    hit = _inside2(a2, b2, c2, p2, tol) | _inside2(a2, b2, c2, q2, tol)
    for u, w in ((a2, b2), (b2, c2), (c2, a2)):
        hit |= _segments_meet2(p2, q2, u, w, tol)
    return hit


#: Orientations below this fraction of L^2 (L the configuration's size) count as zero in the
#: 2-D tests of the triangle's plane.
RELATIVE_TOLERANCE = 1e-12
#: A point closer to a triangle's plane than this fraction of the largest coordinate magnitude
#: (a few float32 ulps: 2^-23 = 1.2e-7) is in the plane: float32 positions of a coplanar layout (a
#: cloth lying on the ground) are that far off it.
PLANE_TOLERANCE = 5e-7


def _plane_projection(a, b, c):
    """The two coordinates kept when projecting onto the triangles' planes (dropping the normal's
    largest axis), (K, 2)."""
    axis = np.argmax(np.abs(np.cross(b - a, c - a)), axis=1)
    return np.array([[1, 2], [0, 2], [0, 1]])[axis]


def segments_meet_triangles(p, q, a, b, c) -> np.ndarray:
    """Row-wise: the closed segment pq has a point in the closed triangle abc (float64). An end
    within :data:`PLANE_TOLERANCE` of the triangle's plane is in it, so a segment in the plane up to
    float32 rounding is tested in the plane, and touching counts; a segment that crosses the plane
    meets the triangle where its crossing point is in the triangle (2-D test in the plane).

    Args:
        p, q: segment ends (K, 3); a, b, c: triangle corners (K, 3).
    """
    p, q, a, b, c = (np.asarray(m, dtype=np.float64).reshape(-1, 3) for m in (p, q, a, b, c))
    size = np.max([np.linalg.norm(m - a, axis=1) for m in (b, c, p, q)], axis=0)
    normal = np.cross(b - a, c - a)
    area2 = np.linalg.norm(normal, axis=1)
    degenerate = area2 <= RELATIVE_TOLERANCE * size**2
    scale = np.where(degenerate, 1.0, area2)
    magnitude = np.max(np.abs(np.stack([p, q, a, b, c])), axis=(0, 2))
    eps = PLANE_TOLERANCE * np.maximum(magnitude, size)
    dp = _snap(np.einsum("ij,ij->i", normal, p - a) / scale, eps)  # signed distances to the plane
    dq = _snap(np.einsum("ij,ij->i", normal, q - a) / scale, eps)
    coplanar = (dp == 0) & (dq == 0) & ~degenerate
    crossing = ~(((dp > 0) & (dq > 0)) | ((dp < 0) & (dq < 0))) & ~coplanar & ~degenerate
    hit = np.zeros(len(p), dtype=bool)
    k = np.flatnonzero(crossing)
    if k.size:
        t = np.where(dp[k] == dq[k], 0.0, dp[k] / np.where(dp[k] == dq[k], 1.0, dp[k] - dq[k]))
        x = p[k] + t[:, None] * (q[k] - p[k])
        keep = _plane_projection(a[k], b[k], c[k])
        rows = np.arange(k.size)[:, None]
        hit[k] = _inside2(*(m[rows, keep] for m in (a[k], b[k], c[k], x)), RELATIVE_TOLERANCE * size[k] ** 2)
    k = np.flatnonzero(coplanar)
    if k.size:
        hit[k] = _coplanar_segment_meets(p[k], q[k], a[k], b[k], c[k], RELATIVE_TOLERANCE * size[k] ** 2)
    return hit


def triangles_intersect(t1, t2) -> np.ndarray:
    """Row-wise: closed triangles t1[k] and t2[k] (K, 3, 3) share a point (float64): an edge of one
    meets the other (exact for non-coplanar pairs; coplanar pairs are tested edge by edge in their
    plane, so containment is found by the other triangle's edges)."""
    t1 = np.asarray(t1, dtype=np.float64).reshape(-1, 3, 3)
    t2 = np.asarray(t2, dtype=np.float64).reshape(-1, 3, 3)
    hit = np.zeros(len(t1), dtype=bool)
    for s, o in ((t1, t2), (t2, t1)):
        for i in range(3):
            rest = ~hit
            if not rest.any():
                break
            k = np.flatnonzero(rest)
            hit[k] |= segments_meet_triangles(s[k, i], s[k, (i + 1) % 3], o[k, 0], o[k, 1], o[k, 2])
    return hit


# -- broad phase ----------------------------------------------------------------------------------------
def _grid_pairs(lo_a, hi_a, lo_b, hi_b, same: bool):
    """(i, j) with box a_i overlapping box b_j (i < j when ``same``), from a uniform grid of cell
    size the largest extent: overlapping boxes have centres in adjacent cells."""
    if len(lo_a) == 0 or len(lo_b) == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    cell = max(float(np.max(hi_a - lo_a)), float(np.max(hi_b - lo_b)), 1e-12)
    ca, cb = 0.5 * (lo_a + hi_a), 0.5 * (lo_b + hi_b)
    origin = np.minimum(ca.min(axis=0), cb.min(axis=0))
    ia = np.floor((ca - origin) / cell).astype(np.int64) + 1
    ib = np.floor((cb - origin) / cell).astype(np.int64) + 1
    dims = np.maximum(ia.max(axis=0), ib.max(axis=0)) + 2

    def key(c):
        return (c[:, 0] * dims[1] + c[:, 1]) * dims[2] + c[:, 2]

    kb = key(ib)
    order = np.argsort(kb, kind="stable")
    cells, start, count = np.unique(kb[order], return_index=True, return_counts=True)
    out_i, out_j = [], []
    offsets = np.stack(np.meshgrid([-1, 0, 1], [-1, 0, 1], [-1, 0, 1], indexing="ij"), axis=-1).reshape(-1, 3)
    for off in offsets:
        ka = key(ia + off)
        pos = np.searchsorted(cells, ka)
        pos_c = np.minimum(pos, len(cells) - 1)
        hit = np.flatnonzero(cells[pos_c] == ka)
        if hit.size == 0:
            continue
        cnt = count[pos_c[hit]]
        first = start[pos_c[hit]]
        rep = np.repeat(hit, cnt)
        within = np.arange(cnt.sum()) - np.repeat(np.cumsum(cnt) - cnt, cnt)
        out_i.append(rep)
        out_j.append(order[np.repeat(first, cnt) + within])
    if not out_i:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    i, j = np.concatenate(out_i), np.concatenate(out_j)
    if same:
        keep = i < j
        i, j = i[keep], j[keep]
    overlap = np.all((lo_a[i] <= hi_b[j]) & (lo_b[j] <= hi_a[i]), axis=1)
    return i[overlap], j[overlap]


def _check_mesh(points, triangles):
    x = np.asarray(points, dtype=np.float64)
    t = np.asarray(triangles, dtype=np.int64)
    if x.ndim != 2 or x.shape[1] != 3:
        raise WarpclothError(f"points must have shape (N, 3), got {x.shape}")
    if t.ndim != 2 or t.shape[1] != 3 or (t.size and (t.min() < 0 or t.max() >= len(x))):
        raise WarpclothError(f"triangles must be (T, 3) indices into {len(x)} points, got shape {t.shape}")
    return x, t


# -- self-intersection ----------------------------------------------------------------------------------
def self_intersections(points, triangles) -> np.ndarray:
    """The pairs (i, j), i < j, of cloth triangles that intersect (closed sets), triangles that share
    a vertex excluded; shape (K, 2)."""
    x, t = _check_mesh(points, triangles)
    corners = x[t]
    lo, hi = corners.min(axis=1), corners.max(axis=1)
    i, j = _grid_pairs(lo, hi, lo, hi, same=True)
    share = np.zeros(len(i), dtype=bool)
    for a in range(3):
        for b in range(3):
            share |= t[i, a] == t[j, b]
    i, j = i[~share], j[~share]
    hit = triangles_intersect(corners[i], corners[j])
    return np.stack([i[hit], j[hit]], axis=1)


def count_self_intersections(points, triangles) -> int:
    """The number of intersecting pairs of non-neighbouring cloth triangles (:func:`self_intersections`)."""
    return int(len(self_intersections(points, triangles)))


# -- collider edges ---------------------------------------------------------------------------------
_BOX_EDGES = np.array([[0, 1], [2, 3], [4, 5], [6, 7], [0, 2], [1, 3], [4, 6], [5, 7], [0, 4], [1, 5], [2, 6], [3, 7]])
_BOX_CORNERS = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=np.float64)


def box_segments(center, half_extents, rotation_matrix) -> np.ndarray:
    """The 12 edges (12, 2, 3) of an oriented box."""
    local = _BOX_CORNERS * np.asarray(half_extents, dtype=np.float64)
    corners = np.asarray(center, dtype=np.float64) + local @ np.asarray(rotation_matrix).T
    return corners[_BOX_EDGES]


def mesh_segments(vertices, triangles) -> np.ndarray:
    """The unique edges (E, 2, 3) of a triangle mesh."""
    v = np.asarray(vertices, dtype=np.float64)
    e = mesh_topology(np.asarray(triangles, dtype=np.int64), len(v)).edges
    return v[e]


def collider_segments(collider, time: float = 0.0) -> np.ndarray:
    """The edges (S, 2, 3) of a :class:`~warpcloth.sim.colliders.Box` or
    :class:`~warpcloth.sim.colliders.MeshCollider` posed at ``time`` [s] (empty for the kinds
    without edges: plane, sphere, capsule)."""
    c = collider.at(time) if getattr(collider, "track", None) is not None else collider
    if c.kind == "box":
        return box_segments(c.center, c.half_extents, quat_matrix(c.rotation))
    if c.kind == "mesh":
        return mesh_segments(c.vertices, c.triangles)
    return np.zeros((0, 2, 3))


def segment_crossings(points, triangles, segments) -> np.ndarray:
    """The pairs (segment s, cloth triangle t) that meet, shape (K, 2), each pair once. Long
    segments are cut into pieces no longer than the grid cell for the broad phase."""
    x, t = _check_mesh(points, triangles)
    seg = np.asarray(segments, dtype=np.float64).reshape(-1, 2, 3)
    if len(seg) == 0 or len(t) == 0:
        return np.zeros((0, 2), np.int64)
    corners = x[t]
    lo_t, hi_t = corners.min(axis=1), corners.max(axis=1)
    cell = max(float(np.max(hi_t - lo_t)), 1e-12)
    length = np.linalg.norm(seg[:, 1] - seg[:, 0], axis=1)
    pieces = np.maximum(1, np.ceil(length / cell).astype(np.int64))
    owner = np.repeat(np.arange(len(seg)), pieces)
    k = np.arange(pieces.sum()) - np.repeat(np.cumsum(pieces) - pieces, pieces)
    f0 = (k / pieces[owner])[:, None]
    f1 = ((k + 1) / pieces[owner])[:, None]
    d = seg[owner, 1] - seg[owner, 0]
    p, q = seg[owner, 0] + f0 * d, seg[owner, 0] + f1 * d
    q[k == pieces[owner] - 1] = seg[owner[k == pieces[owner] - 1], 1]  # the last piece ends exactly at the end
    i, j = _grid_pairs(np.minimum(p, q), np.maximum(p, q), lo_t, hi_t, same=False)
    hit = segments_meet_triangles(p[i], q[i], corners[j, 0], corners[j, 1], corners[j, 2])
    pairs = np.unique(owner[i[hit]] * np.int64(len(t)) + j[hit])
    return np.stack([pairs // len(t), pairs % len(t)], axis=1)


def collider_edge_crossings(points, triangles, colliders, time: float = 0.0) -> int:
    """The number of (collider edge, cloth triangle) pairs that meet, over ``colliders``
    (:mod:`warpcloth.sim.colliders` objects, posed at ``time`` [s]; those without edges add 0)."""
    segs = [collider_segments(c, time) for c in colliders]
    segs = [s for s in segs if len(s)]
    if not segs:
        return 0
    return int(len(segment_crossings(points, triangles, np.concatenate(segs))))


# -- frames ------------------------------------------------------------------------------------------
@dataclass
class IntersectionReport:
    """Counts per frame: ``times`` [s] (or time codes / fps), ``self_intersections`` (pairs of
    non-neighbouring cloth triangles that intersect) and ``collider_crossings`` (collider edges
    crossing cloth triangles)."""

    times: list = field(default_factory=list)
    self_intersections: list = field(default_factory=list)
    collider_crossings: list = field(default_factory=list)

    @property
    def frames(self) -> int:
        return len(self.times)

    @property
    def clean(self) -> bool:
        """No intersection and no crossing in any frame."""
        return not any(self.self_intersections) and not any(self.collider_crossings)

    def first_bad_frame(self) -> int | None:
        for k, (a, b) in enumerate(zip(self.self_intersections, self.collider_crossings)):
            if a or b:
                return k
        return None

    def summary(self) -> str:
        bad = self.first_bad_frame()
        head = (
            f"{self.frames} frames: {sum(1 for a in self.self_intersections if a)} with self-intersections "
            f"(max {max(self.self_intersections, default=0)} triangle pairs), "
            f"{sum(1 for b in self.collider_crossings if b)} with collider edges through the cloth "
            f"(max {max(self.collider_crossings, default=0)})"
        )
        return head if bad is None else f"{head}; first at frame {bad} (t = {self.times[bad]:g} s)"


def check_frames(frames, triangles, times=None, segments_at=None) -> IntersectionReport:
    """Both counts for every frame of cloth positions ``frames`` (F, N, 3); ``segments_at(k)``
    gives frame k's collider edges (S, 2, 3) (none when None)."""
    report = IntersectionReport()
    for k, x in enumerate(frames):
        report.times.append(float(times[k]) if times is not None else float(k))
        report.self_intersections.append(count_self_intersections(x, triangles))
        segs = segments_at(k) if segments_at is not None else None
        crossing = segment_crossings(x, triangles, segs) if segs is not None and len(segs) else ()
        report.collider_crossings.append(int(len(crossing)))
    return report


#: Where warpcloth's writer puts the colliders (a file without them has none).
DEFAULT_COLLIDERS = "/World/Colliders"
#: The extensions of the files :func:`check_usd` reads.
USD_EXTENSIONS = (".usd", ".usda", ".usdc", ".usdz")
#: The largest layer :func:`check_usd` opens [bytes]: warpcloth's writer keeps ~64 MiB of samples
#: a layer (value clips beyond), so a larger one is not a file it wrote, and USD reads it whole.
MAX_USD_LAYER_BYTES = 2**30
#: Layers one checked file may name, all told (a long run writes one value clip per chunk of frames).
MAX_USD_LAYERS = 100_000


def _first_bad(values: np.ndarray) -> int:
    """The first row of ``values`` (K, ...) that is not all finite."""
    return int(np.flatnonzero(~np.isfinite(values.reshape(len(values), -1)).all(axis=1))[0])


def _numbers(value, where: str, what: str, kinds: str = "iuf") -> np.ndarray:
    """An attribute's value as a NumPy array (empty for None), refused unless it holds numbers of
    the ``kinds`` (NumPy kind letters): a file may author ``string points`` or ``float[]`` counts."""
    try:
        a = np.asarray(value if value is not None else [])
    except (TypeError, ValueError):
        a = np.asarray([object()])
    if a.size and a.dtype.kind not in kinds:
        allowed = "integers" if kinds == "iu" else "numbers"
        raise WarpclothError(f"{where}: {what} must be {allowed}, got a {type(value).__name__}")
    return a


def _triangles(mesh, where: str, points: int | None = None) -> np.ndarray:
    """The (T, 3) triangles of a ``UsdGeom.Mesh`` (its default topology), refused unless every face
    is a triangle, the counts match the indices and (given ``points``) every index names a point."""
    counts = _numbers(mesh.GetFaceVertexCountsAttr().Get(), where, "faceVertexCounts", "iu").astype(np.int64).ravel()
    indices = _numbers(mesh.GetFaceVertexIndicesAttr().Get(), where, "faceVertexIndices", "iu").astype(np.int64).ravel()
    if counts.size == 0:
        raise WarpclothError(f"{where} has no faces (faceVertexCounts is empty or missing)")
    if not np.all(counts == 3):
        k = int(np.flatnonzero(counts != 3)[0])
        raise WarpclothError(f"{where}: face {k} has {int(counts[k])} vertices; the checker reads triangle meshes")
    if indices.size != counts.sum():
        raise WarpclothError(
            f"{where}: faceVertexCounts sum to {int(counts.sum())} but there are {indices.size} faceVertexIndices"
        )
    if points is not None:
        _check_indices(indices, points, where)
    return indices.reshape(-1, 3)


def _check_indices(indices: np.ndarray, points: int, where: str) -> None:
    out = np.flatnonzero((indices.ravel() < 0) | (indices.ravel() >= points))
    if out.size:
        raise WarpclothError(
            f"{where}: faceVertexIndices[{int(out[0])}] = {int(indices.ravel()[out[0]])} is out of range: "
            f"its {points} points are 0..{points - 1}"
        )


def _points(value, where: str) -> np.ndarray:
    """A points value as (N, 3) float64, refused when empty or not finite."""
    x = _numbers(value, where, "points").astype(np.float64)
    if x.size == 0:
        raise WarpclothError(f"{where} has no points")
    if x.ndim != 2 or x.shape[1] != 3:
        raise WarpclothError(f"{where}: points must be 3-vectors, got an array of shape {x.shape}")
    if not np.isfinite(x).all():
        k = _first_bad(x)
        raise WarpclothError(f"{where}: point {k} = {tuple(float(v) for v in x[k])} is not finite")
    return x


def _usd_collider_segments(stage, path: str, root: str = "/World/Colliders"):
    """A function of the time code giving the edges of the file's box (Cube) and mesh colliders,
    each checked: a finite positive cube size, a finite triangle mesh whose indices name its
    points, a finite transform at each time."""
    from pxr import Usd, UsdGeom  # noqa: PLC0415 (usd-core loads only where USD is read or written)

    scope = stage.GetPrimAtPath(root)
    if root != DEFAULT_COLLIDERS and not (scope and scope.IsValid()):  # the default may be absent: no colliders
        raise WarpclothError(f"{path}: no prim at {root!r} (the colliders' scope)")
    items = []
    if scope and scope.IsValid():
        for prim in scope.GetChildren():
            name = prim.GetName().lower()
            where = f"{path}: collider {prim.GetPath()}"
            if prim.IsA(UsdGeom.Cube) and name.startswith("box"):
                value = _numbers(UsdGeom.Cube(prim).GetSizeAttr().Get(), where, "size")
                if value.size > 1:
                    raise WarpclothError(f"{where}: its size must be one number, got {value.size}")
                size = 2.0 if value.size == 0 else float(value.ravel()[0])
                if not (np.isfinite(size) and size > 0):
                    raise WarpclothError(f"{where} has size {size}; a cube's size must be a positive finite number")
                items.append((prim, where, 0.5 * size * _BOX_CORNERS[_BOX_EDGES]))
            elif prim.IsA(UsdGeom.Mesh) and name.startswith("mesh"):
                mesh = UsdGeom.Mesh(prim)
                pts = _points(mesh.GetPointsAttr().Get(), where)
                tris = _triangles(mesh, where, len(pts))
                if mesh.GetPointsAttr().GetNumTimeSamples():  # a deforming mesh: its edges at each time
                    items.append((prim, where, (mesh.GetPointsAttr(), tris, len(pts))))
                else:
                    items.append((prim, where, mesh_segments(pts, tris)))
    cache = UsdGeom.XformCache()

    def at(code):
        out = []
        cache.SetTime(Usd.TimeCode(code))
        for prim, where, edges in items:
            local = edges
            if isinstance(edges, tuple):
                attr, tris, count = edges
                pts = _points(attr.Get(Usd.TimeCode(code)), f"{where} at time code {code:g}")
                if len(pts) != count:
                    raise WarpclothError(f"{where} at time code {code:g} has {len(pts)} points, its topology {count}")
                local = mesh_segments(pts, tris)
            m = np.array(cache.GetLocalToWorldTransform(prim), dtype=np.float64)  # row vectors: p' = [p 1] M
            if not np.isfinite(m).all():
                raise WarpclothError(f"{where}: its transform at time code {code:g} is not finite")
            flat = local.reshape(-1, 3)
            world = flat @ m[:3, :3] + m[3, :3]
            out.append(world.reshape(-1, 2, 3))
        return np.concatenate(out) if out else np.zeros((0, 2, 3))

    return at


def check_usd(path: str, cloth: str = "/World/Cloth", colliders: str = DEFAULT_COLLIDERS) -> IntersectionReport:
    """Both counts at every time sample of the cloth's points in a USD file written by warpcloth
    (value clips resolved by USD); times in seconds (time code / timeCodesPerSecond).

    The file and every layer it names are checked before they are opened
    (:func:`~warpcloth.io.meshio.open_usd_stage`, at most :data:`MAX_USD_LAYER_BYTES` a layer), and
    the geometry before it is counted: a triangle mesh whose counts match its indices, indices
    that name points, points at every frame finite and as many as the first frame's, colliders
    likewise.

    Raises:
        WarpclothError: one line naming the file and what is wrong with it.
    """
    try:
        name = os.fspath(path)
    except TypeError:
        raise WarpclothError(f"USD file must be a file name, got {path!r:.80}") from None
    if not isinstance(name, str) or os.path.splitext(name)[1].lower() not in USD_EXTENSIONS:
        raise WarpclothError(f"USD file {name!r} must end in one of {', '.join(USD_EXTENSIONS)}")
    from pxr import Sdf  # noqa: PLC0415 (usd-core loads only where USD is read or written)

    for what, prim, example in (("cloth", cloth, "/World/Cloth"), ("colliders", colliders, DEFAULT_COLLIDERS)):
        if not isinstance(prim, str) or not prim.startswith("/") or not Sdf.Path.IsValidPathString(prim):
            raise WarpclothError(f"the {what} prim path must be an absolute USD path such as {example!r}, got {prim!r}")
    stage, layers = open_usd_stage(name, max_bytes=MAX_USD_LAYER_BYTES, max_layers=MAX_USD_LAYERS)
    try:
        return _check_stage(stage, name, cloth, colliders)
    finally:
        del stage, layers


def _piece_meshes(pieces, path: str):
    """([(points attribute, point count, name)] of each piece's mesh, their triangles (T, 3) with
    indices offset by the pieces before)."""
    from pxr import Usd, UsdGeom  # noqa: PLC0415 (usd-core loads only where USD is read or written)

    attrs, tris, offset = [], [], 0
    for p in pieces:
        mesh, name = UsdGeom.Mesh(p), f"{path}: {p.GetPath()}"
        attr = mesh.GetPointsAttr()
        n = len(_points(attr.Get((attr.GetTimeSamples() or [Usd.TimeCode.Default()])[0]), name))
        tris.append(_triangles(mesh, name, n) + offset)
        attrs.append((attr, n, name))
        offset += n
    return attrs, np.concatenate(tris)


def _check_stage(stage, path: str, cloth: str, colliders: str) -> IntersectionReport:
    """:func:`check_usd` on an opened stage."""
    from pxr import Usd, UsdGeom  # noqa: PLC0415 (usd-core loads only where USD is read or written)

    prim = stage.GetPrimAtPath(cloth)
    pieces = (
        [prim]
        if prim and prim.IsA(UsdGeom.Mesh)
        else [c for c in (prim.GetChildren() if prim else ()) if c.IsA(UsdGeom.Mesh)]
    )
    if not pieces:
        raise WarpclothError(f"{path}: no mesh at {cloth!r} (nor, for a model of several pieces, meshes under it)")
    where = f"{path}: {cloth}"
    if len(pieces) == 1 and pieces[0] == prim:
        attrs, tris = [(UsdGeom.Mesh(prim).GetPointsAttr(), None, where)], _triangles(UsdGeom.Mesh(prim), where)
    else:  # a model of several pieces (/World/Cloth/<name>): one cloth, their triangles end to end
        attrs, tris = _piece_meshes(pieces, path)
    attr = attrs[0][0]
    codes = attr.GetTimeSamples() or [Usd.TimeCode.Default()]
    fps = stage.GetTimeCodesPerSecond()
    if not (np.isfinite(fps) and fps > 0):
        raise WarpclothError(f"{path}: timeCodesPerSecond is {fps}; it must be a positive finite number")
    segments_at = _usd_collider_segments(stage, path, colliders)
    report = IntersectionReport()
    count = None
    for code in codes:
        default = isinstance(code, Usd.TimeCode)
        at = f"{where} at time code {code:g}" if not default else where
        parts = [_points(a.Get(code), at if n is None else f"{w} at time code {code:g}") for a, n, w in attrs]
        for (_, n, w), part in zip(attrs, parts):
            if n is not None and len(part) != n:
                raise WarpclothError(f"{w} at time code {code:g} has {len(part)} points, its first frame {n}")
        x = np.concatenate(parts)
        if count is None:
            count = len(x)
            _check_indices(tris, count, where)
        elif len(x) != count:
            raise WarpclothError(f"{at} has {len(x)} points, the first frame {count}")
        report.times.append(float(code) / fps if not default else 0.0)
        report.self_intersections.append(count_self_intersections(x, tris))
        segs = segments_at(code if not default else 0.0)
        report.collider_crossings.append(int(len(segment_crossings(x, tris, segs))) if len(segs) else 0)
    return report


__all__ = [
    "DEFAULT_COLLIDERS",
    "MAX_USD_LAYERS",
    "MAX_USD_LAYER_BYTES",
    "USD_EXTENSIONS",
    "IntersectionReport",
    "box_segments",
    "check_frames",
    "check_usd",
    "collider_edge_crossings",
    "collider_segments",
    "count_self_intersections",
    "mesh_segments",
    "segment_crossings",
    "segments_meet_triangles",
    "self_intersections",
    "triangles_intersect",
]
