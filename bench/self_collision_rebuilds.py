"""How often a candidate list must be rebuilt in the fold, under the library's rule and three others
(issue 29). The fold at N x N is run (explicit_euler, self-collision on) from ``--start`` for
``--intervals`` collision intervals, one ``simulate`` call an interval, and the positions and velocities
at every interval's start are kept (float64). Then each rule is replayed over those states in NumPy:

- ``library``: rebuild when 2 max_i (D_i - m_i) > skin, D_i = |x_i - x_build_i - u| + |v_i - w| T (u, w:
  the mean displacement and velocity, T: the interval), m_i = |v_i - w| T at the build
  (``kernels/self_contact.decide_self_contact_rebuild``);
- ``two largest``: the same with the two largest D_i - m_i of distinct vertices summed (a pair has two);
- ``predicted, W``: each vertex is expected to go on in a straight line at its velocity at the build, and a
  pair is listed by its gap at the build less its sides' largest difference of that motion over W intervals;
  rebuilt at the window's end, or when a vertex strays from its line (relative to the mean) by skin / 2
  (its velocity's change over the coming interval included);
- ``per vertex``: each vertex keeps its own reference (its position and the mean position when it was last
  queried, its margin then); only the vertices whose own D_i - m_i exceeds skin / 2 are queried again (every
  other box grown by its own motion since its reference: the list's guarantee holds without a factor 2);
  reported as the share of edges with a requeried vertex, each interval.

Each rule is replayed alone: a run also rebuilds over a step's swept motion where the solve or a projection
moved a vertex beyond its margin (``swept_rebuilds``), which these counts leave out.

    python bench/self_collision_rebuilds.py [--size 64] [--start 0.5 1.5 2.3] [--intervals 300]
"""

import argparse

import numpy as np
import warp as wp

from warpcloth.scenarios import get_scenario


def record(size, start, intervals):
    """States at the starts of ``intervals`` collision intervals from ``start`` [s]: x, v (K, n, 3), times."""
    sim = get_scenario("fold").build(rows=size, cols=size, device="cpu", use_graph=False)  # self-collision on
    frame, k = max(1, round((1.0 / 60.0) / sim.dt)), sim._interval_steps()
    while sim.sim_time < start - 1e-9:
        sim.simulate(frame)
    xs, vs, ts = [], [], []
    for _ in range(intervals):
        xs.append(sim.state.particle_q.numpy().astype(np.float64))
        vs.append(sim.state.particle_qd.numpy().astype(np.float64))
        ts.append(sim.sim_time)
        sim.simulate(k)
    sc = sim.self_collision
    return np.array(xs), np.array(vs), np.array(ts), k * sim.dt, sc


def relative(a):
    return np.linalg.norm(a - a.mean(axis=0), axis=1)


def library(xs, vs, T, skin, skin_max, two=False):
    rebuilds, xb, m = 0, None, None
    for x, v in zip(xs, vs):
        if xb is not None:
            d = x - xb
            excess = np.sort(relative(d) + relative(v) * T - m)
            if (excess[-1] + excess[-2] if two else 2.0 * excess[-1]) <= skin:
                continue
        rebuilds, xb, m = rebuilds + 1, x.copy(), np.minimum(relative(v) * T, skin_max)
    return rebuilds


def predicted(xs, vs, ts, T, skin, skin_max, window):
    rebuilds, xb, vb, tb, span = 0, None, None, 0.0, 0.0
    for x, v, t in zip(xs, vs, ts):
        if xb is not None and t - tb + T <= span * (1.0 + 1e-9):
            stray = relative(x - xb - (t - tb) * vb) + relative(v - vb) * T
            if 2.0 * stray.max() <= skin:
                continue
        rebuilds, xb, vb, tb = rebuilds + 1, x.copy(), v.copy(), t
        span = max(T, min(window * T, skin_max / max(relative(v).max(), 1e-12)))  # margins within skin_max
    return rebuilds


def per_vertex(xs, vs, T, skin, skin_max, edges):
    shares, ref, m = [], None, None
    for x, v in zip(xs, vs):
        y = x - x.mean(axis=0)
        speed = relative(v)
        if ref is None:
            ref, m = y.copy(), np.minimum(speed * T, skin_max)
            continue
        due = np.linalg.norm(y - ref, axis=1) + speed * T - m > 0.5 * skin
        shares.append(float(due[edges].any(axis=1).mean()))
        ref[due], m[due] = y[due], np.minimum(speed[due] * T, skin_max)
    return np.array(shares)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--size", type=int, default=64)
    ap.add_argument("--start", type=float, nargs="+", default=[0.5, 1.5, 2.3])
    ap.add_argument("--intervals", type=int, default=300)
    args = ap.parse_args()
    wp.config.quiet = True
    print(
        f"# python bench/self_collision_rebuilds.py --size {args.size} --start {' '.join(map(str, args.start))} "
        f"--intervals {args.intervals}"
    )
    for start in args.start:
        xs, vs, ts, T, sc = record(args.size, start, args.intervals)
        skin, skin_max, edges = sc.skin, sc.skin_max, sc.edge_array()
        dv = np.linalg.norm(vs[:, edges[:, 0]] - vs[:, edges[:, 1]], axis=2)
        print(
            f"from {start:.1f} s, {args.intervals} intervals of {1000 * T:.3f} ms: an edge's two ends' relative speed "
            f"median {np.median(dv):.2f}, 99th percentile {np.percentile(dv, 99):.2f}, largest {dv.max():.2f} m/s"
        )
        print(f"  library: {library(xs, vs, T, skin, skin_max)} rebuilds")
        print(f"  two largest: {library(xs, vs, T, skin, skin_max, two=True)} rebuilds")
        for w in (2, 4, 8):
            print(f"  predicted, W = {w}: {predicted(xs, vs, ts, T, skin, skin_max, w)} rebuilds")
        share = per_vertex(xs, vs, T, skin, skin_max, edges)
        print(
            f"  per vertex: {100 * share.mean():.0f} % of the edges requeried an interval "
            f"(median {100 * np.median(share):.0f} %)"
        )


if __name__ == "__main__":
    main()
