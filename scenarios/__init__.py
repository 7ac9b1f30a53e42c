"""Scenarios: data + a builder each (installed as ``warpcloth.scenarios``).

Each scenario module defines a :class:`~warpcloth.scenarios.common.Scenario` named ``SCENARIO``
and is runnable as ``python -m warpcloth.scenarios.<name>``.
"""

from __future__ import annotations

from ..errors import WarpclothError
from .common import Scenario, ScenarioConfig

_NAMES = ("sheet", "flag")


def scenario_names() -> list[str]:
    return list(_NAMES)


def get_scenario(name: str) -> Scenario:
    """The scenario called ``name``."""
    if name not in _NAMES:
        raise WarpclothError(f"unknown scenario {name!r}; choose from {', '.join(_NAMES)}")
    import importlib

    return importlib.import_module(f"{__name__}.{name}").SCENARIO


__all__ = ["Scenario", "ScenarioConfig", "get_scenario", "scenario_names"]
