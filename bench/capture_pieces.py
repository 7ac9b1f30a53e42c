"""What the CPU's graph size costs a replayed frame: the N x N flag under one integrator, one simulator
per graph size P (:data:`warpcloth.simulator.CPU_GRAPH_STEPS` set in this process), each warmed and captured, then 7 interleaved windows of 40 frames each; process CPU ms per
frame, median [range].

    python bench/capture_pieces.py explicit_euler 16 1,4,16
"""

import statistics
import sys
import time

import warp as wp

import warpcloth.simulator as S
from warpcloth.scenarios import flag

wp.config.quiet = True


def main() -> None:
    name, size = sys.argv[1], int(sys.argv[2])
    sizes = [int(p) for p in sys.argv[3].split(",")]
    sims = {}
    for P in sizes:
        S.CPU_GRAPH_STEPS = P
        sim = flag.build(rows=size, cols=size, integrator=name)
        sim.use_graph = True
        n = max(1, round((1 / 60) / sim.dt))
        sim.warm_up()
        sim.simulate(n)
        sims[P] = (sim, n)
    res = {P: [] for P in sizes}
    for _ in range(7):
        for P in sizes:
            S.CPU_GRAPH_STEPS = P
            sim, n = sims[P]
            t = time.process_time()
            for _ in range(40):
                sim.simulate(n)
            res[P].append((time.process_time() - t) / 40 * 1000)
    for P in sizes:
        v = sorted(res[P])
        print(
            f"{name} {size} P={P:2d} steps/frame {sims[P][1]} frame ms median {statistics.median(v):.4f} [{v[0]:.4f}-{v[-1]:.4f}]"
        )


if __name__ == "__main__":
    main()
