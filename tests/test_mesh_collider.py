"""The static triangle-mesh collider (wp.Mesh) against exact answers: a particle dropped on a mesh
sphere's pole vertex rests at the thickness above it; a cube mesh behaves as the analytic Box (a
cloth dropped on it never goes inside, and ends where the Box's cloth ends); Coulomb friction on a
tilted quad slides at g (sin - mu cos) within 2 % and sticks when mu > tan; OBJ, TOML, CLI and USD;
bad input names the value."""

import math
import sys
from pathlib import Path

import numpy as np
import pytest

from warpcloth import Box, Control, Simulator, WarpclothError, build_grid_cloth
from warpcloth.io.meshio import load_mesh_collider
from warpcloth.sim.colliders import MeshCollider

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from helpers import free_particles, parse_collider

from bench.colliders import mesh_sphere

G = 9.81
CUBE_V = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=np.float64)
# 12 triangles wound outward (counter-clockwise seen from outside); vertex index = 4 (x>0) + 2 (y>0) + (z>0)
CUBE_T = np.array(
    [
        [0, 1, 3],
        [0, 3, 2],
        [4, 6, 7],
        [4, 7, 5],
        [0, 4, 5],
        [0, 5, 1],
        [2, 3, 7],
        [2, 7, 6],
        [0, 2, 6],
        [0, 6, 4],
        [1, 5, 7],
        [1, 7, 3],
    ]
)


def cube(center, half, **settings):
    return MeshCollider(vertices=np.asarray(center) + CUBE_V * np.asarray(half), triangles=CUBE_T, **settings)


def test_the_cube_is_wound_outward():
    tri = CUBE_V[CUBE_T]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    assert np.all(np.sum(n * tri.mean(axis=1), axis=1) > 0)


@pytest.mark.parametrize("integrator", ["explicit_euler", "rk4", "verlet", "implicit_euler", "pbd", "xpbd"])
def test_a_particle_rests_on_the_pole_of_a_mesh_sphere(integrator):
    v, t = mesh_sphere(2000, radius=0.3)
    sim = Simulator(
        free_particles([[0.0, 0.6, 0.0]]),
        integrator,
        Control(colliders=(MeshCollider(vertices=v, triangles=t, thickness=0.01),), device="cpu"),
        dt=1e-3,
    )
    sim.simulate(600)  # lands at 0.25 s
    x = sim.state.particle_q.numpy()[0]
    assert x[1] == pytest.approx(0.31, abs=1e-6) and abs(x[0]) + abs(x[2]) == 0.0


@pytest.mark.parametrize("integrator", ["explicit_euler", "implicit_euler", "pbd"])
def test_a_cube_mesh_holds_a_cloth_as_the_box_does(integrator):
    """Both sharp (edge_radius 0; rounded, the two resolve a particle in two edges' capsules at a
    corner in different orders, both out of every capsule, and this coarse drape amplifies that)."""
    edge_radius = 0.0

    def run(collider):
        model = build_grid_cloth(10, 10, 0.8, 0.8, 0.1, plane="horizontal", origin=(-0.4, 0.45, -0.4), device="cpu")
        sim = Simulator(
            model,
            integrator,
            Control(drag_rate=0.5, colliders=(collider,), device="cpu"),
            dt=1.0 / 60.0 if integrator in ("implicit_euler", "pbd") else None,
        )
        deepest, lowest_centre = -1.0, np.inf
        for _ in range(30):
            sim.simulate(max(1, round(1.0 / 60.0 / sim.dt)))
            x = sim.state.particle_q.numpy().astype(np.float64)
            inside = np.all(
                np.abs(x - (0.0, 0.2, 0.0)) < (0.25, 0.2 + 0.005, 0.25), axis=1
            )  # within the box grown by its thickness
            depth = np.min(np.abs(np.abs(x - (0.0, 0.2, 0.0)) - (0.25, 0.2 + 0.005, 0.25)), axis=1)
            deepest = max(deepest, depth[inside].max() if inside.any() else -1.0)
            lowest_centre = min(lowest_centre, x[np.argsort(np.linalg.norm(x[:, [0, 2]], axis=1))[:4], 1].min())
        return x, deepest, lowest_centre

    x_mesh, deep_mesh, centre_mesh = run(
        cube((0.0, 0.2, 0.0), (0.25, 0.2, 0.25), thickness=0.005, friction=0.3, edge_radius=edge_radius)
    )
    x_box, deep_box, _ = run(
        Box(
            center=(0.0, 0.2, 0.0),
            half_extents=(0.25, 0.2, 0.25),
            thickness=0.005,
            friction=0.3,
            edge_radius=edge_radius,
        )
    )
    assert deep_mesh < 1e-5 and deep_box < 1e-5  # never inside (by more than float32 rounding)
    assert centre_mesh == pytest.approx(
        0.405, abs=1e-5
    )  # it lands on the top face at the thickness (then the flaps bounce it)
    np.testing.assert_allclose(x_mesh, x_box, atol=2e-3)  # the same drape as the analytic box


