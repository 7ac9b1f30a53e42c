"""Contacts: the colliders of a :class:`~warpcloth.sim.control.Control` on the device.

:class:`ColliderSet` holds the colliders (:mod:`warpcloth.sim.colliders`) as one device array of
:class:`~warpcloth.kernels.collide.Collider` records, poses the moving ones, keeps the broad
phase's box, and projects the cloth out of them. How each integrator handles contact (kernels in
:mod:`warpcloth.kernels.collide`; all colliders in one launch per response, with a broad phase):

* force-based (explicit_euler, midpoint, rk4, verlet) and implicit_euler: a projection after
  the step with a velocity correction, in the Simulator's step after the integrator
  (:meth:`ColliderSet.project_velocity`): no particle ends a step inside a collider (posed at
  the step's end t + dt); the approaching normal velocity relative to the collider is removed and
  the relative tangential velocity reduced by mu times that change (Coulomb), the tangential
  change applied to the position as well. RK stages may pass through a collider within a step
  (only the step's end is projected); Verlet's displacement d = x - x_prev is reset to v dt for a
  contact, so its history does not carry the particle back in. Chosen because it is the same,
  exact-to-the-surface rule for every force-based scheme and costs one launch per step.
* pbd / xpbd: collision constraints projected inside the solver loop (Müller et al. 2007,
  Alg. 1 line 13) on the predicted displacement, and friction after the iterations from the
  accumulated normal correction, relative to the collider's motion over the substep; moving
  colliders are posed at each substep's end (see :meth:`ColliderSet.project_displacement`).

Pins win over contacts: pinned particles are never moved by a collider.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from warpcloth.errors import WarpclothError
from warpcloth.kernels import collide as ck
from warpcloth.kernels import edge_contact as ek
from warpcloth.sim.colliders import (
    COLLIDER_TYPES,
    KINDS,
    auto_edge_radius,
    describe,
    quat_matrix,
    signed_distance,
)
from warpcloth.sim.mesh import mesh_topology


class ColliderSet:
    """The colliders of a :class:`~warpcloth.sim.control.Control` as one device array of
    :class:`~warpcloth.kernels.collide.Collider` records, handled by one launch per response.

    Moving colliders are re-posed on the device from the control's simulated time before each
    response (one tiny launch per moving collider), so a captured frame replays their motion.
    Driven ones (:meth:`ColliderTrack.driven <warpcloth.sim.colliders.ColliderTrack.driven>`)
    read their pose from device arrays the host rewrites each frame (``frame_times``: the
    control's :attr:`~warpcloth.sim.control.Control.frame_times`).

    The broad phase's box is computed at the first response (not here: building a control
    loads no kernel module, so a run's compile time counts every module it loads).
    """

    def __init__(self, colliders, device, time=None, step_dt=None, frame_times=None):
        for c in colliders:
            if not isinstance(c, tuple(COLLIDER_TYPES.values())):
                raise WarpclothError(
                    f"colliders must be Plane, Sphere, Capsule, Box or MeshCollider objects, got {c!r:.80}"
                )
        self.colliders = tuple(colliders)
        self.device = device
        order = sorted(self.colliders, key=lambda c: c.kind != "plane")  # planes first: the kernels' half-space tests
        #: The colliders in the order of their device records (planes first).
        self.order = tuple(order)
        self.plane_count = sum(c.kind == "plane" for c in order)
        with wp.ScopedDevice(device):
            self.meshes = [
                wp.Mesh(
                    points=wp.array(c.vertices, dtype=wp.vec3),
                    indices=wp.array(c.triangles.reshape(-1).astype(np.int32), dtype=int),
                    velocities=wp.zeros(len(c.vertices), dtype=wp.vec3) if c.deforming else None,
                )
                if c.kind == "mesh"
                else None
                for c in order
            ]  # kept alive: the records hold their ids
            # a mesh's convex creases and open edges (the capsules of its edge_radius): a wp.Bvh each, kept alive
            self.creases = [_crease_arrays(c) if c.kind == "mesh" else None for c in order]
            records = [_record(c, m, e) for c, m, e in zip(order, self.meshes, self.creases)]
            self.rest = wp.array(records, dtype=ck.Collider)
            self.params = wp.array(records, dtype=ck.Collider)
            self._box = wp.zeros(
                2, dtype=wp.vec3
            )  # broad phase: the box around the non-plane colliders (kernels.collide.eval_collider_bounds)
            self.time = time if time is not None else wp.zeros(1, dtype=wp.float64)
            self.step_dt = step_dt if step_dt is not None else wp.zeros(1, dtype=wp.float64)
            self.substep = wp.array([0, 1], dtype=int)  # (k, S): the position-based substep k of S
            self.frame_times = frame_times if frame_times is not None else wp.zeros(4, dtype=wp.float64)
            self._moving, self.drives, seen = [], [], set()
            self._deforming = []  # (k, mesh, its points' keyframe arguments, creases or None, (min, max) scratch)
            for k, (c, record) in enumerate(zip(order, records)):
                if c.track is None:
                    continue
                if c.kind == "mesh" and c.deforming:
                    self._deforming.append(self._bind_deforming(k, c, seen))
                    continue
                if c.track.kind != "driven":
                    self._moving.append((ck.eval_collider_pose, k, c.track.launch_args()))
                    continue
                drive = c.track.drive
                if id(drive) in seen:
                    raise WarpclothError(
                        "a driven collider track moves one collider: give each its own ColliderTrack.driven()"
                    )
                seen.add(id(drive))
                turn = drive.bind_turn(device, np.array(record.bound_center, dtype=np.float64))
                self._moving.append((ck.eval_collider_driven_pose, k, [self.frame_times, *drive.bind(device), turn]))
                self.drives.append(drive)
        self._box_ready = False
        self._rounded_for = None  # the model whose triangles set the boxes' automatic edge radius (bind_model)
        self._edges = None  # ColliderEdges of the last model asked (edges)
        #: Hold the cloth off the edges and corners of static box and mesh colliders (:meth:`edges`,
        #: docs/self-collision.md). Off by default: with it the tablecloth does not come to rest (its
        #: hanging flaps keep moving at 1-6 cm/s over the table's edge) and a cube mesh and the analytic
        #: box drape a cloth up to 1 cm apart; set it before the first step.
        self.edge_contacts = False

    def bind_model(self, model) -> None:
        """Round the boxes' edges and the meshes' sharp creases for ``model``'s cloth (``edge_radius``
        None: :func:`~warpcloth.sim.colliders.auto_edge_radius` of its triangles at rest):
        host work at a model's first frame, nothing after; the records are rewritten in place, so a
        captured step reads the new radius."""
        rounded = [k for k, c in enumerate(self.order) if c.kind == "box" or self.creases[k] is not None]
        if self._rounded_for is model or not rounded:
            self._rounded_for = model
            return
        auto = auto_edge_radius(model.host.q, model.host.tris)
        rest = self.rest.numpy()
        posed = self.params.numpy()
        for k in rounded:
            c = self.order[k]
            rounding = c.rounding(auto)
            rest[k]["rounding"] = posed[k]["rounding"] = rounding
            if c.kind == "mesh":  # its box (the cheap rejection) grown by the capsules' reach past its surface
                rest[k]["b"] = posed[k]["b"] = np.asarray(_mesh_half(c, rounding), dtype=np.float32)
        self.rest.assign(rest)
        self.params.assign(posed)
        self._bound()  # the broad phase's box grows with the rounding
        self._rounded_for = model

    def roundings(self) -> list:
        """Each collider's rounding [m] as the kernels use it (boxes, and meshes with sharp creases; 0 for the
        others), in ``colliders`` order."""
        values = self.rest.numpy()["rounding"]
        where = {id(c): k for k, c in enumerate(self.order)}
        return [float(values[where[id(c)]]) for c in self.colliders]

    def _bind_deforming(self, k: int, c, seen: set) -> tuple:
        """A deforming mesh's pose arguments: its keys (a MeshTrack's, or a driven one's frame keys)."""
        track = c.track
        if track.kind == "driven":
            if id(track.drive) in seen:
                raise WarpclothError("a driven mesh track moves one mesh: give each its own MeshTrack.driven()")
            seen.add(id(track.drive))
            keys = [self.frame_times, *track.drive.bind(self.device)]
            self.drives.append(track.drive)
        else:
            tangents = track._key_tangents(c.vertices).reshape(-1, 3)
            keys = track._keyframe_args(track.points.reshape(-1, 3), tangents)
        creases = self.creases[k]
        if creases is not None:
            ends = wp.array(_convex_edges(c.vertices, c.triangles).astype(np.int32), dtype=wp.vec2i)
            creases = (creases, ends)
        return k, self.meshes[k], keys, creases, (wp.zeros(1, dtype=wp.vec3), wp.zeros(1, dtype=wp.vec3))

    @property
    def moving(self) -> bool:
        return bool(self._moving) or bool(self._deforming)

    @property
    def deforming(self) -> bool:
        """Whether a mesh collider deforms (a :class:`~warpcloth.sim.colliders.MeshTrack`)."""
        return bool(self._deforming)

    def edges(self, model) -> ColliderEdges | None:
        """The box and mesh colliders' edges and corners bound to ``model`` (:class:`ColliderEdges`, made
        at the first call for a model: host work, never inside a captured step), or None without them
        (or without cloth triangles, or with :attr:`edge_contacts` off)."""
        if not self.edge_contacts or not any(c.kind in ("box", "mesh") for c in self.colliders) or model.tri_count == 0:
            return None
        if self._deforming:
            raise WarpclothError(
                "edge_contacts hold the cloth off rigid colliders' edges; a deforming mesh's move: turn edge_contacts off"
            )
        if self._edges is None or self._edges.model is not model:
            self._edges = ColliderEdges(model, self)
        return self._edges

    def pose(self, offset: float = 0.0, substep: bool = False) -> None:
        """Move every tracked collider to its pose at t = time + offset, or with ``substep`` at
        the end of the current position-based substep, t + dt min(k + 1, S) / S (device
        launches only)."""
        for kernel, k, args in self._moving:
            wp.launch(
                kernel,
                dim=1,
                inputs=[self.time, wp.float64(offset), self.step_dt, self.substep, int(substep), k, self.rest, *args],
                outputs=[self.params],
                device=self.device,
            )
        for k, mesh, keys, creases, bounds in self._deforming:
            self._deform(k, mesh, keys, creases, bounds, offset, substep)
        if self.moving:
            self._bound()

    def _deform(self, k, mesh, keys, creases, bounds, offset: float, substep: bool) -> None:
        """A deforming mesh at t (as :meth:`pose`): its points and vertex velocities written into its
        wp.Mesh's own arrays, its BVH refitted (``wp.Mesh.refit``, on the device, no allocation), its
        creases moved and their BVH refitted, its record's box set around it."""
        d = self.device
        wp.launch(ck.reset_bounds, dim=1, inputs=[*bounds], device=d)
        wp.launch(
            ck.eval_mesh_points,
            dim=mesh.points.shape[0],
            inputs=[self.time, wp.float64(offset), self.step_dt, self.substep, int(substep), *keys],
            outputs=[mesh.points, mesh.velocities, *bounds],
            device=d,
        )
        mesh.refit()
        if creases is not None:
            (bvh, a, b, lo, hi), ends = creases
            wp.launch(
                ck.gather_creases, dim=ends.shape[0], inputs=[mesh.points, ends], outputs=[a, b, lo, hi], device=d
            )
            bvh.refit()
        wp.launch(ck.eval_deformed_record, dim=1, inputs=[k, self.rest, *bounds], outputs=[self.params], device=d)

    def begin_step(self) -> None:
        """At a step's start (Control.update): count its substeps from 0 (S = the last step's count)
        and pose the moving colliders at the first substep's end."""
        if self.moving:
            wp.launch(ck.begin_collider_step, dim=1, inputs=[self.substep], device=self.device)
            self.pose(substep=True)

    @property
    def box(self) -> wp.array:
        """The broad phase's box around the non-plane colliders (2,) vec3 [m]: computed at its first
        use (a step's, in the warm-up before any capture) and at every pose."""
        if not self._box_ready:
            self._bound()
        return self._box

    def _bound(self) -> None:
        wp.launch(
            ck.eval_collider_bounds,
            dim=1,
            inputs=[self.params, self.plane_count],
            outputs=[self._box],
            device=self.device,
        )
        self._box_ready = True

    def _broad_phase(self) -> list:
        return [self.params, self.box, self.plane_count]

    def project_velocity(self, model, state, dt: float, displacement=None, position_weight: float = 1.0) -> None:
        """After a force-based step (the control's time still at the step's start t): colliders
        posed at t + dt, then out of every collider, relative normal velocity removed, friction
        (``position_weight``: how a velocity change within the step moves x, see the kernels)."""
        self.pose(float(dt))
        d = displacement if displacement is not None else state.particle_qd
        wp.launch(
            ck.collide_velocity,
            dim=model.particle_count,
            inputs=[
                state.particle_q,
                state.particle_qd,
                model.particle_inv_mass,
                float(dt),
                float(position_weight),
                d,
                int(displacement is not None),
                *self._broad_phase(),
            ],
            device=model.device,
        )

    @property
    def has_friction(self) -> bool:
        """Whether any collider has a friction coefficient above 0."""
        return any(float(c.friction) > 0.0 for c in self.colliders)

    def project_displacement(
        self, model, x, dp, normal_correction, friction: bool, end_substep: bool | None = None
    ) -> None:
        """Inside a position-based solver: p = x + dp out of every collider (accumulating the
        normal corrections), or the friction pass after the iterations, relative to the
        colliders' motion over the substep.

        Moving colliders are posed at each substep's end: the friction pass, made once per
        substep, counts the substeps on the device (k of S, S counted in the step before; see
        :meth:`begin_step`), so no integrator needs to pass its substep times. ``end_substep``
        False keeps the substep's pose after the friction pass (the solver projects again, then
        calls :meth:`end_substep`); None: the friction pass ends it."""
        wp.launch(
            ck.collide_displacement,
            dim=model.particle_count,
            inputs=[
                int(friction),
                x,
                dp,
                model.particle_inv_mass,
                normal_correction,
                *self._broad_phase(),
                self.step_dt,
                self.substep,
            ],
            device=model.device,
        )
        if friction if end_substep is None else end_substep:
            self.end_substep()

    def end_substep(self) -> None:
        """A position-based substep ends: moving colliders take the next one's pose."""
        if self.moving:
            wp.launch(ck.next_collider_substep, dim=1, inputs=[self.substep], device=self.device)
            self.pose(substep=True)


