"""The package's layers: the physics does not import the harness's outputs, the CLI or the
lab; the lab sits above everything; no module imports itself round a circle."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
ROOTS = {"warpcloth": REPO / "warpcloth", "warpcloth.kernels": REPO / "kernels", "warpcloth.scenarios": REPO / "scenarios"}

#: The physics: what a Simulator needs to step. It may import nothing above it.
PHYSICS = ["warpcloth.model", "warpcloth.state", "warpcloth.forces", "warpcloth.colliders", "warpcloth.metrics",
           "warpcloth.strain_limit", "warpcloth.coloring", "warpcloth.mesh", "warpcloth.meshio", "warpcloth.pins",
           "warpcloth.device", "warpcloth.errors", "warpcloth.integrators", "warpcloth.kernels"]
ABOVE_PHYSICS = ("warpcloth.lab", "warpcloth.cli", "warpcloth.cliparse", "warpcloth.params", "warpcloth.usd",
                 "warpcloth.player", "warpcloth.preview", "warpcloth.frames", "warpcloth.scenarios", "warpcloth.progress")


def modules():
    out = {}
    for package, folder in ROOTS.items():
        for path in folder.rglob("*.py"):
            rel = path.relative_to(folder).with_suffix("")
            parts = [p for p in rel.parts if p != "__init__"]
            name = ".".join([package, *parts])
            if package == "warpcloth" and parts and parts[0] in ("kernels", "scenarios"):
                continue
            out[name] = path
    return out


def imports(name: str, path: Path, top_level_only: bool) -> set[str]:
    tree = ast.parse(path.read_text())
    is_pkg = path.name == "__init__.py"
    base = name.split(".") if is_pkg else name.split(".")[:-1]
    nodes = tree.body if top_level_only else list(ast.walk(tree))
    found = set()
    for node in nodes:
        if isinstance(node, ast.Import):
            found |= {a.name for a in node.names if a.name.startswith("warpcloth")}
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                mod = ".".join(base[: len(base) - node.level + 1] + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            if mod.startswith("warpcloth"):
                found.add(mod)
                found |= {f"{mod}.{a.name}" for a in node.names}
    return found


def resolve(target: str, known) -> str | None:
    while target and target not in known:
        target = target.rpartition(".")[0]
    return target or None


def graph(top_level_only: bool):
    mods = modules()
    return {m: {t for t in (resolve(i, mods) for i in imports(m, p, top_level_only)) if t and t != m} for m, p in mods.items()}


def test_the_physics_imports_nothing_above_it():
    g = graph(top_level_only=False)  # function-level imports count too
    for m, targets in g.items():
        if any(m == p or m.startswith(p + ".") for p in PHYSICS):
            bad = {t for t in targets if t.startswith(ABOVE_PHYSICS)}
            assert not bad, f"{m} imports {sorted(bad)}"


def test_only_the_cli_imports_the_lab():
    g = graph(top_level_only=False)
    for m, targets in g.items():
        if m.startswith("warpcloth.lab") or m == "warpcloth.cli":
            continue
        bad = {t for t in targets if t.startswith("warpcloth.lab")}
        assert not bad, f"{m} imports {sorted(bad)}"
        if m.startswith("warpcloth.lab"):
            assert "warpcloth.cli" not in targets


def test_no_import_circles_at_module_level():
    g = graph(top_level_only=True)
    seen, stack, cycles = set(), [], []

    def visit(m):
        if m in stack:
            cycles.append(stack[stack.index(m):] + [m])
            return
        if m in seen:
            return
        seen.add(m)
        stack.append(m)
        for t in sorted(g.get(m, ())):
            # importing a package's submodule runs the package first: not a circle of its own
            if not m.startswith(t + "."):
                visit(t)
        stack.pop()

    for m in sorted(g):
        visit(m)
    assert not cycles, cycles[:3]


def test_stepping_loads_no_lab_cli_or_scipy():
    code = ("import sys, warpcloth, warpcloth.simulator, warpcloth.harness;"
            "bad = [m for m in sys.modules if m.startswith(('warpcloth.lab', 'warpcloth.cli', 'scipy', 'matplotlib', 'pxr'))];"
            "assert not bad, bad")
    subprocess.run([sys.executable, "-c", code], check=True, cwd=REPO)