def slide(theta, mu, duration=0.5, dt=1e-3):
    n = np.array([-math.sin(theta), math.cos(theta), 0.0])
    down = np.array([-math.cos(theta), -math.sin(theta), 0.0])
    side = np.array([0.0, 0.0, 1.0])
    quad = np.array([-5 * down - 5 * side, -5 * down + 5 * side, 5 * down + 5 * side, 5 * down - 5 * side])
    tris = np.array([[0, 1, 2], [0, 2, 3]])
    if np.dot(np.cross(quad[1] - quad[0], quad[2] - quad[0]), n) < 0:
        tris = tris[:, ::-1]
    sim = Simulator(
        free_particles([[0.0, 0.0, 0.0]]),
        "explicit_euler",
        Control(colliders=(MeshCollider(vertices=quad, triangles=tris, friction=mu),), device="cpu"),
        dt=dt,
    )
    sim.simulate(int(round(duration / dt)))
    x = sim.state.particle_q.numpy()[0].astype(np.float64)
    return float(np.dot(x, down)), float(np.dot(x, n))


def test_coulomb_friction_on_a_tilted_mesh():
    theta = math.radians(30.0)
    s, off = slide(theta, 0.3)
    assert s == pytest.approx(0.5 * G * (math.sin(theta) - 0.3 * math.cos(theta)) * 0.25, rel=0.02)
    assert abs(off) < 1e-5
    s_stick, _ = slide(theta, 0.7)
    assert abs(s_stick) < 1e-5


def test_mesh_from_obj_toml_cli_and_usd(tmp_path, capsys):
    from pxr import Usd, UsdGeom

    from warpcloth.cli import main
    from warpcloth.io.meshio import write_obj
    from warpcloth.io.usd import UsdWriter
    from warpcloth.scenarios import get_scenario

    write_obj(str(tmp_path / "table.obj"), CUBE_V * 0.3 + (0.5, -0.3, 0.5), CUBE_T)
    from_file = load_mesh_collider(str(tmp_path / "table.obj"), thickness=0.01)
    assert from_file.triangles.shape == (12, 3) and from_file.thickness == 0.01
    (tmp_path / "grid.obj").write_text("v 0 1 0\nv 1 1 0\nv 0 1 1\nv 1 1 1\nf 1 3 4 2\n")
    (tmp_path / "s.toml").write_text(
        '[cloth]\nmesh = "grid.obj"\n[[colliders]]\nkind = "mesh"\npath = "table.obj"\nfriction = 0.3\n'
    )
    (mesh,) = get_scenario(str(tmp_path / "s.toml")).build().control.colliders
    assert isinstance(mesh, MeshCollider) and mesh.friction == 0.3 and len(mesh.vertices) == 8
    assert parse_collider(f"mesh:path={tmp_path / 'table.obj'},thickness=0.002,reach=0.1").reach == 0.1
    argv = [
        "run",
        "sheet",
        "--rows",
        "6",
        "--cols",
        "6",
        "--duration",
        "0.2",
        "--collider",
        f"mesh:path={tmp_path / 'table.obj'}",
    ]
    assert main(argv) == 0, capsys.readouterr().err
    model = build_grid_cloth(4, 4, 0.5, 0.5, 0.1, plane="horizontal", device="cpu")
    with UsdWriter(str(tmp_path / "m.usda"), model, 30.0, colliders=(from_file,)) as w:
        w.write_frame(model.host.q, 0.0)
    stage = Usd.Stage.Open(str(tmp_path / "m.usda"))  # held: a prim does not keep its stage alive
    prim = UsdGeom.Mesh(stage.GetPrimAtPath("/World/Colliders/Mesh_0"))
    np.testing.assert_allclose(np.array(prim.GetPointsAttr().Get()), from_file.vertices, atol=1e-6)
    assert list(prim.GetFaceVertexIndicesAttr().Get()) == CUBE_T.reshape(-1).tolist()


