"""Every registered integrator's ``step`` stays readable as its scheme (predict, iterate, finish): at most
``MAX_STEP_LINES`` source lines in its body, the docstring excluded (blank and comment lines inside count).
Options and contact details live in named methods and helpers (issue 47: ``VBD.step`` had grown to 71
lines with 10 branches, ``ImplicitEuler.step`` to 67)."""

from __future__ import annotations

import ast
import inspect
import textwrap

import pytest

from warpcloth.integrators import integrator_class, integrator_names

MAX_STEP_LINES = 35


def body_lines(function) -> int:
    """The source lines of ``function``'s body from its first statement after the docstring to its last line."""
    node = ast.parse(textwrap.dedent(inspect.getsource(function))).body[0]
    assert isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef), node
    body = node.body[1:] if ast.get_docstring(node) is not None and len(node.body) > 1 else node.body
    return node.end_lineno - body[0].lineno + 1


@pytest.mark.parametrize("name", integrator_names())
def test_step_reads_like_its_scheme(name):
    step = integrator_class(name).step
    lines = body_lines(step)
    assert lines <= MAX_STEP_LINES, (
        f"{name}: {step.__qualname__} has {lines} body lines (at most {MAX_STEP_LINES}); move options and contact "
        "handling into named methods or helpers"
    )


def long_step(self, state, control, dt):
    """A docstring that does not count.

    Nor its second line."""
    h = float(dt)
    # a comment line counts
    h += 1.0

    h += 2.0
    return h


def test_the_measure_counts_the_body_and_not_the_docstring():
    assert body_lines(long_step) == 6  # a step that grew past the cap would be seen
    assert body_lines(integrator_class("vbd").step) > 5
