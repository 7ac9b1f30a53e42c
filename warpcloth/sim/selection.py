"""Vertex selection: which vertices a pin list, a vertex group or a predicate names.

A predicate is a Python callable ``f(positions (N, 3)) -> bool mask`` (or indices) or a string
such as ``"y > 0.99 * y.max()"`` or ``"(abs(x) < 0.1) & (y > 1.4)"`` (:func:`parse_predicate`),
parsed with :mod:`ast` against a whitelist, never ``eval``-ed. :func:`resolve_pins` joins pins
given by index, by group name and by predicate (the builders' ``pins``, ``pin_groups`` and
``pin_where``).
"""

from __future__ import annotations

import ast
import operator

import numpy as np

from warpcloth.errors import WarpclothError, require

_BINOPS = {ast.Add: operator.add, ast.Sub: operator.sub, ast.Mult: operator.mul, ast.Div: operator.truediv,
           ast.Pow: operator.pow, ast.Mod: operator.mod, ast.BitAnd: np.logical_and, ast.BitOr: np.logical_or}
_CMPOPS = {ast.Lt: operator.lt, ast.LtE: operator.le, ast.Gt: operator.gt, ast.GtE: operator.ge, ast.Eq: operator.eq, ast.NotEq: operator.ne}
_REDUCTIONS = {"min": np.min, "max": np.max, "mean": np.mean}
_FUNCTIONS = {"abs": np.abs, "sqrt": np.sqrt}
_NAMES = ("x", "y", "z")


def parse_predicate(text: str):
    """A vertex predicate from a string, e.g. ``"y > 0.99 * y.max()"`` or
    ``"(abs(x) < 0.1) & (y > 1.4)"``: a function positions (N, 3) -> bool mask (N,).

    Allowed: the names x, y, z (arrays of the rest coordinates [m]), numbers, + - * / ** %,
    comparisons (chains too), ``and``/``or``/``not`` and ``&``/``|``/``~`` (element-wise),
    ``.min()``, ``.max()``, ``.mean()`` of x, y, z, and ``abs()``, ``sqrt()``. Anything else is
    refused with a :class:`WarpclothError`; the string is parsed with :mod:`ast`, never ``eval``-ed.
    """
    require(isinstance(text, str) and text.strip() != "", f"pin predicate must be a non-empty expression, got {text!r}")
    try:
        tree = ast.parse(text.strip(), mode="eval")
    except SyntaxError as exc:
        raise WarpclothError(f"pin predicate {text!r} is not an expression: {exc.msg}") from None

    def bad(node, what=None):
        return WarpclothError(
            f"pin predicate {text!r}: {what or type(node).__name__} is not allowed "
            f"(use x, y, z, numbers, arithmetic, comparisons, and/or/not, &, |, ~, .min() .max() .mean(), abs(), sqrt())"
        )

    def ev(node, env):
        if isinstance(node, ast.Expression):
            return ev(node.body, env)
        if isinstance(node, ast.Constant):
            if isinstance(node.value, bool) or not isinstance(node.value, (int, float)):
                raise bad(node, f"the constant {node.value!r}")
            return float(node.value)
        if isinstance(node, ast.Name):
            if node.id not in _NAMES:
                raise bad(node, f"the name {node.id!r}")
            return env[node.id]
        if isinstance(node, ast.BinOp) and type(node.op) in _BINOPS:
            return _BINOPS[type(node.op)](ev(node.left, env), ev(node.right, env))
        if isinstance(node, ast.UnaryOp):
            operand = ev(node.operand, env)
            if isinstance(node.op, ast.USub):
                return -operand
            if isinstance(node.op, ast.UAdd):
                return +operand
            if isinstance(node.op, (ast.Not, ast.Invert)):
                return np.logical_not(operand)
            raise bad(node)
        if isinstance(node, ast.BoolOp):
            values = [ev(x, env) for x in node.values]
            f = np.logical_and if isinstance(node.op, ast.And) else np.logical_or
            out = values[0]
            for val in values[1:]:
                out = f(out, val)
            return out
        if isinstance(node, ast.Compare):
            left = ev(node.left, env)
            out = None
            for op, right_node in zip(node.ops, node.comparators):
                if type(op) not in _CMPOPS:
                    raise bad(op)
                right = ev(right_node, env)
                r = _CMPOPS[type(op)](left, right)
                out = r if out is None else np.logical_and(out, r)
                left = right
            return out
        if isinstance(node, ast.Call) and not node.keywords:
            f = node.func
            if isinstance(f, ast.Attribute) and isinstance(f.value, ast.Name) and f.value.id in _NAMES and f.attr in _REDUCTIONS and not node.args:
                return float(_REDUCTIONS[f.attr](env[f.value.id]))
            if isinstance(f, ast.Name) and f.id in _FUNCTIONS and len(node.args) == 1:
                return _FUNCTIONS[f.id](ev(node.args[0], env))
            raise bad(node, "this call")
        raise bad(node)

    ev(tree, {k: np.zeros(1) for k in _NAMES})  # validate the whole expression once

    def predicate(positions):
        p = np.asarray(positions, dtype=np.float64)
        return ev(tree, {"x": p[:, 0], "y": p[:, 1], "z": p[:, 2]})

    predicate.text = text
    return predicate


