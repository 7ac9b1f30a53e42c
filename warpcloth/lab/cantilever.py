"""The cantilever bending test as a simulation (Peirce 1930; ASTM D1388): a strip clamped horizontally
at one end sags under its weight; at rest its tip drop is compared with the inextensible elastica's
(:mod:`warpcloth.sim.elastica`). docs/materials.md, "Dihedral bending".

The strip is a 2 x ``cols`` grid in the horizontal x-z plane with dihedral hinges (``bend="dihedral"``)
of rigidity B, masses by vertex area (rho times the area: the tip column carries half a column's
load), clamped by pinning its first two columns. The clamp sits midway between the two pinned
columns, where the pinned segment's zero slope is defined, so the overhang is L = (cols - 1.5) h:
measured so, the discrete strip's static drop is the elastica's to O(h^2) (from the second column it
would be off by O(h); docs/materials.md, "The cantilever test").
Membrane springs (ks = 1000 N/m, the default damping ratio) keep the strain ~ 1e-3. Air drag
c = 2 omega_1 (omega_1 = 3.516 sqrt(B / (rho L^4)), the small-load strip's first mode) brings it to
rest in about 0.5 s without moving the static answer.
"""

from __future__ import annotations

import math

import numpy as np

from warpcloth.errors import require_int, require_positive
from warpcloth.sim.control import Control
from warpcloth.sim.elastica import tip_deflection
from warpcloth.sim.grid import build_grid_cloth
from warpcloth.sim.model import default_spring_params
from warpcloth.simulator import Simulator

#: Cotton (warpcloth.sim.material PRESETS["cotton"]): areal density [kg/m^2] and bending rigidity [N m].
COTTON_DENSITY, COTTON_RIGIDITY = 0.220, 31.4e-6
GRAVITY = 9.81


def cantilever_strip(
    integrator,
    cols: int = 32,
    overhang: float = 0.05,
    width: float = 0.01,
    rows: int = 2,
    density: float = COTTON_DENSITY,
    rigidity: float = COTTON_RIGIDITY,
    stiffness: float = 1000.0,
    drag: float | None = None,
    dt: float | None = None,
    device: str = "cpu",
) -> Simulator:
    """A :class:`~warpcloth.simulator.Simulator` of the clamped strip (module docstring).

    Args:
        integrator: an integrator or its name.
        cols: particles along the strip (>= 4); overhang: L [m] from the clamp to the tip; width [m];
            rows: particles across it (>= 2; a wide strip bends as a beam: the grid hinges' plate has no
            Poisson coupling).
        density: rho [kg/m^2]; rigidity: B [N m]; stiffness: ks of the membrane springs [N/m].
        drag: air drag rate [1/s] (default 2 omega_1); dt: time step [s] (default the integrator's).
    """
    cols, rows = require_int("cols", cols, 4), require_int("rows", rows, 2)
    overhang, width = require_positive("overhang", overhang, "m"), require_positive("width", width, "m")
    density, rigidity = require_positive("density", density, "kg/m^2"), require_positive("rigidity", rigidity, "N m")
    h = overhang / (cols - 1.5)
    length = h * (cols - 1)
    mass = density * length * width
    pins = [r * cols + c for r in range(rows) for c in (0, 1)]
    params = default_spring_params(mass / (rows * cols), stiffness)
    model = build_grid_cloth(
        rows,
        cols,
        length,
        width,
        mass,
        spring_params=params,
        pins=pins,
        plane="horizontal",
        bend="dihedral",
        bend_rigidity=rigidity,
        mass_mode="area",
        device=device,
    )
    if drag is None:
        drag = 2.0 * first_mode(overhang, rigidity, density)
    return Simulator(model, integrator, Control(drag_rate=drag, device=device), dt=dt)


def first_mode(overhang: float, rigidity: float, density: float) -> float:
    """omega_1 = 3.516 sqrt(B / (rho L^4)) [rad/s], the small-load cantilever's first bending mode."""
    return 3.516 * math.sqrt(rigidity / (density * overhang**4))


def strip_tip_drop(sim: Simulator) -> float:
    """The tip's drop below the clamp [m] (the mean over the strip's rows)."""
    rows, cols = sim.model.rows, sim.model.cols
    y = sim.state.particle_q.numpy().astype(np.float64)[:, 1].reshape(rows, cols)
    return float(y[:, 0].mean() - y[:, -1].mean())


def elastica_tip_drop(
    overhang: float = 0.05, rigidity: float = COTTON_RIGIDITY, density: float = COTTON_DENSITY
) -> float:
    """The inextensible elastica's tip drop [m] for the strip."""
    return tip_deflection(overhang, rigidity, density * GRAVITY)[0]


__all__ = ["COTTON_DENSITY", "COTTON_RIGIDITY", "cantilever_strip", "elastica_tip_drop", "first_mode", "strip_tip_drop"]
