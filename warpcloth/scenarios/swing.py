"""The study's cloth and its swing (docs/study.md): the scenario ``warpcloth advise`` answers for.

**The study's cloth** is :data:`STUDY_MATERIAL` at every n x n, mapped onto the grid by
:func:`~warpcloth.sim.material.grid_spring_params` (the membrane stiffness does not change under
refinement; masses rho x vertex area; Provot bend springs with the material's approximate rule,
which grows as h^-4: docs/materials.md).
:func:`material_grid_model` builds it, and :func:`study_scenario` a scenario of it, for the
study's sheet, flag and contact cloth alike (:mod:`warpcloth.lab.transients`).

**The swing** (:data:`SCENARIO`, ``warpcloth run swing``): 1 m x 1 m of it, its whole top row
pinned, drag 1/s, released at rest from horizontal (its rest shape rotated :data:`SWING_TILT`
degrees about the top row: :func:`tilted_start`, the :attr:`Scenario.start
<warpcloth.scenarios.common.Scenario.start>` hook). It is the study's ``swing`` transient to
the bit (tests/test_swing_scenario.py), so the flags ``warpcloth advise`` prints reproduce the
measured configuration. Its material's values may be changed (``--density``, ``--stretch``, ...);
its bending stays the study's Provot springs.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from warpcloth.errors import WarpclothError, require_int
from warpcloth.scenarios.common import Scenario, ScenarioConfig, scenario_material
from warpcloth.sim.control import Control
from warpcloth.sim.grid import grid_positions, grid_triangles, grid_uvs
from warpcloth.sim.material import Material, grid_spring_params
from warpcloth.sim.model import BendModel, build_model

#: The study's cloth: a plain woven fabric in the range of docs/materials.md's presets (between
#: polyester_light, 343 N/m, and cotton, 4070 N/m), isotropic so that the sheet and the flag
#: differ only in shape and load. Its membrane springs on a square grid: ks = 750 N/m structural,
#: 250 N/m shear, at every size.
STUDY_MATERIAL = Material(
    "study",
    density=0.2,
    stretch_warp=1000.0,
    stretch_weft=1000.0,
    shear=250.0,
    bend_warp=10.0e-6,
    bend_weft=10.0e-6,
    stretch_damping_ratio=0.05,
    note="the study's cloth (docs/study.md): stated, not a measured fabric",
)
#: Air drag of the study's sheet [1/s] (the sheet scenario's).
SHEET_DRAG = 1.0
#: The swing's start: the hanging rest shape rotated this far forward about its top row [deg]
#: (90: horizontal).
SWING_TILT = 90.0


def material_grid_model(cfg: ScenarioConfig, device, origin, pins, mat: Material = STUDY_MATERIAL):
    """A ClothModel of ``mat`` on cfg.rows x cfg.cols particles over cfg.width x cfg.height [m]
    in the vertical plane, particle [0, 0] at ``origin``, ``pins`` pinned (Provot bend springs
    with the material's approximate rule)."""
    rows, cols = int(cfg.rows), int(cfg.cols)
    q = grid_positions(rows, cols, cfg.width, cfg.height, origin, "vertical")
    springs = grid_spring_params(mat, rows, cols, cfg.width, cfg.height, bend=BendModel.PROVOT)
    model = build_model(
        q,
        springs.pairs,
        springs.types,
        springs.mass,
        None,
        pins,
        grid_triangles(rows, cols),
        device,
        **springs.build_kwargs(),
    )
    uv = grid_uvs(rows, cols)[model.host.tris].reshape(-1, 2)
    return replace(
        model,
        rows=rows,
        cols=cols,
        width=cfg.width,
        height=cfg.height,
        bend=BendModel.PROVOT,
        total_mass=float(springs.mass.sum()),
        host=replace(model.host, uv=uv),
    )


def top_row(rows: int, cols: int) -> list:
    """The pins of the study's sheet: its whole top row."""
    return list(range(cols))


def sheet_origin(cfg) -> tuple:
    """Particle [0, 0] of the study's sheet [m]: the top row centred on x = 0, 2 m up."""
    return (-0.5 * cfg.width, 2.0, 0.0)


def sheet_control(cfg, device) -> Control:
    """Gravity and the sheet's drag (:data:`SHEET_DRAG` unless the configuration says)."""
    return Control(drag_rate=SHEET_DRAG if cfg.drag is None else cfg.drag, device=device)


def study_scenario(name, description, defaults, pins, control, origin, stop) -> Scenario:
    """A scenario of the study's cloth (:data:`STUDY_MATERIAL`, :func:`material_grid_model`)."""
    return Scenario(
        name=name,
        description=description,
        defaults=defaults,
        pins=pins,
        control=control,
        origin=origin,
        stop_at_equilibrium=stop,
        model=lambda cfg, device: material_grid_model(cfg, device, origin(cfg), pins(cfg.rows, cfg.cols)),
    )


def tilted_start(model, degrees: float) -> np.ndarray:
    """Positions (N, 3) of the rest shape rotated by ``degrees`` about the x axis through
    particle 0, towards +z: 90 puts a sheet hanging from its top row horizontal (the swing's
    start, :func:`warpcloth.lab.reference.swing_from_horizontal`)."""
    q = model.host.q.astype(np.float64)
    rel = q - q[0]
    a = math.radians(degrees)
    out = q.copy()
    out[:, 1] = q[0, 1] + rel[:, 1] * math.cos(a) + rel[:, 2] * math.sin(a)
    out[:, 2] = q[0, 2] - rel[:, 1] * math.sin(a) + rel[:, 2] * math.cos(a)
    return out


#: The study's sheet: 1 m x 1 m of :data:`STUDY_MATERIAL`, its top row pinned, drag 1/s, at rest
#: (the study's scenario ``study_sheet``: its transients set their own start).
STUDY_SHEET = study_scenario(
    "study_sheet",
    "the study's sheet: its top row pinned (the study material)",
    ScenarioConfig(rows=32, cols=32, width=1.0, height=1.0, duration=1.0),
    top_row,
    sheet_control,
    sheet_origin,
    False,
)


def _swing_model(cfg: ScenarioConfig, device):
    """The study's sheet of the configuration's material (the study's unless its values are given)."""
    mat = scenario_material(cfg)
    if mat is None:
        raise WarpclothError("the swing is made of a material: give a preset or custom, not material none")
    if cfg.bend != BendModel.PROVOT.value:
        raise WarpclothError(
            f"the swing bends with the study's Provot springs: bend {cfg.bend!r} is not available on it "
            "(the sheet scenario takes --bend dihedral)"
        )
    rows, cols = require_int("rows", cfg.rows, 3), require_int("cols", cfg.cols, 3)
    return material_grid_model(cfg, device, sheet_origin(cfg), top_row(rows, cols), mat)


def _swing_start(cfg: ScenarioConfig, model) -> np.ndarray:
    return tilted_start(model, SWING_TILT)


#: ``warpcloth run swing``: the study's sheet released at rest from horizontal (the study's swing).
SCENARIO = replace(
    STUDY_SHEET,
    name="swing",
    description="the study's swing: a sheet of the study's cloth, its top row pinned, released from horizontal",
    defaults=replace(STUDY_SHEET.defaults, material=STUDY_MATERIAL),
    model=_swing_model,
    kind="grid",
    start=_swing_start,
)


def build(**overrides):
    """A Simulator of the swing, at its start, with the defaults and ``overrides`` (see ScenarioConfig)."""
    return SCENARIO.build(**overrides)
