"""The Provot grid cloth: rows x cols particles, structural, shear and bend springs (seed 2.1.2).

Particle [r, c] has index r * cols + c. :func:`build_grid_cloth` builds the
:class:`~warpcloth.sim.model.ClothModel` (through :func:`~warpcloth.sim.model.build_model`) from
:func:`grid_positions`, :func:`grid_springs` and :func:`grid_triangles`; the spring counts equal
seed eq. 2.2 (:func:`expected_spring_counts`).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from warpcloth.errors import (
    WarpclothError,
    require,
    require_int,
    require_non_negative,
    require_positive,
    require_vector,
)
from warpcloth.sim.device import require_memory, resolve_device
from warpcloth.sim.hinges import DEFAULT_BEND_DAMPING_RATIO, DEFAULT_BEND_RIGIDITY, grid_hinges, hinge_damping_for_ratio
from warpcloth.sim.model import (
    BendModel,
    ClothModel,
    SpringParams,
    SpringType,
    build_model,
    check_spring_params,
    default_spring_params,
)


def expected_spring_counts(rows: int, cols: int, bend: str | BendModel = BendModel.PROVOT) -> dict[str, int]:
    """Spring counts of a rows x cols Provot grid, from seed eq. 2.2 (Choi-Ko adds 2(m-2)(n-2))."""
    m, n = rows, cols
    bend = BendModel(bend)
    counts = {
        "structural": 2 * (m - 1) * (n - 1) + (m - 1) + (n - 1),
        "shear": 2 * (m - 1) * (n - 1),
        "bend": 0,
    }
    if bend in (BendModel.PROVOT, BendModel.CHOI_KO):
        counts["bend"] = 2 * (m - 2) * (n - 2) + 2 * ((m - 2) + (n - 2))
    if bend == BendModel.CHOI_KO:
        counts["bend"] += 2 * (m - 2) * (n - 2)
    return counts


#: Bytes per particle and per spring a run needs at most: device arrays (model, state, the largest
#: integrator's scratch, metrics) and the host copies and temporaries made while building.
BYTES_PER_PARTICLE = 400
BYTES_PER_SPRING = 160
#: Bytes per dihedral hinge: its arrays, colouring and adjacency, and its share of the implicit
#: system's larger pattern (about 8 more 3 x 3 blocks per particle, 2 hinges per particle).
BYTES_PER_HINGE = 400


def grid_memory_estimate(rows: int, cols: int, bend: str | BendModel = BendModel.PROVOT) -> int:
    """An upper estimate [bytes] of the memory a rows x cols Provot cloth and its run need
    (about 8 springs per particle with Choi-Ko bend springs; 4 hinges per particle with ``dihedral``)."""
    n = int(rows) * int(cols)
    hinges = 4 * n * BYTES_PER_HINGE if BendModel(bend) == BendModel.DIHEDRAL else 0
    return n * (BYTES_PER_PARTICLE + 8 * BYTES_PER_SPRING) + hinges


def grid_springs(rows: int, cols: int, bend: BendModel = BendModel.PROVOT) -> tuple[np.ndarray, np.ndarray]:
    """Provot springs of a rows x cols grid as (pairs (S, 2) int32, types (S,) int32).

    Particle [r, c] has index r * cols + c. Structural: [r,c]-[r+1,c], [r,c]-[r,c+1]; shear:
    [r,c]-[r+1,c+1], [r+1,c]-[r,c+1]; bend: [r,c]-[r+2,c], [r,c]-[r,c+2] (Choi-Ko adds
    [r,c]-[r+2,c+2], [r+2,c]-[r,c+2]); ``none`` and ``dihedral`` (hinges, not springs) add no bend springs.
    """
    idx = np.arange(rows * cols, dtype=np.int32).reshape(rows, cols)
    pairs, types = [], []

    def add(a, b, t):
        pairs.append(np.stack([a.ravel(), b.ravel()], axis=1))
        types.append(np.full(a.size, int(t), dtype=np.int32))

    add(idx[:-1, :], idx[1:, :], SpringType.STRUCTURAL)
    add(idx[:, :-1], idx[:, 1:], SpringType.STRUCTURAL)
    add(idx[:-1, :-1], idx[1:, 1:], SpringType.SHEAR)
    add(idx[1:, :-1], idx[:-1, 1:], SpringType.SHEAR)
    if bend in (BendModel.PROVOT, BendModel.CHOI_KO):
        add(idx[:-2, :], idx[2:, :], SpringType.BEND)
        add(idx[:, :-2], idx[:, 2:], SpringType.BEND)
    if bend == BendModel.CHOI_KO:
        add(idx[:-2, :-2], idx[2:, 2:], SpringType.BEND)
        add(idx[2:, :-2], idx[:-2, 2:], SpringType.BEND)
    return np.concatenate(pairs).astype(np.int32), np.concatenate(types)


def grid_triangles(rows: int, cols: int) -> np.ndarray:
    """Two counter-clockwise triangles per grid cell, shape (2 (rows-1)(cols-1), 3)."""
    idx = np.arange(rows * cols, dtype=np.int32).reshape(rows, cols)
    a, b = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel()
    c, d = idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
    t1 = np.stack([a, c, b], axis=1)
    t2 = np.stack([b, c, d], axis=1)
    return np.concatenate([t1, t2]).astype(np.int32)


def grid_positions(
    rows: int, cols: int, width: float, height: float, origin=(0.0, 0.0, 0.0), plane: str = "vertical"
) -> np.ndarray:
    """Particle positions of the grid [m]: row 0 at the origin, columns along +x.

    ``plane="vertical"``: rows go down (-y), the cloth lies in the x-y plane (y up).
    ``plane="horizontal"``: rows go along +z, the cloth lies flat in the x-z plane.
    """
    r, c = np.meshgrid(np.arange(rows), np.arange(cols), indexing="ij")
    u = c.ravel() * (width / (cols - 1))
    w = r.ravel() * (height / (rows - 1))
    q = np.zeros((rows * cols, 3), dtype=np.float64)
    q[:, 0] = u
    if plane == "vertical":
        q[:, 1] = -w
    elif plane == "horizontal":
        q[:, 2] = w
    else:
        raise WarpclothError(f"plane must be 'vertical' or 'horizontal', got {plane!r}")
    return (q + np.asarray(origin, dtype=np.float64)).astype(np.float32)


def build_grid_cloth(
    rows: int,
    cols: int,
    width: float = 1.0,
    height: float = 1.0,
    total_mass: float = 0.2,
    spring_params: dict[SpringType, SpringParams] | None = None,
    pins=(),
    origin=(0.0, 0.0, 0.0),
    plane: str = "vertical",
    bend: str | BendModel = BendModel.PROVOT,
    device: str | None = None,
    *,
    bend_rigidity: float | None = None,
    bend_damping_ratio: float | None = None,
    mass_mode: str = "uniform",
) -> ClothModel:
    """Build a Provot mass-spring grid cloth.

    Args:
        rows, cols: particles per column and per row (>= 2; >= 3 with bend springs).
        width, height: physical size of the cloth [m].
        total_mass: cloth mass [kg], split evenly over the particles (seed 4.2.4) or by vertex
            area (``mass_mode``).
        spring_params: per-type :class:`SpringParams`; default :func:`default_spring_params`.
        pins: indices of pinned particles (inverse mass 0).
        origin: position of particle [0, 0] [m].
        plane: ``"vertical"`` (hanging, x-y plane) or ``"horizontal"`` (x-z plane).
        bend: ``"provot"``, ``"choi_ko"``, ``"none"`` (bend springs) or ``"dihedral"``: no bend
            springs, dihedral-angle hinges (discrete shells) on every interior structural edge, once
            per diagonal choice of its two cells (:func:`~warpcloth.sim.hinges.grid_hinges`).
        device: Warp device (default: Warp's current device, see :mod:`warpcloth.sim.device`).
        bend_rigidity: bending rigidity B [N m] of the hinges (``dihedral`` only; default
            :data:`~warpcloth.sim.hinges.DEFAULT_BEND_RIGIDITY`, cotton's).
        bend_damping_ratio: damping ratio of each hinge's own mode (``dihedral`` only; default
            :data:`~warpcloth.sim.hinges.DEFAULT_BEND_DAMPING_RATIO`;
            :func:`~warpcloth.sim.hinges.hinge_damping_for_ratio`).
        mass_mode: ``"uniform"`` (total_mass / particles, the seed's) or ``"area"`` (lumped by
            vertex area: edge particles half, corners a quarter of an interior one's).
    """
    try:
        bend = BendModel(bend)
    except ValueError:
        raise WarpclothError(f"bend must be one of {[b.value for b in BendModel]}, got {bend!r}") from None
    min_dim = 2 if bend in (BendModel.NONE, BendModel.DIHEDRAL) else 3
    if bend != BendModel.DIHEDRAL and (bend_rigidity is not None or bend_damping_ratio is not None):
        raise WarpclothError(
            f"bend_rigidity and bend_damping_ratio are the dihedral model's (bend='dihedral'), not "
            f"{bend.value!r}'s: its bend springs take the bend stiffness and damping"
        )
    require(mass_mode in ("uniform", "area"), f"mass_mode must be 'uniform' or 'area', got {mass_mode!r}")
    rows = require_int("rows", rows, min_dim)
    cols = require_int("cols", cols, min_dim)
    width = require_positive("width", width, "m")
    height = require_positive("height", height, "m")
    total_mass = require_positive("mass", total_mass, "kg")
    origin = require_vector("origin", origin, 3, "m")
    if spring_params is None:
        spring_params = default_spring_params(total_mass / (rows * cols))
    check_spring_params(spring_params)
    device = resolve_device(device)
    require_memory(f"a {rows} x {cols} cloth", grid_memory_estimate(rows, cols, bend), device)

    q = grid_positions(rows, cols, width, height, origin, plane)
    pairs, types = grid_springs(rows, cols, bend)
    if mass_mode == "uniform":
        masses = np.full(rows * cols, total_mass / (rows * cols))
    else:
        share = np.outer(_end_halves(rows), _end_halves(cols)).ravel()
        masses = total_mass * share / share.sum()
    model = build_model(q, pairs, types, masses, spring_params, pins, grid_triangles(rows, cols), device)

    uv = grid_uvs(rows, cols)[model.host.tris].reshape(-1, 2)
    model = replace(
        model,
        rows=rows,
        cols=cols,
        width=width,
        height=height,
        bend=bend,
        total_mass=total_mass,
        host=replace(model.host, uv=uv),
    )
    if bend == BendModel.DIHEDRAL:
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
        hinges = grid_hinges(model.host.q, rows, cols, rigidity)
        hinges = replace(hinges, damping=hinge_damping_for_ratio(model.host.q, hinges, model.host.mass, ratio))
        model = model.with_hinges(hinges)
    return model


def _end_halves(count: int) -> np.ndarray:
    """1 inside, 1/2 at both ends: a particle's share of a line of equal segments."""
    w = np.ones(count)
    w[[0, -1]] = 0.5
    return w


def grid_uvs(rows: int, cols: int) -> np.ndarray:
    """Texture coordinates per particle, u = col / (cols - 1), v = 1 - row / (rows - 1), (N, 2)."""
    r, c = np.meshgrid(np.arange(rows), np.arange(cols), indexing="ij")
    return np.stack([c.ravel() / (cols - 1), 1.0 - r.ravel() / (rows - 1)], axis=1).astype(np.float32)


__all__ = [
    "BYTES_PER_HINGE",
    "BYTES_PER_PARTICLE",
    "BYTES_PER_SPRING",
    "build_grid_cloth",
    "expected_spring_counts",
    "grid_memory_estimate",
    "grid_positions",
    "grid_springs",
    "grid_triangles",
    "grid_uvs",
]
