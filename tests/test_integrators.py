"""Explicit integrators against analytic answers: period, convergence order, energy, pins."""

import math

import numpy as np
import pytest
import warp as wp
from helpers import assert_replay_matches_launches, displace, reference_rk4, simulate, single_spring, small_grid

from warpcloth import Control, Simulator, WarpclothError, make_integrator
from warpcloth.integrators import explicit_euler_dt_bound, stable_dt_estimate
from warpcloth.run.harness import RunHarness

EXPLICIT = ["explicit_euler", "midpoint", "rk4", "verlet"]
NO_GRAVITY = (0.0, 0.0, 0.0)


def measured_period(integrator, ks=40.0, mass=0.1, periods=4, steps_per_period=400):
    """Period of a single undamped mass on a spring, from upward zero crossings of its stretch."""
    model = single_spring(ks=ks, mass=mass)
    T = 2 * math.pi * math.sqrt(mass / ks)
    dt = T / steps_per_period
    sim = Simulator(model, integrator, Control(gravity=NO_GRAVITY), dt=dt)
    displace(sim, 1, (0.0, -0.05, 0.0))
    rest_y = -0.5
    crossings, prev = [], None
    for k in range(int(periods * steps_per_period)):
        sim.step()
        y = float(sim.state.particle_q.numpy()[1, 1]) - rest_y
        if prev is not None and prev < 0.0 <= y:
            crossings.append((k + prev / (prev - y)) * dt)  # linear interpolation of the crossing
        prev = y
    return np.diff(crossings).mean(), T


@pytest.mark.parametrize("integrator", EXPLICIT)
def test_single_spring_period(integrator):
    period, exact = measured_period(integrator)
    assert abs(period - exact) / exact < 0.01


@pytest.fixture(scope="module")
def small_grid_reference() -> np.ndarray:
    """small_grid()'s positions after 1 s by float64 RK4 in 4096 steps (NumPy, ~1 s of CPU): computed once
    for every scheme's convergence order (one xdist group, tests/conftest.py; read-only, so that no test
    can change another's reference)."""
    x = reference_rk4(small_grid(), 1.0, 4096)
    x.flags.writeable = False
    return x


@pytest.mark.parametrize(
    "integrator,dts,order,tol",
    [
        ("explicit_euler", (1 / 128, 1 / 256), 1.0, 0.2),
        ("midpoint", (1 / 64, 1 / 128), 2.0, 0.2),
        ("verlet", (1 / 64, 1 / 128), 2.0, 0.2),
        ("rk4", (1 / 32, 1 / 64), 4.0, 0.3),
    ],
)
def test_convergence_order(integrator, dts, order, tol, small_grid_reference):
    """Error after 1 s against a float64 RK4 reference; order = log2(e(dt) / e(dt/2))."""
    duration = 1.0
    reference = small_grid_reference
    errors = []
    for dt in dts:
        sim = simulate(small_grid(), integrator, dt, duration)
        errors.append(np.abs(sim.state.particle_q.numpy() - reference).max())
    measured = math.log2(errors[0] / errors[1])
    assert abs(measured - order) < tol, f"{integrator}: errors {errors}, order {measured:.2f}"


def energy_history(integrator, dt, periods=30):
    model = single_spring(ks=40.0, mass=0.1)
    T = 2 * math.pi * math.sqrt(0.1 / 40.0)
    sim = Simulator(model, integrator, Control(gravity=NO_GRAVITY), dt=dt)
    displace(sim, 1, (0.0, -0.05, 0.0))
    energies = [RunHarness(sim).energy()]
    steps = max(1, int(T / dt / 4))
    for _ in range(4 * periods):
        sim.simulate(steps)
        energies.append(RunHarness(sim).energy())
    return np.array(energies)


@pytest.mark.parametrize("integrator", ["explicit_euler", "verlet"])
def test_energy_bounded_below_stability_limit_and_not_above(integrator):
    omega = math.sqrt(40.0 / 0.1)
    e = energy_history(integrator, dt=0.5 / omega)  # h omega = 0.5 < 2
    assert np.all(np.isfinite(e))
    assert e.max() < 1.5 * e[0] and e.min() > 0.5 * e[0]
    assert abs(e[-1] - e[0]) / e[0] < 0.2  # symplectic: no drift over 30 periods
    unstable = energy_history(integrator, dt=2.2 / omega, periods=5)  # h omega = 2.2 > 2
    assert not np.all(np.isfinite(unstable)) or unstable[-1] > 1e3 * unstable[0]


