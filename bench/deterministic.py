"""Cost of Warp's deterministic atomics (``warpcloth.sim.device.set_deterministic``, ``--deterministic
on``): ms per step of the sheet at N x N, graph capture on, with Warp's default atomics and with
RUN_TO_RUN, alternating per integrator and size (machine noise falls on both). Each row is
``warpcloth.lab.bench.bench_one``: the median over ``--windows`` timed windows of ``--seconds`` s in
all, with its [min-max]. On the CPU the setting is not applied by a run (its threads run in order);
this script applies it anyway, so a CPU row pair measures the mode's code on that backend.

    python bench/deterministic.py [--device cuda:0] [--sizes 128,512] [--seconds 0.3] [--windows 3]
                                  [--integrators explicit_euler,xpbd,vbd,implicit_euler]

Figures: bench/results/cuda-h200.txt (docs/gpu.md).
"""

import argparse

from warpcloth.lab import bench as lab_bench
from warpcloth.sim.device import set_deterministic


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--device", default="cuda:0")
    parser.add_argument("--sizes", default="128,512", help="comma-separated N for N x N")
    parser.add_argument("--integrators", default="explicit_euler,xpbd,vbd,implicit_euler")
    parser.add_argument("--seconds", type=float, default=0.3, help="wall seconds per row, over all windows")
    parser.add_argument("--windows", type=int, default=3)
    args = parser.parse_args(argv)
    print("deterministic size integrator ms/step_median [min-max]", flush=True)
    try:
        for n in (int(s) for s in args.sizes.split(",")):
            for name in args.integrators.split(","):
                for det in (False, True):
                    set_deterministic(det)
                    r = lab_bench.bench_one(
                        name, n, args.device, True, None, args.seconds, scenario="sheet", windows=args.windows
                    )
                    print(
                        det,
                        n,
                        name,
                        f"{r['ms_per_step_median']:.4f}",
                        f"[{r['ms_per_step_min']:.4f}-{r['ms_per_step_max']:.4f}]",
                        flush=True,
                    )
    finally:
        set_deterministic(False)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
