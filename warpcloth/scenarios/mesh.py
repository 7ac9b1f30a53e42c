"""A cloth from a triangle mesh: ``warpcloth run mesh --mesh cape.obj --pin-group shoulders``
(or ``--pin 'y > 0.95'``). Without ``--mesh`` it is the built-in cape (:func:`make_cape`, also
written to ``examples/cape.obj`` by ``examples/make_cape.py``) pinned by its ``shoulders`` group.

A mesh given with ``--mesh`` is pinned by ``--pin-group`` and ``--pin`` only (no pin: it falls).
Gravity and air drag; a run ends at equilibrium.
"""

from __future__ import annotations

import math

import numpy as np

from warpcloth.io.meshio import load_mesh
from warpcloth.scenarios.common import Scenario, ScenarioConfig, check_rigidity, scenario_material
from warpcloth.sim.control import Control
from warpcloth.sim.grid import grid_triangles
from warpcloth.sim.material import material_mesh_cloth
from warpcloth.sim.mesh import TriangleMesh, build_mesh_cloth

CAPE_ROWS, CAPE_COLS = 20, 16


def make_cape(rows: int = CAPE_ROWS, cols: int = CAPE_COLS) -> TriangleMesh:
    """A cape hanging behind a body: a grid wrapped around a vertical axis, 0.9 m long, widening
    from a 0.18 m radius at the neck (y = 1.5 m) to 0.35 m at the hem, triangulated two
    triangles per cell; vertex group ``shoulders`` = its top two rows; UVs u = col/(cols-1),
    v = 1 - row/(rows-1)."""
    r, c = np.meshgrid(np.arange(rows), np.arange(cols), indexing="ij")
    s, u = r.ravel() / (rows - 1), c.ravel() / (cols - 1)
    radius = 0.18 + (0.35 - 0.18) * s
    phi = 0.8 * math.pi * (u - 0.5)
    q = np.stack([radius * np.sin(phi), 1.5 - 0.9 * s, -radius * np.cos(phi)], axis=1)
    uv = np.stack([u, 1.0 - s], axis=1)
    tris = grid_triangles(rows, cols).astype(np.int64)
    return TriangleMesh(
        vertices=q, triangles=tris, uv=uv[tris], groups={"shoulders": np.arange(2 * cols)}, source="built-in cape"
    )


def _model(config: ScenarioConfig, device: str):
    mesh = load_mesh(config.mesh, config.prim) if config.mesh else make_cape()
    groups, where = config.pin_group, config.pin_where
    if not config.mesh and groups is None and where is None:
        groups = ("shoulders",)
    mat = scenario_material(config)
    if mat is not None:
        return material_mesh_cloth(
            mat,
            mesh,
            pin_groups=groups or (),
            pin_where=where,
            quads=bool(config.quads),
            bend=config.bend,
            device=device,
        )
    check_rigidity(config.bend_rigidity)
    return build_mesh_cloth(
        mesh,
        total_mass=config.mass,
        stiffness=config.stiffness,
        damping=config.damping,
        pin_groups=groups or (),
        pin_where=where,
        quads=bool(config.quads),
        bend=config.bend,
        bend_rigidity=config.bend_rigidity,
        device=device,
    )


def _control(config: ScenarioConfig, device: str) -> Control:
    return Control(drag_rate=1.0 if config.drag is None else config.drag, device=device)


SCENARIO = Scenario(
    name="mesh",
    description="a cloth from a triangle mesh (--mesh FILE.obj|.usd, --pin-group, --pin); default the built-in cape; "
    "runs to equilibrium",
    defaults=ScenarioConfig(rows=1, cols=CAPE_ROWS * CAPE_COLS, mass=0.3, duration=10.0, quads=True),
    pins=lambda rows, cols: [],
    control=_control,
    origin=lambda config: (0.0, 0.0, 0.0),
    stop_at_equilibrium=True,
    model=_model,
)


def build(**overrides):
    """A Simulator of the mesh scenario with the defaults and ``overrides`` (see ScenarioConfig)."""
    return SCENARIO.build(**overrides)