@pytest.mark.parametrize("integrator", EXPLICIT)
def test_free_fall_is_exact_per_scheme(integrator):
    """No springs, constant a = g: midpoint, RK4 and Verlet give x = x0 + g t^2 / 2 exactly;
    explicit Euler's positions lead by g t dt / 2. Velocities: exact, except Verlet's
    (x_new - x) / dt, which is the half-step velocity g (t - dt/2). The scheme-specific terms
    (0.05 m, 0.05 m/s here) are 10x the float32 tolerance (Verlet's roundoff grows as n^2)."""
    from helpers import spring_params

    from warpcloth.sim.model import build_model

    g, dt, n = 10.0, 0.01, 100
    model = build_model([[0.0, 0.0, 0.0]], np.zeros((0, 2)), np.zeros(0), [1.0], spring_params(0.0))
    sim = simulate(model, integrator, dt, n * dt, Control(gravity=(0.0, -g, 0.0)))
    t = n * dt
    y = float(sim.state.particle_q.numpy()[0, 1])
    vy = float(sim.state.particle_qd.numpy()[0, 1])
    expected_y = -0.5 * g * t * t - (0.5 * g * t * dt if integrator == "explicit_euler" else 0.0)
    expected_v = -g * (t - 0.5 * dt) if integrator == "verlet" else -g * t
    assert abs(y - expected_y) < 5e-3
    assert abs(vy - expected_v) < 5e-3


def test_switching_integrators_between_steps_keeps_the_model():
    from warpcloth.scenarios import sheet

    sim = sheet.build(rows=8, cols=8)
    model = sim.model
    sim.simulate(50)
    x_mid = sim.state.particle_q.numpy().copy()
    for name in ["rk4", "verlet", "midpoint", "explicit_euler"]:
        sim.set_integrator(name)
        sim.simulate(20)
        assert sim.model is model and sim.integrator.name == name
    x_end = sim.state.particle_q.numpy()
    assert np.all(np.isfinite(x_end)) and not np.array_equal(x_end, x_mid)
    assert sim.steps == 50 + 4 * 20


def test_verlet_after_switch_continues_smoothly():
    """A switch to Verlet must start its history from the current (x, v): the trajectory then
    matches explicit Euler's to O(dt^2), not jump by the velocity times dt."""
    from warpcloth.scenarios import sheet

    a = sheet.build(rows=6, cols=6, dt=2e-4)
    b = sheet.build(rows=6, cols=6, dt=2e-4)
    a.simulate(300)
    b.simulate(300)
    b.set_integrator("verlet")
    a.simulate(50)
    b.simulate(50)
    diff = np.abs(a.state.particle_q.numpy() - b.state.particle_q.numpy()).max()
    # the starts differ by dt^2 a / 2 per step (~3e-5 here); a history that ignored the
    # velocity (x_prev = x) would drift by |v| dt per step, ~8e-4 after 50 steps
    assert diff < 1e-4


def test_default_dt_is_below_the_stability_estimate():
    model = small_grid(ks=1000.0)
    h = stable_dt_estimate(model)
    assert 0 < h < explicit_euler_dt_bound(model) * 10
    for name in EXPLICIT:
        dt = make_integrator(name).default_dt(model, drag_rate=0.5)
        assert 0 < dt <= h * 1.0001 + 1e-12 or name == "rk4"
    assert make_integrator("midpoint").default_dt(model) == 0.0  # undamped: RK2 has no stable dt


def test_unknown_integrator_and_option():
    with pytest.raises(WarpclothError, match="unknown integrator 'leapfrog'"):
        make_integrator("leapfrog")
    with pytest.raises(WarpclothError, match="has no option 'cg_tol'"):
        make_integrator("rk4", cg_tol=1e-3)


