"""Scenarios, the run loop's measurements, stability detection and USD export."""

import json
import math
import os

import numpy as np
import pytest

from warpcloth import WarpclothError
from warpcloth.io.usd import UsdWriter
from warpcloth.run.harness import RunHarness
from warpcloth.scenarios import flag, get_scenario, sheet


def test_sheet_reaches_equilibrium_and_sags_a_little():
    sim = sheet.build(rows=10, cols=10)
    harness = RunHarness(sim)
    result = harness.run(duration=10.0, stop_at_equilibrium=True)
    assert result.stable and result.equilibrium_reached
    assert 0.0 < result.time_to_equilibrium < result.sim_time <= 10.0
    assert result.time_to_equilibrium_wall is not None and result.time_to_equilibrium_wall <= result.wall_time
    # it stopped at equilibrium: the window after rest was confirmed, no longer
    assert result.sim_time - result.time_to_equilibrium < harness.equilibrium.window + 2.0 / result.fps
    assert result.final_max_speed < harness.equilibrium.speed_tol
    q = sim.state.particle_q.numpy()
    q0 = sim.model.particle_q.numpy()
    sag = (q0[:, 1] - q[:, 1]).max()
    assert 1e-4 < sag < 0.1 * sim.model.height  # it moved, and it is cloth, not rubber
    assert 0.0 < result.max_strain < 0.1


def test_flag_never_reaches_equilibrium():
    sim = flag.build(rows=8, cols=12)
    result = RunHarness(sim).run(duration=4.0, stop_at_equilibrium=True)
    assert result.stable and not result.equilibrium_reached and result.time_to_equilibrium is None
    assert math.isclose(result.sim_time, 4.0, rel_tol=0, abs_tol=sim.dt)
    # the wind moved it out of its plane
    assert np.abs(sim.state.particle_q.numpy()[:, 2]).max() > 0.05


def test_run_measurements_are_consistent():
    sim = sheet.build(rows=6, cols=6, dt=5e-4)
    result = RunHarness(sim).run(duration=0.5, fps=30.0)
    assert result.steps == 1000 and math.isclose(result.sim_time, result.steps * result.dt)
    assert result.frames == 15
    assert result.ms_per_step > 0 and math.isclose(result.steps_per_sec * result.ms_per_step, 1000.0, rel_tol=1e-9)
    assert math.isclose(result.realtime_factor, result.sim_time / result.wall_time)
    assert result.integration_time > 0 and result.other_time >= 0
    assert result.wall_time >= result.integration_time
    assert result.compile_time > 0
    d = json.loads(result.to_json())
    assert d["steps"] == 1000 and d["integrator"] == "explicit_euler" and d["particles"] == 36


def test_frames_are_sampled_by_simulated_time_not_steps():
    """Frames every 1/fps of simulated time, whatever dt is (seed 3.2.2)."""
    for dt in (1e-3, 7e-4):
        result = RunHarness(sheet.build(rows=5, cols=5, dt=dt)).run(duration=1.0, fps=20.0)
        assert result.frames == 20


def test_unstable_run_is_recorded_not_raised():
    sim = sheet.build(rows=10, cols=10)
    sim.set_dt(sim.dt * 20)
    result = RunHarness(sim).run(duration=1.0)
    assert not result.stable
    assert result.unstable_reason
    assert result.unstable_time is not None and result.sim_time < 1.0
    assert not result.equilibrium_reached


def test_unstable_with_nan_is_recorded():
    sim = sheet.build(rows=5, cols=5)
    q = sim.state.particle_q.numpy()
    q[7] = np.nan
    sim.state.particle_q.assign(q)
    result = RunHarness(sim).run(duration=0.2, warm_up=False)
    assert not result.stable and "non-finite" in result.unstable_reason


def test_default_runs_are_stable_for_every_integrator():
    from warpcloth.integrators import integrator_names

    for name in integrator_names():
        for scenario in (sheet, flag):
            sim = scenario.build(integrator=name, rows=8, cols=8)
            result = RunHarness(sim).run(duration=0.5)
            assert result.stable, (scenario.SCENARIO.name, name, result.unstable_reason)


