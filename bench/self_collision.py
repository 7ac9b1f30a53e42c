"""Cost of self-collision in the fold scene (issue 29): ms per explicit_euler step of the fold at
N x N with self-collision on and off, from the same states, against the step without it.

The fold (``warpcloth run fold``: a strip lowered onto the ground and folded back over itself) is
run with self-collision on to each snapshot time (0.6 s: hanging, 1.2 s: laid on the ground, 1.8 s:
folding, 2.4 s: folded, 3.0 s: at rest in layers). From each snapshot, ``--repeats`` times
alternately: ``--steps`` steps with self-collision (detect at the start of each collision interval
of at most ``--interval`` s, filter at its end; the candidate list rebuilt at the first and whenever
the cloth moved, as in a run) and the same steps by a second simulator of the same
fold without it, each timed as a captured graph replayed once (CPU capture, Warp >= 1.19), both
started from the snapshot's state. The cost is the median over the
repeats of (on - off) / off of the same repeat, with its min-max (machine noise falls on both).

    python bench/self_collision.py [--sizes 32 64 128] [--steps 60] [--repeats 5] [--device cpu] [--until 3.0]
                                   [--interval 0.001] [--ccd-passes K]
"""

import argparse
import statistics
import time

import warp as wp

from warpcloth.run.harness import Stopwatch
from warpcloth.run.params import BY_NAME
from warpcloth.scenarios import get_scenario
from warpcloth.sim.self_collision import SelfCollision

SNAPSHOTS = (0.6, 1.2, 1.8, 2.4, 3.0)


def timed(sim, steps, device):
    """Seconds of ``steps`` steps of ``sim`` (its captured graph, replayed once after a first replay)."""
    with Stopwatch(device) as watch:
        sim.simulate(steps)
    return watch.seconds


def snapshot(sim):
    """The state of ``sim`` now, as a function that puts any simulator of the same scene into it (the
    integrator, the pins and the candidate list start from it)."""
    saved = [wp.clone(a) for a in (sim.state.particle_q, sim.state.particle_qd, sim.control.time)]
    saved_time, saved_steps = sim.sim_time, sim.steps

    def start(s):
        for dst, src in zip((s.state.particle_q, s.state.particle_qd, s.control.time), saved):
            wp.copy(dst, src)
        s.sim_time, s.steps = saved_time, saved_steps
        s._rebase_clock()
        s._needs_begin = True

    return start


def measure(size, steps, repeats, device, until=3.0, interval=None, ccd_passes=None):
    fold = get_scenario("fold")
    sim = fold.build(
        rows=size, cols=size, device=device, use_graph=True, self_collision_interval=interval
    )  # self-collision on
    if ccd_passes is not None:  # the continuous response's passes (0: off)
        settings = {**sim.self_collision.settings(), "ccd_passes": ccd_passes}
        sim.set_self_collision(SelfCollision(sim.model, **settings))
    plain = fold.build(rows=size, cols=size, device=device, use_graph=True, self_collision=False)
    sc = sim.self_collision
    frame = max(1, round((1.0 / 60.0) / sim.dt))
    rows = []
    for t in (t for t in SNAPSHOTS if t <= until + 1e-9):
        while sim.sim_time < t - 1e-9:
            sim.simulate(frame)
        start = snapshot(sim)
        on, off, stats = [], [], None
        for r in range(repeats + 1):  # the first repeat captures the graphs (not counted)
            for s in (sim, plain):
                start(s)
                seconds = timed(s, steps, device)
                if s is sim:
                    stats = sc.stats()
                    sc.reset_stats()
                if r:
                    (on if s is sim else off).append(1000.0 * seconds / steps)
        start(sim)
        ratios = [(a - b) / b for a, b in zip(on, off)]
        rows.append((t, on, off, ratios, stats))
    return sim, rows


def spread(values, fmt="{:.3f}"):
    return f"{fmt.format(statistics.median(values))} [{fmt.format(min(values))}-{fmt.format(max(values))}]"


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[32, 64, 128])
    ap.add_argument("--steps", type=int, default=60)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--until", type=float, default=3.0, help="the last snapshot time [s] (128 x 128 runs long)")
    ap.add_argument(
        "--interval",
        type=float,
        default=BY_NAME["self_collision_interval"].default,
        help="the self-collision interval [s] (0: every step)",
    )
    ap.add_argument(
        "--ccd-passes", type=int, default=None, help="the continuous response's passes (0: off; default the library's)"
    )
    args = ap.parse_args()
    wp.init()
    ccd = "" if args.ccd_passes is None else f" --ccd-passes {args.ccd_passes}"
    print(
        f"# python bench/self_collision.py --sizes {' '.join(map(str, args.sizes))} --steps {args.steps} "
        f"--repeats {args.repeats} --device {args.device} --until {args.until} --interval {args.interval}{ccd}"
    )
    print(f"# warp {wp.config.version}; ms per explicit_euler step: median [min-max] of {args.repeats} repeats")
    for size in args.sizes:
        t0 = time.perf_counter()
        sim, rows = measure(size, args.steps, args.repeats, args.device, args.until, args.interval, args.ccd_passes)
        print(
            f"fold {size}x{size} ({sim.model.particle_count} vertices, dt {sim.dt:.3g} s, thickness "
            f"{sim.self_collision.thickness} m, {sim._interval_steps()} steps per collision interval)"
        )
        every = []
        for t, on, off, ratios, st in rows:
            every += ratios
            print(
                f"  t = {t:3.1f} s  off {spread(off)} ms  on {spread(on)} ms  "
                f"self-collision {spread(ratios, '{:+.2f}')} x a step   (contacts up to {st['contacts_max']}, "
                f"candidates {st['candidates_vertex_triangle']}+{st['candidates_edge_edge']}, "
                f"rebuilds {st['rebuilds']} of {st['detects']} detects in {args.steps} steps, "
                f"continuous collisions {st['ccd_collisions']})"
            )
        print(
            f"  all snapshots: self-collision {spread(every, '{:+.2f}')} x an explicit_euler step "
            f"({time.perf_counter() - t0:.0f} s)",
            flush=True,
        )


if __name__ == "__main__":
    main()
