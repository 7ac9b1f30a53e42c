"""The float64 reference (warpcloth.lab.reference) against exact answers, against the Warp force
kernels (a second implementation of the same model), and against warpcloth's float32 integrators.

Every test compares with a number that does not come from the code under test: a closed form, a
hand-computed force, the Warp kernels, or the float32 integrators converging to it."""

import itertools
import math

import numpy as np
import pytest
import warp as wp
from helpers import single_spring, spring_params

from warpcloth import Control, Simulator, SpringType, WarpclothError, WindSchedule, build_grid_cloth
from warpcloth.integrators.forces import eval_forces
from warpcloth.lab.reference import (
    Float64Model,
    cloth_size,
    convergence_check,
    reference_forces,
    reference_trajectory,
    simulate_frames,
    static_equilibrium,
    swing_from_horizontal,
    trajectory_error,
    wind_switch_times,
)
from warpcloth.scenarios import flag, sheet
from warpcloth.sim.model import SpringParams, build_model

NO_GRAVITY = (0.0, 0.0, 0.0)
G = 9.81


# -- exact dynamics ----------------------------------------------------------------------------
def test_single_spring_oscillates_with_the_exact_period():
    """A pinned spring, stretched by s along its axis and released, moves exactly as
    y(t) = -L0 - s cos(2 pi t / T), T = 2 pi sqrt(m/k): sampled every T/8 over two periods."""
    ks, mass, rest, s = 40.0, 0.1, 0.5, 0.05
    model = single_spring(ks=ks, mass=mass, rest=rest)
    mass = float(model.host.mass[1])  # the model's float32 value: the reference is exact for it
    period = 2 * math.pi * math.sqrt(mass / ks)
    x0 = model.host.q.astype(np.float64)
    x0[1, 1] -= s
    traj = reference_trajectory(model, Control(gravity=NO_GRAVITY), 2 * period, period / 8, x0=x0)
    k = np.arange(17)
    exact = -rest - s * np.cos(k * math.pi / 4)
    assert np.abs(traj[:, 1, 1] - exact).max() < 1e-9
    assert (
        np.abs(traj[:, 1, [0, 2]]).max() == 0.0 and np.abs(traj[:, 0]).max() == 0.0
    )  # no sideways motion; the pin stays
    # the period itself: back at the start after T and 2T, at the other extreme after T/2
    assert abs(traj[8, 1, 1] - x0[1, 1]) < 1e-9 and abs(traj[16, 1, 1] - x0[1, 1]) < 1e-9
    assert abs(traj[4, 1, 1] - (-rest + s)) < 1e-9


def test_hanging_mass_released_at_rest_length_oscillates_about_m_g_over_k():
    """Gravity and spring together: released at L0, the mass oscillates about y0 - L0 - m g/k
    with amplitude m g/k."""
    ks, mass, rest = 40.0, 0.1, 0.5
    model = single_spring(ks=ks, mass=mass, rest=rest)
    mass = float(model.host.mass[1])
    omega = math.sqrt(ks / mass)
    frame_dt = 0.01
    traj = reference_trajectory(model, Control(), 0.5, frame_dt)
    t = np.arange(51) * frame_dt
    sag = mass * G / ks
    exact = -rest - sag + sag * np.cos(omega * t)
    assert np.abs(traj[:, 1, 1] - exact).max() < 1e-9


def test_damped_spring_matches_the_damped_oscillator():
    """Spring damping kd: m u'' = -k u - kd u' (u the stretch along the axis), exactly."""
    ks, kd, mass, rest, s = 40.0, 0.3, 0.1, 0.5, 0.05
    model = single_spring(ks=ks, mass=mass, rest=rest, kd=kd)
    mass, kd = float(model.host.mass[1]), float(model.spring_damping.numpy()[0])
    x0 = model.host.q.astype(np.float64)
    x0[1, 1] -= s
    traj = reference_trajectory(model, Control(gravity=NO_GRAVITY), 1.0, 0.02, x0=x0)
    gamma = kd / (2 * mass)
    wd = math.sqrt(ks / mass - gamma**2)
    t = np.arange(51) * 0.02
    u = np.exp(-gamma * t) * (-s * np.cos(wd * t) - gamma * s / wd * np.sin(wd * t))
    assert np.abs(traj[:, 1, 1] - (-rest + u)).max() < 1e-9


