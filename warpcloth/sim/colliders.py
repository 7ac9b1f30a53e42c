"""Colliders: an infinite plane, a sphere, a capsule, an oriented box and a triangle mesh
(:class:`MeshCollider`), each with a thickness (the cloth's offset from the surface) [m] and a
Coulomb friction coefficient mu, given to :class:`~warpcloth.sim.control.Control` as ``colliders=(...)``.
Any of them may move rigidly on a :class:`ColliderTrack` (keyframed offsets
or a rigid motion, as pin tracks, or a pose your own loop sets each frame:
:meth:`ColliderTrack.driven`), posed on the device inside the step.

The quaternion helpers convert a box's rotation (x, y, z, w) to and from a matrix. On the device
the colliders are a :class:`~warpcloth.sim.contacts.ColliderSet` (:mod:`warpcloth.sim.contacts`:
records, broad phase, and how each integrator handles contact).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import warp as wp

from warpcloth.errors import WarpclothError, require, require_non_negative, require_positive, require_vector
from warpcloth.sim.mesh import check_mesh
from warpcloth.sim.pins import PinTrack
from warpcloth.sim.tracks import FrameDrive, HostWrite, Track, check_keyframes, check_rigid, interpolate

#: Collider kinds in the order of their kernel launches (the kernels' ``kind`` argument).
KINDS = ("plane", "sphere", "capsule", "box", "mesh")


def _material(thickness, friction):
    return require_non_negative("collider thickness", thickness, "m"), require_non_negative(
        "collider friction mu", friction
    )


def _track(c):
    if c.track is None or isinstance(c.track, ColliderTrack):
        return
    if c.kind == "mesh" and isinstance(c.track, MeshTrack):
        return
    also = " or, for a mesh, a MeshTrack (its vertices over time)" if c.kind == "mesh" else ""
    raise WarpclothError(
        f"{c.kind} track must be a ColliderTrack (ColliderTrack.keyframes, .rigid or .driven){also}, got {c.track!r:.80}"
    )


@dataclass(frozen=True, eq=False)
class ColliderTrack(Track):
    """A rigid pose track for a collider: keyframed translation ``offsets`` (K, 3) [m], or a rigid
    motion y -> c + u t + R(axis, theta(t)) (y - c) with theta(t) = omega t + A sin(2 pi f t + phi),
    as for :class:`~warpcloth.sim.pins.PinTrack` (both are :class:`~warpcloth.sim.tracks.Track` s).
    The collider as given is its pose at offset 0 / time 0. Evaluated on the device inside the
    step; its velocity field v_c(y) = d'(t) + theta'(t) axis x (y - c - d(t)) is what friction is
    relative to."""

    offsets: np.ndarray | None = None  # (K, 3) [m]

    @property
    def keys(self) -> np.ndarray | None:
        return self.offsets

    @classmethod
    def keyframes(cls, times, offsets, interpolation: str = "linear", tangents=None) -> ColliderTrack:
        """Translation offsets [m] (K, 3) at K increasing times [s], added to the collider as
        given; ``interpolation`` ``"linear"``, ``"catmull_rom"`` or ``"hermite"`` (with
        ``tangents`` [m/s], (K, 3)), as :meth:`PinTrack.keyframes <warpcloth.sim.pins.PinTrack.keyframes>`;
        it holds still before the first key and after the last."""
        offsets = np.asarray(offsets, dtype=np.float64) if not isinstance(offsets, (str, bytes)) else offsets
        t, v, tan = check_keyframes("collider track", times, offsets, interpolation, tangents, 1)
        if v.ndim != 2:
            raise WarpclothError(f"collider track offsets must have shape (K, 3), got {np.shape(offsets)}")
        return cls(kind="keyframes", times=t, offsets=v, tangents=tan, interpolation=interpolation)

    @classmethod
    def rigid(
        cls,
        center=(0.0, 0.0, 0.0),
        axis=(0.0, 0.0, 1.0),
        angular_velocity: float = 0.0,
        swing_amplitude: float = 0.0,
        swing_frequency: float = 0.0,
        swing_phase: float = 0.0,
        velocity=(0.0, 0.0, 0.0),
    ) -> ColliderTrack:
        """A rigid motion: ``center`` c [m] on the rotation ``axis`` at t = 0, ``angular_velocity``
        omega [rad/s], a swing A [rad] at f [Hz] with phase phi [rad], translation ``velocity`` u [m/s]."""
        motion = check_rigid(
            "collider track", center, axis, angular_velocity, swing_amplitude, swing_frequency, swing_phase, velocity
        )
        return cls(**motion)

    @classmethod
    def from_table(cls, table) -> ColliderTrack:
        """A track from a scenario file's ``track = { kind = "rigid", velocity = [0.5, 0, 0] }`` or
        ``{ kind = "keyframes", times = [...], offsets = [[...], ...], interpolation = "linear" }``."""
        if not isinstance(table, dict):
            raise WarpclothError(
                f'collider track must be a table {{ kind = "keyframes" | "rigid", ... }}, got {table!r:.80}'
            )
        keys = {
            "keyframes": ("times", "offsets", "interpolation", "tangents"),
            "rigid": (
                "center",
                "axis",
                "angular_velocity",
                "swing_amplitude",
                "swing_frequency",
                "swing_phase",
                "velocity",
            ),
        }
        kind = table.get("kind")
        if kind not in keys:
            raise WarpclothError(f"collider track kind must be 'keyframes' or 'rigid', got {kind!r}")
        unknown = sorted(set(table) - {"kind", *keys[kind]})
        if unknown:
            raise WarpclothError(
                f"collider track ({kind}): unknown key {unknown[0]!r} (allowed: {', '.join(keys[kind])})"
            )
        args = {k: v for k, v in table.items() if k != "kind"}
        if kind == "keyframes":
            for need in ("times", "offsets"):
                require(need in args, f"collider track (keyframes) needs {need}")
            try:
                return cls.keyframes(**args)
            except (TypeError, ValueError) as exc:
                raise WarpclothError(f"collider track (keyframes): {exc}") from None
        return cls.rigid(**args)

    @classmethod
    def driven(cls, interpolation: str = "linear") -> ColliderTrack:
        """A pose that your loop sets each frame: ``track.set(offset, rotation)`` (or
        :meth:`Simulator.set_collider_pose <warpcloth.simulator.Simulator.set_collider_pose>`)
        says where the collider is at the end of the next ``simulate()`` call, and its steps
        move it there: the offset as a linear (or, with ``"hermite"``, cubic) keyframed
        translation, the rotation about the collider's centre at a constant rate (friction sees
        that velocity). The pose goes into device arrays the captured frame already reads, so
        it costs a copy, not a capture. Give one driven track to one collider."""
        return cls(kind="driven", interpolation=interpolation, drive=ColliderDrive(interpolation))

    def set(self, offset=(0.0, 0.0, 0.0), rotation=None, velocity=None) -> None:
        """A driven track's pose at the end of the next frame: the collider as given, turned by
        the unit quaternion ``rotation`` (x, y, z, w; None: as given) about its centre (a
        sphere's or a box's centre, a capsule's midpoint, a plane's point, a mesh's box centre)
        and moved by ``offset`` [m]; ``velocity`` [m/s] of the offset there (``"hermite"`` only)."""
        require(
            self.kind == "driven", f"collider track is {self.kind}, not driven: only ColliderTrack.driven takes poses"
        )
        self.drive.set_pose(offset, rotation, velocity)

    def transform(self, t: float):
        """(rotation matrix R (3, 3), centre c, offset d) at time t [s]: y -> c + d + R (y - c)."""
        if self.kind == "driven":
            return self.drive.transform(t)
        if self.kind == "rigid":
            theta, _ = self._angle(t)
            a = np.asarray(self.axis)
            k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
            r = math.cos(theta) * np.eye(3) + math.sin(theta) * k + (1 - math.cos(theta)) * np.outer(a, a)
            return r, np.asarray(self.center, dtype=np.float64), np.asarray(self.velocity) * t
        d, _ = self._evaluate(t, np.zeros((1, 3)))
        return np.eye(3), np.zeros(3), d[0]

    def pose(self, t: float):
        """(R (3, 3), T (3,)) at time t [s]: the track moves a point y to R y + T (T = c + d - R c)."""
        r, c, d = self.transform(t)
        c = np.asarray(c, dtype=np.float64)
        return r, c + d - r @ c

    def launch_args(self) -> list:
        """The pose kernel's track arguments (device arrays made once, on the current device)."""
        if self.kind == "driven":
            raise WarpclothError("a driven collider track's arguments come from its drive (ColliderSet binds it)")
        if self.kind == "rigid":
            dummy = wp.zeros(1, dtype=wp.float64), wp.zeros(1, dtype=wp.vec3d)
            return [1, *self._rigid_args(), dummy[0], dummy[1], dummy[1], 0]
        zero = wp.vec3d(0.0, 0.0, 0.0)
        tangents = self._key_tangents(np.zeros((1, 3))).reshape(-1, 3)
        return [
            0,
            zero,
            wp.vec3d(0.0, 0.0, 1.0),
            zero,
            wp.vec4d(0.0, 0.0, 0.0, 0.0),
            *self._keyframe_args(self.offsets, tangents),
        ]


class ColliderDrive(FrameDrive):
    """A :class:`~warpcloth.sim.tracks.FrameDrive` of a collider's offset (one point), and its
    turn: the rotation R0 at the frame's start and the (axis, angle) of R1 R0^T to the target,
    in a device array of two ``vec4d`` (R0 as x, y, z, w; axis and angle [rad]) that the driven
    pose kernel reads (:func:`warpcloth.kernels.collide.eval_collider_driven_pose`)."""

    def __init__(self, interpolation: str = "linear"):
        super().__init__("driven collider", 1, interpolation)
        self.start(np.zeros((1, 3)))
        self.rotation = np.array([0.0, 0.0, 0.0, 1.0])  # (x, y, z, w) at the end of the last frame
        self.center = np.zeros(3)  # the collider's centre as given (bind)
        self._turn = None  # the pending rotation target
        self._turn_keys = (np.array([0.0, 0.0, 0.0, 1.0]), np.array([0.0, 0.0, 1.0]), 0.0)  # (R0, axis, angle)
        self.turn = None

    def set_pose(self, offset, rotation=None, velocity=None) -> None:
        q = (
            self.rotation
            if rotation is None
            else np.asarray(require_vector("driven collider rotation", rotation, 4), dtype=np.float64)
        )
        require(
            np.linalg.norm(q) > 0.0,
            f"driven collider rotation must be a non-zero quaternion (x, y, z, w), got {rotation!r}",
        )
        self.set(require_vector("driven collider offset", offset, 3, "m"), None if velocity is None else [velocity])
        self._turn = q / np.linalg.norm(q)

    def bind_turn(self, device, center) -> wp.array:
        """The device array of the turn (holding the current rotation), for a collider centred at ``center``."""
        self.center = np.asarray(center, dtype=np.float64)
        self._turn_write = HostWrite(np.array([self.rotation, [0.0, 0.0, 1.0, 0.0]]), wp.vec4d, device)
        self.turn = self._turn_write.array
        self._turn_keys = (self.rotation.copy(), np.array([0.0, 0.0, 1.0]), 0.0)
        return self.turn

    def upload(self, t0: float, t1: float) -> bool:
        """Write the next frame's offset keys (:meth:`FrameDrive.upload`) and its turn: from the
        rotation now to the one set (the short way round), or none (a held frame)."""
        target, self._turn = self._turn, None
        q0, axis, angle = self.rotation, np.array([0.0, 0.0, 1.0]), 0.0
        if target is not None:
            target = -target if np.dot(target, q0) < 0.0 else target
            rel = _quat_mul(target, _quat_conj(q0))  # R1 R0^T
            s = float(np.linalg.norm(rel[:3]))
            if s > 0.0:
                axis, angle = rel[:3] / s, 2.0 * math.atan2(s, float(rel[3]))
        if not super().upload(t0, t1):
            return False
        self._turn_write.write(np.array([q0, [*axis, angle]]))
        self._turn_keys, self._turn_frame = (q0.copy(), axis, angle), (t0, t1)
        if target is not None:
            self.rotation = target.copy()
        return True

    def transform(self, t: float):
        """(R (3, 3), centre c, offset d) at time t [s] within the last frame: y -> c + d + R (y - c)."""
        d, _ = self.evaluate(t)
        q0, axis, angle = self._turn_keys
        r = quat_matrix(q0)
        if angle != 0.0:
            t0, t1 = self._turn_frame
            theta = angle * min(max((float(t) - t0) / (t1 - t0), 0.0), 1.0)
            k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
            r = (math.cos(theta) * np.eye(3) + math.sin(theta) * k + (1 - math.cos(theta)) * np.outer(axis, axis)) @ r
        return r, self.center, d[0]


@dataclass(frozen=True, eq=False)
class MeshTrack(Track):
    """A deforming :class:`MeshCollider`'s vertices over time (its ``track``): keyframed points
    ``points`` (K, V, 3) [m] at K increasing ``times`` (a skinned body's frames, a USD mesh's
    time-sampled points), or points that your loop sets each frame (:meth:`driven`). The steps
    interpolate them on the device (linear by default: between frames each vertex moves at
    v = (p_new - p_old) / frame time, the velocity friction is relative to), write them into the
    mesh's own device arrays and refit its BVH (``wp.Mesh.refit``): no allocation, no capture.
    The mesh as given (``vertices``) is its rest pose: attachments (:func:`attach`) are found there."""

    points: np.ndarray | None = None  # (K, V, 3) [m]

    @property
    def keys(self) -> np.ndarray | None:
        return self.points

    @classmethod
    def keyframes(cls, times, points, interpolation: str = "linear", tangents=None) -> MeshTrack:
        """The mesh's V vertices at K increasing ``times`` [s]: ``points`` (K, V, 3) [m]; held
        before the first key and after the last; ``interpolation`` as :meth:`ColliderTrack.keyframes`."""
        v = np.asarray(points, dtype=np.float64) if not isinstance(points, (str, bytes)) else points
        count = int(np.shape(v)[1]) if np.ndim(v) == 3 else 0
        require(count > 0, f"mesh track points must have shape (K, V, 3), got {np.shape(points)}")
        t, v, tan = check_keyframes("mesh track", times, v, interpolation, tangents, count)
        return cls(kind="keyframes", times=t, points=v, tangents=tan, interpolation=interpolation)

    @classmethod
    def driven(cls, interpolation: str = "linear") -> MeshTrack:
        """Points that your loop sets each frame: ``track.set(points)`` says where the V vertices
        are at the end of the next ``simulate()`` call (a :class:`~warpcloth.sim.tracks.FrameDrive`:
        the steps interpolate to it; one copy into the arrays a captured frame reads). Give one
        driven track to one collider."""
        return cls(kind="driven", interpolation=interpolation, drive=MeshDrive(interpolation))

    def set(self, points, velocities=None) -> None:
        """A driven track's vertices (V, 3) [m] at the end of the next frame (and, ``"hermite"``,
        their velocities [m/s]); attachments to the mesh (:func:`attach`) follow."""
        require(self.kind == "driven", f"mesh track is {self.kind}, not driven: only MeshTrack.driven takes points")
        self.drive.set(points, velocities)

    def evaluate(self, t: float, rest: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(points (V, 3) [m], velocities (V, 3) [m/s]) at time t [s] on the host, float64 (the
        kernels' formulas); ``rest`` (V, 3): the mesh as given (a driven track before its first frame)."""
        if self.kind == "driven":
            return self.drive.evaluate(t)
        cubic = self.interpolation != "linear"
        return interpolate(self.times, self.points, self._key_tangents(rest) if cubic else None, float(t))

    def pose(self, t: float):
        raise WarpclothError("a mesh track deforms its mesh: it has no rigid pose (use collider.at(t))")


class MeshDrive(FrameDrive):
    """The :class:`~warpcloth.sim.tracks.FrameDrive` of a driven :class:`MeshTrack`: its V points
    are the mesh's vertices (known when the track is given to a :class:`MeshCollider`); the driven
    pin tracks of attachments to it (:func:`attach`) take the barycentric points of each target."""

    def __init__(self, interpolation: str = "linear"):
        super().__init__("driven mesh collider", 0, interpolation)
        self.followers = []  # (FrameDrive of an attachment's pins, faces (P, 3) vertex indices, weights (P, 3))

    def attach_mesh(self, vertices: np.ndarray) -> None:
        """Start at the mesh's ``vertices`` (V, 3) (a second mesh of another vertex count is refused)."""
        count = len(vertices)
        if self.points == 0:
            self.points = count
            self.velocity = np.zeros((count, 3))
            self.start(vertices)
        require(
            self.points == count,
            f"a driven mesh track moves one mesh: this one has {self.points} vertices, not {count}; "
            "give each mesh collider its own MeshTrack.driven()",
        )

    def set(self, positions, velocities=None) -> None:
        require(self.points > 0, "a driven mesh track takes points once it is a MeshCollider's track")
        super().set(positions, velocities)
        p, v = self._pending
        for drive, faces, weights in self.followers:
            drive.set(
                _barycentric(p, faces, weights), _barycentric(v, faces, weights) if velocities is not None else None
            )


def _barycentric(points: np.ndarray, faces: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """sum_j w_j p[face_j] (P, 3) of ``points`` (..., V, 3), float64."""
    p = np.asarray(points, dtype=np.float64)
    return np.einsum("...pjc,pj->...pc", p[..., faces, :], weights)


def closest_surface_points(vertices, triangles, points) -> tuple[np.ndarray, np.ndarray]:
    """(triangle index (P,), barycentric weights (P, 3)) of the point of the mesh ``vertices`` (V, 3),
    ``triangles`` (T, 3) nearest each of ``points`` (P, 3), on the host in float64 (Ericson's
    closest point on a triangle, every triangle tried: attachments are found once, at rest)."""
    v = np.asarray(vertices, dtype=np.float64)
    tri = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    a, b, c = v[tri[:, 0]], v[tri[:, 1]], v[tri[:, 2]]
    ab, ac = b - a, c - a
    faces, weights = [], []
    for p in np.asarray(points, dtype=np.float64).reshape(-1, 3):
        ap, bp, cp = p - a, p - b, p - c
        d1, d2 = np.einsum("ij,ij->i", ab, ap), np.einsum("ij,ij->i", ac, ap)
        d3, d4 = np.einsum("ij,ij->i", ab, bp), np.einsum("ij,ij->i", ac, bp)
        d5, d6 = np.einsum("ij,ij->i", ab, cp), np.einsum("ij,ij->i", ac, cp)
        va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
        with np.errstate(divide="ignore", invalid="ignore"):
            denom = va + vb + vc
            w = np.stack([va, vb, vc], axis=1) / denom[:, None]  # inside the face
            regions = [
                (d1 <= 0) & (d2 <= 0),  # vertex a
                (d3 >= 0) & (d4 <= d3),  # vertex b
                (d6 >= 0) & (d5 <= d6),  # vertex c
                (vc <= 0) & (d1 >= 0) & (d3 <= 0),  # edge ab
                (vb <= 0) & (d2 >= 0) & (d6 <= 0),  # edge ac
                (va <= 0) & ((d4 - d3) >= 0) & ((d5 - d6) >= 0),  # edge bc
            ]
            s_ab, s_ac = d1 / (d1 - d3), d2 / (d2 - d6)
            s_bc = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        one, zero = np.ones_like(d1), np.zeros_like(d1)
        fixes = [
            np.stack([one, zero, zero], 1),
            np.stack([zero, one, zero], 1),
            np.stack([zero, zero, one], 1),
            np.stack([1 - s_ab, s_ab, zero], 1),
            np.stack([1 - s_ac, zero, s_ac], 1),
            np.stack([zero, 1 - s_bc, s_bc], 1),
        ]
        for region, fix in reversed(list(zip(regions, fixes))):  # the first region that holds wins
            w = np.where(region[:, None], fix, w)
        w = np.where(np.isfinite(w), w, 1.0 / 3.0)
        q = w[:, :1] * a + w[:, 1:2] * b + w[:, 2:] * c
        k = int(np.argmin(np.einsum("ij,ij->i", q - p, q - p)))
        faces.append(k)
        weights.append(w[k])
    return np.asarray(faces, dtype=np.int64), np.asarray(weights, dtype=np.float64).reshape(-1, 3)


def attach(collider, cloth_points, particles, name: str = "attached") -> PinTrack:
    """Pins attached to a mesh collider's surface: each of ``particles`` (P pinned cloth vertex
    indices, e.g. a pin group's) is tied to the point of the mesh nearest its rest position
    ``cloth_points[i]`` [m] (the mesh as given: its rest pose), as a triangle and barycentric
    weights w, and follows sum_j w_j p_j(t) of that triangle's vertices as the mesh deforms. Returns
    a :class:`~warpcloth.sim.pins.PinTrack` for the control's pin tracks: keyframed (the weights
    applied to the mesh track's keys: with linear or Hermite keys, the same point as the weights
    applied to the interpolated vertices), driven (it takes the barycentric points of each
    ``track.set(points)``), or held (a static mesh). The pinned particles start on the surface.
    Its ``faces`` (P,) and ``weights`` (P, 3) attributes say where each is tied."""
    require(isinstance(collider, MeshCollider), f"attach: the collider must be a MeshCollider, got {collider!r:.80}")
    track = collider.track
    require(
        track is None or isinstance(track, MeshTrack),
        "attach: the mesh must be static or deform on a MeshTrack (for a rigid ColliderTrack, give the pins a "
        "PinTrack of the same motion)",
    )
    idx = np.asarray(particles, dtype=np.int64).reshape(-1)
    x = np.asarray(cloth_points, dtype=np.float64).reshape(-1, 3)
    require(idx.size > 0, "attach: no particles given (an empty pin group?)")
    bad = idx[(idx < 0) | (idx >= len(x))]
    require(bad.size == 0, f"attach: particle {int(bad[0]) if bad.size else 0} is out of range 0..{len(x) - 1}")
    faces, weights = closest_surface_points(collider.vertices, collider.triangles, x[idx])
    corners = collider.triangles[faces]
    if track is None:
        pins = PinTrack.keyframes(idx, [0.0], _barycentric(collider.vertices, corners, weights)[None], name=name)
    elif track.kind == "driven":
        pins = PinTrack.driven(idx, interpolation=track.interpolation, name=name)
        pins.drive.start(_barycentric(track.drive.position, corners, weights))
        track.drive.followers.append((pins.drive, corners, weights))
    else:
        keys = _barycentric(track.points, corners, weights)
        tangents = _barycentric(track.tangents, corners, weights) if track.tangents is not None else None
        pins = PinTrack.keyframes(idx, track.times, keys, track.interpolation, tangents, name=name)
    object.__setattr__(pins, "faces", faces)
    object.__setattr__(pins, "weights", weights)
    return pins


def _quat_mul(a, b) -> np.ndarray:
    """The product a b of quaternions (x, y, z, w)."""
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return np.array(
        [
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz,
        ]
    )


def _quat_conj(q) -> np.ndarray:
    return np.array([-q[0], -q[1], -q[2], q[3]])


class _Posed:
    """What every collider kind shares: its kind name, a track, its pose at a time."""

    @property
    def kind(self) -> str:
        return type(self).__name__.lower()

    def at(self, t: float):
        """This collider where its track puts it at time t [s], as a static collider."""
        if self.track is None:
            return self
        r, shift = self.track.pose(float(t))
        move = lambda y: tuple(shift + r @ np.asarray(y, dtype=np.float64))  # noqa: E731
        return self._moved(move, r)


@dataclass(frozen=True)
class Plane(_Posed):
    """The infinite plane through ``point`` with outward ``normal`` (normalised); default the ground y = 0."""

    point: tuple = (0.0, 0.0, 0.0)
    normal: tuple = (0.0, 1.0, 0.0)
    thickness: float = 0.0
    friction: float = 0.0
    track: ColliderTrack | None = None

    def __post_init__(self):
        n = np.asarray(require_vector("plane normal", self.normal), dtype=np.float64)
        require(np.linalg.norm(n) > 0.0, f"plane normal must not be zero, got {self.normal!r}")
        object.__setattr__(self, "normal", tuple(n / np.linalg.norm(n)))
        object.__setattr__(self, "point", require_vector("plane point", self.point, 3, "m"))
        _material(self.thickness, self.friction)
        _track(self)

    def _moved(self, move, r):
        return Plane(
            point=move(self.point),
            normal=tuple(r @ np.asarray(self.normal)),
            thickness=self.thickness,
            friction=self.friction,
        )


@dataclass(frozen=True)
class Sphere(_Posed):
    center: tuple = (0.0, 0.0, 0.0)
    radius: float = 0.5
    thickness: float = 0.0
    friction: float = 0.0
    track: ColliderTrack | None = None

    def __post_init__(self):
        object.__setattr__(self, "center", require_vector("sphere center", self.center, 3, "m"))
        require_positive("sphere radius", self.radius, "m")
        _material(self.thickness, self.friction)
        _track(self)

    def _moved(self, move, r):
        return Sphere(center=move(self.center), radius=self.radius, thickness=self.thickness, friction=self.friction)


@dataclass(frozen=True)
class Capsule(_Posed):
    """The points within ``radius`` of the segment from ``a`` to ``b``."""

    a: tuple = (0.0, 0.0, 0.0)
    b: tuple = (1.0, 0.0, 0.0)
    radius: float = 0.1
    thickness: float = 0.0
    friction: float = 0.0
    track: ColliderTrack | None = None

    def __post_init__(self):
        object.__setattr__(self, "a", require_vector("capsule a", self.a, 3, "m"))
        object.__setattr__(self, "b", require_vector("capsule b", self.b, 3, "m"))
        require_positive("capsule radius", self.radius, "m")
        _material(self.thickness, self.friction)
        _track(self)

    def _moved(self, move, r):
        return Capsule(
            a=move(self.a), b=move(self.b), radius=self.radius, thickness=self.thickness, friction=self.friction
        )


@dataclass(frozen=True)
class Box(_Posed):
    """An oriented box: ``center``, ``half_extents`` (all > 0) and a rotation quaternion
    (x, y, z, w), normalised.

    ``edge_radius`` [m]: the distance the cloth's particles keep from the box's 12 edges and 8
    corners (the faces keep ``thickness``): the contact surface is the box grown by ``thickness``
    with capsules of this radius along its edges. A point of a triangle is never farther than the
    triangle's circumradius from all three of its vertices, so while every cloth triangle's
    circumradius is below R, an edge R or more from every particle cannot pass through the cloth.
    None (the default): :func:`auto_edge_radius` of the cloth the box is bound to (its largest
    circumradius at rest, 20 % to spare for stretch), the thickness where that is larger; 0: the
    sharp box (particles alone, at the thickness). docs/colliders.md."""

    center: tuple = (0.0, 0.0, 0.0)
    half_extents: tuple = (0.5, 0.5, 0.5)
    rotation: tuple = (0.0, 0.0, 0.0, 1.0)
    thickness: float = 0.0
    friction: float = 0.0
    track: ColliderTrack | None = None
    edge_radius: float | None = None

    def __post_init__(self):
        object.__setattr__(self, "center", require_vector("box center", self.center, 3, "m"))
        half = require_vector("box half_extents", self.half_extents, 3, "m")
        if not all(h > 0.0 for h in half):
            raise WarpclothError(
                f"box half_extents must all be > 0 m (a degenerate box has no inside), got {self.half_extents!r}"
            )
        object.__setattr__(self, "half_extents", half)
        q = np.asarray(require_vector("box rotation", self.rotation, 4), dtype=np.float64)
        require(
            np.linalg.norm(q) > 0.0, f"box rotation must be a non-zero quaternion (x, y, z, w), got {self.rotation!r}"
        )
        object.__setattr__(self, "rotation", tuple(q / np.linalg.norm(q)))
        _material(self.thickness, self.friction)
        if self.edge_radius is not None:
            object.__setattr__(self, "edge_radius", require_non_negative("box edge_radius", self.edge_radius, "m"))
        _track(self)

    def _moved(self, move, r):
        return Box(
            center=move(self.center),
            half_extents=self.half_extents,
            rotation=matrix_quat(r @ quat_matrix(self.rotation)),
            thickness=self.thickness,
            friction=self.friction,
            edge_radius=self.edge_radius,
        )

    def rounding(self, auto_radius: float) -> float:
        """The box's edges' radius beyond its thickness [m] (the kernels' ``rounding``): its
        ``edge_radius``, or ``auto_radius`` where that is None, less the thickness; >= 0."""
        return _rounding(self, auto_radius)


def _rounding(c, auto_radius: float) -> float:
    radius = auto_radius if c.edge_radius is None else c.edge_radius
    return max(float(radius) - float(c.thickness), 0.0)


#: Box.edge_radius None: the cloth's largest triangle circumradius at rest times this (the stretch it may take)
AUTO_EDGE_STRETCH = 1.2


def auto_edge_radius(points, triangles) -> float:
    """:data:`AUTO_EDGE_STRETCH` times the largest "reach" of ``triangles`` (T, 3) over ``points``
    (N, 3) [m]: a triangle's circumradius abc / (4 area), or its longest edge / sqrt(2) where that is
    smaller (an obtuse triangle lies in the circle on its longest edge, so each of its points is
    within that of two vertices); 0 without triangles. The grid's right triangles: half the diagonal."""
    tris = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    if tris.size == 0:
        return 0.0
    x = np.asarray(points, dtype=np.float64)
    p, q, r = x[tris[:, 0]], x[tris[:, 1]], x[tris[:, 2]]
    a, b, c = (np.linalg.norm(u, axis=1) for u in (q - r, r - p, p - q))
    area2 = np.linalg.norm(np.cross(q - p, r - p), axis=1)  # twice the area
    longest = np.maximum(np.maximum(a, b), c)
    with np.errstate(divide="ignore", invalid="ignore"):
        circum = np.where(area2 > 0.0, a * b * c / (2.0 * area2), np.inf)
    return AUTO_EDGE_STRETCH * float(np.minimum(circum, longest / np.sqrt(2.0)).max())


@dataclass(frozen=True, eq=False)
class MeshCollider(_Posed):
    """A triangle mesh (``wp.Mesh``, queried with ``wp.mesh_query_point_sign_normal``):
    ``vertices`` (N, 3) [m], ``triangles`` (T, 3) vertex indices; it may move rigidly on a
    ``track`` (the BVH stays in the mesh's own frame and each particle is taken into it). Inside and
    outside come from the nearest face's normal, so a closed mesh should have its triangles wound
    outward (counter-clockwise seen from outside); an open one pushes particles to its front side. A
    particle more than ``reach`` [m] inside is not found (it went through; keep reach above a step's
    motion). ``edge_radius`` [m]: as a :class:`Box`'s, about the mesh's convex creases and open
    edges (None: from the cloth; 0: sharp)."""

    vertices: np.ndarray = None
    triangles: np.ndarray = None
    thickness: float = 0.0
    friction: float = 0.0
    reach: float = 0.05
    track: ColliderTrack | None = None
    source: str = ""
    edge_radius: float | None = None

    def __post_init__(self):
        what = f"mesh collider {self.source!r}" if self.source else "mesh collider"
        if (
            self.vertices is None
            or self.triangles is None
            or np.size(self.triangles) == 0
            or np.size(self.vertices) == 0
        ):
            raise WarpclothError(
                f"{what} is empty (no "
                f"{'vertices' if self.vertices is None or np.size(self.vertices) == 0 else 'triangles'}): give at "
                "least one triangle"
            )
        v, t = check_mesh(self.vertices, self.triangles, what=what)
        object.__setattr__(self, "vertices", v)
        object.__setattr__(self, "triangles", t)
        _material(self.thickness, self.friction)
        require_positive("mesh collider reach", self.reach, "m")
        if self.edge_radius is not None:
            object.__setattr__(
                self, "edge_radius", require_non_negative("mesh collider edge_radius", self.edge_radius, "m")
            )
        _track(self)
        if isinstance(self.track, MeshTrack):
            if self.track.kind == "driven":
                self.track.drive.attach_mesh(self.vertices)
            elif self.track.points.shape[1] != len(self.vertices):
                raise WarpclothError(
                    f"{what}: its mesh track moves {self.track.points.shape[1]} vertices, the mesh has "
                    f"{len(self.vertices)}"
                )

    @property
    def deforming(self) -> bool:
        """Whether its vertices move on a :class:`MeshTrack`."""
        return isinstance(self.track, MeshTrack)

    def at(self, t: float):
        """This collider at time t [s] as a static one (a deforming mesh's points then)."""
        if not self.deforming:
            return super().at(t)
        points, _ = self.track.evaluate(float(t), self.vertices)
        return self._static_with(points)

    def rounding(self, auto_radius: float) -> float:
        """The radius about its convex creases beyond its thickness [m] (as :meth:`Box.rounding`)."""
        return _rounding(self, auto_radius)

    def _static_with(self, vertices) -> MeshCollider:
        """This collider's settings on ``vertices``, without a track (:meth:`at`, :meth:`_moved`)."""
        return MeshCollider(
            vertices=vertices,
            triangles=self.triangles,
            thickness=self.thickness,
            friction=self.friction,
            reach=self.reach,
            source=self.source,
            edge_radius=self.edge_radius,
        )

    def _moved(self, move, r):
        shift = np.asarray(move((0.0, 0.0, 0.0)))  # T of y -> R y + T
        return self._static_with(shift + self.vertices @ r.T)

    @staticmethod
    def check_settings(
        thickness: float = 0.0, friction: float = 0.0, reach: float = 0.05, edge_radius: float | None = None
    ) -> None:
        """Check a mesh collider's settings before its mesh is read (a text description's)."""
        _material(thickness, friction)
        require_positive("mesh collider reach", reach, "m")
        if edge_radius is not None:
            require_non_negative("mesh collider edge_radius", edge_radius, "m")

    def __repr__(self):
        return (
            f"MeshCollider({self.source or 'in memory'}: {len(self.vertices)} vertices, {len(self.triangles)} "
            f"triangles, thickness={self.thickness}, friction={self.friction}, reach={self.reach}, "
            f"edge_radius={self.edge_radius})"
        )

    @property
    def kind(self) -> str:
        return "mesh"


def signed_distance(c, points) -> np.ndarray | None:
    """phi (P,) [m] of ``points`` (P, 3) from collider ``c`` as it is given (negative inside; its
    thickness not counted), on the host in float64; None for a mesh (inside is the device's)."""
    x = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if c.kind == "plane":
        return (x - np.asarray(c.point)) @ np.asarray(c.normal)
    if c.kind == "sphere":
        return np.linalg.norm(x - np.asarray(c.center), axis=1) - c.radius
    if c.kind == "capsule":
        a, b = np.asarray(c.a), np.asarray(c.b)
        ab = b - a
        t = np.clip((x - a) @ ab / max(float(ab @ ab), 1e-20), 0.0, 1.0)
        return np.linalg.norm(x - (a + t[:, None] * ab), axis=1) - c.radius
    if c.kind == "box":
        p = (x - np.asarray(c.center)) @ quat_matrix(c.rotation)  # R^T (x - c), row-wise
        q = np.abs(p) - np.asarray(c.half_extents)
        return np.linalg.norm(np.maximum(q, 0.0), axis=1) + np.minimum(q.max(axis=1), 0.0)
    return None


def box_edge_distance(c, points) -> np.ndarray:
    """The distance [m] of ``points`` (P, 3) from the nearest of box ``c``'s 12 edges (segments), on
    the host in float64."""
    x = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    u = np.abs((x - np.asarray(c.center)) @ quat_matrix(c.rotation)) - np.asarray(c.half_extents)
    along = [np.where(np.arange(3) == i, np.maximum(u, 0.0), u) for i in range(3)]  # to the edges along axis i
    return np.min([np.linalg.norm(w, axis=1) for w in along], axis=0)


def describe(c) -> str:
    """A collider in a few words, for messages: ``sphere at (0, 0.3, 0), radius 0.5``."""
    v = lambda p: "(" + ", ".join(f"{float(u):.3g}" for u in p) + ")"  # noqa: E731
    if c.kind == "plane":
        return f"plane through {v(c.point)}, normal {v(c.normal)}"
    if c.kind == "sphere":
        return f"sphere at {v(c.center)}, radius {c.radius:g}"
    if c.kind == "capsule":
        return f"capsule {v(c.a)}-{v(c.b)}, radius {c.radius:g}"
    if c.kind == "box":
        return f"box at {v(c.center)}, half extents {v(c.half_extents)}"
    return f"mesh collider {c.source or ''}".strip()


COLLIDER_TYPES = {"plane": Plane, "sphere": Sphere, "capsule": Capsule, "box": Box, "mesh": MeshCollider}


def quat_matrix(q) -> np.ndarray:
    """The rotation matrix of a unit quaternion (x, y, z, w)."""
    x, y, z, w = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def matrix_quat(m: np.ndarray) -> tuple:
    """A unit quaternion (x, y, z, w) of a rotation matrix (Shepperd's method)."""
    t = np.trace(m)
    if t > 0:
        s = 2.0 * math.sqrt(t + 1.0)
        q = ((m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s, 0.25 * s)
    else:
        k = int(np.argmax(np.diag(m)))
        i, j = (k + 1) % 3, (k + 2) % 3
        s = 2.0 * math.sqrt(1.0 + m[k, k] - m[i, i] - m[j, j])
        v = [0.0, 0.0, 0.0]
        v[k] = 0.25 * s
        v[i] = (m[i, k] + m[k, i]) / s
        v[j] = (m[j, k] + m[k, j]) / s
        q = (*v, (m[j, i] - m[i, j]) / s)
    q = np.asarray(q)
    return tuple(float(c) for c in q / np.linalg.norm(q))


__all__ = [
    "COLLIDER_TYPES",
    "KINDS",
    "Box",
    "Capsule",
    "ColliderDrive",
    "ColliderTrack",
    "MeshCollider",
    "MeshDrive",
    "MeshTrack",
    "Plane",
    "Sphere",
    "attach",
    "closest_surface_points",
    "describe",
    "matrix_quat",
    "quat_matrix",
    "signed_distance",
]
