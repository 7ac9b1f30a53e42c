"""What a CPU graph capture costs against the replays it saves: per integrator and size, the
process CPU seconds of a run's first frame (its graphs captured, then replayed) and of a replayed
frame (median and range over ``--repeats`` windows of ``--frames`` frames), on the N x N flag at
the integrator's default dt. Each configuration runs in its own process, the configurations
interleaved ``--pairs`` times, so that a second tree (``--other PATH``, e.g. an older checkout)
is measured in alternation with this one: the replay cost must not change with how the steps are
cut into graphs, the first frame should.

    python bench/capture.py [--integrators explicit_euler rk4 projective xpbd] [--sizes 16 32]
                            [--frames 10] [--repeats 5] [--pairs 3] [--other /path/to/old/tree]
"""

import argparse
import json
import os
import statistics
import subprocess
import sys
import time

FRAME = 1.0 / 60.0


def worker(name: str, size: int, frames: int, repeats: int) -> dict:
    import warp as wp

    wp.config.quiet = True
    from warpcloth.scenarios import flag

    sim = flag.build(rows=size, cols=size, integrator=name)
    sim.use_graph = True
    steps = max(1, round(FRAME / sim.dt))
    sim.warm_up()  # kernels compiled and loaded: not part of either figure
    t0 = time.process_time()
    sim.simulate(steps)
    first = time.process_time() - t0
    windows = []
    for _ in range(repeats):
        t0 = time.process_time()
        for _ in range(frames):
            sim.simulate(steps)
        windows.append(1000.0 * (time.process_time() - t0) / frames)
    return {"steps": steps, "first_s": first, "frame_ms": windows}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--integrators", nargs="+", default=["explicit_euler", "rk4", "projective", "xpbd"])
    ap.add_argument("--sizes", nargs="+", type=int, default=[16, 32])
    ap.add_argument("--frames", type=int, default=10)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--pairs", type=int, default=3)
    ap.add_argument("--other", default=None, help="a second warpcloth tree, measured in alternation (PYTHONPATH)")
    ap.add_argument("--worker", nargs=4, metavar=("NAME", "SIZE", "FRAMES", "REPEATS"), help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.worker:
        name, size, frames, repeats = args.worker
        print(json.dumps(worker(name, int(size), int(frames), int(repeats))))
        return
    here = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    trees = [("this", here)] + ([("other", os.path.abspath(args.other))] if args.other else [])
    print(f"# bench/capture.py {' '.join(sys.argv[1:])}")
    print(f"# {time.strftime('%Y-%m-%d %H:%M:%S UTC', time.gmtime())}, load average {os.getloadavg()[0]:.1f}")
    for size in args.sizes:
        for name in args.integrators:
            rows = {label: [] for label, _ in trees}
            for _ in range(args.pairs):
                for label, tree in trees:
                    env = dict(os.environ, PYTHONPATH=tree)
                    cmd = [sys.executable, __file__, "--worker", name, str(size), str(args.frames), str(args.repeats)]
                    out = subprocess.run(cmd, env=env, cwd="/", capture_output=True, text=True, check=True).stdout
                    rows[label].append(json.loads(out.strip().splitlines()[-1]))
            for label, runs in rows.items():
                firsts = [r["first_s"] for r in runs]
                frames = [statistics.median(r["frame_ms"]) for r in runs]
                print(
                    f"{size:4d}^2 {name:15s} {label:5s} {runs[0]['steps']:4d} steps/frame  first frame "
                    f"{statistics.median(firsts):7.3f} s [{min(firsts):.3f}-{max(firsts):.3f}]  replayed frame "
                    f"{statistics.median(frames):8.3f} ms [{min(frames):.3f}-{max(frames):.3f}]"
                )


if __name__ == "__main__":
    main()
