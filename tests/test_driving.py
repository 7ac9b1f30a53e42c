"""Driving a simulation from your own loop (PinTrack.driven, ColliderTrack.driven): a run whose pins
and sphere are set from the host each frame equals, to the bit, the run of the same motion given as
keyframes tracks; targets never recapture the frame graph; a held frame keeps the pins still; a
turned box lands on its target pose; mistakes name the fix."""

import numpy as np
import pytest

from warpcloth import Box, Control, Plane, Simulator, Sphere, WarpclothError, build_grid_cloth, integrator_names
from warpcloth.sim.colliders import ColliderTrack, quat_matrix
from warpcloth.sim.pins import PinTrack

N, FRAMES, FRAME = 12, 9, 1.0 / 60.0
CORNERS = [0, N - 1]
SPHERE = dict(center=(0.5, -0.6, -0.2), radius=0.15, friction=0.4)  # behind the hanging sheet (z = 0)


def _pins(rest, t):
    """A hand's motion for the two corners (positions (2, 3), velocities (2, 3)): smooth, curved."""
    p = rest[CORNERS] + np.array([0.3 * t, 0.1 * np.sin(5 * t), 0.2 * t * t])
    v = np.broadcast_to(np.array([0.3, 0.5 * np.cos(5 * t), 0.4 * t]), (2, 3))
    return p, v


def _ball(t):
    """The sphere's offset and its velocity: it pushes into the sheet while it swings."""
    return np.array([0.1 * np.sin(4 * t), 0.1 * t, 1.5 * t]), np.array([0.4 * np.cos(4 * t), 0.1, 1.5])


def _steps(dt):
    return max(1, round(FRAME / dt))


def _driven_run(integrator, interpolation="hermite", collider=True):
    model = build_grid_cloth(N, N, pins=CORNERS, device="cpu")
    rest = model.host.q.astype(np.float64)
    hand = PinTrack.driven(CORNERS, interpolation=interpolation, name="hand")
    colliders = (
        (Sphere(**SPHERE, track=ColliderTrack.driven(interpolation)), Plane(point=(0, -1, 0))) if collider else ()
    )
    sim = Simulator(model, integrator, Control(device="cpu", pin_tracks=(hand,), colliders=colliders))
    steps = _steps(sim.dt)
    times, frames = [0.0], []
    for k in range(FRAMES + 1):  # one frame more than compared: the track below does not end on the last one
        t1 = (k + 1) * steps * sim.dt
        p, v = _pins(rest, t1)
        sim.set_pin_targets(p, v if interpolation == "hermite" else None)
        if collider:
            d, u = _ball(t1)
            sim.set_collider_pose(0, offset=d, velocity=u if interpolation == "hermite" else None)
        sim.simulate(steps)
        times.append(float(sim.control.time.numpy()[0]))  # the device clock: the keys of the track below
        frames.append(sim.state.particle_q.numpy().copy())
    return sim, np.array(times), frames[:FRAMES]


def _track_run(integrator, dt, times, interpolation="hermite", collider=True):
    model = build_grid_cloth(N, N, pins=CORNERS, device="cpu")
    rest = model.host.q.astype(np.float64)
    steps = _steps(dt)
    hosts = [k * steps * dt for k in range(1, len(times))]
    keys = np.concatenate([[-1.0], times])  # a key before 0: at t = 0 the pins move already, as the driven ones
    pins = [_pins(rest, t) for t in hosts]
    pos = np.stack([rest[CORNERS], rest[CORNERS], *(p for p, _ in pins)])
    kw = {}
    if interpolation == "hermite":
        kw = dict(tangents=np.stack([np.zeros((2, 3)), np.zeros((2, 3)), *(v for _, v in pins)]))
    track = PinTrack.keyframes(CORNERS, keys, pos, interpolation=interpolation, **kw)
    colliders = ()
    if collider:
        ball = [_ball(t) for t in hosts]
        offsets = np.stack([np.zeros(3), np.zeros(3), *(d for d, _ in ball)])
        ckw = (
            dict(tangents=np.stack([np.zeros(3), np.zeros(3), *(u for _, u in ball)]))
            if interpolation == "hermite"
            else {}
        )
        colliders = (
            Sphere(**SPHERE, track=ColliderTrack.keyframes(keys, offsets, interpolation=interpolation, **ckw)),
            Plane(point=(0, -1, 0)),
        )
    sim = Simulator(model, integrator, Control(device="cpu", pin_tracks=(track,), colliders=colliders), dt=dt)
    frames = []
    for _ in range(FRAMES):
        sim.simulate(steps)
        frames.append(sim.state.particle_q.numpy().copy())
    return frames


@pytest.mark.parametrize("integrator", integrator_names())
def test_a_driven_run_equals_the_same_motion_as_keyframes_to_the_bit(integrator):
    # corners dragged along a curve and a sphere with friction swung into the cloth, both set
    # each frame with their velocities (hermite), against keyframes tracks through the same
    # targets at the same device times: every frame equal bit for bit (a driven run's motion is
    # the keyframes' motion, not an approximation of it)
    sim, times, driven = _driven_run(integrator)
    tracked = _track_run(integrator, sim.dt, times)
    centre = np.add(SPHERE["center"], _ball(sim.sim_time)[0])
    touching = np.linalg.norm(driven[-1] - centre, axis=1) < SPHERE["radius"] + 0.01
    assert touching.sum() >= 3  # the ball is in the cloth (its friction and motion matter)
    for k, (a, b) in enumerate(zip(driven, tracked)):
        assert np.array_equal(a.view(np.uint32), b.view(np.uint32)), f"frame {k}: {np.abs(a - b).max():.2e} m"