def test_a_name_is_checked_by_one_function_wherever_it_enters():
    """check_integrator_name: the registry's names pass; 'all' only where a test list means every one;
    anything else is one line naming the value (cut to 60 characters) and the choices."""
    from warpcloth.integrators import check_integrator_name, integrator_names
    from warpcloth.run.params import BY_NAME

    assert [check_integrator_name(n) for n in integrator_names()] == integrator_names()
    assert check_integrator_name("all", allow_all=True) == BY_NAME["integrator"].check("all") == "all"
    choices = ", ".join(integrator_names())
    for name, flag, message in (
        ("all", None, f"unknown integrator 'all'; choose from {choices}"),
        ("all", "--integrator", f"--integrator all is for test lists (warpcloth sweep); choose one of {choices}"),
        (" ", "--integrator", f"--integrator is empty; choose one of {choices}"),
        ("x" * 100, None, f"unknown integrator '{'x' * 56}...; choose from {choices}"),
        (3, None, f"unknown integrator 3; choose from {choices}"),
    ):
        with pytest.raises(WarpclothError) as info:
            check_integrator_name(name, flag=flag)
        assert str(info.value) == message and "\n" not in message
    with pytest.raises(WarpclothError, match=r"^integrator: unknown integrator 'rk5'; .* \(or 'all' in a test list\)$"):
        BY_NAME["integrator"].check("rk5")


from conftest import DEVICES, reproducible  # noqa: E402

#: the solvers that hold contacts themselves (vbd also with its Chebyshev projection), and schemes
#: with the projection after the step
COLLIDING = [
    ("vbd", {}),
    ("vbd", {"vbd_chebyshev_rho": 0.3}),
    ("projective", {}),
    ("pbd", {}),
    ("implicit_euler", {}),
    ("rk4", {}),
]


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("integrator,options", COLLIDING)
def test_graph_replay_with_colliders_is_bit_identical(device, integrator, options):
    """An 8 x 8 cloth (a grid: vbd's multigrid correction on) lying on a sphere that moves and a
    plane: a captured frame replayed equals the same steps launched, to the bit (the colliders'
    struct arguments are captured with the frame; moving ones are posed inside it)."""
    from warpcloth import ColliderTrack, Plane, Sphere, build_grid_cloth
    from warpcloth.simulator import graph_capture_supported

    if not graph_capture_supported(device):
        pytest.skip(f"Warp {wp.config.version} cannot capture on {device}")

    def build():
        track = ColliderTrack.rigid(velocity=(0.1, 0.0, 0.0))
        sphere = Sphere(center=(0.5, 0.0, 0.5), radius=0.3, thickness=0.005, friction=0.5, track=track)
        model = build_grid_cloth(8, 8, 1.0, 1.0, 0.1, plane="horizontal", origin=(0.0, 0.31, 0.0), device=device)
        control = Control(colliders=(sphere, Plane(thickness=0.005, friction=0.5)), device=device)
        return Simulator(model, make_integrator(integrator, **options), control)  # its default dt

    with reproducible(device):  # on CUDA the atomics' order otherwise changes from launch to launch
        a, b = build(), build()
        if not b.integrator.capturable_on(device):
            pytest.skip(f"{integrator} does not capture on {device}")
        assert_replay_matches_launches(a, b)
    q = b.state.particle_q.numpy()
    assert np.isfinite(q).all() and np.abs(q - build().state.particle_q.numpy()).max() > 1e-4  # it moved
    if integrator in ("vbd", "projective") and not options:  # the solve holds contacts at the end
        assert b.integrator.contact_state.numpy().any()


@pytest.mark.parametrize("device", DEVICES)
def test_graph_replay_with_strain_limit_is_bit_identical(device):
    from warpcloth.scenarios import flag
    from warpcloth.simulator import graph_capture_supported

    if not graph_capture_supported(device):
        pytest.skip(f"Warp {wp.config.version} cannot capture on {device}")
    with reproducible(device):
        a = flag.build(rows=6, cols=7, device=device, stiffness=200.0, strain_limit=0.05)
        b = flag.build(rows=6, cols=7, device=device, stiffness=200.0, strain_limit=0.05)
        a.use_graph, b.use_graph = False, True
        for n in (40, 40):
            a.simulate(n)
            b.simulate(n)
        assert np.array_equal(a.state.particle_q.numpy(), b.state.particle_q.numpy())
