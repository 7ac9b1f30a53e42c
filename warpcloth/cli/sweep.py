"""``warpcloth sweep TESTS.xml --out RESULTS.csv``: an XML test list run to CSV (:mod:`warpcloth.lab.sweep`)."""

from __future__ import annotations

import argparse
import sys

from warpcloth.cli.listing import example_path
from warpcloth.errors import WarpclothError
from warpcloth.lab.sweep import run_sweep
from warpcloth.lab.testlist import DEFAULT_MAX_RUNS


def _workers(text: str) -> int:
    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number >= 1") from None
    if n < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1, got {n}")
    return n


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("tests", metavar="TESTS.xml", nargs="?", default=None, help="the test list")
    p.add_argument(
        "--example",
        default=None,
        metavar="NAME",
        help="run a test list shipped with warpcloth (quick, seed_plan; see 'list --examples')",
    )
    p.add_argument("--out", "-o", required=True, metavar="RESULTS.csv", help="results file ('-' for stdout)")
    mode = p.add_mutually_exclusive_group()
    mode.add_argument("--resume", action="store_true", help="continue RESULTS.csv: skip runs already in it")
    mode.add_argument("--overwrite", action="store_true", help="replace RESULTS.csv if it exists")
    p.add_argument(
        "--max-runs",
        type=int,
        default=DEFAULT_MAX_RUNS,
        metavar="N",
        help=f"refuse a test list that expands to more than N runs (default {DEFAULT_MAX_RUNS})",
    )
    p.add_argument(
        "--workers",
        type=_workers,
        default=None,
        metavar="N",
        help="run N runs at once in local worker processes (default 1: one after another; more than "
        "the devices or cores prints a warning: timings are affected)",
    )
    p.add_argument(
        "--devices",
        default=None,
        metavar="cuda:0,cuda:1",
        help="spread the CUDA runs over these GPUs, one worker each (--workers defaults to their number)",
    )
    p.add_argument(
        "--ray",
        default=None,
        metavar="auto|ADDRESS",
        help="run the runs as Ray tasks on a cluster: auto (the local cluster of 'ray start'), HOST:PORT, "
        "ray://HOST:PORT, or local (start one in this process); needs pip install 'warpcloth[cluster]'",
    )
    p.add_argument(
        "--quiet", "-q", action="store_true", help="no progress bar on stderr (the closing summary line still prints)"
    )
    # --verbose comes with every subcommand (cli.parse.add_verbose); --quiet is this one's own


def run(args) -> int:
    if (args.tests is None) == (args.example is None):
        raise WarpclothError(
            "give a test list (TESTS.xml) or --example NAME, not " + ("both" if args.tests else "neither")
        )
    tests = args.tests if args.tests is not None else example_path(args.example)
    devices = None
    if args.devices is not None:
        devices = args.devices.split(",")
        if any(not d.strip() for d in devices):
            raise WarpclothError(
                f"--devices: {args.devices!r} is not a comma-separated list of CUDA devices (cuda:0,cuda:1)"
            )
    summary = run_sweep(
        tests,
        args.out,
        resume=args.resume,
        overwrite=args.overwrite,
        progress=None if args.quiet else sys.stderr,
        max_runs=args.max_runs,
        report=sys.stderr,
        workers=args.workers,
        devices=devices,
        ray=args.ray,
    )
    line = f"{args.out if args.out != '-' else 'stdout'}: {summary.describe()}"
    print(line, file=sys.stderr if args.out == "-" else sys.stdout)  # the result's summary, also with --quiet
    return 1 if summary.outcomes.get("error") else 0


def interrupted_hint(args) -> str:
    """What the line after Ctrl-C or SIGTERM adds: where the finished runs are."""
    return f"; finished runs are in {args.out}, continue with --resume" if args.out != "-" else ""


__all__ = ["add_arguments", "interrupted_hint", "run"]
