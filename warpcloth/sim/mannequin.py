"""A procedural animated body: a mannequin of capsules (hips, torso, shoulders, neck, head, thighs,
shins, upper arms, forearms), each a closed triangle mesh, skinned to 11 bones by linear blend
skinning, x = sum_b w_b M_b(t) x_rest, with limbs blended half-and-half with their parent at the
joint over one limb radius (knees and elbows bend smoothly). It marches in place (thighs lift
forward, knees bend, arms swing against the legs) while turning left and right about the vertical
axis, motion eased in from rest over :data:`EASE_IN` seconds, so its pose at t = 0 is the bind pose.
The body faces +z, y up, its feet at y = 0 and its head at 1.75 m.

:meth:`Mannequin.track` samples the skinned points as :class:`~warpcloth.sim.colliders.MeshTrack`
keyframes for a deforming :class:`~warpcloth.sim.colliders.MeshCollider`; :meth:`Mannequin.offset`
is the same skin moved out along its normals (an attachment surface for garments held just off the
skin, so a pinned row's chords stay outside the body). The character scenario dresses it
(docs/character.md).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from warpcloth.errors import require, require_int, require_non_negative, require_positive
from warpcloth.sim.colliders import MeshCollider, MeshTrack

#: Seconds over which the motion's amplitudes rise from 0 (a smoothstep): the body starts at rest.
EASE_IN = 0.5
#: The marching step's period [s] (one left and one right step) and the turn's period [s].
STEP_PERIOD = 1.2
TURN_PERIOD = 4.0
#: Peak angles [rad]: thigh lift, knee bend, arm swing, turn (yaw either side).
THIGH_LIFT = math.radians(25.0)
KNEE_BEND = math.radians(40.0)
ARM_SWING = math.radians(15.0)
TURN = math.radians(35.0)

# bone: (parent, joint position at rest [m])
BONES = {
    "root": (None, (0.0, 0.95, 0.0)),
    "spine": ("root", (0.0, 1.05, 0.0)),
    "head": ("spine", (0.0, 1.47, 0.0)),
    "thigh_l": ("root", (0.09, 0.9, 0.0)),
    "shin_l": ("thigh_l", (0.09, 0.5, 0.0)),
    "thigh_r": ("root", (-0.09, 0.9, 0.0)),
    "shin_r": ("thigh_r", (-0.09, 0.5, 0.0)),
    "arm_l": ("spine", (0.2, 1.4, 0.0)),
    "forearm_l": ("arm_l", (0.3, 1.15, 0.0)),
    "arm_r": ("spine", (-0.2, 1.4, 0.0)),
    "forearm_r": ("arm_r", (-0.3, 1.15, 0.0)),
}
# capsule: (bone, end a, end b, radius [m]); a limb's end a is its joint with the parent bone
CAPSULES = (
    ("root", (-0.06, 0.92, 0.0), (0.06, 0.92, 0.0), 0.11),
    ("spine", (0.0, 0.98, 0.0), (0.0, 1.3, 0.0), 0.14),
    ("spine", (-0.19, 1.4, 0.0), (0.19, 1.4, 0.0), 0.065),
    ("head", (0.0, 1.42, 0.0), (0.0, 1.52, 0.0), 0.05),
    ("head", (0.0, 1.6, 0.02), (0.0, 1.65, 0.02), 0.1),
    ("thigh_l", (0.09, 0.9, 0.0), (0.09, 0.5, 0.0), 0.075),
    ("shin_l", (0.09, 0.5, 0.0), (0.09, 0.08, 0.0), 0.055),
    ("thigh_r", (-0.09, 0.9, 0.0), (-0.09, 0.5, 0.0), 0.075),
    ("shin_r", (-0.09, 0.5, 0.0), (-0.09, 0.08, 0.0), 0.055),
    ("arm_l", (0.2, 1.4, 0.0), (0.3, 1.15, 0.0), 0.045),
    ("forearm_l", (0.3, 1.15, 0.0), (0.37, 0.92, 0.0), 0.04),
    ("arm_r", (-0.2, 1.4, 0.0), (-0.3, 1.15, 0.0), 0.045),
    ("forearm_r", (-0.3, 1.15, 0.0), (-0.37, 0.92, 0.0), 0.04),
)
#: Bones whose capsules blend with their parent's at the joint (the limbs).
BLENDED = ("thigh_l", "shin_l", "thigh_r", "shin_r", "arm_l", "forearm_l", "arm_r", "forearm_r")


def capsule_mesh(a, b, radius: float, segments: int = 12, rings: int = 4) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A closed capsule mesh about the segment ab: (vertices (V, 3) [m], triangles (T, 3) wound
    outward, axial parameter s (V,) [m] of each vertex along ab from a, negative on a's cap).
    ``segments`` around, ``rings`` latitude steps per hemisphere, the two poles single vertices."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    axis = b - a
    length = float(np.linalg.norm(axis))
    e = axis / length
    helper = np.array([1.0, 0.0, 0.0]) if abs(e[0]) < 0.9 else np.array([0.0, 0.0, 1.0])
    u = np.cross(e, helper)
    u /= np.linalg.norm(u)
    w = np.cross(e, u)
    # latitudes from a's pole (-pi/2) to b's pole (+pi/2); the cylinder between the two equators
    lat = np.concatenate(
        [np.linspace(-0.5 * math.pi, 0.0, rings + 1)[1:], np.linspace(0.0, 0.5 * math.pi, rings + 1)[:-1]]
    )
    centre = np.concatenate([np.zeros(rings), np.full(rings, length)])
    phi = 2.0 * math.pi * np.arange(segments) / segments
    ring_dirs = np.cos(phi)[:, None] * u + np.sin(phi)[:, None] * w
    verts, s = [a - radius * e], [-radius]
    for la, c in zip(lat, centre):
        verts.extend(a + (c + radius * math.sin(la)) * e + radius * math.cos(la) * ring_dirs)
        s.extend([c + radius * math.sin(la)] * segments)
    verts.append(b + radius * e)
    s.append(length + radius)
    n_rings = len(lat)
    tris = []
    for j in range(segments):
        k = (j + 1) % segments
        tris.append((0, 1 + k, 1 + j))  # a's pole fan
        top = 1 + (n_rings - 1) * segments
        tris.append((len(verts) - 1, top + j, top + k))  # b's pole fan
    for r in range(n_rings - 1):
        for j in range(segments):
            k = (j + 1) % segments
            p, q = 1 + r * segments, 1 + (r + 1) * segments
            tris.append((p + j, p + k, q + k))
            tris.append((p + j, q + k, q + j))
    return np.asarray(verts), np.asarray(tris, dtype=np.int64), np.asarray(s)


def vertex_normals(vertices, triangles) -> np.ndarray:
    """Unit vertex normals (..., V, 3) of ``vertices`` (..., V, 3) (one pose or K keyframes): the
    area-weighted normals of the faces around each vertex (triangles wound outward)."""
    v, t = np.asarray(vertices, dtype=np.float64), np.asarray(triangles, dtype=np.int64)
    face = np.cross(v[..., t[:, 1], :] - v[..., t[:, 0], :], v[..., t[:, 2], :] - v[..., t[:, 0], :])
    n = np.zeros_like(v)
    for k in range(3):
        np.add.at(n, (..., t[:, k], slice(None)), face)
    return n / np.maximum(np.linalg.norm(n, axis=-1, keepdims=True), 1e-300)


def offset_collider(collider: MeshCollider, distance: float) -> MeshCollider:
    """A mesh collider's surface moved ``distance`` [m] out along its vertex normals, at rest and at
    every key of its :class:`~warpcloth.sim.colliders.MeshTrack` (a static mesh stays static): a
    surface to :func:`~warpcloth.sim.colliders.attach` a garment's pinned rows to, so that they ride
    just off the skin (pins on the skin itself put the chords between them inside a convex body)."""
    require(isinstance(collider, MeshCollider), f"offset_collider takes a MeshCollider, got {collider!r:.80}")
    d = require_non_negative("offset distance", distance, "m")
    tris = collider.triangles
    rest = collider.vertices + d * vertex_normals(collider.vertices, tris)
    track = collider.track
    if isinstance(track, MeshTrack) and track.kind == "keyframes":
        keys = track.points + d * vertex_normals(track.points, tris)
        track = MeshTrack.keyframes(track.times, keys, interpolation=track.interpolation)
    else:
        require(track is None, "offset_collider: the mesh must be static or on MeshTrack keyframes")
    return MeshCollider(vertices=rest, triangles=tris, track=track, source=f"{collider.source} offset {d:g} m")


def _rotation(axis, angle: float) -> np.ndarray:
    x, y, z = np.asarray(axis, dtype=np.float64) / np.linalg.norm(axis)
    k = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    return np.eye(3) + math.sin(angle) * k + (1.0 - math.cos(angle)) * (k @ k)


def _smoothstep(x: float) -> float:
    x = min(max(x, 0.0), 1.0)
    return x * x * (3.0 - 2.0 * x)


@dataclass(frozen=True)
class Mannequin:
    """The body's bind pose and skinning: ``vertices`` (V, 3) [m], ``triangles`` (T, 3) wound
    outward (one closed capsule per :data:`CAPSULES` entry, the capsules overlapping at the joints),
    ``weights`` (V, B) of the B bones of :data:`BONES` (rows sum to 1). ``scale`` multiplies every
    length (1: 1.75 m tall); ``motion`` multiplies every angle (0: it stands still)."""

    vertices: np.ndarray
    triangles: np.ndarray
    weights: np.ndarray
    scale: float = 1.0
    motion: float = 1.0

    @classmethod
    def build(cls, scale: float = 1.0, motion: float = 1.0, segments: int = 12, rings: int = 4) -> Mannequin:
        """The mannequin at ``scale``, ``segments`` around each capsule and ``rings`` per cap."""
        scale = require_positive("mannequin scale", scale)
        motion = require_non_negative("mannequin motion", motion)
        segments = require_int("mannequin segments", segments, 6)
        rings = require_int("mannequin rings", rings, 2)
        names = list(BONES)
        verts, tris, weights = [], [], []
        offset = 0
        for bone, a, b, radius in CAPSULES:
            v, t, s = capsule_mesh(a, b, radius, segments, rings)
            w = np.zeros((len(v), len(names)))
            own = np.ones(len(v))
            if bone in BLENDED:  # half-and-half at the joint, all the bone's one radius past it
                own = np.clip(0.5 + 0.5 * s / radius, 0.0, 1.0)
                w[:, names.index(BONES[bone][0])] = 1.0 - own
            w[:, names.index(bone)] += own
            verts.append(v * scale)
            tris.append(t + offset)
            weights.append(w)
            offset += len(v)
        return cls(np.concatenate(verts), np.concatenate(tris), np.concatenate(weights), scale, motion)

    def bone_transforms(self, t: float) -> np.ndarray:
        """(B, 3, 4) world transforms [R | T] of the bones at time t [s], x -> R x + T of a bind-pose
        point; the identity at t <= 0."""
        ease = _smoothstep(float(t) / EASE_IN) * self.motion
        phase = 2.0 * math.pi * float(t) / STEP_PERIOD
        lift = {"l": 0.5 * (1.0 - math.cos(phase)), "r": 0.5 * (1.0 + math.cos(phase))}  # 0..1, alternating
        yaw = ease * TURN * math.sin(2.0 * math.pi * float(t) / TURN_PERIOD)
        local = {"root": _rotation((0.0, 1.0, 0.0), yaw), "spine": np.eye(3), "head": np.eye(3)}
        x_axis = (1.0, 0.0, 0.0)
        for side in ("l", "r"):
            other = "r" if side == "l" else "l"
            local[f"thigh_{side}"] = _rotation(x_axis, -ease * THIGH_LIFT * lift[side])  # the knee forward
            local[f"shin_{side}"] = _rotation(x_axis, ease * KNEE_BEND * lift[side])  # the foot back
            local[f"arm_{side}"] = _rotation(x_axis, -ease * ARM_SWING * (lift[other] - 0.5) * 2.0)
            local[f"forearm_{side}"] = _rotation(x_axis, -ease * 0.5 * ARM_SWING * lift[other])
        world = {}
        for name, (parent, joint) in BONES.items():
            j = np.asarray(joint) * self.scale
            m = np.concatenate([local[name], (j - local[name] @ j)[:, None]], axis=1)  # about the joint
            if parent is not None:
                p = world[parent]
                m = np.concatenate([p[:, :3] @ m[:, :3], (p[:, :3] @ m[:, 3] + p[:, 3])[:, None]], axis=1)
            world[name] = m
        return np.stack([world[n] for n in BONES])

    def pose(self, t: float, vertices: np.ndarray | None = None) -> np.ndarray:
        """The skinned points (V, 3) [m] at time t [s]: sum_b w_b (R_b x + T_b) of ``vertices``
        (default the bind pose; :meth:`offset`'s points skin the same way)."""
        x = self.vertices if vertices is None else np.asarray(vertices, dtype=np.float64)
        m = self.bone_transforms(t)
        moved = np.einsum("bij,vj->vbi", m[:, :, :3], x) + m[None, :, :, 3]  # (V, B, 3)
        return np.einsum("vb,vbi->vi", self.weights, moved)

    def offset(self, distance: float) -> np.ndarray:
        """The bind pose moved ``distance`` [m] out along its vertex normals (:func:`vertex_normals`)."""
        d = require_non_negative("offset distance", distance, "m")
        return self.vertices + d * vertex_normals(self.vertices, self.triangles)

    def track(self, duration: float, fps: float = 60.0, vertices: np.ndarray | None = None) -> MeshTrack:
        """:class:`~warpcloth.sim.colliders.MeshTrack` keyframes of :meth:`pose` at every 1/fps from 0
        to past ``duration`` [s] (linear between keys)."""
        require_positive("duration", duration, "s")
        require_positive("fps", fps, "1/s")
        times = np.arange(math.ceil(duration * fps) + 2) / fps
        return MeshTrack.keyframes(times, np.stack([self.pose(t, vertices) for t in times]))

    def collider(self, duration: float, fps: float = 60.0, vertices=None, **settings) -> MeshCollider:
        """A deforming :class:`~warpcloth.sim.colliders.MeshCollider` of this body (or of ``vertices``
        skinned as it, e.g. :meth:`offset`'s) on :meth:`track`; ``settings``: thickness, friction, reach."""
        v = self.vertices if vertices is None else np.asarray(vertices, dtype=np.float64)
        require(v.shape == self.vertices.shape, f"vertices must have shape {self.vertices.shape}, got {v.shape}")
        return MeshCollider(
            vertices=v, triangles=self.triangles, track=self.track(duration, fps, v), source="mannequin", **settings
        )


__all__ = ["BONES", "CAPSULES", "EASE_IN", "Mannequin", "capsule_mesh", "offset_collider", "vertex_normals"]
