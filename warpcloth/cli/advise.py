"""``warpcloth advise --size N --budget-ms B --tolerance T``: the cheapest measured configuration
meeting a tolerance within a budget, from a study's results (:mod:`warpcloth.lab.advise`; by
default the committed CPU study shipped in the package)."""

from __future__ import annotations

import argparse

from warpcloth.lab.advise import AUTO_ORDER, METRICS, SHIPPED, advise, format_advice, load_study
from warpcloth.run.params import Param, argparse_type, grid_dim, positive

#: The numbers advise takes, parsed and worded as ``warpcloth run``'s (:mod:`warpcloth.run.params`):
#: the size as a grid's side (``--size``, ``--rows``), the budget and tolerance as positive finite numbers.
NUMBERS = (
    Param("size", grid_dim, "", "the cloth: N x N particles", "integer >= 3", "cloth", commands=(), metavar="N"),
    Param(
        "budget_ms",
        positive,
        "ms",
        "the budget [ms of computation per 1/60 s of simulated time, the study's cost]",
        "number > 0",
        "run",
        commands=(),
        metavar="MS",
    ),
    Param(
        "tolerance",
        positive,
        "",
        "the largest error allowed, as a fraction of the cloth size (0.05: 5 %%)",
        "number > 0",
        "run",
        commands=(),
        metavar="T",
    ),
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    for param in NUMBERS:
        p.add_argument(param.flag, type=argparse_type(param), required=True, metavar=param.metavar, help=param.help)
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


__all__ = ["NUMBERS", "add_arguments", "run"]
