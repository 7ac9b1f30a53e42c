"""ms/step of the position-based integrators (pbd, xpbd) on the sheet scenario.

    python bench/pbd.py                                  # CPU, 64x64 and 128x128, 10 iterations
    python bench/pbd.py --device cuda --sizes 256 512    # on a GPU

Each row: one integrator on one N x N sheet at dt = 1/60 s with 10 iterations and 1 substep
(the plain figure) or 4 substeps (the integrators' default; about 4x the work); kernels are compiled and run once
before timing (``Simulator.warm_up``), then ``--steps`` steps are timed with the device
synchronised at the end. Not a test: nothing here asserts a speed.
"""

from __future__ import annotations

import argparse
import time

import warp as wp

import warpcloth  # noqa: F401  (quiet Warp before init)
from warpcloth.scenarios import sheet


def time_steps(integrator: str, size: int, device: str, steps: int, options: dict):
    """(ms per step, simulator) of ``steps`` steps of ``integrator`` on a size x size sheet."""
    sim = sheet.build(integrator=integrator, rows=size, cols=size, device=device, integrator_options=options)
    sim.warm_up()
    wp.synchronize_device(device)
    t0 = time.perf_counter()
    sim.simulate(steps)
    wp.synchronize_device(device)
    elapsed = time.perf_counter() - t0
    return 1000.0 * elapsed / steps, sim


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--device", default="cpu", help="Warp device (default cpu)")
    parser.add_argument("--sizes", type=int, nargs="+", default=[64, 128], help="sheet sizes N (N x N particles)")
    parser.add_argument("--steps", type=int, default=30, help="timed steps per row")
    parser.add_argument("--iterations", type=int, default=10, help="solver iterations per (sub)step")
    parser.add_argument("--substeps", type=int, nargs="+", default=[1, 4], help="substeps per step (one row each)")
    args = parser.parse_args(argv)

    with wp.ScopedDevice(args.device):
        device = str(wp.get_device())
        print(
            f"# warp {wp.config.version}, device {device} ({wp.get_device().name}), dt = 1/60 s, {args.steps} timed "
            "steps"
        )
        print(
            f"{'integrator':10s} {'sheet':>9s} {'springs':>8s} {'colours':>7s} {'iter':>4s} {'sub':>3s} {'ms/step':>9s}"
        )
        for size in args.sizes:
            for substeps in args.substeps:
                for name in ("pbd", "xpbd"):
                    ms, sim = time_steps(
                        name, size, device, args.steps, {"iterations": args.iterations, "substeps": substeps}
                    )
                    print(
                        f"{name:10s} {f'{size}x{size}':>9s} {sim.model.spring_count:8d} "
                        f"{sim.integrator.coloring.color_count:7d} {args.iterations:4d} {substeps:3d} {ms:9.3f}"
                    )


if __name__ == "__main__":
    main()
