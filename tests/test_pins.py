"""Kinematic pins: tracks followed at every step time by every integrator, pinned velocity equal
to the track's derivative, a swinging rod's analytic path, implicit Euler's coupling, bad input."""

import math

import numpy as np
import pytest
from helpers import single_spring

from warpcloth import Control, Simulator, WarpclothError, build_grid_cloth, integrator_names
from warpcloth.integrators import integrator_class
from warpcloth.run.harness import RunHarness
from warpcloth.sim.pins import PinTrack

ROWS, COLS = 4, 5
TOP = list(range(COLS))


def hanging_grid(**kw):
    """A 4 x 5 grid at y = 1.5 m (float32 spacing 1.2e-7 m), its top row pinned."""
    return build_grid_cloth(ROWS, COLS, 0.8, 0.6, 0.2, pins=TOP, origin=(-0.4, 1.5, 0.0), **kw)


def curve_track():
    """Cubic keyframes (Catmull-Rom) that move and turn the top row, then stop."""
    times = [0.0, 0.013, 0.027, 0.04]
    offsets = [[0, 0, 0], [0.05, 0.01, 0.0], [0.08, -0.02, 0.03], [0.1, 0.0, 0.05]]
    return PinTrack.keyframes(TOP, times, offsets, interpolation="catmull_rom")


def ulp32(x):
    return np.spacing(np.abs(np.asarray(x, dtype=np.float32))).astype(np.float64)


def track_dt(integrator: str) -> float:
    """The step [s] of the tracks test: 2e-4 s for an explicit scheme (its default on the hanging grid
    is ~1e-3 s), 1e-3 s for the others."""
    return 2e-4 if integrator_class(integrator).explicit else 1e-3


@pytest.mark.parametrize("integrator", integrator_names())
def test_track_followed_exactly_at_every_step_time(integrator):
    model = hanging_grid()
    track = curve_track()
    sim = Simulator(
        model, integrator, Control(drag_rate=0.5, pin_tracks=(track,)), dt=track_dt(integrator), use_graph=False
    )
    rest = model.host.q
    moved = 0.0
    for _ in range(int(0.05 / sim.dt)):
        sim.step()
        t = float(sim.control.time.numpy()[0])
        x, v = sim.state.particle_q.numpy()[TOP], sim.state.particle_qd.numpy()[TOP]
        want_x, want_v = track.evaluate(t, rest)
        assert np.all(np.abs(x - want_x) <= ulp32(want_x)), (t, x - want_x)  # the track rounded once to float32
        np.testing.assert_allclose(v, want_v, rtol=1e-6, atol=1e-6)
        moved = max(moved, float(np.abs(want_x - rest[TOP]).max()))
    assert moved > 0.09  # the pins did go along the track
    x = sim.state.particle_q.numpy()
    assert np.all(np.isfinite(x))
    assert np.abs(x[COLS:] - rest[COLS:]).max() > 1e-3  # and dragged the free cloth with them


def test_pinned_velocity_is_the_track_derivative():
    track = curve_track()
    rest = hanging_grid().host.q
    for t in np.linspace(0.0005, 0.0395, 17):
        h = 1e-6
        numeric = (track.evaluate(t + h, rest)[0] - track.evaluate(t - h, rest)[0]) / (2 * h)
        np.testing.assert_allclose(track.evaluate(t, rest)[1], numeric, rtol=1e-6, atol=1e-6)
    # linear keyframes: the secant velocity, zero before the first key and after the last
    lin = PinTrack.keyframes([0], [0.0, 0.5], [[0, 0, 0], [1.0, 0, 0]])
    assert lin.evaluate(0.25, rest)[1][0].tolist() == [2.0, 0.0, 0.0]
    assert lin.evaluate(0.6, rest)[1][0].tolist() == [0.0, 0.0, 0.0]
    # Catmull-Rom through the keys, Hermite with given tangents
    np.testing.assert_allclose(track.evaluate(0.027, rest)[0], rest[TOP] + [0.08, -0.02, 0.03], atol=1e-15)
    her = PinTrack.keyframes(
        [0], [0.0, 1.0], [[0, 0, 0], [1.0, 0, 0]], interpolation="hermite", tangents=[[3.0, 0, 0], [0, 0, 0]]
    )
    np.testing.assert_allclose(her.evaluate(1e-9, rest)[1][0], [3.0, 0, 0], atol=1e-7)


