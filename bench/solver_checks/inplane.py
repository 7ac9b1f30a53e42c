"""In-plane acceleration (issue 26 item 1): (a) free fall -- an unpinned N x N cloth (1 m, 0.2 kg,
horizontal, no drag) released at rest for 0.5 s with gravity along its plane (x) and across it
(y): mean displacement / (g t^2/2); (b) slope -- an 8 x 8 cloth (0.3 m, 50 g) lying on a
frictionless plane under gravity tilted 30 degrees: mean velocity after 30 steps / (N h g sin).
Backward Euler of a rigid body (what implicit_euler gives) at dt 1/60 s: sum_k k h^2 / (t^2/2) = 1.0333.

    python bench/solver_checks/inplane.py [--integrator vbd] [--opt key=value ...] [--sizes 4 16 32] [--mu 0.3]
"""

import argparse
import math

import numpy as np
import warp as wp
from common import parse_opts

from warpcloth import Control, Plane, Simulator, build_grid_cloth, make_integrator

G, T = 9.81, 0.5


def fall(integrator, n, dt, gravity, opts):
    model = build_grid_cloth(n, n, 1.0, 1.0, 0.2, plane="horizontal", origin=(0.0, 1.5, 0.0), device="cpu")
    sim = Simulator(
        model, make_integrator(integrator, **opts), Control(gravity=gravity, drag_rate=0.0, device="cpu"), dt=dt
    )
    x0 = sim.state.particle_q.numpy().astype(np.float64).mean(axis=0)
    steps = int(round(T / dt))
    sim.simulate(steps)
    d = sim.state.particle_q.numpy().astype(np.float64).mean(axis=0) - x0
    g = np.asarray(gravity, dtype=np.float64)
    be = dt * dt * steps * (steps + 1) / 2 / (0.5 * T * T)  # backward Euler's discrete value
    return float(np.dot(d, g) / np.dot(g, g) / (0.5 * T * T)), be


def slope(integrator, n, dt, opts, mu=0.0, steps=30):
    th = math.radians(30.0)
    model = build_grid_cloth(n, n, 0.3, 0.3, 0.05, plane="horizontal", origin=(0.0, 0.005, 0.0), device="cpu")
    control = Control(
        gravity=(G * math.sin(th), -G * math.cos(th), 0.0),
        colliders=(Plane(thickness=0.005, friction=mu),),
        device="cpu",
    )
    sim = Simulator(model, make_integrator(integrator, **opts), control, dt=dt)
    sim.simulate(steps)
    v = sim.state.particle_qd.numpy().astype(np.float64)
    return float(v[:, 0].mean() / (steps * dt * G * (math.sin(th) - mu * math.cos(th))))


def main():
    wp.config.quiet = True
    ap = argparse.ArgumentParser()
    ap.add_argument("--integrator", default="vbd")
    ap.add_argument("--opt", action="append", default=[])
    ap.add_argument("--sizes", type=int, nargs="*", default=[4, 16, 32])
    ap.add_argument("--mu", type=float, nargs="*", default=[0.0])
    a = ap.parse_args()
    opts = parse_opts(a.opt)
    dt = 1.0 / 60.0
    print(f"# in-plane acceleration of {a.integrator} {opts or '(defaults)'}, dt = 1/60 s")
    for n in a.sizes:
        along, be = fall(a.integrator, n, dt, (-G, 0.0, 0.0), opts)
        across, _ = fall(a.integrator, n, dt, (0.0, -G, 0.0), opts)
        print(
            f"{n}x{n} free fall / (g t^2/2): along {along:.4f} across {across:.4f}  (backward Euler {be:.4f})",
            flush=True,
        )
    for mu in a.mu:
        print(
            f"8x8 on a 30 deg slope, mu {mu:g}: v / (N h g (sin - mu cos)) = "
            f"{slope(a.integrator, 8, dt, opts, mu):.4f}",
            flush=True,
        )


if __name__ == "__main__":
    main()
