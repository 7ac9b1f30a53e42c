"""The study's cloth and its transients (design.md, "Accuracy and the study"; docs/study.md).

**One cloth at every size.** The sheet and the flag are the same material at every n x n:
:data:`STUDY_MATERIAL` mapped onto the grid by :func:`warpcloth.sim.material.grid_spring_params`
(membrane springs keep the material's membrane energy under every uniform strain, so the membrane
stiffness does not change under refinement; masses rho x vertex area). Bending: Provot skip-one
springs with the material's approximate rule ks = 9 B / (kappa_ref^2 h^4), which is *not*
size-independent (it grows as h^-4; docs/materials.md) but stays below 1 % of the membrane
springs' ks at the study's sizes, so the cloths' response is the membrane's.

**Transients** (:data:`TRANSIENTS`):

* ``swing``: the sheet with its whole top row pinned, released from horizontal (tension
  dominated: well-posed where the two-corner sheet buckles);
* ``flag``: the flag from rest in its wind, over a window whose conditioning floor is small;
* ``contact``: the sheet (top row pinned), tilted 30 degrees forward, swings back onto a
  frictionless plane inclined 20 degrees from the vertical and settles; its rest shape is compared
  with the float64 static equilibrium with the contact
  (:func:`warpcloth.lab.reference.contact_equilibrium`), unique because the plane is frictionless
  and convex and the sheet is held by its top row (a sphere's contact set is not unique).

Every size of a profile runs the same window (:meth:`warpcloth.lab.plan.StudyPlan.window_frames`);
where the pointwise e is ill-conditioned at a size, the coarse metrics decide (docs/study.md, "Windows").
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from warpcloth.scenarios.common import Scenario, ScenarioConfig
from warpcloth.scenarios.flag import GUST, GUST_OFF, GUST_ON, LULL, WIND_COEFFICIENT
from warpcloth.sim.colliders import Plane
from warpcloth.sim.control import Control, WindSchedule
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

#: The plane of the contact transient: through CONTACT_POINT [m], inclined CONTACT_INCLINE [deg]
#: from the vertical (its outward normal (0, sin, cos)), thickness [m]; frictionless.
CONTACT_POINT = (0.0, 1.6, 0.0)
CONTACT_INCLINE = 20.0
CONTACT_THICKNESS = 0.005
#: The contact transient's start: the sheet rotated this far forward about its top row [deg].
CONTACT_TILT = 30.0
#: Air drag of the sheet transients [1/s] (the sheet scenario's).
SHEET_DRAG = 1.0
#: Air drag of the contact transient [1/s]: the equilibrium does not depend on it; it brings the
#: sheet to rest within seconds (a time constant of 0.25 s).
CONTACT_DRAG = 4.0


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


def _top_row(rows: int, cols: int) -> list:
    return list(range(cols))


def _left_edge(rows: int, cols: int) -> list:
    return [r * cols for r in range(rows)]


def _sheet_origin(cfg) -> tuple:
    return (-0.5 * cfg.width, 2.0, 0.0)


def _flag_origin(cfg) -> tuple:
    return (0.0, 2.0, 0.0)


def _sheet_control(cfg, device) -> Control:
    return Control(drag_rate=SHEET_DRAG if cfg.drag is None else cfg.drag, device=device)


def _flag_control(cfg, device) -> Control:
    return Control(
        drag_rate=0.0 if cfg.drag is None else cfg.drag,
        wind_coefficient=WIND_COEFFICIENT,
        wind_schedule=WindSchedule.gusts(GUST, GUST_ON, GUST_OFF, base=LULL),
        device=device,
    )


def contact_plane() -> Plane:
    """The contact transient's frictionless inclined plane."""
    a = math.radians(CONTACT_INCLINE)
    return Plane(point=CONTACT_POINT, normal=(0.0, math.sin(a), math.cos(a)), thickness=CONTACT_THICKNESS, friction=0.0)


def _contact_control(cfg, device) -> Control:
    return Control(
        drag_rate=CONTACT_DRAG if cfg.drag is None else cfg.drag, colliders=(contact_plane(),), device=device
    )


def _scenario(name, description, defaults, pins, control, origin, stop) -> Scenario:
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


#: The study's sheet: 1 m x 1 m of :data:`STUDY_MATERIAL`, its top row pinned, drag 1/s.
STUDY_SHEET = _scenario(
    "study_sheet",
    "the study's sheet: its top row pinned (the study material)",
    ScenarioConfig(rows=32, cols=32, width=1.0, height=1.0, duration=1.0),
    _top_row,
    _sheet_control,
    _sheet_origin,
    False,
)
#: The study's flag: 1.5 m x 1 m of :data:`STUDY_MATERIAL` on its pole (left edge), in the flag's wind.
STUDY_FLAG = _scenario(
    "study_flag",
    "the study's flag: its left edge pinned, in gusting wind (the study material)",
    ScenarioConfig(rows=32, cols=32, width=1.5, height=1.0, duration=1.0),
    _left_edge,
    _flag_control,
    _flag_origin,
    False,
)
#: The study's contact cloth: the sheet with a frictionless inclined plane in front of it.
STUDY_CONTACT = _scenario(
    "study_contact",
    "the study's sheet settling onto a frictionless plane (the study material)",
    ScenarioConfig(rows=32, cols=32, width=1.0, height=1.0, duration=10.0),
    _top_row,
    _contact_control,
    _sheet_origin,
    True,
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


@dataclass(frozen=True)
class StudyTransient:
    """A transient of the study.

    Attributes:
        name: ``swing``, ``flag`` or ``contact``.
        scenario: the :class:`~warpcloth.scenarios.common.Scenario` it runs.
        tilt: the start: the rest shape rotated this far forward about the top row [deg] (0: rest).
        static: True when only the rest shape is compared (with the float64 equilibrium).
        description: for the report.
    """

    name: str
    scenario: Scenario
    tilt: float
    static: bool
    description: str

    def start(self, model) -> np.ndarray:
        """The start positions (N, 3) float64, rounded to float32 (what the float32 runs start from)."""
        x = tilted_start(model, self.tilt) if self.tilt else model.host.q.astype(np.float64)
        return np.asarray(x, dtype=np.float32).astype(np.float64)


TRANSIENTS = {
    "swing": StudyTransient(
        "swing", STUDY_SHEET, 90.0, False, "the sheet, its top row pinned, released from horizontal (tension dominated)"
    ),
    "flag": StudyTransient("flag", STUDY_FLAG, 0.0, False, "the flag from rest in its wind (the lull, 2 m/s)"),
    "contact": StudyTransient(
        "contact",
        STUDY_CONTACT,
        CONTACT_TILT,
        True,
        f"the sheet tilted {CONTACT_TILT:g} degrees forward swings back onto a frictionless plane "
        f"inclined {CONTACT_INCLINE:g} degrees, 0.4 m below its top row, and settles on it; its rest "
        "shape against the float64 equilibrium with the contact",
    ),
}
#: The transients compared frame by frame (the others: their rest shape).
DYNAMIC = ("swing", "flag")


__all__ = [
    "CONTACT_DRAG",
    "CONTACT_INCLINE",
    "CONTACT_POINT",
    "CONTACT_THICKNESS",
    "CONTACT_TILT",
    "DYNAMIC",
    "STUDY_CONTACT",
    "STUDY_FLAG",
    "STUDY_MATERIAL",
    "STUDY_SHEET",
    "TRANSIENTS",
    "StudyTransient",
    "contact_plane",
    "material_grid_model",
    "tilted_start",
]
