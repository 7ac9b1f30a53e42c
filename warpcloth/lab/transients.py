"""The study's cloth and its transients (design.md, "Accuracy and the study"; docs/study.md).

**One cloth at every size.** The sheet, the flag and the contact cloth are the study's cloth,
:data:`~warpcloth.scenarios.swing.STUDY_MATERIAL` at every n x n
(:func:`~warpcloth.scenarios.swing.study_scenario`); the swing's sheet and its start from
horizontal are the ``swing`` scenario's (:mod:`warpcloth.scenarios.swing`), so that
``warpcloth run swing`` runs what the study measured.

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
from dataclasses import dataclass

import numpy as np

from warpcloth.scenarios.common import Scenario, ScenarioConfig
from warpcloth.scenarios.flag import GUST, GUST_OFF, GUST_ON, LULL, WIND_COEFFICIENT
from warpcloth.scenarios.swing import (
    STUDY_SHEET,
    SWING_TILT,
    sheet_origin,
    study_scenario,
    tilted_start,
    top_row,
)
from warpcloth.sim.colliders import Plane
from warpcloth.sim.control import Control, WindSchedule

#: The plane of the contact transient: through CONTACT_POINT [m], inclined CONTACT_INCLINE [deg]
#: from the vertical (its outward normal (0, sin, cos)), thickness [m]; frictionless.
CONTACT_POINT = (0.0, 1.6, 0.0)
CONTACT_INCLINE = 20.0
CONTACT_THICKNESS = 0.005
#: The contact transient's start: the sheet rotated this far forward about its top row [deg].
CONTACT_TILT = 30.0
#: Air drag of the contact transient [1/s]: the equilibrium does not depend on it; it brings the
#: sheet to rest within seconds (a time constant of 0.25 s).
CONTACT_DRAG = 4.0


def _left_edge(rows: int, cols: int) -> list:
    return [r * cols for r in range(rows)]


def _flag_origin(cfg) -> tuple:
    return (0.0, 2.0, 0.0)


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


#: The study's flag: 1.5 m x 1 m of the study's cloth on its pole (left edge), in the flag's wind.
STUDY_FLAG = study_scenario(
    "study_flag",
    "the study's flag: its left edge pinned, in gusting wind (the study material)",
    ScenarioConfig(rows=32, cols=32, width=1.5, height=1.0, duration=1.0),
    _left_edge,
    _flag_control,
    _flag_origin,
    False,
)
#: The study's contact cloth: the sheet with a frictionless inclined plane in front of it.
STUDY_CONTACT = study_scenario(
    "study_contact",
    "the study's sheet settling onto a frictionless plane (the study material)",
    ScenarioConfig(rows=32, cols=32, width=1.0, height=1.0, duration=10.0),
    top_row,
    _contact_control,
    sheet_origin,
    True,
)


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
        "swing",
        STUDY_SHEET,
        SWING_TILT,
        False,
        "the sheet, its top row pinned, released from horizontal (tension dominated)",
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
    "TRANSIENTS",
    "StudyTransient",
    "contact_plane",
]