class ColliderEdges:
    """The edges and corners of a :class:`ColliderSet`'s box and mesh colliders against a model's
    edges and triangles (:mod:`warpcloth.kernels.edge_contact`), bound once: the model's unique
    edges, each mesh collider's edges and vertices with their outward directions and a ``wp.Bvh``
    each (in the mesh's own frame). :meth:`project` launches kernels only."""

    #: Jacobi passes of :meth:`project` at most (a vertex's corrections are averaged over its contacts); the
    #: passes after one that moved no vertex return at once (a launch each). Measured on the 12 x 12 sharp-box
    #: tablecloth at 1/60 s: 8 left implicit_euler's and projective's cloth with 3-12 box edges through it,
    #: 16 projective's; 32 none, at 10-16 x 16 too (tests/test_self_collision.py)
    passes = 32
    #: passes of the projection once more after a strain limit (it knows no contacts: it moved implicit_euler's
    #: cloth back over the box's edge, 3-8 crossings a step; 4 passes sufficed, measured as above)
    passes_after_limit = 8

    def __init__(self, model, collision: ColliderSet):
        self.model, self.collision = model, collision
        tris = np.asarray(model.host.tris, dtype=np.int64).reshape(-1, 3)
        n, device = model.particle_count, model.device
        order = collision.order
        self.first = collision.plane_count
        edge_p, edge_q, edge_out, vertex, vertex_out = [], [], [], [], []
        edge_offset, vertex_offset = np.zeros(len(order), np.int32), np.zeros(len(order), np.int32)
        self._bvhs = []  # kept alive: the features hold their ids
        edge_ids, vertex_ids = np.zeros(len(order), np.uint64), np.zeros(len(order), np.uint64)
        with wp.ScopedDevice(device):
            for k, c in enumerate(order):
                if c.kind != "mesh":
                    continue
                p, e, e_out, vo = _mesh_features(c.vertices, c.triangles)
                if len(e) == 0:  # a flat mesh: its faces hold the cloth everywhere but at its vertices
                    e, e_out = np.zeros((1, 2), np.int64), np.zeros((1, 3))
                edge_offset[k], vertex_offset[k] = sum(len(a) for a in edge_p), sum(len(a) for a in vertex)
                edge_p.append(p[e[:, 0]]), edge_q.append(p[e[:, 1]]), edge_out.append(e_out)
                vertex.append(p), vertex_out.append(vo)
                bvh_e = wp.Bvh(
                    wp.array(np.minimum(p[e[:, 0]], p[e[:, 1]]), dtype=wp.vec3),
                    wp.array(np.maximum(p[e[:, 0]], p[e[:, 1]]), dtype=wp.vec3),
                )
                bvh_v = wp.Bvh(wp.array(p, dtype=wp.vec3), wp.array(p, dtype=wp.vec3))
                self._bvhs += [bvh_e, bvh_v]
                edge_ids[k], vertex_ids[k] = bvh_e.id, bvh_v.id

            def cat(parts):
                return wp.array(
                    np.concatenate(parts).astype(np.float32) if parts else np.zeros((1, 3), np.float32), dtype=wp.vec3
                )

            f = ek.MeshFeatures()
            f.edge_bvh, f.vertex_bvh = wp.array(edge_ids, dtype=wp.uint64), wp.array(vertex_ids, dtype=wp.uint64)
            f.edge_offset, f.vertex_offset = wp.array(edge_offset, dtype=int), wp.array(vertex_offset, dtype=int)
            f.edge_p, f.edge_q, f.edge_out = cat(edge_p), cat(edge_q), cat(edge_out)
            f.vertex, f.vertex_out = cat(vertex), cat(vertex_out)
            self.features = f
            self.edges = wp.array(mesh_topology(tris, n).edges.astype(np.int32), dtype=wp.vec2i)
            self.tris = wp.array(tris.astype(np.int32), dtype=wp.vec3i)
            self.dx, self.dv = wp.zeros(n, dtype=wp.vec3), wp.zeros(n, dtype=wp.vec3)
            self.count = wp.zeros(n, dtype=int)
            self.active = wp.zeros(2, dtype=int)  # vertices moved by a pass, by the next (collide_cloth_features)
            self._no_displacement = wp.zeros(1, dtype=wp.vec3)
            self.p, self.zero_v = wp.zeros(n, dtype=wp.vec3), wp.zeros(n, dtype=wp.vec3)
            #: per vertex, the direction the projections after the steps of this collision interval last pushed
            #: it out in (else 0; not those inside a solver's iterations): the self-collision's continuous
            #: response after them pushes it no further against it
            self.held = wp.zeros(n, dtype=wp.vec3)

    @staticmethod
    def needed(collision: ColliderSet | None) -> bool:
        """Whether ``collision`` has colliders with edges (box, mesh)."""
        return collision is not None and any(c.kind in ("box", "mesh") for c in collision.colliders)

    def _launch(self, x, v, k: int) -> None:
        # pass k: it reads the count of vertices pass k - 1 moved from active[k % 2] (pass 0 runs whatever it
        # holds) and its apply counts into active[(k + 1) % 2]
        m, c, d = self.model, self.collision, self.model.device
        lanes = self._lanes(max(self.edges.shape[0], self.tris.shape[0]))
        wp.launch(
            ek.collide_cloth_features,
            dim=lanes,
            inputs=[lanes, self.active, k % 2, (k + 1) % 2, int(k == 0), self.edges, self.tris, x, v]
            + [m.particle_inv_mass, c.params, self.first, self.features],
            outputs=[self.dx, self.dv, self.count],
            device=d,
        )

    def _lanes(self, items: int) -> int:
        # threads of a grid-stride launch: one per item on a GPU; one on the CPU, whose threads run one after
        # another anyway (in the same order: results as with a thread per item), so that a pass with nothing
        # to do costs a launch, not a return per item
        return items if wp.get_device(self.model.device).is_cuda else 1

    def project_increment(self, x, dp) -> None:
        """Inside a position-based solver's iterations (pbd, xpbd, vbd, projective): the same contacts at
        p = x + dp, corrections added to ``dp`` (positions only)."""
        n, d = self.model.particle_count, self.model.device
        wp.launch(ek.eval_positions, dim=n, inputs=[x, dp], outputs=[self.p], device=d)
        self._launch(self.p, self.zero_v, 0)
        wp.launch(ek.apply_edge_increments, dim=n, inputs=[self.dx, self.dv, self.count], outputs=[dp], device=d)

    def project(
        self, state, dt: float, displacement=None, position_weight: float = 1.0, passes: int | None = None
    ) -> None:
        """After a step's per-vertex contacts (colliders posed at its end): cloth edges out of the
        colliders' edges and triangles off their corners, to the thickness, with the approaching
        relative normal velocity removed; pinned vertices stay. ``passes`` at most (default
        :attr:`passes`): each after one that moved no vertex returns at once."""
        m, d = self.model, self.model.device
        x, v = state.particle_q, state.particle_qd
        out = [self.dx, self.dv, self.count]
        disp = displacement if displacement is not None else self._no_displacement
        lanes = self._lanes(m.particle_count)
        for k in range(self.passes if passes is None else passes):
            self._launch(x, v, k)
            wp.launch(
                ek.apply_edge_contacts,
                dim=lanes,
                inputs=[lanes, float(position_weight) * float(dt), int(displacement is not None), *out, self.active]
                + [k % 2, (k + 1) % 2, int(k == 0)],
                outputs=[x, v, disp, self.held],
                device=d,
            )

    def begin_step(self) -> None:
        """A collision interval's projections start (each step where the self-collision's intervals are one
        step): no vertex pushed out yet (:attr:`held`)."""
        self.held.zero_()


