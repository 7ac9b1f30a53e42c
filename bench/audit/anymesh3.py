# ruff: noqa
# One-off audit script of issues 26, 30 and 31 (2026-12-03, branch audit); outputs in bench/results/audit-26-30-31.txt.
import numpy as np, warp as wp, sys
from scipy.spatial import Delaunay
from warpcloth import Simulator, build_mesh_cloth, make_integrator, Control, RunHarness
from warpcloth.lab.reference import static_equilibrium

seed, n = int(sys.argv[1]), int(sys.argv[2])
rng = np.random.default_rng(seed)
pts = np.vstack([rng.random((n - 4, 2)), [[0, 0], [1, 0], [0, 1], [1, 1]]])
tri = Delaunay(pts).simplices
v = np.c_[pts[:, 0] - 0.5, pts[:, 1] + 1.0, np.zeros(len(pts))]
model = build_mesh_cloth(v, tri, total_mass=0.2, pins=[n - 2, n - 1], device="cpu")
control = Control(drag_rate=1.0, device="cpu")
eq = static_equilibrium(model, control)
rest = model.host.q.astype(np.float64)
sref = np.linalg.norm(eq.x - rest, axis=1).max()
sim = Simulator(model, make_integrator("vbd"), control, dt=1 / 60)
r = RunHarness(sim).run(8.0, stop_at_equilibrium=True)
x = sim.state.particle_q.numpy().astype(np.float64)
a = f"seed {seed} n {n}: declared {r.equilibrium_reached} at {r.time_to_equilibrium:.3g} s: sag {100 * (np.linalg.norm(x - rest, axis=1).max() - sref) / sref:+.3f} %, shape {np.linalg.norm(x - eq.x, axis=1).max() / sref * 100:.3f} %"
sim.simulate(240)
x = sim.state.particle_q.numpy().astype(np.float64)
print(
    a
    + f"; 4 s later: sag {100 * (np.linalg.norm(x - rest, axis=1).max() - sref) / sref:+.3f} %, shape {np.linalg.norm(x - eq.x, axis=1).max() / sref * 100:.3f} %",
    flush=True,
)