def test_usd_export(tmp_path):
    from pxr import Usd, UsdGeom

    path = tmp_path / "flag.usda"
    result = get_scenario("flag").run(usd_path=str(path), rows=5, cols=7, duration=0.5, fps=20.0)
    assert path.exists()
    assert [p.name for p in tmp_path.iterdir()] == ["flag.usda"]  # no temporary file left
    stage = Usd.Stage.Open(str(path))
    assert stage.GetTimeCodesPerSecond() == 20.0
    assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.y
    assert UsdGeom.GetStageMetersPerUnit(stage) == 1.0
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/World/Cloth"))
    points = mesh.GetPointsAttr()
    samples = points.GetTimeSamples()
    assert len(samples) == result.frames + 1 == 11
    assert len(points.Get(samples[-1])) == 35
    assert len(mesh.GetFaceVertexCountsAttr().Get()) == 2 * 4 * 6
    assert not mesh.GetFaceVertexIndicesAttr().GetTimeSamples()  # topology written once
    assert len(mesh.GetExtentAttr().GetTimeSamples()) == len(samples)
    first, last = np.array(points.Get(samples[0])), np.array(points.Get(samples[-1]))
    assert np.abs(last - first).max() > 1e-3
    pinned = np.array(UsdGeom.PrimvarsAPI(mesh).GetPrimvar("pinned").Get())
    assert pinned.sum() == 5 and pinned[0] == 1
    pins = UsdGeom.Points(stage.GetPrimAtPath("/World/Pins")).GetPointsAttr()
    assert np.allclose(np.array(pins.Get(samples[-1])), first[pinned == 1])


def test_usd_writer_leaves_target_untouched_on_failure(tmp_path):
    path = tmp_path / "keep.usda"
    path.write_text("old")
    model = sheet.build(rows=4, cols=4).model
    with pytest.raises(RuntimeError):
        with UsdWriter(str(path), model) as w:
            w.write_frame(model.particle_q.numpy())
            raise RuntimeError("boom")
    assert path.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["keep.usda"]


@pytest.mark.parametrize(
    "path,match",
    [("nowhere/x.usda", "does not exist"), ("x.obj", "must end in one of"), ("afile/x.usda", "is not a folder")],
)
def test_bad_usd_path(tmp_cwd, path, match):
    (tmp_cwd / "afile").write_text("")
    with pytest.raises(WarpclothError, match=match):
        get_scenario("sheet").run(usd_path=path, rows=4, cols=4, duration=0.1)


def test_unwritable_usd_folder(tmp_path):
    if os.geteuid() == 0:
        pytest.skip("root can write anywhere")
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    with pytest.raises(WarpclothError, match="not writable"):
        get_scenario("sheet").run(usd_path=str(ro / "x.usda"), rows=4, cols=4, duration=0.1)


def test_sim_time_follows_dt_changes_and_matches_the_device_clock():
    sim = sheet.build(rows=5, cols=5, dt=1e-3)
    sim.simulate(10)
    sim.set_dt(2e-3)
    sim.simulate(1)
    sim.set_integrator("verlet", dt=5e-4)
    sim.step()
    assert math.isclose(sim.sim_time, 10e-3 + 2e-3 + 5e-4, rel_tol=1e-12)
    assert math.isclose(float(sim.control.time.numpy()[0]), sim.sim_time, rel_tol=1e-9)


def test_captured_frames_follow_control_changes():
    a, b = sheet.build(rows=5, cols=5), sheet.build(rows=5, cols=5)
    a.use_graph, b.use_graph = False, True
    for sim in (a, b):
        sim.simulate(20)
        sim.control.drag_rate = 50.0  # a host value baked into a captured frame
        sim.simulate(20)
    assert b.graph_enabled
    assert np.array_equal(a.state.particle_q.numpy(), b.state.particle_q.numpy())


def test_two_runs_equal_one_long_run():
    a, b = sheet.build(rows=5, cols=5, integrator="verlet"), sheet.build(rows=5, cols=5, integrator="verlet")
    RunHarness(a).run(duration=0.2)
    RunHarness(a).run(duration=0.2)
    RunHarness(b).run(duration=0.4)
    assert a.steps == b.steps
    assert np.array_equal(a.state.particle_q.numpy(), b.state.particle_q.numpy())


