"""``warpcloth list``: the scenarios, integrators and material presets, or (``--examples``) the examples shipped with
warpcloth: XML test lists, meshes, scenario files and example scripts, with their paths."""

from __future__ import annotations

import argparse
import os
import sys

from warpcloth import examples
from warpcloth.errors import WarpclothError
from warpcloth.examples.__main__ import example_files
from warpcloth.integrators import integrator_class, integrator_names
from warpcloth.scenarios import get_scenario, scenario_names
from warpcloth.sim.material import PRESETS


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--examples",
        action="store_true",
        help="list the examples shipped with warpcloth (test lists, meshes, scenario files, scripts) and their paths",
    )


def examples_dir() -> str:
    """The folder of the XML test lists shipped in the package (``warpcloth.examples``)."""
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
    print("materials (--material NAME; docs/materials.md):")
    for line in material_lines():
        print("  " + line)
    return 0


def material_lines() -> list[str]:
    """One line per material preset: density, stretch, shear, bending rigidity and length, source."""
    lines = []
    for name, m in PRESETS.items():
        stretch = (
            f"{m.stretch_warp:g}" if m.stretch_warp == m.stretch_weft else f"{m.stretch_warp:g}/{m.stretch_weft:g}"
        )
        bend = (
            f"{m.bend_warp * 1e6:.3g}"
            if m.bend_warp == m.bend_weft
            else f"{m.bend_warp * 1e6:.3g}/{m.bend_weft * 1e6:.3g}"
        )
        estimated = ", estimated" if m.estimated else ""
        cw, cf = (100 * m.bending_length(d) for d in ("warp", "weft"))
        length = f"{cw:.2f}" if m.bend_warp == m.bend_weft else f"{cw:.2f}/{cf:.2f}"
        lines.append(
            f"{name:16s} {1000 * m.density:.0f} g/m^2, stretch {stretch} N/m, shear {m.shear:g} N/m, "
            f"bending {bend} uN m (bending length {length} cm) [{m.source}{estimated}]"
        )
    return lines


__all__ = ["add_arguments", "example_names", "example_path", "examples_dir", "material_lines", "run"]
