"""Cost of one implicit_euler step at dt = 1/60 s against explicit_euler steps on the same sheet.

    python bench/implicit.py [--device cpu] [--sizes 64 128] [--steps 10] [--matrix free bsr] [--repeats 3]

For each sheet size and system matrix (matrix-free LinearOperator and assembled BSR), prints
ms/step of implicit_euler (kernel time after warm-up, from the sheet at rest: the first steps
of its fall), the mean and max CG iterations, and the ratio to the cost of 12 explicit_euler
steps of the same sheet measured in the same run (the issue's target is a ratio < 1).

With ``--repeats N`` every case is timed N times, the matrices alternating (free, bsr, free,
bsr, ...) so that load on a shared machine falls on both, and a summary gives the median
ms/step with its range (min-max) and, with both matrices, the bsr / free ratio per step and per
CG iteration (median of the per-repeat ratios, with their range).
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import time

import warp as wp

from warpcloth.scenarios import sheet


def ms_per_step(sim, steps: int) -> float:
    """Mean wall time of ``steps`` steps [ms] from the current state, after warm-up (and, where
    frames are captured, after an untimed first capture), synchronised."""
    sim.warm_up()
    if sim.graph_enabled:
        sim.simulate(steps)  # capture the graph of ``steps`` steps outside the timing
        sim.reset()
    wp.synchronize_device(sim.model.device)
    t0 = time.perf_counter()
    sim.simulate(steps)
    wp.synchronize_device(sim.model.device)
    return 1000.0 * (time.perf_counter() - t0) / steps


def _num(v: float) -> str:
    return f"{v:.0f}" if abs(v) >= 100 else f"{v:.3g}"


def spread(values) -> str:
    """median [min-max] of ``values``."""
    return f"{_num(statistics.median(values))} [{_num(min(values))}-{_num(max(values))}]"


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--device", default="cpu")
    p.add_argument("--sizes", type=int, nargs="+", default=[64, 128])
    p.add_argument("--steps", type=int, default=10, help="implicit steps timed per case")
    p.add_argument("--explicit-steps", type=int, default=100)
    p.add_argument("--matrix", nargs="+", default=["free", "bsr"], choices=["free", "bsr"])
    p.add_argument(
        "--repeats",
        type=int,
        default=1,
        help="times each case is timed (matrices alternating); > 1 adds a median summary",
    )
    p.add_argument("--cg-tol", type=float, default=None)
    p.add_argument("--cg-max-iter", type=int, default=None)
    p.add_argument("--jacobian", default=None, choices=["full", "approx"])
    args = p.parse_args(argv)
    options = {
        k: v
        for k, v in (("cg_tol", args.cg_tol), ("cg_max_iter", args.cg_max_iter), ("jacobian", args.jacobian))
        if v is not None
    }

    with wp.ScopedDevice(args.device):
        print(
            f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, {os.cpu_count()} CPU cores "
            f"({platform.processor() or platform.machine()}), device {wp.get_device()}, warp {wp.config.version}, "
            f"implicit options {options or 'defaults'}, {args.steps} steps per case, {args.repeats} repeat(s)"
        )
        print(
            f"{'sheet':>9} {'matrix':>6} {'ms/step':>9} {'CG mean':>8} {'CG max':>7} {'explicit ms':>12} "
            f"{'ratio to 12 explicit':>21}"
        )
        summary = []
        for n in args.sizes:
            explicit = sheet.build(rows=n, cols=n, integrator="explicit_euler", device=args.device)
            sims = {
                matrix: sheet.build(
                    rows=n,
                    cols=n,
                    integrator="implicit_euler",
                    dt=1.0 / 60.0,
                    device=args.device,
                    integrator_options={**options, "matrix": matrix},
                )
                for matrix in args.matrix
            }
            ms = {matrix: [] for matrix in args.matrix}
            ms_iter = {matrix: [] for matrix in args.matrix}
            for _ in range(args.repeats):
                explicit.reset()
                explicit_ms = ms_per_step(explicit, args.explicit_steps)
                for matrix, sim in sims.items():
                    sim.reset()  # every repeat times the same steps: the first ones of the fall from rest
                    t = ms_per_step(sim, args.steps)
                    st = sim.integrator.stats()
                    ms[matrix].append(t)
                    ms_iter[matrix].append(t / max(st["cg_iterations_mean"], 1e-9))
                    print(
                        f"{n:>4}x{n:<4} {matrix:>6} {t:9.2f} {st['cg_iterations_mean']:8.1f} "
                        f"{st['cg_iterations_max']:7d} {explicit_ms:12.3f} {t / (12.0 * explicit_ms):21.2f}",
                        flush=True,
                    )
            summary.append((n, ms, ms_iter))
        if args.repeats > 1:
            print(f"\nmedian [min-max] over {args.repeats} repeats")
            for n, ms, ms_iter in summary:
                line = f"{n:>4}x{n:<4} " + ", ".join(
                    f"{matrix} {spread(values)} ms/step" for matrix, values in ms.items()
                )
                if "free" in ms and "bsr" in ms:
                    per_step = [b / f for b, f in zip(ms["bsr"], ms["free"])]
                    per_iter = [b / f for b, f in zip(ms_iter["bsr"], ms_iter["free"])]
                    line += f"; bsr/free {spread(per_step)} per step, {spread(per_iter)} per CG iteration"
                print(line)


if __name__ == "__main__":
    main()
