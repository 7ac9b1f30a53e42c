"""Cost of self-collision (issue 29): detect + repulsion + velocity filter of
:class:`~warpcloth.sim.self_collision.SelfCollision` on an N x N sheet folded over onto itself
(the half beyond x = 0.5 lies 0.9 h above the other, so every vertex of the overlap is in
contact), against one explicit_euler step of the same cloth (``time_steps``, the Simulator's
captured frame).

Each case is a captured graph of ``--batch`` cycles (CPU capture, Warp >= 1.19) replayed in
windows; the cases alternate within each repeat so machine noise falls on all of them; medians
and min-max of ``--repeats`` windows. Cases:

* ``cycle``: detect (the Verlet list still valid: no rebuild) + filter_velocities (with the
  repulsion impulse), what an explicit scheme adds to a typical step;
* ``cycle+rebuild``: the same with the list rebuilt every step (``invalidate`` first), the worst
  step (a rebuild happens when a vertex may have moved skin / 2 since the last);
* the pieces: ``detect``, ``detect+rebuild``, ``filter``, and ``forces`` (the repulsion as a force,
  for schemes that put it in their force instead).

``--edge-fractions`` runs the cases for each edge-edge thickness fraction (1: edge pairs act
within h, as vertex-triangle pairs; 0.5: within h / 2).

``--alternatives`` also times, per build, broad phases made of Warp's own structures for the
vertex-triangle candidates (plain launches, each with its query kernel counting the triangles
within the list radius of every vertex): ``wp.HashGrid.build`` over the vertices + a query per
triangle, ``wp.Bvh.refit`` over triangle boxes + a query per vertex, ``wp.Mesh.refit`` + a
``mesh_query_aabb`` per vertex; and this module's own (its rebuild launches, vertex-triangle part).
Warp's builds and refits are host calls: a captured frame must run them every step, where the
kernel-built hash's launches exit at once on the device when no rebuild is due.

    python bench/self_contact.py [--sizes 32 64 128] [--repeats 7] [--batch 20] [--thickness 0.005]
        [--edge-fractions 1.0 0.5] [--iterations 2] [--alternatives]
"""

import argparse
import statistics
import time

import numpy as np
import warp as wp

from warpcloth import Control, Simulator, build_grid_cloth
from warpcloth.kernels import self_contact as sk
from warpcloth.lab.intersections import count_self_intersections
from warpcloth.run.harness import time_steps
from warpcloth.sim.self_collision import SelfCollision


def folded(model, gap, slide=(0.5, 0.3)):
    """The sheet folded at x = 0.5 w, the far half ``gap`` above the near half and slid by
    ``slide`` grid spacings in x and z (so its vertices do not lie over the near half's)."""
    q = model.host.q.astype(np.float64).copy()
    x0 = q[:, 0].min()
    spacing = (q[:, 0].max() - x0) / (model.cols - 1)
    half = x0 + 0.5 * (q[:, 0].max() - x0)
    fold = q[:, 0] > half + 1e-9
    q[fold, 0] = 2.0 * half - q[fold, 0] + slide[0] * spacing
    q[fold, 2] += slide[1] * spacing
    q[fold, 1] += gap
    return q.astype(np.float32)


def window_ms(graph, replays, device):
    wp.synchronize_device(device)
    t = time.perf_counter()
    for _ in range(replays):
        wp.capture_launch(graph)
    wp.synchronize_device(device)
    return 1000.0 * (time.perf_counter() - t)


def capture(fn, batch, device):
    fn()  # module load and first launches outside the capture
    with wp.ScopedCapture(device=device) as cap:
        for _ in range(batch):
            fn()
    return cap.graph


def measure(size, thickness, repeats, batch, device, edge_fraction=1.0, iterations=2):
    model = build_grid_cloth(size, size, 1.0, 1.0, 0.2, plane="horizontal", device=device)
    q = folded(model, 0.9 * thickness)
    sim = Simulator(model, "explicit_euler", Control(device=device))
    sim.state.particle_q.assign(q)
    dt = sim.dt
    sc = SelfCollision(model, thickness=thickness, friction=0.3, edge_fraction=edge_fraction, iterations=iterations)
    with wp.ScopedDevice(device):
        x = wp.array(q, dtype=wp.vec3)
        v = wp.zeros_like(x)
        f = wp.zeros_like(x)
    sc.detect(x, v, dt)
    stats = sc.stats()

    def detect():
        sc.detect(x, v, dt)

    def rebuild():
        sc.invalidate()
        sc.detect(x, v, dt)

    def forces():
        sc.apply_forces(x, v, f, dt)

    def filt():
        sc.filter_velocities(x, v, dt)

    cases = {
        "cycle": lambda: (detect(), filt()),
        "cycle+rebuild": lambda: (rebuild(), filt()),
        "detect": detect,
        "detect+rebuild": rebuild,
        "filter": filt,
        "forces": forces,
    }
    graphs = {name: capture(fn, batch, device) for name, fn in cases.items()}
    time_steps(sim, windows=1, steps=batch)  # warm-up, capture of the step count
    ms = {name: [] for name in ["explicit_euler step", *cases]}
    for _ in range(repeats):
        ms["explicit_euler step"].extend(time_steps(sim, windows=1, steps=batch, warm_up=False).ms_per_step)
        for name, graph in graphs.items():
            ms[name].append(window_ms(graph, 1, device) / batch)
    after = sc.stats()
    return model, ms, stats, after


