"""A cape and a skirt on an animated body: ``warpcloth run character --usd c.usdc --html c.html``.

The body is the procedural :class:`~warpcloth.sim.mannequin.Mannequin` (capsules skinned to 11
bones, marching in place and turning), a deforming mesh collider on MeshTrack keyframes at the run's
fps. Two garments of two materials in one model (:class:`~warpcloth.sim.builder.ClothBuilder`): a
cape (the run's material, cotton by default) of rows x cols hanging behind the shoulders, and a
skirt (:data:`SKIRT_MATERIAL`) flaring from the waist, a tube of ``rows`` rings of ``2 * cols``
vertices. Their top rows are pinned with :func:`~warpcloth.sim.colliders.attach` to the
body's skin moved :data:`BAND` out along its normals (skinned as the body), so the pins ride the
moving body while each pinned row's edges stay off the skin. Self-collision is on (both garments in
one collision group: the cape's hem meets the skirt). xpbd at 1 iteration x 32 substeps (the fidelity
rule in motion, :data:`XPBD`): on the CPU a deforming collider runs plain launches, so a frame costs its
substeps' launches. The run lasts its
duration (no equilibrium: the body keeps moving). docs/character.md.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from warpcloth.errors import WarpclothError, require_int
from warpcloth.scenarios.common import Scenario, ScenarioConfig, scenario_material
from warpcloth.sim.builder import ClothBuilder
from warpcloth.sim.colliders import attach, closest_surface_points
from warpcloth.sim.control import Control
from warpcloth.sim.grid import grid_triangles
from warpcloth.sim.mannequin import Mannequin
from warpcloth.sim.mesh import TriangleMesh

#: The skirt's material (the cape's is the run's, ``--material``, cotton by default).
SKIRT_MATERIAL = "silk"
#: The body's contact offset [m], friction, and how far inside a vertex is still found [m]. Its
#: creases are sharp (edge_radius 0): a faceted smooth body has a convex crease at every edge, and
#: rounding them by the cloth's triangle size would inflate the whole body by that much.
THICKNESS = 0.015
FRICTION = 0.5
REACH = 0.06
#: The distance self-collision keeps between the garments' layers [m]: at the default 5 mm the cape's
#: second row folded through its pinned row and the skirt's hem through itself in a few frames; at 1 cm
#: the skirt, pressed by a lifting knee, still folded through itself in 8 of 181 frames (docs/character.md).
SELF_THICKNESS = 0.015
#: How far off the skin the garments' pinned rows ride [m] (a waistband, a collar).
BAND = 0.02
#: Cape: its top arc's height, radius about the body's axis and half-angle; its length; its hem radius.
#: The top arc lies on the band (the torso's top moved BAND out is 0.125 m round at y = 1.4 m).
CAPE_TOP, CAPE_RADIUS, CAPE_ANGLE, CAPE_LENGTH, CAPE_HEM = 1.4, 0.125, math.radians(40.0), 0.55, 0.3
#: Skirt: its waist's height and radius, its length and its hem's radius [m].
SKIRT_TOP, SKIRT_WAIST, SKIRT_LENGTH, SKIRT_HEM = 1.03, 0.14 + BAND, 0.5, 0.38

#: The solver: the cheapest configuration measured to meet the fidelity rule in motion (docs/materials.md, each
#: garment's peak strain at most 2 % above the converged dynamics', xpbd 1 x 128 and 1 x 256) by more than the
#: skirt's reference spread (0.58 % and 1.06 %), with no intersection over 3 s. At 16 x 16, 1.5 s: 1 x 32 peaks
#: cape 0.95 %, skirt 1.41 % (+0.14, +0.83 over 1 x 128's), 233 ms/frame; 2 x 16 cape 2.14 %, skirt 2.54 % (+1.95:
#: 0.05 from the bound, inside that spread: undecided), 160 ms; 1 x 16 skirt 3.02 % (+2.44: fails), 161 ms; vbd and
#: projective meet at 1.5 s but self-intersect (vbd, from 1.7 s) or go unstable (projective, 2.8 s) within
#: 3 s; implicit Euler hits its strain cap. `python bench/fidelity.py --scenes character --moving --size 16
#: --duration 1.5`, then `warpcloth run character -i NAME --usd c.usdc` and `warpcloth check-intersections`.
XPBD = {"iterations": 1, "substeps": 32}


def make_cape(rows: int, cols: int) -> TriangleMesh:
    """The cape: rows x cols vertices behind the body (-z), its top row an arc of radius
    :data:`CAPE_RADIUS` at y = :data:`CAPE_TOP`, its radius growing as the square root of the
    distance down to :data:`CAPE_HEM` at the hem (clear of the back at once); two triangles per cell;
    vertex group ``top`` = its first row; texture coordinates u around, v down."""
    r, c = np.meshgrid(np.arange(rows), np.arange(cols), indexing="ij")
    s, u = r.ravel() / (rows - 1), c.ravel() / (cols - 1)
    radius = CAPE_RADIUS + (CAPE_HEM - CAPE_RADIUS) * np.sqrt(s)  # flaring fast off the back, then hanging
    phi = CAPE_ANGLE * (2.0 * u - 1.0)
    q = np.stack([radius * np.sin(phi), CAPE_TOP - CAPE_LENGTH * s, -radius * np.cos(phi)], axis=1)
    tris = np.asarray(grid_triangles(rows, cols), dtype=np.int64)
    uv = np.stack([u, 1.0 - s], axis=1)[tris]  # warp along u (around), weft along v (down)
    return TriangleMesh(vertices=q, triangles=tris, uv=uv, groups={"top": np.arange(cols)}, source="cape")


def tube(rings: int, around: int, top: float, bottom: float, length: float):
    """A closed tube about +y hanging from y = 0 (a cone where the radii ``top`` != ``bottom``) [m]: ``rings``
    rings of ``around`` vertices, two triangles per quad, uv per corner with u around (the seam's corners
    take u = 1, not 0) and v down: (vertices, triangles, uv)."""
    r, c = np.meshgrid(np.arange(rings), np.arange(around), indexing="ij")
    s, phi = r.ravel() / (rings - 1), 2.0 * math.pi * c.ravel() / around
    radius = top + (bottom - top) * s
    q = np.stack([radius * np.sin(phi), -length * s, radius * np.cos(phi)], axis=1)
    tris, uv = [], []
    for i in range(rings - 1):
        v0, v1 = 1.0 - i / (rings - 1), 1.0 - (i + 1) / (rings - 1)
        for j in range(around):
            k = (j + 1) % around
            a, b, c2, d = i * around + j, i * around + k, (i + 1) * around + k, (i + 1) * around + j
            u0, u1 = j / around, (j + 1) / around
            tris += [(a, c2, b), (a, d, c2)]
            uv += [[(u0, v0), (u1, v1), (u1, v0)], [(u0, v0), (u0, v1), (u1, v1)]]
    return q, np.asarray(tris, dtype=np.int64), np.asarray(uv)


def make_skirt(rings: int, around: int) -> TriangleMesh:
    """The skirt: a closed tube of ``rings`` rings of ``around`` vertices, from the waist (radius
    :data:`SKIRT_WAIST` at y = :data:`SKIRT_TOP`) to the hem (:data:`SKIRT_HEM`, :data:`SKIRT_LENGTH`
    lower); vertex group ``waist`` = its first ring."""
    q, tris, uv = tube(rings, around, SKIRT_WAIST, SKIRT_HEM, SKIRT_LENGTH)
    return TriangleMesh(
        vertices=q + [0.0, SKIRT_TOP, 0.0], triangles=tris, uv=uv, groups={"waist": np.arange(around)}, source="skirt"
    )


def garment_sizes(config: ScenarioConfig) -> tuple[tuple[int, int], tuple[int, int]]:
    """((cape rows, cols), (skirt rings, around)) of a configuration's rows and cols (each at least 3);
    the garments' sizes are the body's, so a width or height other than 1 is refused."""
    rows, cols = require_int("rows", config.rows, 3), require_int("cols", config.cols, 3)
    if (config.width, config.height) != (1.0, 1.0):
        raise WarpclothError(
            f"the character's garments are cut to the body: --width and --height do not apply (got "
            f"{config.width:g} x {config.height:g}); --rows and --cols set their resolution"
        )
    return (rows, cols), (rows, 2 * cols)


def _body() -> Mannequin:
    return Mannequin.build()


def on_band(mesh: TriangleMesh, group: str, body: Mannequin) -> TriangleMesh:
    """``mesh`` with its vertex group ``group`` moved to the nearest points of the body's skin
    :data:`BAND` out (where :func:`attach` will tie them): the garment's rest shape starts there, so
    the pins do not jump at the first step."""
    band = body.offset(BAND)
    idx = mesh.groups[group]
    faces, weights = closest_surface_points(band, body.triangles, mesh.vertices[idx])
    q = np.array(mesh.vertices, dtype=np.float64)
    q[idx] = np.einsum("pj,pjc->pc", weights, band[body.triangles[faces]])
    return replace(mesh, vertices=q)


def _model(config: ScenarioConfig, device: str):
    (rows, cols), (rings, around) = garment_sizes(config)
    cape = scenario_material(config)
    if cape is None:
        raise WarpclothError(
            "the character scene's garments are made of materials: give the cape's --material as a preset "
            "(or custom), not none"
        )
    body = _body()
    b = ClothBuilder()
    common = {"quads": True, "bend": config.bend}
    b.add_mesh(on_band(make_cape(rows, cols), "top", body), material=cape, pin_groups=["top"], name="cape", **common)
    skirt = on_band(make_skirt(rings, around), "waist", body)
    b.add_mesh(skirt, material=SKIRT_MATERIAL, pin_groups=["waist"], name="skirt", **common)
    return b.finalize(device)


def _control(config: ScenarioConfig, device: str) -> Control:
    body = _body().collider(
        config.duration, config.fps, thickness=THICKNESS, friction=FRICTION, reach=REACH, edge_radius=0.0
    )
    return Control(colliders=(body,), drag_rate=0.5 if config.drag is None else config.drag, device=device)


def _tracks(config: ScenarioConfig, model) -> list:
    """The pinned rows tied to the skin moved :data:`BAND` out (found at rest, :func:`attach`)."""
    body = _body()
    band = body.collider(config.duration, config.fps, vertices=body.offset(BAND))
    q = model.host.q
    return [attach(band, q, np.asarray(model.pinned)[_in(model, p)], name=p.name) for p in model.pieces]


def _in(model, piece) -> np.ndarray:
    pinned = np.asarray(model.pinned)
    return (pinned >= piece.particle_offset) & (pinned < piece.particle_offset + piece.particle_count)


SCENARIO = Scenario(
    name="character",
    description="a cape (cotton) and a skirt (silk) pinned to an animated body (a skinned mannequin marching "
    "in place and turning, a deforming mesh collider); runs its duration",
    defaults=ScenarioConfig(
        rows=16,
        cols=16,
        width=1.0,
        height=1.0,
        duration=3.0,
        material="cotton",
        integrator="xpbd",
        self_collision_thickness=SELF_THICKNESS,
    ),
    pins=lambda rows, cols: [],
    control=_control,
    origin=lambda config: (0.0, 0.0, 0.0),
    stop_at_equilibrium=False,
    model=_model,
    tracks=_tracks,
    kind="grid",
    self_collision=True,
    integrator_defaults={"xpbd": XPBD},
)


def build(**overrides):
    """A Simulator of the character scene with the defaults and ``overrides`` (see ScenarioConfig)."""
    return SCENARIO.build(**overrides)