@pytest.mark.parametrize("drag", [0.0, 0.8])
def test_free_fall_is_exact(drag):
    """One free particle, no springs: x(t) = x0 + v0 t + g t^2/2 without drag; with linear drag
    c, v(t) = g/c + (v0 - g/c) e^{-ct}, x(t) = x0 + (g/c) t + (v0 - g/c)(1 - e^{-ct})/c."""
    g = np.array([0.3, -G, 0.1])
    model = build_model([[0.0, 1.0, 0.0]], np.zeros((0, 2)), [], [0.2], spring_params(1.0))
    x0, v0 = np.array([0.0, 1.0, 0.0]), np.array([1.0, 2.0, -0.5])
    traj = reference_trajectory(model, Control(gravity=tuple(g), drag_rate=drag), 1.0, 0.1, v0=[v0])
    t = np.arange(11)[:, None] * 0.1
    if drag == 0.0:
        exact = x0 + v0 * t + 0.5 * g * t**2
    else:
        vinf = g / drag
        exact = x0 + vinf * t + (v0 - vinf) * (1 - np.exp(-drag * t)) / drag
    assert np.abs(traj[:, 0] - exact).max() < 1e-10


# -- wind --------------------------------------------------------------------------------------
def _triangle_model(mass=0.05):
    # A = 1 m^2, normal +z; no springs: the wind is the only force (with gravity off)
    return build_model(
        [[0, 0, 0], [2, 0, 0], [0, 1, 0]], np.zeros((0, 2)), [], [mass] * 3, spring_params(1.0), triangles=[[0, 1, 2]]
    )


def test_wind_force_on_a_single_triangle_is_the_analytic_one():
    """f = c_w A (n . (W - v_mean)) n, one third on each vertex, computed by hand: A = 1 m^2,
    n = +z, v_mean = (0, 0, 1), W = (5, -3, 4): n . (W - v_mean) = 3, so each vertex gets
    0.6 * 1 * 3 / 3 = 0.6 N along +z (drag and gravity off)."""
    model = _triangle_model()
    v = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, -2.0], [0.0, 0.0, 4.0]])
    control = Control(gravity=NO_GRAVITY, wind_coefficient=0.6, wind_schedule=WindSchedule.constant((5.0, -3.0, 4.0)))
    f = reference_forces(model, control, model.host.q, v, t=0.0)
    np.testing.assert_allclose(f, np.tile([0.0, 0.0, 0.6], (3, 1)), rtol=0, atol=1e-15)
    # the force does not depend on the winding (n and the projection both flip)
    flipped = build_model(model.host.q, np.zeros((0, 2)), [], [0.05] * 3, spring_params(1.0), triangles=[[0, 2, 1]])
    np.testing.assert_allclose(reference_forces(flipped, control, model.host.q, v), f, rtol=0, atol=1e-15)
    # rotating the triangle, its velocities and the wind rotates the force
    R = np.linalg.qr(np.random.default_rng(3).normal(size=(3, 3)))[0]
    rotated = Control(
        gravity=NO_GRAVITY, wind_coefficient=0.6, wind_schedule=WindSchedule.constant(tuple(R @ [5.0, -3.0, 4.0]))
    )
    np.testing.assert_allclose(
        reference_forces(model, rotated, model.host.q @ R.T, v @ R.T), f @ R.T, rtol=0, atol=1e-14
    )
    # before the schedule's first start the air is still: n . (0 - v_mean) = -1, 0.2 N along -z
    late = Control(
        gravity=NO_GRAVITY, wind_coefficient=0.6, wind_schedule=WindSchedule(starts=(1.0,), winds=((5.0, -3.0, 4.0),))
    )
    np.testing.assert_allclose(
        reference_forces(model, late, model.host.q, v, t=0.5), np.tile([0.0, 0.0, -0.2], (3, 1)), rtol=0, atol=1e-15
    )


