"""The Python API answers bad arguments with a WarpclothError (a ValueError) naming the argument,
the value and what is allowed, before any allocation (issue: Python API errors)."""

import math

import pytest

from warpcloth import Control, Simulator, WarpclothError, build_grid_cloth, make_integrator
from warpcloth.io.usd import UsdWriter
from warpcloth.run.harness import RunHarness
from warpcloth.scenarios import sheet
from warpcloth.sim.control import WindSchedule

INF, NAN = math.inf, math.nan


@pytest.mark.parametrize(
    "kwargs,match",
    [
        ({"rows": INF}, "rows must be an integer"),
        ({"rows": 10**20}, "needs about .* available"),
        ({"rows": 10**9, "cols": 8}, "needs about .* available"),
        ({"rows": 20000, "cols": 20000}, "needs about .* available"),
        ({"pins": ["a"]}, "pins must hold integer particle indices .* got 'a'"),
        ({"pins": [1.5]}, "pins must hold integer particle indices .* got 1.5"),
        ({"pins": "abc"}, "pins must be a sequence of particle indices"),
        ({"pins": 5}, "pins must be a sequence of particle indices"),
        ({"pins": [NAN]}, "pins must hold integer particle indices .* got nan"),
        ({"pins": [99]}, "pin index 99 is out of range: particles are 0..15"),
        ({"origin": "abc"}, "origin must be 3 numbers"),
        ({"origin": (0, 0)}, "origin must be 3 numbers"),
        ({"origin": (0, NAN, 0)}, r"origin\[1\] must be a finite number"),
        ({"spring_params": "abc"}, "spring_params must map each SpringType to SpringParams"),
        ({"device": "cuda:7"}, "device 'cuda:7' is not available"),
        ({"device": "gpu"}, "device 'gpu' is not available"),
        ({"device": 7}, "device must be a device name"),
    ],
)
def test_build_grid_cloth_bad_arguments(kwargs, match):
    args = {"rows": 4, "cols": 4, **kwargs}
    with pytest.raises(WarpclothError, match=match):
        build_grid_cloth(**args)


def test_a_pin_given_as_an_integral_float_or_numpy_int_is_accepted():
    import numpy as np

    model = build_grid_cloth(4, 4, pins=[0.0, np.int64(3)], device="cpu")
    assert model.pinned.tolist() == [0, 3]


@pytest.fixture(scope="module")
def sim():
    return Simulator(build_grid_cloth(4, 4, pins=[0], device="cpu"), "explicit_euler", dt=1e-3)


@pytest.mark.parametrize(
    "model,control,match",
    [
        ("not a model", None, "model must be a ClothModel"),
        (None, None, "model must be a ClothModel"),
        ("grid", "x", "control must be a warpcloth.Control"),
    ],
)
def test_simulator_bad_model_and_control(model, control, match):
    model = build_grid_cloth(3, 3, device="cpu") if model == "grid" else model
    with pytest.raises(WarpclothError, match=match):
        Simulator(model, control=control)


@pytest.mark.parametrize("steps", [1.5, "3", None, NAN, True, -1])
def test_simulate_needs_an_integer_count(sim, steps):
    with pytest.raises(WarpclothError, match="steps must be an integer >= 0"):
        sim.simulate(steps)


def test_run_keywords(sim, tmp_path):
    with pytest.raises(WarpclothError, match="unknown keyword 'usd_path'; its keywords are duration, fps"):
        RunHarness(sim).run(0.1, usd_path="x.usda")
    with pytest.raises(WarpclothError, match="frames must be a frame sink with write_frame"):
        RunHarness(sim).run(0.1, frames=3)
    with pytest.raises(WarpclothError, match="fps .* frames per step"):
        RunHarness(sim).run(0.05, fps=1e12, wall_cap=2)
    out = tmp_path / "x.usda"
    writer = UsdWriter(str(out), sim.model, 60.0)
    r = RunHarness(sim).run(0.05, frames=writer, warm_up=False)  # a writer receives every frame
    writer.close()
    assert r.frames >= 3 and out.exists() and "timeSamples" in out.read_text()


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"instability_strain": -1.0}, "instability strain must be > 0"),
        ({"equilibrium": 3}, "equilibrium must be an EquilibriumCriteria"),
        ({"energy": "x"}, "energy must be an EnergyCriteria"),
    ],
)
def test_harness_bad_settings(sim, kwargs, match):
    with pytest.raises(WarpclothError, match=match):
        RunHarness(sim, **kwargs)
    with pytest.raises(WarpclothError, match="RunHarness needs a warpcloth.Simulator"):
        RunHarness("sim")


