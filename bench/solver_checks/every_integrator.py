"""The in-plane checks of issue 26 for every integrator at its default dt (what tests/test_contract.py
asserts): (a) a free 16 x 16 cloth (1 m, 0.2 kg, no drag) falling 0.5 s along its plane, its mean
displacement over the scheme's own discrete free fall; (b) an 8 x 8 cloth on a frictionless 30
degree slope, 0.5 s, its mean velocity over n h g sin; (c) max |P| [kg m/s] of a free symmetric
16 x 16 cloth (kd 0, no gravity, no drag) released stretched 5 %, over 1 s (midpoint: dt 2e-5 s,
it has no stable dt without damping).

    python bench/solver_checks/every_integrator.py [--cases vbd vbd:vbd_rigid_mode=0 ...]
"""

import argparse
import math

import numpy as np
import warp as wp
from common import parse_case
from momentum import run as momentum

from warpcloth import Control, Plane, Simulator, build_grid_cloth, integrator_names, make_integrator

G = 9.81


def discrete_free_fall(integrator, steps, h):
    if integrator.name in ("midpoint", "rk4", "verlet"):
        return 0.5 * (steps * h) ** 2
    s = getattr(integrator, "substeps", 1)
    n, hs = steps * s, h / s
    return hs * hs * n * (n + 1) / 2


def main():
    wp.config.quiet = True
    ap = argparse.ArgumentParser()
    ap.add_argument("--cases", nargs="*", default=None)
    a = ap.parse_args()
    print(
        "# free fall along the plane / discrete value, frictionless slope v / (n h g sin), max |P| [kg m/s]; default dt"
    )
    for case in a.cases or integrator_names():
        name, opts = parse_case(case)
        integ = make_integrator(name, **opts)
        model = build_grid_cloth(16, 16, 1.0, 1.0, 0.2, plane="horizontal", origin=(0.0, 1.5, 0.0), device="cpu")
        sim = Simulator(model, integ, Control(gravity=(-G, 0.0, 0.0), drag_rate=0.0, device="cpu"))
        steps = max(1, round(0.5 / sim.dt))
        x0 = sim.state.particle_q.numpy().astype(np.float64).mean(axis=0)
        sim.simulate(steps)
        fall = (x0[0] - sim.state.particle_q.numpy().astype(np.float64).mean(axis=0)[0]) / (
            G * discrete_free_fall(integ, steps, sim.dt)
        )
        th = math.radians(30.0)
        model = build_grid_cloth(8, 8, 0.3, 0.3, 0.05, plane="horizontal", origin=(0.0, 0.005, 0.0), device="cpu")
        control = Control(
            gravity=(G * math.sin(th), -G * math.cos(th), 0.0),
            colliders=(Plane(thickness=0.005, friction=0.0),),
            device="cpu",
        )
        slope_sim = Simulator(model, make_integrator(name, **opts), control)
        n = max(1, round(0.5 / slope_sim.dt))
        slope_sim.simulate(n)
        slope = slope_sim.state.particle_qd.numpy().astype(np.float64)[:, 0].mean() / (
            n * slope_sim.dt * G * math.sin(th)
        )
        worst, _, _ = momentum(case, 16, 1.0, 2.0e-5 if name == "midpoint" else None)
        print(f"{case:32s} dt {sim.dt:.4g} s: free fall {fall:.6f}  slope {slope:.6f}  max |P| {worst:.2e}", flush=True)


if __name__ == "__main__":
    main()
