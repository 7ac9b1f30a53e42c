"""xpbd's static sag against the float64 equilibrium of the same ks, and its cost, per configuration
(iterations x substeps; issue 26 item 4): the scenario sheet (two corner pins), dt 1/60 s, sag after
--duration s (the sheet is at rest by then: its max speed is printed), ms/step of --timing-steps
steps after a warm-up of as many (one run each: +-30 % on a loaded machine).

    python bench/solver_checks/xpbd_table.py --sizes 24 32 --configs 10x4 4x16 2x32 1x64 1x128
    python bench/solver_checks/xpbd_table.py --integrator pbd --sizes 24 --configs 10x1 10x4 10x8 10x16 20x4 40x4
"""

import argparse
import time

import numpy as np
import warp as wp

from warpcloth.lab.reference import static_equilibrium
from warpcloth.scenarios import get_scenario


def main():
    wp.config.quiet = True
    ap = argparse.ArgumentParser()
    ap.add_argument("--sizes", type=int, nargs="*", default=[24, 32, 64])
    ap.add_argument("--configs", nargs="*", default=["10x4", "1x64"], help="ITERATIONSxSUBSTEPS")
    ap.add_argument("--duration", type=float, default=6.0)
    ap.add_argument("--timing-steps", type=int, default=20)
    ap.add_argument("--integrator", default="xpbd", choices=["xpbd", "pbd"])
    a = ap.parse_args()
    print(f"# {a.integrator} static sag error against float64 after {a.duration:g} s, scenario sheet, dt 1/60 s")
    for n in a.sizes:
        ref = rest = None
        for c in a.configs:
            iterations, substeps = (int(v) for v in c.split("x"))
            sim = get_scenario("sheet").build(
                rows=n,
                cols=n,
                integrator=a.integrator,
                integrator_options=dict(iterations=iterations, substeps=substeps),
            )
            if ref is None:
                eq = static_equilibrium(sim.model, sim.control)
                rest = sim.model.host.q.astype(np.float64)
                ref = float(np.max(np.linalg.norm(eq.x - rest, axis=1)))
            sim.simulate(a.timing_steps)  # warm-up (compile, capture)
            wp.synchronize()
            t0 = time.perf_counter()
            sim.simulate(a.timing_steps)
            wp.synchronize()
            ms = 1e3 * (time.perf_counter() - t0) / a.timing_steps
            sim.simulate(int(round(a.duration * 60)) - 2 * a.timing_steps)
            x = sim.state.particle_q.numpy().astype(np.float64)
            sag = float(np.max(np.linalg.norm(x - rest, axis=1)))
            v = float(np.abs(sim.state.particle_qd.numpy()).max())
            print(
                f"{a.integrator} {n}^2 {c:7s}: sag error {100 * (sag - ref) / ref:+8.2f} %  "
                f"({sag * 1e3:.4f} vs {ref * 1e3:.4f} mm, max|v| {v:.1e})  {ms:7.2f} ms/step",
                flush=True,
            )


if __name__ == "__main__":
    main()
