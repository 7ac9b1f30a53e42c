"""Self-collision of a cloth: vertex-triangle and edge-edge contacts with a thickness h [m] and a
Coulomb friction coefficient mu, on the device (kernels in :mod:`warpcloth.kernels.self_contact`).

A :class:`SelfCollision` is bound to a :class:`~warpcloth.sim.model.ClothModel` once: it makes
the unique edges, the neighbour exclusion tables, the spatial hash, the Verlet list of candidate
pairs and the contact list (fixed capacities), and every counter. Its methods launch kernels only
(no host work, no allocation), so they can sit inside a captured frame:

* :meth:`SelfCollision.detect` at the step's start (x, v): rebuild the candidate list when motion
  since the last build asks for it, then the contacts (gap < h + 2 v_max dt);
* :meth:`SelfCollision.filter_velocities` after the step: inelastic impulses on approaching pairs
  within h, Bridson's repulsion impulse min(dt k (h - d), m (0.1 (h - d)/dt - v_n)), impulses that
  leave every pair at least ``min_gap_fraction`` h apart, Coulomb friction; x moves with v as the
  step would have moved it (Bridson, Fedkiw & Anderson 2002, Sec. 7.2). An explicit scheme needs
  only ``detect`` and this;
* :meth:`SelfCollision.apply_forces`: the same repulsion as a force k (h - d) n, equal and opposite,
  for schemes that want it in their force (then the filter's is off);
* :meth:`SelfCollision.prevent_crossings`, the last word of a step: every listed pair followed along
  its straight motion (continuous collision detection, :mod:`warpcloth.kernels.ccd`), a pair that met
  on the way pushed apart, equal and opposite.

The :class:`~warpcloth.simulator.Simulator` detects before each step, filters after it and ends it
with the continuous response; how each integrator holds the contacts inside its own step
(:meth:`project_increment`, :meth:`eval_vertex_terms`, implicit Euler's system): docs/self-collision.md.
"""

from __future__ import annotations

import math

import numpy as np
import warp as wp

from warpcloth.errors import WarpclothError, require, require_count, require_non_negative, require_positive
from warpcloth.kernels import ccd
from warpcloth.kernels import self_contact as sk
from warpcloth.sim.mesh import mesh_topology
from warpcloth.sim.model import SpringType

#: threads of the continuous response's grid-stride kernels on the CPU (a launch's cost grows with its threads)
CPU_LANES = 64

#: Counter names of :meth:`SelfCollision.stats`, by their slot in the device counter array.
COUNT_NAMES = {
    "candidates_vertex_triangle": sk.CAND_VT,
    "candidates_edge_edge": sk.CAND_EE,
    "contacts": sk.CONTACTS,
    "rebuilds": sk.REBUILDS,
    "overflow_candidates": sk.OVERFLOW_CANDIDATES,
    "overflow_contacts": sk.OVERFLOW_CONTACTS,
    "truncated_queries": sk.TRUNCATED,
    "unresolved": sk.UNRESOLVED,
    "detects": sk.DETECTS,
    "contacts_max": sk.CONTACTS_MAX,
    "candidates_max": sk.CANDIDATES_MAX,
    "fast": sk.FAST,
    "ccd_collisions": sk.CCD_COLLISIONS,
    "ccd_rollbacks": sk.CCD_ROLLBACKS,
    "ccd_unresolved": sk.CCD_UNRESOLVED,
    "swept_rebuilds": sk.SWEPT_REBUILDS,
}
#: The counters :meth:`SelfCollision.reset_stats` zeroes (those that accumulate over steps).
CUMULATIVE = (
    "rebuilds",
    "overflow_candidates",
    "overflow_contacts",
    "truncated_queries",
    "unresolved",
    "detects",
    "contacts_max",
    "candidates_max",
    "fast",
    "ccd_collisions",
    "ccd_rollbacks",
    "ccd_unresolved",
    "swept_rebuilds",
)


def exclusion_tables(triangles: np.ndarray, edges: np.ndarray, vertex_count: int, rings: int):
    """Neighbour exclusion as CSR tables (sorted rows): per vertex the triangles it must not
    collide with, per edge the edges, beyond the rule every kernel applies itself (a vertex and its
    own triangles; edges that share a vertex). ``rings`` 1 adds nothing; ``rings`` r > 1 excludes
    every triangle with a vertex within r - 1 edge rings of the vertex, and every edge with a vertex
    within r - 1 rings of the edge's vertices (Newton's n-ring contact filter).

    Returns ((vt_offsets, vt_items), (ee_offsets, ee_items)), int32 NumPy arrays (NumPy only: a bind
    loads no SciPy)."""
    n = int(vertex_count)
    tris = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    edges = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    if rings <= 1:
        return (
            (np.zeros(n + 1, np.int32), np.zeros(0, np.int32)),
            (np.zeros(len(edges) + 1, np.int32), np.zeros(0, np.int32)),
        )
    ring = _csr(
        np.concatenate([edges[:, 0], edges[:, 1], np.arange(n)]),
        np.concatenate([edges[:, 1], edges[:, 0], np.arange(n)]),
        n,
        n,
    )
    reach = _csr(np.arange(n), np.arange(n), n, n)
    for _ in range(rings - 1):
        reach = _compose(reach, ring, n)
    vertex_tris = _csr(tris.reshape(-1), np.repeat(np.arange(len(tris)), 3), n, len(tris))
    vertex_edges = _csr(edges.reshape(-1), np.repeat(np.arange(len(edges)), 2), n, len(edges))
    edge_vertices = _csr(np.repeat(np.arange(len(edges)), 2), edges.reshape(-1), len(edges), n)
    vt = _compose(reach, vertex_tris, len(tris))
    ee = _compose(_compose(edge_vertices, reach, n), vertex_edges, len(edges))
    return tuple((off.astype(np.int32), idx.astype(np.int32)) for off, idx in (vt, ee))


