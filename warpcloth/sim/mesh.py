"""Cloth from any triangle mesh: springs, lumped masses and pins derived from the mesh.

:func:`build_mesh_cloth` turns vertices and triangles into a
:class:`~warpcloth.sim.model.ClothModel` (through :func:`~warpcloth.sim.model.build_model`):

- **structural** springs on the unique edges;
- **bend** springs across each interior edge, between the two vertices opposite it (one per
  interior edge; an edge shared by more than two triangles gets none);
- with ``quads=True``, triangle pairs that form a quad (rule below) get the shared diagonal and the
  other diagonal as **shear** springs, and the bend springs are the 2-ring straight lines: a
  triangulated Provot grid gives exactly the springs of :func:`~warpcloth.sim.grid.build_grid_cloth`.

Quad rule (``quads=True``): an interior edge that is the strictly longest edge of both of its
triangles (longer than each other edge by a factor 1 + 1e-6) is the diagonal of a quad. Each
triangle has at most one longest edge, so it belongs to at most one quad, and such a quad is convex.
The remaining edges are structural. A bend spring joins u and w, two structural neighbours of a
vertex v, when the edges v-u and v-w are not two sides of one face (a quad or a leftover triangle)
and the angle u-v-w at rest is at least 150 degrees (a straight line through v).

Masses: a total mass [kg] or an areal density [kg/m^2], lumped by vertex area (a third of each
adjacent triangle's area) or split uniformly (seed 4.2.4). Pins: vertex indices, named vertex groups,
or a predicate on the rest positions (:mod:`warpcloth.sim.selection`, never ``eval``-ed).
docs/meshes.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from warpcloth.errors import WarpclothError, require, require_non_negative, require_positive
from warpcloth.sim.device import require_memory, resolve_device
from warpcloth.sim.grid import BYTES_PER_PARTICLE, BYTES_PER_SPRING
from warpcloth.sim.hinges import (
    DEFAULT_BEND_DAMPING_RATIO,
    DEFAULT_BEND_RIGIDITY,
    build_hinges,
    hinge_damping_for_ratio,
    triangle_hinges,
)
from warpcloth.sim.model import BendModel, ClothModel, SpringParams, SpringType, build_model, default_spring_params
from warpcloth.sim.selection import resolve_pins

#: A bend spring of the quad rule spans at least this angle u-v-w [degrees] at rest.
STRAIGHT_ANGLE_DEG = 150.0
#: The quad rule's diagonal is longer than the triangle's other edges by this factor.
LONGEST_MARGIN = 1e-6
#: A triangle whose area is below this fraction of the squared bounding-box diagonal is degenerate.
DEGENERATE_AREA = 1e-12
#: The largest |coordinate| of a vertex [m]: the kernels square distances in float32 (spring
#: lengths, triangle areas), which must stay below float32's largest value (3.4e38).
MAX_COORDINATE = 1e18
#: Bytes per triangle a mesh cloth needs beside its particles and springs (the topology's edge
#: tables, areas, the triangle list on the device and host).
BYTES_PER_TRIANGLE = 200
#: Springs per triangle at most: its edges (1.5), the bends across them (1.5) and a quad's shear.
SPRINGS_PER_TRIANGLE = 4


def mesh_memory_estimate(vertex_count: int, triangle_count: int) -> int:
    """An upper estimate [bytes] of the memory a mesh cloth of ``vertex_count`` vertices and
    ``triangle_count`` triangles and its run need, per particle and spring as
    :func:`~warpcloth.sim.grid.grid_memory_estimate` (a triangulated grid has 2 triangles, 8
    springs per particle)."""
    v, t = int(vertex_count), int(triangle_count)
    return v * BYTES_PER_PARTICLE + t * (SPRINGS_PER_TRIANGLE * BYTES_PER_SPRING + BYTES_PER_TRIANGLE)


@dataclass
class TriangleMesh:
    """A triangle mesh as read from a file.

    Attributes:
        vertices: rest positions [m], shape (N, 3), float64.
        triangles: vertex indices, shape (T, 3), int64 (counter-clockwise seen from the front).
        uv: texture coordinates per triangle corner, shape (T, 3, 2), or None.
        groups: vertex groups, name -> sorted vertex indices.
        source: where it came from (a path, or "arrays").
    """

    vertices: np.ndarray
    triangles: np.ndarray
    uv: np.ndarray | None = None
    groups: dict = field(default_factory=dict)
    source: str = "arrays"
    loose: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    """The file's vertices that belong to no face, dropped when it was read (0-based, in the file's
    vertex order; :func:`drop_loose_vertices`); the others keep their order."""

    def file_indices(self, indices, what: str = "vertex indices") -> list:
        """Vertex indices as numbered in the file (0-based, loose vertices included) as indices of
        this mesh. Raises :class:`WarpclothError` for a dropped (loose) vertex."""
        indices = [int(i) for i in indices]
        if not self.loose.size:
            return indices
        count = self.vertices.shape[0] + self.loose.size
        new = np.full(count, -1, dtype=np.int64)
        new[np.setdiff1d(np.arange(count), self.loose)] = np.arange(self.vertices.shape[0])
        for i in indices:
            require(0 <= i < count, f"{what}: vertex {i} is out of range: the file has vertices 0..{count - 1}")
            require(new[i] >= 0, f"{what}: vertex {i} belongs to no face in {self.source} (it was dropped as loose)")
        return [int(new[i]) for i in indices]


# -- validation ----------------------------------------------------------------------------


def drop_loose_vertices(mesh: TriangleMesh) -> TriangleMesh:
    """``mesh`` without the vertices that belong to no triangle (what deleting faces in a DCC
    leaves behind), triangles and groups renumbered, the dropped ones in :attr:`TriangleMesh.loose`.
    Returned as it is where every vertex is used or a triangle's index is out of range
    (:func:`check_mesh` names that)."""
    t = np.asarray(mesh.triangles)
    n = np.asarray(mesh.vertices).shape[0]
    if t.size == 0 or not np.issubdtype(t.dtype, np.integer) or t.min() < 0 or t.max() >= n:
        return mesh
    used = np.zeros(n, dtype=bool)
    used[t.ravel()] = True
    if used.all():
        return mesh
    new = np.full(n, -1, dtype=np.int64)
    new[used] = np.arange(int(used.sum()))

    def renumber(group):
        g = np.asarray(group, dtype=np.int64)
        inside = (g >= 0) & (g < n)
        g = np.where(inside, new[np.clip(g, 0, n - 1)], g - n + int(used.sum()))  # out of range stays out
        return g[~inside | (g >= 0)]

    return TriangleMesh(
        vertices=np.asarray(mesh.vertices)[used],
        triangles=new[t],
        uv=mesh.uv,
        groups={name: renumber(g) for name, g in mesh.groups.items()},
        source=mesh.source,
        loose=np.flatnonzero(~used),
    )


def check_mesh(vertices, triangles, what: str = "mesh") -> tuple[np.ndarray, np.ndarray]:
    """Vertices (N, 3) float64 and triangles (T, 3) int64, checked: not empty, finite vertices,
    integer indices in range, no repeated index, no zero-area triangle, every vertex in a
    triangle. Raises :class:`WarpclothError` naming the first bad value."""
    try:
        v = np.asarray(vertices, dtype=np.float64)
    except (TypeError, ValueError):
        raise WarpclothError(f"{what}: vertices must be numbers, shape (N, 3)") from None
    require(v.size > 0, f"{what} is empty: no vertices")
    require(v.ndim == 2 and v.shape[1] == 3, f"{what}: vertices must have shape (N, 3), got {v.shape}")
    bad = np.flatnonzero(~np.all(np.isfinite(v), axis=1))
    if bad.size:
        raise WarpclothError(
            f"{what}: vertex {int(bad[0])} is not finite ({v[bad[0]].tolist()}); vertices must be finite numbers"
        )
    far = np.flatnonzero(np.any(np.abs(v) > MAX_COORDINATE, axis=1))
    if far.size:
        k = int(far[0])
        raise WarpclothError(
            f"{what}: vertex {k} at ({', '.join(f'{c:.3g}' for c in v[k])}) m is out of range: coordinates must "
            f"be within +-{MAX_COORDINATE:.0e} m (float32 must hold squared distances)"
        )
    t = np.asarray(triangles)
    require(t.size > 0, f"{what} is empty: no triangles")
    require(t.ndim == 2 and t.shape[1] == 3, f"{what}: triangles must have shape (T, 3), got {t.shape}")
    if not np.issubdtype(t.dtype, np.integer):
        tf = np.asarray(t, dtype=np.float64)
        require(np.all(tf == np.round(tf)), f"{what}: triangle indices must be integers")
        t = tf.astype(np.int64)
    t = t.astype(np.int64)
    n = v.shape[0]
    out = np.flatnonzero(np.any((t < 0) | (t >= n), axis=1))
    if out.size:
        k = int(out[0])
        raise WarpclothError(
            f"{what}: triangle {k} has vertex index {t[k].tolist()} out of range: vertices are 0..{n - 1}"
        )
    rep = np.flatnonzero((t[:, 0] == t[:, 1]) | (t[:, 1] == t[:, 2]) | (t[:, 0] == t[:, 2]))
    if rep.size:
        k = int(rep[0])
        raise WarpclothError(
            f"{what}: triangle {k} repeats a vertex ({t[k].tolist()}): a triangle needs three different vertices"
        )
    area = triangle_areas(v, t)
    scale = float(np.sum(np.ptp(v, axis=0) ** 2))
    flat = np.flatnonzero(area <= DEGENERATE_AREA * max(scale, np.finfo(float).tiny))
    if flat.size:
        k = int(flat[0])
        raise WarpclothError(
            f"{what}: triangle {k} ({t[k].tolist()}) is degenerate (zero area): remove it or fix its vertices"
        )
    used = np.zeros(n, dtype=bool)
    used[t.ravel()] = True
    if not used.all():
        k = int(np.flatnonzero(~used)[0])
        raise WarpclothError(
            f"{what}: vertex {k} belongs to no triangle (every vertex of a cloth must be in a triangle)"
        )
    return v, t


def triangle_areas(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Area of each triangle [m^2] (float64)."""
    a, b, c = (vertices[triangles[:, k]] for k in range(3))
    return 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)


