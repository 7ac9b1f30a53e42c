"""What every scenario shares: its configuration, its builder and its run."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np
import warp as wp

from warpcloth.errors import WarpclothError, require_int, require_non_negative, require_positive
from warpcloth.integrators import make_integrator
from warpcloth.io.checkpoint import resume_checkpoint
from warpcloth.io.frames import FrameSinks
from warpcloth.io.meshio import load_mesh_collider
from warpcloth.io.usd import usd_frames
from warpcloth.run.harness import RunHarness, RunResult
from warpcloth.run.metrics import DEFAULT_INSTABILITY_STRAIN
from warpcloth.run.params import BY_NAME, SPRING_TYPES
from warpcloth.run.parse import ColliderSpec
from warpcloth.sim.control import Control
from warpcloth.sim.device import resolve_device
from warpcloth.sim.grid import build_grid_cloth
from warpcloth.sim.material import MATERIAL_VALUES, material_grid_cloth, material_with
from warpcloth.sim.model import BendModel, default_spring_params
from warpcloth.simulator import Simulator


@dataclass
class ScenarioConfig:
    """Parameters of a scenario run; ``None`` means the scenario's or integrator's default.

    stiffness / damping: one number for every spring type, or three (structural, shear, bend).
    strain_limit: Provot's deformation constraint tau (None: the integrator's own, implicit_euler's
        ``strain_cap``, else off), see :class:`Simulator`.
    instability_strain: a spring stretched past (1 + this) x its rest length makes the run unstable.
    mesh, prim, pin_group, pin_where, quads: the cloth of a mesh scenario (a mesh file and its USD
    prim path, the vertex groups and the predicate to pin, quad detection; see
    :func:`warpcloth.build_mesh_cloth`); grid scenarios ignore them.
    material, density, stretch, shear, bend_rigidity, compression, warp_angle, *_damping_ratio: the
    cloth in physical units (:func:`scenario_material`); with a material, mass, stiffness and damping
    do not apply (its density and stiffnesses give them).
    self_collision: the cloth against itself on or off (None: the scenario's own,
    :attr:`Scenario.self_collision`), with self_collision_thickness [m], self_collision_friction and
    self_collision_interval [s] (None: the defaults of :mod:`warpcloth.run.params`); see
    :class:`~warpcloth.sim.self_collision.SelfCollision`.
    collider_edges: hold the cloth off the edges and corners of box and mesh colliders too
    (:attr:`ColliderSet.edge_contacts <warpcloth.sim.contacts.ColliderSet.edge_contacts>`; off by default).
    deterministic: bit-reproducible atomics on CUDA, process-wide (None: as they are; see
    :func:`~warpcloth.sim.device.set_deterministic`).
    """

    rows: int = 32
    cols: int = 32
    width: float = 1.0
    height: float = 1.0
    mass: float = 0.2
    integrator: str = "explicit_euler"
    integrator_options: dict = field(default_factory=dict)
    dt: float | None = None
    duration: float = 10.0
    fps: float = 60.0
    stiffness: float | tuple | None = None
    damping: float | tuple | None = None
    drag: float | None = None
    bend: str = "provot"
    bend_rigidity: float | None = None  # B [N m] of the dihedral hinges (bend="dihedral"); None: the builder's
    device: str | None = None
    strain_limit: float | None = None
    instability_strain: float = DEFAULT_INSTABILITY_STRAIN
    colliders: tuple = ()
    use_graph: bool | None = None  # graph capture: True, False, or None (wherever supported)
    deterministic: bool | None = None  # CUDA atomics in a fixed order (set_deterministic); None: as they are
    mesh: str | None = None
    prim: str | None = None
    pin_group: tuple | None = None
    pin_where: str | None = None
    quads: bool | None = None
    self_collision: bool | None = None
    self_collision_thickness: float | None = None
    self_collision_friction: float | None = None
    self_collision_interval: float | None = None
    # box and mesh colliders' edges and corners against the cloth (ColliderSet.edge_contacts)
    collider_edges: bool = False
    # the material in physical units (docs/materials.md): a preset's name, "custom", a Material, or None /
    # "none" (per-spring stiffness and damping); the values below replace the material's (None: its own)
    material: object = None
    density: float | None = None  # rho [kg/m^2]
    stretch: float | tuple | None = None  # C11 (and C22) [N/m]
    shear: float | None = None  # G [N/m]
    compression: float | None = None  # phi in [0, 1]
    warp_angle: float | None = None  # [rad]
    stretch_damping_ratio: float | None = None
    bend_damping_ratio: float | None = None


#: ScenarioConfig fields that set a material's values (warpcloth.sim.material.MATERIAL_VALUES).
MATERIAL_FIELDS = tuple(MATERIAL_VALUES)
#: ScenarioConfig fields of the per-spring model, which a material replaces.
PER_SPRING_FIELDS = ("mass", "stiffness", "damping")


def scenario_material(cfg: ScenarioConfig):
    """The :class:`~warpcloth.sim.material.Material` of a configuration (its ``material`` with the
    values given), or None for per-spring parameters."""
    return material_with(cfg.material, **{k: getattr(cfg, k) for k in MATERIAL_FIELDS})


def check_material_overrides(scenario: Scenario, given: dict) -> None:
    """Refuse per-spring values (mass, stiffness, damping) on a cloth made of a material, and a
    material's values on a per-spring cloth, naming what to give instead."""
    base = given.get("material", scenario.defaults.material)
    has_material = base is not None and not (isinstance(base, str) and base.strip().lower() == "none")
    if has_material:
        clash = next((k for k in PER_SPRING_FIELDS if k in given), None)
        if clash is not None:
            name = base if isinstance(base, str) else base.name
            where = "" if "material" in given else f"scenario {scenario.name!r} is made of "
            raise WarpclothError(
                f"{clash} is a per-spring value and {where}material {name!r}, whose density and stiffnesses "
                f"give the masses and springs; change the material's values (density, stretch, shear, ...) or "
                f"give material none"
            )
    else:
        clash = next((k for k in MATERIAL_FIELDS if k != "bend_rigidity" and k in given), None)
        if clash is not None:
            raise WarpclothError(
                f"{clash} is a material's value and scenario {scenario.name!r} has no material: give a material "
                "(a preset, or custom with density, stretch, shear and bend_rigidity)"
            )


