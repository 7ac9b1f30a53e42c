"""Cost of the self-collision list's swept check (``SelfCollision._cover_swept``: before the continuous
response, the list is rebuilt over the step's motion where the end positions fail the detect's coverage
test): ms a step of a scene with the check and with it replaced by a no-op (which leaves the list as the
detect built it, as before the check), medians [min-max] of repeats alternated within one process, each a
fresh run from the scene's start for ``--seconds`` of simulated time (captured frames, as `warpcloth run`
replays them; the first frame, which compiles and captures, is not timed), with the rebuild counters.

    python bench/swept_check.py [--scene fold] [--size 64] [--integrator explicit_euler] [--seconds 1.5]
                                [--repeats 3]
"""

import argparse
import statistics
import time

import warp as wp

from warpcloth.scenarios import get_scenario
from warpcloth.sim.self_collision import SelfCollision

CHECK = SelfCollision._cover_swept


def run(scene: str, size: int, integrator: str, seconds: float, check: bool) -> tuple[float, dict]:
    SelfCollision._cover_swept = CHECK if check else (lambda self, x, skip_capped=False: None)
    try:
        sim = get_scenario(scene).build(rows=size, cols=size, integrator=integrator, self_collision=True)
        frame = max(1, round((1.0 / 60.0) / sim.dt))
        sim.simulate(frame)  # compile and capture, untimed
        start, t0 = sim.steps, time.perf_counter()
        while sim.sim_time < seconds - 1e-9:
            sim.simulate(frame)
        wp.synchronize_device(sim.model.device)
        ms = (time.perf_counter() - t0) / max(1, sim.steps - start) * 1e3
    finally:
        SelfCollision._cover_swept = CHECK
    return ms, sim.self_collision.stats()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="fold")
    ap.add_argument("--size", type=int, default=64)
    ap.add_argument("--integrator", default="explicit_euler")
    ap.add_argument("--seconds", type=float, default=1.5)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    wp.config.quiet = True
    times, stats = {False: [], True: []}, {}
    for _ in range(args.repeats):
        for check in (False, True):
            ms, stats[check] = run(args.scene, args.size, args.integrator, args.seconds, check)
            times[check].append(ms)
    print(
        f"# python bench/swept_check.py --scene {args.scene} --size {args.size} --integrator {args.integrator} "
        f"--seconds {args.seconds} --repeats {args.repeats}"
    )
    print(f"# warp {wp.config.version}; ms a step: median [min-max] of {args.repeats} repeats")

    def cell(values):
        return f"{statistics.median(values):.3f} [{min(values):.3f}-{max(values):.3f}]"

    def counts(s):
        return f"rebuilds {s['rebuilds']} of {s['detects']} detects, swept {s['swept_rebuilds']}, fast {s['fast']}"

    off, on = times[False], times[True]
    label = f"{args.scene} {args.size}x{args.size} {args.integrator}"
    print(f"{label}: without the check {cell(off)} ({counts(stats[False])})")
    change = statistics.median(on) / statistics.median(off) - 1.0
    print(f"{label}: with it           {cell(on)} ({counts(stats[True])})  {change:+.1%}")


if __name__ == "__main__":
    main()
