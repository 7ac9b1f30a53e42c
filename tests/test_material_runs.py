"""A material as a run's parameters (CLI, XML, scenario files, Python) and what uses it: the cloth it
builds, the one-line errors of bad values on every entry point, the cantilever and Cusick scenarios,
calibration, the drape's fold count and ``warpcloth list``."""

from __future__ import annotations

import csv
import math

import numpy as np
import pytest

from warpcloth.cli import main
from warpcloth.cli.model import config_from_args
from warpcloth.errors import WarpclothError
from warpcloth.lab import calibrate as cal
from warpcloth.lab.testlist import parse_test_list
from warpcloth.run.drape import fold_count
from warpcloth.scenarios import get_scenario
from warpcloth.scenarios.cusick import disc_grid, disc_hinges
from warpcloth.sim.hinges import build_hinges
from warpcloth.sim.material import PRESETS, Material, grid_spring_params, material, material_with


def cli_config(scenario: str, *argv):
    """The ScenarioConfig ``warpcloth run SCENARIO ARGV`` makes (no run)."""
    from warpcloth.cli import build_parser

    args = build_parser(("run",)).parse_args(["run", scenario, *argv])
    return config_from_args(get_scenario(scenario), args)


def one_line_error(capsys, *argv) -> str:
    with pytest.raises(SystemExit) as exc:
        raise SystemExit(main(list(argv)))
    assert exc.value.code == 2
    _out, err = capsys.readouterr()
    lines = [line for line in err.splitlines() if line.strip() and "CUDA" not in line]
    assert len(lines) == 1 and lines[0].startswith("warpcloth: error: ") and "Traceback" not in err, err
    return lines[0]


# -- the material of a run -----------------------------------------------------------------------


def test_cli_material_values_build_the_cloth_of_that_material():
    cfg = cli_config(
        "sheet",
        *("--size", "6", "--material", "denim", "--stretch", "2000,400", "--compression", "0.25"),
        *("--bend", "dihedral", "--bend-rigidity", "1e-5,3e-5", "--density", "0.3"),
    )
    sim = get_scenario("sheet").build(cfg)
    m = sim.model
    want = PRESETS["denim"].replace(
        name="x", stretch_warp=2000.0, stretch_weft=400.0, compression=0.25, bend_warp=1e-5, bend_weft=3e-5, density=0.3
    )
    springs = grid_spring_params(want, 6, 6, 1.0, 1.0, bend="dihedral")
    assert m.material.name == "denim*" and m.material.stretch_weft == 400.0
    np.testing.assert_allclose(m.spring_stiffness.numpy(), springs.stiffness, rtol=1e-6)
    np.testing.assert_allclose(m.spring_damping.numpy(), springs.damping, rtol=1e-6)
    assert m.spring_compression.numpy().tolist() == [0.25] * m.spring_count  # no bend springs: all membrane
    assert m.host.mass.sum() == pytest.approx(0.3 * 1.0 * 1.0, rel=1e-6)  # rho x area
    # grid hinges: y-edges (across the columns) bend along the warp, x-edges along the weft
    rigidity = m.host.hinges.rigidity
    assert sorted(set(np.round(rigidity * 1e6, 9))) == [10.0, 30.0]
    kd_over_k = m.host.hinges.damping / m.host.hinges.stiffness
    np.testing.assert_allclose(kd_over_k, want.bend_damping_time())  # Rayleigh, the same at every size


def test_a_preset_alone_is_the_preset_and_none_is_the_per_spring_model():
    cfg = cli_config("sheet", "--size", "6", "--material", "cotton")
    assert get_scenario("sheet").build(cfg).model.material is PRESETS["cotton"]
    cfg = cli_config("drape", "--size", "6", "--material", "none", "--stiffness", "500")
    model = get_scenario("drape").build(cfg).model
    assert model.material is None and float(model.spring_stiffness.numpy().max()) == 500.0


