"""Two sheets in one model (:class:`~warpcloth.sim.builder.ClothBuilder`): a cotton sheet and a
silk one, each rows x cols, hanging by their top corners side by side 0.5 m apart, gravity and
drag; a run ends at equilibrium. The cost of several cloths stepped as one system:
``warpcloth bench --scenario pair``; ``warpcloth run pair --usd pair.usda`` writes one mesh prim
per sheet (``/World/Cloth/cotton``, ``/World/Cloth/silk``). docs/garments.md.
"""

from warpcloth.scenarios.common import Scenario, ScenarioConfig, scenario_material
from warpcloth.sim.builder import ClothBuilder
from warpcloth.sim.control import Control

#: The second sheet's material (the first one's is the run's, cotton by default).
SECOND = "silk"
#: The gap between the two sheets [m].
GAP = 0.5


def _model(config: ScenarioConfig, device: str):
    rows, cols = config.rows, config.cols
    first = scenario_material(config)
    b = ClothBuilder()
    corners = [0, cols - 1]
    x0 = -config.width - 0.5 * GAP
    common = {"pins": corners, "plane": "vertical", "bend": config.bend}
    if first is None:  # per-spring parameters (--material none)
        b.add_grid(
            rows,
            cols,
            config.width,
            config.height,
            name="cloth",
            total_mass=config.mass,
            origin=(x0, 2.0, 0.0),
            **common,
        )
    else:
        b.add_grid(
            rows,
            cols,
            config.width,
            config.height,
            material=first,
            name=first.name.replace("-", "_"),
            origin=(x0, 2.0, 0.0),
            **common,
        )
    b.add_grid(
        rows, cols, config.width, config.height, material=SECOND, name=SECOND, origin=(0.5 * GAP, 2.0, 0.0), **common
    )
    return b.finalize(device)


def _control(config: ScenarioConfig, device: str) -> Control:
    return Control(drag_rate=1.0 if config.drag is None else config.drag, device=device)


SCENARIO = Scenario(
    name="pair",
    description="two sheets (cotton and silk) in one model, hanging by their top corners side by side; runs to "
    "equilibrium",
    defaults=ScenarioConfig(rows=32, cols=32, width=1.0, height=1.0, duration=10.0, material="cotton"),
    pins=lambda rows, cols: [0, cols - 1],
    control=_control,
    origin=lambda config: (0.0, 2.0, 0.0),
    stop_at_equilibrium=True,
    model=_model,
    kind="grid",
)


def build(**overrides):
    """A Simulator of the two sheets with the defaults and ``overrides`` (see ScenarioConfig)."""
    return SCENARIO.build(**overrides)
