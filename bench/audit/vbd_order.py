# ruff: noqa
# One-off audit script of issues 26, 30 and 31 (2026-12-03, branch audit); outputs in bench/results/audit-26-30-31.txt.
import sys, numpy as np, warp as wp

wp.config.quiet = True
from warpcloth import Control, Simulator, build_grid_cloth, make_integrator
import warpcloth.integrators.vbd as V

G = 9.81
H = 1 / 60
swap = sys.argv[1] == "swap"
if swap:
    orig = V.VBDIntegrator.coarse_correction if hasattr(V, "VBDIntegrator") else None
cls = [c for c in vars(V).values() if isinstance(c, type) and hasattr(c, "coarse_correction")][0]
if swap:
    oc = cls.coarse_correction

    def cc(self, x, h, contacts=None, _first=[True]):
        # rigid correction before the V-cycle as well
        if contacts is None and self.vbd_rigid_mode:
            self.rigid_correction(x, h)
        oc(self, x, h, contacts)

    cls.coarse_correction = cc
for n in (16, 32):
    model = build_grid_cloth(n, n, 1.0, 1.0, 0.2, plane="vertical", origin=(0, 3, 0), device="cpu")
    sim = Simulator(model, make_integrator("vbd"), Control(gravity=(0, -G, 0), drag_rate=0.0, device="cpu"), dt=H)
    x0 = sim.state.particle_q.numpy().astype(np.float64)
    sim.simulate(30)
    d = x0[:, 1] - sim.state.particle_q.numpy().astype(np.float64)[:, 1]
    be = H * H * 30 * 31 / 2 * G
    print(sys.argv[1], n, "per-particle fall / BE: min %.5f max %.5f" % (d.min() / be, d.max() / be))
