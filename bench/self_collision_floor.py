"""How far the self-collision rebuild's searches are from the least work of their kind (issue 29): in the
fold at N x N, from the states of the default run at ``--times``, the candidate list is built once, then
its two searches (vertex-triangle and edge-edge, ``kernels/self_contact.py``) are timed against two
minimal kernels that walk the same hash cells in the same order (CPU only: its buckets are ordered, and
an edge's walk stops at its own index as the search's does there):

- *walk*: every item of the query's cells is visited (its index and the bucket's next, the cell test
  that finds it once), nothing else;
- *boxes*: the same, plus the box test placed as in the searches, before the cell test (the candidates'
  boxes that meet the query's are counted);

the searches do these and the exclusion test, the exact distance and the record of the pairs that the
boxes let through. Each kernel runs ``--repeats`` times, alternated; medians [min-max] in ms a build.

With the rebuilds a run makes at that state (counted over ``--steps`` steps from it, as in a run) and
the step's own cost without self-collision (as many steps of a second simulator of the fold, a captured
graph, from the snapshot's positions and velocities on its own clock), each kernel's time is also given as a share of a
step: a search of this hash costs at least the *walk* figure at every rebuild, whatever the rest of
self-collision costs.

    python bench/self_collision_floor.py [--size 64] [--times 0.6 1.2 1.8 2.4] [--repeats 7] [--steps 480]
"""

import argparse
import statistics
import time

import warp as wp

from warpcloth.kernels import self_contact as sk
from warpcloth.run.harness import Stopwatch
from warpcloth.scenarios import get_scenario

Vec3Array = wp.array(dtype=wp.vec3)
IntArray = wp.array(dtype=int)


@wp.func
def walk_cells(
    lo: wp.vec3i,
    hi: wp.vec3i,
    mask: int,
    head: IntArray,
    next_item: IntArray,
    box_lo: Vec3Array,
    box_hi: Vec3Array,
    item_cell: wp.array(dtype=wp.vec3i),
    lo_q: wp.vec3,
    hi_q: wp.vec3,
    after: int,
    test_boxes: int,
):
    # a search's walk of the cells lo..hi, each bucket's items down to the first <= after (the edge-edge search's
    # stop on the CPU; -1: every item), counting (items visited, items of the cell [whose box meets the query's])
    seen = int(0)
    met = int(0)
    for ci in range(lo[0], hi[0] + 1):
        for cj in range(lo[1], hi[1] + 1):
            for ck in range(lo[2], hi[2] + 1):
                f = head[sk.cell_bucket(ci, cj, ck, mask)]
                while f > after:
                    seen += 1
                    if test_boxes != 0:
                        if sk.boxes_overlap(box_lo[f], box_hi[f], lo_q, hi_q):
                            if item_cell[f] == wp.vec3i(ci, cj, ck):
                                met += 1
                    elif item_cell[f] == wp.vec3i(ci, cj, ck):
                        met += 1
                    f = next_item[f]
    return wp.vec2i(seen, met)


@wp.kernel
def walk_edges(
    scalars: wp.array(dtype=float),
    counts: IntArray,
    x: Vec3Array,
    edges: wp.array(dtype=wp.vec2i),
    mask: int,
    head: IntArray,
    next_item: IntArray,
    box_lo: Vec3Array,
    box_hi: Vec3Array,
    item_cell: wp.array(dtype=wp.vec3i),
    item_margin: wp.array(dtype=float),
    test_boxes: int,
    visits: IntArray,
    overlaps: IntArray,
):
    # the edge-edge search's walk (the same window, cells and order, the same stop at f <= e as on the CPU)
    e = wp.tid()
    a = x[edges[e][0]]
    b = x[edges[e][1]]
    r_e = scalars[sk.R_BUILD_EE] + item_margin[e]
    reach = sk.half_extents(scalars, sk.EDGE_HALF, r_e, a)
    lo, hi = sk.cell_range(wp.min(a, b) - reach, wp.max(a, b) + reach, scalars[sk.INV_CELL], counts)
    lo_e = wp.min(a, b) - wp.vec3(r_e)
    hi_e = wp.max(a, b) + wp.vec3(r_e)
    n = walk_cells(lo, hi, mask, head, next_item, box_lo, box_hi, item_cell, lo_e, hi_e, e, test_boxes)
    visits[e] = n[0]
    overlaps[e] = n[1]


@wp.kernel
def walk_triangles(
    scalars: wp.array(dtype=float),
    counts: IntArray,
    x: Vec3Array,
    margin: wp.array(dtype=float),
    mask: int,
    head: IntArray,
    next_item: IntArray,
    box_lo: Vec3Array,
    box_hi: Vec3Array,
    item_cell: wp.array(dtype=wp.vec3i),
    test_boxes: int,
    visits: IntArray,
    overlaps: IntArray,
):
    # the vertex-triangle search's walk (every item of each bucket), counting
    i = wp.tid()
    p = x[i]
    r_i = scalars[sk.R_BUILD] + margin[i]
    reach = sk.half_extents(scalars, sk.TRI_HALF, r_i, p)
    lo, hi = sk.cell_range(p - reach, p + reach, scalars[sk.INV_CELL], counts)
    lo_p = p - wp.vec3(r_i)
    hi_p = p + wp.vec3(r_i)
    n = walk_cells(lo, hi, mask, head, next_item, box_lo, box_hi, item_cell, lo_p, hi_p, -1, test_boxes)
    visits[i] = n[0]
    overlaps[i] = n[1]


