"""Where a self-collision run's time goes, kernel by kernel (issue 29): the fold at N x N run for
``--seconds`` with every ``wp.launch`` timed on the host (plain launches, not a captured graph, so
the figures carry Python's launch overhead, a few microseconds each; on the CPU a launch returns when
its kernel is done; the first step, which loads the modules, is not timed). Prints ms per step of each
kernel, largest first, and the self-collision counters.

    python bench/self_collision_profile.py [--size 64] [--seconds 3.0] [--integrator explicit_euler]
                                           [--self-collision on|off] [--top 30] [--start 0.0]

``--start``: run to this time untimed first (a later phase of the fold: 2.4 s folded); the counters
then count from there, to ``--seconds`` (an end time, not a duration).
"""

import argparse
import collections
import time

import warp as wp

from warpcloth.scenarios import get_scenario


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=64)
    ap.add_argument("--seconds", type=float, default=3.0)
    ap.add_argument("--integrator", default="explicit_euler")
    ap.add_argument("--self-collision", choices=("on", "off"), default="on")
    ap.add_argument("--top", type=int, default=30)
    ap.add_argument("--start", type=float, default=0.0)
    args = ap.parse_args()
    wp.config.quiet = True
    sim = get_scenario("fold").build(
        rows=args.size,
        cols=args.size,
        integrator=args.integrator,
        device="cpu",
        use_graph=False,
        self_collision=args.self_collision == "on",
    )
    frame = max(1, round((1.0 / 60.0) / sim.dt))
    seconds, calls = collections.defaultdict(float), collections.Counter()
    launch = wp.launch

    def timed(kernel, *a, **kw):
        t = time.perf_counter()
        out = launch(kernel, *a, **kw)
        name = getattr(kernel, "key", str(kernel))
        seconds[name] += time.perf_counter() - t
        calls[name] += 1
        return out

    sim.simulate(1)  # module loads and first launches, untimed
    while sim.sim_time < args.start - 1e-9:
        sim.simulate(frame)
    if sim.self_collision is not None:
        sim.self_collision.reset_stats()
    wp.launch = timed
    try:
        start, t0 = sim.steps, time.perf_counter()
        while sim.sim_time < args.seconds - 1e-9:
            sim.simulate(frame)
        wall, steps = time.perf_counter() - t0, sim.steps - start
    finally:
        wp.launch = launch
    print(
        f"# python bench/self_collision_profile.py --size {args.size} --seconds {args.seconds} "
        f"--integrator {args.integrator} --self-collision {args.self_collision} --start {args.start}"
    )
    print(f"# warp {wp.config.version}; fold {args.size}x{args.size}, dt {sim.dt:.3g} s, {steps} steps")
    print(f"launches {sum(seconds.values()) * 1e3 / steps:.3f} ms a step, wall {wall * 1e3 / steps:.3f} ms a step")
    if sim.self_collision is not None:
        print("counters:", sim.self_collision.stats())
    for name, s in sorted(seconds.items(), key=lambda kv: -kv[1])[: args.top]:
        print(f"  {name:42s} {s * 1e3 / steps:8.4f} ms a step  ({calls[name]} launches)")


if __name__ == "__main__":
    main()
