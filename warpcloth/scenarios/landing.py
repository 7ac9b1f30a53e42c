"""The builder that drape and tablecloth share: a square cloth, held flat, falls onto colliders resting on
the ground, settles (a run ends at equilibrium) and reports the folds of what hangs over them."""

from __future__ import annotations

from collections.abc import Callable

from warpcloth.errors import WarpclothError
from warpcloth.run.drape import fold_count
from warpcloth.scenarios.common import Scenario, ScenarioConfig
from warpcloth.sim.colliders import Plane
from warpcloth.sim.control import Control

#: The air drag [1/s] of a landing unless the configuration says (``--drag``).
DRAG = 1.0


def landing_scenario(
    *,
    name: str,
    description: str,
    colliders: Callable[[], tuple],
    thickness: float,
    friction: float,
    start_height: float,
    fold_cut: float,
    fold_norm: str,
    size: float,
    mass: float,
    integrator_defaults: dict,
) -> Scenario:
    """A :class:`Scenario` of a landing: cotton at 64 x 64 with its Provot bend springs (the material's
    rule; ``--bend dihedral`` for hinges, 3x the cost) stepped by xpbd, self-collision on.

    Args:
        colliders: () -> the scene's colliders (new ones each run); the ground (a :class:`Plane`
            of ``thickness`` [m] and friction ``friction``) is added after them.
        start_height: height [m] of the flat cloth at the start, centred over the origin.
        fold_cut: height [m] of the level cut whose outline's peaks are the folds
            (:func:`warpcloth.run.drape.fold_count` with ``fold_norm``; a hanging corner counts as a fold).
        size: the cloth's width and height [m]; mass: its mass [kg].
        integrator_defaults: per integrator, the options this scene runs it with
            (:attr:`Scenario.integrator_defaults`).
    """

    def control(config: ScenarioConfig, device: str) -> Control:
        drag = DRAG if config.drag is None else config.drag
        ground = Plane(thickness=thickness, friction=friction)
        return Control(drag_rate=drag, colliders=(*colliders(), ground), device=device)

    def origin(config: ScenarioConfig) -> tuple:
        return (-0.5 * config.width, start_height, -0.5 * config.height)

    def measure(sim, config: ScenarioConfig, result=None) -> dict:
        """The folds of the cloth hanging around the colliders: peaks of its level cut at ``fold_cut``."""
        x = sim.state.particle_q.numpy()
        try:
            folds = fold_count(x, sim.model.host.tris, fold_cut, norm=fold_norm)
        except WarpclothError:  # the cloth does not reach the cut
            return {"folds": None, "fold_cut_m": fold_cut}
        return {"folds": folds, "fold_cut_m": fold_cut}

    return Scenario(
        name=name,
        description=description,
        # cotton at 64 x 64: folds; its Provot bend springs (the material's rule) and xpbd keep it interactive on
        # a CPU (dihedral hinges cost 3x: --bend dihedral; docs/materials.md)
        defaults=ScenarioConfig(
            rows=64,
            cols=64,
            width=size,
            height=size,
            mass=mass,
            duration=10.0,
            integrator="xpbd",
            material="cotton",
            bend="provot",
        ),
        pins=lambda rows, cols: [],
        control=control,
        origin=origin,
        stop_at_equilibrium=True,
        plane="horizontal",
        measure=measure,
        self_collision=True,
        integrator_defaults=integrator_defaults,
    )


__all__ = ["DRAG", "landing_scenario"]
