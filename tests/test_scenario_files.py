"""Scenarios users can add: the curtain (kinematic pins, settles), the mesh scenario (the cape,
--mesh, --pin-group, --pin), TOML scenario files through run and sweep, the registry, bad input."""

import csv
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from warpcloth import WarpclothError
from warpcloth.cli import main
from warpcloth.io.meshio import load_mesh
from warpcloth.run.harness import RunHarness
from warpcloth.scenarios import Scenario, curtain, get_scenario, register, scenario_names
from warpcloth.scenarios import mesh as mesh_scenario

REPO = Path(__file__).resolve().parents[1]


def run_cli(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def one_line_exit_2(capsys, *argv):
    with pytest.raises(SystemExit) as exc:
        raise SystemExit(main(list(argv)))
    assert exc.value.code == 2
    out, err = capsys.readouterr()
    lines = [line for line in err.splitlines() if line.strip() and "CUDA" not in line]
    assert len(lines) == 1 and lines[0].startswith("warpcloth: error: ") and "Traceback" not in err, err
    assert out == ""
    return lines[0]


def test_curtain_rod_slides_stops_and_the_curtain_settles():
    sim = curtain.build(rows=8, cols=10)
    result = RunHarness(sim).run(10.0, stop_at_equilibrium=True)
    assert result.stable, result.unstable_reason
    assert result.equilibrium_reached and result.time_to_equilibrium > curtain.SLIDE_TIME
    q0, x = sim.model.host.q, sim.state.particle_q.numpy()
    top = np.arange(10)
    np.testing.assert_allclose(
        x[top] - q0[top], np.tile([curtain.SLIDE, 0, 0], (10, 1)), atol=1e-7
    )  # the rod stopped there
    assert abs(np.mean(x[10:, 0] - q0[10:, 0]) - curtain.SLIDE) < 0.01  # and the curtain hangs under it
    assert np.abs(sim.state.particle_qd.numpy()).max() < 5e-3


def test_cape_example_is_the_built_in_cape(tmp_path):
    out = subprocess.run(
        [sys.executable, str(REPO / "warpcloth" / "examples" / "make_cape.py"), str(tmp_path / "cape.obj")],
        capture_output=True,
        text=True,
        check=True,
    )
    assert out.returncode == 0
    written, shipped, built = (
        load_mesh(str(tmp_path / "cape.obj")),
        load_mesh(str(REPO / "warpcloth" / "examples" / "cape.obj")),
        mesh_scenario.make_cape(),
    )
    np.testing.assert_allclose(written.vertices, built.vertices, atol=1e-8)
    np.testing.assert_array_equal(shipped.triangles, written.triangles)
    assert sorted(map(tuple, written.triangles.tolist())) == sorted(map(tuple, built.triangles.tolist()))
    assert written.groups["shoulders"].tolist() == built.groups["shoulders"].tolist() == list(range(32))

    def vertex_uv(m):
        uv = np.full((m.vertices.shape[0], 2), np.nan)
        uv[m.triangles.ravel()] = m.uv.reshape(-1, 2)
        return uv

    np.testing.assert_allclose(vertex_uv(written), vertex_uv(built), atol=1e-8)


def test_mesh_scenario_cape_with_group_and_predicate_pins(capsys):
    cape = str(REPO / "warpcloth" / "examples" / "cape.obj")
    code, out, err = run_cli(
        capsys, "run", "mesh", "--mesh", cape, "--pin-group", "shoulders", "--duration", "0.3", "--json"
    )
    assert code == 0, err
    d = json.loads(out)
    assert d["scenario"] == "mesh" and d["particles"] == 320 and d["stable"]
    sim = mesh_scenario.build(mesh=cape, pin_where="y > 1.47", duration=0.3)
    assert sim.model.pinned.tolist() == list(range(16))  # the neck row only (the next row is at y = 1.453 m)
    assert mesh_scenario.build().model.pinned.tolist() == list(range(32))  # built-in cape: its shoulders
    assert (
        "shear" in mesh_scenario.build().model.spring_counts()
        and mesh_scenario.build().model.spring_counts()["shear"] == 2 * 19 * 15
    )


SCENARIO_TOML = """
name = "windy-cape"
description = "a cape whose shoulders sway, in wind"

[cloth]
mesh = "cape.obj"
quads = true
mass = 0.25

[pins]
where = "y > 1.45"

[[tracks]]
groups = ["shoulders"]
kind = "keyframes"
times = [0.0, 0.1, 0.2]
offsets = [[0, 0, 0], [0.02, 0, 0], [0.03, 0, 0.01]]
interpolation = "catmull_rom"

[forces]
drag = 0.5
wind = [2, 0, 1]

[run]
integrator = "xpbd"
integrator_options = { iterations = 8 }
dt = 0.005
duration = 0.3
"""


@pytest.fixture
def scenario_file(tmp_path):
    import shutil

    shutil.copy(REPO / "warpcloth" / "examples" / "cape.obj", tmp_path / "cape.obj")
    path = tmp_path / "windy.toml"
    path.write_text(SCENARIO_TOML)
    return path


def test_scenario_file_runs_through_run(capsys, scenario_file):
    code, out, err = run_cli(capsys, "run", str(scenario_file), "--json")
    assert code == 0, err
    d = json.loads(out)
    assert d["scenario"] == "windy-cape" and d["integrator"] == "xpbd" and d["dt"] == 0.005 and d["stable"]
    assert d["particles"] == 320
    assert d["solver"]["iterations"] == 8  # the file's integrator options (they were dropped on this path)
    code, out, err = run_cli(capsys, "run", str(scenario_file), "--substeps", "2", "--duration", "0.02", "--json")
    assert code == 0 and json.loads(out)["solver"]["iterations"] == 8 and json.loads(out)["solver"]["substeps"] == 2
    sim = get_scenario(str(scenario_file)).build()
    assert sim.control.has_wind and sim.control.drag_rate == 0.5
    assert sim.model.pinned.tolist() == list(range(32))  # the predicate's top row and the tracked shoulders
    sim.simulate(int(round(0.2 / 0.005)))
    x = sim.state.particle_q.numpy()
    np.testing.assert_allclose(x[:32] - sim.model.host.q[:32], np.tile([0.03, 0, 0.01], (32, 1)), atol=2e-7)
    # flags override the file
    code, out, err = run_cli(
        capsys, "run", str(scenario_file), "--integrator", "implicit_euler", "--duration", "0.05", "--json"
    )
    assert code == 0 and json.loads(out)["integrator"] == "implicit_euler"


def test_scenario_file_runs_through_sweep(capsys, scenario_file, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    tests = tmp_path / "t.xml"
    tests.write_text('<test_list><test integrator="xpbd pbd" scenario="windy.toml" duration="0.1"/></test_list>')
    code, _out, err = run_cli(capsys, "sweep", str(tests), "--out", "r.csv", "--quiet")
    assert code == 0, err
    rows = list(csv.DictReader(open(tmp_path / "r.csv")))
    assert [r["scenario"] for r in rows] == ["windy.toml", "windy.toml"]
    assert [r["integrator"] for r in rows] == ["xpbd", "pbd"] and all(r["outcome"] != "error" for r in rows), rows


@pytest.mark.parametrize(
    "change,message",
    [
        (
            ("[run]", "[run]\nspeed = 3"),
            "windy.toml: [run]: unknown key 'speed' (allowed: deterministic, device, dt, duration",
        ),
        (("name =", "colour = 1\nname ="), "windy.toml: the top level: unknown key 'colour'"),
        (
            ("times = [0.0, 0.1, 0.2]", "times = [0.0, 0.2, 0.1]"),
            "windy.toml: [[tracks]] #1: pin track keyframes out of order: time 0.1 s (key 2) is not after 0.2 s (key "
            "1)",
        ),
        (
            ('groups = ["shoulders"]', 'groups = ["hips"]'),
            "pin group 'hips' does not exist in the mesh (its vertex groups: cloth, shoulders)",
        ),
        (('where = "y > 1.45"', 'where = "y > 9"'), "pin predicate 'y > 9' selects no vertex"),
        (('where = "y > 1.45"', 'where = "__import__(1)"'), "pin predicate '__import__(1)'"),
        (('mesh = "cape.obj"', 'mesh = "cope.obj"'), "cope.obj' does not exist"),
        (('integrator = "xpbd"', 'integrator = "leapfrog"'), "unknown integrator 'leapfrog'"),
        (("dt = 0.005", "dt = 0.005\ndt = 1"), "not valid TOML"),
    ],
)
def test_bad_scenario_files_are_one_line_exit_2(capsys, scenario_file, change, message):
    scenario_file.write_text(SCENARIO_TOML.replace(*change))
    line = one_line_exit_2(capsys, "run", str(scenario_file))
    assert message in line


def test_bad_mesh_flags_are_one_line_exit_2(capsys, tmp_path):
    assert "pin group 'hips' does not exist" in one_line_exit_2(capsys, "run", "mesh", "--pin-group", "hips")
    assert "does not exist" in one_line_exit_2(capsys, "run", "mesh", "--mesh", str(tmp_path / "none.obj"))
    (tmp_path / "m.ply").write_text("ply")
    assert "unsupported format '.ply'" in one_line_exit_2(capsys, "run", "mesh", "--mesh", str(tmp_path / "m.ply"))
    assert "scenario file" in one_line_exit_2(capsys, "run", str(tmp_path / "nothing.toml"))
    assert "--rows does not apply to scenario 'mesh': its cloth is a mesh" in one_line_exit_2(
        capsys, "run", "mesh", "--rows", "5"
    )
    assert "--pin-group does not apply to scenario 'sheet': its cloth is a grid" in one_line_exit_2(
        capsys, "run", "sheet", "--pin-group", "a"
    )


def test_registry_lists_new_scenarios_and_takes_user_ones():
    assert {"sheet", "flag", "curtain", "mesh"} <= set(scenario_names())
    mine = Scenario(
        name="my-sheet",
        description="mine",
        defaults=curtain.SCENARIO.defaults,
        pins=lambda r, c: [0],
        control=curtain.SCENARIO.control,
        origin=lambda cfg: (0.0, 1.5, 0.0),
        stop_at_equilibrium=False,
    )
    register(mine)
    assert get_scenario("my-sheet") is mine and "my-sheet" in scenario_names()
    with pytest.raises(WarpclothError, match="is built in"):
        register(
            Scenario(
                name="sheet",
                description="",
                defaults=mine.defaults,
                pins=mine.pins,
                control=mine.control,
                origin=mine.origin,
                stop_at_equilibrium=False,
            )
        )


def test_scenario_files_on_python_3_10_name_what_they_need(monkeypatch, scenario_file):
    from warpcloth.scenarios import file as file_scenarios

    monkeypatch.setitem(sys.modules, "tomllib", None)  # as on Python 3.10 without tomli
    monkeypatch.setitem(sys.modules, "tomli", None)
    file_scenarios._load.cache_clear()
    with pytest.raises(
        WarpclothError, match=r"needs Python 3.11 \(tomllib\) or the tomli package \(pip install tomli\)"
    ):
        get_scenario(str(scenario_file))


def test_scenario_file_and_mesh_scenario_through_bench(capsys, scenario_file, tmp_path):
    out = tmp_path / "b.csv"
    code, _, err = run_cli(
        capsys,
        "bench",
        "--scenario",
        str(scenario_file),
        "--integrators",
        "xpbd",
        "--devices",
        "cpu",
        "--steps",
        "2",
        "--graph",
        "off",
        "--out",
        str(out),
        "--quiet",
    )
    assert code == 0, err
    import csv

    rows = list(csv.DictReader(open(out)))
    assert [(r["scenario"], r["integrator"], r["particles"]) for r in rows] == [(str(scenario_file), "xpbd", "320")]
    code, _, err = run_cli(capsys, "bench", "--scenario", str(scenario_file), "--sizes", "8", "--steps", "2")
    assert code == 2 and "--sizes does not apply to the mesh scenario" in err
    code, _, err = run_cli(
        capsys,
        "bench",
        "--scenario",
        "curtain",
        "--sizes",
        "6",
        "--integrators",
        "rk4",
        "--devices",
        "cpu",
        "--steps",
        "2",
        "--graph",
        "off",
        "--out",
        str(out),
        "--quiet",
    )
    assert code == 0, err
    assert [(r["scenario"], r["rows"], r["cols"]) for r in csv.DictReader(open(out))] == [("curtain", "6", "6")]


def test_the_shipped_example_scenario_file_runs(capsys):
    code, out, err = run_cli(
        capsys, "run", str(REPO / "warpcloth" / "examples" / "cape.toml"), "--duration", "0.05", "--json"
    )
    assert code == 0, err
    d = json.loads(out)
    assert d["scenario"] == "swaying-cape" and d["particles"] == 320 and d["stable"]


# -- issue 31: every key of a scenario file honoured or refused --------------------------------
def _model_ks(path, *argv):
    """The per-type stiffness of the model a run of the file builds, with ``argv`` flags."""
    from warpcloth.cli import build_parser
    from warpcloth.cli.model import config_from_args

    args = build_parser().parse_args(["run", str(path), *argv])
    scenario = get_scenario(str(path))
    sim = scenario.build(config_from_args(scenario, args))
    return {t.name.lower(): p.stiffness for t, p in sim.model.spring_params.items()}, sim


def test_scenario_file_stiffness_and_damping_are_used_and_flags_override(scenario_file):
    soft = SCENARIO_TOML.replace("mass = 0.25", "mass = 0.25\nstiffness = 1\ndamping = [0.5, 0.25, 0.125]")
    scenario_file.write_text(soft)
    ks, sim = _model_ks(scenario_file)
    assert ks == {"structural": 1.0, "shear": 1.0, "bend": 1.0}
    assert {t.name.lower(): p.damping for t, p in sim.model.spring_params.items()} == {
        "structural": 0.5,
        "shear": 0.25,
        "bend": 0.125,
    }
    scenario_file.write_text(soft.replace("stiffness = 1", "stiffness = 1000000"))
    assert _model_ks(scenario_file)[0] == {"structural": 1e6, "shear": 1e6, "bend": 1e6}
    assert _model_ks(scenario_file, "--stiffness", "7")[0] == {"structural": 7.0, "shear": 7.0, "bend": 7.0}
    # a per-type flag replaces that type only; the file's value stays for the others
    assert _model_ks(scenario_file, "--stiffness-bend", "3")[0] == {"structural": 1e6, "shear": 1e6, "bend": 3.0}


@pytest.mark.parametrize(
    "change,message",
    [
        (("quads = true", 'quads = "no"'), "windy.toml: cloth.quads: must be true or false, got 'no'"),
        (("quads = true", 'quads = true\nbend = "false"'), "windy.toml: cloth.bend: unknown bend model 'false'"),
        (
            ("name =", 'stop_at_equilibrium = "false"\nname ='),
            "windy.toml: stop_at_equilibrium: must be true or false, got 'false'",
        ),
        (
            ("[pins]", "[pins]\nindices = [1.5]"),
            "windy.toml: pins.indices: must be a list of vertex indices (integers), got 1.5",
        ),
        (
            ("[pins]", "[pins]\nindices = 3"),
            "windy.toml: pins.indices: must be a list of vertex indices (integers), got 3",
        ),
        (("[pins]", '[pins]\nindices = ["a"]'), "windy.toml: pins.indices: must be a list of vertex indices"),
        (("wind = [2, 0, 1]", "wind = [nan, 0, 0]"), "windy.toml: forces.wind[0] must be a finite number, got nan"),
        (
            ("wind = [2, 0, 1]", 'wind = [2, 0, "x"]'),
            "windy.toml: forces.wind must be 3 numbers [m/s], got [2, 0, 'x']",
        ),
        (
            ("wind = [2, 0, 1]", 'wind = [2, 0, 1]\nwind_coefficient = "strong"'),
            "windy.toml: forces.wind_coefficient: must be a number, got 'strong'",
        ),
        (("drag = 0.5", "drag = -1"), "windy.toml: forces.drag: '-1' must be >= 0"),
        (('name = "windy-cape"', "name = { a = 1 }"), "windy.toml: name: must be a non-empty string, got {'a': 1}"),
        (("quads = true", "quads = true\nprim = 5"), "windy.toml: cloth.prim: must be a string, got 5"),
        (("mass = 0.25", 'mass = "0.25"'), "windy.toml: cloth.mass: must be a number, got '0.25'"),
        (
            ("mass = 0.25", "mass = 0.25\nstiffness = [1, 2]"),
            "windy.toml: cloth.stiffness: must be a number or 3 numbers",
        ),
        (("mass = 0.25", "mass = 0.25\nstiffness = -5"), "windy.toml: cloth.stiffness: '-5' must be >= 0"),
        (("mass = 0.25", 'mass = 0.25\nmass_mode = "lumpy"'), "windy.toml: cloth.mass_mode: must be one of"),
        (("dt = 0.005", "dt = 0.005\nstrain_limit = true"), "windy.toml: run.strain_limit: must be a number, got True"),
        (("dt = 0.005", "dt = [0.005]"), "windy.toml: run.dt: must be a number or a string, got [0.005]"),
        (
            ('where = "y > 1.45"', 'where = "y + 1"'),
            "windy.toml: pins.where: pin predicate 'y + 1' is a number, not a condition",
        ),
        (
            ('groups = ["shoulders"]', "groups = [1]"),
            "windy.toml: tracks[0].groups: must be a list of names (strings), got [1]",
        ),
        (
            (
                "[run]",
                '[[colliders]]\nkind = "sphere"\nradius = 0.2\ntrack = { kind = "rigid", angular_velocity = "fast" '
                "}\n[run]",
            ),
            "windy.toml: [[colliders]] #1: collider track angular_velocity must be a number, got 'fast'",
        ),
        (
            ("[run]", '[[colliders]]\nkind = "sphere"\nradius = "big"\n[run]'),
            "windy.toml: [[colliders]] #1: radius must be a number or a list of numbers, got 'big'",
        ),
        (
            ("[run]", '[[colliders]]\nkind = "mesh"\npath = "cape.obj"\nprim = 5\n[run]'),
            "windy.toml: [[colliders]] #1: prim must be a prim path such as '/World/Table', got 5",
        ),
    ],
)
def test_wrong_types_in_a_scenario_file_are_one_line_naming_file_key_and_value(capsys, scenario_file, change, message):
    assert change[0] in SCENARIO_TOML
    scenario_file.write_text(SCENARIO_TOML.replace(*change, 1))
    line = one_line_exit_2(capsys, "run", str(scenario_file))
    assert message in line, line
    assert len(line) < 300


def test_a_file_device_is_used_unless_the_flag_gives_one(capsys, scenario_file):
    scenario_file.write_text(SCENARIO_TOML.replace("[run]", '[run]\ndevice = "cuda:7"'))
    line = one_line_exit_2(capsys, "run", str(scenario_file))
    assert "device 'cuda:7' is not available" in line
    code, out, err = run_cli(capsys, "run", str(scenario_file), "--device", "cpu", "--duration", "0.02", "--json")
    assert code == 0, err
    assert json.loads(out)["device"] == "cpu"


@pytest.mark.parametrize(
    "content,message",
    [
        (b"a = " + b"[" * 2000 + b"]" * 2000, "nested 2000 deep; a scenario file nests at most 8"),
        (b"a = " + b"{ b = " * 2000 + b"1" + b" }" * 2000, "nested 2000 deep"),
        (b'name = "caf\xe9"\n', "not UTF-8 text (byte 0xe9 at offset 11)"),
        (
            b"# " + b"x" * 1_200_000 + b"\n",
            "is 1.14 MiB, more than the 1 MiB warpcloth reads",
        ),  # checked before it is parsed
        (b"a" + b".b" * 20 + b" = 1\n", "nested more than 8 deep"),
    ],
)
def test_the_toml_reader_is_bounded(capsys, tmp_path, content, message):
    path = tmp_path / "bad.toml"
    path.write_bytes(content)
    line = one_line_exit_2(capsys, "run", str(path))
    assert message in line, line
    assert len(line) < 300


def test_special_files_are_refused_as_scenario_files_and_meshes(capsys, tmp_path, scenario_file):
    from helpers import unblocked_fifo

    with unblocked_fifo(tmp_path / "pipe.toml") as fifo:
        assert "pipe.toml' is a FIFO, not a regular file" in one_line_exit_2(capsys, "run", str(tmp_path / "pipe.toml"))
    with unblocked_fifo(tmp_path / "pipe.obj") as fifo2:
        scenario_file.write_text(SCENARIO_TOML.replace('mesh = "cape.obj"', 'mesh = "pipe.obj"'))
        assert "pipe.obj' is a FIFO, not a regular file" in one_line_exit_2(capsys, "run", str(scenario_file))
        assert "pipe.obj' is a FIFO, not a regular file" in one_line_exit_2(
            capsys, "run", "mesh", "--mesh", str(tmp_path / "pipe.obj")
        )
        line = one_line_exit_2(capsys, "run", "sheet", "--collider", f"mesh:path={tmp_path / 'pipe.obj'}")
        assert "is not a regular file" in line, line
    assert fifo.opened == fifo2.opened == 0
    (tmp_path / "kmsg.obj").symlink_to(
        "/proc/self/mounts"
    )  # a "regular" file that /proc/kmsg would be, but it never blocks
    assert "is a system file under /proc, not a regular file" in one_line_exit_2(
        capsys, "run", "mesh", "--mesh", str(tmp_path / "kmsg.obj")
    )
    scenario_file.write_text(SCENARIO_TOML.replace('mesh = "cape.obj"', 'mesh = "kmsg.obj"'))
    assert "is a system file under /proc" in one_line_exit_2(capsys, "run", str(scenario_file))
    line = one_line_exit_2(capsys, "run", "sheet", "--collider", f"mesh:path={tmp_path / 'kmsg.obj'}")
    assert "is a system file under /proc" in line, line


def _usd_mesh_with_fifo_layer(tmp_path, how: str) -> str:
    """A USD file whose mesh is fine but which names a FIFO as a sublayer, reference, payload
    or value clip."""
    from pxr import Sdf, Usd, UsdGeom

    good = tmp_path / "good.usda"
    if not good.exists():
        stage = Usd.Stage.CreateNew(str(good))
        mesh = UsdGeom.Mesh.Define(stage, "/World/Cloth")
        mesh.CreatePointsAttr([(0, 0, 0), (1, 0, 0), (0, 1, 0), (1, 1, 0)])
        mesh.CreateFaceVertexCountsAttr([4])
        mesh.CreateFaceVertexIndicesAttr([0, 1, 3, 2])
        stage.GetRootLayer().Save()
    layer = Sdf.Layer.CreateNew(str(tmp_path / f"{how}.usda"))
    layer.subLayerPaths.append("./good.usda")
    world = Sdf.CreatePrimInLayer(layer, "/World")
    world.specifier = Sdf.SpecifierDef
    if how == "sublayer":
        layer.subLayerPaths.append("./pipe.usda")
    elif how == "reference":
        world.referenceList.Prepend(Sdf.Reference("./pipe.usda"))
    elif how == "payload":
        world.payloadList.Prepend(Sdf.Payload("./pipe.usda"))
    else:
        world.SetInfo("clips", {"default": {"assetPaths": Sdf.AssetPathArray(["./pipe.usda"]), "primPath": "/World"}})
    layer.Save()
    return str(tmp_path / f"{how}.usda")


@pytest.mark.parametrize("how", ["sublayer", "reference", "payload", "clip"])
def test_a_usd_mesh_naming_a_fifo_layer_is_refused_before_it_is_opened(capsys, tmp_path, scenario_file, how):
    from helpers import unblocked_fifo

    usd = _usd_mesh_with_fifo_layer(tmp_path, how)
    with unblocked_fifo(tmp_path / "pipe.usda") as fifo:
        message = "names './pipe.usda' ("
        assert message in one_line_exit_2(capsys, "run", "mesh", "--mesh", usd)
        scenario_file.write_text(
            SCENARIO_TOML.replace('mesh = "cape.obj"', f'mesh = "{how}.usda"')
            .replace("[pins]\n", "[pins]\nindices = [0]\n")
            .replace('groups = ["shoulders"]', "indices = [1]")
        )
        line = one_line_exit_2(capsys, "run", str(scenario_file))
        assert message in line and "is a FIFO, not a regular file" in line, line
        line = one_line_exit_2(capsys, "run", "sheet", "--collider", f"mesh:path={usd}")
        assert message in line and "is a FIFO, not a regular file" in line, line
    assert fifo.opened == 0