def alternatives(size, thickness, repeats, device):
    """ms per build of vertex-triangle candidate finding with Warp's HashGrid, Bvh, Mesh and ours."""
    model = build_grid_cloth(size, size, 1.0, 1.0, 0.2, plane="horizontal", device=device)
    q = folded(model, 0.9 * thickness)
    sc = SelfCollision(model, thickness=thickness)
    r = sc.thickness + sc.skin
    n, t = model.particle_count, model.tri_count
    spacing = 1.0 / (size - 1)
    with wp.ScopedDevice(device):
        x = wp.array(q, dtype=wp.vec3)
        v0 = wp.zeros_like(x)
        tris = sc.tris
        lo, hi = wp.zeros(t, dtype=wp.vec3), wp.zeros(t, dtype=wp.vec3)
        centres = wp.zeros(t, dtype=wp.vec3)
        out = wp.zeros(max(n, t), dtype=int)
        grid = wp.HashGrid(64, 64, 64)
        grid.reserve(n)
        wp.launch(_boxes, t, [x, tris, r, lo, hi, centres])
        bvh = wp.Bvh(lo, hi)
        mesh = wp.Mesh(points=wp.clone(x), indices=wp.array(model.host.tris.reshape(-1), dtype=int))
        reach = r + 0.75 * spacing * 1.5  # a triangle's box half diagonal, strained a little

    for fn in (lambda: grid.build(x, r + reach), bvh.refit, mesh.refit):
        fn()

    def hashgrid():
        grid.build(x, r + reach)
        wp.launch(_grid_query, t, [grid.id, x, tris, r, reach, out], device=device)

    def bvh_refit():
        wp.launch(_boxes, t, [x, tris, r, lo, hi, centres], device=device)
        bvh.refit()
        wp.launch(_bvh_query, n, [bvh.id, x, tris, r, out], device=device)

    def mesh_refit():
        wp.copy(mesh.points, x)
        mesh.refit()
        wp.launch(_mesh_query, n, [mesh.id, x, tris, r, out], device=device)

    def ours():
        sc.invalidate()
        sc._decide(x, v0, 1e-4)
        sc._build(x, v0, 1e-4, edges=False)

    def refit_alone():
        wp.launch(_boxes, t, [x, tris, r, lo, hi, centres], device=device)
        bvh.refit()

    def gated():  # what a step without a rebuild pays for the broad phase: its launches return at once
        sc._decide(x, v0, 1e-4)  # no motion since the build: no rebuild due
        sc._build(x, v0, 1e-4, edges=False)

    cases = {
        "wp.HashGrid build + query": hashgrid,
        "wp.Bvh refit + query": bvh_refit,
        "wp.Mesh refit + query": mesh_refit,
        "own hash (kernels)": ours,
        "wp.Bvh refit alone (every step)": refit_alone,
    }
    for fn in cases.values():
        fn()
    cases["own hash, no rebuild due"] = gated
    ms = {k: [] for k in cases}
    for _ in range(repeats):
        for name, fn in cases.items():
            wp.synchronize_device(device)
            t0 = time.perf_counter()
            for _ in range(10):
                fn()
            wp.synchronize_device(device)
            ms[name].append(100.0 * (time.perf_counter() - t0))
    return ms


@wp.kernel(enable_backward=False)
def _boxes(
    x: wp.array(dtype=wp.vec3),
    tris: wp.array(dtype=wp.vec3i),
    r: float,
    lo: wp.array(dtype=wp.vec3),
    hi: wp.array(dtype=wp.vec3),
    centres: wp.array(dtype=wp.vec3),
):
    t = wp.tid()
    a, b, c = x[tris[t][0]], x[tris[t][1]], x[tris[t][2]]
    lo[t] = wp.min(wp.min(a, b), c) - wp.vec3(r)
    hi[t] = wp.max(wp.max(a, b), c) + wp.vec3(r)
    centres[t] = (a + b + c) / 3.0