def _csr(rows, cols, row_count: int, col_count: int):
    """(offsets, columns) of the boolean matrix with ones at (rows, cols), columns sorted per row."""
    key = np.unique(np.asarray(rows, np.int64) * col_count + np.asarray(cols, np.int64))
    r = key // col_count
    return np.searchsorted(r, np.arange(row_count + 1)), key % col_count


def _compose(a, b, col_count: int):
    """The boolean product of CSR matrices ``a`` (R x K) and ``b`` (K x col_count): row i holds every
    column of b's rows at a's columns of row i."""
    (a_off, a_idx), (b_off, b_idx) = a, b
    rows = np.repeat(np.arange(len(a_off) - 1), np.diff(a_off))
    counts = np.diff(b_off)[a_idx]
    within = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
    cols = b_idx[np.repeat(b_off[a_idx], counts) + within]
    return _csr(np.repeat(rows, counts), cols, len(a_off) - 1, col_count)


def _struct(cls, **fields):
    """An instance of the Warp struct ``cls`` with every one of its fields set from ``fields`` (a field left
    unset would be a null array in the kernels)."""
    missing = set(cls.vars) - set(fields)
    unknown = set(fields) - set(cls.vars)
    if missing or unknown:
        raise WarpclothError(f"{cls.key}: fields missing {sorted(missing)}, unknown {sorted(unknown)}")
    out = cls()
    for name, value in fields.items():
        setattr(out, name, value)
    return out


