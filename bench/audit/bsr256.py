# ruff: noqa
# One-off audit script of issues 26, 30 and 31 (2026-12-03, branch audit); outputs in bench/results/audit-26-30-31.txt.
"""Issue 26 item 6 on the peers' workload: 1 kg sheet, ks 1000, kd 1, no drag, two top corners pinned, dt 1/60 s;
implicit_euler matrix=bsr vs matrix=free (defaults otherwise) after STEPS steps: lowest point below the top row."""

import json
import sys
import time

import numpy as np
import warp as wp

wp.config.quiet = True
from warpcloth.scenarios import sheet

n, steps = int(sys.argv[1]), int(sys.argv[2])
opts_extra = json.loads(sys.argv[3]) if len(sys.argv) > 3 else {}
xs = {}
for matrix in ("bsr", "free"):
    sim = sheet.build(
        rows=n,
        cols=n,
        integrator="implicit_euler",
        integrator_options=dict(matrix=matrix, cg_max_iter=5000, **opts_extra),
        dt=1 / 60,
        mass=1.0,
        stiffness=1000.0,
        damping=1.0,
        drag=0.0,
        device="cpu",
    )
    top = float(sim.model.host.q[:, 1].max())
    t0 = time.perf_counter()
    sim.simulate(steps)
    wall = time.perf_counter() - t0
    x = sim.state.particle_q.numpy().astype(np.float64)
    xs[matrix] = x
    st = sim.integrator.stats()
    print(
        f"{n}^2 {matrix} {opts_extra} after {steps} steps: lowest - top = {x[:, 1].min() - top:+.7f} m; {wall / steps:.2f} s/step; "
        f"CG its mean {st.get('cg_iterations_mean')}, capped {st.get('cg_capped_steps')}, true residual max {st.get('cg_true_residual_max')}",
        flush=True,
    )
print(
    f"{n}^2 {opts_extra}: max |x_bsr - x_free| = {np.abs(xs['bsr'] - xs['free']).max():.3e} m, lowest points differ by {xs['bsr'][:, 1].min() - xs['free'][:, 1].min():+.3e} m",
    flush=True,
)