@pytest.mark.parametrize(
    "kwargs,match",
    [
        ({"rows": INF}, "rows must be an integer"),
        ({"stiffness": "abc"}, "stiffness must be a number, got 'abc'"),
        ({"stiffness": {"foo": 1}}, "stiffness: unknown spring type 'foo'; the types are structural, shear, bend"),
        ({"stiffness": (1.0, 2.0)}, "stiffness per type must be 3 values"),
        ({"damping": -1.0}, "damping must be >= 0"),
        ({"integrator_options": {"iterations": 3}}, "integrator 'explicit_euler' has no option 'iterations'"),
    ],
)
def test_scenario_build_bad_arguments(kwargs, match):
    with pytest.raises(WarpclothError, match=match):
        sheet.build(rows=4, cols=4, **kwargs) if "rows" not in kwargs else sheet.build(cols=4, **kwargs)


@pytest.mark.parametrize(
    "name,options,match",
    [
        ("implicit_euler", {"cg_max_iter": 1.5}, "cg_max_iter must be an integer, got 1.5"),
        ("xpbd", {"iterations": 10**9}, r"iterations must be at most 10000"),
        ("pbd", {"substeps": 10**7}, r"substeps must be at most 10000"),
        ("xpbd", {"iterations": True}, "iterations must be an integer"),
    ],
)
def test_integrator_options_reject_non_integral_and_absurd_counts(name, options, match):
    with pytest.raises(WarpclothError, match=match):
        make_integrator(name, **options)


def test_control_bad_arguments():
    with pytest.raises(WarpclothError, match="drag must be a number"):
        Control(drag_rate="fast")
    with pytest.raises(WarpclothError, match="device 'foo' is not available"):
        Control(device="foo")
    with pytest.raises(WarpclothError, match="gravity must be 3 numbers"):
        Control(gravity="abc")


# -- issue 31 ----------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "call,match",
    [
        (
            lambda: sheet.SCENARIO.run(integrator_options="abc", rows=4, cols=4, duration=0.01),
            "integrator_options must be a dict of option names and values, got 'abc'",
        ),
        (
            lambda: sheet.SCENARIO.run(usd_path=123, rows=4, cols=4, duration=0.01),
            "USD path must be a file name, got 123",
        ),
        (lambda: UsdWriter(123, build_grid_cloth(3, 3, device="cpu")), "USD path must be a file name, got 123"),
    ],
)
def test_scenario_run_bad_arguments(call, match):
    with pytest.raises(WarpclothError, match=match):
        call()


@pytest.mark.parametrize(
    "call,match",
    [
        (lambda: WindSchedule.gusts("abc", 1.0, 1.0), r"gust wind must be 3 numbers \[m/s\], got 'abc'"),
        (lambda: WindSchedule.gusts((1, 0, 0), "abc", 1.0), "gust on duration must be a number, got 'abc'"),
        (lambda: WindSchedule.gusts((1, 0, 0), 1.0, -1.0), "gust off duration must be > 0 s"),
        (
            lambda: WindSchedule.gusts((1, 0, 0), 1.0, 1.0, base=(0, NAN, 0)),
            r"gust base wind\[1\] must be a finite number",
        ),
        (lambda: WindSchedule.constant((NAN, 0, 0)), r"wind\[0\] must be a finite number, got nan"),
        (lambda: WindSchedule.constant("abc"), r"wind must be 3 numbers \[m/s\]"),
        (
            lambda: WindSchedule(starts=(0.0, INF), winds=((0, 0, 0), (1, 0, 0))),
            "wind schedule start 1 must be a finite number",
        ),
        (lambda: WindSchedule(starts="ab", winds=((0, 0, 0), (1, 0, 0))), "wind schedule starts must be a sequence"),
        (lambda: WindSchedule(starts=(0.0,), winds=(("a", 0, 0),)), r"wind schedule wind 0\[0\] must be a number"),
    ],
)
def test_wind_schedule_bad_arguments(call, match):
    with pytest.raises(WarpclothError, match=match):
        call()