def test_a_free_triangle_follows_a_switching_wind_exactly():
    """A free triangle in wind translates along its normal: m v' = (c_w A / 3)(W_n(t) - v) - m c v,
    with W_n piecewise constant (gusts, periodic). Exact piecewise exponentials, through 5 switches
    (the reference restarts at each)."""
    mass, cw, drag, area = 0.05, 0.6, 0.4, 1.0
    schedule = WindSchedule.gusts((1.0, 2.0, 3.0), on=0.3, off=0.2, base=(0.0, 0.0, -1.0))
    control = Control(gravity=NO_GRAVITY, drag_rate=drag, wind_coefficient=cw, wind_schedule=schedule)
    model = _triangle_model(mass)
    mass = float(model.host.mass[0])
    duration, frame_dt = 1.2, 0.05
    traj = reference_trajectory(model, control, duration, frame_dt)
    rate = cw * area / (3 * mass) + drag  # v' = b W_n - rate v
    b = cw * area / (3 * mass)
    # exact: integrate the piecewise linear ODE of (z, w) segment by segment in closed form
    edges = [0.0] + wind_switch_times(schedule, 0.0, duration) + [duration]
    assert edges == pytest.approx([0.0, 0.3, 0.5, 0.8, 1.0, 1.2])

    def exact(t):
        z, w = 0.0, 0.0
        for a, e in itertools.pairwise(edges):
            h = min(t, e) - a
            if h <= 0:
                break
            wn = schedule(0.5 * (a + e))[2]
            vinf = b * wn / rate
            z += vinf * h + (w - vinf) * (1 - math.exp(-rate * h)) / rate
            w = vinf + (w - vinf) * math.exp(-rate * h)
        return z

    times = np.arange(traj.shape[0]) * frame_dt
    expected = np.array([exact(t) for t in times])
    for vertex in range(3):
        assert np.abs(traj[:, vertex, 2] - expected).max() < 1e-10
    assert np.abs(traj[:, :, :2] - model.host.q[None, :, :2]).max() < 1e-12  # only along the normal
    assert abs(expected).max() > 0.05  # the wind moved it


def test_wind_switch_times():
    gusts = WindSchedule.gusts((8.0, 0.0, 3.0), on=1.5, off=1.0)
    assert wind_switch_times(gusts, 0.0, 6.0) == pytest.approx([1.5, 2.5, 4.0, 5.0])
    assert wind_switch_times(gusts, 2.0, 4.5) == pytest.approx([2.5, 4.0])
    once = WindSchedule(starts=(0.0, 0.7, 2.0), winds=((1, 0, 0), (2, 0, 0), (3, 0, 0)))
    assert wind_switch_times(once, 0.0, 1.5) == pytest.approx([0.7])
    assert wind_switch_times(WindSchedule(), 0.0, 5.0) == []


# -- the Warp force kernels, a second implementation -------------------------------------------
def _warp_forces(model, control, x, v, t):
    control.set_time(t)
    f = wp.zeros(model.particle_count, dtype=wp.vec3, device=model.device)
    xw = wp.array(x, dtype=wp.vec3, device=model.device)
    vw = wp.array(v, dtype=wp.vec3, device=model.device)
    eval_forces(model, xw, vw, control, f)
    return f.numpy().astype(np.float64)


WIND = dict(
    wind_coefficient=0.6, wind_schedule=WindSchedule.gusts((8.0, 0.0, 3.0), on=1.5, off=1.0, base=(2.0, 0.0, -1.0))
)


