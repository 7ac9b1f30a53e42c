"""The fidelity rule per shipped scene: its default and candidate configurations against the float64 equilibrium.

    python bench/fidelity.py [--scenes drape,tablecloth,...] [--size N] [--only default] [--json out.json]
    python bench/fidelity.py --scenes warpcloth/examples/cape.toml --breeze --pick 0,1
    python bench/fidelity.py --scenes tablecloth --size 16 --duration 20 --speeds
    python bench/fidelity.py --scenes warpcloth/examples/cape.toml --duration 8 --speeds --pick 0,1
    python bench/fidelity.py --scenes character --moving --size 16 --duration 1.5

Each scene (a scenario or a scenario file) runs to rest on the CPU with its default configuration and the
candidates below (warpcloth.lab.fidelity.measure_fidelity); prints the largest structural strain at rest
against the float64 equilibrium's (ratio, rule <= 1.5x), the shape error (rule <= 2 % of the size), the
peak strain in motion less the equilibrium's (rule <= 2 %), the capped steps (solve cap / strain cap) and
CPU ms per 1/60 s frame at rest. A scene in STILL_AIR (the cape) rests with its wind stilled and is
measured in motion in its wind as well; ``--breeze`` prints, for such a scene, the peak strain in its wind of
the picked candidates and of the converged dynamics (explicit Euler at a quarter of its dt), and times those
candidates interleaved 1 s into the wind (7 rounds of time_steps, thread CPU ms per 1/60 s frame). These are
the figures of docs/materials.md's "Fidelity of the shipped scenes"; tests/test_fidelity.py holds each
default to the rule at a reduced size. ``--speeds`` prints a run of the picked candidates (default: the
scene's default) every 0.5 s: the largest particle speed, where that particle is, and how many move faster
than the equilibrium detector's 5 mm/s. ``--moving`` judges a scene that never rests (MOVING: the character's
walking body) in motion only: each garment's peak strain per candidate against the converged dynamics'
(MOVING_REFERENCES, two refinements), with CPU process ms per frame (intersections: ``warpcloth run ... --usd``
then ``warpcloth check-intersections``, docs/character.md).
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import time
from dataclasses import replace

import numpy as np

from warpcloth.lab.accuracy import OVERSTRETCH
from warpcloth.lab.fidelity import measure_fidelity, motion_peak_strain, motion_piece_peaks
from warpcloth.run.harness import time_steps
from warpcloth.scenarios import get_scenario

CAPE = "warpcloth/examples/cape.toml"
#: Scenes whose wind never lets them rest (the cape flaps in its breeze): at rest with the wind stilled, in
#: motion in their wind too (measure_fidelity's still_air, for the scene's own duration); scene -> the simulated
#: seconds [s] its rest in still air may take (the cape's explicit Euler rests at 8.8 s).
STILL_AIR = {CAPE: 15.0}
#: The landing scenes' candidates (drape and tablecloth measure the same configurations).
LANDING = [
    (None, None, None),
    ("xpbd", {"iterations": 1, "substeps": 64}, None),
    ("xpbd", {"iterations": 2, "substeps": 32}, None),
    ("implicit_euler", {"preconditioner": "multigrid"}, None),
    ("projective", {}, None),
    ("xpbd", {"iterations": 1, "substeps": 48}, None),
    ("xpbd", {"iterations": 1, "substeps": 32}, None),
]
#: scene -> its candidates: (integrator, options, dt [s] or None: the default); (None, None, None): the default.
CANDIDATES = {
    "drape": LANDING,
    "tablecloth": LANDING,
    "fold": [
        (None, None, None),
        ("xpbd", {}, None),
        ("xpbd", {"iterations": 2, "substeps": 32}, None),
        ("xpbd", {"iterations": 1, "substeps": 64}, None),
        ("implicit_euler", {"preconditioner": "multigrid"}, None),
        ("projective", {}, None),
    ],
    "cantilever": [
        (None, None, None),
        ("projective", {}, None),
        ("xpbd", {"iterations": 1, "substeps": 64}, None),
    ],
    CAPE: [
        (None, None, None),
        ("implicit_euler", {"preconditioner": "block_jacobi"}, None),
        ("xpbd", {}, None),
        ("xpbd", {"iterations": 2, "substeps": 32}, None),
        ("xpbd", {"iterations": 1, "substeps": 64}, None),
        ("projective", {}, None),
    ],
}

#: Scenes that never rest (the character's body walks for the whole run): judged in motion only, each piece's
#: peak strain at most OVERSTRETCH above the converged dynamics' (the larger of MOVING_REFERENCES' two
#: refinements, shown to agree). scene -> its candidates (integrator, options; None: the default).
MOVING = {
    "character": [
        (None, None),
        ("xpbd", {"iterations": 1, "substeps": 32}),
        ("xpbd", {"iterations": 2, "substeps": 16}),
        ("xpbd", {"iterations": 1, "substeps": 64}),
        ("implicit_euler", {}),
        ("vbd", {}),
        ("projective", {}),
    ]
}
MOVING_REFERENCES = [("xpbd", {"iterations": 1, "substeps": 128}), ("xpbd", {"iterations": 1, "substeps": 256})]


def moving(scene: str, chosen: list, **size) -> None:
    """Each piece's peak strain in motion of the converged references and the candidates (module docstring)."""
    refs = {}
    for integrator, options in MOVING_REFERENCES:
        peaks, cpu, frames, _ = motion_piece_peaks(scene, integrator, options, **size)
        print(f"reference {integrator} {options}: " + ", ".join(f"{k} {100 * v:.2f} %" for k, v in peaks.items()))
        for k, v in peaks.items():
            refs[k] = max(refs.get(k, -math.inf), v)
    for integrator, options in chosen:
        peaks, cpu, frames, result = motion_piece_peaks(scene, integrator, options, **size)
        excess = {k: v - refs[k] for k, v in peaks.items()}
        ok = result.stable and not result.capped_cause and all(e <= OVERSTRETCH for e in excess.values())
        cells = ", ".join(f"{k} {100 * peaks[k]:.2f} % ({100 * excess[k]:+.2f})" for k in peaks)
        print(
            f"{integrator or 'default'} {options or ''}: {cells}; {1e3 * cpu / frames:.1f} ms/frame; "
            f"capped {result.capped_steps}; {'meets' if ok else 'fails'}",
            flush=True,
        )


