"""Integrators behind one interface, chosen by name at run time.

Names are the same everywhere (CLI, CSV, XML, code). Integrators added by later modules
register themselves with :func:`register`.
"""

from __future__ import annotations

from warpcloth.errors import WarpclothError
from warpcloth.integrators.base import Integrator, Option, explicit_euler_dt_bound, stable_dt_estimate
from warpcloth.integrators.explicit_euler import ExplicitEuler
from warpcloth.integrators.implicit_euler import ImplicitEuler
from warpcloth.integrators.midpoint import Midpoint
from warpcloth.integrators.pbd import PBD
from warpcloth.integrators.projective import Projective
from warpcloth.integrators.rk4 import RK4
from warpcloth.integrators.vbd import VBD
from warpcloth.integrators.verlet import Verlet
from warpcloth.integrators.xpbd import XPBD

_REGISTRY: dict[str, type[Integrator]] = {}


def register(cls: type[Integrator]) -> type[Integrator]:
    """Register an integrator class under ``cls.name``."""
    _REGISTRY[cls.name] = cls
    return cls


for _cls in (ExplicitEuler, Midpoint, RK4, Verlet, ImplicitEuler, PBD, XPBD, VBD, Projective):
    register(_cls)


def integrator_names() -> list[str]:
    """Names of every registered integrator, in registration order."""
    return list(_REGISTRY)


def integrator_class(name: str) -> type[Integrator]:
    try:
        return _REGISTRY[name]
    except KeyError:
        raise WarpclothError(f"unknown integrator {name!r}; choose from {', '.join(_REGISTRY)}") from None


def all_options() -> dict[str, tuple[Option, list[str]]]:
    """Every integrator option by name, with the integrators that take it."""
    out: dict[str, tuple[Option, list[str]]] = {}
    for name, cls in _REGISTRY.items():
        for opt in cls.options:
            out.setdefault(opt.name, (opt, []))[1].append(name)
    return out


def make_integrator(name: str, **options) -> Integrator:
    """A new integrator by name, with its options (unknown options are an error)."""
    return integrator_class(name)(**options)


__all__ = [
    "Integrator",
    "Option",
    "all_options",
    "explicit_euler_dt_bound",
    "stable_dt_estimate",
    "integrator_class",
    "integrator_names",
    "make_integrator",
    "register",
]