@pytest.mark.parametrize(
    "argv, message",
    [
        (("--material", "linen"), "unknown material 'linen'; choose a preset (cotton, denim"),
        (("--material", "cotton", "--compression", "1.5"), "'1.5' must be in [0, 1]"),
        (("--material", "cotton", "--density", "-1"), "'-1' must be > 0"),
        (("--material", "cotton", "--stretch", "nan"), "'nan' is not a finite number"),
        (("--material", "cotton", "--stretch", "1,2,3"), "give one number, or two separated by a comma"),
        (("--material", "cotton", "--shear", "5000"), "shear must be < sqrt(stretch_warp * stretch_weft)"),
        (("--material", "custom", "--density", "0.2"), "a custom material needs density, stretch, shear and"),
        (("--material", "cotton", "--mass", "0.3"), "mass is a per-spring value and material 'cotton'"),
        (
            (
                "--shear",
                "30",
            ),
            "shear is a material's value and scenario 'sheet' has no material",
        ),
        (("--bend", "dihedral", "--bend-rigidity", "1e-5,2e-5"), "two rigidities (warp,weft) need a material"),
    ],
)
def test_bad_material_values_on_the_command_line_are_one_line_errors(capsys, argv, message):
    line = one_line_error(capsys, "run", "sheet", "--size", "4", "--num-frames", "1", *argv)
    assert message in line


def test_a_scenario_made_of_a_material_refuses_per_spring_values_naming_the_way_out():
    with pytest.raises(WarpclothError, match=r"scenario 'cantilever' is made of material 'cotton'.*material none"):
        get_scenario("cantilever").config(stiffness=500.0)
    with pytest.raises(WarpclothError, match="unknown material value 'thickness'"):
        material_with("cotton", thickness=1e-3)
    assert material_with("none") is None and material_with("cotton") is PRESETS["cotton"]


def test_test_list_material_columns_run_key_and_errors(tmp_path):
    path = tmp_path / "t.xml"
    path.write_text(
        '<test_list scenario="sheet" duration="0.02">\n'
        '<test integrator="implicit_euler" size="4" material="cotton none" compression="0.5"/>\n'
        '<test integrator="implicit_euler" size="4" material="wool"/>\n</test_list>'
    )
    with pytest.raises(WarpclothError, match=r"t.xml:2: .*'compression' is a material's value and the run has no"):
        parse_test_list(str(path))
    path.write_text(
        '<test_list scenario="sheet" duration="0.02">\n<test integrator="implicit_euler" size="4" '
        'material="wool" stretch="2000,1500"/>\n<test integrator="implicit_euler" size="4"/>\n</test_list>'
    )
    runs = parse_test_list(str(path)).runs
    assert "material=wool;stretch=2000.0/1500.0" in runs[0].key and "material" not in runs[1].key
    assert runs[0].mass is None and runs[0].stiffness is None  # the material gives them
    assert runs[0].config().material == "wool" and runs[0].config().stretch == (2000.0, 1500.0)
    path.write_text('<test_list scenario="sheet">\n<test integrator="rk4" material="wool" mass="0.3"/>\n</test_list>')
    with pytest.raises(WarpclothError, match=r"t.xml:2: .*'mass' is a per-spring value and does not go with material"):
        parse_test_list(str(path))
    path.write_text('<test_list scenario="sheet">\n<test integrator="rk4" material="wool" shear="9000"/>\n</test_list>')
    with pytest.raises(WarpclothError, match=r"t.xml:2: .*shear must be <"):
        parse_test_list(str(path))


def test_sweep_writes_the_material_columns(tmp_path, capsys):
    path = tmp_path / "t.xml"
    path.write_text(
        '<test_list scenario="sheet" duration="0.02">\n'
        '<test integrator="implicit_euler" size="4" material="silk" compression="0.3"/>\n</test_list>'
    )
    assert main(["sweep", str(path), "--out", str(tmp_path / "o.csv"), "--quiet"]) == 0
    row = next(csv.DictReader(open(tmp_path / "o.csv")))
    assert (row["material"], row["compression"], row["mass"], row["outcome"]) == ("silk", "0.3", "", "completed")