def _mesh_features(vertices, triangles):
    """A mesh's vertices (V, 3), its crease edges (E, 2) with each one's outward direction (the
    normalised sum of its faces' unit normals) and each vertex's (the angle-weighted pseudo-normal),
    float64. Edges between coplanar faces (a face's diagonal: normals within 2.6 degrees) are not
    features: the face holds the cloth there, as the analytic box's faces do; an open edge (one face)
    is one."""
    p = np.asarray(vertices, dtype=np.float64)
    t = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    face = np.cross(p[t[:, 1]] - p[t[:, 0]], p[t[:, 2]] - p[t[:, 0]])
    unit = face / np.maximum(np.linalg.norm(face, axis=1, keepdims=True), 1e-300)
    edges = mesh_topology(t, len(p)).edges
    keys = edges[:, 0] * len(p) + edges[:, 1]  # sorted (mesh_topology sorts its packed keys)
    e_out = np.zeros((len(edges), 3))
    faces_at = np.zeros(len(edges), np.int64)
    first = np.zeros((len(edges), 3))
    crease = np.zeros(len(edges), dtype=bool)
    for a, b in ((0, 1), (1, 2), (2, 0)):
        k = np.searchsorted(keys, np.minimum(t[:, a], t[:, b]) * len(p) + np.maximum(t[:, a], t[:, b]))
        np.add.at(e_out, k, unit)
        np.add.at(faces_at, k, 1)
        seen = faces_at[k] > 1  # the edge's second face: a crease where it turns from the first
        crease[k[seen]] |= np.einsum("ij,ij->i", first[k[seen]], unit[seen]) < 0.999
        first[k[~seen]] = unit[~seen]
    crease |= faces_at == 1
    v_out = np.zeros_like(p)
    for k in range(3):  # the angle of each face at its corner k
        e1, e2 = p[t[:, (k + 1) % 3]] - p[t[:, k]], p[t[:, (k + 2) % 3]] - p[t[:, k]]
        cos = np.einsum("ij,ij->i", e1, e2) / np.maximum(
            np.linalg.norm(e1, axis=1) * np.linalg.norm(e2, axis=1), 1e-300
        )
        np.add.at(v_out, t[:, k], np.arccos(np.clip(cos, -1.0, 1.0))[:, None] * unit)

    def normalised(a):
        return a / np.maximum(np.linalg.norm(a, axis=1, keepdims=True), 1e-300)

    return p, edges[crease], normalised(e_out[crease]), normalised(v_out)