@pytest.mark.parametrize(
    "make,match",
    [
        (lambda: MeshCollider(vertices=np.zeros((0, 3)), triangles=np.zeros((0, 3), int)), "mesh collider is empty"),
        (
            lambda: MeshCollider(vertices=CUBE_V, triangles=np.zeros((0, 3), int)),
            r"mesh collider is empty \(no triangles\)",
        ),
        (
            lambda: MeshCollider(vertices=CUBE_V, triangles=CUBE_T + 1),
            "vertex index .* out of range: vertices are 0..7",
        ),
        (lambda: cube((0, 0, 0), (1, 1, 1), reach=0.0), "mesh collider reach must be > 0"),
        (lambda: cube((0, 0, 0), (1, 1, 1), thickness=-1.0), "collider thickness must be >= 0"),
        (lambda: parse_collider("mesh:thickness=0.1"), "collider mesh needs path=FILE"),
        (lambda: parse_collider("mesh:path=nothing.obj"), "mesh file 'nothing.obj' does not exist"),
    ],
)
def test_bad_mesh_colliders_name_the_value(make, match):
    with pytest.raises(WarpclothError, match=match):
        make()


def test_an_empty_mesh_file_is_one_line_and_exit_2(tmp_path, capsys):
    from warpcloth.cli import main

    (tmp_path / "empty.obj").write_text("# nothing\n")
    assert main(["run", "sheet", "--collider", f"mesh:path={tmp_path / 'empty.obj'}"]) == 2
    err = capsys.readouterr().err.strip()
    assert "is empty" in err and len(err.splitlines()) == 1


# -- moving meshes (a ColliderTrack: the BVH stays in the mesh's frame, particles are taken into it)
@pytest.mark.parametrize("integrator", ["explicit_euler", "implicit_euler", "pbd"])
def test_a_sliding_mesh_ground_drags_a_particle_by_friction(integrator):
    # as the sliding Plane (tests/test_moving_colliders.py): friction accelerates the particle at
    # mu g until it moves with the ground at u: x(t) = u t - u^2 / (2 mu g)
    from warpcloth.sim.colliders import ColliderTrack

    mu, u, duration = 0.5, 0.5, 0.5
    quad = np.array(
        [[-5.0, 0.0, -5.0], [-5.0, 0.0, 5.0], [5.0, 0.0, 5.0], [5.0, 0.0, -5.0]]
    )  # counter-clockwise seen from +y
    ground = MeshCollider(
        vertices=quad, triangles=[[0, 1, 2], [0, 2, 3]], friction=mu, track=ColliderTrack.rigid(velocity=(u, 0.0, 0.0))
    )
    dt = 1.0 / 600.0 if integrator == "pbd" else 1e-3
    sim = Simulator(free_particles([[0.0, 0.0, 0.0]]), integrator, Control(colliders=(ground,), device="cpu"), dt=dt)
    sim.simulate(int(round(duration / dt)))
    x, v = sim.state.particle_q.numpy()[0], sim.state.particle_qd.numpy()[0]
    assert x[0] == pytest.approx(u * duration - u * u / (2 * mu * G), rel=0.02)  # 0.2245 m; a still mesh gives 0
    assert v[0] == pytest.approx(u, abs=1e-4)
    assert abs(x[1]) < 1e-6


