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
from warpcloth.scenarios import Scenario, curtain, get_scenario, register, scenario_names
from warpcloth.scenarios import mesh as mesh_scenario
from warpcloth.run.harness import RunHarness

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
    q0, x = sim.model.host["q"], sim.state.particle_q.numpy()
    top = np.arange(10)
    np.testing.assert_allclose(x[top] - q0[top], np.tile([curtain.SLIDE, 0, 0], (10, 1)), atol=1e-7)  # the rod stopped there
    assert abs(np.mean(x[10:, 0] - q0[10:, 0]) - curtain.SLIDE) < 0.01  # and the curtain hangs under it
    assert np.abs(sim.state.particle_qd.numpy()).max() < 5e-3


def test_cape_example_is_the_built_in_cape(tmp_path):
    out = subprocess.run([sys.executable, str(REPO / "examples" / "make_cape.py"), str(tmp_path / "cape.obj")], capture_output=True, text=True, check=True)
    assert out.returncode == 0
    written, shipped, built = load_mesh(str(tmp_path / "cape.obj")), load_mesh(str(REPO / "examples" / "cape.obj")), mesh_scenario.make_cape()
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
    cape = str(REPO / "examples" / "cape.obj")
    code, out, err = run_cli(capsys, "run", "mesh", "--mesh", cape, "--pin-group", "shoulders", "--duration", "0.3", "--json")
    assert code == 0, err
    d = json.loads(out)
    assert d["scenario"] == "mesh" and d["particles"] == 320 and d["stable"]
    sim = mesh_scenario.build(mesh=cape, pin_where="y > 1.47", duration=0.3)
    q = sim.model.host["q"]
    assert sim.model.pinned.tolist() == list(range(16))  # the neck row only (the next row is at y = 1.453 m)
    assert mesh_scenario.build().model.pinned.tolist() == list(range(32))  # built-in cape: its shoulders
    assert "shear" in mesh_scenario.build().model.spring_counts() and mesh_scenario.build().model.spring_counts()["shear"] == 2 * 19 * 15


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

    shutil.copy(REPO / "examples" / "cape.obj", tmp_path / "cape.obj")
    path = tmp_path / "windy.toml"
    path.write_text(SCENARIO_TOML)
    return path


def test_scenario_file_runs_through_run(capsys, scenario_file):
    code, out, err = run_cli(capsys, "run", str(scenario_file), "--json")
    assert code == 0, err
    d = json.loads(out)
    assert d["scenario"] == "windy-cape" and d["integrator"] == "xpbd" and d["dt"] == 0.005 and d["stable"]
    assert d["particles"] == 320
    sim = get_scenario(str(scenario_file)).build()
    assert sim.control.has_wind and sim.control.drag_rate == 0.5
    assert sim.model.pinned.tolist() == list(range(32))  # the predicate's top row and the tracked shoulders
    sim.simulate(int(round(0.2 / 0.005)))
    x = sim.state.particle_q.numpy()
    np.testing.assert_allclose(x[:32] - sim.model.host["q"][:32], np.tile([0.03, 0, 0.01], (32, 1)), atol=2e-7)
    # flags override the file
    code, out, err = run_cli(capsys, "run", str(scenario_file), "--integrator", "implicit_euler", "--duration", "0.05", "--json")
    assert code == 0 and json.loads(out)["integrator"] == "implicit_euler"


