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
from warpcloth.sim.colliders import COLLIDER_TYPES, KINDS, _quat_matrix, describe, signed_distance


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
        self.plane_count = sum(c.kind == "plane" for c in order)
        with wp.ScopedDevice(device):
            self.meshes = [
                wp.Mesh(
                    points=wp.array(c.vertices, dtype=wp.vec3),
                    indices=wp.array(c.triangles.reshape(-1).astype(np.int32), dtype=int),
                )
                if c.kind == "mesh"
                else None
                for c in order
            ]  # kept alive: the records hold their ids
            records = [_record(c, m) for c, m in zip(order, self.meshes)]
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
            for k, (c, record) in enumerate(zip(order, records)):
                if c.track is None:
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

    @property
    def moving(self) -> bool:
        return bool(self._moving)

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
        if self._moving:
            self._bound()

    def begin_step(self) -> None:
        """At a step's start (Control.update): count its substeps from 0 (S = the last step's count)
        and pose the moving colliders at the first substep's end."""
        if self._moving:
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

    def project_displacement(self, model, x, dp, normal_correction, friction: bool) -> None:
        """Inside a position-based solver: p = x + dp out of every collider (accumulating the
        normal corrections), or the friction pass after the iterations, relative to the
        colliders' motion over the substep.

        Moving colliders are posed at each substep's end: the friction pass, made once per
        substep, counts the substeps on the device (k of S, S counted in the step before; see
        :meth:`begin_step`), so no integrator needs to pass its substep times."""
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
        if friction and self._moving:  # the substep ends: the next one's pose
            wp.launch(ck.next_collider_substep, dim=1, inputs=[self.substep], device=self.device)
            self.pose(substep=True)


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


def _record(c, mesh=None):
    """The rest :class:`~warpcloth.kernels.collide.Collider` record of a collider (``mesh``: the
    wp.Mesh of a MeshCollider)."""
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
        half = (
            0.5 * (hi - lo) + c.thickness + c.reach
        )  # a particle up to reach inside is still found (a flat mesh has no height)
        r.a = r.bound_center = r.rest_center = wp.vec3(*(0.5 * (lo + hi)))
        r.b = wp.vec3(*(half * (1.0 + 1e-5) + 1e-6))  # float32 rounding never rejects a contact
        r.radius = float(c.reach)
        r.mesh = mesh.id
    else:
        r.a = r.bound_center = wp.vec3(*c.center)
        r.b = wp.vec3(*c.half_extents)
        r.rotation = wp.mat33(_quat_matrix(c.rotation).astype(np.float32))
    r.velocity = r.omega = r.origin = wp.vec3(0.0, 0.0, 0.0)
    r.moving = 0
    return r


__all__ = ["ColliderSet", "starting_inside"]
