"""Cost of one implicit_euler step at dt = 1/60 s against explicit_euler steps on the same sheet.

    python bench/implicit.py [--device cpu] [--sizes 64 128] [--steps 10] [--matrix free bsr]

For each sheet size and system matrix (matrix-free LinearOperator and assembled BSR), prints
ms/step of implicit_euler (kernel time after warm-up, from the sheet at rest: the first steps
of its fall), the mean and max CG iterations, and the ratio to the cost of 12 explicit_euler
steps of the same sheet measured in the same run (the issue's target is a ratio < 1).
"""

from __future__ import annotations

import argparse
import time

import warp as wp

from warpcloth.scenarios import sheet


def ms_per_step(sim, steps: int) -> float:
    """Mean wall time of ``steps`` steps [ms], after warm-up, synchronised."""
    sim.warm_up()
    wp.synchronize_device(sim.model.device)
    t0 = time.perf_counter()
    sim.simulate(steps)
    wp.synchronize_device(sim.model.device)
    return 1000.0 * (time.perf_counter() - t0) / steps


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--device", default="cpu")
    p.add_argument("--sizes", type=int, nargs="+", default=[64, 128])
    p.add_argument("--steps", type=int, default=10, help="implicit steps timed per case")
    p.add_argument("--explicit-steps", type=int, default=100)
    p.add_argument("--matrix", nargs="+", default=["free", "bsr"], choices=["free", "bsr"])
    p.add_argument("--cg-tol", type=float, default=None)
    p.add_argument("--cg-max-iter", type=int, default=None)
    p.add_argument("--jacobian", default=None, choices=["full", "approx"])
    args = p.parse_args(argv)
    options = {k: v for k, v in (("cg_tol", args.cg_tol), ("cg_max_iter", args.cg_max_iter), ("jacobian", args.jacobian)) if v is not None}

    with wp.ScopedDevice(args.device):
        print(f"device {wp.get_device()}, warp {wp.config.version}, implicit options {options or 'defaults'}")
        print(f"{'sheet':>9} {'matrix':>6} {'ms/step':>9} {'CG mean':>8} {'CG max':>7} {'explicit ms':>12} {'ratio to 12 explicit':>21}")
        for n in args.sizes:
            explicit = sheet.build(rows=n, cols=n, integrator="explicit_euler", device=args.device)
            explicit_ms = ms_per_step(explicit, args.explicit_steps)
            for matrix in args.matrix:
                sim = sheet.build(rows=n, cols=n, integrator="implicit_euler", dt=1.0 / 60.0, device=args.device, integrator_options={**options, "matrix": matrix})
                ms = ms_per_step(sim, args.steps)
                st = sim.integrator.stats()
                print(f"{n:>4}x{n:<4} {matrix:>6} {ms:9.2f} {st['cg_iterations_mean']:8.1f} {st['cg_iterations_max']:7d} {explicit_ms:12.3f} {ms / (12.0 * explicit_ms):21.2f}")


if __name__ == "__main__":
    main()
