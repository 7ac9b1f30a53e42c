"""Curtain on a sliding rod: the top edge hangs from a rod that slides sideways and stops
(kinematic pins, :class:`~warpcloth.sim.pins.PinTrack`); the curtain swings and settles.

The top row is pinned and follows the rod: a Catmull-Rom track of two keys, so the rod starts
and stops at rest (position x0 + SLIDE s(t), s the smoothstep 3u^2 - 2u^3 of u = t / SLIDE_TIME).
A run ends at equilibrium. Run it with ``warpcloth run curtain`` (or
``python -m warpcloth run curtain``).
"""

from warpcloth.scenarios.common import Scenario, ScenarioConfig
from warpcloth.sim.control import Control
from warpcloth.sim.pins import PinTrack

#: How far the rod slides [m] along +x, and in how long [s].
SLIDE = 0.5
SLIDE_TIME = 1.5


def _pins(rows: int, cols: int) -> list:
    return list(range(cols))  # the top row, on the rod


def _tracks(config: ScenarioConfig, model):
    top = list(range(model.cols))
    return [
        PinTrack.keyframes(
            top, [0.0, SLIDE_TIME], [[0.0, 0.0, 0.0], [SLIDE, 0.0, 0.0]], interpolation="catmull_rom", name="rod"
        )
    ]


def _control(config: ScenarioConfig, device: str) -> Control:
    drag = 1.0 if config.drag is None else config.drag
    return Control(drag_rate=drag, device=device)


def _origin(config: ScenarioConfig) -> tuple:
    return (-0.5 * config.width, 2.2, 0.0)


SCENARIO = Scenario(
    name="curtain",
    description=f"a curtain whose rod slides {SLIDE} m sideways in {SLIDE_TIME} s and stops (kinematic pins); runs to "
    "equilibrium",
    defaults=ScenarioConfig(rows=24, cols=32, width=1.6, height=1.2, mass=0.4, duration=10.0),
    pins=_pins,
    control=_control,
    origin=_origin,
    stop_at_equilibrium=True,
    tracks=_tracks,
)


def build(**overrides):
    """A Simulator of the curtain with the defaults and ``overrides`` (see ScenarioConfig)."""
    return SCENARIO.build(**overrides)
