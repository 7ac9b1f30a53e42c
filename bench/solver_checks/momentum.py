"""Linear momentum (issue 26 item 2): a free, symmetric N x N cloth (1 m, 0.2 kg, default ks, kd = 0),
no gravity, no drag, released from rest stretched by 5 % about its centre. Prints max |P| over the
run [kg m/s] per integrator / option set (dt: the integrator's default, or --dt).

    python bench/solver_checks/momentum.py [--duration 2] [--cases vbd vbd:vbd_rigid_mode=0 implicit_euler ...]
"""

import argparse

import numpy as np
import warp as wp
from common import parse_case

from warpcloth import Control, Simulator, SpringParams, SpringType, build_grid_cloth, integrator_names, make_integrator
from warpcloth.sim.model import DEFAULT_STIFFNESS


def run(case, n, duration, dt=None, stretch=0.05):
    name, opts = parse_case(case)
    params = {t: SpringParams(DEFAULT_STIFFNESS[t], 0.0) for t in SpringType}
    model = build_grid_cloth(n, n, 1.0, 1.0, 0.2, spring_params=params, plane="horizontal", device="cpu")
    integrator = make_integrator(name, **opts)
    if dt is None:  # the default dt (of the cloth with its default damping where kd = 0 has none: midpoint)
        damped = build_grid_cloth(n, n, 1.0, 1.0, 0.2, plane="horizontal", device="cpu")
        dt = integrator.default_dt(damped, 0.0) if integrator.no_stable_dt_reason(model, 0.0) else None
    sim = Simulator(model, integrator, Control(gravity=(0.0, 0.0, 0.0), drag_rate=0.0, device="cpu"), dt=dt)
    q = sim.state.particle_q.numpy()
    c = q.mean(axis=0)
    sim.state.particle_q.assign(((q - c) * (1.0 + stretch) + c).astype(np.float32))
    m = model.host.mass.astype(np.float64)
    worst, P = 0.0, np.zeros(3)
    per_frame = max(1, int(round((1.0 / 60.0) / sim.dt)))
    for _ in range(int(round(duration * 60))):
        sim.simulate(per_frame)
        P = (m[:, None] * sim.state.particle_qd.numpy().astype(np.float64)).sum(axis=0)
        worst = max(worst, float(np.linalg.norm(P)))
    return worst, P, sim.dt


def main():
    wp.config.quiet = True
    ap = argparse.ArgumentParser()
    ap.add_argument("--size", type=int, default=16)
    ap.add_argument("--duration", type=float, default=2.0)
    ap.add_argument("--dt", type=float, default=None)
    ap.add_argument("--cases", nargs="*", default=None, help="integrator[:key=value,...] (default: every integrator)")
    a = ap.parse_args()
    print(
        f"# max |P| [kg m/s] sampled every 1/60 s over {a.duration:g} s: free {a.size}^2 cloth, kd 0, no gravity, "
        "no drag, released stretched 5 %"
    )
    for case in a.cases or integrator_names():
        worst, P, dt = run(case, a.size, a.duration, a.dt)
        print(
            f"{case:45s} dt={dt:.4g}: max |P| = {worst:.3g}  (final P = {np.array2string(P, precision=3)})", flush=True
        )


if __name__ == "__main__":
    main()
