"""CG dot products on the CPU: implicit_euler's single-batch operator (plain loops) against
Warp's tiled reduction (made for GPUs), timed per implicit step.

    python bench/cpu_dot.py [--sizes 32 64] [--steps 10] [--repeats 5] [--matrix free]

Each repeat times ``--steps`` steps of the sheet falling from rest at dt = 1/60 s with each
variant, alternating (single, tiled, single, tiled, ...); the summary gives the median ms/step
with its range (min-max) and the tiled / single ratio per step (median of the per-repeat
ratios, with their range). Both variants take the same CG iterations (printed).
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time

import warp as wp

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from implicit import ms_per_step, spread  # noqa: E402  (bench/implicit.py)

from warpcloth.integrators.implicit_euler import ImplicitEuler  # noqa: E402
from warpcloth.scenarios import sheet  # noqa: E402

VARIANTS = {"single": True, "tiled": False}


def build(n: int, variant: str, matrix: str):
    saved = ImplicitEuler.cpu_single_batch_dot
    ImplicitEuler.cpu_single_batch_dot = VARIANTS[variant]  # read when the Simulator binds the integrator
    try:
        return sheet.build(rows=n, cols=n, integrator="implicit_euler", dt=1.0 / 60.0, device="cpu", integrator_options={"matrix": matrix})
    finally:
        ImplicitEuler.cpu_single_batch_dot = saved


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--sizes", type=int, nargs="+", default=[32, 64])
    p.add_argument("--steps", type=int, default=10)
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--matrix", default="free", choices=["free", "bsr"])
    args = p.parse_args(argv)
    print(f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, {os.cpu_count()} CPU cores ({platform.processor() or platform.machine()}), "
          f"warp {wp.config.version}, implicit_euler matrix={args.matrix}, {args.steps} steps per case, {args.repeats} repeats")
    print(f"{'sheet':>9} {'dot':>6} {'ms/step':>9} {'CG mean':>8}")
    summary = []
    for n in args.sizes:
        sims = {variant: build(n, variant, args.matrix) for variant in VARIANTS}
        ms = {variant: [] for variant in VARIANTS}
        for _ in range(args.repeats):
            for variant, sim in sims.items():
                sim.reset()
                t = ms_per_step(sim, args.steps)
                ms[variant].append(t)
                print(f"{n:>4}x{n:<4} {variant:>6} {t:9.2f} {sim.integrator.stats()['cg_iterations_mean']:8.1f}", flush=True)
        summary.append((n, ms))
    print(f"\nmedian [min-max] over {args.repeats} repeats")
    for n, ms in summary:
        ratio = [t / s for t, s in zip(ms["tiled"], ms["single"])]
        print(f"{n:>4}x{n:<4} single {spread(ms['single'])} ms/step, tiled {spread(ms['tiled'])} ms/step; tiled/single {spread(ratio)} per step")


if __name__ == "__main__":
    main()
