"""Cost of a step with dihedral bending against Provot bend springs, per integrator.

    python bench/bending_step_cost.py [--size 64] [--integrators explicit_euler implicit_euler ...]
                                      [--steps 20] [--windows 5] [--device cpu]

The sheet scenario at size x size with ``--bend provot`` and ``--bend dihedral`` (cotton's B), each
integrator at its default options and dt. Per configuration: the median over ``--windows`` timed
windows of ``--steps`` steps [ms/step], the two bend models' windows alternating (the machine's load
then affects both alike), after a warm-up (compile, capture). Prints a table and the ratio.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import warp as wp

from warpcloth.integrators import integrator_names
from warpcloth.scenarios import sheet


def window(sim, steps: int) -> float:
    wp.synchronize_device(sim.model.device)
    t = time.perf_counter()
    sim.simulate(steps)
    wp.synchronize_device(sim.model.device)
    return (time.perf_counter() - t) / steps * 1e3


def measure(name: str, size: int, steps: int, windows: int, device: str) -> dict:
    sims = {
        bend: sheet.build(rows=size, cols=size, integrator=name, bend=bend, device=device)
        for bend in ("provot", "dihedral")
    }
    for sim in sims.values():  # compile, capture both step counts
        sim.simulate(steps)
        sim.simulate(steps)
    times = {bend: [] for bend in sims}
    for _ in range(windows):
        for bend, sim in sims.items():
            times[bend].append(window(sim, steps))
    out = {bend: float(np.median(t)) for bend, t in times.items()}
    out["hinges"] = sims["dihedral"].model.hinge_count
    out["springs"] = (sims["provot"].model.spring_count, sims["dihedral"].model.spring_count)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=64)
    parser.add_argument("--integrators", nargs="+", default=integrator_names())
    parser.add_argument("--steps", type=int, default=20)
    parser.add_argument("--windows", type=int, default=5)
    parser.add_argument("--device", default="cpu")
    args = parser.parse_args()
    print(
        f"sheet {args.size}x{args.size} on {args.device}, ms/step (median of {args.windows} windows of {args.steps} "
        "steps)"
    )
    print("| integrator | provot | dihedral | ratio |")
    print("|---|---|---|---|")
    for name in args.integrators:
        r = measure(name, args.size, args.steps, args.windows, args.device)
        print(f"| {name} | {r['provot']:.2f} | {r['dihedral']:.2f} | {r['dihedral'] / r['provot']:.2f} |", flush=True)


if __name__ == "__main__":
    main()
