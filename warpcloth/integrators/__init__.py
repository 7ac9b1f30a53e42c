"""Integrators behind one interface, chosen by name at run time.

Names are the same everywhere (CLI, CSV, XML, code). Integrators added by later modules
register themselves with :func:`register`.
"""

from __future__ import annotations

from contextlib import contextmanager

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


def unregister(name: str) -> type[Integrator]:
    """Remove the integrator registered under ``name`` and return its class (an unknown name is an error)."""
    cls = integrator_class(name)
    del _REGISTRY[name]
    return cls


@contextmanager
def registered(cls: type[Integrator]):
    """``cls`` registered for the ``with`` block, then removed (for a scheme tried out in a test or a
    notebook); yields ``cls``. A name already registered is an error: the block would replace it."""
    if cls.name in _REGISTRY:
        raise WarpclothError(f"integrator {cls.name!r} is already registered")
    register(cls)
    try:
        yield cls
    finally:
        unregister(cls.name)


for _cls in (ExplicitEuler, Midpoint, RK4, Verlet, ImplicitEuler, PBD, XPBD, VBD, Projective):
    register(_cls)


def integrator_names() -> list[str]:
    """Names of every registered integrator, in registration order."""
    return list(_REGISTRY)


def check_integrator_name(name, allow_all: bool = False, flag: str | None = None) -> str:
    """``name`` if an integrator is registered under it (or ``all``, every one, where ``allow_all``:
    a test list); else one line naming the value and the choices (``flag``: the CLI flag it came
    from, named when it is empty or ``all``). The one check of a name, where it enters (the
    ``integrator`` run parameter, the CLI's flags, a study's list, :func:`integrator_class`); what
    follows trusts it."""
    if isinstance(name, str) and (name in _REGISTRY or (allow_all and name == "all")):
        return name
    choices = ", ".join(_REGISTRY)
    if flag and name == "all":
        raise WarpclothError(f"{flag} all is for test lists (warpcloth sweep); choose one of {choices}")
    if flag and isinstance(name, str) and not name.strip():
        raise WarpclothError(f"{flag} is empty; choose one of {choices}")
    text = repr(name) if len(repr(name)) <= 60 else repr(name)[:57] + "..."
    raise WarpclothError(
        f"unknown integrator {text}; choose from {choices}" + (" (or 'all' in a test list)" if allow_all else "")
    )


def integrator_class(name: str) -> type[Integrator]:
    """The class registered under ``name`` (an unknown name: one line, :func:`check_integrator_name`)."""
    return _REGISTRY[check_integrator_name(name)]


def all_options() -> dict[str, tuple[Option, list[str]]]:
    """Every integrator option by name, with the integrators that take it (the first one's
    declaration; :func:`option_owners` gives each owner's own)."""
    out: dict[str, tuple[Option, list[str]]] = {}
    for name, cls in _REGISTRY.items():
        for opt in cls.options:
            out.setdefault(opt.name, (opt, []))[1].append(name)
    return out


def option_owners(option: str) -> dict[str, Option]:
    """Each registered integrator that takes ``option``, with its own declaration of it (schemes may
    share an option's name with different defaults: pbd's and xpbd's ``substeps``)."""
    return {name: o for name, cls in _REGISTRY.items() for o in cls.options if o.name == option}


def option_help(option: str) -> str:
    """The help line of the flag ``option`` becomes: one declaration's help with its owners and default,
    ``"... [pbd, xpbd; default 4]"``; where owners declare it differently, each owner's default,
    ``"... [pbd: 4, mine: 2]"``."""
    owners = option_owners(option)
    first = next(iter(owners.values()))
    if all(o == first for o in owners.values()):
        return f"{first.help} [{', '.join(owners)}; default {first.default}]"
    return f"{first.help} [{', '.join(f'{n}: {o.default}' for n, o in owners.items())}]"


def make_integrator(name: str, **options) -> Integrator:
    """A new integrator by name, with its options (unknown options are an error)."""
    return integrator_class(name)(**options)


__all__ = [
    "Integrator",
    "Option",
    "all_options",
    "check_integrator_name",
    "explicit_euler_dt_bound",
    "integrator_class",
    "integrator_names",
    "make_integrator",
    "option_help",
    "option_owners",
    "register",
    "registered",
    "stable_dt_estimate",
    "unregister",
]