def test_scenario_file_runs_through_sweep(capsys, scenario_file, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    tests = tmp_path / "t.xml"
    tests.write_text('<test_list><test integrator="xpbd pbd" scenario="windy.toml" duration="0.1"/></test_list>')
    code, out, err = run_cli(capsys, "sweep", str(tests), "--out", "r.csv", "--quiet")
    assert code == 0, err
    rows = list(csv.DictReader(open(tmp_path / "r.csv")))
    assert [r["scenario"] for r in rows] == ["windy.toml", "windy.toml"]
    assert [r["integrator"] for r in rows] == ["xpbd", "pbd"] and all(r["outcome"] != "error" for r in rows), rows


@pytest.mark.parametrize(
    "change,message",
    [
        (("[run]", "[run]\nspeed = 3"), "windy.toml: [run]: unknown key 'speed' (allowed: device, dt, duration"),
        (("name =", "colour = 1\nname ="), "windy.toml: the top level: unknown key 'colour'"),
        (("times = [0.0, 0.1, 0.2]", "times = [0.0, 0.2, 0.1]"), "windy.toml: [[tracks]] #1: pin track keyframes out of order: time 0.1 s (key 2) is not after 0.2 s (key 1)"),
        (('groups = ["shoulders"]', 'groups = ["hips"]'), "pin group 'hips' does not exist in the mesh (its vertex groups: cloth, shoulders)"),
        (('where = "y > 1.45"', 'where = "y > 9"'), "pin predicate 'y > 9' selects no vertex"),
        (('where = "y > 1.45"', 'where = "__import__(1)"'), "pin predicate '__import__(1)'"),
        (('mesh = "cape.obj"', 'mesh = "cope.obj"'), "cope.obj' does not exist"),
        (("integrator = \"xpbd\"", "integrator = \"leapfrog\""), "unknown integrator 'leapfrog'"),
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
    assert "--rows does not apply to scenario 'mesh': its cloth is a mesh" in one_line_exit_2(capsys, "run", "mesh", "--rows", "5")
    assert "--pin-group does not apply to scenario 'sheet': its cloth is a grid" in one_line_exit_2(capsys, "run", "sheet", "--pin-group", "a")


def test_registry_lists_new_scenarios_and_takes_user_ones():
    assert {"sheet", "flag", "curtain", "mesh"} <= set(scenario_names())
    mine = Scenario(name="my-sheet", description="mine", defaults=curtain.SCENARIO.defaults, pins=lambda r, c: [0],
                    control=curtain.SCENARIO.control, origin=lambda cfg: (0.0, 1.5, 0.0), stop_at_equilibrium=False)
    register(mine)
    assert get_scenario("my-sheet") is mine and "my-sheet" in scenario_names()
    with pytest.raises(WarpclothError, match="is built in"):
        register(Scenario(name="sheet", description="", defaults=mine.defaults, pins=mine.pins, control=mine.control,
                          origin=mine.origin, stop_at_equilibrium=False))


def test_scenario_files_on_python_3_10_name_what_they_need(monkeypatch, scenario_file):
    from warpcloth.scenarios import file as file_scenarios

    monkeypatch.setitem(sys.modules, "tomllib", None)  # as on Python 3.10 without tomli
    monkeypatch.setitem(sys.modules, "tomli", None)
    file_scenarios._load.cache_clear()
    with pytest.raises(WarpclothError, match=r"needs Python 3.11 \(tomllib\) or the tomli package \(pip install tomli\)"):
        get_scenario(str(scenario_file))


def test_scenario_file_and_mesh_scenario_through_bench(capsys, scenario_file, tmp_path):
    out = tmp_path / "b.csv"
    code, _, err = run_cli(capsys, "bench", "--scenario", str(scenario_file), "--integrators", "xpbd", "--devices", "cpu",
                           "--steps", "2", "--graph", "off", "--out", str(out), "--quiet")
    assert code == 0, err
    import csv

    rows = list(csv.DictReader(open(out)))
    assert [(r["scenario"], r["integrator"], r["particles"]) for r in rows] == [(str(scenario_file), "xpbd", "320")]
    code, _, err = run_cli(capsys, "bench", "--scenario", str(scenario_file), "--sizes", "8", "--steps", "2")
    assert code == 2 and "--sizes does not apply to the mesh scenario" in err
    code, _, err = run_cli(capsys, "bench", "--scenario", "curtain", "--sizes", "6", "--integrators", "rk4", "--devices", "cpu",
                           "--steps", "2", "--graph", "off", "--out", str(out), "--quiet")
    assert code == 0, err
    assert [(r["scenario"], r["rows"], r["cols"]) for r in csv.DictReader(open(out))] == [("curtain", "6", "6")]


def test_the_shipped_example_scenario_file_runs(capsys):
    code, out, err = run_cli(capsys, "run", str(REPO / "examples" / "cape.toml"), "--duration", "0.05", "--json")
    assert code == 0, err
    d = json.loads(out)
    assert d["scenario"] == "swaying-cape" and d["particles"] == 320 and d["stable"]
