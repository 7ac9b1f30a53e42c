"""Day-one inputs: a cloth that starts inside a collider gets one warning line before the run
(how many vertices, which collider), an unstable run's summary always says why, and a mesh file
with loose vertices is read without them (one note line)."""

import numpy as np
import pytest

from warpcloth import Box, Capsule, Control, Plane, Sphere, WarpclothError
from warpcloth.cli import main
from warpcloth.sim.colliders import signed_distance
from warpcloth.sim.contacts import starting_inside


def test_host_signed_distances_are_exact():
    x = np.array([[0.0, 0.0, 0.0], [0.0, 2.0, 0.0], [3.0, 0.0, 0.0]])
    assert np.allclose(signed_distance(Sphere(center=(0, 0, 0), radius=1.0), x), [-1.0, 1.0, 2.0])
    assert np.allclose(signed_distance(Plane(point=(0, 1, 0)), x), [-1.0, 1.0, -1.0])
    assert np.allclose(signed_distance(Capsule(a=(-1, 0, 0), b=(1, 0, 0), radius=0.5), x), [-0.5, 1.5, 1.5])
    # a box turned 90 degrees about z: its long x side now lies along y
    box = Box(center=(0, 0, 0), half_extents=(2.0, 0.5, 0.5), rotation=(0, 0, np.sin(np.pi / 4), np.cos(np.pi / 4)))
    assert np.allclose(signed_distance(box, x), [-0.5, -0.0, 2.5], atol=1e-12)


def test_vertices_inside_are_counted_per_collider():
    points = np.array([[0.0, 0.1, 0.0], [0.0, 0.5, 0.0], [5.0, 0.5, 0.0], [0.0, -0.1, 0.0]])
    free = np.array([True, True, True, False])  # the pinned one is not counted
    found = starting_inside((Plane(), Sphere(center=(0, 0, 0), radius=0.3)), points, free)
    assert [(k, n) for k, _, n in found] == [(1, 1)] and "sphere at (0, 0, 0), radius 0.3" in found[0][1]


def test_a_cloth_started_inside_a_sphere_is_warned_before_the_run_and_its_failure_explained(capsys):
    # the drape's cloth (y = 0.75) inside a sphere of radius 0.5 at y = 0.4; a low instability
    # strain makes the push-out an instability: the summary names the collider as the cause
    code = main(
        [
            "run",
            "drape",
            "--size",
            "8",
            "--num-frames",
            "5",
            "--collider",
            "sphere:center=0/0.4/0,radius=0.5",
            "--instability-strain",
            "0.01",
        ]
    )
    out, err = capsys.readouterr()
    assert code == 0
    warning = [line for line in err.splitlines() if "start inside" in line]
    assert len(warning) == 1 and warning[0].startswith("warpcloth: warning: ")
    assert "of 64 free cloth vertices start inside collider 2 (sphere at (0, 0.4, 0), radius 0.5)" in warning[0]
    assert "stable: NO (" in out and "started inside collider 2 (sphere" in out


def test_an_unstable_run_without_colliders_names_the_time_step(capsys):
    code = main(["run", "sheet", "--size", "8", "--num-frames", "5", "--dt", "0.01"])
    out, err = capsys.readouterr()
    assert code == 0 and "stable: NO (" in out and "start inside" not in err
    assert "the likeliest cause is the time step: dt = 0.01 s for explicit_euler" in out and "warpcloth max-dt" in out


# -- loose vertices (faces deleted in a DCC): dropped with a one-line note, not refused ---------------
LOOSE_OBJ = """# a quad whose third and sixth vertices lost their faces
v 0 0 0
v 1 0 0
v 5 5 5
v 1 1 0
v 0 1 0
v 7 7 7
vt 0 0
vt 1 0
vt 1 1
vt 0 1
g top
f 1/1 2/2 4/3
g rest
f 1/1 4/3 5/4
"""


def test_loose_vertices_of_an_obj_are_dropped_with_one_note(tmp_path, capsys):
    from warpcloth.io.meshio import load_mesh

    path = tmp_path / "loose.obj"
    path.write_text(LOOSE_OBJ)
    mesh = load_mesh(str(path))
    err = [line for line in capsys.readouterr().err.splitlines() if "CUDA" not in line]
    assert (
        len(err) == 1
        and err[0].startswith("warpcloth: note: mesh ")
        and "loose.obj: 2 vertices in no face dropped (3, 6," in err[0]
    )
    assert "use the other 4" in err[0]
    assert mesh.vertices.tolist() == [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]]
    # the triangles are the file's faces on the renumbered vertices, the groups follow
    assert mesh.vertices[mesh.triangles].tolist() == [
        [[0, 0, 0], [1, 0, 0], [1, 1, 0]],
        [[0, 0, 0], [1, 1, 0], [0, 1, 0]],
    ]
    assert {k: v.tolist() for k, v in mesh.groups.items()} == {"top": [0, 1, 2], "rest": [0, 2, 3]}
    assert mesh.loose.tolist() == [2, 5] and mesh.uv.shape == (2, 3, 2)
    assert mesh.file_indices([4, 0]) == [3, 0]  # the file's vertex 4 (0-based) is the mesh's 3
    with pytest.raises(WarpclothError, match="vertex 2 belongs to no face"):
        mesh.file_indices([2])