def launches(sc, x):
    """name -> a function that runs that kernel pair once (both searches, or both minimal walks)."""
    n, d, mask = sc.model.particle_count, sc.device, sc.bucket_count - 1
    vis_v, met_v = wp.zeros(n, dtype=int, device=d), wp.zeros(n, dtype=int, device=d)
    vis_e, met_e = wp.zeros(sc.edge_count, dtype=int, device=d), wp.zeros(sc.edge_count, dtype=int, device=d)
    counts = sc.counts.numpy().copy()  # as after the build: a rebuild due, its candidate lists emptied for each search
    counts[sk.REBUILD], counts[sk.CAND_VT], counts[sk.CAND_EE] = 1, 0, 0

    def searches():
        sc.counts.assign(counts)
        wp.launch(
            sk.find_vertex_triangle_candidates,
            dim=n,
            inputs=[sc.counts, sc.scalars, x, sc.topology, sc.broad_phase],
            device=d,
        )
        wp.launch(
            sk.find_edge_edge_candidates,
            dim=sc.edge_count,
            inputs=[sc.counts, sc.scalars, x, sc.topology, sc.broad_phase],
            device=d,
        )

    def walks(test_boxes):
        def run():
            wp.launch(
                walk_triangles,
                dim=n,
                inputs=[sc.scalars, sc.counts, x, sc.margin, mask, sc.head_tri, sc.next_tri, sc.tri_lo, sc.tri_hi]
                + [sc.tri_cell, test_boxes],
                outputs=[vis_v, met_v],
                device=d,
            )
            wp.launch(
                walk_edges,
                dim=sc.edge_count,
                inputs=[sc.scalars, sc.counts, x, sc.edges, mask, sc.head_edge, sc.next_edge, sc.edge_lo]
                + [sc.edge_hi, sc.edge_cell, sc.edge_margin, test_boxes],
                outputs=[vis_e, met_e],
                device=d,
            )

        return run

    walks(1)()
    tallies = {
        "visits a vertex query": float(vis_v.numpy().mean()),
        "boxes met a vertex query": float(met_v.numpy().mean()),
        "visits an edge query": float(vis_e.numpy().mean()),
        "boxes met an edge query": float(met_e.numpy().mean()),
    }
    return {"searches": searches, "walk": walks(0), "boxes": walks(1)}, tallies


def spread(values):
    return f"{statistics.median(values):.2f} [{min(values):.2f}-{max(values):.2f}]"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--size", type=int, default=64)
    ap.add_argument("--times", type=float, nargs="+", default=[0.6, 1.2, 1.8, 2.4])
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--steps", type=int, default=480)
    args = ap.parse_args()
    wp.config.quiet = True
    wp.init()
    print(
        f"# python bench/self_collision_floor.py --size {args.size} --times {' '.join(map(str, args.times))} "
        f"--repeats {args.repeats} --steps {args.steps}"
    )
    fold = get_scenario("fold")
    sim = fold.build(rows=args.size, cols=args.size, device="cpu", use_graph=False)  # self-collision on
    plain = fold.build(rows=args.size, cols=args.size, device="cpu", use_graph=True, self_collision=False)
    sc, frame = sim.self_collision, max(1, round((1.0 / 60.0) / sim.dt))
    interval = sim._interval_steps() * sim.dt
    print(f"# warp {wp.config.version}; fold {args.size}x{args.size}, ms a build: median [min-max] of {args.repeats}")
    for t in args.times:
        while sim.sim_time < t - 1e-9:
            sim.simulate(frame)
        q, qd = wp.clone(sim.state.particle_q), wp.clone(sim.state.particle_qd)
        # the rebuilds a run makes from here (and the step's own cost, the same steps without self-collision)
        sc.reset_stats()
        sim.simulate(args.steps)
        stats = sc.stats()
        rebuilds_a_step = stats["rebuilds"] / args.steps
        plain_ms = []
        for r in range(6):
            wp.copy(plain.state.particle_q, q)
            wp.copy(plain.state.particle_qd, qd)
            with Stopwatch("cpu") as watch:
                plain.simulate(args.steps)
            if r:
                plain_ms.append(1000.0 * watch.seconds / args.steps)
        step_ms = statistics.median(plain_ms)
        # one build at the snapshot's state by a second list of the same settings (the run's own list and its
        # course untouched), then its searches and the minimal walks over it
        probe = sc.rebind(sim.model)
        probe.detect(q, qd, interval)
        runs, tallies = launches(probe, q)
        ms = {k: [] for k in runs}
        for _ in range(args.repeats):
            for name, run in runs.items():
                t0 = time.perf_counter()
                run()
                ms[name].append(1000.0 * (time.perf_counter() - t0))
        cands = probe.stats()
        print(
            f"t = {t:.1f} s: {stats['rebuilds']} rebuilds in {args.steps} steps ({rebuilds_a_step:.3f} a step), "
            f"a step without self-collision {step_ms:.3f} ms; candidates {cands['candidates_vertex_triangle']}"
            f"+{cands['candidates_edge_edge']}; " + ", ".join(f"{k} {v:.1f}" for k, v in tallies.items())
        )
        for name in runs:
            share = statistics.median(ms[name]) * rebuilds_a_step / step_ms
            print(f"  {name:9s} {spread(ms[name])} ms a build, x {rebuilds_a_step:.3f} a step: {share:.2f} x a step")


if __name__ == "__main__":
    main()
