"""Wall time of the float64 Warp RK4 reference (warpcloth.lab.reference_warp) with its halving
run, on the sheet with its whole top row pinned, released from horizontal (the well-posed
transient of design.md), per size.

    python bench/reference_warp.py --sizes 32 64 --duration 1.0
    python bench/reference_warp.py --sizes 128 --duration 0.25
    python bench/reference_warp.py --sizes 64 --duration 1.0 --profile 0,1,2   # |x_h - x_h/2| per frame

Prints per size: the stability estimate, dt, steps, every halving estimate (relative to the
size), whether it was accepted, and the wall time. ``--profile L0,L1,...``: instead, runs the
given halving levels (0 = safety x limit, 1 = half of it, ...) and prints the difference between
consecutive levels every 6 frames (where in time the estimate grows).
"""

from __future__ import annotations

import argparse
import itertools
import math
import time
from dataclasses import replace

import numpy as np
import warp as wp


def top_row_swing(n: int, device: str):
    from warpcloth.lab.reference import swing_from_horizontal
    from warpcloth.scenarios import sheet

    scenario = replace(sheet.SCENARIO, pins=lambda rows, cols: list(range(cols)))
    sim = scenario.build(rows=n, cols=n, device=device)
    # float32-exact, as AccuracyProblem starts it
    x0 = np.asarray(swing_from_horizontal(sim.model), dtype=np.float32).astype(np.float64)
    return sim, x0


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--sizes", type=int, nargs="+", default=[32, 64])
    p.add_argument("--duration", type=float, default=1.0)
    p.add_argument("--frame-dt", type=float, default=1.0 / 60.0)
    p.add_argument("--safety", type=float, default=None)
    p.add_argument("--max-halvings", type=int, default=None)
    p.add_argument("--parallel", action="store_true", help="the first two runs in two threads")
    p.add_argument("--device", default="cpu")
    p.add_argument("--profile", default=None, help="comma-separated halving levels to compare frame by frame")
    a = p.parse_args()
    wp.config.quiet = True
    wp.init()
    from warpcloth.lab import reference_warp as rw
    from warpcloth.lab.reference import Float64Model, cloth_size

    for n in a.sizes:
        sim, x0 = top_row_swing(n, a.device)
        size = cloth_size(sim.model)
        if a.profile:
            levels = [int(s) for s in a.profile.split(",")]
            m64 = Float64Model.from_model(sim.model, sim.control)
            limit = rw.stability_limit(m64, x0)
            frames = int(round(a.duration / a.frame_dt))
            pieces = rw._pieces(m64, (), a.duration, frames, a.frame_dt)
            h = (a.safety or rw.DEFAULT_SAFETY) * limit.dt
            base = [math.ceil((q.end - q.start) / h) for q in pieces]
            run = rw._Run(m64, (), x0, np.zeros_like(x0), frames, wp.get_device(a.device))
            out = {}
            for level in levels:
                t0 = time.perf_counter()
                out[level] = run.run(pieces, [b << level for b in base])
                wall = time.perf_counter() - t0
                print(f"{n}x{n} level {level}: {sum(base) << level} steps, {wall:.1f} s", flush=True)
            for lo, hi in itertools.pairwise(levels):
                per = np.linalg.norm(out[lo] - out[hi], axis=-1).max(axis=1) / size
                every = " ".join(f"{v:.2g}" for v in per[::6])
                print(
                    f"  |x_{lo} - x_{hi}| / size every 6 frames: {every}; max {per.max():.3g} at frame {per.argmax()}"
                )
            continue
        options = {}
        if a.safety is not None:
            options["safety"] = a.safety
        if a.max_halvings is not None:
            options["max_halvings"] = a.max_halvings
        t0 = time.perf_counter()
        r = rw.warp_reference(
            sim.model,
            sim.control,
            a.duration,
            a.frame_dt,
            x0=x0,
            device=a.device,
            parallel=a.parallel,
            require_accepted=False,
            **options,
        )
        wall = time.perf_counter() - t0
        s = r.stability
        print(
            f"{n}x{n} swing {a.duration:g} s: omega {s.omega:.4g} rad/s (Gershgorin {s.omega_gershgorin:.4g}), "
            f"gamma {s.gamma:.4g} 1/s, limit {s.dt:.3g} s; finest dt {r.dt:.3g} s, {r.steps} steps; estimates/size "
            + ", ".join(f"{e:.3g}" for e in r.estimates)
            + f"; accepted {r.accepted}; wall {wall:.1f} s",
            flush=True,
        )


if __name__ == "__main__":
    main()
