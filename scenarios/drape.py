"""Drape: a square cloth, held flat, falls onto a sphere resting on the ground and drapes over it
(colliders, :mod:`warpcloth.sim.colliders`); a run ends at equilibrium. Run it with
``python -m warpcloth.scenarios.drape`` or ``warpcloth run drape``.
"""

from warpcloth.scenarios.common import Scenario, ScenarioConfig

from warpcloth.sim.colliders import Plane, Sphere
from warpcloth.sim.control import Control

#: The sphere [m] (resting on the ground y = 0), the cloth's offset from surfaces [m] and mu.
RADIUS = 0.3
THICKNESS = 0.005
FRICTION = 0.4
DROP = 0.15  # m: the cloth starts this far above the sphere's top


def _pins(rows: int, cols: int) -> list:
    return []


def _control(config: ScenarioConfig, device: str) -> Control:
    drag = 1.0 if config.drag is None else config.drag
    colliders = (
        Sphere(center=(0.0, RADIUS, 0.0), radius=RADIUS, thickness=THICKNESS, friction=FRICTION),
        Plane(thickness=THICKNESS, friction=FRICTION),
    )
    return Control(drag_rate=drag, colliders=colliders, device=device)


def _origin(config: ScenarioConfig) -> tuple:
    return (-0.5 * config.width, 2.0 * RADIUS + DROP, -0.5 * config.height)


SCENARIO = Scenario(
    name="drape",
    description="a square cloth falls onto a sphere on the ground and drapes over it (colliders); runs to equilibrium",
    defaults=ScenarioConfig(rows=24, cols=24, width=1.0, height=1.0, mass=0.2, duration=10.0),
    pins=_pins,
    control=_control,
    origin=_origin,
    stop_at_equilibrium=True,
    plane="horizontal",
    self_collision=True,
)


def build(**overrides):
    """A Simulator of the drape with the defaults and ``overrides`` (see ScenarioConfig)."""
    return SCENARIO.build(**overrides)


if __name__ == "__main__":
    from warpcloth.cli import scenario_main

    scenario_main("drape")