def test_scenario_file_takes_a_material_in_its_cloth_table(tmp_path):
    from warpcloth.scenarios.mesh import make_cape

    cape = make_cape(6, 5)
    lines = [f"v {x:.9g} {y:.9g} {z:.9g}" for x, y, z in cape.vertices]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in cape.triangles]
    (tmp_path / "cape.obj").write_text("\n".join(lines) + "\n")
    good = tmp_path / "good.toml"
    good.write_text(
        '[cloth]\nmesh = "cape.obj"\nquads = true\nmaterial = "denim"\nstretch = [1500, 300]\ndensity = 0.25\n'
        "[pins]\nindices = [0, 1]\n"
    )
    model = get_scenario(str(good)).build(device="cpu").model
    assert model.material.stretch_weft == 300.0 and model.material.density == 0.25
    assert model.host.mass.sum() == pytest.approx(0.25 * cape_area(cape), rel=1e-6)
    bad = tmp_path / "bad.toml"
    for text, message in (
        ('material = "denim"\nmass = 0.3', "bad.toml: cloth.mass: does not go with cloth.material 'denim'"),
        ("shear = 20", "bad.toml: cloth.shear: is a material's value: give cloth.material"),
        ('material = "denim"\ncompression = 2', "bad.toml: cloth.compression: '2' must be in [0, 1]"),
        ('material = "denim"\nstretch = [1, 2, 3]', "bad.toml: cloth.stretch: must be a number or 2 numbers"),
    ):
        bad.write_text(f'[cloth]\nmesh = "cape.obj"\n{text}\n')
        with pytest.raises(WarpclothError) as exc:
            get_scenario(str(bad))
        assert message in str(exc.value)


def cape_area(cape) -> float:
    v, t = cape.vertices, cape.triangles
    return float(0.5 * np.linalg.norm(np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]]), axis=1).sum())


def test_warpcloth_list_shows_every_preset_with_its_bending_length(capsys):
    assert main(["list"]) == 0
    out = capsys.readouterr().out
    assert "materials (--material NAME" in out
    for name, m in PRESETS.items():
        line = next(s for s in out.splitlines() if s.strip().startswith(name + " "))
        assert f"{100 * m.bending_length():.2f}" in line and f"{1000 * m.density:.0f} g/m^2" in line


# -- the textile tests as scenarios --------------------------------------------------------------


def test_cantilever_scenario_reads_the_bending_length_of_the_exact_elastica():
    scenario = get_scenario("cantilever")
    cfg = scenario.config(device="cpu", integrator_options={"preconditioner": "block_jacobi"})
    result = scenario.run(cfg)
    got = result.measurements
    cotton = PRESETS["cotton"]
    assert result.stable and result.equilibrium_reached
    assert abs(got["tip_drop_error"]) < 0.005  # 32.5 segments: the discrete strip rests at the elastica
    assert got["bending_length_m"] == pytest.approx(cotton.bending_length(), rel=0.005)
    assert got["rigidity_Nm"] == pytest.approx(cotton.bend_warp, rel=0.015)
    assert got["astm_reading_valid"] and got["chord_angle_deg"] == pytest.approx(41.5, abs=0.3)
    assert got["astm_bending_length_m"] == pytest.approx(cotton.bending_length(), rel=0.002)  # L / 2 at 41.5 deg


def test_cantilever_refinement_ladder_converges_to_the_elastica():
    """The same cotton strip at 6, 10 and 18 particles (h halves): the tip drop's error against the
    exact elastica shrinks (the discrete strip is second order in h with the mid-clamp)."""
    scenario = get_scenario("cantilever")
    errors = []
    for cols in (6, 10, 18):
        width = scenario.defaults.width * (scenario.defaults.cols - 1.5) / (scenario.defaults.cols - 1)  # the overhang
        cfg = scenario.config(
            cols=cols,
            width=width * (cols - 1) / (cols - 1.5),
            device="cpu",
            integrator_options={"preconditioner": "block_jacobi"},
        )
        result = scenario.run(cfg)
        assert result.stable and result.equilibrium_reached
        errors.append(abs(result.measurements["tip_drop_error"]))
    assert errors[0] > errors[1] > errors[2] and errors[2] < 0.01, errors


