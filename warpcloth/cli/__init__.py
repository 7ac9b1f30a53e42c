"""The ``warpcloth`` command line: :func:`main` and the table of subcommands (:data:`COMMANDS`),
one module each.

    warpcloth run SCENARIO [--integrator NAME] [--rows N] [--cols N] [--dt S] ... [--usd PATH] [--json]
    warpcloth list [--examples]
    warpcloth bench [--integrators ...] [--sizes 32,64,128] [--devices cpu,cuda] [--out bench.csv]
    warpcloth sweep TESTS.xml --out RESULTS.csv [--resume | --overwrite] [--max-runs N]
                    [--workers N] [--devices cuda:0,cuda:1] [--ray auto|ADDRESS]
    warpcloth max-dt SCENARIO --integrator NAME [--rows N --cols N --stiffness KS ...] [--precision 0.02]
    warpcloth calibrate MATERIAL --target bending_length=0.021 [--target drape_coefficient=0.6] [--fit bend,...]
    warpcloth study --profile quick --out DIR [--workers N] [--resume | --overwrite] [--estimate]
    warpcloth check-intersections FILE.usd [--frames] [--json]
    warpcloth advise --size N --budget-ms MS --tolerance T [--metric M] [--device D] [--results DIR]

Bad input prints one line, ``warpcloth: error: ...``, and exits with status 2; an output that
cannot be written during the work exits 74, SIGTERM 143, Ctrl-C 130, a closed stdout 141
(:func:`warpcloth.cli.parse.guarded`). Every subcommand takes ``--verbose`` (Warp's messages).

A subcommand's module is imported only when it is chosen (or when :func:`build_parser` is asked
for every subcommand): ``warpcloth --version`` and ``warpcloth --help`` build the top level only.
Each module has ``add_arguments(parser)`` and ``run(args) -> int``, and may have
``interrupted_hint(args)`` (what the line after Ctrl-C adds).
"""

from __future__ import annotations

import importlib
import sys

from warpcloth.cli.parse import EXIT_USAGE, Parser, add_verbose, guarded
from warpcloth.version import __version__

#: The subcommands, in the order ``--help`` lists them: name -> (module, help line, whether the
#: common ``--quiet`` is added: ``sweep`` has its own).
COMMANDS = {
    "run": ("warpcloth.cli.run", "run a scenario and print a summary", True),
    "list": (
        "warpcloth.cli.listing",
        "list scenarios, integrators and material presets (--examples: the shipped XML test lists)",
        True,
    ),
    "bench": ("warpcloth.cli.bench", "benchmark integrators x sizes x devices on the sheet (bench/devices.py)", True),
    "sweep": ("warpcloth.cli.sweep", "run an XML test list, one CSV row per run (docs/sweep.md)", False),
    "max-dt": ("warpcloth.cli.maxdt", "find the largest stable time step of an integrator on a scenario", True),
    "calibrate": (
        "warpcloth.cli.calibrate",
        "fit a material's bending rigidity (stretch, compression) to measured bending length / drape coefficient",
        True,
    ),
    "study": (
        "warpcloth.cli.study",
        "the accuracy-aware study: stable/accurate dt, cost, real-time frontier, report (docs/study.md)",
        True,
    ),
    "check-intersections": (
        "warpcloth.cli.intersections",
        "count self-intersections and collider edges through the cloth at every frame of a USD file",
        True,
    ),
    "advise": (
        "warpcloth.cli.advise",
        "the cheapest measured configuration meeting a tolerance within a budget at a size, from a study's results",
        True,
    ),
}


def _module(command: str):
    return importlib.import_module(COMMANDS[command][0])


def build_parser(commands=None) -> Parser:
    """The ``warpcloth`` parser. ``commands``: the subcommands whose flags are added (None: every
    one; the others are listed, with their help line, without importing their modules)."""
    parser = Parser(
        prog="warpcloth", description="Mass-spring cloth simulator and integrator laboratory on NVIDIA Warp."
    )
    parser.add_argument("-V", "--version", action="version", version=f"warpcloth {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=Parser)
    for name, (_, help_line, quiet) in COMMANDS.items():
        p = sub.add_parser(name, help=help_line)
        if commands is None or name in commands:
            _module(name).add_arguments(p)
            add_verbose(p, quiet=quiet)
    return parser


def _chosen(argv: list) -> str | None:
    """The subcommand named in ``argv`` (the top level takes no option with a value: the first
    word that is not an option), or None."""
    word = next((a for a in argv if not a.startswith("-")), None)
    return word if word in COMMANDS else None


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    chosen = _chosen(argv)
    parser = build_parser(() if chosen is None else (chosen,))
    args = parser.parse_args(argv)
    args.argv = argv
    module = _module(args.command)
    hint = module.interrupted_hint(args) if hasattr(module, "interrupted_hint") else ""
    return guarded(args, lambda: module.run(args), hint)


__all__ = ["COMMANDS", "EXIT_USAGE", "build_parser", "main"]


if __name__ == "__main__":
    sys.exit(main())
