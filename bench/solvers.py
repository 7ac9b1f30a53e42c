"""Modern solvers against implicit Euler: speed at one sheet size, the numpy/scipy peer, and the
static sag each solver settles to.

    python bench/solvers.py [--size 128] [--steps 10] [--repeats 3] [--settle-size 64]
                            [--settle-time 10] [--settle-implicit] [--peer ../shared/peers/numpy/bench_cloth.py]

Speed, on the peer's workload (../shared/peers/numpy/bench_cloth.py: a 1 m x 1 m, 1 kg sheet of
size x size particles, ks = 1000 N/m and kd = 1 N s/m for every spring, two top corners pinned,
gravity, no drag), dt = 1/60 s, CG relative tolerance 1e-3: ms/step of implicit_euler with the
Jacobi and the multigrid preconditioner, of vbd and projective at their default options, and of
the peer's implicit Euler (scipy CG, Jacobi, run as a subprocess with its own timer), the cases
alternating every repeat (A B C D E, B C D E A, ...) so that load on the shared machine falls on
all of them. Each warpcloth case times ``--steps`` steps from rest after warm-up (compile time
excluded), wall and process CPU time; the summary quotes medians with their range [min-max] and
the ratios asked by issue 15 (per-repeat ratios, median [range]).

Statics: the scenario sheet (``warpcloth run sheet`` defaults: 0.2 kg, drag 1/s) at
``--settle-size``, run for ``--settle-time`` simulated seconds at dt = 1/60 s with each solver's
defaults; its sag (the largest drop of a particle below its rest height) against the float64
equilibrium's (warpcloth.lab.reference.static_equilibrium), and the largest speed left.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import time

import numpy as np
import warp as wp

from warpcloth.lab.reference import static_equilibrium
from warpcloth.scenarios import sheet

DT = 1.0 / 60.0
CG_TOL = 1e-3


def cases(cg_tol: float) -> dict:
    """The timed warpcloth cases: name -> (integrator, options)."""
    return {
        "implicit_euler/jacobi": ("implicit_euler", {"preconditioner": "jacobi", "cg_tol": cg_tol}),
        "implicit_euler/multigrid": ("implicit_euler", {"preconditioner": "multigrid", "cg_tol": cg_tol}),
        "vbd": ("vbd", {}),
        "projective": ("projective", {}),
    }


CASES = cases(CG_TOL)
PEER = "numpy-peer/implicit"
DEFAULT_PEER = os.path.join(os.path.dirname(__file__), "..", "..", "shared", "peers", "numpy", "bench_cloth.py")


def _num(v: float) -> str:
    return f"{v:.0f}" if abs(v) >= 100 else f"{v:.3g}"


def spread(values) -> str:
    """median [min-max] of ``values``."""
    return f"{_num(statistics.median(values))} [{_num(min(values))}-{_num(max(values))}]"


def peer_workload(size: int, integrator: str, options: dict):
    return sheet.build(
        rows=size,
        cols=size,
        integrator=integrator,
        integrator_options=options,
        dt=DT,
        mass=1.0,
        stiffness=1000.0,
        damping=1.0,
        drag=0.0,
        device="cpu",
    )


def time_case(sim, steps: int) -> dict:
    """Wall and CPU ms/step of ``steps`` steps from rest after warm-up, and the solver stats."""
    sim.reset()  # every repeat from rest (the first steps of the fall), as the peer's runs
    sim.warm_up()
    if sim.graph_enabled:
        sim.simulate(steps)  # capture outside the timing
        sim.reset()
    sim.integrator.reset_stats()
    wp.synchronize_device(sim.model.device)
    t0, c0 = time.perf_counter(), time.process_time()
    sim.simulate(steps)
    wp.synchronize_device(sim.model.device)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    finite = bool(np.all(np.isfinite(sim.state.particle_q.numpy())))
    return {"ms": 1e3 * wall / steps, "cpu_ms": 1e3 * cpu / steps, "stats": sim.integrator.stats(), "finite": finite}


def time_peer(peer: str, python: str, size: int, steps: int, cg_tol: float = CG_TOL) -> dict:
    cmd = [
        python,
        peer,
        "--rows",
        str(size),
        "--cols",
        str(size),
        "--integrator",
        "implicit",
        "--dt",
        repr(DT),
        "--cg-rtol",
        repr(cg_tol),
        "--steps",
        str(steps),
        "--warmup",
        "1",
    ]
    out = subprocess.run(cmd, check=True, capture_output=True, text=True).stdout.strip().splitlines()[-1]
    r = json.loads(out)
    return {
        "ms": r["ms_per_step"],
        "cpu_ms": float("nan"),
        "stats": {"cg_iterations_mean": r["cg_iters_mean"]},
        "finite": r["finite"],
    }


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--size", type=int, default=128)
    p.add_argument("--steps", type=int, default=10)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--settle-size", type=int, default=64, help="sheet side for the static sag check (0 skips it)")
    p.add_argument("--settle-time", type=float, default=10.0, help="simulated seconds of the settling run [s]")
    p.add_argument(
        "--settle-implicit", action="store_true", help="also settle implicit_euler (multigrid) for the sag check"
    )
    p.add_argument("--cg-tol", type=float, default=CG_TOL, help="CG relative tolerance of implicit_euler and the peer")
    p.add_argument(
        "--cases",
        nargs="+",
        default=list(CASES),
        choices=list(CASES),
        help="warpcloth cases timed (ratios need theirs)",
    )
    p.add_argument("--peer", default=DEFAULT_PEER, help="the numpy/scipy peer script ('' skips it)")
    p.add_argument(
        "--peer-python", default=sys.executable, help="the Python that runs the peer (needs numpy and scipy)"
    )
    args = p.parse_args(argv)

    wp.init()
    print(f"# bench/solvers.py {' '.join(argv if argv is not None else sys.argv[1:])}")
    print(
        f"# {time.strftime('%Y-%m-%d %H:%M:%S %Z')}, {platform.machine()} {os.cpu_count()} CPUs, load average "
        f"{os.getloadavg()[0]:.1f}, warp {wp.config.version}"
    )
    print(
        f"# speed: peer workload, {args.size}x{args.size}, dt = 1/60 s, CG tol {args.cg_tol:g}, {args.steps} steps "
        "from rest per case"
    )
    timed = cases(args.cg_tol)
    names = list(args.cases) + ([PEER] if args.peer else [])
    sims = {name: peer_workload(args.size, *timed[name]) for name in args.cases}
    results = {name: [] for name in names}
    for rep in range(args.repeats):
        order = names[rep % len(names) :] + names[: rep % len(names)]
        for name in order:
            r = (
                time_peer(args.peer, args.peer_python, args.size, args.steps, args.cg_tol)
                if name == PEER
                else time_case(sims[name], args.steps)
            )
            results[name].append(r)
            it = r["stats"].get("cg_iterations_mean")
            extra = f", CG iterations mean {it:.1f}" if it is not None else ""
            print(
                f"repeat {rep + 1} {name:26s} {r['ms']:9.1f} ms/step wall, {r['cpu_ms']:8.1f} ms "
                f"CPU{extra}{'' if r['finite'] else ' NON-FINITE'}",
                flush=True,
            )

    print("\n# summary: median [min-max] over repeats")
    for name in names:
        ms = [r["ms"] for r in results[name]]
        its = [r["stats"].get("cg_iterations_mean") for r in results[name]]
        extra = f", CG iterations {spread(its)}" if its[0] is not None else ""
        print(f"{name:26s} {spread(ms)} ms/step{extra}")

    def ratio(a: str, b: str, label: str, note: str = "") -> None:
        if a in results and b in results:
            print(f"{label:42s} {spread([ra['ms'] / rb['ms'] for ra, rb in zip(results[a], results[b])])}{note}")

    print("\n# ratios of ms/step, per repeat, median [min-max]")
    ratio(
        PEER,
        "implicit_euler/multigrid",
        "peer implicit / implicit_euler multigrid:",
        "  (target >= 5 at tol 1e-3, >= 2 at 1e-5)",
    )
    ratio(PEER, "implicit_euler/jacobi", "peer implicit / implicit_euler jacobi:")
    ratio("implicit_euler/jacobi", "implicit_euler/multigrid", "implicit_euler jacobi / multigrid:")
    ratio("implicit_euler/jacobi", "vbd", "implicit_euler jacobi / vbd:", "  (target >= 5)")
    ratio("implicit_euler/jacobi", "projective", "implicit_euler jacobi / projective:", "  (target >= 5)")

    if args.settle_size:
        n = args.settle_size
        steps = int(round(args.settle_time / DT))
        print(f"\n# statics: scenario sheet {n}x{n}, dt = 1/60 s, {args.settle_time:g} s, default options")
        base = sheet.build(rows=n, cols=n, dt=DT, device="cpu")
        eq = static_equilibrium(base.model, base.control)
        y0 = base.model.host.q[:, 1].astype(np.float64)
        sag_ref = float((y0 - eq.x[:, 1]).max())
        print(f"float64 equilibrium: sag {sag_ref * 1e3:.4f} mm (residual {eq.residual:.1e} N)")
        settle = [("vbd", ("vbd", {})), ("projective", ("projective", {}))]
        if args.settle_implicit:
            settle.insert(0, ("implicit_euler/multigrid", ("implicit_euler", {"preconditioner": "multigrid"})))
        for name, (integrator, options) in settle:
            sim = sheet.build(rows=n, cols=n, integrator=integrator, integrator_options=options, dt=DT, device="cpu")
            sim.simulate(steps)
            sag = float((y0 - sim.state.particle_q.numpy()[:, 1]).max())
            speed = float(np.linalg.norm(sim.state.particle_qd.numpy(), axis=1).max())
            print(
                f"{name:26s} sag {sag * 1e3:.4f} mm, error {100 * (sag - sag_ref) / sag_ref:+.2f} % (target within 2 "
                f"%), max speed {speed:.2e} m/s"
            )


if __name__ == "__main__":
    main()
