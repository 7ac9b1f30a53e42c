"""Text parsers of the run parameters that describe objects: a collider as the command line and
the test lists write it, ``kind:key=value,...``.

:func:`parse_collider_spec` parses and checks the text completely (kind, setting names, numbers,
the shape's own checks) but reads no file: a mesh collider's file is read once, when its
scenario builds the run (:meth:`ColliderSpec.collider` with the mesh reader of
:mod:`warpcloth.io.meshio`).
"""

from __future__ import annotations

import os
from dataclasses import dataclass

from warpcloth.errors import WarpclothError
from warpcloth.sim.colliders import COLLIDER_TYPES, MeshCollider

#: Settings of a mesh collider that are text, not numbers.
MESH_TEXT_FIELDS = ("path", "prim")


@dataclass(frozen=True)
class ColliderSpec:
    """A checked collider description: ``kind`` and its ``settings`` ((name, value), ...)."""

    kind: str
    settings: tuple
    text: str = ""

    def collider(self, load_mesh_collider=None):
        """The collider object. A mesh collider needs ``load_mesh_collider(path, prim, **settings)``
        (:func:`warpcloth.io.meshio.load_mesh_collider`), which reads its file."""
        settings = dict(self.settings)
        if self.kind != "mesh":
            return COLLIDER_TYPES[self.kind](**settings)
        if load_mesh_collider is None:
            raise WarpclothError(
                f"collider {self.text!r}: a mesh collider is read by a mesh loader (warpcloth.io.meshio)"
            )
        return load_mesh_collider(settings.pop("path"), settings.pop("prim", None), **settings)


def _split_outside_quotes(text: str, at) -> list[str]:
    """``text`` cut where ``at(text, k)`` holds for a character outside single or double quotes."""
    parts, start, quote = [], 0, None
    for k, ch in enumerate(text):
        if quote:
            quote = None if ch == quote else quote
        elif ch in "'\"":
            quote = ch
        elif at(text, k):
            parts.append(text[start:k])
            start = k + 1
    if quote:
        raise WarpclothError(f"collider {_short(text)} has an unclosed {quote} quote")
    parts.append(text[start:])
    return parts


def _unquote(value: str) -> str:
    v = value.strip()
    if len(v) >= 2 and v[0] == v[-1] and v[0] in "'\"":
        return v[1:-1]
    return v


def parse_collider_spec(text: str) -> ColliderSpec:
    """A collider from the CLI form ``kind:key=value,...`` (vectors as ``x/y/z``), e.g.
    ``sphere:center=0/1/0,radius=0.3,friction=0.4``, ``plane:normal=0/1/0,thickness=0.005`` or
    ``mesh:path=table.obj,thickness=0.005`` (``prim=/World/Table`` for a USD file). A value may be
    quoted (``path="a,b.obj"``); a setting given twice is refused."""
    if not isinstance(text, str):
        raise WarpclothError(f"a collider must be text KIND:K=V,..., got {text!r:.80}")
    kind, _, rest = text.partition(":")
    kind = kind.strip()
    cls = COLLIDER_TYPES.get(kind)
    if cls is None:
        raise WarpclothError(
            f"unknown collider kind {kind[:40]!r} in {_short(text)}; choose from {', '.join(COLLIDER_TYPES)}"
        )
    text_fields = set(MESH_TEXT_FIELDS) if cls is MeshCollider else set()
    fields = {
        f for f in cls.__dataclass_fields__ if f not in ("track", "vertices", "triangles", "source")
    } | text_fields
    kwargs = {}
    for item in filter(None, (p.strip() for p in _split_outside_quotes(rest, lambda s, k: s[k] == ","))):
        key, eq, value = item.partition("=")
        key = key.strip()
        if not eq or key not in fields:
            raise WarpclothError(
                f"collider {kind}: unknown or empty setting {item[:60]!r}; its settings are {', '.join(sorted(fields))}"
            )
        if key in kwargs:
            raise WarpclothError(f"collider {kind}: setting {key!r} is given twice in {_short(text)}")
        if key in text_fields:
            kwargs[key] = _unquote(value)
            continue
        parts = _unquote(value).split("/")
        try:
            numbers = [float(p) for p in parts]
        except ValueError:
            raise WarpclothError(
                f"collider {kind}: {key} must be numbers (x/y/z for vectors), got {value[:60]!r}"
            ) from None
        kwargs[key] = tuple(numbers) if len(numbers) > 1 else numbers[0]
    if cls is MeshCollider:
        if "path" not in kwargs:
            raise WarpclothError(f"collider mesh needs path=FILE (.obj or .usd), got {_short(text)}")
        path = os.path.expanduser(kwargs["path"])
        if not path:
            raise WarpclothError("collider mesh: path is empty; give path=FILE (.obj or .usd)")
        if not os.path.isfile(path):
            raise WarpclothError(
                f"mesh file {kwargs['path']!r} does not exist"
                if not os.path.exists(path)
                else f"mesh file {kwargs['path']!r} is not a regular file"
            )
        MeshCollider.check_settings(**{k: v for k, v in kwargs.items() if k not in text_fields})
    else:
        cls(**kwargs)  # the shape's own checks, now
    return ColliderSpec(kind=kind, settings=tuple(sorted(kwargs.items())), text=text.strip())


def _short(text: str, limit: int = 80) -> str:
    """``text`` quoted, cut to ``limit`` characters (messages stay one short line)."""
    return repr(text) if len(text) <= limit else repr(text[:limit]) + f"... ({len(text):,} characters)"


def _starts_collider(text: str, k: int) -> bool:
    """Whether the ``+`` at ``text[k]`` joins two colliders: the next collider's kind follows it
    (``+plane``, ``+sphere:...``), so the ``+`` of an exponent (``1e+3``) or inside a file name
    (``a+b.obj``) does not split."""
    if text[k] != "+":
        return False
    head = text[k + 1 :].lstrip()
    if not head or head[0] == "+":  # an empty collider: refused by the caller
        return True
    for kind in COLLIDER_TYPES:
        if head.startswith(kind):
            after = head[len(kind) :].lstrip()
            if after == "" or after[0] in ":+":
                return True
    return False


def collider_specs(text: str) -> tuple:
    """One or more colliders joined by ``+`` (``sphere:center=0/1/0,radius=0.3+plane``); a ``+``
    joins only where a collider kind follows it, so exponents (``radius=1e+3``) and file names
    with ``+`` stay whole (or repeat ``--collider``, or quote the value: ``path="a+plane"``)."""
    if not isinstance(text, str):
        raise WarpclothError(f"colliders must be text KIND:K=V,..., got {text!r:.80}")
    if not text.strip():
        raise WarpclothError("the collider is empty; give KIND:K=V,... (plane, sphere, capsule, box, mesh)")
    parts = _split_outside_quotes(text, _starts_collider)
    if any(not s.strip() for s in parts):
        raise WarpclothError(f"{_short(text)} has an empty collider; join colliders with single '+'")
    return tuple(parse_collider_spec(s) for s in parts)


__all__ = ["ColliderSpec", "collider_specs", "parse_collider_spec"]
