"""Static sag of the scenario sheet (two corner pins) against the float64 equilibrium
(warpcloth.lab.reference.static_equilibrium), sampled every --every seconds of simulated time;
grid, or the same sheet as a mesh (--mesh: build_mesh_cloth of the grid's triangles with quads,
identical springs, masses and pins). Issue 26 items 1 and 3.

    python bench/solver_checks/sag.py --size 32 --duration 5 [--integrator vbd] [--mesh] [--opt k=v]
"""

import argparse
import time

import numpy as np
import warp as wp
from common import mesh_twin, parse_opts

from warpcloth import Simulator, make_integrator
from warpcloth.lab.reference import static_equilibrium
from warpcloth.scenarios import get_scenario


def main():
    wp.config.quiet = True
    ap = argparse.ArgumentParser()
    ap.add_argument("--size", type=int, default=32)
    ap.add_argument("--duration", type=float, default=5.0)
    ap.add_argument("--every", type=float, default=0.5)
    ap.add_argument("--integrator", default="vbd")
    ap.add_argument("--dt", type=float, default=1.0 / 60.0)
    ap.add_argument("--mesh", action="store_true")
    ap.add_argument("--opt", action="append", default=[])
    a = ap.parse_args()
    opts = parse_opts(a.opt)
    sim = get_scenario("sheet").build(
        rows=a.size, cols=a.size, integrator=a.integrator, integrator_options=opts, dt=a.dt
    )
    if a.mesh:
        sim = Simulator(mesh_twin(sim.model), make_integrator(a.integrator, **opts), sim.control, dt=a.dt)
    eq = static_equilibrium(sim.model, sim.control)
    rest = sim.model.host.q.astype(np.float64)
    sag_ref = float(np.max(np.linalg.norm(eq.x - rest, axis=1)))
    print(
        f"# sag against float64: {a.integrator} {opts or '(defaults)'} {'mesh' if a.mesh else 'grid'} {a.size}^2 "
        f"dt={a.dt:.4g}: float64 sag {sag_ref * 1e3:.4f} mm (residual {eq.residual:.2g} N)"
    )
    steps = int(round(a.every / a.dt))
    t, wall = 0.0, 0.0
    while t < a.duration - 1e-9:
        t0 = time.perf_counter()
        sim.simulate(steps)
        wp.synchronize()
        wall += time.perf_counter() - t0
        t += steps * a.dt
        x = sim.state.particle_q.numpy().astype(np.float64)
        sag = float(np.max(np.linalg.norm(x - rest, axis=1)))
        v = float(np.abs(sim.state.particle_qd.numpy()).max())
        print(
            f"t={t:5.2f}s sag {sag * 1e3:.4f} mm  error {100 * (sag - sag_ref) / sag_ref:+.2f} %  max|v| {v:.2e}  "
            f"({1e3 * wall / (t / a.dt):.2f} ms/step)",
            flush=True,
        )


if __name__ == "__main__":
    main()
