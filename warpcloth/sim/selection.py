"""Vertex selection: which vertices a pin list, a vertex group or a predicate names.

A predicate is a Python callable ``f(positions (N, 3)) -> bool mask`` (or indices) or a string
such as ``"y > 0.99 * y.max()"`` or ``"(abs(x) < 0.1) & (y > 1.4)"`` (:func:`parse_predicate`),
parsed with :mod:`ast` against a whitelist, never ``eval``-ed. :func:`resolve_pins` joins pins
given by index, by group name and by predicate (the builders' ``pins``, ``pin_groups`` and
``pin_where``).
"""

from __future__ import annotations

import ast
import math
import operator

import numpy as np

from warpcloth.errors import FLOAT32_MAX, WarpclothError, require

_ARITH = {
    ast.Add: operator.add,
    ast.Sub: operator.sub,
    ast.Mult: operator.mul,
    ast.Div: operator.truediv,
    ast.Pow: operator.pow,
    ast.Mod: operator.mod,
}
_LOGIC = {ast.BitAnd: np.logical_and, ast.BitOr: np.logical_or}
_CMPOPS = {
    ast.Lt: operator.lt,
    ast.LtE: operator.le,
    ast.Gt: operator.gt,
    ast.GtE: operator.ge,
    ast.Eq: operator.eq,
    ast.NotEq: operator.ne,
}
_REDUCTIONS = {"min": np.min, "max": np.max, "mean": np.mean}
_FUNCTIONS = {"abs": (np.abs, abs), "sqrt": (np.sqrt, math.sqrt)}
_NAMES = ("x", "y", "z")
#: The longest predicate read [characters] and its deepest expression tree (a predicate is one
#: line of conditions; longer ones are refused before they are parsed).
MAX_PREDICATE_CHARS = 1000
MAX_PREDICATE_DEPTH = 50
#: The largest |number| in a predicate, written or computed from numbers (float32's largest).
MAX_CONSTANT = FLOAT32_MAX
_ALLOWED = "x y z, numbers, + - * / ** %, comparisons, and or not & | ~, .min() .max() .mean(), abs(), sqrt()"


def _short(text: str, limit: int = 40) -> str:
    """``text`` quoted for a message, cut to ``limit`` characters."""
    return repr(text) if len(text) <= limit else repr(text[:limit]) + f"... ({len(text):,} characters)"


def _depth(tree) -> int:
    deepest, todo = 0, [(tree, 1)]
    while todo:
        node, d = todo.pop()
        deepest = max(deepest, d)
        if deepest > MAX_PREDICATE_DEPTH:
            break
        todo.extend((child, d + 1) for child in ast.iter_child_nodes(node))
    return deepest


