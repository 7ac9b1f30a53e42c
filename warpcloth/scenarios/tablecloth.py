"""Tablecloth: a cloth falls onto a square table (an oriented box collider with friction) and
hangs over its edges; a run ends at equilibrium and reports the folds of the overhang. Run it with
``warpcloth run tablecloth``.

By default the cloth is cotton (``--material``, docs/materials.md) at 64 x 64 with its Provot
bend springs (the material's rule; ``--bend dihedral`` for hinges of its rigidity, 3x the cost),
stepped by xpbd; ``--material none --bend provot --size 24 --integrator explicit_euler``
is the scene of before (per-spring parameters).
"""

from warpcloth.scenarios.common import Scenario, ScenarioConfig

from warpcloth.errors import WarpclothError
from warpcloth.run.drape import fold_count
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


#: The height [m] of the level cut whose outline's peaks are the folds (Scenario.measure).
FOLD_CUT = HEIGHT - 0.1


def measure(sim, config: ScenarioConfig) -> dict:
    """The folds of the cloth hanging around the table: peaks of its level cut at FOLD_CUT
    (:func:`warpcloth.run.drape.fold_count` around the square table: distance max(|x|, |z|), so the
    table's own corners are no peaks; a hanging corner's cone is a fold)."""
    x = sim.state.particle_q.numpy()
    try:
        folds = fold_count(x, sim.model.host.tris, FOLD_CUT, norm="square")
    except WarpclothError:  # the cloth does not reach the cut
        return {"folds": None, "fold_cut_m": FOLD_CUT}
    return {"folds": folds, "fold_cut_m": FOLD_CUT}


SCENARIO = Scenario(
    name="tablecloth",
    description=(
        "a cloth falls on a square table (box collider, friction) and hangs over its edges; runs to equilibrium"
    ),
    # cotton at 64 x 64: folds; its Provot bend springs (the material's rule) and xpbd keep it interactive on a
    # CPU (dihedral hinges cost 3x: --bend dihedral; docs/materials.md)
    defaults=ScenarioConfig(
        rows=64,
        cols=64,
        width=1.3,
        height=1.3,
        mass=0.3,
        duration=10.0,
        integrator="xpbd",
        material="cotton",
        bend="provot",
    ),
    pins=_pins,
    control=_control,
    origin=_origin,
    stop_at_equilibrium=True,
    plane="horizontal",
    measure=measure,
    self_collision=True,
    # vbd: its multigrid correction held to 10 % stretch as the table's rounded edges catch the cloth's rim
    # before its middle lands (unlimited, the 64 x 64 landing blew up at 0.15 s, strain 1.06; docs/solvers.md)
    integrator_defaults={"vbd": {"vbd_correction_strain": 0.1}},
)


def build(**overrides):
    """A Simulator of the tablecloth with the defaults and ``overrides`` (see ScenarioConfig)."""
    return SCENARIO.build(**overrides)