def starting_inside(colliders, points, free, t: float = 0.0) -> list[tuple[int, str, int]]:
    """The colliders that free cloth vertices start inside: (index in ``colliders``, the collider in
    words, how many of the ``free`` (N,) bool vertices of ``points`` (N, 3) have phi < 0 at time
    ``t``), on the host. A vertex inside is pushed out at the first step (often with a spring
    strain far past any limit); mesh colliders are not checked here."""
    x = np.asarray(points, dtype=np.float64)[np.asarray(free, dtype=bool)]
    found = []
    for k, c in enumerate(colliders or ()):
        posed = c.at(t) if c.track is not None else c
        phi = signed_distance(posed, x)
        if phi is not None and (inside := int(np.count_nonzero(phi < 0.0))):
            found.append((k, describe(posed), inside))
    return found


#: A mesh crease turning by this much or more [degrees] is rounded like a box's edge (_convex_edges)
SHARP_CREASE_DEGREES = 30.0


def _convex_edges(vertices, triangles) -> np.ndarray:
    """The edges (E, 2) of a mesh that can stand between a cloth's vertices: its sharp convex creases
    (the other face's far vertex behind a face's plane, the faces turning by :data:`SHARP_CREASE_DEGREES`
    or more), its open edges (one face) and any edge of more than two faces. A concave crease (a
    valley) is not one, nor a tessellated curve's blunt edge: over an edge turning by theta, a cloth
    edge of length s resting on both faces dips (s / 2) tan(theta / 2) below their shells, 1.3 mm for
    a 2 cm cloth edge at 15 degrees, within a thickness of a few mm; capsules along every edge of a
    mesh sphere would instead hold the cloth off it by their radius. Copies of a vertex at one place
    (within 1e-7 of the mesh's size) are one vertex. Convex and concave are told by the faces'
    winding, which must be consistent (outward, as the mesh query's inside and outside need too)."""
    p = np.asarray(vertices, dtype=np.float64)
    t = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    # vertices at one place count as one (a UV seam's or a triangle soup's copies: else every seam is two
    # open edges, rounded into a ridge); the edges come back as indices of the first copy
    scale = max(float(np.ptp(p, axis=0).max()), 1e-300)
    _, first, merged = np.unique(np.round(p / (1e-7 * scale)), axis=0, return_index=True, return_inverse=True)
    t = first[merged.reshape(-1)][t]
    face = np.cross(p[t[:, 1]] - p[t[:, 0]], p[t[:, 2]] - p[t[:, 0]])
    unit = face / np.maximum(np.linalg.norm(face, axis=1, keepdims=True), 1e-300)
    i = np.concatenate([t[:, 0], t[:, 1], t[:, 2]])
    j = np.concatenate([t[:, 1], t[:, 2], t[:, 0]])
    far = np.concatenate([t[:, 2], t[:, 0], t[:, 1]])
    owner = np.tile(np.arange(len(t)), 3)
    lo, hi = np.minimum(i, j), np.maximum(i, j)
    order = np.lexsort((hi, lo))
    lo, hi, far, owner = lo[order], hi[order], far[order], owner[order]
    start = np.flatnonzero(np.r_[True, (lo[1:] != lo[:-1]) | (hi[1:] != hi[:-1])])
    count = np.diff(np.r_[start, len(lo)])
    keep = count != 2
    two = start[count == 2]
    f1, f2 = owner[two], owner[two + 1]
    ahead = np.einsum("ij,ij->i", p[far[two + 1]] - p[lo[two]], unit[f1])  # < 0: behind face 1's plane
    bent = np.einsum("ij,ij->i", unit[f1], unit[f2]) < np.cos(np.radians(SHARP_CREASE_DEGREES))
    convex = np.zeros(len(start), dtype=bool)
    convex[count == 2] = bent & (ahead < 0.0)
    return np.stack([lo[start], hi[start]], axis=1)[keep | convex]


