"""Module docstrings say what a module is and why (equation, units, one line of reason, a link to
docs/); measured histories belong in docs/, beside the command that reproduces them (issue 47).

The cap is 25 lines (from the opening to the closing quotes): the longest docstrings that only say
what and why (vbd's iteration box, the bending kernel's angle and gradient formulas, the list of
collider responses) need 23-25 lines, while every docstring that ran longer carried a measurement
history or a reference page that docs/ now holds.
"""

import ast
import re
from pathlib import Path

PACKAGE = Path(__file__).resolve().parent.parent / "warpcloth"
MAX_MODULE_DOCSTRING_LINES = 25

# Cheap signs of a measured history. Each pattern avoids what equations and units look like
# ("[m/s]", "h^2 ks / m", "10 %" as a setting): a number of milliseconds, a signed percentage,
# a percentage "off", and the phrases a lab notebook uses.
HISTORY_PATTERNS = {
    "a time in milliseconds": r"\d\s*ms\b",
    "a signed percentage": r"(?<![\w)\]])[+\-\u2212]\d+(\.\d+)?\s*%",
    "a percentage off": r"%\s+off\b",
    "a cited bench output": r"bench/results/",
    "'measured on/at'": r"\bmeasured (on|at)\b",
    "a one-off run": r"\b(loaded|profiling) run\b",
    "the research branch": r"\bresearch branch\b",
    "a failure story": r"\b(went unstable at|blew up)\b",
    "a tried variant": r"\b(tried on|not kept)\b",
    "a speed-up figure": r"\d\s*(x|\u00d7|times) (faster|slower|as long)\b",
    "an issue's story": r"\bissue \d+",
}


def module_docstrings():
    """(path relative to the repository, first line, last line, text) of every module docstring."""
    for path in sorted(PACKAGE.rglob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        if ast.get_docstring(tree, clean=False) is None:
            continue
        node = tree.body[0]
        yield path.relative_to(PACKAGE.parent), node.lineno, node.end_lineno, ast.get_docstring(tree, clean=False)


def test_every_module_docstring_is_found():
    found = {str(path) for path, *_ in module_docstrings()}
    # the package face, a kernel module, an integrator and a scenario: the walk covers every subfolder
    for expected in (
        "warpcloth/__init__.py",
        "warpcloth/kernels/vbd.py",
        "warpcloth/integrators/vbd.py",
        "warpcloth/scenarios/file.py",
        "warpcloth/examples/drive.py",
    ):
        assert expected in found


def test_module_docstrings_are_short():
    too_long = [
        f"{path}: {last - first + 1} lines"
        for path, first, last, _ in module_docstrings()
        if last - first + 1 > MAX_MODULE_DOCSTRING_LINES
    ]
    assert not too_long, (
        f"module docstrings over {MAX_MODULE_DOCSTRING_LINES} lines (move the details to docs/): {too_long}"
    )


def test_module_docstrings_carry_no_measured_history():
    found = []
    for path, first, _, text in module_docstrings():
        for offset, line in enumerate(text.splitlines()):
            for what, pattern in HISTORY_PATTERNS.items():
                if re.search(pattern, line, flags=re.IGNORECASE):
                    found.append(f"{path}:{first + offset}: {what}: {line.strip()}")
    assert not found, "measured histories belong in docs/ (beside their command):\n" + "\n".join(found)


def test_history_patterns_catch_what_they_name():
    # the kinds of line that module docstrings carried before issue 47, and lines they must let pass
    caught = [
        "after 10 s with 20 sweeps per step the sheet was still -68 % off the equilibrium's sag",
        "check every iteration (Jacobi at 32^2: 48 ms/step before, 18.5 after, one loaded run)",
        "40 x 4 -29 %; 32 x 32: 10 x 4 +431 %, 10 x 8 +36 %",
        "Measured on the 16 x 16 and 32 x 32 sheets at dt = 1/60 s with 10 iterations",
        "(``python bench/coloring.py``, bench/results/coloring.txt)",
        "MCS on the springs' line graph took 3.6 times as long at 54,000 springs",
        "pushed a landed vertex 1 cm out, and the run went unstable at 0.18 s",
    ]
    passed = [
        "c = 2 omega_1 (omega_1 = 3.516 sqrt(B / (rho L^4))) brings it to rest",
        '``color="strain"``: from blue (0) to red (``strain_scale``, default 10 %)',
        "dy = h v + h^2 f_ext / m ;  dx = h v     (-C - alpha~ lambda) / (w_i + w_j)",
        "the groups it is measured in (:func:`plan_groups`); a measured bending length c [m]",
        "ms/step over ``timing_windows`` windows after a warm-up (compile)",
    ]

    def flagged(line):
        return any(re.search(p, line, flags=re.IGNORECASE) for p in HISTORY_PATTERNS.values())

    assert all(flagged(line) for line in caught)
    assert not any(flagged(line) for line in passed)
