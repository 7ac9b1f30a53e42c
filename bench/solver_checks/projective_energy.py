"""Energy between frames without damping (issue 26 item 8): the scenario sheet with kd = 0 and no drag,
2 s at dt 1/60 s from rest: the largest gain of mechanical energy between two frames, in J and as a
fraction of the energy the fall releases by 2 s (E0 - min E), per integrator / options.

    python bench/solver_checks/projective_energy.py --sizes 16 32 --cases projective projective:pd_rigid_mode=0
    implicit_euler
"""

import argparse

import numpy as np
import warp as wp
from common import parse_case

from warpcloth.run.harness import RunHarness
from warpcloth.scenarios import get_scenario


def main():
    wp.config.quiet = True
    ap = argparse.ArgumentParser()
    ap.add_argument("--sizes", type=int, nargs="*", default=[16, 32])
    ap.add_argument(
        "--cases",
        nargs="*",
        default=[
            "projective",
            "projective:pd_rigid_mode=0",
            "projective:pd_rigid_mode=0,pd_cg_iterations=100",
            "implicit_euler",
        ],
    )
    a = ap.parse_args()
    print("# largest energy gain between frames, scenario sheet, kd 0, no drag, 2 s at dt 1/60 s")
    for case in a.cases:
        name, opts = parse_case(case)
        for n in a.sizes:
            harness = RunHarness(
                get_scenario("sheet").build(
                    rows=n, cols=n, integrator=name, integrator_options=opts, damping=0.0, drag=0.0
                )
            )
            e = [harness.energy()]
            for _ in range(120):
                harness.sim.simulate(1)
                e.append(harness.energy())
            e = np.array(e)
            d = np.diff(e)
            released = e[0] - e.min()
            print(
                f"{case:45s} {n}^2: max gain {d.max():+.3e} J = {d.max() / released:+.2e} of the energy released "
                f"({released:.3e} J), at frame {d.argmax() + 1}",
                flush=True,
            )


if __name__ == "__main__":
    main()
