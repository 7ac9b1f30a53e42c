"""Projective dynamics with kd = 0 (issue 26 item 8): the bend of a free N x N cloth (1 m, 0.2 kg,
horizontal, no drag) falling across its plane for 0.5 s at dt 1/60 s, bend = max |(x_i - mean x) -
(x0_i - mean x0)| [m] (the shape change; a rigid fall keeps it 0).

    python bench/solver_checks/projective_probe.py [--sizes 16 32] [--cases projective projective:pd_rigid_mode=0 ...]
"""

import argparse

import numpy as np
import warp as wp
from common import parse_case

from warpcloth import Control, Simulator, SpringParams, SpringType, build_grid_cloth, make_integrator
from warpcloth.sim.model import DEFAULT_STIFFNESS


def bend(case: str, n: int) -> float:
    name, opts = parse_case(case)
    params = {t: SpringParams(DEFAULT_STIFFNESS[t], 0.0) for t in SpringType}
    model = build_grid_cloth(
        n, n, 1.0, 1.0, 0.2, spring_params=params, plane="horizontal", origin=(0.0, 1.5, 0.0), device="cpu"
    )
    sim = Simulator(
        model, make_integrator(name, **opts), Control(gravity=(0.0, -9.81, 0.0), drag_rate=0.0, device="cpu"), dt=1 / 60
    )
    x0 = sim.state.particle_q.numpy().astype(np.float64)
    sim.simulate(30)
    x = sim.state.particle_q.numpy().astype(np.float64)
    return float(np.abs((x - x.mean(0)) - (x0 - x0.mean(0))).max())


def main():
    wp.config.quiet = True
    ap = argparse.ArgumentParser()
    ap.add_argument("--sizes", type=int, nargs="*", default=[16, 32])
    ap.add_argument(
        "--cases",
        nargs="*",
        default=[
            "projective",
            "projective:pd_rigid_mode=0",
            "projective:pd_rigid_mode=0,pd_cg_iterations=30",
            "projective:pd_rigid_mode=0,pd_iterations=30",
            "implicit_euler",
        ],
    )
    a = ap.parse_args()
    print("# bend [m] of a free cloth (kd 0, no drag) falling across its plane for 0.5 s, dt 1/60 s")
    for case in a.cases:
        print(f"{case:50s} " + "  ".join(f"{n}^2: {bend(case, n):.3g}" for n in a.sizes), flush=True)


if __name__ == "__main__":
    main()
