"""warpcloth's vbd against Newton's VBD (vbd_springs) at equal work, in process CPU time (issue 51).

    python bench/vbd_vs_newton.py [--sizes 32 64] [--pairs 5] [--steps 20] [--substeps 10] [--iterations 10]
        [--peer-iterations 40] [--peer ../shared/peers/newton/bench_cloth.py]
        [--peer-python /work/newton-venv/bin/python] [--bare] [--opt vbd_multigrid_every=2 ...]

The workload of the Newton peer (bench_cloth.py, solver vbd_springs): a 1 m x 1 m, 1 kg sheet of n x n
particles hanging from its two top corners, gravity, no collisions, no drag; every spring 1000 N/m with
kd = 1e-4 N s/m (taken implicitly along the spring by both: kd/h n n^T). Springs: Newton's are every
triangle edge plus the flip edge across each interior edge (5766 at 32^2), warpcloth's Provot's
structural, shear and bend springs (5826 at 32^2). A frame is 1/60 s of ``--substeps`` steps of
``--iterations`` sweeps each (Newton's cloth_hanging default 10 x 10), replayed as one captured graph
by both (``--peer-iterations``: Newton's sweeps where they differ, for the cost at equal accuracy). Each
run is its own process, the two alternating A B A B; each times ``--steps`` frames after an untimed frame
that compiles and captures, with time.process_time (Newton's own ms/step is wall time).
``--bare`` adds warpcloth's vbd without its multigrid and rigid-translation corrections (the sweeps only,
Newton's algorithm); ``--opt key=value`` sets an option of warpcloth's vbd (not the bare run's). Physical
comparability: each run's sag (pins' height minus the lowest particle) and largest structural-edge stretch
after its frames. Results: bench/results/vbd-vs-newton-cpu.txt.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import platform
import statistics
import subprocess
import sys
import time

import numpy as np
import warp as wp

try:  # the Newton worker runs in Newton's own environment, which has no warpcloth
    from warpcloth.scenarios import sheet
except ImportError:
    sheet = None

HERE = os.path.dirname(os.path.abspath(__file__))
DEFAULT_PEER = os.path.join(HERE, "..", "..", "shared", "peers", "newton", "bench_cloth.py")
DEFAULT_PEER_PYTHON = "/work/newton-venv/bin/python"
DT = 1.0 / 60.0


def structural_stretch(q: np.ndarray, rows: int, cols: int) -> float:
    """Largest l / l0 - 1 over the grid's horizontal and vertical edges (rest spacing 1 / (n - 1))."""
    g = q.reshape(rows, cols, 3).astype(np.float64)
    h = np.linalg.norm(g[:, 1:] - g[:, :-1], axis=2) * (cols - 1)
    v = np.linalg.norm(g[1:] - g[:-1], axis=2) * (rows - 1)
    return float(max(h.max(), v.max()) - 1.0)


def worker_newton(args) -> dict:
    spec = importlib.util.spec_from_file_location("bench_cloth", args.peer)
    peer = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(peer)
    p = dict(peer.SOLVER_DEFAULTS["vbd_springs"], iterations=args.iterations)
    device = wp.get_device("cpu")
    with wp.ScopedDevice(device):
        model, pins = peer.build("vbd_springs", args.size, args.size, device, p, "vertical")
        solver = peer.make_solver("vbd_springs", model, p)
        states = [model.state(), model.state()]
        control = model.control()
    sub_dt = DT / args.substeps

    def frame():
        for _ in range(args.substeps):
            states[0].clear_forces()
            solver.step(states[0], states[1], control, None, sub_dt)
            states[0], states[1] = states[1], states[0]

    with wp.ScopedDevice(device):
        frame()  # compile and load
        q_before = states[0].particle_q.numpy().copy()
        with wp.ScopedCapture(device=device) as capture:
            frame()
        graph = capture.graph
        warm_frames = 1 + int(not np.array_equal(q_before, states[0].particle_q.numpy()))
        wp.synchronize_device(device)
        c0, t0 = time.process_time(), time.perf_counter()
        for _ in range(args.steps):
            wp.capture_launch(graph)
        wp.synchronize_device(device)
        cpu, wall = time.process_time() - c0, time.perf_counter() - t0
    q = states[0].particle_q.numpy()
    pin_z = float(model.particle_q.numpy()[pins, 2].mean())
    return {
        "code": "newton",
        "springs": int(model.spring_count),
        "frames": warm_frames + args.steps,
        "cpu_ms": 1e3 * cpu / args.steps,
        "wall_ms": 1e3 * wall / args.steps,
        "sag": pin_z - float(q[:, 2].min()),
        "stretch": structural_stretch(q, args.size, args.size),
        "finite": bool(np.all(np.isfinite(q))),
    }


