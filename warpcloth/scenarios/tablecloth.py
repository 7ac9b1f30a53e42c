"""Tablecloth: a cloth falls onto a square table (an oriented box collider with friction) and
hangs over its edges; a run ends at equilibrium and reports the folds of the overhang. Run it with
``warpcloth run tablecloth``.

By default the cloth is cotton (``--material``, docs/materials.md) at 64 x 64 with its Provot
bend springs (the material's rule; ``--bend dihedral`` for hinges of its rigidity, at a higher cost),
stepped by xpbd at 2 iterations x 32 substeps (the fidelity rule's cheapest measured; docs/materials.md);
``--material none --bend provot --size 24 --integrator explicit_euler``
is the scene of before (per-spring parameters).
"""

from warpcloth.scenarios.landing import landing_scenario
from warpcloth.sim.colliders import Box

#: The table top: 0.8 m square, 0.75 m high (its top face), the cloth's offset [m] and mu.
HALF = 0.4
HEIGHT = 0.75
THICKNESS = 0.004
FRICTION = 0.5
#: The height [m] of the level cut whose outline's peaks are the folds (Scenario.measure): around the
#: square table, distance max(|x|, |z|), so the table's own corners are no peaks; a hanging corner's cone is a fold.
FOLD_CUT = HEIGHT - 0.1


def _colliders() -> tuple:
    return (
        Box(
            center=(0.0, 0.5 * HEIGHT, 0.0),
            half_extents=(HALF, 0.5 * HEIGHT, HALF),
            thickness=THICKNESS,
            friction=FRICTION,
        ),
    )


SCENARIO = landing_scenario(
    name="tablecloth",
    description=(
        "a cloth falls on a square table (box collider, friction) and hangs over its edges; runs to equilibrium"
    ),
    colliders=_colliders,
    thickness=THICKNESS,
    friction=FRICTION,
    start_height=HEIGHT + 0.1,
    fold_cut=FOLD_CUT,
    fold_norm="square",
    size=1.3,
    mass=0.3,
    # vbd: its multigrid correction held to 10 % stretch as the table's rounded edges catch the cloth's rim
    # before its middle lands (unlimited, the 64 x 64 landing blew up at 0.15 s, strain 1.06; docs/solvers.md)
    # xpbd: 2 iterations x 32 substeps, the cheapest configuration measured to reproduce cotton (the fidelity
    # rule, docs/materials.md): at 24 x 24 its strain is 1.03x the float64 equilibrium's, the shape within 0.04 %;
    # xpbd's own 10 x 4 left 7.8x (1.27 % against 0.16 %)
    integrator_defaults={"vbd": {"vbd_correction_strain": 0.1}, "xpbd": {"iterations": 2, "substeps": 32}},
)


def build(**overrides):
    """A Simulator of the tablecloth with the defaults and ``overrides`` (see ScenarioConfig)."""
    return SCENARIO.build(**overrides)