def test_usd_time_codes_are_simulated_time_when_a_step_is_longer_than_a_frame(tmp_path):
    from pxr import Usd, UsdGeom

    path = tmp_path / "slow.usda"
    get_scenario("flag").run(
        usd_path=str(path), rows=5, cols=5, integrator="implicit_euler", dt=1 / 30, duration=1.0, fps=60.0
    )
    stage = Usd.Stage.Open(str(path))
    samples = UsdGeom.Mesh(stage.GetPrimAtPath("/World/Cloth")).GetPointsAttr().GetTimeSamples()
    assert samples[0] == 0.0 and samples[1] == 2.0 and samples[-1] == 60.0
    assert stage.GetEndTimeCode() == 60.0


def test_graph_flag_off_is_bit_identical_to_on_and_capture_is_apart(capsys, tmp_path):
    import json

    from warpcloth.cli import main

    outs = {}
    for mode in ("on", "off"):
        usd = tmp_path / f"{mode}.usda"
        assert (
            main(
                [
                    "run",
                    "flag",
                    "--rows",
                    "5",
                    "--cols",
                    "6",
                    "--duration",
                    "0.3",
                    "--graph",
                    mode,
                    "--json",
                    "--usd",
                    str(usd),
                ]
            )
            == 0
        )
        d = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
        assert d["graph"] is (mode == "on")
        assert (d["capture_time"] > 0) is (mode == "on")  # capture reported apart, never in ms/step
        outs[mode] = usd.read_text()
    assert (
        outs["on"].split("timeSamples", 1)[1] == outs["off"].split("timeSamples", 1)[1]
    )  # the same frames, bit for bit
    from warpcloth.lab.testlist import parse_test_list

    xml = tmp_path / "t.xml"
    xml.write_text(
        '<test_list size="4" scenario="sheet" duration="0.1" dt="1e-3"><test integrator="rk4" graph="off '
        'on"/></test_list>'
    )
    runs = parse_test_list(str(xml)).runs
    assert [r.graph for r in runs] == ["off", "on"] and [r.config().use_graph for r in runs] == [False, True]
    with pytest.raises(SystemExit) as exit_:
        main(["run", "sheet", "--graph", "maybe"])
    assert exit_.value.code == 2 and "invalid choice: 'maybe'" in capsys.readouterr().err


def test_a_scene_runs_an_integrator_with_its_own_settings_unless_the_user_gives_them():
    """The fold runs projective with 20 local/global iterations, the drape pbd with 8 substeps and
    xpbd with 1 iteration x 64 substeps (the work those scenes need: docs/self-collision.md,
    docs/materials.md); the user's options win; other integrators and
    scenes keep the integrators' defaults."""
    fold, drape, plain = get_scenario("fold"), get_scenario("drape"), get_scenario("sheet")
    assert fold.build(integrator="projective", rows=6, cols=4).integrator.pd_iterations == 20
    assert (
        fold.build(
            integrator="projective", rows=6, cols=4, integrator_options={"pd_iterations": 3}
        ).integrator.pd_iterations
        == 3
    )
    assert drape.build(integrator="pbd", rows=6, cols=6).integrator.substeps == 8
    xpbd = drape.build(integrator="xpbd", rows=6, cols=6).integrator
    assert (xpbd.iterations, xpbd.substeps) == (1, 64)  # the drape's measured faithful default (docs/materials.md)
    assert plain.build(integrator="xpbd", rows=6, cols=6).integrator.substeps == 4
    assert plain.build(integrator="projective", rows=6, cols=6).integrator.pd_iterations == 10
    from warpcloth.integrators import integrator_names, make_integrator
    from warpcloth.scenarios import scenario_names

    for scenario in map(get_scenario, scenario_names()):  # every scene's settings: known integrators, options
        for name, options in scenario.integrator_defaults.items():
            assert name in integrator_names(), (scenario.name, name)
            make_integrator(name, **options)
