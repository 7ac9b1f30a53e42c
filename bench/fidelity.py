"""The fidelity rule per shipped scene: its default and candidate configurations against the float64 equilibrium.

    python bench/fidelity.py [--scenes drape,tablecloth,...] [--size N] [--only default] [--json out.json]

Each scene (a scenario or a scenario file) runs to rest on the CPU with its default configuration and the
candidates below (warpcloth.lab.fidelity.measure_fidelity); prints the largest structural strain at rest
against the float64 equilibrium's (ratio, rule <= 1.5x), the shape error (rule <= 2 % of the size), the
peak strain in motion less the equilibrium's (rule <= 2 %), the capped steps (solve cap / strain cap) and
CPU ms per 1/60 s frame at rest. These are the figures of docs/materials.md's "Fidelity of the shipped
scenes"; tests/test_fidelity.py holds each default to the rule at a reduced size.
"""

from __future__ import annotations

import argparse
import json
import time

from warpcloth.lab.fidelity import measure_fidelity

CAPE = "warpcloth/examples/cape.toml"
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
        ("xpbd", {}, None),
        ("xpbd", {"iterations": 2, "substeps": 32}, None),
        ("xpbd", {"iterations": 1, "substeps": 64}, None),
        ("implicit_euler", {"preconditioner": "multigrid"}, None),
        ("projective", {}, None),
    ],
}


def _label(f) -> str:
    opts = ",".join(f"{k}={v}" for k, v in f.options.items())
    return f"{f.integrator}({opts})" if opts else f.integrator


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", default=",".join(CANDIDATES))
    ap.add_argument("--size", type=int, default=None, help="rows = cols of a grid scene (default: the scene's)")
    ap.add_argument("--rows", type=int, default=None, help="rows (with --size: its columns) of a grid scene")
    ap.add_argument("--duration", type=float, default=None, help="simulated seconds at most (default: the scene's)")
    ap.add_argument("--only", choices=("default", "all"), default="all")
    ap.add_argument("--pick", default=None, help="candidates by index (0: the default), e.g. 1,3")
    ap.add_argument("--json", default=None, help="append every row as a JSON line to this file")
    args = ap.parse_args(argv)
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
        if args.duration:
            size["duration"] = args.duration
        chosen = CANDIDATES[scene][: 1 if args.only == "default" else None]
        if args.pick:
            chosen = [chosen[int(k)] for k in args.pick.split(",")]
        for integrator, options, dt in chosen:
            start = time.perf_counter()
            f = measure_fidelity(scene, integrator, options, dt=dt, **size)
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
