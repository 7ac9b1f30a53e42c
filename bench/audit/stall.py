# ruff: noqa
# One-off audit script of issues 26, 30 and 31 (2026-12-03, branch audit); outputs in bench/results/audit-26-30-31.txt.
import numpy as np
from warpcloth.scenarios import get_scenario

from warpcloth import RunHarness, Simulator, build_mesh_cloth, make_integrator
from warpcloth.lab.reference import static_equilibrium
from warpcloth.sim.grid import grid_triangles

n = 32
grid = get_scenario("sheet").build(rows=n, cols=n, integrator="vbd", dt=1 / 60)
h = grid.model.host
mm = build_mesh_cloth(
    h.q,
    grid_triangles(n, n),
    total_mass=float(h.mass.sum()),
    mass_mode="uniform",
    quads=True,
    pins=list(np.flatnonzero(h.inv_mass == 0)),
    device="cpu",
    spring_params=grid.model.spring_params,
)
eq = static_equilibrium(grid.model, grid.control)
rest = h.q.astype(np.float64)
sref = np.linalg.norm(eq.x - rest, axis=1).max()
for opts in (
    {"vbd_rigid_mode": 0, "vbd_mesh_multigrid": 0, "vbd_iterations": 1},
    {"vbd_rigid_mode": 0, "vbd_mesh_multigrid": 0},
):
    sim = Simulator(mm, make_integrator("vbd", **opts), grid.control, dt=1 / 60)
    r = RunHarness(sim).run(8.0, stop_at_equilibrium=True)
    x = sim.state.particle_q.numpy().astype(np.float64)
    s = np.linalg.norm(x - rest, axis=1).max()
    print(
        opts,
        "equilibrium",
        r.equilibrium_reached,
        "at",
        r.time_to_equilibrium,
        f"sag then {100 * (s - sref) / sref:+.2f} % of the float64 sag",
    )
