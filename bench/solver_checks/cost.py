"""ms per step of option sets (issue 26's cost figures) on the scenario sheet, or its mesh twin
(--mesh), cases alternating in each repeat after a warm-up (frames captured as a run does). Prints
the median [min-max] ms/step and the ratio to the first case per size.

    python bench/solver_checks/cost.py --integrator vbd --sizes 32 64 --cases "" vbd_rigid_mode=0
    python bench/solver_checks/cost.py --integrator vbd --mesh --sizes 32 64 --cases "" vbd_mesh_multigrid=0
"""

import argparse
import time

import numpy as np
import warp as wp
from common import mesh_twin, parse_opts

from warpcloth import Simulator, make_integrator
from warpcloth.scenarios import get_scenario


def main():
    wp.config.quiet = True
    ap = argparse.ArgumentParser()
    ap.add_argument("--integrator", default="vbd")
    ap.add_argument("--sizes", type=int, nargs="*", default=[32, 64])
    ap.add_argument(
        "--cases", nargs="*", default=["", "vbd_rigid_mode=0"], help='"key=value,key=value" ("" the defaults)'
    )
    ap.add_argument("--mesh", action="store_true", help="the sheet as a build_mesh_cloth model")
    ap.add_argument("--steps", type=int, default=20)
    ap.add_argument("--repeats", type=int, default=3)
    a = ap.parse_args()
    print(
        f"# {a.integrator} ms/step on the {'mesh twin of the ' if a.mesh else ''}scenario sheet, dt 1/60 s, {a.steps} "
        f"steps x {a.repeats} repeats, cases alternating"
    )
    for n in a.sizes:
        sims = []
        for case in a.cases:
            sim = get_scenario("sheet").build(
                rows=n, cols=n, integrator=a.integrator, integrator_options=parse_opts(case)
            )
            if a.mesh:
                sim = Simulator(
                    mesh_twin(sim.model), make_integrator(a.integrator, **parse_opts(case)), sim.control, dt=sim.dt
                )
            sim.simulate(a.steps)  # warm-up: compile, capture
            wp.synchronize()
            sims.append(sim)
        times = [[] for _ in sims]
        for _ in range(a.repeats):
            for k, sim in enumerate(sims):
                t0 = time.perf_counter()
                sim.simulate(a.steps)
                wp.synchronize()
                times[k].append(1e3 * (time.perf_counter() - t0) / a.steps)
        ref = np.array(times[0])
        for case, t in zip(a.cases, times):
            t = np.array(t)
            r = t / ref
            print(
                f"{a.integrator} {n}^2 [{case or 'defaults'}]: {np.median(t):.2f} [{t.min():.2f}-{t.max():.2f}] "
                f"ms/step, / first {np.median(r):.2f} [{r.min():.2f}-{r.max():.2f}]",
                flush=True,
            )


if __name__ == "__main__":
    main()
