"""Float32 awareness: integrators carry increments, so small accelerations are not rounded away
at realistic heights (y = 1.5 m, where ulp(y) = 1.2e-7 m) and small time steps."""

import numpy as np
import pytest
from test_contract import simulate_frames

from warpcloth import Control, Simulator, SpringParams, SpringType, make_integrator
from warpcloth.run.harness import RunHarness
from warpcloth.scenarios import sheet
from warpcloth.sim.model import build_model

G = 9.81
Y0 = 1.5
FORCE_BASED = ["explicit_euler", "midpoint", "rk4", "verlet", "implicit_euler"]


def _params(ks, kd=0.0):
    return {t: SpringParams(ks, kd) for t in SpringType}


def falling_pair(y=Y0):
    """Two free 0.1 kg particles 0.1 m apart on a spring of ks = 0 (it exerts nothing)."""
    return build_model(
        [[0.0, y, 0.0], [0.1, y, 0.0]], [[0, 1]], [SpringType.STRUCTURAL], [0.1, 0.1], _params(0.0), device="cpu"
    )


def sheet64_default_dt(name):
    """The integrator's default dt on the 64 x 64 sheet (7.5e-5 s for explicit Euler)."""
    return sheet.build(rows=64, cols=64, integrator=name).dt


def drop_ratio(integrator, dt, duration=0.2, y=Y0, substeps=0):
    """Drop / (g t^2 / 2); with ``substeps``, drop / the symplectic-Euler drop g h^2 M (M + 1) / 2
    of M substeps of h (the position-based integrators' exact discrete answer)."""
    model = falling_pair(y)
    sim = Simulator(model, integrator, Control(device="cpu"), dt=dt)
    steps = int(round(duration / dt))
    simulate_frames(sim, steps)
    drop = y - sim.state.particle_q.numpy()[:, 1].astype(np.float64)
    if substeps:
        h, m = dt / substeps, steps * substeps
        return drop / (0.5 * G * h * h * m * (m + 1))
    t = steps * dt
    return drop / (0.5 * G * t * t)


@pytest.mark.parametrize("fraction", [1.0, 0.25])
@pytest.mark.parametrize("name", FORCE_BASED)
def test_free_fall_from_realistic_height_at_default_and_small_dt(name, fraction):
    # verlet in the two-position form did not fall at all at 7.5e-5 s (drop ratio 0)
    # implicit Euler defaults to 1/60 s: take explicit Euler's small step for it
    dt = fraction * sheet64_default_dt("explicit_euler" if name == "implicit_euler" else name)
    assert dt < 1e-4
    # 0.1 s at the default dt, 0.025 s at a quarter of it (the same step count, ~1300; drop >= 3 mm = 25000 ulp(y)):
    # the first steps, the slowest, are the ones whose increments a rounded absolute loses
    np.testing.assert_allclose(drop_ratio(name, dt, duration=0.1 * fraction), 1.0, atol=0.01)


@pytest.mark.parametrize("substeps", [4, 200, 400])
@pytest.mark.parametrize("name", ["pbd", "xpbd"])
def test_position_based_free_fall_with_many_substeps(name, substeps):
    # with p = x + h v, v = (p - x)/h: 400 substeps at 1/60 s floated, 200 fell at 1.75 g (0.1 s: 6 steps, the
    # slowest, whose substep increments v h are the smallest against ulp(y))
    integrator = make_integrator(name, substeps=substeps, iterations=1)
    np.testing.assert_allclose(drop_ratio(integrator, 1.0 / 60.0, duration=0.1, substeps=substeps), 1.0, atol=0.01)


def hanging_mass(y=Y0, mass=0.1, ks=100.0, rest=0.5):
    q = [[0.0, y, 0.0], [0.0, y - rest, 0.0]]
    return build_model(q, [[0, 1]], [SpringType.STRUCTURAL], [mass, mass], _params(ks), pins=[0], device="cpu")


@pytest.mark.parametrize("substeps", [1, 64])
def test_xpbd_static_extension_at_realistic_height(substeps):
    # the extension is m g / k = 9.81 mm; the p = x + h v form was off by 5.6e-4 (1 substep)
    # and 2.3e-3 (64 substeps, h = 1/3840 s) relative at y = 1.5 m
    mass, ks = 0.1, 100.0
    model = hanging_mass(mass=mass, ks=ks)
    sim = Simulator(
        model,
        make_integrator("xpbd", substeps=substeps, iterations=4),
        Control(drag_rate=20.0, device="cpu"),
        dt=1.0 / 60.0,
    )
    simulate_frames(sim, 150)  # drag (which does not move the equilibrium) settles it within 2.5 s
    q = sim.state.particle_q.numpy().astype(np.float64)
    extension = (q[0, 1] - q[1, 1]) - 0.5
    assert extension == pytest.approx(mass * G / ks, rel=1e-4)


def chain(n=8, y=Y0, ks=200.0, mass=0.02, spacing=0.05):
    q = [[0.0, y - k * spacing, 0.0] for k in range(n + 1)]
    pairs = [[k, k + 1] for k in range(n)]
    return build_model(
        q, pairs, [SpringType.STRUCTURAL] * n, [mass] * (n + 1), _params(ks, 0.05), pins=[0], device="cpu"
    )


def test_verlet_hanging_chain_settles_at_a_quarter_of_the_default_dt():
    # the two-position form lost the small restoring accelerations near rest and never settled
    model = chain()
    integ = make_integrator("verlet")
    dt = 0.25 * integ.default_dt(model, 1.0)
    sim = Simulator(model, integ, Control(drag_rate=1.0, device="cpu"), dt=dt)
    result = RunHarness(sim).run(15.0, stop_at_equilibrium=True, warm_up=False)  # explicit Euler: at rest after 9 s
    assert result.stable and result.equilibrium_reached
    # at rest: spring k (from the top) carries the weight of the n - k particles below it
    q = sim.state.particle_q.numpy().astype(np.float64)
    ext = -np.diff(q[:, 1]) - 0.05
    expected = 0.02 * G * np.arange(8, 0, -1) / 200.0
    np.testing.assert_allclose(ext, expected, rtol=1e-2)  # still moving at 3 mm/s: 0.5 % off


def test_verlet_error_against_a_float64_reference_falls_when_dt_halves():
    # a soft 4 x 4 grid at y = 1.5 m swinging on one pin for 0.2 s. Verlet is second order: the
    # error falls ~4x per halving down to the float32 floor (~1e-6 m here). The two-position form
    # rounded a dt^2 to ulp(x): its error grew as dt shrank (5e-4 m at 4e-4 s, 9e-3 m at 1e-4 s).
    from helpers import reference_rk4, spring_params

    from warpcloth import build_grid_cloth

    model = build_grid_cloth(
        4, 4, 0.3, 0.3, 0.16, spring_params=spring_params(20.0), pins=[0], origin=(0.0, Y0, 0.0), device="cpu"
    )
    duration = 0.2
    x_ref = reference_rk4(model, duration, 4000)

    def error(dt):
        sim = Simulator(model, "verlet", Control(device="cpu"), dt=dt)
        sim.simulate(int(round(duration / dt)))
        return np.abs(sim.state.particle_q.numpy() - x_ref).max()

    e4, e2, e1 = error(4e-3), error(2e-3), error(1e-3)
    assert e4 / e2 > 3.0 and e2 / e1 > 3.0  # second order (4x), measured 4.0 and 4.4
    assert error(1e-4) < 5e-6  # at the float32 floor, not above the large-dt error
