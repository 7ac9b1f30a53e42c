"""Sheet on a washing line (seed 4.1): top-left and top-right particles pinned, gravity only.

The sheet hangs in the vertical x-y plane and sags under its weight; a run ends at equilibrium
or at its duration. Run it with ``warpcloth run sheet [--integrator rk4 ...]``.
"""

from warpcloth.scenarios.common import Scenario, ScenarioConfig
from warpcloth.sim.control import Control


def _pins(rows: int, cols: int) -> list:
    return [0, cols - 1]


def _control(config: ScenarioConfig, device: str) -> Control:
    drag = 1.0 if config.drag is None else config.drag
    return Control(drag_rate=drag, device=device)


def _origin(config: ScenarioConfig) -> tuple:
    return (-0.5 * config.width, 2.0, 0.0)


SCENARIO = Scenario(
    name="sheet",
    description="a sheet hanging from a washing line by its top corners; gravity only; runs to equilibrium",
    defaults=ScenarioConfig(rows=32, cols=32, width=1.0, height=1.0, mass=0.2, duration=10.0),
    pins=_pins,
    control=_control,
    origin=_origin,
    stop_at_equilibrium=True,
)


def build(**overrides):
    """A Simulator of the sheet with the defaults and ``overrides`` (see ScenarioConfig)."""
    return SCENARIO.build(**overrides)