def select_vertices(positions, where) -> np.ndarray:
    """Indices of the vertices for which ``where`` holds: a callable on the (N, 3) positions
    returning a bool mask (or indices), or a string predicate (:func:`parse_predicate`).
    A predicate that selects nothing is an error."""
    p = np.asarray(positions, dtype=np.float64)
    f = parse_predicate(where) if isinstance(where, str) else where
    require(callable(f), f"pin predicate must be a callable or a string expression, got {where!r}")
    try:
        mask = np.asarray(f(p))
    except WarpclothError:
        raise
    except Exception as exc:
        raise WarpclothError(f"pin predicate {getattr(f, 'text', f)!r} failed: {exc}") from None
    if mask.dtype == bool:
        require(mask.shape == (p.shape[0],), f"pin predicate must return one bool per vertex ({p.shape[0]}), got shape {mask.shape}")
        idx = np.flatnonzero(mask)
    else:
        idx = np.unique(mask.astype(np.int64).ravel())
    require(idx.size > 0, f"pin predicate {getattr(f, 'text', where)!r} selects no vertex (the mesh spans {_span(p)})")
    return idx


def _span(p: np.ndarray) -> str:
    lo, hi = p.min(axis=0), p.max(axis=0)
    return ", ".join(f"{n} in [{a:.4g}, {b:.4g}]" for n, a, b in zip("xyz", lo, hi))


def resolve_pins(positions, pins=(), pin_groups=(), pin_where=None, groups=None) -> np.ndarray:
    """Union of pinned vertex indices given by index, by group name and by predicate."""
    n = np.asarray(positions).shape[0]
    groups = groups or {}
    out = [np.asarray(list(pins), dtype=np.int64).reshape(-1)]
    if isinstance(pin_groups, str):
        pin_groups = [pin_groups]
    for name in pin_groups:
        if name not in groups:
            have = ", ".join(sorted(groups)) or "none"
            raise WarpclothError(f"pin group {name!r} does not exist in the mesh (its vertex groups: {have})")
        out.append(np.asarray(groups[name], dtype=np.int64))
    if pin_where is not None:
        out.append(select_vertices(positions, pin_where))
    idx = np.unique(np.concatenate(out))
    bad = idx[(idx < 0) | (idx >= n)]
    if bad.size:
        raise WarpclothError(f"pin index {int(bad[0])} is out of range: vertices are 0..{n - 1}")
    return idx


__all__ = ["parse_predicate", "resolve_pins", "select_vertices"]
