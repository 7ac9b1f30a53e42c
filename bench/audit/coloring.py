# ruff: noqa
# One-off audit script of issues 26, 30 and 31 (2026-12-03, branch audit); outputs in bench/results/audit-26-30-31.txt.
import time

import numpy as np

from warpcloth import build_grid_cloth, build_mesh_cloth, load_mesh
from warpcloth.sim.coloring import color_vertices, greedy_vertex_colors, is_valid_vertex_coloring, warp_vertex_colors
from warpcloth.sim.grid import grid_triangles

cases = {}
m = load_mesh(str(__import__("pathlib").Path(__file__).resolve().parents[2] / "warpcloth" / "examples" / "cape.obj"))
cases["cape quads"] = build_mesh_cloth(m, quads=True, device="cpu")
cases["cape dihedral"] = build_mesh_cloth(m, bend="dihedral", device="cpu")
for n in (32, 96):
    g = build_grid_cloth(n, n, device="cpu")
    cases[f"grid{n} mesh twin"] = build_mesh_cloth(g.host.q, grid_triangles(n, n), quads=True, device="cpu")
    cases[f"grid{n} mesh choi_ko"] = build_mesh_cloth(
        g.host.q, grid_triangles(n, n), quads=True, bend="choi_ko", device="cpu"
    )
rng = np.random.default_rng(0)
pts = rng.random((3000, 2))
from scipy.spatial import Delaunay

tri = Delaunay(pts).simplices
cases["random delaunay 3000"] = build_mesh_cloth(np.c_[pts, np.zeros(len(pts))], tri, device="cpu")
for name, model in cases.items():
    pairs = model.host.pairs
    n = model.particle_count
    t0 = time.perf_counter()
    w = warp_vertex_colors(pairs, n)
    t1 = time.perf_counter()
    g = greedy_vertex_colors(pairs, n)
    t2 = time.perf_counter()
    used = color_vertices(pairs, n)
    print(
        f"{name:24s} {n:6d} v: MCS {w.max() + 1} colours ({(t1 - t0) * 1e3:.1f} ms, valid {is_valid_vertex_coloring(pairs, w)}), greedy {g.max() + 1} ({(t2 - t1) * 1e3:.1f} ms); used {used.count if hasattr(used, 'count') else len(used.offsets) - 1 if hasattr(used, 'offsets') else '?'}"
    )
