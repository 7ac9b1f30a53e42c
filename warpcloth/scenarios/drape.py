"""Drape: a square cloth, held flat, falls onto a sphere resting on the ground and drapes over it
(colliders, :mod:`warpcloth.sim.colliders`); a run ends at equilibrium and reports the folds of the
hanging skirt. Run it with ``python -m warpcloth.scenarios.drape`` or ``warpcloth run drape``.

By default the cloth is cotton (``--material``, docs/materials.md) at 64 x 64 with its Provot
bend springs (the material's rule; ``--bend dihedral`` for hinges of its rigidity, 3x the cost),
stepped by xpbd; ``--material none --bend provot --size 24 --integrator explicit_euler``
is the scene of before (per-spring parameters).
"""

from warpcloth.scenarios.common import Scenario, ScenarioConfig

from warpcloth.errors import WarpclothError
from warpcloth.run.drape import fold_count
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


#: The height [m] of the level cut whose outline's peaks are the folds (Scenario.measure).
FOLD_CUT = RADIUS - 0.05  # 5 cm below the sphere's equator, where the skirt hangs free


def measure(sim, config: ScenarioConfig) -> dict:
    """The folds of the cloth hanging around the sphere: peaks of its level cut at FOLD_CUT
    (:func:`warpcloth.run.drape.fold_count`; a hanging corner counts as a fold)."""
    x = sim.state.particle_q.numpy()
    try:
        folds = fold_count(x, sim.model.host.tris, FOLD_CUT)
    except WarpclothError:  # the cloth does not reach the cut
        return {"folds": None, "fold_cut_m": FOLD_CUT}
    return {"folds": folds, "fold_cut_m": FOLD_CUT}


SCENARIO = Scenario(
    name="drape",
    description="a square cloth falls onto a sphere on the ground and drapes over it (colliders); runs to equilibrium",
    # cotton at 64 x 64: folds; its Provot bend springs (the material's rule) and xpbd keep it interactive on a
    # CPU (dihedral hinges cost 3x: --bend dihedral; docs/materials.md)
    defaults=ScenarioConfig(
        rows=64,
        cols=64,
        width=1.0,
        height=1.0,
        mass=0.2,
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
    # pbd with its default 4 substeps let layers through where the skirt folds (155 of 181 frames, up to 32
    # triangle pairs, from 0.43 s); with 8: 0 frames, peak strain 0.18 (docs/self-collision.md). Measured at 64 x 64;
    # at 12 x 12 the skirt then still swings at 0.015 m/s after 16 s
    integrator_defaults={"pbd": {"substeps": 8}},
)


def build(**overrides):
    """A Simulator of the drape with the defaults and ``overrides`` (see ScenarioConfig)."""
    return SCENARIO.build(**overrides)
