"""Bad values on the newer surfaces (issue 50): calibrate's targets, the cantilever's elastica, a
scenario file's material, the driving API, Material.replace, a material grid's memory, an OBJ's
texture coordinates and the self-collision flags. Each ends in one ``warpcloth: error: ...`` line
(exit 2) or one WarpclothError naming the argument, or a documented result: never a traceback, a
value dropped without a word, or a cloth that turns non-finite."""

import math
import types

import numpy as np
import pytest
import warp as wp

from warpcloth import Control, Simulator, Sphere, WarpclothError, build_grid_cloth
from warpcloth.cli import build_parser, main
from warpcloth.cli.model import config_from_args
from warpcloth.errors import warn
from warpcloth.io.meshio import load_mesh
from warpcloth.lab import calibrate as cal
from warpcloth.scenarios import cantilever, get_scenario
from warpcloth.scenarios.file import load_scenario
from warpcloth.sim import elastica
from warpcloth.sim.colliders import ColliderTrack
from warpcloth.sim.material import PRESETS, material, material_grid_cloth
from warpcloth.sim.pins import PinTrack

N = 6
CORNERS = [0, N - 1]


def one_line_error(capsys, *argv) -> str:
    """``warpcloth ARGV`` exits 2 with one ``warpcloth: error:`` line on stderr and no traceback."""
    with pytest.raises(SystemExit) as exc:
        raise SystemExit(main(list(argv)))
    assert exc.value.code == 2
    _out, err = capsys.readouterr()
    lines = [line for line in err.splitlines() if line.strip() and "CUDA" not in line]
    assert len(lines) == 1 and lines[0].startswith("warpcloth: error: ") and "Traceback" not in err, err
    return lines[0]


def one_line(exc_info) -> str:
    text = str(exc_info.value)
    assert "\n" not in text
    return text


# -- calibrate -------------------------------------------------------------------------------------


def test_calibrate_refuses_a_bending_length_no_fit_can_reach(capsys):
    line = one_line_error(capsys, "calibrate", "silk", "--target", "bending_length=1e-300")
    assert "bending_length 1e-300 m is out of reach from silk" in line
    c = PRESETS["silk"].bending_length()
    assert f"{0.1 * c:.4g}..{10 * c:.4g} m" in line  # the bend factor's bounds 1e-3..1e3, cube-rooted
    with pytest.raises(WarpclothError, match=r"out of reach") as exc:
        cal.calibrate("silk", {"bending_length": 1e3})
    one_line(exc)


def test_calibrate_refuses_a_target_given_twice(capsys):
    line = one_line_error(
        capsys, "calibrate", "silk", "--target", "bending_length=0.02", "--target", "bending_length=0.03"
    )
    assert "--target bending_length is given twice (0.02 and 0.03)" in line


def test_calibrate_says_a_repeated_warning_once(monkeypatch, capsys):
    """The same warning from every run of a fit (numbers aside) comes once; another comes too."""
    calls = []

    def fake(mat, targets, size, integrator, device, options, bend):
        calls.append(mat)
        warn(f"implicit_euler: the true residual ended above the tolerance in {len(calls)} of 75 steps")
        if len(calls) == 2:
            warn("something else")
        factor = mat.bend_warp / PRESETS["silk"].bend_warp
        return {"bending_length": 0.9 * PRESETS["silk"].bending_length() * factor**0.3}  # the start misses

    monkeypatch.setattr(cal, "measure", fake)
    result = cal.calibrate("silk", {"bending_length": 1.3 * PRESETS["silk"].bending_length()}, tolerance=1e-6)
    assert result.runs >= 3
    err = capsys.readouterr().err
    assert err.count("the true residual ended above the tolerance") == 1, err
    assert "in 1 of 75 steps" in err and err.count("something else") == 1


# -- the cantilever's elastica ----------------------------------------------------------------------


def test_the_elastica_refuses_a_lambda_its_shooting_cannot_solve():
    assert elastica.chord_angle_of(elastica.MAX_LAMBDA) >= elastica.MAX_CHORD_ANGLE  # the constant is in range
    with pytest.raises(WarpclothError, match=r"lambda = w L\^3 / B must be <= 100") as exc:
        elastica.tip_angle(48918.9)  # --material none's strip: brentq found no sign change
    one_line(exc)
    with pytest.raises(WarpclothError, match=r"angle must be in \(0, 80.36\] degrees"):
        elastica.lambda_for_chord_angle(math.radians(85.0))
    assert elastica.lambda_for_chord_angle(elastica.MAX_CHORD_ANGLE) <= elastica.MAX_LAMBDA


