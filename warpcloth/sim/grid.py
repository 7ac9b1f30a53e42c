"""The Provot grid cloth: rows x cols particles, structural, shear and bend springs (seed 2.1.2).

Particle [r, c] has index r * cols + c. :func:`build_grid_cloth` builds the
:class:`~warpcloth.sim.model.ClothModel` (through :func:`~warpcloth.sim.model.build_model`) from
:func:`grid_positions`, :func:`grid_springs` and :func:`grid_triangles`; the spring counts equal
seed eq. 2.2 (:func:`expected_spring_counts`).
"""

from __future__ import annotations

import numpy as np

from warpcloth.errors import WarpclothError, require_int, require_positive, require_vector
from warpcloth.sim.device import require_memory, resolve_device
from warpcloth.sim.model import (BendModel, ClothModel, SpringParams, SpringType, build_model, check_spring_params,
                                 default_spring_params)


def expected_spring_counts(rows: int, cols: int, bend: str | BendModel = BendModel.PROVOT) -> dict[str, int]:
    """Spring counts of a rows x cols Provot grid, from seed eq. 2.2 (Choi-Ko adds 2(m-2)(n-2))."""
    m, n = rows, cols
    bend = BendModel(bend)
    counts = {
        "structural": 2 * (m - 1) * (n - 1) + (m - 1) + (n - 1),
        "shear": 2 * (m - 1) * (n - 1),
        "bend": 0,
    }
    if bend != BendModel.NONE:
        counts["bend"] = 2 * (m - 2) * (n - 2) + 2 * ((m - 2) + (n - 2))
    if bend == BendModel.CHOI_KO:
        counts["bend"] += 2 * (m - 2) * (n - 2)
    return counts


#: Bytes per particle and per spring a run needs at most: device arrays (model, state, the largest
#: integrator's scratch, metrics) and the host copies and temporaries made while building.
BYTES_PER_PARTICLE = 400
BYTES_PER_SPRING = 160


def grid_memory_estimate(rows: int, cols: int) -> int:
    """An upper estimate [bytes] of the memory a rows x cols Provot cloth and its run need
    (about 8 springs per particle with Choi-Ko bend springs)."""
    n = int(rows) * int(cols)
    return n * (BYTES_PER_PARTICLE + 8 * BYTES_PER_SPRING)


def grid_springs(rows: int, cols: int, bend: BendModel = BendModel.PROVOT) -> tuple[np.ndarray, np.ndarray]:
    """Provot springs of a rows x cols grid as (pairs (S, 2) int32, types (S,) int32).

    Particle [r, c] has index r * cols + c. Structural: [r,c]-[r+1,c], [r,c]-[r,c+1]; shear:
    [r,c]-[r+1,c+1], [r+1,c]-[r,c+1]; bend: [r,c]-[r+2,c], [r,c]-[r,c+2] (Choi-Ko adds
    [r,c]-[r+2,c+2], [r+2,c]-[r,c+2]).
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
    if bend != BendModel.NONE:
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


def grid_positions(rows: int, cols: int, width: float, height: float, origin=(0.0, 0.0, 0.0), plane: str = "vertical") -> np.ndarray:
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
) -> ClothModel:
    """Build a Provot mass-spring grid cloth.

    Args:
        rows, cols: particles per column and per row (>= 2; >= 3 with bend springs).
        width, height: physical size of the cloth [m].
        total_mass: cloth mass [kg], split evenly over the particles (seed 4.2.4).
        spring_params: per-type :class:`SpringParams`; default :func:`default_spring_params`.
        pins: indices of pinned particles (inverse mass 0).
        origin: position of particle [0, 0] [m].
        plane: ``"vertical"`` (hanging, x-y plane) or ``"horizontal"`` (x-z plane).
        bend: ``"provot"``, ``"choi_ko"`` or ``"none"``.
        device: Warp device (default: Warp's current device, see :mod:`warpcloth.sim.device`).
    """
    try:
        bend = BendModel(bend)
    except ValueError:
        raise WarpclothError(f"bend must be one of {[b.value for b in BendModel]}, got {bend!r}") from None
    min_dim = 2 if bend == BendModel.NONE else 3
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
    require_memory(f"a {rows} x {cols} cloth", grid_memory_estimate(rows, cols), device)

    q = grid_positions(rows, cols, width, height, origin, plane)
    pairs, types = grid_springs(rows, cols, bend)
    model = build_model(q, pairs, types, np.full(rows * cols, total_mass / (rows * cols)), spring_params, pins, grid_triangles(rows, cols), device)
    from dataclasses import replace

    uv = grid_uvs(rows, cols)[model.host.tris].reshape(-1, 2)
    return replace(model, rows=rows, cols=cols, width=width, height=height, bend=bend, total_mass=total_mass,
                   host=replace(model.host, uv=uv))


def grid_uvs(rows: int, cols: int) -> np.ndarray:
    """Texture coordinates per particle, u = col / (cols - 1), v = 1 - row / (rows - 1), (N, 2)."""
    r, c = np.meshgrid(np.arange(rows), np.arange(cols), indexing="ij")
    return np.stack([c.ravel() / (cols - 1), 1.0 - r.ravel() / (rows - 1)], axis=1).astype(np.float32)


__all__ = [
    "BYTES_PER_PARTICLE", "BYTES_PER_SPRING", "build_grid_cloth", "expected_spring_counts", "grid_memory_estimate",
    "grid_positions", "grid_springs", "grid_triangles", "grid_uvs",
]
