"""``warpcloth list``: the scenarios and integrators, or (``--examples``) the examples shipped with
warpcloth: XML test lists, meshes, scenario files and example scripts, with their paths."""

from __future__ import annotations

import argparse
import os
import sys

from warpcloth.errors import WarpclothError


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--examples",
        action="store_true",
        help="list the examples shipped with warpcloth (test lists, meshes, scenario files, scripts) and their paths",
    )


def examples_dir() -> str:
    """The folder of the XML test lists shipped in the package (``warpcloth.examples``)."""
    from warpcloth import examples

    return os.path.dirname(os.path.abspath(examples.__file__))


def example_names() -> list[str]:
    return sorted(os.path.splitext(n)[0] for n in os.listdir(examples_dir()) if n.endswith(".xml"))


def example_path(name: str) -> str:
    names = example_names()
    if name not in names:
        raise WarpclothError(
            f"no example test list {name!r}; the examples are {', '.join(names)} ('warpcloth list --examples')"
        )
    return os.path.join(examples_dir(), name + ".xml")


def _print_examples() -> None:
    from warpcloth.examples.__main__ import example_files

    for kind, path in example_files():
        name = os.path.splitext(os.path.basename(path))[0]
        print(f"{kind + ':':15s}{name:12s} {path}")
    scripts = sorted(
        os.path.splitext(n)[0] for n in os.listdir(examples_dir()) if n.endswith(".py") and not n.startswith("_")
    )
    for name in scripts:
        print(f"{'script:':15s}{name:12s} python -m warpcloth.examples.{name}")
    print("(python -m warpcloth.examples [DIR] copies the files into DIR, default ./examples)")


def run(args) -> int:
    from warpcloth.integrators import integrator_class, integrator_names
    from warpcloth.scenarios import get_scenario, scenario_names

    if getattr(args, "examples", False):
        if not args.quiet:
            _print_examples()
        return 0
    if args.quiet:
        return 0
    print("scenarios:")
    for name in scenario_names():
        print(f"  {name:16s} {get_scenario(name).description}")
    print("integrators:")
    for name in integrator_names():
        doc = (
            (integrator_class(name).__doc__ or sys.modules[integrator_class(name).__module__].__doc__ or "")
            .strip()
            .splitlines()
        )
        print(f"  {name:16s} {doc[0] if doc else ''}")
    return 0


__all__ = ["add_arguments", "example_names", "example_path", "examples_dir", "run"]