def test_cusick_disc_geometry_is_an_inscribed_polygon_with_flat_hinges():
    for n in (8, 16, 32):
        pts, tris, index = disc_grid(n, 0.15)
        a, b, c = (pts[tris[:, k]] for k in range(3))
        signed = 0.5 * ((c[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1]) - (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]))
        h = 0.3 / (n - 1)
        assert np.all(signed > 0.1 * 0.5 * h * h)  # one winding, no sliver
        area = signed.sum() / (math.pi * 0.15**2) - 1.0
        assert -1.5 * h * h / 0.15**2 < area < 0.0  # inscribed: within O(h^2) below the disc
        assert np.all(np.hypot(pts[:, 0], pts[:, 1]) <= 0.15 + 1e-12)
        x = np.stack([pts[:, 0], np.zeros(len(pts)), pts[:, 1]], axis=1)
        q, rigidity = disc_hinges(n, index, x, 2e-5, 1e-5, 0.0)
        hinges = build_hinges(x, q, rigidity, 0.5)
        assert np.all(hinges.rest_angle == 0.0) and len(q) > 0
        assert sorted(set(np.round(rigidity * 1e6, 9))) == [10.0, 20.0]


def test_cusick_scenario_drapes_a_coarse_disc_within_its_refinement_band():
    """Cotton on a 16-point disc lands in the band of drape coefficients its finer discs give (24, 32
    and 48 points: 71.3, 77.6, 76.2 %, bench/results/cusick-presets.txt), far from a flat disc (1) or
    one hanging straight down (0)."""
    scenario = get_scenario("cusick")
    result = scenario.run(scenario.config(rows=16, cols=16, device="cpu"))
    got = result.measurements
    assert result.stable
    assert 0.69 <= got["drape_coefficient"] <= 0.80, got  # measured 0.711
    assert got["nodes"] >= 4 and (got["published_dc_low"], got["published_dc_high"]) == (0.55, 0.80)
    assert got["within_published"]


# -- calibration -------------------------------------------------------------------------------


def test_calibrate_bending_length_on_a_coarse_strip_recovers_b():
    target = 1.15 * PRESETS["silk"].bending_length()
    options = {"preconditioner": "block_jacobi"}
    result = cal.calibrate("silk", {"bending_length": target}, size=12, tolerance=5e-3, options=options)
    assert result.converged and abs(result.residual["bending_length"]) <= 5e-3
    assert result.unknowns["bend"] == pytest.approx(1.15**3, rel=0.03)  # B = w c^3, the 12-particle strip's error
    assert result.runs >= 1 and result.wall_s > 0.0
    assert "--material silk --bend-rigidity" in result.flags()


def test_calibrate_least_squares_finds_known_values_of_a_smooth_model(monkeypatch):
    """Two unknowns, two targets on a model whose answer is known: the solver, not the scenarios."""

    def fake(mat, targets, size, integrator, device, options, bend):
        bend = mat.bend_warp / PRESETS["wool"].bend_warp
        return {
            "bending_length": 0.015 * bend ** (1 / 3),
            "drape_coefficient": 0.5 * bend**0.3 * (0.5 + 0.5 * mat.compression),
        }

    monkeypatch.setattr(cal, "measure", fake)
    targets = {"bending_length": 0.015 * 2.0 ** (1 / 3), "drape_coefficient": 0.5 * 2.0**0.3 * 0.8}
    result = cal.calibrate("wool", targets, fit=("bend", "compression"))
    assert result.unknowns["bend"] == pytest.approx(2.0, rel=1e-3)
    assert result.unknowns["compression"] == pytest.approx(0.6, rel=1e-3)
    assert max(abs(r) for r in result.residual.values()) < 1e-3