@pytest.mark.parametrize("integrator", ["explicit_euler", "pbd"])
def test_a_moving_turning_cube_mesh_pushes_a_cloth_as_the_box_does(integrator):
    # a cube mesh and the analytic Box on one rigid track (sliding along +z while turning about y)
    # sweep through a cloth with no gravity: no particle ever inside the moving box, the same cloth
    from warpcloth.sim.colliders import ColliderTrack

    track = ColliderTrack.rigid(
        center=(0.5, 0.0, -0.3), axis=(0.0, 1.0, 0.0), angular_velocity=2.0, velocity=(0.0, 0.0, 1.0)
    )
    centre, half = np.array([0.5, 0.0, -0.3]), np.array([0.2, 0.2, 0.1])

    def run(collider):
        model = build_grid_cloth(9, 9, 1.0, 1.0, 0.2, plane="vertical", origin=(0.0, 0.5, 0.0), device="cpu")
        sim = Simulator(
            model,
            integrator,
            Control(gravity=(0, 0, 0), colliders=(collider,), device="cpu"),
            dt=1.0 / 600.0 if integrator == "pbd" else None,
        )
        deepest = -1.0
        for _ in range(20):
            sim.simulate(max(1, round(0.025 / sim.dt)))
            r, c, d = track.transform(sim.sim_time)
            local = (
                sim.state.particle_q.numpy().astype(np.float64) - (c + d + r @ (centre - c))
            ) @ r  # into the box's frame
            depth = np.min(half + 0.005 - np.abs(local), axis=1)  # > 0: inside the box grown by the thickness
            deepest = max(deepest, depth.max())
        return sim.state.particle_q.numpy().astype(np.float64), deepest

    x_mesh, deep_mesh = run(cube(centre, half, thickness=0.005, friction=0.3, track=track, edge_radius=0.0))
    x_box, deep_box = run(
        Box(center=tuple(centre), half_extents=tuple(half), thickness=0.005, friction=0.3, track=track, edge_radius=0.0)
    )  # both sharp
    assert deep_mesh < 1e-4 and deep_box < 1e-4  # never inside the moving box (beyond a step's rounding)
    assert (
        np.abs(x_box - x_mesh).max() < 3e-3
    )  # the same sweep as the analytic box (pbd: 2.4 mm of a 0.7 m sweep, float32 frame changes)
    assert np.abs(x_box[:, 2]).max() > 0.1  # and it did push the cloth


@pytest.mark.parametrize("thickness", [0.0, 0.01])
def test_a_particle_rests_on_a_flat_mesh_floor(thickness):
    # a flat quad has a bounding box of no height: the box test must still find a particle that
    # went up to reach below it (it used to let it fall through when thickness = 0)
    quad = np.array([[-1.0, 0.0, -1.0], [-1.0, 0.0, 1.0], [1.0, 0.0, 1.0], [1.0, 0.0, -1.0]])
    floor = MeshCollider(vertices=quad, triangles=[[0, 1, 2], [0, 2, 3]], thickness=thickness)
    sim = Simulator(
        free_particles([[0.1, 0.2, 0.0]]), "explicit_euler", Control(colliders=(floor,), device="cpu"), dt=1e-3
    )
    sim.simulate(400)  # lands at 0.2 s
    assert sim.state.particle_q.numpy()[0, 1] == pytest.approx(thickness, abs=1e-6)


