"""Drape: a square cloth, held flat, falls onto a sphere resting on the ground and drapes over it
(colliders, :mod:`warpcloth.sim.colliders`); a run ends at equilibrium and reports the folds of the
hanging skirt. Run it with ``warpcloth run drape`` (or ``python -m warpcloth run drape``).

By default the cloth is cotton (``--material``, docs/materials.md) at 64 x 64 with its Provot
bend springs (the material's rule; ``--bend dihedral`` for hinges of its rigidity, at a higher cost),
stepped by xpbd at 1 iteration x 64 substeps (the fidelity rule's cheapest measured; docs/materials.md);
``--material none --bend provot --size 24 --integrator explicit_euler``
is the scene of before (per-spring parameters).
"""

from warpcloth.scenarios.landing import landing_scenario
from warpcloth.sim.colliders import Sphere

#: The sphere [m] (resting on the ground y = 0), the cloth's offset from surfaces [m] and mu.
RADIUS = 0.3
THICKNESS = 0.005
FRICTION = 0.4
DROP = 0.15  # m: the cloth starts this far above the sphere's top
#: The height [m] of the level cut whose outline's peaks are the folds (Scenario.measure).
FOLD_CUT = RADIUS - 0.05  # 5 cm below the sphere's equator, where the skirt hangs free


def _colliders() -> tuple:
    return (Sphere(center=(0.0, RADIUS, 0.0), radius=RADIUS, thickness=THICKNESS, friction=FRICTION),)


SCENARIO = landing_scenario(
    name="drape",
    description="a square cloth falls onto a sphere on the ground and drapes over it (colliders); runs to equilibrium",
    colliders=_colliders,
    thickness=THICKNESS,
    friction=FRICTION,
    start_height=2.0 * RADIUS + DROP,
    fold_cut=FOLD_CUT,
    fold_norm="circle",
    size=1.0,
    mass=0.2,
    # pbd with its default 4 substeps let layers through where the skirt folds (155 of 181 frames, up to 32
    # triangle pairs, from 0.43 s); with 8: 0 frames, peak strain 0.18 (docs/self-collision.md). Measured at 64 x 64;
    # at 12 x 12 the skirt then still swings at 0.015 m/s after 16 s
    # xpbd: 1 iteration x 64 substeps, the cheapest configuration measured to reproduce cotton (the fidelity
    # rule, docs/materials.md): at 24 x 24 its rest strain is 1.27x the float64 equilibrium's and the shape
    # within 0.07 % of the size; xpbd's own 10 x 4 left 13x (3.8 % against 0.29 %), 2 x 32 1.63x
    integrator_defaults={"pbd": {"substeps": 8}, "xpbd": {"iterations": 1, "substeps": 64}},
)


def build(**overrides):
    """A Simulator of the drape with the defaults and ``overrides`` (see ScenarioConfig)."""
    return SCENARIO.build(**overrides)