def parse_predicate(text: str):
    """A vertex predicate from a string, e.g. ``"y > 0.99 * y.max()"`` or
    ``"(abs(x) < 0.1) & (y > 1.4)"``: a function positions (N, 3) -> bool mask (N,).

    Allowed: the names x, y, z (arrays of the rest coordinates [m]), numbers, + - * / ** %,
    comparisons (chains too), ``and``/``or``/``not`` and ``&``/``|``/``~`` (element-wise, on
    conditions), ``.min()``, ``.max()``, ``.mean()`` of x, y, z, and ``abs()``, ``sqrt()``. The
    whole must be a condition (a number, ``x`` or ``y.max()``, is refused). Numbers and what is
    computed from numbers alone are folded when parsed and must stay within float32's range
    (``1 / 0``, ``10 ** 400`` are refused); at most :data:`MAX_PREDICATE_CHARS` characters.
    Anything else is refused with a :class:`WarpclothError` of one short line; the string is
    parsed with :mod:`ast`, never ``eval``-ed.
    """
    require(
        isinstance(text, str) and text.strip() != "", f"pin predicate must be a non-empty expression, got {text!r:.80}"
    )
    shown = _short(text.strip())
    if len(text) > MAX_PREDICATE_CHARS:
        raise WarpclothError(f"pin predicate {shown} is longer than {MAX_PREDICATE_CHARS} characters")
    try:
        tree = ast.parse(text.strip(), mode="eval")
    except SyntaxError as exc:
        raise WarpclothError(f"pin predicate {shown} is not an expression: {str(exc.msg)[:80]}") from None
    except (ValueError, RecursionError, MemoryError) as exc:  # NUL characters, 4300+ digit integers, nesting
        raise WarpclothError(f"pin predicate {shown} cannot be read: {str(exc).split(';')[0][:80]}") from None
    if _depth(tree) > MAX_PREDICATE_DEPTH:
        raise WarpclothError(f"pin predicate {shown} is nested more than {MAX_PREDICATE_DEPTH} deep")

    def bad(node, what=None):
        return WarpclothError(
            f"pin predicate {shown}: {what or type(node).__name__} is not allowed (allowed: {_ALLOWED})"
        )

    def constant(value: float, node) -> float:
        part = ast.get_source_segment(text.strip(), node) or "a number"
        if isinstance(value, complex):
            raise WarpclothError(f"pin predicate {shown}: {_short(part, 30)} is not a real number")
        if not math.isfinite(value) or abs(value) > MAX_CONSTANT:
            raise WarpclothError(
                f"pin predicate {shown}: {_short(part, 30)} is out of range (|value| <= {MAX_CONSTANT:.3g})"
            )
        return float(value)

    # check: each node is a number ("num", its value when it is made of numbers alone) or a
    # condition ("bool"); numbers made of numbers alone are folded
    folded: dict = {}

    def check(node) -> str:
        if isinstance(node, ast.Expression):
            return check(node.body)
        if isinstance(node, ast.Constant):
            if isinstance(node.value, bool) or not isinstance(node.value, (int, float)):
                raise bad(node, f"the constant {_short(repr(node.value), 30)}")
            try:
                folded[node] = constant(float(node.value), node)
            except OverflowError:
                raise WarpclothError(
                    f"pin predicate {shown}: a number is out of range (|value| <= {MAX_CONSTANT:.3g})"
                ) from None
            return "num"
        if isinstance(node, ast.Name):
            if node.id not in _NAMES:
                raise bad(node, f"the name {_short(node.id, 30)}")
            return "num"
        if isinstance(node, ast.BinOp) and type(node.op) in _ARITH:
            if check(node.left) != "num" or check(node.right) != "num":
                raise bad(node, "arithmetic on a condition")
            if isinstance(node.op, (ast.Div, ast.Mod)) and folded.get(node.right) == 0.0:
                # x / 0 is infinite at every vertex (x / 0 > 1 would pin half the cloth); a divisor
                # that is zero only at some vertices (x / x) stays nan or inf there, as documented
                part = ast.get_source_segment(text.strip(), node) or "a division"
                raise WarpclothError(f"pin predicate {shown}: {_short(part, 30)} divides by zero")
            if node.left in folded and node.right in folded:
                try:
                    value = _ARITH[type(node.op)](folded[node.left], folded[node.right])
                except ZeroDivisionError:
                    part = ast.get_source_segment(text.strip(), node) or "a division"
                    raise WarpclothError(f"pin predicate {shown}: {_short(part, 30)} divides by zero") from None
                except OverflowError:
                    value = math.inf
                folded[node] = constant(value, node)
            return "num"
        if isinstance(node, ast.BinOp) and type(node.op) in _LOGIC:
            if check(node.left) != "bool" or check(node.right) != "bool":
                raise bad(node, "& or | of a number")
            return "bool"
        if isinstance(node, ast.UnaryOp):
            kind = check(node.operand)
            if isinstance(node.op, (ast.USub, ast.UAdd)):
                if kind != "num":
                    raise bad(node, "a sign on a condition")
                if node.operand in folded:
                    folded[node] = -folded[node.operand] if isinstance(node.op, ast.USub) else folded[node.operand]
                return "num"
            if isinstance(node.op, (ast.Not, ast.Invert)):
                if kind != "bool":
                    raise bad(node, "not or ~ of a number")
                return "bool"
            raise bad(node)
        if isinstance(node, ast.BoolOp):
            if any(check(v) != "bool" for v in node.values):
                raise bad(node, "and/or of a number")
            return "bool"
        if isinstance(node, ast.Compare):
            for op in node.ops:
                if type(op) not in _CMPOPS:
                    raise bad(op)
            if any(check(v) != "num" for v in [node.left, *node.comparators]):
                raise bad(node, "a comparison of a condition")
            return "bool"
        if isinstance(node, ast.Call) and not node.keywords:
            f = node.func
            if (
                isinstance(f, ast.Attribute)
                and isinstance(f.value, ast.Name)
                and f.value.id in _NAMES
                and f.attr in _REDUCTIONS
                and not node.args
            ):
                return "num"
            if isinstance(f, ast.Name) and f.id in _FUNCTIONS and len(node.args) == 1:
                if check(node.args[0]) != "num":
                    raise bad(node, f"{f.id}() of a condition")
                if node.args[0] in folded:
                    value = folded[node.args[0]]
                    if f.id == "sqrt" and value < 0:
                        raise WarpclothError(f"pin predicate {shown}: sqrt of a negative number")
                    folded[node] = constant(_FUNCTIONS[f.id][1](value), node)
                return "num"
            raise bad(node, "this call")
        raise bad(node)

    if check(tree) != "bool":
        raise WarpclothError(f"pin predicate {shown} is a number, not a condition such as 'y > 0.9 * y.max()'")

    def ev(node, env):
        if node in folded:
            return folded[node]
        if isinstance(node, ast.Expression):
            return ev(node.body, env)
        if isinstance(node, ast.Name):
            return env[node.id]
        if isinstance(node, ast.BinOp):
            op = _ARITH.get(type(node.op)) or _LOGIC[type(node.op)]
            return op(ev(node.left, env), ev(node.right, env))
        if isinstance(node, ast.UnaryOp):
            operand = ev(node.operand, env)
            return (
                -operand
                if isinstance(node.op, ast.USub)
                else +operand
                if isinstance(node.op, ast.UAdd)
                else np.logical_not(operand)
            )
        if isinstance(node, ast.BoolOp):
            f = np.logical_and if isinstance(node.op, ast.And) else np.logical_or
            out = ev(node.values[0], env)
            for val in node.values[1:]:
                out = f(out, ev(val, env))
            return out
        if isinstance(node, ast.Compare):
            left, out = ev(node.left, env), None
            for op, right_node in zip(node.ops, node.comparators):
                right = ev(right_node, env)
                r = _CMPOPS[type(op)](left, right)
                out = r if out is None else np.logical_and(out, r)
                left = right
            return out
        f = node.func  # a call, checked above
        if isinstance(f, ast.Attribute):
            return float(_REDUCTIONS[f.attr](env[f.value.id]))
        return _FUNCTIONS[f.id][0](ev(node.args[0], env))

    def predicate(positions):
        p = np.asarray(positions, dtype=np.float64)
        with np.errstate(all="ignore"):  # x / 0, sqrt(-1), overflow: inf and nan compare false, silently
            try:
                mask = ev(tree, {"x": p[:, 0], "y": p[:, 1], "z": p[:, 2]})
            except RecursionError:
                raise WarpclothError(f"pin predicate {shown} is nested too deeply") from None
        return np.broadcast_to(np.asarray(mask, dtype=bool), (p.shape[0],)).copy()

    predicate(np.zeros((1, 3)))  # evaluate the whole expression once
    predicate.text = text
    return predicate