def check_rigidity(value) -> None:
    """A per-spring cloth's dihedral rigidity is one number (warp,weft pairs need a material)."""
    if isinstance(value, (tuple, list)):
        raise WarpclothError(
            f"bend_rigidity {','.join(f'{v:g}' for v in value)}: two rigidities (warp,weft) need a material; "
            "give one number"
        )


@dataclass(frozen=True)
class Scenario:
    """A named scenario: defaults, a builder of the model and control, and how a run ends.

    Attributes:
        name: scenario name (CLI, CSV).
        description: one line.
        defaults: the :class:`ScenarioConfig` of a plain run.
        pins: function (rows, cols) -> pinned particle indices.
        control: function (config, device) -> :class:`~warpcloth.sim.control.Control`.
        origin: function (config) -> position of particle [0, 0].
        stop_at_equilibrium: whether a run ends once the cloth is at rest.
        model: function (config, device) -> :class:`~warpcloth.sim.model.ClothModel` for a scenario
            that is not a Provot grid (a mesh); None: the grid of ``pins``, ``origin``, ``plane``.
        tracks: function (config, model) -> kinematic pin tracks (:class:`~warpcloth.sim.pins.PinTrack`).
        measure: function (sim, config, result) -> dict of what the scenario measures at the end of a run
            (a textile test's reading, a fold count), put in ``RunResult.measurements``; None: nothing. It
            may read the run's :class:`~warpcloth.run.harness.RunResult` (a capped run is no measurement:
            :meth:`~warpcloth.run.harness.RunResult.capped_cause`).
        kind: ``"grid"`` or ``"mesh"``: which cloth parameters apply (``--size`` or ``--mesh``); None:
            ``"mesh"`` where ``model`` is given. A ``model`` of kind ``"grid"`` builds its own cloth from
            rows, cols, width and height (the Cusick disc).
        self_collision: whether the cloth collides with itself unless the configuration says
            (scenes that fold: fold, drape, tablecloth).
        integrator_defaults: per integrator, option values this scene runs it with unless the
            configuration's ``integrator_options`` say otherwise (the solver work a scene needs, e.g.
            pbd's substeps on the drape; the integrator's own defaults elsewhere).
        start: function (config, model) -> the positions (N, 3) [m] a run starts from, at rest
            (velocities 0), rounded to float32 (the swing's sheet released from horizontal); None: the
            model's rest shape. :meth:`Simulator.reset <warpcloth.simulator.Simulator.reset>` goes back
            to the rest shape (a max-dt search's trials start from rest).
    """

    name: str
    description: str
    defaults: ScenarioConfig
    pins: Callable[[int, int], list]
    control: Callable[[ScenarioConfig, str], Control]
    origin: Callable[[ScenarioConfig], tuple]
    stop_at_equilibrium: bool
    plane: str = "vertical"
    model: Callable | None = None
    tracks: Callable | None = None
    self_collision: bool = False
    measure: Callable | None = None
    kind: str | None = None
    integrator_defaults: dict = field(default_factory=dict)
    start: Callable | None = None

    def integrator_options(self, integrator: str, options: dict | None = None) -> dict:
        """The options this scene runs ``integrator`` with: its :attr:`integrator_defaults` for it,
        then ``options`` (the user's) over them."""
        return {**self.integrator_defaults.get(integrator, {}), **(options or {})}

    @property
    def is_mesh(self) -> bool:
        """Whether the cloth is a mesh (its size from the mesh; grid parameters refused): ``kind``,
        or by default whether the scenario builds its own ``model``."""
        return self.kind == "mesh" if self.kind is not None else self.model is not None

    def config(self, **overrides) -> ScenarioConfig:
        """The default configuration with ``overrides`` (None values keep the default)."""
        unknown = set(overrides) - set(ScenarioConfig.__dataclass_fields__)
        if unknown:
            raise WarpclothError(f"unknown scenario parameter {sorted(unknown)[0]!r}")
        given = {k: v for k, v in overrides.items() if v is not None}
        check_material_overrides(self, given)
        for kind in ("stiffness", "damping"):  # a partial {type: value} keeps the default's other types
            base = getattr(self.defaults, kind)
            if isinstance(given.get(kind), dict) and base is not None and not isinstance(base, dict):
                full = base if isinstance(base, tuple) else (base,) * 3
                given[kind] = tuple(given[kind].get(t, full[i]) for i, t in enumerate(SPRING_TYPES))
        return replace(self.defaults, **given)

    def build(self, config: ScenarioConfig | None = None, **overrides) -> Simulator:
        """A :class:`~warpcloth.simulator.Simulator` for this scenario."""
        cfg = replace(config, **overrides) if config is not None else self.config(**overrides)
        device = resolve_device(cfg.device)
        require_positive("mass", cfg.mass, "kg")
        if not isinstance(cfg.integrator_options, dict):
            raise WarpclothError(
                f"integrator_options must be a dict of option names and values, got {cfg.integrator_options!r:.80}"
            )
        if isinstance(cfg.integrator, str):
            cfg = replace(cfg, integrator_options=self.integrator_options(cfg.integrator, cfg.integrator_options))
        if self.model is not None:  # a mesh: the scenario builds its own model
            integrator = make_integrator(cfg.integrator, **cfg.integrator_options)
            with wp.ScopedDevice(device):
                return self._simulator(cfg, self.model(cfg, device), integrator, device)
        try:
            bend = BendModel(cfg.bend)
        except ValueError:
            raise WarpclothError(
                f"bend must be one of {', '.join(b.value for b in BendModel)}, got {cfg.bend!r}"
            ) from None
        min_dim = 2 if bend in (BendModel.NONE, BendModel.DIHEDRAL) else 3
        rows = require_int("rows", cfg.rows, min_dim)
        cols = require_int("cols", cfg.cols, min_dim)
        integrator = make_integrator(cfg.integrator, **cfg.integrator_options)
        mat = scenario_material(cfg)
        if mat is not None:
            with wp.ScopedDevice(device):
                model = material_grid_cloth(
                    mat,
                    rows,
                    cols,
                    cfg.width,
                    cfg.height,
                    pins=self.pins(rows, cols),
                    origin=self.origin(cfg),
                    plane=self.plane,
                    bend=bend,
                    device=device,
                )
                return self._simulator(cfg, model, integrator, device)
        check_rigidity(cfg.bend_rigidity)
        params = default_spring_params(cfg.mass / (rows * cols), cfg.stiffness, cfg.damping)
        with wp.ScopedDevice(device):
            model = build_grid_cloth(
                rows,
                cols,
                cfg.width,
                cfg.height,
                cfg.mass,
                spring_params=params,
                pins=self.pins(rows, cols),
                origin=self.origin(cfg),
                plane=self.plane,
                bend=bend,
                device=device,
                **({"bend_rigidity": cfg.bend_rigidity} if cfg.bend_rigidity is not None else {}),
            )
            return self._simulator(cfg, model, integrator, device)

    def _simulator(self, cfg: ScenarioConfig, model, integrator, device: str) -> Simulator:
        control = self.control(cfg, device)
        if cfg.colliders:  # added to the scenario's own (--collider); a mesh's file is read here, once
            control.colliders = tuple(control.colliders) + tuple(
                c.collider(load_mesh_collider) if isinstance(c, ColliderSpec) else c for c in cfg.colliders
            )
        if cfg.collider_edges not in (True, False):
            raise WarpclothError(f"collider_edges must be True or False, got {cfg.collider_edges!r:.80}")
        if cfg.collider_edges and control.collision is not None:
            control.collision.edge_contacts = True
        if self.tracks is not None:
            control.pin_tracks = tuple(self.tracks(cfg, model))
        sim = Simulator(
            model,
            integrator,
            control,
            dt=cfg.dt,
            strain_limit=cfg.strain_limit,
            use_graph=cfg.use_graph,
            self_collision=self.self_collision_settings(cfg),
            deterministic=cfg.deterministic,
        )
        if self.start is not None:
            self._start(sim, cfg)
        return sim

    def _start(self, sim: Simulator, cfg: ScenarioConfig) -> None:
        """Put ``sim`` at the scenario's :attr:`start` (float32 positions, velocities 0)."""
        x0 = np.asarray(self.start(cfg, sim.model), dtype=np.float32)
        if x0.shape != (sim.model.particle_count, 3) or not np.all(np.isfinite(x0)):
            raise WarpclothError(
                f"scenario {self.name!r}: its start must be {sim.model.particle_count} finite positions (N, 3), got "
                f"an array of shape {x0.shape}"
            )
        sim.state.particle_q.assign(wp.array(x0, dtype=wp.vec3, device=sim.model.device))

    def self_collision_settings(self, cfg: ScenarioConfig) -> dict | None:
        """The :class:`~warpcloth.sim.self_collision.SelfCollision` settings of a run (None: off); a bad
        thickness or friction is refused whether it is on or not."""
        thickness, friction = cfg.self_collision_thickness, cfg.self_collision_friction
        interval = cfg.self_collision_interval
        settings = {
            "thickness": BY_NAME["self_collision_thickness"].default if thickness is None else thickness,
            "friction": BY_NAME["self_collision_friction"].default if friction is None else friction,
            "interval": BY_NAME["self_collision_interval"].default if interval is None else interval,
        }
        require_positive("self_collision_thickness", settings["thickness"], "m")
        require_non_negative("self_collision_friction", settings["friction"])
        require_non_negative("self_collision_interval", settings["interval"], "s")
        on = self.self_collision if cfg.self_collision is None else cfg.self_collision
        if on not in (True, False):
            raise WarpclothError(f"self_collision must be True, False or None (the scenario's), got {on!r:.80}")
        return settings if on else None

    def harness(self, config: ScenarioConfig | None = None, **overrides) -> RunHarness:
        """A :class:`~warpcloth.run.harness.RunHarness` of a newly built simulator (``.sim``) with
        this scenario's name and the configuration's verdict settings (instability strain)."""
        cfg = replace(config, **overrides) if config is not None else self.config(**overrides)
        return RunHarness(self.build(cfg), scenario=self.name, instability_strain=cfg.instability_strain)

    def run(
        self,
        config: ScenarioConfig | None = None,
        usd_path: str | None = None,
        wall_cap: float | None = None,
        writers=(),
        resume_from: str | None = None,
        **overrides,
    ) -> RunResult:
        """Build and run; writes a USD file when ``usd_path`` is given.

        ``writers``: more frame writers, each a function ``(sim, config) -> writer`` called
        once the :class:`~warpcloth.simulator.Simulator` is built; a writer has ``write_frame(points, sim_time)``,
        ``close()`` and
        ``abort()`` (:class:`~warpcloth.io.frames.FrameSinks`). Every writer is closed after the
        run, or aborted (its target left as it was) when the run fails.

        ``resume_from``: a checkpoint file (:mod:`warpcloth.io.checkpoint`) of a run of this scenario
        and configuration: the run continues from it to ``duration`` (counted from the first run's
        start), bit-identically to the uninterrupted run on the same device.
        """
        cfg = replace(config, **overrides) if config is not None else self.config(**overrides)
        require_positive("duration", cfg.duration, "s")
        require_positive("fps", cfg.fps, "1/s")
        if usd_path is not None:
            writers = (usd_frames(usd_path), *writers)  # checks the path now, before any work
        harness = self.harness(cfg)
        sim = harness.sim
        resumed = resume_checkpoint(resume_from, sim).clock["steps"] if resume_from is not None else 0
        sinks = FrameSinks()
        try:
            for make in writers:
                sinks.writers.append(make(sim, cfg))
            result = harness.run(
                cfg.duration,
                fps=cfg.fps,
                stop_at_equilibrium=self.stop_at_equilibrium,
                wall_cap=wall_cap,
                frames=sinks if sinks else None,
                resumed_steps=resumed,
            )
        except BaseException:
            sinks.abort()
            raise
        sinks.close()
        if self.measure is not None and result.stable:
            result.measurements = dict(self.measure(sim, cfg, result))
        return result
