"""Figures of the float64 reference (docs/reference.md): convergence between two tolerances and
agreement with warpcloth's float32 integrators on the study's transients, and the static sheet.

    python bench/reference.py                       # 6x6 sheet swing 0.3 s, 5x6 flag 0.5 s, 8x8 static
    python bench/reference.py --rows 16 --cols 16 --swing 1.0 --flag 0.5
    python bench/reference.py --conditioning       # also: how a 1e-7 m perturbation of x0 grows
    python bench/reference.py --floor              # also: rk4 and explicit_euler at tiny dt (float32 floor)

Prints one line per measurement. CPU only; a few seconds to a minute.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import warp as wp

from warpcloth import Control, Simulator
from warpcloth.lab.reference import (
    cloth_size,
    convergence_check,
    reference_trajectory,
    simulate_frames,
    static_equilibrium,
    swing_from_horizontal,
    trajectory_error,
)
from warpcloth.scenarios import flag, sheet


def _run(model, integrator, dt, control, x0, duration, frame_dt):
    sim = Simulator(model, integrator, control, dt=dt)
    sim.state.particle_q.assign(np.asarray(x0, dtype=np.float32))
    return simulate_frames(sim, duration, frame_dt)


def transient(name, model, make_control, x0, duration, frame_dt, runs, conditioning=False):
    size = cloth_size(model)
    t0 = time.perf_counter()
    conv = convergence_check(model, make_control(), duration, frame_dt, x0=x0)
    wall = time.perf_counter() - t0
    print(
        f"{name}: {model.particle_count} particles, {duration:g} s, size {size:g} m; "
        f"reference rtol 1e-10 vs 1e-12: max |dx| = {conv.difference:.3g} m = {conv.difference / size:.3g} x size "
        f"(threshold 1e-2, required < 1e-5); both solves {wall:.1f} s"
    )
    for integrator, dt in runs:
        err = trajectory_error(
            _run(model, integrator, dt, make_control(), x0, duration, frame_dt), conv.reference, size
        )
        print(f"  {integrator:15s} dt {dt:.3g} s: e = {err:.3g} x size")
    if conditioning:
        # the float64 reference from x0 + a random 1e-7 m perturbation (about float32 rounding at
        # the cloth's coordinates): how far it ends from the unperturbed one bounds the float32 floor
        rng = np.random.default_rng(0)
        xp = np.asarray(x0, dtype=np.float64) + rng.normal(0.0, 1e-7, np.shape(x0))
        xp[model.pinned] = np.asarray(x0, dtype=np.float64)[model.pinned]
        perturbed = reference_trajectory(model, make_control(), duration, frame_dt, x0=xp)
        growth = np.linalg.norm(perturbed - conv.reference, axis=-1).max(axis=1)
        print(
            f"  conditioning: a 1e-7 m perturbation of x0 grows to {growth.max():.3g} m "
            f"(at t = {np.argmax(growth) * frame_dt:.2f} s) = {growth.max() / size:.3g} x size"
        )


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", type=int, default=6)
    ap.add_argument("--cols", type=int, default=6)
    ap.add_argument("--swing", type=float, default=0.3, help="sheet swing duration [s]")
    ap.add_argument("--flag", type=float, default=0.5, help="flag duration [s]")
    ap.add_argument("--static-size", type=int, default=8)
    ap.add_argument("--conditioning", action="store_true", help="also integrate from a perturbed x0")
    ap.add_argument("--floor", action="store_true", help="also run rk4 and explicit_euler at tiny dt")
    args = ap.parse_args(argv)
    wp.init()

    s = sheet.build(rows=args.rows, cols=args.cols, device="cpu")
    drag = s.control.drag_rate
    transient(
        f"sheet swing {args.rows}x{args.cols}",
        s.model,
        lambda: Control(drag_rate=drag),
        swing_from_horizontal(s.model),
        args.swing,
        0.01,
        [("explicit_euler", 1e-4), ("explicit_euler", 5e-5), ("rk4", 1 / 400), ("rk4", 1 / 800), ("rk4", 1 / 1600)]
        + ([("rk4", 1 / 2000), ("rk4", 1 / 4000), ("rk4", 1 / 8000), ("explicit_euler", 2.5e-5)] if args.floor else []),
        args.conditioning,
    )

    f = flag.build(rows=args.rows, cols=args.cols, device="cpu")
    fc = f.control
    transient(
        f"flag {args.rows}x{args.cols}",
        f.model,
        lambda: Control(drag_rate=fc.drag_rate, wind_coefficient=fc.wind_coefficient, wind_schedule=fc.wind_schedule),
        f.model.host.q,
        args.flag,
        0.01,
        [("explicit_euler", 1e-4), ("explicit_euler", 5e-5), ("rk4", 1 / 1000), ("rk4", 1 / 2000)]
        + ([("rk4", 1 / 4000), ("rk4", 1 / 8000), ("explicit_euler", 2.5e-5)] if args.floor else []),
        args.conditioning,
    )

    n = args.static_size
    st = sheet.build(rows=n, cols=n, device="cpu")
    t0 = time.perf_counter()
    eq = static_equilibrium(st.model, st.control)
    wall = time.perf_counter() - t0
    moved = np.linalg.norm(eq.x - st.model.host.q, axis=1).max()
    print(
        f"static sheet {n}x{n}: residual {eq.residual:.3g} N in {wall * 1e3:.0f} ms; max displacement from rest "
        f"{moved:.4g} m"
    )
    for dt, drag in ((2.5e-4, 5.0),):
        run = Simulator(st.model, "explicit_euler", Control(drag_rate=drag), dt=dt)
        run.simulate(int(round(2.0 / dt)))
        dev = np.linalg.norm(run.state.particle_q.numpy() - eq.x, axis=1).max()
        print(f"  explicit_euler dt {dt:g} s, drag {drag:g} 1/s, after 2 s: max |x - x_eq| = {dev:.3g} m")


if __name__ == "__main__":
    main()
