"""The float64 Warp RK4 reference (warpcloth.lab.reference_warp) against the SciPy DOP853
reference (an independent implementation of the same model), against closed forms for moving
pins, and its halving estimate against its true error."""

import math

import numpy as np
import pytest
from conftest import DEVICES
from helpers import single_spring

from warpcloth import Control, WarpclothError, WindSchedule
from warpcloth.lab import reference_warp as rw
from warpcloth.lab.reference import cloth_size, reference_trajectory, swing_from_horizontal, trajectory_error
from warpcloth.scenarios import flag, sheet
from warpcloth.sim.pins import PinTrack

SWING_DURATION, SWING_FRAME = 0.3, 0.01
GUST, LULL = (8.0, 0.0, 3.0), (2.0, 0.0, -1.0)


@pytest.fixture(scope="module")
def swing():
    """The 6x6 sheet scenario (drag 1/s, spring damping) released from horizontal, 0.3 s, and
    its DOP853 reference at rtol 1e-12 (converged to ~1e-14 m, docs/reference.md)."""
    sim = sheet.build(rows=6, cols=6, device="cpu")
    x0 = swing_from_horizontal(sim.model)
    exact = reference_trajectory(sim.model, sim.control, SWING_DURATION, SWING_FRAME, x0=x0, rtol=1e-12, atol=1e-14)
    return sim.model, sim.control, x0, exact


def gusty_control():
    # switches at 0.105 s (between frames) and 0.2 s (a frame), then a period of 0.2 s; drag 0.5/s
    schedule = WindSchedule(starts=(0.0, 0.105), winds=(GUST, LULL), period=0.2)
    return Control(drag_rate=0.5, wind_coefficient=0.6, wind_schedule=schedule)


# -- (a) agreement with DOP853 ---------------------------------------------------------------------
def test_agrees_with_dop853_on_the_sheet_swing(swing):
    model, control, x0, exact = swing
    r = rw.warp_reference(model, control, SWING_DURATION, SWING_FRAME, x0=x0)
    assert r.accepted and r.relative_estimate <= rw.DEFAULT_TOLERANCE
    assert r.frames.shape == exact.shape and r.frames.dtype == np.float64
    assert trajectory_error(r.frames, exact, cloth_size(model)) < 1e-7  # measured 7.6e-9
    assert np.abs(exact[-1] - x0).max() > 0.2  # a real transient: the sheet swung down


def test_agrees_with_dop853_on_a_flag_in_switching_gusts():
    """A 4x5 flag in gusts switching at 0.105 s (inside a frame) and 0.2 s, with drag, 0.3 s."""
    model = flag.build(rows=4, cols=5, device="cpu").model
    duration, frame_dt = 0.3, 1.0 / 60.0
    exact = reference_trajectory(model, gusty_control(), duration, frame_dt, rtol=1e-12, atol=1e-14)
    r = rw.warp_reference(model, gusty_control(), duration, frame_dt)
    size = cloth_size(model)
    assert r.accepted
    assert trajectory_error(r.frames, exact, size) < 1e-7  # measured 8.5e-9
    # the wind and its switches are in the dynamics: a steady gust moves the flag elsewhere
    steady = Control(drag_rate=0.5, wind_coefficient=0.6, wind_schedule=WindSchedule.constant(GUST))
    assert trajectory_error(rw.reference_trajectory(model, steady, duration, frame_dt), exact, size) > 1e-3