@pytest.mark.parametrize(
    "part,ks,kd,control",
    [
        ("springs", 1000.0, 0.0, dict(gravity=NO_GRAVITY)),
        ("spring damping", 0.0, 2.0, dict(gravity=NO_GRAVITY)),
        ("wind (gust)", 0.0, 0.0, dict(gravity=NO_GRAVITY, **WIND)),
        ("gravity and drag", 0.0, 0.0, dict(gravity=(0.5, -9.81, 0.2), drag_rate=0.7)),
        ("everything", 1000.0, 0.3, dict(drag_rate=0.7, **WIND)),
    ],
)
@pytest.mark.parametrize("t", [0.3, 2.0])  # in a gust, in the lull
def test_reference_forces_agree_with_the_warp_kernels(part, ks, kd, control, t):
    """NumPy float64 forces vs eval_forces (float32) on a deformed, moving 5x6 flag grid (bend
    springs too), one force term at a time and all together: relative agreement ~1e-7
    (float32 rounding), required < 1e-6."""
    model = build_grid_cloth(5, 6, 1.5, 1.0, 0.3, spring_params=spring_params(ks, kd), pins=[0, 6, 12], device="cpu")
    rng = np.random.default_rng(7)
    x = (model.host.q + rng.normal(0.0, 0.03, model.host.q.shape)).astype(np.float32)
    v = rng.normal(0.0, 0.7, x.shape).astype(np.float32)
    ctl = Control(device="cpu", **control)
    ref = reference_forces(model, ctl, x, v, t)
    got = _warp_forces(model, ctl, x, v, t)
    scale = np.abs(ref).max()
    assert scale > 0.05, part
    assert np.abs(got - ref).max() / scale < 1e-6, part  # measured 0.9e-7 .. 2.0e-7


# -- convergence and agreement with the float32 integrators ------------------------------------
SWING_DURATION, SWING_FRAME = 0.3, 0.01


@pytest.fixture(scope="module")
def swing():
    """The 6x6 sheet scenario swinging down from horizontal for 0.3 s, and its reference."""
    sim = sheet.build(rows=6, cols=6, device="cpu")
    x0 = swing_from_horizontal(sim.model)
    conv = convergence_check(sim.model, sim.control, SWING_DURATION, SWING_FRAME, x0=x0)
    return sim.model, sim.control.drag_rate, x0, conv


def _run(model, integrator, dt, x0, control, duration=SWING_DURATION, frame_dt=SWING_FRAME):
    sim = Simulator(model, integrator, control, dt=dt)
    sim.state.particle_q.assign(np.asarray(x0, dtype=np.float32))
    return simulate_frames(sim, duration, frame_dt)


def test_reference_is_converged_on_the_swinging_sheet(swing):
    """rtol 1e-10 vs 1e-12: the difference is far below 1e-3 of the 1 % accuracy threshold."""
    model, _, x0, conv = swing
    size = cloth_size(model)
    assert conv.difference < 1e-5 * size
    assert np.abs(conv.reference[-1] - x0).max() > 0.2  # a real transient: the sheet swung down
    assert np.abs(conv.reference[:, list(model.pinned)] - x0[list(model.pinned)]).max() == 0.0


def test_convergence_check_measures_the_integration_error():
    """At loose tolerances the difference between two tolerances is the actual error (against
    the exact solution of the single spring) to within a factor of 2."""
    ks, mass, rest, s = 40.0, 0.1, 0.5, 0.05
    model = single_spring(ks=ks, mass=mass, rest=rest)
    period = 2 * math.pi * math.sqrt(float(model.host.mass[1]) / ks)
    x0 = model.host.q.astype(np.float64)
    x0[1, 1] -= s
    control = Control(gravity=NO_GRAVITY)
    loose = dict(rtol=1e-5, atol=1e-7)
    conv = convergence_check(model, control, 4 * period, period / 8, x0=x0, **loose)
    traj = reference_trajectory(model, control, 4 * period, period / 8, x0=x0, **loose)
    exact = -rest - s * np.cos(np.arange(33) * math.pi / 4)
    error = np.abs(traj[:, 1, 1] - exact).max()
    assert error > 1e-9  # loose enough to be measurable
    assert 0.5 < conv.difference / error < 2.0


def test_explicit_euler_converges_to_the_reference_at_first_order(swing):
    """The float32 symplectic Euler run converges to the reference: e(dt) / e(dt/2) = 2 (a
    reference off by d would make the ratio tend to 1)."""
    model, drag, x0, conv = swing
    size = cloth_size(model)
    errors = [
        trajectory_error(_run(model, "explicit_euler", dt, x0, Control(drag_rate=drag)), conv.reference, size)
        for dt in (1e-4, 5e-5)
    ]
    assert errors[0] < 1e-3
    assert 1.8 < errors[0] / errors[1] < 2.2, errors