def test_a_mesh_run_and_a_scenario_file_use_the_mesh_without_its_loose_vertices(tmp_path, capsys):
    from pxr import Usd, UsdGeom

    (tmp_path / "loose.obj").write_text(LOOSE_OBJ)
    usd = tmp_path / "out.usda"
    code = main(
        ["run", "mesh", "--mesh", str(tmp_path / "loose.obj"), "--pin", "y > 0.5", "--num-frames", "1"]
        + ["--usd", str(usd)]
    )
    out, err = capsys.readouterr()
    assert code == 0 and "2 vertices in no face dropped" in err
    # a mesh has no rows and columns: its summary names its vertices and triangles (it printed 1x4)
    assert "mesh: explicit_euler on cpu, 4 vertices, 2 triangles (" in out and "1x4" not in out, out
    stage = Usd.Stage.Open(str(usd))  # kept: a prim of a stage that is gone is invalid
    points = UsdGeom.Mesh(stage.GetPrimAtPath("/World/Cloth")).GetPointsAttr()
    assert len(points.Get(points.GetTimeSamples()[0])) == 4
    # a scenario file's indices number the file's vertices: 4 (0-based) is (0, 1, 0), the mesh's 3
    scenario = tmp_path / "loose.toml"
    scenario.write_text('[cloth]\nmesh = "loose.obj"\n[pins]\nindices = [4]\n[run]\nduration = 0.05\n')
    from warpcloth.scenarios import get_scenario

    sim = get_scenario(str(scenario)).build()
    assert sim.model.host.q[sim.model.pinned].tolist() == [[0.0, 1.0, 0.0]]
    scenario.write_text('[cloth]\nmesh = "loose.obj"\n[pins]\nindices = [2]\n')
    capsys.readouterr()
    with pytest.raises(SystemExit) as exc:
        raise SystemExit(main(["run", str(scenario)]))
    lines = capsys.readouterr().err.splitlines()
    err = [line for line in lines if line.startswith("warpcloth:") and not line.startswith("warpcloth: note:")]
    assert exc.value.code == 2 and len(err) == 1
    assert "loose.toml: pins.indices: vertex 2 belongs to no face" in err[0], err


def test_a_cloth_starting_within_a_boxs_rounded_edge_is_warned_of(capsys):
    """A 9 x 9 cloth (10 cm spacing: the box's automatic edge radius 8.5 cm) laid 5 mm over a box
    whose edge runs under it: one warning names the box and the radius; the same cloth 20 cm up: none."""
    from warpcloth import Simulator, build_grid_cloth
    from warpcloth.run.harness import RunHarness

    box = Box(center=(0.0, 0.0, 0.0), half_extents=(0.25, 0.1, 0.25))
    for height, warned in ((0.105, True), (0.3, False)):
        model = build_grid_cloth(9, 9, 0.8, 0.8, 0.1, plane="horizontal", origin=(-0.4, height, -0.4), device="cpu")
        sim = Simulator(model, "explicit_euler", Control(colliders=(box,), device="cpu"))
        RunHarness(sim).run(0.01)
        err = capsys.readouterr().err
        lines = [line for line in err.splitlines() if "start within the rounded edges" in line]
        if warned:
            assert (
                len(lines) == 1 and "of collider 0 (box at (0, 0, 0)" in lines[0] and "edge radius 0.0849 m" in lines[0]
            )
        else:
            assert lines == []


def test_dash_capital_v_is_version(capsys):
    for flag in ("-V", "--version"):
        with pytest.raises(SystemExit) as exc:
            main([flag])
        assert exc.value.code == 0 and capsys.readouterr().out.startswith("warpcloth ")


def test_a_grid_prints_rows_by_columns_and_a_mesh_its_vertices_and_triangles():
    from warpcloth.cli.run import cloth_shape

    assert cloth_shape(24, 32, 768, 1426) == "24x32"
    assert cloth_shape(1, 320, 320, 576) == "320 vertices, 576 triangles"


def test_the_fast_vertex_warning_says_it_counts_vertex_builds_and_what_to_do(capsys):
    """A skin_max far below a falling cloth's motion: every vertex is capped at every list build, and
    the warning counts those vertex-builds, over how many builds (it called them vertices: 25,604 on
    a 4,096-vertex cloth)."""
    from warpcloth import Simulator
    from warpcloth.run.harness import RunHarness
    from warpcloth.scenarios import get_scenario
    from warpcloth.sim.self_collision import SelfCollision

    model = get_scenario("sheet").build(rows=6, cols=6).model
    sc = SelfCollision(model, thickness=0.005, skin=1e-5, skin_max=1e-9)  # rebuilt often, every margin cut
    sim = Simulator(model, "xpbd", Control(device="cpu"), self_collision=sc)
    result = RunHarness(sim).run(0.1)
    fast, builds = result.self_collision["fast"], result.self_collision["rebuilds"]
    assert builds > 1 and model.particle_count < fast <= model.particle_count * builds
    lines = [line for line in capsys.readouterr().err.splitlines() if "may have missed pairs" in line]
    assert len(lines) == 1 and f"{fast:,} vertex-builds over {builds:,} list builds" in lines[0], lines
    assert "lower --dt" in lines[0] and "skin_max" in lines[0]