# -- (b) the halving estimate against the true error -------------------------------------------
def test_the_halving_estimate_is_fifteen_times_the_finer_runs_error(swing):
    """RK4's error is C h^4: |x_h - x_{h/2}| = (16 - 1) C (h/2)^4, fifteen times the error of the
    finer run it returns and 15/16 of the error of the coarser one. Measured against DOP853 at
    dt 2e-3 / 1e-3 / 5e-4 s on the swing: estimate / finer error 16.6 and 15.3 (allowed 10-25),
    estimate / coarser error 0.94 (allowed 0.8-1.25)."""
    model, control, x0, exact = swing
    size = cloth_size(model)
    loose = dict(tolerance=1.0, max_halvings=0)
    r1 = rw.warp_reference(model, control, SWING_DURATION, SWING_FRAME, x0=x0, dt=2e-3, **loose)  # runs 2e-3 and 1e-3
    r2 = rw.warp_reference(model, control, SWING_DURATION, SWING_FRAME, x0=x0, dt=1e-3, **loose)  # runs 1e-3 and 5e-4
    assert (r1.dt, r2.dt) == pytest.approx((1e-3, 5e-4), rel=1e-12)
    e1, e2 = (trajectory_error(r.frames, exact, size) for r in (r1, r2))
    assert e1 > 1e-8 and e2 > 1e-10  # far above DOP853's own error (1e-14)
    for r, e in ((r1, e1), (r2, e2)):
        assert 10.0 < r.relative_estimate / e < 25.0, (r.relative_estimate, e)
    assert 0.8 < r2.relative_estimate / e1 < 1.25, (r2.relative_estimate, e1)
    assert 10.0 < e1 / e2 < 25.0  # fourth order


def test_halves_again_until_accepted(swing):
    """Started at a step whose estimate is above the tolerance, it halves (one more run each
    time) until accepted, and returns the finest run."""
    model, control, x0, exact = swing
    r = rw.warp_reference(model, control, SWING_DURATION, SWING_FRAME, x0=x0, dt=2e-3, tolerance=2e-7)
    assert len(r.estimates) >= 2 and r.estimates[0] > 2e-7 >= r.estimates[-1]
    assert r.estimates == sorted(r.estimates, reverse=True)
    assert r.dt == pytest.approx(2e-3 / 2 ** len(r.estimates), rel=1e-12)
    assert trajectory_error(r.frames, exact, cloth_size(model)) < r.relative_estimate


# -- (c) pins ---------------------------------------------------------------------------------------
def test_a_fixed_pin_stays_put_to_the_bit(swing):
    model, control, x0, _ = swing
    r = rw.warp_reference(model, control, SWING_DURATION, SWING_FRAME, x0=x0)
    pins = list(model.pinned)
    assert np.array_equal(r.frames[:, pins], np.broadcast_to(x0[pins], r.frames[:, pins].shape))
    assert np.abs(r.frames[-1] - x0).max() > 0.2


def _spring_on_a_moving_pin():
    ks, rest = 40.0, 0.5
    model = single_spring(ks=ks, mass=0.1, rest=rest)
    omega = math.sqrt(ks / float(model.host.mass[1]))
    return model, rest, omega


def test_a_spring_on_a_pin_moving_rigidly_follows_the_closed_form():
    """Pin 0 moves down at u (a rigid track), particle 1 hangs below it at rest length, no
    gravity: the separation is s(t) = L0 - (u/omega) sin(omega t)."""
    model, rest, omega = _spring_on_a_moving_pin()
    u = 0.3
    control = Control(gravity=(0.0, 0.0, 0.0), pin_tracks=(PinTrack.rigid([0], velocity=(0.0, -u, 0.0)),))
    r = rw.warp_reference(model, control, 0.5, 0.01, dt=1e-3, tolerance=1e-9)
    t = np.arange(51) * 0.01
    np.testing.assert_allclose(r.frames[:, 0, 1], -u * t, rtol=0, atol=1e-15)  # the track, in float64
    exact = -u * t - rest + (u / omega) * np.sin(omega * t)
    assert np.abs(r.frames[:, 1, 1] - exact).max() < 1e-9
    assert np.abs(r.frames[:, :, [0, 2]]).max() == 0.0