def _crease_arrays(c):
    """(bvh, a, b) of a mesh collider's :func:`_convex_edges` (device arrays, its own frame), or None
    without any."""
    edges = _convex_edges(c.vertices, c.triangles)
    if len(edges) == 0:
        return None
    v = np.asarray(c.vertices, dtype=np.float32)
    a, b = wp.array(v[edges[:, 0]], dtype=wp.vec3), wp.array(v[edges[:, 1]], dtype=wp.vec3)
    lo = wp.array(np.minimum(v[edges[:, 0]], v[edges[:, 1]]), dtype=wp.vec3)
    hi = wp.array(np.maximum(v[edges[:, 0]], v[edges[:, 1]]), dtype=wp.vec3)
    return wp.Bvh(lo, hi), a, b, lo, hi


def _mesh_half(c, rounding: float = 0.0):
    """A mesh collider's box half size for the cheap rejection: grown by its thickness, its reach (a
    particle up to reach inside is still found; a flat mesh has no height) and its creases' rounding,
    and a float32 margin (rounding never rejects a contact)."""
    lo, hi = c.vertices.min(axis=0), c.vertices.max(axis=0)
    half = 0.5 * (hi - lo) + c.thickness + c.reach + rounding
    return wp.vec3(*(half * (1.0 + 1e-5) + 1e-6))


