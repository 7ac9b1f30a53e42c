"""``warpcloth study``: the flags and the entry point of the accuracy-aware study
(:mod:`warpcloth.lab.study`)."""

from __future__ import annotations

import argparse
import shlex
import sys

from warpcloth.errors import WarpclothError
from warpcloth.lab.accuracy import DEFAULT_TOLERANCE
from warpcloth.lab.estimate import RECORDED_ON, calibrate, estimate_plan, format_estimate, recorded_costs
from warpcloth.lab.plan import PROFILES, make_plan
from warpcloth.lab.study import available_devices, run_study


def _list(kind: str):
    def parse(text: str) -> list:
        items = [t.strip() for t in text.split(",")]
        if not text.strip() or any(not t for t in items):
            raise argparse.ArgumentTypeError(
                f"--{kind} must be a comma-separated list without empty items, got {text!r}"
            )
        return items

    return parse


def _sizes(text: str) -> list:
    items = _list("sizes")(text)
    try:
        sizes = [int(t) for t in items]
    except ValueError:
        raise argparse.ArgumentTypeError(f"--sizes must be comma-separated integers >= 3, got {text!r}") from None
    if any(s < 3 for s in sizes):
        raise argparse.ArgumentTypeError(
            f"--sizes must be comma-separated integers >= 3 (n x n particles), got {text!r}"
        )
    return sizes


def _count():
    def parse(text: str) -> int:
        try:
            n = int(text)
        except ValueError:
            n = None
        if n is None or n < 1:
            raise argparse.ArgumentTypeError(f"must be a whole number >= 1, got {text!r}")
        return n

    return parse


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--profile",
        default="quick",
        choices=list(PROFILES),
        help="quick (tiny sizes, a few minutes on 2 CPU cores), standard (sizes 16-128 on the CPU, the committed "
        "study), gpu (64 and 128 on cuda, <= 8 min of device time)",
    )
    p.add_argument(
        "--integrators", type=_list("integrators"), default=None, metavar="A,B", help="integrators (default: all)"
    )
    p.add_argument(
        "--sizes",
        type=_sizes,
        default=None,
        metavar="N,M",
        help="n x n sizes (default: the profile's); every size is measured for accuracy against a float64 reference",
    )
    p.add_argument(
        "--scenarios",
        type=_list("scenarios"),
        default=None,
        metavar="grid,FILE.toml",
        help="grid (the study's swing, flag and contact transients: default; 'sheet,flag' is the same) and/or "
        "scenario files (.toml) or other registered scenarios, measured at their own mesh: max stable dt, "
        "time to equilibrium, ms/step (no float64 reference: no accuracy)",
    )
    p.add_argument(
        "--devices",
        type=_list("devices"),
        default=None,
        metavar="cpu,cuda",
        help="Warp devices (default cpu; seed: cpu,cuda); a missing one is skipped with one line",
    )
    p.add_argument(
        "--tolerance",
        type=float,
        default=DEFAULT_TOLERANCE,
        help="the verdict's accuracy tolerance as a fraction of the cloth size (default 0.01; the tables also "
        "give 1 %%, 5 %% and 10 %%)",
    )
    p.add_argument(
        "--budget-ms",
        type=float,
        default=None,
        metavar="MS",
        help="the frame budget [ms per 60 FPS frame] the report answers for (default 2; the whole frame, "
        "16.7 ms, is given beside it)",
    )
    p.add_argument(
        "--out",
        "-o",
        default=None,
        metavar="DIR",
        help="output folder: results.csv, report.md, PNG plots (required but with --estimate)",
    )
    p.add_argument(
        "--estimate",
        action="store_true",
        help="measure per-step costs (seconds to a minute) and print the plan's estimated time per phase; measures "
        "nothing else, writes nothing",
    )
    p.add_argument(
        "--workers",
        type=_count(),
        default=None,
        metavar="N",
        help="run the searches (stability, accuracy, equilibrium) in N worker processes; the timings follow, "
        "--timing-workers at a time (docs/study.md)",
    )
    p.add_argument(
        "--timing-workers",
        type=_count(),
        default=None,
        metavar="M",
        help="timed runs at once in a parallel study (default 1: each timing has the machine to itself; "
        "more than the devices is warned about)",
    )
    p.add_argument(
        "--ray",
        default=None,
        metavar="auto|ADDRESS",
        help="run the searches as Ray tasks: auto (the cluster of 'ray start'), HOST:PORT, ray://HOST:PORT, or "
        "local (start one in this process); needs pip install 'warpcloth[cluster]'",
    )
    mode = p.add_mutually_exclusive_group()
    mode.add_argument(
        "--resume", action="store_true", help="continue DIR/results.csv: finished measurements are not redone"
    )
    mode.add_argument("--overwrite", action="store_true", help="replace DIR/results.csv if it exists")
    # --quiet (no progress, no summary) and --verbose come with every subcommand (cli.parse.add_verbose)