def test_a_keyframed_pin_stopping_between_frames_follows_the_closed_form():
    """A linear keyframe track moves pin 0 down at u until t1 = 0.2337 s (inside a frame) and
    holds it there: the pin's velocity jumps, so the steps must stop at t1. After t1,
    s = L0 + A cos(omega tau) + B sin(omega tau), tau = t - t1."""
    model, rest, omega = _spring_on_a_moving_pin()
    u, t1 = 0.3, 0.2337
    track = PinTrack.keyframes([0], times=(0.0, t1), positions=[(0.0, 0.0, 0.0), (0.0, -u * t1, 0.0)])
    control = Control(gravity=(0.0, 0.0, 0.0), pin_tracks=(track,))
    r = rw.warp_reference(model, control, 0.5, 0.01, dt=1e-3, tolerance=1e-9)
    t = np.arange(51) * 0.01
    before = -u * t - rest + (u / omega) * np.sin(omega * t)
    tau = t - t1
    a, b = -(u / omega) * math.sin(omega * t1), (u - u * math.cos(omega * t1)) / omega
    after = -u * t1 - (rest + a * np.cos(omega * tau) + b * np.sin(omega * tau))
    exact = np.where(t < t1, before, after)
    assert np.abs(r.frames[:, 1, 1] - exact).max() < 1e-9
    np.testing.assert_allclose(r.frames[:, 0, 1], np.where(t < t1, -u * t, -u * t1), rtol=0, atol=1e-15)


# -- (d) bad input -----------------------------------------------------------------------------
@pytest.mark.parametrize(
    "bad, match",
    [
        (dict(duration=0.305), "whole number of frames"),
        (dict(frame_dt=0.0), "frame dt"),
        (dict(x0=np.zeros((5, 3))), "shape"),
        (dict(x0="nan"), "finite"),
        (dict(safety=0.0), "safety"),
        (dict(safety=1.5), "safety"),
        (dict(tolerance=-1e-5), "tolerance"),
        (dict(max_halvings=-1), "halvings"),
        (dict(dt=0.0), "dt"),
        (dict(control="free pin track"), "not pinned"),
        (dict(tolerance=1e-30, max_halvings=0), "did not converge"),
    ],
)
def test_bad_input_raises(swing, bad, match):
    model, control, x0, _ = swing
    args = dict(control=control, duration=0.05, frame_dt=SWING_FRAME, x0=x0)
    args.update(bad)
    if isinstance(args["x0"], str):
        args["x0"] = x0.copy()
        args["x0"][3, 1] = np.nan
    if args["control"] == "free pin track":
        args["control"] = Control(pin_tracks=(PinTrack.rigid([7], velocity=(1.0, 0.0, 0.0)),))
    with pytest.raises(WarpclothError, match=match):
        rw.warp_reference(model, **args)


def test_an_unconverged_reference_can_be_returned_flagged(swing):
    model, control, x0, _ = swing
    r = rw.warp_reference(
        model, control, 0.05, SWING_FRAME, x0=x0, tolerance=1e-30, max_halvings=0, require_accepted=False
    )
    assert not r.accepted and len(r.estimates) == 1 and np.all(np.isfinite(r.frames))


# -- reproducibility and devices ----------------------------------------------------------------
def test_runs_are_bit_identical_serial_parallel_and_drop_in(swing):
    model, control, x0, _ = swing
    a = rw.warp_reference(model, control, 0.1, SWING_FRAME, x0=x0)
    b = rw.warp_reference(model, control, 0.1, SWING_FRAME, x0=x0, parallel=True)
    c = rw.reference_trajectory(model, control, 0.1, SWING_FRAME, x0=x0)
    assert np.array_equal(a.frames, b.frames) and np.array_equal(a.frames, c)
    assert a.halving_estimate == b.halving_estimate


@pytest.mark.parametrize("device", DEVICES)
def test_every_device_gives_the_cpu_trajectory(device):
    """The flag in gusts with a swinging rigid pin track: the same kernels on ``device`` agree
    with the CPU to float64 rounding (the sums have the same order; only fused multiply-adds
    and math libraries may differ)."""
    sim = flag.build(rows=4, cols=5, device="cpu")
    model = sim.model
    pins = list(model.pinned)
    control = gusty_control()
    track = PinTrack.rigid(pins, center=(0.0, 2.0, 0.0), axis=(0.0, 0.0, 1.0), swing_amplitude=0.2, swing_frequency=2.0)
    control.pin_tracks = (track,)
    cpu = rw.warp_reference(model, control, 0.2, 1.0 / 60.0, device="cpu")
    other = rw.warp_reference(model, control, 0.2, 1.0 / 60.0, device=device)
    assert trajectory_error(other.frames, cpu.frames, cloth_size(model)) < 1e-12
    assert np.abs(cpu.frames[-1, pins] - cpu.frames[0, pins]).max() > 1e-2  # the track moved the pins
