"""Seconds to build a cloth model from a triangle mesh (warpcloth.build_mesh_cloth).

    python bench/mesh_build.py                       # a ~100k-triangle mesh, CPU device
    python bench/mesh_build.py --triangles 400000 --quads

The mesh is a wavy triangulated grid (a cloth draped over bumps, so no two rows are alike)
with ~``--triangles`` triangles. Each figure is the best of ``--repeat`` builds (topology,
springs, lumped masses, pins by predicate, device arrays), after one build that warms up
Warp. Not a test: nothing here asserts a speed.
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

import warpcloth
from warpcloth.sim.grid import grid_positions, grid_triangles


def wavy_grid(triangles: int):
    n = max(3, int(math.sqrt(triangles / 2.0)) + 1)
    q = grid_positions(n, n, 2.0, 2.0, plane="horizontal").astype(np.float64)
    q[:, 1] = 0.05 * np.sin(7.0 * q[:, 0]) * np.cos(5.0 * q[:, 2])
    return q, grid_triangles(n, n)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--triangles", type=int, default=100_000)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--quads", action="store_true", help="also detect quads (shear and straight-line bend springs)")
    ap.add_argument("--device", default="cpu")
    args = ap.parse_args(argv)
    q, t = wavy_grid(args.triangles)
    for quads in [False, True] if args.quads else [False]:
        warpcloth.build_mesh_cloth(*wavy_grid(200), device=args.device)  # warm-up
        best = math.inf
        for _ in range(args.repeat):
            t0 = time.perf_counter()
            model = warpcloth.build_mesh_cloth(q, t, density=0.2, pin_where="x < 0.01", quads=quads, device=args.device)
            best = min(best, time.perf_counter() - t0)
        print(
            f"{t.shape[0]} triangles, {q.shape[0]} vertices, {model.spring_count} springs, quads={quads}: "
            f"build_mesh_cloth {best:.3f} s (best of {args.repeat}, {args.device})"
        )


if __name__ == "__main__":
    main()