def _label(f) -> str:
    opts = ",".join(f"{k}={v}" for k, v in f.options.items())
    return f"{f.integrator}({opts})" if opts else f.integrator


def breeze(scene: str, chosen: list) -> None:
    """Peak strain in ``scene``'s wind (each candidate; the converged dynamics: explicit Euler at a quarter of its
    stable dt) and the candidates' interleaved timing."""
    for integrator, options, scale in [("explicit_euler", {}, 0.25)] + [(i, o, 1.0) for i, o, _ in chosen]:
        peak = motion_peak_strain(scene, integrator, options, dt_scale=scale)
        print(f"{integrator or 'default'} {options or ''} dt x {scale:g}: peak strain in the wind {100 * peak:.3f} %")
    scenario, sims = get_scenario(scene), []
    for integrator, options, _ in chosen:
        cfg = scenario.config(device="cpu", **({"integrator": integrator} if integrator else {}))
        sim = scenario.build(replace(cfg, integrator_options=scenario.integrator_options(cfg.integrator, options)))
        sim.simulate(round(1.0 / sim.dt))
        sims.append(sim)
    rounds = [[] for _ in sims]
    for r in range(7):
        for sim, ms in zip(sims, rounds, strict=True):
            t = time_steps(sim, windows=1, window_seconds=0.3, warm_up=r == 0)
            ms.append(t.median_ms * (1.0 / 60.0) / sim.dt)
    for (integrator, options, _), ms in zip(chosen, rounds, strict=True):
        spread = ", ".join(f"{m:.1f}" for m in ms)
        print(f"{integrator or 'default'} {options or ''}: {statistics.median(ms):.2f} ms/frame [{spread}]")