def _record(c, mesh=None, creases=None):
    """The rest :class:`~warpcloth.kernels.collide.Collider` record of a collider (``mesh``: the
    wp.Mesh of a MeshCollider, ``creases`` its :func:`_crease_arrays`)."""
    r = ck.Collider()
    r.kind = KINDS.index(c.kind)
    r.radius = float(getattr(c, "radius", 0.0))
    r.rotation = wp.mat33(np.eye(3, dtype=np.float32))
    r.thickness, r.mu = float(c.thickness), float(c.friction)
    if c.kind == "plane":
        r.a, r.b = wp.vec3(*c.point), wp.vec3(*c.normal)
        r.bound_center = wp.vec3(*c.point)
    elif c.kind == "sphere":
        r.a = r.bound_center = wp.vec3(*c.center)
    elif c.kind == "capsule":
        a, b = np.asarray(c.a), np.asarray(c.b)
        r.a, r.b = wp.vec3(*a), wp.vec3(*b)
        r.bound_center = wp.vec3(*(0.5 * (a + b)))
    elif c.kind == "mesh":
        lo, hi = c.vertices.min(axis=0), c.vertices.max(axis=0)
        r.a = r.bound_center = r.rest_center = wp.vec3(*(0.5 * (lo + hi)))
        r.radius = float(c.reach)
        r.mesh = mesh.id
        if creases is not None:
            r.crease_bvh, r.crease_a, r.crease_b = creases[0].id, creases[1], creases[2]
            r.rounding = c.rounding(0.0)  # edge_radius None: 0 until bind_model
        r.b = _mesh_half(c, r.rounding)
        r.deforming = int(c.deforming)
    else:
        r.a = r.bound_center = wp.vec3(*c.center)
        r.b = wp.vec3(*c.half_extents)
        r.rotation = wp.mat33(quat_matrix(c.rotation).astype(np.float32))
        r.rounding = c.rounding(0.0)  # edge_radius None: 0 until bind_model
    r.velocity = r.omega = r.origin = wp.vec3(0.0, 0.0, 0.0)
    r.moving = 0
    return r


__all__ = ["ColliderEdges", "ColliderSet", "starting_inside"]
