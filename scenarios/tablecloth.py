"""Tablecloth: a cloth falls onto a square table (an oriented box collider with friction) and
hangs over its edges; a run ends at equilibrium. Run it with ``warpcloth run tablecloth``.
"""

from warpcloth.scenarios.common import Scenario, ScenarioConfig

from warpcloth.sim.colliders import Box, Plane
from warpcloth.sim.control import Control

#: The table top: 0.8 m square, 0.75 m high (its top face), the cloth's offset [m] and mu.
HALF = 0.4
HEIGHT = 0.75
THICKNESS = 0.004
FRICTION = 0.5


def _pins(rows: int, cols: int) -> list:
    return []


def _control(config: ScenarioConfig, device: str) -> Control:
    drag = 1.0 if config.drag is None else config.drag
    table = Box(
        center=(0.0, 0.5 * HEIGHT, 0.0), half_extents=(HALF, 0.5 * HEIGHT, HALF), thickness=THICKNESS, friction=FRICTION
    )
    return Control(drag_rate=drag, colliders=(table, Plane(thickness=THICKNESS, friction=FRICTION)), device=device)


def _origin(config: ScenarioConfig) -> tuple:
    return (-0.5 * config.width, HEIGHT + 0.1, -0.5 * config.height)


SCENARIO = Scenario(
    name="tablecloth",
    description=(
        "a cloth falls on a square table (box collider, friction) and hangs over its edges; runs to equilibrium"
    ),
    defaults=ScenarioConfig(rows=24, cols=24, width=1.3, height=1.3, mass=0.3, duration=10.0),
    pins=_pins,
    control=_control,
    origin=_origin,
    stop_at_equilibrium=True,
    plane="horizontal",
    self_collision=True,
)


def build(**overrides):
    """A Simulator of the tablecloth with the defaults and ``overrides`` (see ScenarioConfig)."""
    return SCENARIO.build(**overrides)


if __name__ == "__main__":
    from warpcloth.cli import scenario_main

    scenario_main("tablecloth")