@pytest.mark.parametrize("integrator", ["explicit_euler", "verlet", "xpbd", "vbd"])
def test_linear_targets_equal_a_linear_track_to_the_bit(integrator):
    # positions only (velocity (p1 - p0) / frame time): the same as a linear keyframes track
    # where the step reads no velocity at the frame's last instant (no collider here; see docs/driving.md)
    sim, times, driven = _driven_run(integrator, "linear", collider=False)
    tracked = _track_run(integrator, sim.dt, times, "linear", collider=False)
    for k, (a, b) in enumerate(zip(driven, tracked)):
        assert np.array_equal(a.view(np.uint32), b.view(np.uint32)), f"frame {k}: {np.abs(a - b).max():.2e} m"


def test_targets_write_into_the_captured_frame_and_never_recapture():
    model = build_grid_cloth(N, N, pins=CORNERS, device="cpu")
    hand = PinTrack.driven(CORNERS)
    ball = ColliderTrack.driven()
    sim = Simulator(model, "xpbd", Control(device="cpu", pin_tracks=(hand,), colliders=(Sphere(**SPHERE, track=ball),)))
    assert sim.graph_enabled
    rest = model.host.q.astype(np.float64)
    sim.set_pin_targets(rest[CORNERS])
    sim.simulate(4)
    graphs, captured, version = dict(sim._graphs), sim.capture_time, sim.step_version
    for k in range(1, 6):
        target = rest[CORNERS] + [0.05 * k, 0.0, 0.0]
        hand.set(target)  # the track's own set, as sim.set_pin_targets
        ball.set(offset=(0.0, 0.02 * k, 0.0))
        sim.simulate(4)
        assert np.array_equal(sim.state.particle_q.numpy()[CORNERS], target.astype(np.float32))
    assert sim._graphs == graphs and sim.capture_time == captured and sim.step_version == version
    sphere = sim.control.collision.params.numpy()[0]
    assert np.allclose(sphere["a"], np.add(SPHERE["center"], (0.0, 0.1, 0.0)), atol=1e-6)  # the last pose set


def test_without_a_new_target_the_pins_hold_still():
    model = build_grid_cloth(N, N, pins=CORNERS, device="cpu")
    sim = Simulator(model, "explicit_euler", Control(device="cpu", pin_tracks=(PinTrack.driven(CORNERS),)))
    target = model.host.q[CORNERS] + np.float32(0.1)
    sim.set_pin_targets(target)
    sim.simulate(20)
    sim.simulate(20)  # no target: held at the last one, at rest
    x, v = sim.state.particle_q.numpy()[CORNERS], sim.state.particle_qd.numpy()[CORNERS]
    assert np.array_equal(x, target) and not v.any()


def test_a_driven_box_turns_to_its_target_pose():
    # a box turned 90 degrees about y and moved, in one frame: the device record is the host pose
    box = Box(center=(0.5, -0.5, 0.0), half_extents=(0.3, 0.1, 0.2), track=ColliderTrack.driven())
    model = build_grid_cloth(N, N, pins=CORNERS, device="cpu")
    sim = Simulator(model, "xpbd", Control(device="cpu", colliders=(box,)))
    q = np.array([0.0, np.sin(np.pi / 4), 0.0, np.cos(np.pi / 4)])
    sim.set_collider_pose(0, offset=(0.1, 0.2, 0.0), rotation=q)
    sim.simulate(4)
    record = sim.control.collision.params.numpy()[0]
    assert np.allclose(record["a"], (0.6, -0.3, 0.0), atol=1e-6)
    assert np.allclose(record["rotation"], quat_matrix(q), atol=1e-6)
    r, c, d = box.track.transform(sim.sim_time)  # the host's view (writers, players) agrees
    assert np.allclose(r, quat_matrix(q), atol=1e-9) and np.allclose(c + d, (0.6, -0.3, 0.0))
    assert np.allclose(box.at(sim.sim_time).center, (0.6, -0.3, 0.0))


def test_driving_mistakes_name_the_fix():
    model = build_grid_cloth(N, N, pins=CORNERS, device="cpu")
    sim = Simulator(model, "xpbd", Control(device="cpu", colliders=(Sphere(**SPHERE),)))
    with pytest.raises(WarpclothError, match=r"PinTrack.driven"):
        sim.set_pin_targets(np.zeros((2, 3)))
    with pytest.raises(WarpclothError, match=r"ColliderTrack.driven"):
        sim.set_collider_pose(0, offset=(0, 0, 0))
    hand = PinTrack.driven(CORNERS, interpolation="hermite")
    with pytest.raises(WarpclothError, match=r"shape \(2, 3\)"):
        hand.set(np.zeros((3, 3)), np.zeros((3, 3)))
    with pytest.raises(WarpclothError, match=r"velocities"):
        hand.set(np.zeros((2, 3)))
    with pytest.raises(WarpclothError, match=r"not driven"):
        PinTrack.keyframes(CORNERS, [0.0], [[0, 0, 0]]).set(np.zeros((2, 3)))


def test_the_documented_loop_runs(tmp_path, capsys):
    # docs/driving.md's loop, as python -m warpcloth.examples.drive: the corner lands on its last target
    from warpcloth.examples import drive

    drive.main(["--num-frames", "6", "--size", "8", "--usd", str(tmp_path / "drive.usda"), "--device", "cpu"])
    out = capsys.readouterr().out
    assert "graph replay: True" in out and (tmp_path / "drive.usda").exists()