@pytest.mark.parametrize(
    "targets, fit, message",
    [
        ({"stiffness": 1.0}, ("bend",), "unknown calibration target 'stiffness'"),
        ({"bending_length": -0.02}, ("bend",), "bending_length must be > 0"),
        ({"drape_coefficient": 1.5}, ("bend",), "drape_coefficient must be between 0 and 1"),
        ({"bending_length": 0.02}, ("bend", "stretch"), "2 unknowns (bend, stretch) need at least as many targets"),
        ({"bending_length": 0.02}, ("thickness",), "unknown calibration unknown 'thickness'"),
    ],
)
def test_calibrate_bad_input_is_one_line(targets, fit, message):
    with pytest.raises(WarpclothError) as exc:
        cal.calibrate("silk", targets, fit=fit)
    assert message in str(exc.value) and "\n" not in str(exc.value)


def test_calibrate_command_line_errors_are_one_line(capsys):
    assert "unknown material 'linen'" in one_line_error(capsys, "calibrate", "linen", "--target", "bending_length=1")
    assert "is not NAME=VALUE" in one_line_error(capsys, "calibrate", "silk", "--target", "bend=0.02")
    line = one_line_error(capsys, "calibrate", "silk", "--target", "bending_length=0.02", "--density", "nan")
    assert "'nan' is not a finite number" in line


# -- folds ----------------------------------------------------------------------------------


def skirt(k: int, amplitude=0.02, radius=0.3, n_phi=240, n_y=8):
    """A vertical skirt r(phi) = R + a cos(k phi), y in [0, 0.3]: k folds."""
    phi = np.linspace(0.0, 2.0 * math.pi, n_phi, endpoint=False)
    y = np.linspace(0.0, 0.3, n_y)
    p, yy = np.meshgrid(phi, y)
    r = radius + amplitude * np.cos(k * p)
    pts = np.stack([r * np.cos(p), yy, r * np.sin(p)], axis=-1).reshape(-1, 3)
    idx = np.arange(n_y * n_phi).reshape(n_y, n_phi)
    nxt = np.roll(idx, -1, axis=1)
    tris = np.concatenate(
        [
            np.stack([idx[:-1].ravel(), idx[1:].ravel(), nxt[:-1].ravel()], axis=1),
            np.stack([nxt[:-1].ravel(), idx[1:].ravel(), nxt[1:].ravel()], axis=1),
        ]
    )
    return pts, tris


@pytest.mark.parametrize("k", [3, 5, 8, 12])
def test_fold_count_of_a_skirt_with_k_folds(k):
    pts, tris = skirt(k)
    assert fold_count(pts, tris, 0.15) == k
    assert fold_count(pts, tris, 0.15, center=(0.005, 0.0)) == k  # off-centre by a quarter of a fold's depth


def test_fold_count_around_a_square_table_sees_no_fold_on_straight_sides():
    """A square tube (a tablecloth's flat flaps, no folds): four peaks around its centre by distance
    (its corners), none by the square distance max(|x|, |z|)."""
    s = np.linspace(-1.0, 1.0, 41)[:-1]
    side = [np.stack([np.full_like(s, 1.0), s], 1), np.stack([-s, np.full_like(s, 1.0)], 1)]
    side += [np.stack([np.full_like(s, -1.0), -s], 1), np.stack([s, np.full_like(s, -1.0)], 1)]
    ring = 0.4 * np.concatenate(side)  # 160 points around a 0.8 m square
    n = len(ring)
    pts = np.concatenate([np.stack([ring[:, 0], np.full(n, y), ring[:, 1]], 1) for y in (0.0, 0.3)])
    k = np.arange(n)
    tris = np.concatenate([np.stack([k, k + n, (k + 1) % n], 1), np.stack([(k + 1) % n, k + n, (k + 1) % n + n], 1)])
    assert fold_count(pts, tris, 0.15) == 4
    assert fold_count(pts, tris, 0.15, norm="square") == 0


def test_fold_count_refuses_a_cut_the_cloth_does_not_reach():
    pts, tris = skirt(4)
    with pytest.raises(WarpclothError, match="does not cross the plane at height 0.5"):
        fold_count(pts, tris, 0.5)


def test_material_mapping_errors_name_the_field():
    with pytest.raises(WarpclothError, match="material 'x': density must be > 0"):
        Material("x", -0.1, 100.0, 100.0, 10.0, 1e-6, 1e-6)
    with pytest.raises(WarpclothError, match="unknown material 'linen'"):
        material("linen")