@pytest.mark.parametrize("integrator", ["explicit_euler", "implicit_euler", "xpbd"])
def test_swinging_rod_follows_the_analytic_path_with_bounded_strain(integrator):
    """The top row hangs from a rod through (0, 1.5, 0) along x that swings about its own axis by
    theta(t) = A sin(2 pi f t): each pin moves on a circle of radius r = its distance from the
    rod, here r = 0 for the rod itself, so pins are offset 0.1 m below it."""
    rows, cols = 6, 6
    model = build_grid_cloth(rows, cols, 0.5, 0.5, 0.1, pins=range(cols), origin=(-0.25, 1.4, 0.0))
    amplitude, frequency = 0.6, 1.0
    track = PinTrack.rigid(
        range(cols), center=(0.0, 1.5, 0.0), axis=(1.0, 0.0, 0.0), swing_amplitude=amplitude, swing_frequency=frequency
    )
    dt = {"explicit_euler": 2e-4, "implicit_euler": 2e-3, "xpbd": 1 / 120}[integrator]
    sim = Simulator(model, integrator, Control(drag_rate=0.5), dt=dt)
    sim.set_pin_track(track)
    result = RunHarness(sim).run(1.0, fps=30)
    t = float(sim.control.time.numpy()[0])
    theta = amplitude * math.sin(2 * math.pi * frequency * t)
    # analytic: a pin 0.1 m below the rod at x0 is at (x0, 1.5 - 0.1 cos theta, -0.1 sin theta)... rotating +theta about
    # +x
    x = sim.state.particle_q.numpy()[:cols]
    want = np.stack(
        [model.host.q[:cols, 0], 1.5 - 0.1 * np.cos(theta) * np.ones(cols), -0.1 * np.sin(theta) * np.ones(cols)],
        axis=1,
    )
    np.testing.assert_allclose(x, want, atol=2e-7)
    v = sim.state.particle_qd.numpy()[:cols]
    theta_dot = amplitude * 2 * math.pi * frequency * math.cos(2 * math.pi * frequency * t)
    np.testing.assert_allclose(
        v, np.tile([0.0, 0.1 * math.sin(theta) * theta_dot, -0.1 * math.cos(theta) * theta_dot], (cols, 1)), atol=1e-6
    )
    assert result.stable
    assert result.max_strain < 0.05  # the cloth follows the rod without being torn
    free = sim.state.particle_q.numpy()[cols:]
    assert np.abs(free[:, 2]).max() > 0.02  # and it swung with it


def test_implicit_euler_couples_the_prescribed_pin_velocity():
    """One implicit step of a pin that starts moving: the free particle's dv from the float64
    linear system with the pin's known dv moved to the right-hand side."""
    ks, kd, m, h = 40.0, 0.5, 0.1, 0.01
    model = single_spring(ks=ks, kd=kd, mass=m, rest=0.5, stretch=0.0)
    q = model.host.q.astype(np.float64)
    track = PinTrack.keyframes([0], [0.0, 1.0], [[0, 0, 0], [0, 1.0, 0]])  # the pin starts up along the spring at 1 m/s
    sim = Simulator(model, "implicit_euler", Control(pin_tracks=[track]), dt=h, use_graph=False)
    sim.integrator.cg_tol = 1e-7
    x1 = q[1] + [0.0, -0.05, 0.0]  # stretched 5 cm
    xs = sim.state.particle_q.numpy()
    xs[1] = x1
    sim.state.particle_q.assign(xs)
    sim.step()
    d = x1 - q[0]
    L = np.linalg.norm(d)
    n = d / L
    nn = np.outer(n, n)
    K = ks * (nn + max(0.0, 1 - 0.5 / L) * (np.eye(3) - nn))
    D = kd * nn
    B = h * D + h * h * K
    f1 = -ks * (L - 0.5) * n + m * np.array([0.0, -9.81, 0.0])
    dv_pin = np.array([0.0, 1.0, 0.0])  # (track(h) - x)/h - v with v = 0
    dv = np.linalg.solve(m * np.eye(3) + B, h * f1 + B @ dv_pin)
    np.testing.assert_allclose(sim.state.particle_qd.numpy()[1], dv, rtol=1e-4, atol=1e-6)
    np.testing.assert_allclose(sim.state.particle_q.numpy()[1], x1 + h * dv, atol=3e-7)
    uncoupled = np.linalg.solve(m * np.eye(3) + B, h * f1)
    assert np.abs(dv - uncoupled).max() > 0.05  # the coupling matters (B dv_pin / m ~ 0.08 m/s)
    np.testing.assert_allclose(sim.state.particle_q.numpy()[0], q[0] + [0, h, 0], atol=1e-8)


def test_captured_frame_replays_the_track_bit_identically():
    runs = []
    for graph in (False, True):
        sim = Simulator(hanging_grid(), "rk4", Control(pin_tracks=(curve_track(),)), dt=2e-4, use_graph=graph)
        sim.simulate(40)
        sim.simulate(40)
        runs.append((sim.state.particle_q.numpy(), sim.state.particle_qd.numpy()))
    assert np.array_equal(runs[0][0], runs[1][0]) and np.array_equal(runs[0][1], runs[1][1])


def test_set_pin_track_clears_and_replaces():
    sim = Simulator(hanging_grid(), "explicit_euler", dt=2e-4)
    sim.set_pin_track(PinTrack.rigid(TOP, velocity=(1.0, 0.0, 0.0)))
    sim.simulate(10)
    x = sim.state.particle_q.numpy()[TOP]
    np.testing.assert_allclose(x[:, 0] - sim.model.host.q[TOP, 0], 10 * 2e-4, atol=1e-7)
    sim.set_pin_track()
    sim.simulate(10)
    assert np.array_equal(sim.state.particle_q.numpy()[TOP], x)  # without a track the pins stay