def select_vertices(positions, where) -> np.ndarray:
    """Indices of the vertices for which ``where`` holds: a callable on the (N, 3) positions
    returning a bool mask (or integer indices), or a string predicate (:func:`parse_predicate`).
    A predicate that selects nothing is an error."""
    p = np.asarray(positions, dtype=np.float64)
    f = parse_predicate(where) if isinstance(where, str) else where
    require(callable(f), f"pin predicate must be a callable or a string expression, got {where!r:.80}")
    name = _short(getattr(f, "text", None) or getattr(f, "__name__", "the callable"))
    try:
        with np.errstate(all="ignore"):
            mask = np.asarray(f(p))
    except WarpclothError:
        raise
    except Exception as exc:
        raise WarpclothError(f"pin predicate {name} failed: {type(exc).__name__}: {str(exc)[:100]}") from None
    if mask.dtype == bool:
        require(
            mask.shape == (p.shape[0],),
            f"pin predicate must return one bool per vertex ({p.shape[0]}), got shape {mask.shape}",
        )
        idx = np.flatnonzero(mask)
    elif np.issubdtype(mask.dtype, np.integer):
        idx = np.unique(mask.astype(np.int64).ravel())
    else:
        raise WarpclothError(
            f"pin predicate {name} must return a bool mask or integer indices, got {mask.dtype} values"
        )
    require(idx.size > 0, f"pin predicate {name} selects no vertex (the mesh spans {_span(p)})")
    return idx


def _span(p: np.ndarray) -> str:
    lo, hi = p.min(axis=0), p.max(axis=0)
    return ", ".join(f"{n} in [{a:.4g}, {b:.4g}]" for n, a, b in zip("xyz", lo, hi))


def _indices(pins) -> np.ndarray:
    """Vertex indices as int64: integers (Python or NumPy) or integral floats; a fraction, a
    boolean, text or a non-finite number is refused (``1.5`` does not pin vertex 1)."""
    if isinstance(pins, (str, bytes)) or not hasattr(pins, "__iter__"):
        raise WarpclothError(f"pins must be a sequence of vertex indices (integers), got {pins!r:.80}")
    if isinstance(pins, np.ndarray) and np.issubdtype(pins.dtype, np.integer):
        return pins.astype(np.int64).reshape(-1)
    a = np.asarray(list(pins), dtype=object).reshape(-1)
    for v in a:
        ok = not isinstance(v, (bool, np.bool_)) and (
            isinstance(v, (int, np.integer))
            or (isinstance(v, (float, np.floating)) and math.isfinite(v) and float(v).is_integer())
        )
        if not ok:
            raise WarpclothError(f"pins must hold integer vertex indices, got {v!r:.40}")
    return a.astype(np.int64) if a.size else np.zeros(0, dtype=np.int64)


def resolve_pins(positions, pins=(), pin_groups=(), pin_where=None, groups=None) -> np.ndarray:
    """Union of pinned vertex indices given by index, by group name and by predicate."""
    n = np.asarray(positions).shape[0]
    groups = groups or {}
    out = [_indices(pins)]
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
