"""The cantilever strip with dihedral bending, per integrator, against the inextensible elastica.

    python bench/cantilever.py [--cols 32] [--integrators ...] [--device cpu]

The clamped cotton strip of warpcloth.lab.cantilever (2 x cols particles, 5 cm overhang, lambda =
rho g L^3 / B = 8.6) run to rest with each integrator's configuration below; prints the tip drop's
error against the elastica [%], the largest speed at the end [m/s], steps and wall time. These are
the figures of docs/materials.md's dihedral-bending table (tests/test_bending_integrators.py asserts
2 % with the same configurations).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from warpcloth.integrators import make_integrator
from warpcloth.lab.cantilever import cantilever_strip, elastica_tip_drop, strip_tip_drop

#: name -> (label, integrator options, dt [s] (None: default), simulated time [s])
CONFIGS = [
    ("explicit_euler", {}, None, 0.45),
    ("verlet", {}, None, 0.45),
    ("midpoint", {}, None, 0.45),
    ("rk4", {}, None, 0.45),
    ("implicit_euler", {"preconditioner": "block_jacobi"}, 1.0 / 60.0, 0.67),
    ("vbd", {}, 1.0 / 60.0, 1.0),
    ("vbd", {"vbd_iterations": 4}, 1.0 / 4800.0, 0.5),
    ("projective", {}, 1.0 / 60.0, 1.0),
    ("projective", {"pd_iterations": 2, "pd_cg_iterations": 10}, 1.0 / 2400.0, 0.7),
    ("xpbd", {"substeps": 10, "iterations": 1}, 1.0 / 600.0, 0.45),
    ("xpbd", {"substeps": 20, "iterations": 1}, 1.0 / 600.0, 0.45),
    ("xpbd", {"substeps": 40, "iterations": 1}, 1.0 / 600.0, 0.45),
    ("xpbd", {"substeps": 60, "iterations": 1}, 1.0 / 600.0, 0.45),
    ("xpbd", {}, 1.0 / 60.0, 1.0),
    ("pbd", {}, 1.0 / 60.0, 1.0),
    ("pbd", {"iterations": 40}, 1.0 / 60.0, 1.0),
]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cols", type=int, default=32)
    parser.add_argument("--integrators", nargs="+", default=None)
    parser.add_argument("--device", default="cpu")
    args = parser.parse_args()
    want = elastica_tip_drop()
    print(f"elastica tip drop {want * 1e3:.3f} mm; strip 2 x {args.cols}")
    print("| integrator | options | dt [s] | steps | drop error | max speed [m/s] | wall [s] |")
    print("|---|---|---|---|---|---|---|")
    for name, options, dt, duration in CONFIGS:
        if args.integrators and name not in args.integrators:
            continue
        sim = cantilever_strip(make_integrator(name, **options), cols=args.cols, dt=dt, device=args.device)
        steps = int(round(duration / sim.dt))
        t = time.perf_counter()
        sim.simulate(steps)
        wall = time.perf_counter() - t
        error = strip_tip_drop(sim) / want - 1.0
        speed = float(np.abs(sim.state.particle_qd.numpy()).max())
        label = ", ".join(f"{k}={v}" for k, v in options.items()) or "defaults"
        print(
            f"| {name} | {label} | {sim.dt:.3g} | {steps} | {error * 100:+.2f} % | {speed:.1e} | {wall:.2f} |",
            flush=True,
        )


if __name__ == "__main__":
    main()
