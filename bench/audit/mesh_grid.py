# ruff: noqa
# One-off audit script of issues 26, 30 and 31 (2026-12-03, branch audit); outputs in bench/results/audit-26-30-31.txt.
"""vbd (defaults, dt 1/60): the sheet as a grid and as a mesh (same springs, masses, pins): static shape,
and the harness's equilibrium verdict on the mesh. Usage: mesh_grid.py SIZE DURATION"""

import sys

import numpy as np
import warp as wp

wp.config.quiet = True
from warpcloth.scenarios import get_scenario

from warpcloth import RunHarness, Simulator, build_mesh_cloth, make_integrator
from warpcloth.lab.reference import static_equilibrium
from warpcloth.sim.grid import grid_triangles

n = int(sys.argv[1])
dur = float(sys.argv[2])
grid = get_scenario("sheet").build(rows=n, cols=n, integrator="vbd", dt=1 / 60)
h = grid.model.host
mesh_model = build_mesh_cloth(
    h.q,
    grid_triangles(n, n),
    total_mass=float(h.mass.sum()),
    mass_mode="uniform",
    quads=True,
    pins=list(np.flatnonzero(h.inv_mass == 0)),
    device="cpu",
    spring_params=grid.model.spring_params,
)
assert mesh_model.spring_count == grid.model.spring_count, (mesh_model.spring_count, grid.model.spring_count)
mesh = Simulator(mesh_model, make_integrator("vbd"), grid.control, dt=1 / 60)
rest = h.q.astype(np.float64)
eq = static_equilibrium(grid.model, grid.control)
sag_ref = np.linalg.norm(eq.x - rest, axis=1).max()
steps = int(round(dur * 60))
out = {}
for label, sim in (("grid", grid), ("mesh", mesh)):
    sim.simulate(steps)
    x = sim.state.particle_q.numpy().astype(np.float64)
    out[label] = x
    sag = np.linalg.norm(x - rest, axis=1).max()
    print(
        f"{n}^2 {label} after {dur} s: sag {sag * 1e3:.4f} mm, vs float64 {sag_ref * 1e3:.4f} mm: {100 * (sag - sag_ref) / sag_ref:+.3f} %; max|x - x_eq| / sag {np.linalg.norm(x - eq.x, axis=1).max() / sag_ref * 100:.3f} %; max|v| {np.abs(sim.state.particle_qd.numpy()).max():.2e}"
    )
print(
    f"{n}^2 mesh vs grid: max |x_mesh - x_grid| / sag = {np.linalg.norm(out['mesh'] - out['grid'], axis=1).max() / sag_ref * 100:.3f} %"
)
# the harness verdict on a fresh mesh run
mesh2 = Simulator(mesh_model, make_integrator("vbd"), grid.control, dt=1 / 60)
res = RunHarness(mesh2, scenario="sheet").run(duration=10.0, stop_at_equilibrium=True)
x = mesh2.state.particle_q.numpy().astype(np.float64)
sag = np.linalg.norm(x - rest, axis=1).max()
print(
    f"{n}^2 mesh harness: equilibrium at {res.time_to_equilibrium} s; sag then {sag * 1e3:.4f} mm ({100 * (sag - sag_ref) / sag_ref:+.3f} %), max|x-x_eq|/sag {np.linalg.norm(x - eq.x, axis=1).max() / sag_ref * 100:.3f} %"
)
