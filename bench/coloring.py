"""Build-time cost of the colourings on meshes (not grids): vertex colouring (Vertex Block Descent)
by the greedy loop and by Warp's ``wp.utils.graph_coloring_assign`` (MCS and GREEDY), and spring
colouring (position-based solvers) by the greedy edge colouring and by MCS on the springs' line
graph: colours and milliseconds (best of ``--repeats``) on the cape, a 96 x 96 grid read as a mesh
and a 9,248-vertex UV sphere.

    python bench/coloring.py [--repeats 3]
"""

import argparse
import time

import numpy as np
import warp as wp

from warpcloth.io.provenance import machine
from warpcloth.scenarios.mesh import make_cape
from warpcloth.sim.coloring import (
    greedy_spring_colors,
    greedy_vertex_colors,
    is_valid_coloring,
    is_valid_vertex_coloring,
)
from warpcloth.sim.grid import build_grid_cloth
from warpcloth.sim.mesh import build_mesh_cloth


def uv_sphere(nu: int):
    nv = nu // 2
    th, ph = np.meshgrid(np.linspace(0, 2 * np.pi, nu, endpoint=False), np.linspace(0.1, np.pi - 0.1, nv))
    v = np.stack([np.sin(ph) * np.cos(th), np.cos(ph), np.sin(ph) * np.sin(th)], -1).reshape(-1, 3)
    tris = []
    for j in range(nv - 1):
        for i in range(nu):
            a, b, c, d = j * nu + i, j * nu + (i + 1) % nu, (j + 1) * nu + i, (j + 1) * nu + (i + 1) % nu
            tris += [[a, c, b], [b, c, d]]
    return v, np.array(tris)


def line_graph(pairs: np.ndarray, n: int) -> np.ndarray:
    """Edges between springs that share a particle."""
    s = len(pairs)
    ends, ids = np.concatenate([pairs[:, 0], pairs[:, 1]]), np.concatenate([np.arange(s), np.arange(s)])
    order = np.argsort(ends, kind="stable")
    ends, ids = ends[order], ids[order]
    starts = np.searchsorted(ends, np.arange(n + 1))
    out = []
    for i in range(n):
        group = ids[starts[i] : starts[i + 1]]
        if len(group) > 1:
            a, b = np.triu_indices(len(group), 1)
            out.append(np.stack([group[a], group[b]], 1))
    return np.concatenate(out)


def best(fn, repeats):
    times, value = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        value = fn()
        times.append(time.perf_counter() - t0)
    return value, 1e3 * min(times)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    wp.init()
    print(f"# {time.strftime('%Y-%m-%d %H:%M')} {machine()}; warp {wp.config.version}; best of {args.repeats}")
    grid = build_grid_cloth(96, 96, device="cpu")
    cape = make_cape()
    cases = {
        "cape": (cape.vertices, cape.triangles),
        "grid96 as a mesh": (grid.host.q, grid.host.tris),
        "uv sphere": uv_sphere(136),
    }
    for name, (v, t) in cases.items():
        m = build_mesh_cloth(v, t, device="cpu")
        pairs, n = m.spring_indices.numpy().reshape(-1, 2).astype(np.int64), m.particle_count
        edges = wp.array(pairs.astype(np.int32), dtype=int, device="cpu")
        g, tg = best(lambda: greedy_vertex_colors(pairs, n), args.repeats)
        row = [f"{name}: {n} vertices, {len(pairs)} springs", f"vertex greedy {g.max() + 1} colours {tg:.1f} ms"]
        for alg in wp.utils.GraphColoringAlgorithm:
            colors = wp.zeros(n, dtype=int, device="cpu")
            k, tw = best(lambda: wp.utils.graph_coloring_assign(edges, colors, alg), args.repeats)
            assert is_valid_vertex_coloring(pairs, colors.numpy())
            row.append(f"warp {alg.name} {k} colours {tw:.1f} ms")
        s, ts = best(lambda: greedy_spring_colors(pairs, n), args.repeats)
        row.append(f"springs greedy {s.max() + 1} colours {ts:.0f} ms")

        def mcs_springs():
            c = wp.zeros(len(pairs), dtype=int, device="cpu")
            edges = wp.array(line_graph(pairs, n).astype(np.int32), dtype=int, device="cpu")
            k = wp.utils.graph_coloring_assign(edges, c)
            return k, c.numpy()

        (k, c), tl = best(mcs_springs, args.repeats)
        assert is_valid_coloring(pairs, c, n)
        row.append(f"springs MCS (line graph) {k} colours {tl:.0f} ms")
        print("\n  ".join(row))


if __name__ == "__main__":
    main()