# -- topology ------------------------------------------------------------------------------


@dataclass
class MeshTopology:
    """Unique edges of a triangle mesh and what lies across them (all NumPy, vectorised).

    Attributes:
        edges: unique edges (E, 2), lower index first, sorted.
        edge_triangles: number of triangles at each edge (1: boundary, 2: interior).
        half_edge: edge id of each triangle side, shape (T, 3) (side k joins corners k, k+1).
        opposite: (E, 2) the vertices opposite each interior edge in its two triangles (-1 else).
        edge_tris: (E, 2) the two triangles of each interior edge (-1 else).
    """

    edges: np.ndarray
    edge_triangles: np.ndarray
    half_edge: np.ndarray
    opposite: np.ndarray
    edge_tris: np.ndarray

    @property
    def interior(self) -> np.ndarray:
        return self.edge_triangles == 2


def mesh_topology(triangles: np.ndarray, vertex_count: int) -> MeshTopology:
    """Unique edges by sorting packed keys lo * N + hi (no per-edge Python loop)."""
    t = np.asarray(triangles, dtype=np.int64)
    T = t.shape[0]
    a = t.reshape(-1)
    b = t[:, [1, 2, 0]].reshape(-1)
    opp = t[:, [2, 0, 1]].reshape(-1)
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    key = lo * np.int64(vertex_count) + hi
    order = np.argsort(key, kind="stable")
    ks = key[order]
    first = np.ones(ks.size, dtype=bool)
    first[1:] = ks[1:] != ks[:-1]
    edge_of_sorted = np.cumsum(first) - 1
    E = int(edge_of_sorted[-1]) + 1
    half_edge = np.empty(3 * T, dtype=np.int64)
    half_edge[order] = edge_of_sorted
    starts = np.flatnonzero(first)
    counts = np.diff(np.append(starts, ks.size))
    edges = np.stack([lo[order[starts]], hi[order[starts]]], axis=1)
    opposite = np.full((E, 2), -1, dtype=np.int64)
    edge_tris = np.full((E, 2), -1, dtype=np.int64)
    two = np.flatnonzero(counts == 2)
    h0, h1 = order[starts[two]], order[starts[two] + 1]
    opposite[two, 0], opposite[two, 1] = opp[h0], opp[h1]
    edge_tris[two, 0], edge_tris[two, 1] = h0 // 3, h1 // 3
    same = two[opposite[two, 0] == opposite[two, 1]]
    if same.size:
        e = int(same[0])
        raise WarpclothError(
            f"mesh: triangles {int(edge_tris[e, 0])} and {int(edge_tris[e, 1])} are the same triangle (vertices "
            f"{[int(edges[e, 0]), int(edges[e, 1]), int(opposite[e, 0])]})"
        )
    return MeshTopology(edges, counts, half_edge.reshape(T, 3), opposite, edge_tris)


