"""When does the harness declare the sheet (grid, or its build_mesh_cloth twin) at equilibrium, and
how far is its sag then from the float64 equilibrium? Issue 26 item 3. Also prints the per-particle
force floor and the largest patch net force per weight at the stop.

    python bench/solver_checks/verdict.py [--size 32] [--mesh] [--integrator vbd] [--opt vbd_rigid_mode=0]
    [--per-particle-only]
"""

import argparse

import numpy as np
import warp as wp
from common import mesh_twin, parse_opts

from warpcloth import Simulator, make_integrator
from warpcloth.lab.reference import static_equilibrium
from warpcloth.run.harness import RunHarness
from warpcloth.scenarios import get_scenario


def main():
    wp.config.quiet = True
    ap = argparse.ArgumentParser()
    ap.add_argument("--size", type=int, default=32)
    ap.add_argument("--duration", type=float, default=10.0)
    ap.add_argument("--integrator", default="vbd")
    ap.add_argument("--mesh", action="store_true")
    ap.add_argument("--opt", action="append", default=[])
    ap.add_argument("--per-particle-only", action="store_true", help="the old verdict: no patch net forces")
    a = ap.parse_args()
    opts = parse_opts(a.opt)
    sim = get_scenario("sheet").build(rows=a.size, cols=a.size, integrator=a.integrator, integrator_options=opts)
    if a.mesh:
        sim = Simulator(mesh_twin(sim.model), make_integrator(a.integrator, **opts), sim.control, dt=sim.dt)
    eq = static_equilibrium(sim.model, sim.control)
    rest = sim.model.host.q.astype(np.float64)
    sag_ref = float(np.max(np.linalg.norm(eq.x - rest, axis=1)))
    harness = RunHarness(sim)
    if a.per_particle_only:
        harness.probe.patch_count = 0
    r = harness.run(a.duration, stop_at_equilibrium=True)
    x = sim.state.particle_q.numpy().astype(np.float64)
    sag = float(np.max(np.linalg.norm(x - rest, axis=1)))
    frame = harness.measure()
    verdict = "old verdict (per particle)" if a.per_particle_only else "verdict with patches"
    print(
        f"{a.integrator} {opts or '(defaults)'} {'mesh' if a.mesh else 'grid'} {a.size}^2, {verdict}: equilibrium "
        f"{r.equilibrium_reached} at {r.time_to_equilibrium} s (stopped at {r.sim_time:.2f} s, force floor "
        f"{harness.probe.force_floor:.3g}); sag {sag * 1e3:.4f} mm vs {sag_ref * 1e3:.4f} mm "
        f"({100 * (sag - sag_ref) / sag_ref:+.2f} %); final max speed {r.final_max_speed:.2e}, max |f|/mg "
        f"{frame.max_force_per_weight:.3g}, max patch |f|/mg {frame.max_patch_force_per_weight:.3g}",
        flush=True,
    )


if __name__ == "__main__":
    main()
