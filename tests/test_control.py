"""Control: the wind schedule on the device agrees with the host at exact switch times and follows
reassignment; one device rule for every builder."""

import numpy as np
import pytest
import warp as wp
from helpers import spring_params

from warpcloth import Control, Simulator, WarpclothError, WindSchedule, build_grid_cloth
from warpcloth.scenarios import flag, sheet
from warpcloth.sim.device import resolve_device
from warpcloth.sim.model import build_model


def device_wind_per_step(schedule, dt, steps, use_graph=False):
    model = build_grid_cloth(3, 3, device="cpu")
    control = Control(wind_coefficient=0.6, wind_schedule=schedule, device="cpu")
    sim = Simulator(model, "explicit_euler", control, dt=dt, use_graph=use_graph)
    out = []
    for _ in range(steps):
        sim.step()
        control.update()  # W at the time reached, as the next step sees it
        out.append((sim.sim_time, control.wind.numpy()[0].copy()))
    return out


@pytest.mark.parametrize(
    "schedule,dt,steps",
    [
        (WindSchedule(starts=(0.0, 0.1), winds=((8.0, 0.0, 3.0), (2.0, 0.0, -1.0))), 1e-4, 1010),
        (
            WindSchedule.gusts((8.0, 0.0, 3.0), on=0.1, off=0.15),
            1e-3,
            400,
        ),  # float32(0.35) mod 0.25 < 0.1 switched late
        (WindSchedule.gusts((8.0, 0.0, 3.0), on=0.3, off=0.2), 1.0 / 60.0, 90),
    ],
)
def test_device_schedule_equals_host_schedule_at_every_step(schedule, dt, steps):
    for t, w in device_wind_per_step(schedule, dt, steps):
        np.testing.assert_array_equal(w, schedule(t).astype(np.float32), err_msg=f"t = {t!r}")


def test_time_is_steps_times_dt_so_switch_times_land_on_steps():
    sim = Simulator(build_grid_cloth(3, 3, device="cpu"), "explicit_euler", Control(device="cpu"), dt=1e-4)
    sim.simulate(1000)
    assert sim.sim_time == 0.1 and float(sim.control.time.numpy()[0]) == 0.1  # a running sum gives 0.09999999999999937
    sim.set_dt(1e-3)
    sim.simulate(100)
    assert sim.sim_time == float(sim.control.time.numpy()[0]) == 0.1 + 100 * 1e-3


def test_reassigned_wind_schedule_reaches_the_device():
    control = Control(wind_coefficient=0.6, wind_schedule=WindSchedule.constant((1.0, 0.0, 0.0)), device="cpu")
    np.testing.assert_array_equal(control.wind.numpy()[0], [1.0, 0.0, 0.0])
    control.wind_schedule = WindSchedule.constant((0.0, 0.0, 5.0))
    np.testing.assert_array_equal(control.wind.numpy()[0], [0.0, 0.0, 5.0])
    control.wind_schedule = WindSchedule(
        starts=(0.0, 1.0, 2.0), winds=((1, 1, 1), (2, 2, 2), (3, 3, 3))
    )  # more entries
    control.set_time(1.5)
    np.testing.assert_array_equal(control.wind.numpy()[0], [2.0, 2.0, 2.0])
    with pytest.raises(WarpclothError, match="wind_schedule must be a WindSchedule"):
        control.wind_schedule = "gusty"


def test_reassigned_schedule_changes_a_captured_run():
    a, b = flag.build(rows=4, cols=5), flag.build(rows=4, cols=5)
    a.simulate(20)
    b.simulate(20)
    b.control.wind_schedule = WindSchedule.constant((0.0, 0.0, -8.0))
    a.simulate(60)
    b.simulate(60)
    assert np.abs(a.state.particle_q.numpy() - b.state.particle_q.numpy()).max() > 1e-3


def test_one_device_rule():
    current = wp.get_device()
    assert resolve_device(None) == current
    grid = build_grid_cloth(3, 3)
    scenario = sheet.build(rows=3, cols=3)
    arrays = build_model([[0, 0, 0], [1, 0, 0]], [[0, 1]], [0], [1.0, 1.0], spring_params(1.0))
    for device in (grid.device, scenario.model.device, arrays.device, Control().device):
        assert isinstance(device, wp.Device) and device == current
    assert build_grid_cloth(3, 3, device="cpu").particle_q.device == wp.get_device("cpu")


@pytest.mark.parametrize("device", ["gpu", "foo", 7, "cuda:7", ""])
def test_bad_devices_name_the_value_and_what_exists(device):
    with pytest.raises(WarpclothError, match=r"device .*(available: cpu|not available)"):
        build_grid_cloth(3, 3, device=device)
    with pytest.raises(WarpclothError, match="available"):
        sheet.build(rows=3, cols=3, device=device)


@pytest.mark.parametrize("rows,cols", [(10**9, 8), (20000, 20000), (10**20, 3)])
def test_a_cloth_too_large_for_memory_is_refused_before_allocating(rows, cols):
    with pytest.raises(WarpclothError, match=r"cloth needs about .* but cpu has .* available"):
        build_grid_cloth(rows, cols, device="cpu")


@pytest.mark.parametrize("bad", [float("inf"), float("nan"), 2.5, "abc"])
def test_rows_that_are_not_integers(bad):
    with pytest.raises(WarpclothError, match="rows must be an integer"):
        build_grid_cloth(bad, 4, device="cpu")