def speeds(scene: str, duration: float | None, integrator=None, options=None, **size) -> None:
    """A run of ``scene`` (``integrator`` and ``options``, None: its default) every 0.5 s: its fastest particle
    (speed, position) and how many move faster than 5 mm/s."""
    scenario = get_scenario(scene)
    cfg = scenario.config(device="cpu", **size, **({"duration": duration} if duration else {}))
    cfg = replace(cfg, integrator=integrator or cfg.integrator)
    sim = scenario.build(replace(cfg, integrator_options=scenario.integrator_options(cfg.integrator, options)))
    print(f"{scenario.name} {cfg.integrator} {options or ''}")
    frame = max(1, math.ceil((1.0 / 60.0) / sim.dt - 1e-9))
    while sim.sim_time < cfg.duration - 1e-9:
        sim.simulate(30 * frame)
        v = np.linalg.norm(sim.state.particle_qd.numpy(), axis=1)
        k = int(np.argmax(v))
        where = np.round(sim.state.particle_q.numpy()[k], 3)
        print(
            f"t {sim.sim_time:5.2f} s: fastest {1e3 * v[k]:7.2f} mm/s (particle {k} at {where}); {np.sum(v > 5e-3)} > 5 mm/s"
        )


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", default=",".join(CANDIDATES))
    ap.add_argument("--size", type=int, default=None, help="rows = cols of a grid scene (default: the scene's)")
    ap.add_argument("--rows", type=int, default=None, help="rows (with --size: its columns) of a grid scene")
    ap.add_argument(
        "--duration", type=float, default=None, help="simulated seconds at most to rest (default: the scene's)"
    )
    ap.add_argument("--only", choices=("default", "all"), default="all")
    ap.add_argument("--pick", default=None, help="candidates by index (0: the default), e.g. 1,3")
    ap.add_argument("--json", default=None, help="append every row as a JSON line to this file")
    ap.add_argument("--breeze", action="store_true", help="a wind scene's peak strains and interleaved timing")
    ap.add_argument("--speeds", action="store_true", help="a scene's default run: its fastest particle every 0.5 s")
    ap.add_argument("--moving", action="store_true", help="a scene that never rests: its pieces' peak strains")
    args = ap.parse_args(argv)
    if args.moving:
        for scene in args.scenes.split(","):
            size = {"rows": args.size, "cols": args.size} if args.size else {}
            if args.duration:
                size["duration"] = args.duration
            chosen = MOVING[scene]
            moving(scene, [chosen[int(k)] for k in args.pick.split(",")] if args.pick else chosen, **size)
        return
    if args.speeds:
        for scene in args.scenes.split(","):
            size = {"rows": args.rows or args.size, "cols": args.size} if args.size else {}
            for integrator, options, _ in [CANDIDATES[scene][int(k)] for k in (args.pick or "0").split(",")]:
                speeds(scene, args.duration, integrator, options, **size)
        return
    if args.breeze:
        for scene in args.scenes.split(","):
            chosen = CANDIDATES[scene]
            breeze(scene, [chosen[int(k)] for k in args.pick.split(",")] if args.pick else chosen)
        return
    print(
        f"{'scene':12} {'n':>5} {'configuration':44} {'strain':>7} {'eq':>7} {'ratio':>6} {'shape':>6} "
        f"{'motion':>7} {'capped':>7} {'ms/fr':>7}  verdict"
    )
    for scene in args.scenes.split(","):
        size = {} if args.size is None or scene.endswith(".toml") or scene == "cantilever" else {"rows": args.size}
        if "rows" in size:
            size["cols"] = args.size
            if args.rows:
                size["rows"] = args.rows
        if args.duration or scene in STILL_AIR:
            size["duration"] = args.duration or STILL_AIR[scene]
        chosen = CANDIDATES[scene][: 1 if args.only == "default" else None]
        if args.pick:
            chosen = [chosen[int(k)] for k in args.pick.split(",")]
        for integrator, options, dt in chosen:
            start = time.perf_counter()
            f = measure_fidelity(scene, integrator, options, dt=dt, still_air=scene in STILL_AIR, **size)
            wall = time.perf_counter() - start
            verdict = "meets" if f.meets else "; ".join(f.failures)
            print(
                f"{f.scene[:12]:12} {f.particles:5d} {_label(f)[:44]:44} {100 * f.strain:6.2f}% {100 * f.strain_eq:6.2f}% "
                f"{f.strain_ratio:6.2f} {100 * f.shape:5.2f}% {100 * f.stretch_excess:+6.2f}% "
                f"{f.capped_steps:3d}/{f.strain_capped_steps:<3d} {f.ms_frame:7.1f}  {verdict}  ({wall:.0f} s)",
                flush=True,
            )
            if args.json:
                row = dict(vars(f)) | {
                    "strain_ratio": f.strain_ratio,
                    "stretch_excess": f.stretch_excess,
                    "meets": f.meets,
                    "failures": f.failures,
                    "wall_s": wall,
                }
                with open(args.json, "a") as fh:
                    fh.write(json.dumps(row) + "\n")


if __name__ == "__main__":
    main()