def worker_warpcloth(args) -> dict:
    options = {"vbd_iterations": args.iterations}
    if args.worker == "warpcloth-bare":
        options.update(vbd_multigrid_every=0, vbd_rigid_mode=0)
    else:
        options.update(parse_options(args.opt))
    sim = sheet.build(
        rows=args.size,
        cols=args.size,
        mass=1.0,
        stiffness=1000.0,
        damping=1e-4,
        drag=0.0,
        integrator="vbd",
        integrator_options=options,
        dt=DT / args.substeps,
        device="cpu",
        use_graph=True,
    )
    sim.use_graph = True  # captured from its first frame (None may defer capture on the CPU)
    sim.warm_up()  # compile and load (state restored)
    sim.simulate(args.substeps)  # capture the frame's graph (one frame advanced)
    wp.synchronize_device(sim.model.device)
    c0, t0 = time.process_time(), time.perf_counter()
    for _ in range(args.steps):
        sim.simulate(args.substeps)
    wp.synchronize_device(sim.model.device)
    cpu, wall = time.process_time() - c0, time.perf_counter() - t0
    q = sim.state.particle_q.numpy()
    pins = [0, args.size - 1]
    return {
        "code": args.worker,
        "springs": int(sim.model.spring_count),
        "frames": 1 + args.steps,
        "cpu_ms": 1e3 * cpu / args.steps,
        "wall_ms": 1e3 * wall / args.steps,
        "sag": float(sim.model.host.q[pins, 1].mean()) - float(q[:, 1].min()),
        "stretch": structural_stretch(q, args.size, args.size),
        "finite": bool(np.all(np.isfinite(q))),
        "graph": bool(sim.graph_enabled),
    }


def parse_options(pairs) -> dict:
    """``key=value`` strings as vbd options (int, else float)."""
    options = {}
    for pair in pairs:
        key, _, value = pair.partition("=")
        try:
            options[key] = int(value)
        except ValueError:
            options[key] = float(value)
    return options


def spread(values) -> str:
    """median [min-max]."""
    return f"{statistics.median(values):.3g} [{min(values):.3g}-{max(values):.3g}]"


def run_worker(python: str, code: str, size: int, args) -> dict:
    iterations = args.peer_iterations if code == "newton" and args.peer_iterations else args.iterations
    cmd = [python, os.path.abspath(__file__), "--worker", code, "--size", str(size), "--steps", str(args.steps)]
    cmd += ["--substeps", str(args.substeps), "--iterations", str(iterations), "--peer", args.peer]
    cmd += [f"--opt={pair}" for pair in args.opt]
    out = subprocess.run(cmd, check=True, capture_output=True, text=True).stdout.strip().splitlines()[-1]
    return json.loads(out)


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--sizes", type=int, nargs="+", default=[32, 64])
    p.add_argument("--pairs", type=int, default=5, help="A B pairs per size")
    p.add_argument("--steps", type=int, default=20, help="timed frames of 1/60 s per run")
    p.add_argument("--substeps", type=int, default=10)
    p.add_argument("--iterations", type=int, default=10, help="sweeps per substep")
    p.add_argument(
        "--peer-iterations", type=int, default=None, help="Newton's sweeps per substep (default --iterations)"
    )
    p.add_argument("--peer", default=DEFAULT_PEER)
    p.add_argument("--peer-python", default=DEFAULT_PEER_PYTHON, help="a Python with newton installed")
    p.add_argument("--bare", action="store_true", help="also time warpcloth's vbd without its corrections")
    p.add_argument("--opt", action="append", default=[], help="key=value: an option of warpcloth's vbd (repeatable)")
    p.add_argument("--worker", choices=["newton", "warpcloth", "warpcloth-bare"], help=argparse.SUPPRESS)
    p.add_argument("--size", type=int, help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    args.peer = os.path.abspath(args.peer)

    if args.worker:
        wp.config.quiet = True
        wp.init()
        r = worker_newton(args) if args.worker == "newton" else worker_warpcloth(args)
        print(json.dumps(r), flush=True)
        return

    wp.init()
    print(f"# bench/vbd_vs_newton.py {' '.join(argv if argv is not None else sys.argv[1:])}")
    print(
        f"# {time.strftime('%Y-%m-%d %H:%M:%S %Z')}, {platform.machine()} {os.cpu_count()} CPUs, load average "
        f"{os.getloadavg()[0]:.1f}, warp {wp.config.version}; peer {args.peer_python}"
    )
    print(
        f"# frame 1/60 s = {args.substeps} substeps x {args.iterations} sweeps"
        + (f" (newton: {args.peer_iterations})" if args.peer_iterations else "")
        + f", {args.steps} timed frames per run, graph capture on, process CPU ms per frame"
    )
    codes = [("warpcloth", sys.executable), ("newton", args.peer_python)]
    if args.bare:
        codes.insert(1, ("warpcloth-bare", sys.executable))
    for size in args.sizes:
        results = {code: [] for code, _ in codes}
        for pair in range(args.pairs):
            for code, python in codes:
                r = run_worker(python, code, size, args)
                results[code].append(r)
                print(
                    f"{size}^2 pair {pair + 1} {code:15s} {r['cpu_ms']:8.2f} ms CPU/frame ({r['wall_ms']:8.2f} wall), "
                    f"{r['springs']} springs, after {r['frames']} frames sag {r['sag']:.4f} m, max structural "
                    f"stretch {100 * r['stretch']:.2f} %{'' if r['finite'] else ' NON-FINITE'}",
                    flush=True,
                )
        print(f"\n# {size}^2 summary: median [min-max] over {args.pairs} runs")
        for code, _ in codes:
            print(f"{code:15s} {spread([r['cpu_ms'] for r in results[code]])} ms CPU/frame")
        for code, _ in codes[:-1]:
            ratios = [a["cpu_ms"] / b["cpu_ms"] for a, b in zip(results[code], results["newton"])]
            print(f"{code + ' / newton':24s} {spread(ratios)}  (per pair; < 1: warpcloth cheaper)")
        print()


if __name__ == "__main__":
    main()