def test_rk4_agrees_with_the_reference(swing):
    """rk4 at dt 1/800 s is at the float32 floor on the swinging sheet: error < 5e-6 of the size."""
    model, drag, x0, conv = swing
    error = trajectory_error(
        _run(model, "rk4", 1 / 800, x0, Control(drag_rate=drag)), conv.reference, cloth_size(model)
    )
    assert error < 5e-6


def test_rk4_error_decreases_when_dt_halves():
    """The same transient with softer springs (ks = 100 N/m), where rk4's truncation error is
    above the float32 floor at dt = 1/200 s: halving dt cuts the error by more than 4 (4th order
    until the float32 floor)."""
    sim = sheet.build(rows=6, cols=6, device="cpu", stiffness=100.0)
    x0 = swing_from_horizontal(sim.model)
    ref = reference_trajectory(sim.model, sim.control, SWING_DURATION, SWING_FRAME, x0=x0)
    size = cloth_size(sim.model)
    errors = [
        trajectory_error(_run(sim.model, "rk4", dt, x0, Control(drag_rate=sim.control.drag_rate)), ref, size)
        for dt in (1 / 200, 1 / 400)
    ]
    assert errors[0] < 2e-5
    assert errors[0] / errors[1] > 4.0, errors


def test_flag_in_switching_wind_agrees_with_the_integrators():
    """The 4x4 flag with the wind switching at 0.1 s: the reference and float32 rk4 agree at the
    float32 floor, and explicit Euler converges to it at first order."""
    model = flag.build(rows=4, cols=4, device="cpu").model

    def control():
        return Control(
            wind_coefficient=0.6,
            wind_schedule=WindSchedule(starts=(0.0, 0.1), winds=((8.0, 0.0, 3.0), (2.0, 0.0, -1.0))),
        )

    duration, frame_dt = 0.2, 0.02
    ref = reference_trajectory(model, control(), duration, frame_dt)
    size = cloth_size(model)
    x0 = model.host.q
    assert trajectory_error(_run(model, "rk4", 1e-3, x0, control(), duration, frame_dt), ref, size) < 5e-6
    errors = [
        trajectory_error(_run(model, "explicit_euler", dt, x0, control(), duration, frame_dt), ref, size)
        for dt in (1e-4, 5e-5)
    ]
    assert 1.7 < errors[0] / errors[1] < 2.3, errors
    # without the switch the trajectory is visibly different: the test sees the schedule
    steady = Control(wind_coefficient=0.6, wind_schedule=WindSchedule.constant((8.0, 0.0, 3.0)))
    assert trajectory_error(reference_trajectory(model, steady, duration, frame_dt), ref, size) > 1e-3


# -- statics -----------------------------------------------------------------------------------
def test_single_hanging_mass_extends_by_m_g_over_k():
    ks, mass, rest = 40.0, 0.1, 0.5
    model = single_spring(ks=ks, mass=mass, rest=rest)
    mass = float(model.host.mass[1])
    eq = static_equilibrium(model, Control(), tol=1e-13)
    assert eq.residual < 1e-13
    assert eq.x[1] == pytest.approx([0.0, -rest - mass * G / ks, 0.0], abs=1e-14)
    assert np.all(eq.x[0] == 0.0)


