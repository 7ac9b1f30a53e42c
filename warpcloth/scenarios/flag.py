"""Flag in gusting wind (seed 4.1): the left edge pinned to a pole, gravity plus wind gusts
switched on and off at pre-determined times. It never reaches equilibrium.

Run it with ``warpcloth run flag [--integrator verlet ...]``.
"""

from warpcloth.scenarios.common import Scenario, ScenarioConfig
from warpcloth.sim.control import Control, WindSchedule

#: Gust wind velocity [m/s], and the calmer wind between gusts.
GUST = (8.0, 0.0, 3.0)
LULL = (2.0, 0.0, -1.0)
GUST_ON, GUST_OFF = 1.5, 1.0  # s
WIND_COEFFICIENT = 0.6  # kg/(m^2 s): about rho_air * 1/2


def _pins(rows: int, cols: int) -> list:
    return [r * cols for r in range(rows)]


def _control(config: ScenarioConfig, device: str) -> Control:
    drag = 0.0 if config.drag is None else config.drag
    return Control(
        drag_rate=drag,
        wind_coefficient=WIND_COEFFICIENT,
        wind_schedule=WindSchedule.gusts(GUST, GUST_ON, GUST_OFF, base=LULL),
        device=device,
    )


def _origin(config: ScenarioConfig) -> tuple:
    return (0.0, 2.0, 0.0)


SCENARIO = Scenario(
    name="flag",
    description="a flag pinned along its left edge, in wind gusting on and off; never at rest",
    defaults=ScenarioConfig(rows=20, cols=30, width=1.5, height=1.0, mass=0.3, duration=10.0),
    pins=_pins,
    control=_control,
    origin=_origin,
    stop_at_equilibrium=False,
)


def build(**overrides):
    """A Simulator of the flag with the defaults and ``overrides`` (see ScenarioConfig)."""
    return SCENARIO.build(**overrides)
