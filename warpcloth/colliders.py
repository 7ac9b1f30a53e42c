"""Colliders: an infinite plane, a sphere, a capsule and an oriented box, each with a thickness
(the cloth's offset from the surface) [m] and a Coulomb friction coefficient mu, given to
:class:`~warpcloth.forces.Control` as ``colliders=(...)``.

How each integrator handles contact (kernels in :mod:`warpcloth.kernels.collide`):

* force-based (explicit_euler, midpoint, rk4, verlet) and implicit_euler: a projection after
  the step with a velocity correction, in the Simulator's step after the integrator: no
  particle ends a step inside a collider; the approaching normal velocity is removed and the
  tangential velocity reduced by mu times that change (Coulomb), the tangential change applied
  to the position as well. RK stages may pass through a collider within a step (only the step's
  end is projected); Verlet's displacement d = x - x_prev is reset to v dt for a contact, so its
  history does not carry the particle back in. Chosen because it is the same, exact-to-the-surface
  rule for every force-based scheme and costs one launch per collider kind per step.
* pbd / xpbd: collision constraints projected inside the solver loop (Müller et al. 2007,
  Alg. 1 line 13) on the predicted displacement, and friction after the iterations from the
  accumulated normal correction.

Pins win over contacts: pinned particles are never moved by a collider. Colliders are static in
this version (no pose tracks yet).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import warp as wp

from .errors import WarpclothError, require, require_non_negative, require_positive, require_vector

#: Collider kinds in the order of their kernel launches (the kernels' ``kind`` argument).
KINDS = ("plane", "sphere", "capsule", "box")


def _material(thickness, friction):
    return require_non_negative("collider thickness", thickness, "m"), require_non_negative("collider friction mu", friction)


@dataclass(frozen=True)
class Plane:
    """The infinite plane through ``point`` with outward ``normal`` (normalised); default the ground y = 0."""

    point: tuple = (0.0, 0.0, 0.0)
    normal: tuple = (0.0, 1.0, 0.0)
    thickness: float = 0.0
    friction: float = 0.0

    def __post_init__(self):
        n = np.asarray(require_vector("plane normal", self.normal), dtype=np.float64)
        require(np.linalg.norm(n) > 0.0, f"plane normal must not be zero, got {self.normal!r}")
        object.__setattr__(self, "normal", tuple(n / np.linalg.norm(n)))
        object.__setattr__(self, "point", require_vector("plane point", self.point, 3, "m"))
        _material(self.thickness, self.friction)


@dataclass(frozen=True)
class Sphere:
    center: tuple = (0.0, 0.0, 0.0)
    radius: float = 0.5
    thickness: float = 0.0
    friction: float = 0.0

    def __post_init__(self):
        object.__setattr__(self, "center", require_vector("sphere center", self.center, 3, "m"))
        require_positive("sphere radius", self.radius, "m")
        _material(self.thickness, self.friction)


@dataclass(frozen=True)
class Capsule:
    """The points within ``radius`` of the segment from ``a`` to ``b``."""

    a: tuple = (0.0, 0.0, 0.0)
    b: tuple = (1.0, 0.0, 0.0)
    radius: float = 0.1
    thickness: float = 0.0
    friction: float = 0.0

    def __post_init__(self):
        object.__setattr__(self, "a", require_vector("capsule a", self.a, 3, "m"))
        object.__setattr__(self, "b", require_vector("capsule b", self.b, 3, "m"))
        require_positive("capsule radius", self.radius, "m")
        _material(self.thickness, self.friction)


@dataclass(frozen=True)
class Box:
    """An oriented box: ``center``, ``half_extents`` (all > 0) and a rotation quaternion
    (x, y, z, w), normalised."""

    center: tuple = (0.0, 0.0, 0.0)
    half_extents: tuple = (0.5, 0.5, 0.5)
    rotation: tuple = (0.0, 0.0, 0.0, 1.0)
    thickness: float = 0.0
    friction: float = 0.0

    def __post_init__(self):
        object.__setattr__(self, "center", require_vector("box center", self.center, 3, "m"))
        half = require_vector("box half_extents", self.half_extents, 3, "m")
        if not all(h > 0.0 for h in half):
            raise WarpclothError(f"box half_extents must all be > 0 m (a degenerate box has no inside), got {self.half_extents!r}")
        object.__setattr__(self, "half_extents", half)
        q = np.asarray(require_vector("box rotation", self.rotation, 4), dtype=np.float64)
        require(np.linalg.norm(q) > 0.0, f"box rotation must be a non-zero quaternion (x, y, z, w), got {self.rotation!r}")
        object.__setattr__(self, "rotation", tuple(q / np.linalg.norm(q)))
        _material(self.thickness, self.friction)


COLLIDER_TYPES = {"plane": Plane, "sphere": Sphere, "capsule": Capsule, "box": Box}


def parse_collider(text: str):
    """A collider from the CLI form ``kind:key=value,...`` (vectors as ``x/y/z``), e.g.
    ``sphere:center=0/1/0,radius=0.3,friction=0.4`` or ``plane:normal=0/1/0,thickness=0.005``."""
    kind, _, rest = text.partition(":")
    cls = COLLIDER_TYPES.get(kind.strip())
    if cls is None:
        raise WarpclothError(f"unknown collider kind {kind.strip()!r} in {text!r}; choose from {', '.join(COLLIDER_TYPES)}")
    fields = {f for f in cls.__dataclass_fields__}
    kwargs = {}
    for item in filter(None, (p.strip() for p in rest.split(","))):
        key, eq, value = item.partition("=")
        key = key.strip()
        if not eq or key not in fields:
            raise WarpclothError(f"collider {kind}: unknown or empty setting {item!r}; its settings are {', '.join(sorted(fields))}")
        parts = value.split("/")
        try:
            numbers = [float(p) for p in parts]
        except ValueError:
            raise WarpclothError(f"collider {kind}: {key} must be numbers (x/y/z for vectors), got {value!r}") from None
        kwargs[key] = tuple(numbers) if len(numbers) > 1 else numbers[0]
    return cls(**kwargs)


class ColliderSet:
    """The colliders of a :class:`~warpcloth.forces.Control` as device arrays, one group per kind."""

    def __init__(self, colliders, device):
        for c in colliders:
            if not isinstance(c, tuple(COLLIDER_TYPES.values())):
                raise WarpclothError(f"colliders must be Plane, Sphere, Capsule or Box objects, got {c!r:.80}")
        self.colliders = tuple(colliders)
        self.groups = []  # (kind index, a, b, radius, rotation, material) per kind present
        with wp.ScopedDevice(device):
            for k, name in enumerate(KINDS):
                mine = [c for c in self.colliders if isinstance(c, COLLIDER_TYPES[name])]
                if not mine:
                    continue
                if name == "plane":
                    a, b = [c.point for c in mine], [c.normal for c in mine]
                elif name == "sphere":
                    a, b = [c.center for c in mine], [(0.0, 0.0, 0.0)] * len(mine)
                elif name == "capsule":
                    a, b = [c.a for c in mine], [c.b for c in mine]
                else:
                    a, b = [c.center for c in mine], [c.half_extents for c in mine]
                radius = [getattr(c, "radius", 0.0) for c in mine]
                rotation = [getattr(c, "rotation", (0.0, 0.0, 0.0, 1.0)) for c in mine]
                material = [(c.thickness, c.friction) for c in mine]
                self.groups.append((
                    k, wp.array(np.asarray(a, np.float32), dtype=wp.vec3), wp.array(np.asarray(b, np.float32), dtype=wp.vec3),
                    wp.array(np.asarray(radius, np.float32), dtype=float), wp.array(np.asarray(rotation, np.float32), dtype=wp.quat),
                    wp.array(np.asarray(material, np.float32), dtype=wp.vec2),
                ))

    def project_velocity(self, model, state, dt: float, displacement=None, position_weight: float = 1.0) -> None:
        """After a force-based step: out of every collider, normal velocity removed, friction
        (``position_weight``: how a velocity change within the step moves x, see the kernels)."""
        from warpcloth.kernels import collide as ck

        d = displacement if displacement is not None else state.particle_qd
        for kind, a, b, radius, rotation, material in self.groups:
            wp.launch(ck.collide_velocity, dim=model.particle_count,
                      inputs=[kind, state.particle_q, state.particle_qd, model.particle_inv_mass, float(dt), float(position_weight), d,
                              int(displacement is not None), a, b, radius, rotation, material], device=model.device)

    def project_displacement(self, model, x, dp, normal_correction, friction: bool) -> None:
        """Inside a position-based solver: p = x + dp out of every collider (accumulating the
        normal corrections), or the friction pass after the iterations."""
        from warpcloth.kernels import collide as ck

        for kind, a, b, radius, rotation, material in self.groups:
            wp.launch(ck.collide_displacement, dim=model.particle_count,
                      inputs=[kind, int(friction), x, dp, model.particle_inv_mass, normal_correction, a, b, radius, rotation, material],
                      device=model.device)


__all__ = ["Box", "COLLIDER_TYPES", "Capsule", "ColliderSet", "KINDS", "Plane", "Sphere", "parse_collider"]