def test_a_cantilever_without_a_material_reports_what_it_can(capsys):
    """``run cantilever --material none``: the default per-spring strip hangs nearly straight down
    (lambda 4.9e4); the measurement reports its drop and chord and says why there is no elastica."""
    scenario = get_scenario("cantilever")
    config = scenario.config(material="none")
    rows, cols, length = config.rows, config.cols, cantilever.overhang(config)
    h = length / (cols - 1.5)
    x = np.zeros((rows, cols, 3))
    for c in range(cols):  # the two clamped columns level at the ledge, the rest hanging almost straight down
        x[:, c, 0] = (c - 0.5) * h if c < 2 else 0.5 * h + 0.05 * (c - 1) * h
        x[:, c, 1] = cantilever.LEDGE - max(0, c - 1) * h
    sim = types.SimpleNamespace(state=types.SimpleNamespace(particle_q=wp.array(x.reshape(-1, 3), dtype=wp.vec3)))
    out = cantilever.measure(sim, config)
    assert out["chord_angle_deg"] > 80.36 and out["tip_drop_m"] > 0
    assert "elastica_tip_drop_m" not in out and "bending_length_m" not in out
    err = capsys.readouterr().err
    assert "lambda = w L^3 / B = 4.892e+04 is beyond the elastica's 100" in err
    assert all(line.startswith("warpcloth: warning: ") for line in err.splitlines() if line.strip())


# -- a scenario file's material ----------------------------------------------------------------------


def test_a_scenario_file_refuses_a_density_with_material_none(tmp_path, capsys):
    obj = tmp_path / "sq.obj"
    obj.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 4 3\n")
    toml = tmp_path / "s.toml"
    toml.write_text('[cloth]\nmesh = "sq.obj"\nmaterial = "none"\ndensity = 0.2\n')
    with pytest.raises(WarpclothError, match=r"s.toml: cloth.density: is a material's value") as exc:
        load_scenario(str(toml))
    assert "cloth.material is 'none'" in one_line(exc)
    line = one_line_error(capsys, "run", str(toml))
    assert "cloth.density" in line
    # the same pair on the command line, refused the same way
    assert "density is a material's value" in one_line_error(
        capsys, "run", "sheet", "--material", "none", "--density", "0.2"
    )
    toml.write_text('[cloth]\nmesh = "sq.obj"\ndensity = 0.5\n')  # without material: the areal density
    assert load_scenario(str(toml)).defaults.mass == pytest.approx(0.5)  # kg/m^2 x 1 m^2


# -- the driving API ----------------------------------------------------------------------------------


def _driven_sim(interpolation="linear", collider=False):
    model = build_grid_cloth(N, N, pins=CORNERS, device="cpu")
    hand = PinTrack.driven(CORNERS, interpolation=interpolation, name="hand")
    colliders = (Sphere(center=(0.5, -0.6, -0.3), radius=0.15, track=ColliderTrack.driven()),) if collider else ()
    return Simulator(model, "xpbd", Control(device="cpu", pin_tracks=(hand,), colliders=colliders))


@pytest.mark.parametrize("value", [1e300, -1e19, math.inf, math.nan])
def test_pin_targets_far_or_non_finite_are_refused_and_the_cloth_stays_finite(value):
    sim = _driven_sim()
    with pytest.raises(WarpclothError, match=r"pin track 'hand' target positions must be") as exc:
        sim.set_pin_targets([[value, 0, 0], [0, 0, 0]])
    one_line(exc)
    sim.simulate(2)
    assert np.all(np.isfinite(sim.state.particle_q.numpy()))


def test_hermite_velocities_far_or_non_finite_are_refused():
    sim = _driven_sim("hermite")
    p = np.zeros((2, 3))
    for v in (1e300, math.nan):
        with pytest.raises(WarpclothError, match=r"pin track 'hand' velocities must be"):
            sim.set_pin_targets(p, [[v, 0, 0], [0, 0, 0]])
    sim.simulate(2)
    assert np.all(np.isfinite(sim.state.particle_q.numpy()))


@pytest.mark.parametrize(
    "positions",
    [
        [["a", "b", "c"], ["d", "e", "f"]],
        [[0, 0], [0, 0, 0]],
        [[1j, 0, 0], [0, 0, 0]],
        np.array([[1j, 0, 0], [0, 0, 0]]),
        np.array([[None, object(), 0], [0, 0, 0]], dtype=object),
        {"a": 1},
        (x for x in range(6)),
        [[True, 0, 0], [0, 0, 0]],
        "0 0 0 0 0 0",
        None,
    ],
    ids=["strings", "ragged", "complex", "complex-array", "object-array", "dict", "generator", "bool", "str", "none"],
)
def test_pin_targets_that_are_not_numbers_are_one_error_naming_the_argument(positions):
    sim = _driven_sim()
    with pytest.raises(WarpclothError, match=r"pin track 'hand' target positions must be numbers") as exc:
        sim.set_pin_targets(positions)
    one_line(exc)


