"""Scenarios: data + a builder each (installed as ``warpcloth.scenarios``), in a registry.

Each built-in scenario module defines a :class:`~warpcloth.scenarios.common.Scenario` named
``SCENARIO`` and runs as ``warpcloth run <name>`` (or ``python -m warpcloth run <name>``). Users add
scenarios without touching this package: a TOML file (:mod:`warpcloth.scenarios.file`; pass its path
wherever a scenario name goes: ``warpcloth run my.toml``, ``scenarios="my.toml"`` in a sweep),
or a :class:`Scenario` object given to :func:`register` from Python.
"""

from __future__ import annotations

from warpcloth.errors import WarpclothError
from warpcloth.scenarios import (
    cantilever,
    character,
    curtain,
    cusick,
    drape,
    flag,
    fold,
    mesh,
    pair,
    sheet,
    swing,
    tablecloth,
)
from warpcloth.scenarios.common import Scenario, ScenarioConfig
from warpcloth.scenarios.file import is_scenario_file, load_scenario

#: The built-in scenarios by name, in the order ``warpcloth list`` shows them.
_BUILT_IN = {
    m.SCENARIO.name: m.SCENARIO
    for m in (sheet, flag, curtain, mesh, drape, tablecloth, fold, cantilever, cusick, swing, pair, character)
}
_REGISTERED: dict[str, Scenario] = {}


def scenario_names() -> list[str]:
    """Names of the built-in and registered scenarios (scenario files are not listed)."""
    return list(_BUILT_IN) + [n for n in _REGISTERED if n not in _BUILT_IN]


def register(scenario: Scenario) -> Scenario:
    """Add ``scenario`` to the registry under ``scenario.name`` (replacing a registered one of
    that name; a built-in name is refused)."""
    if not isinstance(scenario, Scenario):
        raise WarpclothError(f"register takes a Scenario, got {scenario!r}")
    if scenario.name in _BUILT_IN:
        raise WarpclothError(f"scenario name {scenario.name!r} is built in; choose another name")
    _REGISTERED[scenario.name] = scenario
    return scenario


def check_scenario(text: str) -> str:
    """``text`` if it names a scenario or a scenario file (.toml) that loads; else one line."""
    if text.lower().endswith(".toml"):
        get_scenario(text)
    elif text not in scenario_names():
        raise WarpclothError(
            f"unknown scenario {text!r}; choose from {', '.join(scenario_names())}, or a scenario file (.toml)"
        )
    return text


def get_scenario(name: str) -> Scenario:
    """The scenario called ``name``, or the one described by the TOML file at ``name``."""
    if is_scenario_file(name):
        return load_scenario(name)
    if name in _REGISTERED:
        return _REGISTERED[name]
    if name not in _BUILT_IN:
        raise WarpclothError(
            f"unknown scenario {name!r}; choose from {', '.join(scenario_names())}, or give a scenario file (.toml)"
        )
    return _BUILT_IN[name]


__all__ = ["Scenario", "ScenarioConfig", "check_scenario", "get_scenario", "register", "scenario_names"]