class SelfCollision:
    """Self-contact of one cloth model, bound once (every array allocated here).

    Args:
        model: the :class:`~warpcloth.sim.model.ClothModel` (its triangles and masses).
        thickness: h [m], the distance the response keeps between any two non-neighbouring parts.
        friction: Coulomb mu of cloth on cloth.
        stiffness: k [N/m] of the repulsion spring; default a quarter of the model's largest
            structural spring stiffness (of the order of the cloth's stretch springs, so an explicit
            step stays stable with a contact at a vertex; the velocity cap bounds it anyway).
        min_gap_fraction: the filter leaves every contact at least this fraction of h apart.
        iterations: Jacobi passes of the velocity filter.
        edge_fraction: edge-edge pairs act within h_e = edge_fraction h (1: as vertex-triangle
            pairs; less is cheaper where layers lie parallel, whose crossing edges are all contacts,
            but lets two edges that no vertex-triangle pair holds rest nearer than h).
        skin: the extra radius of the candidate list [m] (default h) besides the pair's motion
            margins; the list is rebuilt when a vertex may have moved skin / 2 beyond its margin since
            the last build, relative to the cloth's mean motion (a larger skin rebuilds less often but
            holds more candidates, each tested every step; in the fold at 32 x 32 and 64 x 64, h costs
            1.6-1.9x an explicit step, h / 2 2.1-2.4x, 2 h 2.4-2.9x: bench/self_collision.py).
        skin_max: the largest motion margin of a vertex [m] (default the larger of 2 h and the longest
            rest edge): a vertex's margin covers a step of its motion up to it; a vertex faster than
            skin_max a step (relative to the mean) can miss a pair (counted in ``fast``). Twice that
            (4 h or two edges) overflowed the default 64 x 64 drape's list at its landing (1.4 million
            candidates did not fit) and left 11 triangle pairs through each other; 2 h alone (below a
            coarse strip's edges) let pbd's 24 x 8 fold pass through itself.
        exclude_rings: 1: exclude a vertex and its own triangles, edges sharing a vertex; r > 1:
            also pairs within r - 1 rings (:func:`exclusion_tables`); default 1 where h is at most half
            the shortest rest edge (a flat cloth then has no pair within h: a vertex is at least a
            triangle's height from the triangles of its neighbours), else 2 (and then two triangles one
            ring apart may pass through each other in a fold sharper than the mesh).
        candidates_per_vertex, candidates_per_edge, contacts_per_element: capacities of the lists
            (vertex-triangle candidates: per vertex, edge-edge: per edge, contacts: per vertex + edge).
            128 candidates: the default 64 x 64 drape's landing needs up to 78 a vertex and 64 an edge
            under pbd, xpbd and vbd (at 64 each, 2,000-160,000 candidates did not fit over a run, and the
            run warned; 12 bytes a candidate: 25 MB at 64 x 64, 100 MB at 128 x 128). 16 contacts: the
            default drape under xpbd 1 x 64 (its material's setting) overflowed 8 by 59,511 contacts in
            its first 0.7 s, and none at 16 (about 52 bytes a contact: 13 MB at 64 x 64).
        interval: the collision time step [s] of the schemes that only filter (explicit Euler, midpoint,
            RK4, Verlet: their ``self_contact_filter`` is ``"full"``): contacts are found at the start
            of an interval of whole steps no longer than this and the velocity filter acts at its end,
            on the interval's motion (Bridson, Fedkiw & Anderson 2002, Sec. 7: the collision step may
            exceed the internal dynamics' step); 0: every step. Intervals restart with each
            :meth:`Simulator.simulate <warpcloth.simulator.Simulator.simulate>` call (a frame). Schemes
            that hold the contacts in their solve find them every step. Its filter makes twice
            ``iterations`` passes (the interval's corrections are larger), and the velocity the
            step goes on with takes only what its own normal velocity lacks (docs/self-collision.md).
        ccd_passes: Jacobi passes of the continuous collision response that ends each step (each
            collision interval): every listed pair is followed along its motion from the start to the
            end positions, and a pair that met on the way is pushed apart, equal and opposite, to the
            minimum gap along the collision's normal (:meth:`prevent_crossings`); pairs the passes
            leave crossing have their free vertices moved back to the step's start (two rounds). 0: off.
    """

    def __init__(
        self,
        model,
        thickness: float,
        friction: float = 0.0,
        stiffness: float | None = None,
        min_gap_fraction: float = 0.1,
        iterations: int = 2,
        skin: float | None = None,
        skin_max: float | None = None,
        exclude_rings: int | None = None,
        edge_fraction: float = 1.0,
        candidates_per_vertex: int = 128,
        candidates_per_edge: int = 128,
        contacts_per_element: int = 16,
        interval: float = 0.001,
        ccd_passes: int = 8,
    ):
        self.model = model
        self._settings = {
            "thickness": thickness,
            "friction": friction,
            "stiffness": stiffness,
            "min_gap_fraction": min_gap_fraction,
            "iterations": iterations,
            "skin": skin,
            "skin_max": skin_max,
            "exclude_rings": exclude_rings,
            "edge_fraction": edge_fraction,
            "candidates_per_vertex": candidates_per_vertex,
            "candidates_per_edge": candidates_per_edge,
            "contacts_per_element": contacts_per_element,
            "interval": interval,
            "ccd_passes": ccd_passes,
        }
        self.thickness = require_positive("self-collision thickness", thickness, "m")
        self.friction = require_non_negative("self-collision friction mu", friction)
        self.edge_fraction = float(edge_fraction)
        require(0.0 < self.edge_fraction <= 1.0, f"edge_fraction must be in (0, 1], got {edge_fraction!r}")
        self.min_gap_fraction = float(min_gap_fraction)
        require(
            0.0 < self.min_gap_fraction <= self.edge_fraction,
            f"min_gap_fraction must be in (0, edge_fraction = {self.edge_fraction:g}], got {min_gap_fraction!r}",
        )
        self.iterations = require_count("self-collision iterations", iterations, 1)
        self.interval = require_non_negative("self-collision interval", interval, "s")
        self.ccd_passes = require_count("self-collision ccd_passes", ccd_passes, 0)
        self.skin = require_positive("self-collision skin", self.thickness if skin is None else skin, "m")
        stiffness = self._default_stiffness(model) if stiffness is None else stiffness
        self.stiffness = require_positive("self-collision stiffness", stiffness, "N/m")
        host = model.host
        tris = np.asarray(host.tris, dtype=np.int32).reshape(-1, 3)
        require(len(tris) > 0, "self-collision needs a model with triangles")
        n = model.particle_count
        edges = mesh_topology(tris, n).edges.astype(np.int32)
        q = np.asarray(host.q, dtype=np.float64)
        lengths = np.linalg.norm(q[edges[:, 1]] - q[edges[:, 0]], axis=1)
        longest = float(np.max(lengths))
        if exclude_rings is None:
            exclude_rings = 1 if self.thickness <= 0.5 * float(np.min(lengths)) else 2
        self.exclude_rings = require_count("exclude_rings", exclude_rings, 1)
        skin_max = max(2.0 * self.thickness, longest) if skin_max is None else skin_max
        self.skin_max = require_positive("self-collision skin_max", skin_max, "m")
        #: the hash's least cell size [m] (a build adds its largest vertex margin): a query of the list
        #: radius plus a triangle's reach spans about three cells
        self.cell_size = self.thickness + self.skin + 0.75 * longest
        buckets = 1 << max(4, math.ceil(math.log2(2 * max(len(tris), len(edges)))))
        (vt_off, vt_ex), (ee_off, ee_ex) = exclusion_tables(tris, edges, n, self.exclude_rings)
        self.vt_capacity = require_count("candidates_per_vertex", candidates_per_vertex, 1) * n
        self.ee_capacity = require_count("candidates_per_edge", candidates_per_edge, 1) * len(edges)
        self._contact_capacity = require_count("contacts_per_element", contacts_per_element, 1) * (n + len(edges))
        self.edge_count = len(edges)
        self.bucket_count = buckets
        device = model.device
        self.device = device
        # Warp's CPU backend runs a launch's threads one after another in thread order, so the edge insertion
        # leaves each bucket's list in decreasing edge order and the edge-edge search stops a bucket's walk at
        # its own index (tests/test_self_contact.py checks the lists against brute force); on CUDA any order
        self._ordered_buckets = wp.get_device(device).is_cpu
        with wp.ScopedDevice(device):
            self.tris = wp.array(tris, dtype=wp.vec3i)
            self.edges = wp.array(edges, dtype=wp.vec2i)
            self.vt_exclude_offsets = wp.array(vt_off, dtype=int)
            self.vt_exclude = wp.array(vt_ex if vt_ex.size else np.zeros(1, np.int32), dtype=int)
            self.ee_exclude_offsets = wp.array(ee_off, dtype=int)
            self.ee_exclude = wp.array(ee_ex if ee_ex.size else np.zeros(1, np.int32), dtype=int)
            group = host.collision_group  # the pieces' collision groups (ClothBuilder); None: one group
            self.vertex_group = wp.array(np.zeros(n, np.int32) if group is None else group, dtype=int)
            self.head_tri = wp.full(buckets, -1, dtype=int)
            self.head_edge = wp.full(buckets, -1, dtype=int)
            self.next_tri = wp.zeros(len(tris), dtype=int)
            self.next_edge = wp.zeros(len(edges), dtype=int)
            self.tri_lo, self.tri_hi = wp.zeros(len(tris), dtype=wp.vec3), wp.zeros(len(tris), dtype=wp.vec3)
            self.tri_cell = wp.zeros(len(tris), dtype=wp.vec3i)
            self.edge_lo, self.edge_hi = wp.zeros(len(edges), dtype=wp.vec3), wp.zeros(len(edges), dtype=wp.vec3)
            self.edge_cell = wp.zeros(len(edges), dtype=wp.vec3i)
            self.x_build = wp.zeros(n, dtype=wp.vec3)
            self.margin = wp.zeros(n, dtype=float)  # per vertex at the build: |v - w| dt, at most skin_max [m]
            #: per vertex (|x - x_build - u| [m], |v - w| [m/s], |v| [m/s]): its displacement since the build and
            #: its velocity relative to the mean (u, w), and its speed, at the last detect (the narrow phase's bound)
            self.motion_speed = wp.zeros(n, dtype=wp.vec3)
            self.tri_margin = wp.zeros(len(tris), dtype=float)
            self.edge_margin = wp.zeros(len(edges), dtype=float)
            self.cand_vt = wp.zeros(self.vt_capacity, dtype=wp.vec2i)
            self.cand_ee = wp.zeros(self.ee_capacity, dtype=wp.vec2i)
            self.cand_vt_gap = wp.zeros(self.vt_capacity, dtype=float)
            self.cand_ee_gap = wp.zeros(self.ee_capacity, dtype=float)
            self.contact_indices = wp.zeros(self._contact_capacity, dtype=wp.vec4i)
            self.contact_weights = wp.zeros(self._contact_capacity, dtype=wp.vec4)
            self.contact_normals = wp.zeros(self._contact_capacity, dtype=wp.vec3)
            self.contact_gaps = wp.zeros(self._contact_capacity, dtype=float)
            self.contact_thickness = wp.zeros(self._contact_capacity, dtype=float)
            self.splits = wp.zeros(n, dtype=int)
            # a filter pass's per-contact change (W, n, (dv_n, velocity target)): found by its count, used by its filter
            self.filter_weights = wp.zeros(self.contact_capacity, dtype=wp.vec4)
            self.filter_normals = wp.zeros(self.contact_capacity, dtype=wp.vec3)
            self.filter_changes = wp.zeros(self.contact_capacity, dtype=wp.vec2)
            self.acting = wp.zeros(n, dtype=int)  # per vertex, the contacts acting in a response pass (zeroed after it)
            self.dv = wp.zeros(n, dtype=wp.vec3)
            self.x_start = wp.zeros(n, dtype=wp.vec3)  # x at the collision interval's start (detect)
            self.v_average = wp.zeros(n, dtype=wp.vec3)  # the interval's mean velocity (its filter)
            self.dv_end = wp.zeros(n, dtype=wp.vec3)  # the end velocity's change over an interval
            self.swept = wp.zeros(n, dtype=wp.vec3)  # x - x_start at the continuous response (its list's margins)
            self.swept_length = wp.zeros(n, dtype=float)  # |x - x_start - its mean| there (the first pass's bound)
            self.filter_inv_mass = wp.zeros(n, dtype=float)  # 1/m, 0 where a collider holds the vertex (filter)
            #: per vertex, the contacts' penalty force [N] and Gauss-Newton Hessian [N/m] (vbd's vertex step)
            self.vertex_force = wp.zeros(n, dtype=wp.vec3)
            self.vertex_hessian = wp.zeros(n, dtype=wp.mat33)
            self.counts = wp.zeros(sk.COUNT_SLOTS, dtype=int)
            self.scalars = wp.zeros(sk.SCALAR_SLOTS, dtype=float)
            self.motion_sums = wp.zeros(2, dtype=wp.vec3)
            self._no_displacement = wp.zeros(1, dtype=wp.vec3)
            # the continuous collision response: this pass's collisions (pair, W, n, depth), per vertex
            # whether its pairs are tested in the next pass, whether it was in a collision, the fail-safe's marks
            self.hit_indices = wp.zeros(self.contact_capacity, dtype=wp.vec4i)
            self.hit_weights = wp.zeros(self.contact_capacity, dtype=wp.vec4)
            self.hit_normals = wp.zeros(self.contact_capacity, dtype=wp.vec3)
            self.hit_depths = wp.zeros(self.contact_capacity, dtype=float)
            self.ccd_moved = wp.zeros(n, dtype=int)
            self.ccd_touched = wp.zeros(n, dtype=int)
            self.ccd_rollback = wp.zeros(n, dtype=int)
            self.ccd_held = wp.zeros(n, dtype=wp.vec3)  # a holding collider's outward normal at the vertex, else 0
        self._bind_structs()

    def _bind_structs(self) -> None:
        """The kernels' arguments that stay fixed after the bind, as Warp structs (made once: a launch, and a
        captured frame, copies them by value; what changes between steps is in ``counts`` and ``scalars``)."""
        self.topology = _struct(
            sk.SelfContactMesh,
            tris=self.tris,
            edges=self.edges,
            vt_exclude_offsets=self.vt_exclude_offsets,
            vt_exclude=self.vt_exclude,
            ee_exclude_offsets=self.ee_exclude_offsets,
            ee_exclude=self.ee_exclude,
            group=self.vertex_group,
        )
        self.broad_phase = _struct(
            sk.SelfContactGrid,
            mask=self.bucket_count - 1,
            ordered=int(self._ordered_buckets),
            head_tri=self.head_tri,
            next_tri=self.next_tri,
            tri_lo=self.tri_lo,
            tri_hi=self.tri_hi,
            tri_cell=self.tri_cell,
            tri_margin=self.tri_margin,
            head_edge=self.head_edge,
            next_edge=self.next_edge,
            edge_lo=self.edge_lo,
            edge_hi=self.edge_hi,
            edge_cell=self.edge_cell,
            edge_margin=self.edge_margin,
            x_build=self.x_build,
            margin=self.margin,
            motion_speed=self.motion_speed,
            cand_vt=self.cand_vt,
            cand_vt_gap=self.cand_vt_gap,
            cand_ee=self.cand_ee,
            cand_ee_gap=self.cand_ee_gap,
            vt_capacity=self.vt_capacity,
            ee_capacity=self.ee_capacity,
        )
        self.contact_list = _struct(
            sk.SelfContactList,
            idx=self.contact_indices,
            w=self.contact_weights,
            n=self.contact_normals,
            d=self.contact_gaps,
            h=self.contact_thickness,
            splits=self.splits,
            capacity=self._contact_capacity,
        )
        self.filter_work = _struct(
            sk.SelfContactFilter,
            f_w=self.filter_weights,
            f_n=self.filter_normals,
            f_change=self.filter_changes,
            acting=self.acting,
            dv=self.dv,
            dv_end=self.dv_end,
            v_average=self.v_average,
        )
        self.params = _struct(
            sk.SelfContactSettings,
            thickness=self.thickness,
            edge_thickness=self.edge_thickness,
            skin=self.skin,
            skin_max=self.skin_max,
            cell_size=self.cell_size,
            min_gap=self.min_gap,
            friction=self.friction,
        )
        self.ccd_state = _struct(
            ccd.CcdState,
            moved=self.ccd_moved,
            touched=self.ccd_touched,
            rollback=self.ccd_rollback,
            acting=self.acting,
            held=self.ccd_held,
            swept_length=self.swept_length,
            hit_idx=self.hit_indices,
            hit_w=self.hit_weights,
            hit_n=self.hit_normals,
            hit_depth=self.hit_depths,
            capacity=self._contact_capacity,
            eta=self.ccd_tolerance,
        )

    @property
    def contact_capacity(self) -> int:
        """The contact list's capacity (and the continuous response's per pass): the launches read it from the
        bound structs, which setting it updates."""
        return self._contact_capacity

    @contact_capacity.setter
    def contact_capacity(self, capacity: int) -> None:
        self._contact_capacity = int(capacity)
        self.contact_list.capacity = self._contact_capacity
        self.ccd_state.capacity = self._contact_capacity

    def settings(self) -> dict:
        """The keyword arguments this object was made with (to bind the same settings to another model)."""
        return dict(self._settings)

    def rebind(self, model) -> SelfCollision:
        """A new :class:`SelfCollision` with these settings bound to ``model``."""
        return SelfCollision(model, **self._settings)

    @staticmethod
    def _default_stiffness(model) -> float:
        ks = model.spring_stiffness.numpy()
        structural = model.spring_type == int(SpringType.STRUCTURAL)
        k = float(ks[structural].max()) if np.any(structural) else float(ks.max()) if ks.size else 0.0
        if k <= 0.0:
            raise WarpclothError("self-collision stiffness: the model has no stiff springs; give stiffness [N/m]")
        return 0.25 * k

    @property
    def edge_thickness(self) -> float:
        """h_e [m]: the thickness edge-edge contacts act within (``edge_fraction`` h)."""
        return self.edge_fraction * self.thickness

    @property
    def min_gap(self) -> float:
        """The least gap [m] the filter leaves a contact with (``min_gap_fraction`` h)."""
        return self.min_gap_fraction * self.thickness

    def interval_steps(self, dt: float, filter_kind: str) -> int:
        """Steps of ``dt`` [s] per collision interval for an integrator whose ``self_contact_filter``
        is ``filter_kind``: the most whole steps within :attr:`interval` (at least 1) where it is
        ``"full"``, else 1."""
        if filter_kind != "full" or self.interval <= 0.0:
            return 1
        return max(1, int(math.floor(self.interval / float(dt) * (1.0 + 1.0e-9))))

    # -- per step (kernel launches only) ------------------------------------------------------
    def detect(self, x: wp.array, v: wp.array, dt: float) -> None:
        """Contacts at the step's start: positions ``x`` [m], velocities ``v`` [m/s], step ``dt`` [s]."""
        self._decide(x, v, dt)
        self._build(x, v, dt)
        self._narrow(x, v, dt)

    def _decide(self, x, v, dt) -> None:
        """Motion since the last build; whether this detect rebuilds (on the device)."""
        c, s, d = self.counts, self.scalars, self.device
        n = self.model.particle_count
        wp.launch(sk.begin_self_contact_detect, dim=1, inputs=[c, s, self.motion_sums], device=d)
        wp.launch(sk.sum_self_contact_motion, dim=n, inputs=[x, v, self.x_build, self.motion_sums], device=d)
        wp.launch(
            sk.eval_self_contact_motion,
            dim=n,
            inputs=[x, v, self.broad_phase, self.motion_sums, float(dt), self.contact_list, s, self.x_start],
            device=d,
        )
        wp.launch(sk.decide_self_contact_rebuild, dim=1, inputs=[c, s, self.params, float(dt)], device=d)

    def _build(self, x, v, dt, edges: bool = True) -> None:
        """The hash and the candidate lists (every launch returns at once unless a rebuild is due);
        ``edges`` False: the vertex-triangle part only (for the bench)."""
        m, d, n = self.model, self.device, self.model.particle_count
        c, s, mesh, grid = self.counts, self.scalars, self.topology, self.broad_phase
        wp.launch(
            sk.clear_self_contact_cells,
            dim=max(self.bucket_count, n),
            inputs=[c, x, v, self.motion_sums, float(dt), self.params, grid, s],
            device=d,
        )
        wp.launch(sk.size_self_contact_cells, dim=1, inputs=[c, self.params, s], device=d)
        wp.launch(sk.insert_self_contact_triangles, dim=m.tri_count, inputs=[c, x, mesh, grid, s], device=d)
        wp.launch(sk.find_vertex_triangle_candidates, dim=n, inputs=[c, s, x, mesh, grid], device=d)
        if not edges:
            return
        wp.launch(sk.insert_self_contact_edges, dim=self.edge_count, inputs=[c, x, mesh, grid, s], device=d)
        wp.launch(sk.find_edge_edge_candidates, dim=self.edge_count, inputs=[c, s, x, mesh, grid], device=d)

    def _narrow(self, x, v, dt) -> None:
        """This step's contacts from the candidate lists."""
        n, d = self.model.particle_count, self.device
        wp.launch(
            sk.eval_self_contacts,
            dim=n,
            inputs=[n, self.counts, self.scalars, x, v, float(dt), self.topology, self.broad_phase]
            + [self.contact_list, self.params],
            device=d,
        )
        self._finish()

    def _finish(self) -> None:
        """The lists' lengths capped at their capacities, the largest so far (after a detect or a rebuild)."""
        wp.launch(
            sk.finish_self_contact_detect,
            dim=1,
            inputs=[self.counts, self.broad_phase, self.contact_list],
            device=self.device,
        )

    def apply_forces(self, x: wp.array, v: wp.array, f: wp.array, dt: float) -> None:
        """Add the repulsion of every contact at ``x``, ``v`` to the forces ``f`` [N] (equal and opposite)."""
        n = self.model.particle_count
        wp.launch(
            sk.eval_self_contact_forces,
            dim=n,
            inputs=[
                n,
                self.counts,
                x,
                v,
                self.model.particle_inv_mass,
                self.contact_list,
                self.stiffness,
                float(dt),
            ],
            outputs=[f],
            device=self.device,
        )

    def filter_velocities(
        self,
        x: wp.array,
        v: wp.array,
        dt: float,
        position_weight: float = 1.0,
        displacement: wp.array | None = None,
        repulsion: bool = True,
        inelastic: bool = True,
        colliders=None,
        steps: int = 1,
    ) -> None:
        """After the step (``x``, ``v`` at its end): the velocity filter, in place. A velocity change
        dv moves x by ``position_weight`` dt dv (1 where x += dt v_new; 1/2 for the Runge-Kutta
        schemes, as for colliders); ``displacement`` (Verlet's x - x_prev) moves by as much.
        ``steps``: the collision interval's steps of ``dt`` since the contacts were found (its
        repulsion acts over ``steps`` dt, and dv moves x by (``steps`` - 1 + ``position_weight``) dt dv,
        as if it had acted from the interval's start).
        ``repulsion``: Bridson's repulsion impulse in the filter (off where the scheme had
        :meth:`apply_forces` in its force). ``inelastic`` False: only the last pass's guarantee, every
        pair at least ``min_gap`` apart (where the solve held the contacts itself). ``colliders``: a
        :class:`~warpcloth.sim.contacts.ColliderSet` whose contacts win: a vertex within a collider's
        thickness (+ ``min_gap``) takes no impulse, the pair's other side all of it."""
        n, d = self.model.particle_count, self.device
        steps = require_count("self-collision filter steps", steps, 1)
        dt_d = float(position_weight) * float(dt)
        if not dt_d > 0.0:
            raise WarpclothError(f"self-collision filter: position_weight * dt must be > 0, got {dt_d!r}")
        dt_x = dt_d + (steps - 1) * float(dt)
        dt = steps * float(dt)
        v_out, average = v, steps > 1
        if average:  # the filter acts on the interval's motion, the end velocity changes by as much
            wp.launch(
                sk.eval_interval_velocity, dim=n, inputs=[x, self.x_start, dt], outputs=[self.v_average], device=d
            )
            v = self.v_average
        disp = displacement if displacement is not None else self._no_displacement
        k = self.stiffness if repulsion else 0.0
        inv_mass = self.model.particle_inv_mass
        if colliders is not None and len(colliders.colliders):
            inv_mass = self.held_inverse_mass(x, colliders)
        contacts, work, params = self.contact_list, self.filter_work, self.params
        for _ in range(self.iterations * (2 if steps > 1 else 1)):  # an interval's corrections are larger
            wp.launch(
                sk.count_filter_contacts,
                dim=n,
                inputs=[n, self.counts, x, v, inv_mass, contacts, params, int(inelastic), k, float(dt), dt_x, work],
                device=d,
            )
            wp.launch(
                sk.filter_self_contact_velocities,
                dim=n,
                inputs=[n, self.counts, inv_mass, contacts, work, params, v_out, int(average)],
                device=d,
            )
            wp.launch(
                sk.apply_self_contact_velocities,
                dim=n,
                inputs=[work, dt_x, dt_d, int(displacement is not None), int(average)],
                outputs=[x, v_out, disp],
                device=d,
            )
        if self.ccd_passes == 0:  # else after the continuous response, the step's last word
            self._count_unresolved(x)

    def _count_unresolved(self, x: wp.array) -> None:
        n = self.model.particle_count
        wp.launch(
            sk.count_unresolved_self_contacts,
            dim=n,
            inputs=[n, self.counts, x, self.contact_list, self.params, self.model.particle_inv_mass],
            device=self.device,
        )

    #: rounds of the continuous response's passes: before each, the list is made to cover the motion so far
    #: (:meth:`_cover_swept`); a later round runs only where that rebuilt the list (the pushes of the round
    #: before moved a vertex beyond it: a vertex shot through two layers pushes the first through the second,
    #: a pair the first list did not hold), its first pass testing every pair
    CCD_ROUNDS = 2

    #: rounds of the continuous response's fail-safe (free vertices of a crossing pair back to the step's start)
    CCD_ROLLBACK_ROUNDS = 2

    @property
    def ccd_tolerance(self) -> float:
        """eta [m]: a pair collides where its four points lie in one plane with the vertex within eta of
        the triangle (the edges within eta of each other): a hundredth of the minimum gap."""
        return 0.01 * self.min_gap

    def prevent_crossings(
        self,
        x: wp.array,
        v: wp.array,
        dt: float,
        position_weight: float = 1.0,
        displacement: wp.array | None = None,
        colliders=None,
        steps: int = 1,
        held: wp.array | None = None,
    ) -> None:
        """The last word of a step (of a collision interval of ``steps`` steps of ``dt``): every listed
        pair follows the straight motion from the positions at the last :meth:`detect` to ``x``; a pair
        that met on the way (continuous collision detection: the roots of the coplanarity cubic in
        [0, 1]) is pushed apart along the collision's normal, equal and opposite, so that the pair ends
        on its start's side at least :attr:`min_gap` apart along it (:attr:`ccd_passes` Jacobi passes,
        each testing only the pairs of vertices that moved or collided in the pass before); a push dx
        changes v by dx / (``steps`` dt), the velocity that moves x by as much over the interval (the
        filter's dx / dt_x, with dt_x = dt / 2 for the Runge-Kutta schemes, bounced a lone vertex back at
        1.3 times its speed). Pairs still crossing after the
        passes have their free vertices moved back to the step's start (the fail-safe; momentum is
        not kept), :attr:`CCD_ROLLBACK_ROUNDS` rounds; what is left is counted (``ccd_unresolved``).
        A pinned vertex is not pushed, nor one within a collider's thickness (``colliders``, a
        :class:`~warpcloth.sim.contacts.ColliderSet`) where the push would move it into that collider, nor,
        where no collider holds it, one against its direction in ``held`` (per vertex a unit vector or 0:
        :attr:`ColliderEdges.held <warpcloth.sim.contacts.ColliderEdges.held>`, the direction the collider
        edge contacts pushed it out in this step). First the list is made to cover the interval's motion
        (:meth:`_cover_swept`)."""
        if self.ccd_passes == 0:
            return
        n, d = self.model.particle_count, self.device
        steps = require_count("self-collision ccd steps", steps, 1)
        dt_d = float(position_weight) * float(dt)
        if not dt_d > 0.0:
            raise WarpclothError(f"self-collision ccd: position_weight * dt must be > 0, got {dt_d!r}")
        dt_v = steps * float(dt)
        disp = displacement if displacement is not None else self._no_displacement
        inv_mass = self.model.particle_inv_mass
        if colliders is not None and len(colliders.colliders):
            wp.launch(
                ccd.eval_ccd_held, dim=n, inputs=[x, colliders.params, self.min_gap], outputs=[self.ccd_held], device=d
            )
        else:
            self.ccd_held.zero_()
        if held is not None:  # where no collider holds a vertex, the edge contacts' push direction does
            wp.launch(ccd.merge_ccd_held, dim=n, inputs=[held], outputs=[self.ccd_held], device=d)
        # the passes' kernels loop over their pairs and vertices (grid-stride): a pass that has nothing to do
        # returns at once, which on the CPU costs per thread launched (measured: 30 us a launch of 4096)
        lanes = n if wp.get_device(d).is_cuda else min(n, CPU_LANES)
        find_inputs = [lanes, self.counts, self.x_start, x, inv_mass, self.topology, self.broad_phase, self.params]
        find_inputs.append(self.ccd_state)
        apply_inputs = [lanes, dt_v, dt_d, int(displacement is not None), self.dv, x, v, disp, self.ccd_state]

        def find(mode: int, first: int = 0) -> None:
            wp.launch(ccd.begin_ccd_pass, dim=1, inputs=[self.counts, first], device=d)
            wp.launch(
                ccd.find_ccd_collisions,
                dim=lanes,
                inputs=[*find_inputs, mode, first],
                device=d,
            )

        def apply() -> None:
            wp.launch(ccd.apply_ccd_corrections, dim=lanes, inputs=[*apply_inputs, self.counts], device=d)

        for r in range(self.CCD_ROUNDS):
            self._cover_swept(x, r > 0)  # the list covers the motion so far (the round before's pushes included)
            if r == 0:
                self.ccd_moved.fill_(1)  # the first pass tests every pair
            else:
                wp.launch(ccd.begin_ccd_round, dim=n, inputs=[self.counts], outputs=[self.ccd_moved], device=d)
            for k in range(self.ccd_passes):
                find(int(ccd.MODE_PUSH), int(r == 0 and k == 0))
                wp.launch(
                    ccd.push_ccd_collisions,
                    dim=lanes,
                    inputs=[lanes, self.counts, inv_mass, self.ccd_state, self.dv],
                    device=d,
                )
                apply()
            if r > 0:
                wp.launch(ccd.end_ccd_round, dim=1, inputs=[self.counts], device=d)
        for _ in range(self.CCD_ROLLBACK_ROUNDS):
            find(int(ccd.MODE_ROLLBACK))
            wp.launch(
                ccd.roll_back_vertices,
                dim=lanes,
                inputs=[lanes, self.counts, self.x_start, x, self.ccd_rollback, self.dv],
                device=d,
            )
            apply()
        find(int(ccd.MODE_COUNT))
        self.ccd_touched.zero_()
        self._count_unresolved(x)

    def _cover_swept(self, x: wp.array, skip_capped: bool = False) -> None:
        """Before the continuous response: the list covers the straight motion from the interval's start
        (:attr:`x_start`) to ``x`` where the detect's test holds at its end too (every vertex within skin / 2
        of its margin, relative to the mean displacement since the build); else (the solve, a collider's
        or an edge's projection, a strain limit moved a vertex beyond what its velocity at the detect
        predicted) the list is rebuilt at the start positions with each vertex's margin its motion to the
        end (relative to the mean; at most ``skin_max``, beyond counted in ``fast``), so the response sees
        every pair that may have met on the way (``swept_rebuilds``). ``skip_capped``: vertices whose margin
        is ``skin_max`` are left out of the test (after the response's first round: a rebuild would cap them
        again). Launches only."""
        n, d, s = self.model.particle_count, self.device, self.scalars
        wp.launch(sk.begin_swept_check, dim=1, inputs=[s, self.motion_sums], device=d)
        wp.launch(sk.sum_swept_motion, dim=n, inputs=[x, self.x_start, self.x_build, self.motion_sums], device=d)
        wp.launch(
            sk.eval_swept_motion,
            dim=n,
            inputs=[x, self.x_start, self.broad_phase, self.motion_sums, s, self.params, int(skip_capped)]
            + [self.swept, self.swept_length],
            device=d,
        )
        wp.launch(sk.decide_swept_rebuild, dim=1, inputs=[self.counts, s, self.params], device=d)
        # the build's margins are MARGIN_STEPS dt |v - w|: here v = the swept motion over dt = 1 (MARGIN_STEPS 1:
        # the motion itself; more would widen these margins alike)
        self._build(self.x_start, self.swept, 1.0)
        self._finish()

    def held_inverse_mass(self, x: wp.array, colliders) -> wp.array:
        """Per vertex 1/m, 0 where it lies within a collider's thickness + the minimum gap at ``x`` (a
        :class:`~warpcloth.sim.contacts.ColliderSet`): the filter's masses, and for :meth:`project_increment`,
        so that a layer on the ground is not pressed into it by the one above (the colliders' projection after
        it would put the upper layer back into the lower's plane). Device launches only; the array is this
        object's."""
        wp.launch(
            sk.eval_filter_inverse_mass,
            dim=self.model.particle_count,
            inputs=[x, self.model.particle_inv_mass, colliders.params, self.min_gap],
            outputs=[self.filter_inv_mass],
            device=self.device,
        )
        return self.filter_inv_mass

    def project_increment(self, x: wp.array, dp: wp.array, inv_mass: wp.array | None = None) -> None:
        """Inside a position-based solver's iterations (pbd, xpbd, projective): every contact as a
        constraint on p = x + dp, its gap found anew at p, d >= h (each pair's own thickness), with
        Coulomb friction on the relative tangential displacement up to mu times the normal correction;
        corrections equal and opposite, a vertex's mass split over its violated contacts (one Jacobi
        pass, in place on ``dp``). ``inv_mass``: the vertices' 1/m (default the model's; 0 moves none)."""
        n, d = self.model.particle_count, self.device
        inv_mass = self.model.particle_inv_mass if inv_mass is None else inv_mass
        wp.launch(
            sk.count_violated_contacts,
            dim=n,
            inputs=[n, self.counts, x, dp, inv_mass, self.contact_list],
            outputs=[self.acting],
            device=d,
        )
        wp.launch(
            sk.project_self_contact_increments,
            dim=n,
            inputs=[n, self.counts, x, dp, inv_mass, self.acting, self.contact_list, self.friction],
            outputs=[self.dv],
            device=d,
        )
        wp.launch(sk.apply_increment_corrections, dim=n, inputs=[self.dv], outputs=[dp, self.acting], device=d)

    def eval_vertex_terms(self, x: wp.array, dx: wp.array, stiffness: float | None = None) -> None:
        """The contacts' penalty k delta^2 / 2 at x + dx (delta = h - gap > 0) per vertex:
        :attr:`vertex_force` [N] and the Gauss-Newton :attr:`vertex_hessian` [N/m] (vbd's local Newton
        step; equal and opposite); k = ``stiffness`` [N/m], default :attr:`stiffness`."""
        n, d = self.model.particle_count, self.device
        wp.launch(
            sk.clear_self_contact_vertex_terms,
            dim=n,
            outputs=[self.vertex_force, self.vertex_hessian],
            device=d,
        )
        wp.launch(
            sk.eval_self_contact_vertex_terms,
            dim=n,
            inputs=[
                n,
                self.counts,
                x,
                dx,
                self.model.particle_inv_mass,
                self.contact_list,
                self.stiffness if stiffness is None else float(stiffness),
            ],
            outputs=[self.vertex_force, self.vertex_hessian],
            device=d,
        )

    # -- outside the step (host reads) --------------------------------------------------------------
    def invalidate(self) -> None:
        """Rebuild the candidate list at the next detect (after the state was changed from outside)."""
        wp.launch(sk.invalidate_self_contact_list, dim=1, inputs=[self.counts], device=self.device)

    def stats(self) -> dict:
        """Counters (reads the device): this step's candidates and contacts, and since the last
        :meth:`reset_stats`: rebuilds, overflows (pairs that did not fit), truncated queries, contacts
        left closer than the minimum gap, detects, the largest lists, ``fast`` (vertex-builds: at each
        build, the vertices whose motion was more than ``skin_max`` covers: a pair may have been missed), the
        continuous response's ``ccd_collisions`` (pairs its first pass pushed), ``ccd_rollbacks`` and
        ``ccd_unresolved`` (pairs left crossing), ``swept_rebuilds`` (lists rebuilt over an interval's motion
        before or between the continuous response's rounds, also counted in ``rebuilds``); the list's radius
        [m]."""
        c = self.counts.numpy()
        s = self.scalars.numpy()
        out = {name: int(c[k]) for name, k in COUNT_NAMES.items()}
        out.update(
            radius=float(s[sk.R_BUILD]),
            skin=float(s[sk.SKIN]),
            margin_max=float(s[sk.MARGIN_MAX]),
            capacity_candidates=self.vt_capacity + self.ee_capacity,
            capacity_contacts=self.contact_capacity,
        )
        return out

    def reset_stats(self) -> None:
        """Zero the cumulative counters (rebuilds, overflows, truncated, unresolved, detects, maxima)."""
        c = self.counts.numpy()
        for name in CUMULATIVE:
            c[COUNT_NAMES[name]] = 0
        self.counts.assign(c)

    def contacts(self) -> dict:
        """This step's contacts as NumPy arrays: ``indices`` (C, 4), ``weights`` (C, 4),
        ``normals`` (C, 3), ``gaps`` (C,) [m] at detection."""
        k = int(self.counts.numpy()[sk.CONTACTS])
        return {
            "indices": self.contact_indices.numpy()[:k],
            "weights": self.contact_weights.numpy()[:k],
            "normals": self.contact_normals.numpy()[:k],
            "gaps": self.contact_gaps.numpy()[:k],
        }

    def candidates(self) -> tuple[np.ndarray, np.ndarray]:
        """The Verlet list: (vertex, triangle) pairs (K, 2) and (edge, edge) pairs (L, 2)."""
        c = self.counts.numpy()
        return self.cand_vt.numpy()[: c[sk.CAND_VT]], self.cand_ee.numpy()[: c[sk.CAND_EE]]

    def edge_array(self) -> np.ndarray:
        """The unique edges (E, 2) the edge-edge contacts index."""
        return self.edges.numpy()


__all__ = ["SelfCollision", "exclusion_tables"]