@wp.func
def _near(x: wp.array(dtype=wp.vec3), tri: wp.vec3i, i: int, r: float):
    if tri[0] == i or tri[1] == i or tri[2] == i:
        return 0
    q, _w = sk.closest_point_triangle(x[i], x[tri[0]], x[tri[1]], x[tri[2]])
    if wp.length(x[i] - q) <= r:
        return 1
    return 0


@wp.kernel(enable_backward=False)
def _grid_query(
    grid: wp.uint64,
    x: wp.array(dtype=wp.vec3),
    tris: wp.array(dtype=wp.vec3i),
    r: float,
    reach: float,
    out: wp.array(dtype=int),
):
    t = wp.tid()
    tri = tris[t]
    centre = (x[tri[0]] + x[tri[1]] + x[tri[2]]) / 3.0
    query = wp.hash_grid_query(grid, centre, reach + r)
    k = int(0)
    i = int(0)
    while wp.hash_grid_query_next(query, i):
        k += _near(x, tri, i, r)
    out[t] = k


@wp.kernel(enable_backward=False)
def _bvh_query(
    bvh: wp.uint64, x: wp.array(dtype=wp.vec3), tris: wp.array(dtype=wp.vec3i), r: float, out: wp.array(dtype=int)
):
    i = wp.tid()
    p = x[i]
    query = wp.bvh_query_aabb(bvh, p, p)
    k = int(0)
    t = int(0)
    while wp.bvh_query_next(query, t):
        k += _near(x, tris[t], i, r)
    out[i] = k


@wp.kernel(enable_backward=False)
def _mesh_query(
    mesh: wp.uint64, x: wp.array(dtype=wp.vec3), tris: wp.array(dtype=wp.vec3i), r: float, out: wp.array(dtype=int)
):
    i = wp.tid()
    p = x[i]
    query = wp.mesh_query_aabb(mesh, p - wp.vec3(r), p + wp.vec3(r))
    k = int(0)
    t = int(0)
    while wp.mesh_query_aabb_next(query, t):
        k += _near(x, tris[t], i, r)
    out[i] = k


def fmt(values):
    return f"{statistics.median(values):8.4f} [{min(values):.4f}-{max(values):.4f}]"


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--sizes", type=int, nargs="+", default=[32, 64, 128])
    p.add_argument("--repeats", type=int, default=7)
    p.add_argument("--batch", type=int, default=20, help="cycles per captured graph (one window)")
    p.add_argument("--thickness", type=float, default=0.005, help="h [m]")
    p.add_argument("--device", default="cpu")
    p.add_argument("--edge-fractions", type=float, nargs="+", default=[1.0, 0.5])
    p.add_argument("--iterations", type=int, default=2, help="Jacobi passes of the filter")
    p.add_argument("--alternatives", action="store_true", help="also time broad phases of Warp's HashGrid, Bvh, Mesh")
    a = p.parse_args(argv)
    wp.init()
    print(
        f"# warp {wp.config.version}, device {a.device}, thickness {a.thickness} m, fold gap 0.9 h "
        f"(slid 0.5, 0.3 cells), {a.iterations} filter iterations, {a.repeats} windows of {a.batch} cycles "
        f"(captured), cases alternating"
    )
    print(
        "# ms per cycle: median [min-max]; ratio: median of the per-window ratios to the same repeat's "
        "explicit_euler step"
    )
    for size in a.sizes:
        for fraction in a.edge_fractions:
            model, ms, before, after = measure(size, a.thickness, a.repeats, a.batch, a.device, fraction, a.iterations)
            base = ms["explicit_euler step"]
            x = folded(model, 0.9 * a.thickness)
            t0 = time.perf_counter()
            bad = count_self_intersections(x, model.host.tris)
            check_s = time.perf_counter() - t0
            print(
                f"{size}x{size}, edge fraction {fraction:g}: {model.particle_count} vertices, "
                f"{model.tri_count} triangles, {before['candidates_vertex_triangle']} + "
                f"{before['candidates_edge_edge']} candidates (vt + ee), {before['contacts']} contacts, overflow "
                f"{after['overflow_candidates']} / {after['overflow_contacts']}, checker {check_s:.2f} s "
                f"({bad} intersections)"
            )
            for name, values in ms.items():
                ratio = [v / b for v, b in zip(values, base)]
                print(
                    f"  {size}x{size} {a.device} e{fraction:g} {name:20s} {fmt(values)} ms   "
                    f"ratio {statistics.median(ratio):6.2f} [{min(ratio):.2f}-{max(ratio):.2f}]"
                )
    if a.alternatives:
        print(
            "# broad phase alternatives, vertex-triangle candidates only, ms per build (plain launches, 10 per window)"
        )
        for size in [s for s in a.sizes if s >= 64]:
            for name, values in alternatives(size, a.thickness, a.repeats, a.device).items():
                print(f"  {size}x{size} {a.device} {name:34s} {fmt(values)} ms")


if __name__ == "__main__":
    main()