def test_a_cube_mesh_rounds_its_edges_as_the_box_does():
    """Free particles around a cube, outside it, away from its corners: one step of a cube mesh with
    edge_radius 7.5 cm puts each where the analytic box with the same radius does (its 12 edges are the
    mesh's sharp convex creases; its faces' diagonals are not)."""
    from warpcloth.sim.colliders import box_edge_distance, signed_distance

    centre, half = np.array([0.0, 0.2, 0.0]), np.array([0.25, 0.2, 0.25])
    box = Box(center=tuple(centre), half_extents=tuple(half), thickness=0.005, edge_radius=0.075)
    x = centre + np.random.default_rng(1).uniform(-1.0, 1.0, (4000, 3)) * (half + 0.08)
    x = x[
        (signed_distance(box, x) > 0.0) & (np.linalg.norm(np.abs(x - centre) - half, axis=1) > 0.12)
    ]  # 12 cm from a corner
    ends = []
    for collider in (cube(centre, half, thickness=0.005, edge_radius=0.075), box):
        sim = Simulator(
            free_particles(x), "explicit_euler", Control(gravity=(0, 0, 0), colliders=(collider,), device="cpu")
        )
        sim.simulate(1)
        ends.append(sim.state.particle_q.numpy().astype(np.float64))
    held = np.linalg.norm(ends[1] - x, axis=1) > 1e-6
    assert held.sum() > 200 and (box_edge_distance(box, x[held]) < 0.075).sum() > 100  # the capsules held many
    np.testing.assert_allclose(ends[0], ends[1], atol=1e-5)


@pytest.mark.parametrize("edge_radius,clean", [(None, True), (0.0, False)])
def test_no_cube_mesh_edge_passes_through_a_cloth_draped_over_it(edge_radius, clean):
    """A 10 x 10 cloth dropped over a cube mesh (explicit Euler, 1 s): with the edges rounded for the
    cloth (the default) no cube edge crosses a cloth triangle at any frame; sharp, one does."""
    from warpcloth.lab import intersections as ix

    model = build_grid_cloth(10, 10, 0.8, 0.8, 0.1, plane="horizontal", origin=(-0.4, 0.45, -0.4), device="cpu")
    mesh = cube((0.0, 0.2, 0.0), (0.25, 0.2, 0.25), thickness=0.005, friction=0.3, edge_radius=edge_radius)
    sim = Simulator(model, "explicit_euler", Control(drag_rate=0.5, colliders=(mesh,), device="cpu"))
    worst = 0
    for _ in range(60):
        sim.simulate(max(1, round(1.0 / 60.0 / sim.dt)))
        worst = max(worst, ix.collider_edge_crossings(sim.state.particle_q.numpy(), model.host.tris, [mesh]))
    assert (worst == 0) is clean, worst


def test_only_a_meshs_sharp_convex_creases_and_open_edges_are_rounded():
    """A cube's 12 edges (not its faces' diagonals); a flat quad's 4 open edges; the valley of an L-shaped
    step (a concave crease) and a fine mesh sphere's blunt edges (a few degrees) none; vertices copied at
    one place (a triangle soup) count once."""
    from warpcloth.sim.contacts import _convex_edges

    assert len(_convex_edges(CUBE_V, CUBE_T)) == 12
    quad = np.array([[0, 0, 0], [1, 0, 0], [1, 0, 1], [0, 0, 1]], float)
    assert len(_convex_edges(quad, [[0, 2, 1], [0, 3, 2]])) == 4
    v, t = mesh_sphere(2000, radius=0.3)
    assert len(_convex_edges(v, t)) == 0
    # a step: floor at y = 0 (x < 0), wall x = 0 up to y = 1, top at y = 1 (x > 0), as one open strip
    # (z in [0, 1]): the floor-wall edge is a valley, the wall-top edge a convex crease
    p = np.array([[-1, 0, 0], [-1, 0, 1], [0, 0, 0], [0, 0, 1], [0, 1, 0], [0, 1, 1], [1, 1, 0], [1, 1, 1]], float)
    tris = [[0, 1, 3], [0, 3, 2], [2, 3, 5], [2, 5, 4], [4, 5, 7], [4, 7, 6]]
    edges = {tuple(e) for e in _convex_edges(p, tris).tolist()}
    assert (4, 5) in edges and (2, 3) not in edges
    # a triangle soup (each triangle its own three vertices) and a UV sphere's seam of copies: the same edges
    soup = CUBE_V[CUBE_T].reshape(-1, 3)
    assert len(_convex_edges(soup, np.arange(len(soup)).reshape(-1, 3))) == 12
    assert len(_convex_edges(v[t].reshape(-1, 3), np.arange(t.size).reshape(-1, 3))) == 0