def mesh_springs(vertices, triangles, quads: bool = False, bend: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Springs of a triangle mesh as (pairs (S, 2) int32, types (S,) int32); see the module
    docstring for the rules."""
    v = np.asarray(vertices, dtype=np.float64)
    t = np.asarray(triangles, dtype=np.int64)
    topo = mesh_topology(t, v.shape[0])
    edges = topo.edges
    pairs, types = [], []

    def add(p, kind):
        p = np.asarray(p, dtype=np.int64).reshape(-1, 2)
        pairs.append(p)
        types.append(np.full(p.shape[0], int(kind), dtype=np.int32))

    if not quads:
        add(edges, SpringType.STRUCTURAL)
        if bend:
            add(topo.opposite[topo.interior], SpringType.BEND)
        return np.concatenate(pairs).astype(np.int32), np.concatenate(types)

    length = np.linalg.norm(v[edges[:, 1]] - v[edges[:, 0]], axis=1)
    side = length[topo.half_edge]  # (T, 3)
    longest = np.argmax(side, axis=1)
    srt = np.sort(side, axis=1)
    strict = srt[:, 2] > srt[:, 1] * (1.0 + LONGEST_MARGIN)
    tri_diag = np.where(strict, topo.half_edge[np.arange(t.shape[0]), longest], -1)  # each triangle's longest edge
    diag_votes = np.bincount(tri_diag[tri_diag >= 0], minlength=edges.shape[0])
    is_diag = topo.interior & (diag_votes == 2)
    add(edges[~is_diag], SpringType.STRUCTURAL)
    add(edges[is_diag], SpringType.SHEAR)
    add(topo.opposite[is_diag], SpringType.SHEAR)
    if bend:
        add(_straight_bends(v, t, topo, is_diag), SpringType.BEND)
    return np.concatenate(pairs).astype(np.int32), np.concatenate(types)


def _straight_bends(v, t, topo: MeshTopology, is_diag: np.ndarray) -> np.ndarray:
    """Bend pairs (u, w) of the quad rule: u, w structural neighbours of v, v-u and v-w not
    two sides of one face, angle u-v-w >= STRAIGHT_ANGLE_DEG."""
    n = np.int64(v.shape[0])
    structural = topo.edges[~is_diag]
    centre = np.concatenate([structural[:, 0], structural[:, 1]])
    other = np.concatenate([structural[:, 1], structural[:, 0]])
    order = np.lexsort((other, centre))
    centre, other = centre[order], other[order]
    # corners of faces: (centre, lower neighbour, higher neighbour) packed into one key
    diag = np.flatnonzero(is_diag)
    u, w = topo.edges[diag, 0], topo.edges[diag, 1]
    p, q = topo.opposite[diag, 0], topo.opposite[diag, 1]
    in_quad = np.zeros(t.shape[0], dtype=bool)
    in_quad[topo.edge_tris[diag].ravel()] = True
    lone = t[~in_quad]
    corner_c = [u, p, w, q, lone[:, 0], lone[:, 1], lone[:, 2]]
    corner_a = [p, u, p, w, lone[:, 1], lone[:, 2], lone[:, 0]]
    corner_b = [q, w, q, u, lone[:, 2], lone[:, 0], lone[:, 1]]
    cc, ca, cb = (np.concatenate(x).astype(np.int64) for x in (corner_c, corner_a, corner_b))
    corner_keys = np.sort((cc * n + np.minimum(ca, cb)) * n + np.maximum(ca, cb))  # membership by binary search
    cos_limit = math.cos(math.radians(STRAIGHT_ANGLE_DEG))
    found = []
    for d in range(1, centre.size):  # pairs of neighbours of one centre, offset d apart in the sorted list
        same = np.flatnonzero(centre[d:] == centre[:-d])
        if same.size == 0:
            break
        c, a, b = centre[same], other[same], other[same + d]
        key = (c * n + np.minimum(a, b)) * n + np.maximum(a, b)
        at = np.minimum(np.searchsorted(corner_keys, key), corner_keys.size - 1)
        keep = corner_keys[at] != key
        da, db = v[a] - v[c], v[b] - v[c]
        cos = np.einsum("ij,ij->i", da, db) / (np.linalg.norm(da, axis=1) * np.linalg.norm(db, axis=1))
        keep &= cos <= cos_limit + 1e-12
        found.append((np.minimum(a, b) * n + np.maximum(a, b))[keep])
    if not found:
        return np.zeros((0, 2), dtype=np.int64)
    keys = np.sort(np.concatenate(found))
    keys = keys[np.append(True, keys[1:] != keys[:-1])] if keys.size else keys  # one spring per pair
    return np.stack([keys // n, keys % n], axis=1)


# -- masses --------------------------------------------------------------------------------

MASS_MODES = ("area", "uniform")


def lumped_masses(
    vertices, triangles, total_mass: float | None = None, density: float | None = None, mode: str = "area"
) -> np.ndarray:
    """Particle masses [kg] (float64): ``mode="area"`` gives each vertex a third of the area of
    each adjacent triangle times the density; ``"uniform"`` splits the total evenly. Give the
    total mass [kg] or the areal density [kg/m^2] (default: 0.2 kg in all)."""
    require(mode in MASS_MODES, f"mass mode must be one of {', '.join(MASS_MODES)}, got {mode!r}")
    require(total_mass is None or density is None, "give a total mass or an areal density, not both")
    v = np.asarray(vertices, dtype=np.float64)
    t = np.asarray(triangles, dtype=np.int64)
    area = triangle_areas(v, t)
    total_area = float(area.sum())
    if density is not None:
        total_mass = require_positive("density", density, "kg/m^2") * total_area
    elif total_mass is None:
        total_mass = 0.2
    total_mass = require_positive("mass", total_mass, "kg")
    if mode == "uniform":
        return np.full(v.shape[0], total_mass / v.shape[0])
    vertex_area = np.zeros(v.shape[0])
    for k in range(3):
        np.add.at(vertex_area, t[:, k], area / 3.0)
    return vertex_area * (total_mass / total_area)


# -- the builder ---------------------------------------------------------------------------


def build_mesh_cloth(
    vertices,
    triangles=None,
    total_mass: float | None = None,
    density: float | None = None,
    mass_mode: str = "area",
    spring_params: dict[SpringType, SpringParams] | None = None,
    stiffness=None,
    damping=None,
    pins=(),
    pin_groups=(),
    pin_where=None,
    groups: dict | None = None,
    uv=None,
    quads: bool = False,
    bend: bool | str = True,
    device: str | None = None,
    *,
    bend_rigidity: float | None = None,
    bend_damping_ratio: float | None = None,
) -> ClothModel:
    """Build a mass-spring cloth from a triangle mesh (rules in :mod:`warpcloth.sim.mesh`).

    Args:
        vertices: (N, 3) rest positions [m]; or a :class:`TriangleMesh` (then ``triangles`` is
            ignored and its uv and groups are used).
        triangles: (T, 3) vertex indices.
        total_mass: cloth mass [kg] (default 0.2 kg unless ``density`` is given).
        density: areal density [kg/m^2] instead of a total mass.
        mass_mode: ``"area"`` (lumped by vertex area) or ``"uniform"`` (seed 4.2.4).
        spring_params: per-type :class:`SpringParams`; default :func:`default_spring_params`
            for the mean particle mass, with ``stiffness`` / ``damping`` as there.
        pins: vertex indices to pin; pin_groups: names of vertex groups to pin; pin_where: a
            predicate (callable or string, :func:`~warpcloth.sim.selection.parse_predicate`) on the rest positions.
        groups: vertex groups, name -> indices.
        uv: texture coordinates per triangle corner (T, 3, 2) or per vertex (N, 2); written to
            USD as ``primvars:st``.
        quads: detect triangle pairs forming quads: shear springs on their diagonals, bend
            springs on 2-ring straight lines (a triangulated grid gives the Provot springs).
        bend: add bend springs (True, ``"provot"``, ``"choi_ko"``), none (False, ``"none"``), or
            ``"dihedral"``: no bend springs, a dihedral-angle hinge on every interior edge
            (:func:`~warpcloth.sim.hinges.triangle_hinges`, one diagonal per quad: on a triangulated
            grid 3x stiffer across that diagonal, docs/materials.md).
        device: Warp device.
        bend_rigidity: bending rigidity B [N m] of the hinges (``dihedral`` only; default
            :data:`~warpcloth.sim.hinges.DEFAULT_BEND_RIGIDITY`).
        bend_damping_ratio: damping ratio of each hinge's own mode (``dihedral`` only).
    """
    if isinstance(vertices, TriangleMesh):
        mesh = vertices
        vertices, triangles = mesh.vertices, mesh.triangles
        uv = mesh.uv if uv is None else uv
        groups = {**mesh.groups, **(groups or {})}
    v, t = check_mesh(vertices, triangles)
    device = resolve_device(device)
    require_memory(
        f"a mesh cloth of {v.shape[0]:,} vertices and {t.shape[0]:,} triangles",
        mesh_memory_estimate(v.shape[0], t.shape[0]),
        device,
    )
    masses = lumped_masses(v, t, total_mass, density, mass_mode)
    if spring_params is None:
        spring_params = default_spring_params(float(masses.mean()), stiffness, damping)
    pinned = resolve_pins(v, pins, pin_groups, pin_where, groups)
    bend_model = mesh_bend(bend)
    if bend_model != BendModel.DIHEDRAL and (bend_rigidity is not None or bend_damping_ratio is not None):
        raise WarpclothError(
            "bend_rigidity and bend_damping_ratio are the dihedral model's (bend='dihedral'), not the bend springs'"
        )
    pairs, types = mesh_springs(v, t, quads=quads, bend=bend_model in (BendModel.PROVOT, BendModel.CHOI_KO))
    model = build_model(v, pairs, types, masses, spring_params, pinned, t, device)

    host = replace(
        model.host,
        uv=corner_uvs(uv, t, v.shape[0]) if uv is not None else None,
        groups={k: np.asarray(g, dtype=np.int64) for k, g in (groups or {}).items()},
    )
    model = replace(model, host=host)
    if bend_model == BendModel.DIHEDRAL:
        rigidity = (
            DEFAULT_BEND_RIGIDITY
            if bend_rigidity is None
            else require_non_negative("bend_rigidity", bend_rigidity, "N m")
        )
        ratio = (
            DEFAULT_BEND_DAMPING_RATIO
            if bend_damping_ratio is None
            else require_non_negative("bend_damping_ratio", bend_damping_ratio, "")
        )
        q = model.host.q
        hinges = build_hinges(q, triangle_hinges(t), rigidity, 1.0)
        hinges = replace(hinges, damping=hinge_damping_for_ratio(q, hinges, model.host.mass, ratio))
        model = replace(model.with_hinges(hinges), bend=BendModel.DIHEDRAL)
    return model


def mesh_bend(bend) -> BendModel:
    """A mesh's ``bend`` argument (a bool or a :class:`BendModel` name) as a BendModel."""
    if isinstance(bend, (bool, np.bool_)):
        return BendModel.PROVOT if bend else BendModel.NONE
    try:
        return BendModel(bend)
    except ValueError:
        raise WarpclothError(
            f"bend must be True, False or one of {[b.value for b in BendModel]}, got {bend!r}"
        ) from None


def corner_uvs(uv, triangles: np.ndarray, vertex_count: int) -> np.ndarray:
    """Texture coordinates per triangle corner (T * 3, 2) float32 from per-corner (T, 3, 2) or
    per-vertex (N, 2) values."""
    a = np.asarray(uv, dtype=np.float32)
    T = triangles.shape[0]
    if a.shape == (vertex_count, 2):
        a = a[triangles]
    require(a.shape == (T, 3, 2), f"uv must have shape (T, 3, 2) per corner or (N, 2) per vertex, got {a.shape}")
    require(bool(np.all(np.isfinite(a))), "uv must be finite numbers")
    return a.reshape(-1, 2)


__all__ = [
    "MASS_MODES",
    "MeshTopology",
    "TriangleMesh",
    "build_mesh_cloth",
    "check_mesh",
    "corner_uvs",
    "drop_loose_vertices",
    "lumped_masses",
    "mesh_bend",
    "mesh_memory_estimate",
    "mesh_springs",
    "mesh_topology",
    "triangle_areas",
]