def test_pin_targets_and_collider_poses_take_warp_arrays():
    sim = _driven_sim(collider=True)
    rest = sim.model.host.q[CORNERS].astype(np.float64)
    sim.set_pin_targets(wp.array(rest + 0.01, dtype=wp.vec3d, device="cpu"))
    sim.set_collider_pose(0, offset=wp.array([0.0, 0.1, 0.0], dtype=float, device="cpu"))
    sim.simulate(4)
    assert np.allclose(sim.state.particle_q.numpy()[CORNERS], rest + 0.01, atol=1e-6)
    assert np.allclose(sim.control.collision.params.numpy()[0]["a"], (0.5, -0.5, -0.3), atol=1e-6)
    for offset in ((math.nan, 0, 0), (1e30, 0, 0), wp.array([1e30, 0.0, 0.0], dtype=float, device="cpu")):
        with pytest.raises(WarpclothError, match=r"collider 0's offset must be") as exc:
            sim.set_collider_pose(0, offset=offset)
        one_line(exc)


@pytest.mark.parametrize("name", [5, "", None, "a\nb", b"x"])
def test_a_pin_track_name_must_be_text(name):
    for make in (
        lambda: PinTrack.driven([0], name=name),
        lambda: PinTrack.keyframes([0], [0.0], [[0, 0, 0]], name=name),
        lambda: PinTrack.rigid([0], name=name),
    ):
        with pytest.raises(WarpclothError, match=r"pin track name must be non-empty printable text") as exc:
            make()
        one_line(exc)


# -- materials ----------------------------------------------------------------------------------------


def test_material_replace_names_an_unknown_field():
    with pytest.raises(WarpclothError, match=r"unknown field 'foo' \(fields: name, .*density") as exc:
        material("cotton").replace(foo=1)
    one_line(exc)
    assert material("cotton").replace(density=0.3).density == 0.3


def test_a_material_grid_too_big_for_memory_is_refused_before_any_array():
    with pytest.raises(WarpclothError, match=r"a 1000000000 x 3 cloth needs about .* available") as exc:
        material_grid_cloth(material("cotton"), 10**9, 3, 1, 1)
    one_line(exc)
    with pytest.raises(WarpclothError, match=r"rows must be an integer >= 3"):
        material_grid_cloth(material("cotton"), 2, 3, 1, 1)  # provot bend springs span two rows


# -- an OBJ's texture coordinates ------------------------------------------------------------------------


@pytest.mark.parametrize("line, what", [("vt nan 0", "texture"), ("vt 0 inf", "texture"), ("v nan 0 0", "vertex")])
def test_an_obj_with_a_non_finite_coordinate_names_the_file_and_line(tmp_path, capsys, line, what):
    obj = tmp_path / "F.obj"
    obj.write_text(f"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 5 5 5\nvt 0 0\nvt 1 0\nvt 0 1\n{line}\nf 1/1 2/2 3/3\n")
    with pytest.raises(WarpclothError, match=rf"F.obj:8: {what} coordinates must be finite") as exc:
        load_mesh(str(obj))
    one_line(exc)
    err = one_line_error(capsys, "run", "mesh", "--mesh", str(obj))  # no 'note:' line before it
    assert f"F.obj:8: {what} coordinates must be finite, got '{line[len(line.split()[0]) + 1 :]}'" in err


# -- self-collision's settings -----------------------------------------------------------------------------


def _config(scenario, *argv):
    args = build_parser(("run",)).parse_args(["run", scenario, *argv])
    return config_from_args(get_scenario(scenario), args)


@pytest.mark.parametrize(
    "flag, value",
    [("--self-collision-thickness", "0.01"), ("--self-collision-friction", "0.1"), ("--self-collision-interval", "0")],
)
def test_self_collision_settings_need_self_collision_on(capsys, flag, value):
    line = one_line_error(capsys, "run", "sheet", flag, value)
    assert f"{flag} applies with self-collision on, and it is off in scenario 'sheet'" in line
    assert "--self-collision on" in line
    line = one_line_error(capsys, "run", "fold", "--self-collision", "off", flag, value)
    assert "off in scenario 'fold'" in line
    # on by the flag, or by the scenario's own default (fold): taken
    assert _config("sheet", "--self-collision", "on", flag, value).self_collision is True
    cfg = _config("fold", flag, value)
    assert cfg.self_collision is None and get_scenario("fold").self_collision_settings(cfg) is not None


def test_a_scenario_files_self_collision_settings_need_self_collision_on(tmp_path, capsys):
    """The CLI's rule for a scenario file's [run] keys: a setting where its self-collision is off is
    refused in one line naming the file, not silently unused; with self_collision = true it is taken."""
    obj = tmp_path / "sq.obj"
    obj.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 4 3\n")
    toml = tmp_path / "s.toml"
    toml.write_text('[cloth]\nmesh = "sq.obj"\n\n[run]\nself_collision_interval = 0.01\n')
    line = one_line_error(capsys, "run", str(toml), "--num-frames", "1")
    assert "s.toml: [run] self_collision_interval applies with self-collision on" in line, line
    toml.write_text('[cloth]\nmesh = "sq.obj"\n\n[run]\nself_collision = true\nself_collision_interval = 0.01\n')
    assert load_scenario(str(toml)).defaults.self_collision_interval == pytest.approx(0.01)
