"""Self-collision settings compared from the same states (issue 29): the fold at N x N under explicit_euler,
run with the default settings to each snapshot time; from each snapshot, ``--steps`` steps with each value of
one :class:`~warpcloth.sim.self_collision.SelfCollision` setting (a simulator of its own per value, its
captured graph replayed; the values alternated, ``--repeats`` times after a first, uncounted replay).

Each value's runs start from the same positions, velocities and time, so the states' differences do not
blur the settings' (a whole run per value would reach different folded states). Prints ms per step,
median [min-max], with the rebuilds and the largest lists of each.

    python bench/self_collision_settings.py --setting skin --values 0.005 0.0075 0.01
                                            [--size 64] [--steps 1500] [--repeats 3] [--snapshots 0.6 1.2 1.8 2.4 3.0]
"""

import argparse
import statistics

import warp as wp
from self_collision import snapshot  # bench/self_collision.py (this script's folder leads sys.path)

from warpcloth.run.harness import Stopwatch
from warpcloth.scenarios import get_scenario
from warpcloth.sim.self_collision import SelfCollision


def number(text: str):
    """An integer where written as one (passes, iterations, capacities), else a float."""
    try:
        return int(text)
    except ValueError:
        return float(text)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--setting", required=True, help="a SelfCollision keyword argument (skin, skin_max, interval, ...)")
    ap.add_argument("--values", type=number, nargs="+", required=True)
    ap.add_argument("--size", type=int, default=64)
    ap.add_argument("--steps", type=int, default=1500)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--snapshots", type=float, nargs="+", default=[0.6, 1.2, 1.8, 2.4, 3.0])
    args = ap.parse_args()
    wp.config.quiet = True
    fold = get_scenario("fold")
    base = fold.build(rows=args.size, cols=args.size, device="cpu", use_graph=True)
    settings = base.self_collision.settings()
    if args.setting not in settings:
        raise SystemExit(f"--setting must be one of {', '.join(sorted(settings))}, got {args.setting!r}")
    runs = {}
    for value in args.values:
        sim = fold.build(rows=args.size, cols=args.size, device="cpu", use_graph=True)
        sim.set_self_collision(SelfCollision(sim.model, **{**settings, args.setting: value}))
        runs[value] = sim
    frame = max(1, round((1.0 / 60.0) / base.dt))
    print(
        f"# python bench/self_collision_settings.py --setting {args.setting} --values "
        f"{' '.join(map(str, args.values))} --size {args.size} --steps {args.steps} --repeats {args.repeats}"
    )
    print(f"# warp {wp.config.version}; fold {args.size}x{args.size} explicit_euler, ms a step: median [min-max]")
    for t in sorted(args.snapshots):
        while base.sim_time < t - 1e-9:
            base.simulate(frame)
        start = snapshot(base)
        times = {value: [] for value in args.values}
        stats = {}
        for r in range(args.repeats + 1):  # the first replays capture the graphs (not counted)
            for value, sim in runs.items():
                start(sim)
                with Stopwatch(sim.model.device) as watch:
                    sim.simulate(args.steps)
                stats[value] = sim.self_collision.stats()
                sim.self_collision.reset_stats()
                if r:
                    times[value].append(1000.0 * watch.seconds / args.steps)
        for value in args.values:
            ms, k = times[value], stats[value]
            print(
                f"t = {t:.1f} s  {args.setting} = {value:g}: {statistics.median(ms):.3f} [{min(ms):.3f}-{max(ms):.3f}] "
                f"ms  (rebuilds {k['rebuilds']} of {k['detects']} intervals, candidates up to {k['candidates_max']}, "
                f"contacts up to {k['contacts_max']})",
                flush=True,
            )


if __name__ == "__main__":
    main()
