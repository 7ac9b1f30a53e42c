"""``warpcloth calibrate``: fit a material's bending rigidity (and, with more targets, its stretch or
compression) so that a chosen resolution and integrator reproduce measured textile-test values
(:mod:`warpcloth.lab.calibrate`, docs/materials.md "Calibration")."""

from __future__ import annotations

import argparse
import json

from warpcloth.cli.model import add_integrator_options, integrator_options_from_args
from warpcloth.errors import WarpclothError
from warpcloth.integrators import check_integrator_name
from warpcloth.lab.calibrate import TARGETS, UNKNOWNS, calibrate
from warpcloth.run.params import BY_NAME, PARAMS, add_flags, argparse_type, cli_value
from warpcloth.sim.material import material_with


def _target(text: str) -> tuple[str, float]:
    name, sep, value = text.partition("=")
    if not sep or name.strip() not in TARGETS:
        raise argparse.ArgumentTypeError(
            f"{text!r} is not NAME=VALUE with NAME one of {', '.join(TARGETS)} (e.g. bending_length=0.021)"
        )
    try:
        number = float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: {value!r} is not a number") from None
    return name.strip(), number


def _unknowns(text: str) -> tuple:
    names = tuple(s.strip() for s in text.split(","))
    bad = [n for n in names if n not in UNKNOWNS]
    if bad:
        raise argparse.ArgumentTypeError(f"unknown {bad[0]!r}; fit any of {', '.join(UNKNOWNS)} (comma-separated)")
    return names


#: The material's run parameters (its values), taken as flags here as by ``warpcloth run``.
MATERIAL_FLAGS = tuple(p.name for p in PARAMS if p.group == "material" and p.name != "material") + ("bend_rigidity",)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "material",
        type=argparse_type(BY_NAME["material"]),
        help="the material to start from: a preset ('warpcloth list'), or custom with --density, --stretch, --shear "
        "and --bend-rigidity",
    )
    p.add_argument(
        "--target",
        action="append",
        type=_target,
        required=True,
        metavar="NAME=VALUE",
        help="a measured value to reproduce: bending_length=METRES (the cantilever test) or drape_coefficient=DC "
        "(the Cusick test); repeat for several",
    )
    p.add_argument(
        "--fit",
        type=_unknowns,
        default=("bend",),
        metavar="NAMES",
        help="what to fit, comma-separated: bend (a factor on B), stretch (a factor on the stretch stiffness), "
        "compression (phi); as many targets as unknowns at least (default bend)",
    )
    p.add_argument(
        "--size",
        type=int,
        default=None,
        help="resolution: particles along the cantilever strip, points across the Cusick disc "
        "(default the scenarios': 34, 64)",
    )
    p.add_argument(
        "--integrator", "-i", default=None, help="integrator of the runs (default the scenarios': implicit_euler)"
    )
    p.add_argument(
        "--bend",
        choices=["dihedral", "provot", "choi_ko"],
        default=None,
        help="bending model of the runs (default the scenarios': dihedral; provot and choi_ko: bend springs)",
    )
    p.add_argument("--device", default="cpu", help="Warp device (default cpu)")
    p.add_argument("--tolerance", type=float, default=1e-3, help="relative residual to stop at (default 0.001)")
    p.add_argument("--max-runs", type=int, default=40, help="the most scenario runs (default 40)")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of the summary")
    add_flags(p, "run", skip=tuple(q.name for q in PARAMS if q.name not in MATERIAL_FLAGS))
    add_integrator_options(p)


def run(args) -> int:
    check_integrator_name(args.integrator or "implicit_euler", flag="--integrator")
    options = integrator_options_from_args(args.integrator or "implicit_euler", args)
    values = {name: cli_value(BY_NAME[name], args) for name in MATERIAL_FLAGS}
    start = material_with(args.material, **values)
    if start is None:
        raise WarpclothError("calibrate needs a material to start from: a preset, or custom with its values")
    targets = {}
    for name, value in args.target:
        if name in targets:
            raise WarpclothError(
                f"--target {name} is given twice ({targets[name]:g} and {value:g}): give each target once"
            )
        targets[name] = value
    quiet = getattr(args, "quiet", False) or args.json

    def progress(e):
        if not quiet:
            tried = ", ".join(f"{k}={v:.6g}" for k, v in e.values.items())
            got = ", ".join(f"{k}={v:.6g}" for k, v in e.measured.items())
            print(f"  run {tried}: {got} ({e.wall_s:.1f} s)", flush=True)

    result = calibrate(
        start,
        targets,
        fit=args.fit,
        size=args.size,
        integrator=args.integrator,
        device=args.device,
        tolerance=args.tolerance,
        max_runs=args.max_runs,
        progress=progress,
        options=options,
        bend=args.bend,
    )
    if args.json:
        print(json.dumps(result.to_dict()))
        return 0
    if quiet:
        return 0
    print(summary(result))
    return 0


def summary(result) -> str:
    m = result.material
    lines = [f"calibrate {result.start.name}: " + ", ".join(_unknown_line(k, v, m) for k, v in result.unknowns.items())]
    for name, target in result.targets.items():
        unit = " m" if name == "bending_length" else ""
        lines.append(
            f"  {name}: target {target:.6g}{unit}, measured {result.measured[name]:.6g}{unit}, "
            f"residual {100 * result.residual[name]:+.3f} %"
        )
    lines.append(
        f"  converged: {'yes' if result.converged else 'NO'} ({result.message}); {result.runs} evaluations, "
        f"{result.wall_s:.1f} s wall"
    )
    lines.append(f"  use: warpcloth run SCENARIO {result.flags()}")
    return "\n".join(lines)


def _unknown_line(name: str, value: float, m) -> str:
    if name == "bend":
        return f"bend x {value:.4g} (B_warp {m.bend_warp:.4g} N m, B_weft {m.bend_weft:.4g} N m)"
    if name == "stretch":
        return f"stretch x {value:.4g} (C11 {m.stretch_warp:.4g} N/m, C22 {m.stretch_weft:.4g} N/m)"
    return f"compression {value:.4g}"


__all__ = ["add_arguments", "run", "summary"]
