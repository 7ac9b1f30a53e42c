"""Cost of the collider edge contacts (``--collider-edges on``): ms a step of the tablecloth scene
with them off and on, medians [min-max] of repeats alternated within one process, each repeat a fresh
run from the scene's start for ``--seconds`` of simulated time (captured frames, as `warpcloth run`
replays them; the first frame, which compiles and captures, is not timed).

    python bench/edge_contacts.py [--size 64] [--integrator explicit_euler] [--seconds 0.3] [--repeats 3]
                                  [--sharp]

``--sharp`` gives the table sharp edges (``edge_radius`` 0), where the contacts have work to do; by
default its edges are rounded (the scene's default), and the contacts mostly find nothing.
"""

import argparse
import statistics
import time
from dataclasses import replace

import warp as wp

from warpcloth.scenarios import get_scenario


def run(size: int, integrator: str, seconds: float, edges: bool, sharp: bool) -> float:
    sim = get_scenario("tablecloth").build(rows=size, cols=size, integrator=integrator, collider_edges=edges)
    if sharp:
        sim.control.colliders = tuple(
            replace(c, edge_radius=0.0) if c.kind == "box" else c for c in sim.control.colliders
        )
        sim.control.collision.edge_contacts = edges
    frame = max(1, round((1.0 / 60.0) / sim.dt))
    sim.simulate(frame)  # compile and capture, untimed
    start, t0 = sim.steps, time.perf_counter()
    while sim.sim_time < seconds - 1e-9:
        sim.simulate(frame)
    wp.synchronize_device(sim.model.device)
    return (time.perf_counter() - t0) / max(1, sim.steps - start) * 1e3


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=64)
    ap.add_argument("--integrator", default="explicit_euler")
    ap.add_argument("--seconds", type=float, default=0.3)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--sharp", action="store_true")
    args = ap.parse_args()
    wp.config.quiet = True
    times = {False: [], True: []}
    for _ in range(args.repeats):
        for edges in (False, True):
            times[edges].append(run(args.size, args.integrator, args.seconds, edges, args.sharp))
    print(
        f"# python bench/edge_contacts.py --size {args.size} --integrator {args.integrator} --seconds {args.seconds} "
        f"--repeats {args.repeats}{' --sharp' if args.sharp else ''}"
    )
    print(f"# warp {wp.config.version}; ms a step: median [min-max] of {args.repeats} repeats")

    def cell(values):
        return f"{statistics.median(values):.3f} [{min(values):.3f}-{max(values):.3f}]"

    off, on = times[False], times[True]
    print(
        f"tablecloth {args.size}x{args.size} {args.integrator}: edge contacts off {cell(off)}  on {cell(on)}  "
        f"+{statistics.median(on) / statistics.median(off) - 1.0:.2f}x"
    )


if __name__ == "__main__":
    main()