def test_bad_tracks_are_refused():
    with pytest.raises(
        WarpclothError, match=r"keyframes out of order: time 0.1 s \(key 2\) is not after 0.5 s \(key 1\)"
    ):
        PinTrack.keyframes([0], [0.0, 0.5, 0.1], [[0, 0, 0]] * 3)
    with pytest.raises(WarpclothError, match="interpolation must be one of linear, catmull_rom, hermite, got 'cubic'"):
        PinTrack.keyframes([0], [0.0], [[0, 0, 0]], interpolation="cubic")
    with pytest.raises(WarpclothError, match="'hermite' needs tangents"):
        PinTrack.keyframes([0], [0.0, 1.0], [[0, 0, 0]] * 2, interpolation="hermite")
    with pytest.raises(WarpclothError, match=r"positions must have shape \(K, 3\) offsets or \(K, P, 3\)"):
        PinTrack.keyframes([0, 1], [0.0, 1.0], np.zeros((2, 3, 3)))
    with pytest.raises(WarpclothError, match="times must be finite"):
        PinTrack.keyframes([0], [0.0, math.nan], [[0, 0, 0]] * 2)
    with pytest.raises(WarpclothError, match="axis must be a non-zero 3-vector"):
        PinTrack.rigid([0], axis=(0, 0, 0))
    with pytest.raises(WarpclothError, match=r"particle 7 is not pinned in the model"):
        Simulator(hanging_grid(), "explicit_euler", Control(pin_tracks=[PinTrack.rigid([0, 7])]), dt=1e-4)
    with pytest.raises(WarpclothError, match=r"particle 99 is out of range"):
        Simulator(hanging_grid(), "explicit_euler", Control(pin_tracks=[PinTrack.rigid([99])]), dt=1e-4)
    with pytest.raises(WarpclothError, match=r"particle 0 is in two pin tracks"):
        Simulator(
            hanging_grid(),
            "explicit_euler",
            Control(pin_tracks=[PinTrack.rigid([0], name="a"), PinTrack.rigid([0, 1], name="b")]),
            dt=1e-4,
        )


@pytest.mark.parametrize("integrator", ["midpoint", "rk4"])
def test_runge_kutta_stages_see_the_pin_at_the_stage_times(integrator):
    """One step of a spring whose pin moves up along it at 1 m/s: the float64 Runge-Kutta step
    with the pin at track(t + c_k h) in each stage (c = 0, 1/2 for midpoint; 0, 1/2, 1/2, 1 for RK4)."""
    ks, kd, m, h, rest = 40.0, 0.2, 0.1, 0.01, 0.5
    model = single_spring(ks=ks, kd=kd, mass=m, rest=rest, stretch=0.0)
    q = model.host.q.astype(np.float64)
    track = PinTrack.rigid([0], velocity=(0.0, 1.0, 0.0))
    sim = Simulator(model, integrator, Control(pin_tracks=[track]), dt=h, use_graph=False)
    sim.step()
    g = np.array([0.0, -9.81, 0.0])

    def accel(t, x, v):
        xp, vp = q[0] + t * np.array([0.0, 1.0, 0.0]), np.array([0.0, 1.0, 0.0])
        d = xp - x
        L = np.linalg.norm(d)
        n = d / L
        return (ks * (L - rest) + kd * np.dot(vp - v, n)) * n / m + g

    x, v = q[1], np.zeros(3)
    if integrator == "midpoint":
        xm, vm = x + 0.5 * h * v, v + 0.5 * h * accel(0.0, x, v)
        want_x, want_v = x + h * vm, v + h * accel(0.5 * h, xm, vm)
    else:
        k1x, k1v = v, accel(0.0, x, v)
        k2x, k2v = v + 0.5 * h * k1v, accel(0.5 * h, x + 0.5 * h * k1x, v + 0.5 * h * k1v)
        k3x, k3v = v + 0.5 * h * k2v, accel(0.5 * h, x + 0.5 * h * k2x, v + 0.5 * h * k2v)
        k4x, k4v = v + h * k3v, accel(h, x + h * k3x, v + h * k3v)
        want_x, want_v = x + h / 6 * (k1x + 2 * k2x + 2 * k3x + k4x), v + h / 6 * (k1v + 2 * k2v + 2 * k3v + k4v)
    np.testing.assert_allclose(sim.state.particle_qd.numpy()[1], want_v, atol=2e-6)
    np.testing.assert_allclose(sim.state.particle_q.numpy()[1], want_x, atol=1e-7)
    np.testing.assert_allclose(sim.state.particle_q.numpy()[0], q[0] + [0.0, h, 0.0], atol=1e-7)
