# ruff: noqa
# One-off audit script of issues 26, 30 and 31 (2026-12-03, branch audit); outputs in bench/results/audit-26-30-31.txt.
"""xpbd sag on the sheet at dt 1/60 vs the float64 equilibrium; ms/step (median of 5 windows). args: SIZE [iters substeps]"""

import sys
import time

import numpy as np
import warp as wp

wp.config.quiet = True
from warpcloth.scenarios import get_scenario

from warpcloth.lab.reference import static_equilibrium

n = int(sys.argv[1])
opts = {} if len(sys.argv) < 4 else {"iterations": int(sys.argv[2]), "substeps": int(sys.argv[3])}
sim = get_scenario("sheet").build(rows=n, cols=n, integrator="xpbd", integrator_options=opts, dt=1 / 60)
eq = static_equilibrium(sim.model, sim.control)
rest = sim.model.host.q.astype(np.float64)
sag_ref = np.linalg.norm(eq.x - rest, axis=1).max()
sim.simulate(60)  # warm-up/compile + 1 s
times = []
for w in range(5):
    t0 = time.perf_counter()
    sim.simulate(60)
    wp.synchronize()
    times.append((time.perf_counter() - t0) / 60 * 1e3)
x = sim.state.particle_q.numpy().astype(np.float64)
sag = np.linalg.norm(x - rest, axis=1).max()
print(
    f"xpbd {opts or 'defaults ' + str({k: getattr(sim.integrator, k) for k in ('iterations', 'substeps')})} {n}^2 at 6 s: sag {sag * 1e3:.4f} mm vs float64 {sag_ref * 1e3:.4f}: {100 * (sag - sag_ref) / sag_ref:+.2f} %; max|v| {np.abs(sim.state.particle_qd.numpy()).max():.1e}; ms/step median {np.median(times):.2f} [{min(times):.2f}-{max(times):.2f}]",
    flush=True,
)