def test_hanging_chain_extensions_are_the_weight_below_over_k():
    """A vertical chain of 6 springs from a pin, unequal masses and stiffnesses: spring i
    stretches by (weight of the particles below it) / k_i."""
    n = 6
    masses = np.array([1.0, 0.05, 0.1, 0.02, 0.08, 0.03, 0.12])
    rest = np.array([0.1, 0.2, 0.15, 0.1, 0.25, 0.1])
    y = -np.concatenate([[0.0], np.cumsum(rest)])
    q = np.stack([np.zeros(n + 1), y, np.zeros(n + 1)], axis=1)
    types = [SpringType(k % 3) for k in range(n)]
    params = {
        SpringType.STRUCTURAL: SpringParams(30.0, 0.0),
        SpringType.SHEAR: SpringParams(55.0, 0.0),
        SpringType.BEND: SpringParams(80.0, 0.0),
    }
    model = build_model(q, [[k, k + 1] for k in range(n)], types, masses, params, pins=[0])
    eq = static_equilibrium(model, Control())
    assert eq.residual < 1e-10
    ks = np.array([params[t].stiffness for t in types])
    m32 = model.host.mass.astype(np.float64)  # the model's masses (float32 values)
    weight_below = G * np.cumsum(m32[::-1])[::-1][1:]
    extension = -np.diff(eq.x[:, 1]) - model.host.rest.astype(np.float64)
    np.testing.assert_allclose(extension, weight_below / ks, rtol=1e-10)
    assert np.abs(eq.x[:, [0, 2]]).max() == 0.0


def test_stiffness_matrix_is_the_force_jacobian():
    """The analytic Hessian equals -d(force)/dx by central differences on a deformed grid
    (springs both stretched and compressed)."""
    model = build_grid_cloth(3, 4, 1.0, 0.7, 0.2, spring_params=spring_params(100.0), pins=[0], device="cpu")
    m64 = Float64Model.from_model(model, Control())
    rng = np.random.default_rng(2)
    x = model.host.q.astype(np.float64) + rng.normal(0.0, 0.05, (12, 3))
    H = m64.stiffness_matrix(x).toarray()
    h = 1e-6
    numeric = np.empty_like(H)
    for k in range(36):
        e = np.zeros(36)
        e[k] = h
        numeric[:, k] = -(m64.static_forces(x + e.reshape(-1, 3)) - m64.static_forces(x - e.reshape(-1, 3))).ravel() / (
            2 * h
        )
    assert np.abs(H - numeric).max() < 1e-6 * np.abs(H).max()
    assert np.abs(H - H.T).max() < 1e-14 * np.abs(H).max()


@pytest.mark.parametrize("stiffness", [None, 10.0])  # the scenario's sheet; a soft one that sags 6 cm
def test_sheet_equilibrium_is_where_a_damped_float32_run_settles(stiffness):
    """The 8x8 sheet: Newton reaches a residual < 1e-8 N; symplectic Euler (float32) with strong
    drag, 2 s, ends on it within 1 % of how far the cloth moved from its rest shape (and < 1 mm)."""
    sim = sheet.build(rows=8, cols=8, device="cpu", stiffness=stiffness)
    eq = static_equilibrium(sim.model, sim.control)
    assert eq.residual < 1e-8
    f = reference_forces(sim.model, Control(), eq.x, np.zeros_like(eq.x))
    free = np.ones(sim.model.particle_count, bool)
    free[sim.model.pinned] = False
    assert np.abs(f[free]).max() < 1e-8  # the residual is the net force, checked independently
    moved = np.linalg.norm(eq.x - sim.model.host.q, axis=1).max()
    dt = 5e-4 if stiffness else 2.5e-4
    run = Simulator(sim.model, "explicit_euler", Control(drag_rate=5.0), dt=dt)
    run.simulate(int(round(2.0 / dt)))
    deviation = np.linalg.norm(run.state.particle_q.numpy() - eq.x, axis=1).max()
    assert deviation < 1e-3 and deviation < 0.01 * moved, (deviation, moved)


# -- API ---------------------------------------------------------------------------------------
def test_trajectory_error_and_argument_checks():
    a = np.zeros((3, 2, 3))
    b = a.copy()
    b[1, 1] = [0.0, 0.3, 0.4]
    assert trajectory_error(a, b, 2.0) == pytest.approx(0.25)
    with pytest.raises(WarpclothError):
        trajectory_error(a, b[:2], 1.0)
    model = single_spring()
    with pytest.raises(WarpclothError, match="whole number of frames"):
        reference_trajectory(model, Control(), 0.25, 0.1)
    with pytest.raises(WarpclothError, match="shape"):
        reference_trajectory(model, Control(), 0.2, 0.1, x0=np.zeros((3, 3)))
