"""``warpcloth advise --size N --budget-ms B --tolerance T``: the cheapest measured configuration
meeting a tolerance within a budget, from a study's results (:mod:`warpcloth.lab.advise`; by
default the committed CPU study shipped in the package)."""

from __future__ import annotations

import argparse
import math

from warpcloth.lab.advise import AUTO_ORDER, METRICS, SHIPPED, advise, format_advice, load_study


def _positive(kind: str, whole: bool = False):
    def parse(text: str):
        try:
            value = int(text) if whole else float(text)
        except ValueError:
            value = None
        if value is None or not math.isfinite(value) or value <= 0:
            what = "a whole number >= 1" if whole else "a finite number > 0"
            raise argparse.ArgumentTypeError(f"{kind} must be {what}, got {text!r}")
        return value

    return parse


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--size", type=_positive("--size", whole=True), required=True, metavar="N", help="the cloth: N x N particles"
    )
    p.add_argument(
        "--budget-ms",
        type=_positive("--budget-ms"),
        required=True,
        metavar="MS",
        help="the budget [ms of computation per 1/60 s of simulated time, the study's cost]",
    )
    p.add_argument(
        "--tolerance",
        type=_positive("--tolerance"),
        required=True,
        metavar="T",
        help="the largest error allowed, as a fraction of the cloth size (0.05: 5 %%)",
    )
    p.add_argument(
        "--metric",
        default="auto",
        choices=["auto", *METRICS],
        help=f"the error judged (default auto: the first of {', '.join(AUTO_ORDER)} whose float64 floor allows a "
        "verdict at that size)",
    )
    p.add_argument("--device", default=None, help="the study's device (default: the only one it measured)")
    p.add_argument(
        "--results",
        default=None,
        metavar="DIR",
        help="a study's output folder (its results.csv; default: the committed CPU study shipped with warpcloth)",
    )


def run(args) -> int:
    study = load_study(args.results or SHIPPED)
    print(format_advice(advise(study, args.size, args.tolerance, args.budget_ms, args.metric, args.device)))
    return 0


__all__ = ["add_arguments", "run"]
