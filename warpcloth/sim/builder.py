"""Several cloths in one model: :class:`ClothBuilder` adds grids and meshes, each with its own
material (or per-spring parameters), pins and self-collision group, and finalizes one
:class:`~warpcloth.sim.model.ClothModel` that every integrator steps as one system (one launch per
kernel for all pieces: a GPU stays busy with a cape and a skirt as with one larger cloth).

Each piece is built by the one-cloth builder of its kind (:func:`~warpcloth.sim.grid.build_grid_cloth`,
:func:`~warpcloth.sim.mesh.build_mesh_cloth`, or with a material
:func:`~warpcloth.sim.material.material_grid_cloth` / :func:`~warpcloth.sim.material.material_mesh_cloth`),
so a piece's springs, masses, pins and hinges are exactly those of the same cloth built alone; the
model concatenates them (particle, spring, triangle and hinge indices offset by the pieces before)
and records each piece's ranges (:class:`~warpcloth.sim.model.ClothPiece`, ``model.pieces``) for the
outputs (one USD mesh prim per piece). A builder of one piece gives that piece's model as its builder
makes it (bit-identical), with its piece record. Pieces in different ``collision_group``\\ s do not
collide with each other (the self-collision skips those pairs); pieces of one group do, as one cloth
with itself. docs/garments.md.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, replace

import numpy as np
import warp as wp

from warpcloth.errors import WarpclothError, require, require_int
from warpcloth.sim.device import resolve_device
from warpcloth.sim.grid import build_grid_cloth
from warpcloth.sim.hinges import Hinges
from warpcloth.sim.material import Material, material, material_grid_cloth, material_mesh_cloth
from warpcloth.sim.mesh import build_mesh_cloth
from warpcloth.sim.model import BendModel, ClothModel, ClothPiece, build_model

#: A piece's name: a USD identifier (a letter or _, then letters, digits, _).
NAME_PATTERN = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


@dataclass(frozen=True)
class PieceHandle:
    """What :meth:`ClothBuilder.add_grid` / :meth:`ClothBuilder.add_mesh` return: the piece's name,
    its index among the builder's pieces and its particle offset in the finalized model (particle i
    of the piece is ``offset + i`` there)."""

    name: str
    index: int
    offset: int
    particle_count: int

    def particles(self) -> slice:
        """The piece's particles as a slice of the finalized model's arrays."""
        return slice(self.offset, self.offset + self.particle_count)


class ClothBuilder:
    """Collects cloth pieces and finalizes them into one model.

    Example::

        b = ClothBuilder()
        cape = b.add_grid(12, 10, 0.6, 0.8, material="silk", pins=range(10), origin=(-0.3, 1.5, -0.2))
        skirt = b.add_mesh(mesh, material="denim", pin_groups=["waist"], collision_group=1)
        model = b.finalize("cpu")
    """

    def __init__(self):
        self._pieces: list[tuple[str, ClothModel, int, callable]] = []  # (name, CPU model, group, rebuild)

    @property
    def piece_count(self) -> int:
        return len(self._pieces)

    def add_grid(
        self,
        rows: int,
        cols: int,
        width: float = 1.0,
        height: float = 1.0,
        *,
        material=None,
        name: str | None = None,
        collision_group: int = 0,
        **options,
    ) -> PieceHandle:
        """Add a rows x cols Provot grid: ``options`` are :func:`~warpcloth.sim.grid.build_grid_cloth`'s
        (total_mass, spring_params, pins, origin, plane, bend, ...), or with a ``material`` (a
        :class:`~warpcloth.sim.material.Material` or a preset's name)
        :func:`~warpcloth.sim.material.material_grid_cloth`'s (pins, origin, plane, bend). Pins are the
        piece's own particle indices."""
        mat = self._material(material, name)
        if mat is None:

            def build(device):
                return build_grid_cloth(rows, cols, width, height, device=device, **options)
        else:

            def build(device):
                return material_grid_cloth(mat, rows, cols, width, height, device=device, **options)

        return self._add(build, name, collision_group, "grid")

    def add_mesh(
        self,
        vertices,
        triangles=None,
        *,
        material=None,
        name: str | None = None,
        collision_group: int = 0,
        **options,
    ) -> PieceHandle:
        """Add a cloth from a triangle mesh (vertices and triangles, or a
        :class:`~warpcloth.sim.mesh.TriangleMesh`): ``options`` are
        :func:`~warpcloth.sim.mesh.build_mesh_cloth`'s (total_mass, density, pins, pin_groups,
        pin_where, groups, uv, quads, bend, ...), or with a ``material``
        :func:`~warpcloth.sim.material.material_mesh_cloth`'s. Pins are the piece's own vertex indices."""
        mat = self._material(material, name)
        if mat is None:

            def build(device):
                return build_mesh_cloth(vertices, triangles, device=device, **options)
        else:

            def build(device):
                return material_mesh_cloth(mat, vertices, triangles, device=device, **options)

        return self._add(build, name, collision_group, "mesh")

    def _material(self, value, name):
        if value is None or isinstance(value, Material):
            return value
        if isinstance(value, str):
            return material(value)
        what = f"piece {name!r}" if name else f"piece {len(self._pieces)}"
        raise WarpclothError(
            f"{what}: material must be a Material, a preset's name or None (per-spring parameters), "
            f"got {type(value).__name__} {value!r:.60}"
        )

    def _add(self, build, name, collision_group, kind) -> PieceHandle:
        index = len(self._pieces)
        name = f"{kind}{index}" if name is None else name
        if not isinstance(name, str) or not NAME_PATTERN.fullmatch(name):
            raise WarpclothError(
                f"piece name must be a letter or _ followed by letters, digits or _ (a USD prim name), got {name!r:.60}"
            )
        taken = {p[0] for p in self._pieces}
        require(name not in taken, f"piece name {name!r} is already taken; the pieces are {', '.join(sorted(taken))}")
        group = require_int(f"collision_group of piece {name!r}", collision_group, 0)
        try:
            model = build("cpu")  # checked now: a bad piece is named where it is added
        except WarpclothError as exc:
            raise WarpclothError(f"piece {name!r}: {exc}") from None
        except TypeError as exc:  # an option the piece's builder does not take
            raise WarpclothError(f"piece {name!r}: {exc}") from None
        offset = sum(p[1].particle_count for p in self._pieces)
        self._pieces.append((name, model, group, build))
        return PieceHandle(name, index, offset, model.particle_count)

    def finalize(self, device=None) -> ClothModel:
        """One :class:`~warpcloth.sim.model.ClothModel` of every piece on ``device``, with its
        :class:`~warpcloth.sim.model.ClothPiece` records in ``model.pieces``."""
        require(bool(self._pieces), "the builder has no piece: add a grid or a mesh before finalize")
        device = resolve_device(device)
        if len(self._pieces) == 1:  # the piece as its own builder makes it, on the device
            name, _, group, build = self._pieces[0]
            model = build(device)
            piece = _record(name, model, group, 0, 0)
            host = model.host
            if group:
                host = replace(host, collision_group=np.full(model.particle_count, group, dtype=np.int32))
            return replace(model, pieces=(piece,), host=host)
        return _concatenate(self._pieces, device)


def _record(name, m, group, particle_offset, tri_offset) -> ClothPiece:
    bend = BendModel(m.bend)
    return ClothPiece(
        name, particle_offset, m.particle_count, tri_offset, m.tri_count, m.material, group, bend, m.rows, m.cols
    )


def _concatenate(pieces, device) -> ClothModel:
    """The pieces' host arrays end to end (indices offset), one model on ``device``."""
    q, pairs, types, mass, pins, tris, ks, kd, phi, uv, records, group_of = ([] for _ in range(12))
    groups = {}
    hinges = []
    n = t = 0
    for name, m, group, _ in pieces:
        h = m.host
        q.append(h.q)
        pairs.append(h.pairs.astype(np.int64) + n)
        types.append(np.asarray(m.spring_type, dtype=np.int32))
        mass.append(h.mass)
        pins.append(np.asarray(m.pinned, dtype=np.int64) + n)
        tris.append(h.tris.astype(np.int64) + n)
        ks.append(m.spring_stiffness.numpy())
        kd.append(m.spring_damping.numpy())
        phi.append(m.spring_compression.numpy())
        uv.append(h.uv if h.uv is not None else np.zeros((3 * m.tri_count, 2), dtype=np.float32))
        groups.update({f"{name}/{g}": np.asarray(idx, dtype=np.int64) + n for g, idx in h.groups.items()})
        if h.hinges is not None and h.hinges.hinge_count:
            hinges.append(replace(h.hinges, indices=(h.hinges.indices + n).astype(np.int32)))
        records.append(_record(name, m, group, n, t))
        group_of.append(np.full(m.particle_count, group, dtype=np.int32))
        n += m.particle_count
        t += m.tri_count
    model = build_model(
        np.concatenate(q),
        np.concatenate(pairs),
        np.concatenate(types),
        np.concatenate(mass),
        None,
        np.concatenate(pins),
        np.concatenate(tris),
        device,
        spring_stiffness=np.concatenate(ks),
        spring_damping=np.concatenate(kd),
        spring_compression=np.concatenate(phi),
    )
    materials = {id(r.material) for r in records}
    bends = {r.bend for r in records}
    has_uv = any(m.host.uv is not None for _, m, _, _ in pieces)
    host = replace(
        model.host,
        uv=np.concatenate(uv) if has_uv else None,
        groups=groups,
        collision_group=np.concatenate(group_of) if any(r.collision_group for r in records) else None,
    )
    model = replace(
        model,
        bend=bends.pop() if len(bends) == 1 else BendModel.NONE,
        material=records[0].material if len(materials) == 1 else None,
        host=host,
        pieces=tuple(records),
    )
    if hinges:
        with wp.ScopedDevice(device):
            model = model.with_hinges(
                Hinges(**{f: np.concatenate([getattr(h, f) for h in hinges]) for f in Hinges.__dataclass_fields__})
            )
    return model


__all__ = ["NAME_PATTERN", "ClothBuilder", "PieceHandle"]