def run(args) -> int:
    plan = make_plan(
        args.profile,
        integrators=args.integrators,
        sizes=args.sizes,
        devices=args.devices,
        tolerance=args.tolerance,
        scenarios=args.scenarios,
        budget_ms=args.budget_ms,
    )
    if args.estimate:
        devices = available_devices(plan.devices, sys.stderr)
        if not devices:  # a model of per-step costs timed on the devices; for CUDA, those recorded on an H200
            costs = recorded_costs(plan) if all(d.startswith("cuda") for d in plan.devices) else None
            if costs is None:
                raise WarpclothError(
                    f"no estimate: --estimate times steps on the plan's devices and none of "
                    f"{', '.join(plan.devices)} is available here (no recorded costs for this plan either)"
                )
            phases = {plan.devices[0]: estimate_plan(plan, costs, plan.devices[0])}
            print(format_estimate(plan, phases, args.workers or 1, recorded=RECORDED_ON))
            return 0
        quiet = getattr(args, "quiet", False)
        by_device = {d: estimate_plan(plan, calibrate(plan, d, None if quiet else sys.stderr), d) for d in devices}
        print(format_estimate(plan, by_device, args.workers or 1))
        return 0
    if not args.out:
        raise WarpclothError(
            "--out DIR is required (where results.csv, report.md and the plots go), except with --estimate"
        )
    command = (
        "warpcloth " + " ".join(shlex.quote(a) for a in sys.argv[1:])
        if sys.argv and sys.argv[0].endswith("warpcloth")
        else "warpcloth study " + " ".join(shlex.quote(a) for a in _argv(args))
    )
    summary = run_study(
        plan,
        args.out,
        resume=args.resume,
        overwrite=args.overwrite,
        progress=None if getattr(args, "quiet", False) else sys.stderr,
        command=command,
        workers=args.workers,
        ray=args.ray,
        timing_workers=args.timing_workers,
    )
    failed = f", {summary['failed']} group(s) failed (see above; --resume retries them)" if summary["failed"] else ""
    if not getattr(args, "quiet", False) or failed:
        print(
            f"{args.out}: {summary['measured']} measurements made, {summary['reused']} reused from the file, "
            f"{summary['wall_s']:.0f} s{failed}; wrote {', '.join(summary['files'])}"
        )
    return 1 if failed else 0


def _argv(args) -> list:
    """The flags of ``args`` again (for the report's command line when not run as ``warpcloth``)."""
    out = ["--profile", args.profile]
    for flag, value in (
        ("--integrators", args.integrators),
        ("--scenarios", args.scenarios),
        ("--devices", args.devices),
    ):
        if value:
            out += [flag, ",".join(value)]
    if args.sizes:
        out += ["--sizes", ",".join(map(str, args.sizes))]
    if args.tolerance != DEFAULT_TOLERANCE:
        out += ["--tolerance", repr(args.tolerance)]
    if args.budget_ms is not None:
        out += ["--budget-ms", repr(args.budget_ms)]
    for flag, value in (("--workers", args.workers), ("--timing-workers", args.timing_workers), ("--ray", args.ray)):
        if value is not None:
            out += [flag, str(value)]
    for flag, on in (("--resume", args.resume), ("--overwrite", args.overwrite)):
        if on:
            out.append(flag)
    return out + (["--out", args.out] if args.out else [])


def interrupted_hint(args) -> str:
    """What the line after Ctrl-C or SIGTERM adds: where the finished measurements are (nothing for
    ``--estimate``, which writes none)."""
    if getattr(args, "estimate", False) or not getattr(args, "out", None):
        return ""
    return f"; finished measurements are in {args.out}/results.csv, continue with --resume"


__all__ = ["add_arguments", "interrupted_hint", "run"]
