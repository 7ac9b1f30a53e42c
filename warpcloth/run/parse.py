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
            raise WarpclothError(f"collider {self.text!r}: a mesh collider is read by a mesh loader (warpcloth.io.meshio)")
        return load_mesh_collider(settings.pop("path"), settings.pop("prim", None), **settings)


def parse_collider_spec(text: str) -> ColliderSpec:
    """A collider from the CLI form ``kind:key=value,...`` (vectors as ``x/y/z``), e.g.
    ``sphere:center=0/1/0,radius=0.3,friction=0.4``, ``plane:normal=0/1/0,thickness=0.005`` or
    ``mesh:path=table.obj,thickness=0.005`` (``prim=/World/Table`` for a USD file)."""
    kind, _, rest = text.partition(":")
    kind = kind.strip()
    cls = COLLIDER_TYPES.get(kind)
    if cls is None:
        raise WarpclothError(f"unknown collider kind {kind!r} in {text!r}; choose from {', '.join(COLLIDER_TYPES)}")
    text_fields = set(MESH_TEXT_FIELDS) if cls is MeshCollider else set()
    fields = {f for f in cls.__dataclass_fields__ if f not in ("track", "vertices", "triangles", "source")} | text_fields
    kwargs = {}
    for item in filter(None, (p.strip() for p in rest.split(","))):
        key, eq, value = item.partition("=")
        key = key.strip()
        if not eq or key not in fields:
            raise WarpclothError(f"collider {kind}: unknown or empty setting {item!r}; its settings are {', '.join(sorted(fields))}")
        if key in text_fields:
            kwargs[key] = value.strip()
            continue
        parts = value.split("/")
        try:
            numbers = [float(p) for p in parts]
        except ValueError:
            raise WarpclothError(f"collider {kind}: {key} must be numbers (x/y/z for vectors), got {value!r}") from None
        kwargs[key] = tuple(numbers) if len(numbers) > 1 else numbers[0]
    if cls is MeshCollider:
        if "path" not in kwargs:
            raise WarpclothError(f"collider mesh needs path=FILE (.obj or .usd), got {text!r}")
        path = os.path.expanduser(kwargs["path"])
        if not os.path.isfile(path):
            raise WarpclothError(f"mesh file {kwargs['path']!r} does not exist" if not os.path.exists(path)
                                 else f"mesh file {kwargs['path']!r} is not a regular file")
        MeshCollider.check_settings(**{k: v for k, v in kwargs.items() if k not in text_fields})
    else:
        cls(**kwargs)  # the shape's own checks, now
    return ColliderSpec(kind=kind, settings=tuple(sorted(kwargs.items())), text=text.strip())


def collider_specs(text: str) -> tuple:
    """One or more colliders joined by ``+`` (``sphere:center=0/1/0,radius=0.3+plane``)."""
    parts = text.split("+")
    if any(not s.strip() for s in parts):
        raise WarpclothError(f"{text!r} has an empty collider; join colliders with single '+'")
    return tuple(parse_collider_spec(s) for s in parts)


__all__ = ["ColliderSpec", "collider_specs", "parse_collider_spec"]
