"""The package's layers (docs/architecture.md): one ordered list, every import of a warpcloth module
counted, at module level and inside functions (only ``if __name__ == "__main__":`` blocks are
exempt). An import goes to its own layer or a lower one; ``run`` and ``io`` (one rank) do not
import each other; nothing inside the package imports the package face; there is no circle."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
ROOTS = {"warpcloth": REPO / "warpcloth"}

#: Lowest first: (rank, layer, module prefixes). A layer imports its own rank or lower ranks;
#: two layers of one rank do not import each other.
LAYERS = [
    (0, "base", ("warpcloth.errors", "warpcloth.version")),
    (1, "kernels", ("warpcloth.kernels",)),
    (2, "sim", ("warpcloth.sim",)),
    (3, "integrators", ("warpcloth.integrators",)),
    (4, "simulator", ("warpcloth.simulator",)),
    (5, "run", ("warpcloth.run",)),
    (5, "io", ("warpcloth.io",)),
    (6, "scenarios", ("warpcloth.scenarios", "warpcloth.examples")),
    (7, "lab", ("warpcloth.lab",)),
    (8, "cli", ("warpcloth.cli", "warpcloth.__main__")),
]
#: The package face: ``warpcloth`` itself. Users import it; nothing inside the package does.
FACE = ("warpcloth",)

#: The optional extras (``warpcloth[plot]``, ``warpcloth[cluster]``): imported inside the
#: functions that use them, so that everything else works without them.
OPTIONAL = ("matplotlib", "ray")


def modules() -> dict[str, Path]:
    out = {}
    for package, folder in ROOTS.items():
        for path in folder.rglob("*.py"):
            rel = path.relative_to(folder).with_suffix("")
            parts = [p for p in rel.parts if p != "__init__"]
            out[".".join([package, *parts])] = path
    return out


def _is_main_block(node) -> bool:
    t = node.test if isinstance(node, ast.If) else None
    return (
        isinstance(t, ast.Compare)
        and isinstance(t.left, ast.Name)
        and t.left.id == "__name__"
        and any(isinstance(c, ast.Constant) and c.value == "__main__" for c in t.comparators)
    )


def _walk(nodes, top: bool):
    """(node, at_module_level) for every node, skipping ``if __name__ == "__main__":`` blocks."""
    for node in nodes:
        if _is_main_block(node):
            continue
        yield node, top
        inner_top = top and isinstance(node, (ast.If, ast.Try, ast.With))  # still runs at import
        yield from _walk(ast.iter_child_nodes(node), inner_top)


def imports(name: str, path: Path, known) -> list[tuple[str, bool, int]]:
    """(imported warpcloth module, at module level, line) for every import in ``path``."""
    tree = ast.parse(path.read_text())
    base = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
    found = []
    for node, top in _walk(tree.body, True):
        if isinstance(node, ast.Import):
            found += [(a.name, top, node.lineno) for a in node.names if a.name.startswith("warpcloth")]
        elif isinstance(node, ast.ImportFrom):
            mod = (
                ".".join(base[: len(base) - node.level + 1] + [node.module or ""]).strip(".")
                if node.level
                else node.module
            )
            if not (mod or "").startswith("warpcloth"):
                continue
            for a in node.names:  # a submodule imported by name is that module; a symbol is its module's
                found.append((f"{mod}.{a.name}" if f"{mod}.{a.name}" in known else mod, top, node.lineno))
    return found


def resolve(target: str, known) -> str | None:
    while target and target not in known:
        target = target.rpartition(".")[0]
    return target or None


def layer_of(module: str):
    if module in FACE:
        return None
    for rank, layer, prefixes in LAYERS:
        if any(module == p or module.startswith(p + ".") for p in prefixes):
            return rank, layer
    raise AssertionError(f"{module} is in no layer: put it in the folder of its layer (docs/architecture.md)")


def edges():
    mods = modules()
    out = []
    for m, path in mods.items():
        for target, top, line in imports(m, path, mods):
            t = resolve(target, mods)
            if t and t != m and not m.startswith(t + "."):  # a package's own __init__ runs first: not an edge
                out.append((m, t, top, line))
    return out


def test_every_module_is_in_a_layer():
    for m in modules():
        layer_of(m)


def test_imports_go_down_or_sideways_within_a_layer():
    bad = []
    for m, t, _, line in edges():
        if m in FACE:
            continue
        if t in FACE:
            bad.append(f"{m}:{line} imports the package face {t}")
            continue
        (rank_m, layer_m), (rank_t, layer_t) = layer_of(m), layer_of(t)
        if rank_t > rank_m or (rank_t == rank_m and layer_t != layer_m):
            bad.append(f"{m}:{line} ({layer_m}) imports {t} ({layer_t})")
    assert not bad, "\n".join(bad)


def test_no_import_circles():
    graph = {}
    for m, t, _, _ in edges():
        graph.setdefault(m, set()).add(t)
    seen, stack, cycles = set(), [], []

    def visit(m):
        if m in stack:
            cycles.append(stack[stack.index(m) :] + [m])
            return
        if m in seen:
            return
        seen.add(m)
        stack.append(m)
        for t in sorted(graph.get(m, ())):
            visit(t)
        stack.pop()

    for m in sorted(graph):
        visit(m)
    assert not cycles, cycles[:3]


def test_optional_libraries_are_imported_lazily():
    bad = []
    for m, path in modules().items():
        for node, top in _walk(ast.parse(path.read_text()).body, True):
            if top and isinstance(node, (ast.Import, ast.ImportFrom)):
                names = [a.name for a in node.names] if isinstance(node, ast.Import) else [node.module or ""]
                bad += [f"{m}:{node.lineno} imports {n} at module level" for n in names if n.split(".")[0] in OPTIONAL]
    assert not bad, "\n".join(bad)


def test_the_checker_sees_a_function_level_import_upward(tmp_path):
    """Negative control: an import inside a function that goes up a layer is found."""
    bad = tmp_path / "model.py"
    bad.write_text(
        "def f():\n    from warpcloth.lab import study\n\nif __name__ == '__main__':\n    from warpcloth import cli\n"
    )
    found = imports("warpcloth.sim.model", bad, modules())
    assert [(t, top) for t, top, _ in found] == [("warpcloth.lab.study", False)]


@pytest.mark.parametrize("entry", ["warpcloth.simulator", "warpcloth.run.harness"])
def test_stepping_loads_no_lab_cli_or_optional_library(entry):
    """Stepping and running load none of the lab, the CLI, SciPy, matplotlib, USD or Ray."""
    code = (
        f"import sys, warpcloth, {entry};"
        "bad = [m for m in sys.modules if m.startswith(('warpcloth.lab', 'warpcloth.cli', 'scipy', 'matplotlib', "
        "'pxr', 'ray'))];"
        "assert not bad, bad"
    )
    subprocess.run([sys.executable, "-c", code], check=True, cwd=REPO)


#: The only imports of warpcloth modules made inside functions, (module, function) -> why. Everything
#: else is imported at module level, where the import graph shows it: lazy only where
#: ``import warpcloth`` and the command line's top level (``warpcloth --version``) stay free of Warp.
#: Third-party optional libraries (OPTIONAL, pxr, SciPy) are not counted here.
LAZY_IMPORTS = {
    (
        "warpcloth",
        "__getattr__",
    ): "the package face loads a name's module on first use: `import warpcloth` imports no Warp",
    ("warpcloth.cli", "_module"): "the command line imports the chosen subcommand's module only (`--version` none)",
    (
        "warpcloth.cli.parse",
        "guarded",
    ): "Warp starts when a command runs, not when the parser is built (--version, --help)",
}
MAX_LAZY_IMPORTS = 10


def _is_dynamic_import(node) -> bool:
    f = node.func if isinstance(node, ast.Call) else None
    return (isinstance(f, ast.Attribute) and f.attr == "import_module") or (
        isinstance(f, ast.Name) and f.id in ("import_module", "__import__")
    )


def lazy_imports(path: Path) -> list[tuple[str, int]]:
    """(enclosing function, line) of every import of a warpcloth module inside a function of ``path``
    (relative imports included), and of every ``importlib.import_module`` / ``__import__`` call there:
    the module those load is chosen at run time, so they count whatever they name."""
    found = []

    def visit(nodes, function):
        for node in nodes:
            if _is_main_block(node):
                continue
            inner = node.name if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) else function
            if function is not None:
                if isinstance(node, ast.Import) and any(a.name.split(".")[0] == "warpcloth" for a in node.names):
                    found.append((function, node.lineno))
                elif isinstance(node, ast.ImportFrom) and (
                    node.level or (node.module or "").split(".")[0] == "warpcloth"
                ):
                    found.append((function, node.lineno))
                elif _is_dynamic_import(node):
                    found.append((function, node.lineno))
            visit(ast.iter_child_nodes(node), inner)

    visit(ast.parse(path.read_text()).body, None)
    return found


def test_warpcloth_modules_are_imported_inside_functions_only_where_listed():
    found = [(m, fn, line) for m, path in modules().items() for fn, line in lazy_imports(path)]
    unlisted = [f"{m}:{line} in {fn}()" for m, fn, line in found if (m, fn) not in LAZY_IMPORTS]
    assert not unlisted, "import these at module level (or list them in LAZY_IMPORTS, with why):\n" + "\n".join(
        unlisted
    )
    stale = set(LAZY_IMPORTS) - {(m, fn) for m, fn, _ in found}
    assert not stale, f"LAZY_IMPORTS lists imports that are gone: {sorted(stale)}"
    assert len(found) <= MAX_LAZY_IMPORTS, found


def test_the_lazy_import_count_sees_imports_in_nested_functions_and_import_module(tmp_path):
    """Negative control: a function-level import, a relative one, one in a nested function and an
    import_module call are counted; module-level imports, other libraries and __main__ blocks are not."""
    bad = tmp_path / "mod.py"
    bad.write_text(
        "import importlib\nfrom warpcloth.errors import WarpclothError\n\n"
        "def f():\n    import numpy\n    from warpcloth.sim import model\n    from . import grid\n\n"
        "class C:\n    def g(self):\n        def h():\n            import warpcloth.lab.study\n"
        "        return importlib.import_module('warpcloth.cli')\n\n"
        "if __name__ == '__main__':\n    def k():\n        from warpcloth import cli\n"
    )
    assert lazy_imports(bad) == [("f", 6), ("f", 7), ("h", 12), ("g", 13)]


def private_imports(name: str, path: Path, known) -> list[str]:
    """Private names (``_x``, not dunders) of another warpcloth module that ``path`` imports
    (``from warpcloth.m import _x``) or reads from a module it imported (``m._x``)."""
    tree = ast.parse(path.read_text())
    base = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
    found, aliases = [], {}
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            mod = (
                ".".join(base[: len(base) - node.level + 1] + [node.module or ""]).strip(".")
                if node.level
                else node.module
            )
            if (mod or "").split(".")[0] != "warpcloth":
                continue
            for a in node.names:
                if f"{mod}.{a.name}" in known:
                    aliases[a.asname or a.name] = f"{mod}.{a.name}"
                elif a.name.startswith("_") and not a.name.startswith("__"):
                    found.append(f"{name}:{node.lineno} imports {mod}.{a.name}")
        elif isinstance(node, ast.Import):
            aliases.update({a.asname: a.name for a in node.names if a.asname and a.name.split(".")[0] == "warpcloth"})
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id in aliases:
            if node.attr.startswith("_") and not node.attr.startswith("__") and aliases[node.value.id] != name:
                found.append(f"{name}:{node.lineno} uses {aliases[node.value.id]}.{node.attr}")
    return found


def test_no_private_name_is_imported_across_modules():
    mods = modules()
    bad = [line for m, path in mods.items() for line in private_imports(m, path, mods)]
    assert not bad, "make the name public where it is defined (a name other modules use is its API):\n" + "\n".join(bad)


def test_the_private_check_sees_an_imported_and_an_attribute_private_name(tmp_path):
    """Negative control: ``from warpcloth.sim.colliders import _x`` and ``bench._y`` are found;
    public names and dunders are not."""
    bad = tmp_path / "intersections.py"
    bad.write_text(
        "from warpcloth.sim.colliders import _x, Plane, __all__\nfrom warpcloth.lab import bench\n\n"
        "def f():\n    return bench._y(Plane), bench.run, bench.__name__\n"
    )
    assert private_imports("warpcloth.lab.intersections", bad, modules()) == [
        "warpcloth.lab.intersections:1 imports warpcloth.sim.colliders._x",
        "warpcloth.lab.intersections:5 uses warpcloth.lab.bench._y",
    ]


#: Kernel files of one scheme each; the other files of kernels/ hold what schemes share (springs,
#: linear algebra, multigrid, the implicit system, the increment solvers' vertex step, contacts,
#: pins, forces, metrics).
KERNEL_SCHEMES = ("implicit", "vbd", "projective", "constraints", "integrate", "strain_limit")


def cross_scheme_imports(edge_list, package: str, schemes) -> list[str]:
    """``package.<scheme>`` modules that import another ``package.<scheme>`` module."""
    names = {f"{package}.{s}" for s in schemes}
    found = (f"{m}:{line} imports {t}" for m, t, _, line in edge_list if m in names and t in names and t != m)
    return list(dict.fromkeys(found))


def test_kernel_scheme_files_import_only_shared_kernel_files():
    bad = cross_scheme_imports(edges(), "warpcloth.kernels", KERNEL_SCHEMES)
    assert not bad, "move what schemes share into a shared kernel file:\n" + "\n".join(bad)


def test_the_scheme_check_sees_a_kernel_scheme_importing_another(tmp_path):
    """Negative control: vbd borrowing implicit's function is found; a shared file is not."""
    bad = tmp_path / "vbd.py"
    bad.write_text(
        "from warpcloth.kernels.implicit import eval_rhs\nfrom warpcloth.kernels.springs import spring_force\n"
    )
    mods = modules()
    found = [
        ("warpcloth.kernels.vbd", resolve(t, mods), top, line)
        for t, top, line in imports("warpcloth.kernels.vbd", bad, mods)
    ]
    assert cross_scheme_imports(found, "warpcloth.kernels", KERNEL_SCHEMES) == [
        "warpcloth.kernels.vbd:1 imports warpcloth.kernels.implicit"
    ]


#: Integrator modules of one scheme each, with the kernel scheme files each may use; the other
#: modules of warpcloth/integrators/ hold what schemes share (base, forces, position_based,
#: increment, system, linalg, multigrid).
INTEGRATOR_SCHEMES = {
    "explicit_euler": "integrate",
    "midpoint": "integrate",
    "rk4": "integrate",
    "verlet": "integrate",
    "implicit_euler": "implicit",
    "pbd": "constraints",
    "xpbd": "constraints",
    "vbd": "vbd",
    "projective": "projective",
    "strain_limit": "strain_limit",
}


def test_integrator_schemes_import_only_shared_modules_and_their_own_kernels():
    bad = cross_scheme_imports(edges(), "warpcloth.integrators", INTEGRATOR_SCHEMES)
    for m, t, _, line in edges():
        scheme = m.removeprefix("warpcloth.integrators.")
        if scheme in INTEGRATOR_SCHEMES and t.removeprefix("warpcloth.kernels.") in KERNEL_SCHEMES:
            if t != f"warpcloth.kernels.{INTEGRATOR_SCHEMES[scheme]}":
                bad.append(f"{m}:{line} imports another scheme's kernels {t}")
    assert not bad, "move what schemes share into a shared module:\n" + "\n".join(bad)
