"""The integrator contract: what every registered integrator must do, one test each over
``integrator_names()`` (a new integrator is in it the moment it is registered).

- pinned particles do not move by one bit, while the rest of the cloth does;
- a mass hanging on one spring at y ~ 1.5 m rests at the extension its scheme's material gives
  (m g / k for every scheme with a spring stiffness; pbd's stiffness is dimensionless per substep,
  its stationary extension (1 - k)/k g h^2 per Müller et al. 2007);
- a cloth at rest, without gravity, stays at rest;
- a captured frame graph replays bit-identically to plain launches;
- a step allocates no memory (plain and captured);
- a free cloth falls along its own plane by its scheme's discrete free fall, and slides down a
  frictionless slope at t g sin(theta) (issue 26: vbd did neither);
- a free cloth keeps its linear momentum (issue 26: vbd made 0.03 kg m/s).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import warp as wp
from conftest import DEVICES, reproducible
from helpers import assert_replay_matches_launches, released_stretched_cloth, spring_params

from warpcloth import Control, Plane, Simulator, SpringType, build_grid_cloth, make_integrator
from warpcloth.integrators import Integrator, integrator_class, integrator_names
from warpcloth.scenarios import flag
from warpcloth.sim.model import build_model
from warpcloth.simulator import graph_capture_supported

NAMES = integrator_names()
G = 9.81


def simulate_frames(sim, steps: int) -> None:
    """``steps`` steps in calls of one 1/60 s frame each, as a run makes them: one frame's graph captured,
    then replayed. On the CPU a capture costs more than launching the steps it records, a replay almost
    nothing (projective on the 6 x 8 flag: 30 steps captured in 7.5 s of CPU, launched in 2.0 s, replayed
    in 0.04 s), so a short run is cheapest as one frame replayed; the same steps to the bit
    (test_graph_replay_is_bit_identical_to_launches)."""
    per_call = max(1, round((1.0 / 60.0) / sim.dt))
    while steps > 0:
        n = min(per_call, steps)
        sim.simulate(n)
        steps -= n


def test_the_contract_covers_every_scheme():
    assert {"explicit_euler", "midpoint", "rk4", "verlet", "implicit_euler", "pbd", "xpbd", "vbd", "projective"} <= set(
        NAMES
    )


@pytest.mark.parametrize("name", NAMES)
def test_pins_do_not_move_by_one_bit(name):
    sim = flag.build(rows=6, cols=8, integrator=name)
    pins = sim.model.pinned
    before = sim.state.particle_q.numpy()[pins].copy()
    simulate_frames(sim, 60)
    after = sim.state.particle_q.numpy()
    assert np.array_equal(after[pins], before)
    assert np.array_equal(sim.state.particle_qd.numpy()[pins], np.zeros((len(pins), 3), np.float32))
    moved = np.abs(np.delete(after, pins, axis=0) - np.delete(sim.model.particle_q.numpy(), pins, axis=0)).max()
    assert moved > 1e-3, f"{name}: the free cloth moved {moved:.3g} m (a frozen cloth fails here)"


def hanging_mass(ks: float, mass: float, kd: float):
    """Particle 0 pinned at y = 2 m, particle 1 hanging 0.5 m below it on one spring."""
    q = [[0.0, 2.0, 0.0], [0.0, 1.5, 0.0]]
    return build_model(
        q, [[0, 1]], [SpringType.STRUCTURAL], [mass, mass], spring_params(ks, kd), pins=[0], device="cpu"
    )


@pytest.mark.parametrize("name", NAMES)
def test_hanging_mass_rests_at_its_schemes_extension(name):
    """m g / k = 0.0196 m at y ~ 1.5 m (float32 spacing 1.2e-7 m there) to 2e-5 m after 12 s, at
    each integrator's default dt (a missing factor of dt or a wrong sign is off by far more)."""
    ks, mass = 50.0, 0.1
    # pbd's default stiffness 1 projects a substep's fall away entirely: a half-stiff spring hangs
    options = {"pbd_stiffness": 0.5} if "pbd_stiffness" in integrator_class(name).option_defaults() else {}
    integrator = make_integrator(name, **options)
    sim = Simulator(hanging_mass(ks, mass, kd=0.5), integrator, Control(drag_rate=2.0, device="cpu"))
    simulate_frames(sim, max(1, round(12.0 / sim.dt)))
    y = sim.state.particle_q.numpy()[:, 1].astype(np.float64)
    extension = (y[0] - y[1]) - 0.5
    want = integrator.rest_extension(mass, ks, G, sim.dt)
    assert abs(extension - want) < 2e-5, (
        f"{name}: extension {extension:.7f} m, expected {want:.7f} m (dt {sim.dt:.3g} s)"
    )
    assert np.abs(sim.state.particle_qd.numpy()).max() < 1e-3


@pytest.mark.parametrize("name", NAMES)
def test_rest_stays_at_rest(name):
    """Without gravity or wind, a cloth built at its rest shape does not move (to float32 rounding
    of the rest lengths at ~1 m: far below a millimetre)."""
    sim = flag.build(rows=6, cols=8, integrator=name)
    sim.control.gravity = (0.0, 0.0, 0.0)
    sim.control.wind_coefficient = 0.0
    x0 = sim.state.particle_q.numpy().copy()
    simulate_frames(sim, 120)
    x = sim.state.particle_q.numpy()
    assert np.all(np.isfinite(x))
    assert np.abs(x - x0).max() < 1e-5, f"{name} moved a cloth at rest by {np.abs(x - x0).max():.3g} m"
    assert np.abs(sim.state.particle_qd.numpy()).max() < 1e-4


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("name", NAMES)
def test_graph_replay_is_bit_identical_to_launches(name, device):
    if not graph_capture_supported(device):
        pytest.skip(f"Warp {wp.config.version} cannot capture on {device}")
    with reproducible(device):  # on CUDA the atomics' order otherwise changes from launch to launch
        a = flag.build(rows=6, cols=7, integrator=name, device=device)
        b = flag.build(rows=6, cols=7, integrator=name, device=device)
        if not b.integrator.capturable_on(device):
            pytest.skip(f"{name} is not capturable on {device}")
        assert_replay_matches_launches(a, b)
    assert np.abs(a.state.particle_q.numpy() - a.model.particle_q.numpy()).max() > 1e-4  # it moved
    if device.startswith("cuda"):  # Warp's default atomics: the same steps to rounding
        c = flag.build(rows=6, cols=7, integrator=name, device=device, deterministic=False)
        c.simulate(24)
        gap = np.abs(c.state.particle_q.numpy() - b.state.particle_q.numpy()).max()
        assert gap < 1e-5, f"{name}: deterministic and default atomics {gap:.3g} m apart after 24 steps"


@pytest.mark.parametrize("graph", [False, True], ids=["plain", "captured"])
@pytest.mark.parametrize("name", NAMES)
def test_step_allocates_no_memory(name, graph, count_allocations):
    """No device memory is allocated by a step (array views made by Warp's CG are not memory)."""
    start, stop = count_allocations
    sim = flag.build(rows=5, cols=6, integrator=name)
    if graph and not (graph_capture_supported("cpu") and sim.integrator.capturable_on("cpu")):
        pytest.skip("no CPU capture")
    sim.use_graph = graph
    sim.simulate(2)  # begin(), first launches, captures of both step counts below
    sim.simulate(3)
    sim.simulate(2)
    created = start()  # counted: replays (or launches) of the two step counts run above, 5 steps
    sim.simulate(3)
    sim.simulate(2)
    stop()
    assert created == [], f"{name} allocated {len(created)} buffers in 5 steps"


def test_the_allocation_counter_sees_an_allocation(count_allocations):
    start, stop = count_allocations
    created = start()
    wp.zeros(3, device="cpu")
    stop()
    assert created, "allocation counter saw nothing"


def discrete_free_fall(integrator, steps: int, h: float) -> float:
    """The distance a rigid body falls from rest in ``steps`` steps of ``h`` per unit acceleration,
    in the scheme's own discretisation (:attr:`~warpcloth.integrators.Integrator.free_fall`):
    ``"euler"``, symplectic and backward Euler x_n = h^2 n (n + 1) / 2 (explicit_euler; implicit_euler,
    vbd, projective), the same per substep for the position-based schemes (velocity damping 0: their
    default); ``"exact"``, (n h)^2 / 2, for midpoint, rk4 and verlet (primed with d = h v - h^2 a / 2)."""
    kinds = ("euler", "exact")
    assert integrator.free_fall in kinds, f"{integrator.name}: free_fall {integrator.free_fall!r} is not one of {kinds}"
    if integrator.free_fall == "exact":
        return 0.5 * (steps * h) ** 2
    substeps = getattr(integrator, "substeps", 1)
    n, hs = steps * substeps, h / substeps
    return hs * hs * n * (n + 1) / 2


def test_the_contract_holds_every_scheme_to_1e3_unless_it_says_otherwise():
    """A scheme's free motion is held to 1e-3 unless its class declares a looser tolerance itself:
    the explicit and position-based schemes move a free cloth's centroid exactly (its internal forces
    cancel), the solvers implicit_euler, vbd and projective by a solve (2 %)."""
    assert Integrator.free_motion_rtol == 1e-3 and Integrator.free_fall == "euler"
    loose = {n for n in NAMES if integrator_class(n).free_motion_rtol != 1e-3}
    assert {"implicit_euler", "vbd", "projective"} <= loose
    assert not loose & {"explicit_euler", "midpoint", "rk4", "verlet", "pbd", "xpbd"}


@pytest.mark.parametrize("name", NAMES)
def test_free_cloth_falls_along_its_plane_by_its_schemes_discrete_free_fall(name):
    """An unpinned 16 x 16 cloth (1 m, 0.2 kg, horizontal, no drag) released at rest with gravity
    along its plane, 0.25 s at the scheme's default dt: its mean displacement is the scheme's
    discrete free fall (to 1e-3 for the exact schemes, 2 % for the solvers). A cloth that lags
    in its own plane fails: vbd moved 16 % of it before its rigid translation correction. (The wrong
    discretisation, exact for euler or back, is off by 1/n, n the (sub)steps: 0.1 % (midpoint, 1043
    steps) to 7 % (the solvers, 15 steps), twice what it was at 0.5 s.)"""
    model = build_grid_cloth(16, 16, 1.0, 1.0, 0.2, plane="horizontal", origin=(0.0, 1.5, 0.0), device="cpu")
    integrator = make_integrator(name)
    sim = Simulator(model, integrator, Control(gravity=(-G, 0.0, 0.0), drag_rate=0.0, device="cpu"))
    steps = max(1, round(0.25 / sim.dt))
    x0 = sim.state.particle_q.numpy().astype(np.float64).mean(axis=0)
    simulate_frames(sim, steps)
    moved = x0[0] - sim.state.particle_q.numpy().astype(np.float64).mean(axis=0)[0]
    want = G * discrete_free_fall(integrator, steps, sim.dt)
    rel = integrator.free_motion_rtol
    assert moved == pytest.approx(want, rel=rel), (
        f"{name}: fell {moved:.6f} m along its plane, expected {want:.6f} m (dt {sim.dt:.3g} s)"
    )


@pytest.mark.parametrize("name,options", [(n, {}) for n in NAMES] + [("vbd", {"vbd_correction_strain": 0.0})], ids=str)
def test_free_cloth_slides_down_a_frictionless_slope_at_g_sin(name, options):
    """An 8 x 8 cloth (0.3 m, 50 g) lying on a frictionless plane, gravity tilted 30 degrees, 0.25 s
    at the scheme's default dt: it stays on the surface and its mean velocity along the slope is
    n h g sin(30) (to 1e-3 for the exact schemes, 2 % for the solvers; vbd slid at 0.6 % of it). vbd
    also without its correction's stretch limit (on by default since issue 51), which acts only with colliders."""
    theta = math.radians(30.0)
    model = build_grid_cloth(8, 8, 0.3, 0.3, 0.05, plane="horizontal", origin=(0.0, 0.005, 0.0), device="cpu")
    control = Control(
        gravity=(G * math.sin(theta), -G * math.cos(theta), 0.0),
        colliders=(Plane(thickness=0.005, friction=0.0),),
        device="cpu",
    )
    integrator = make_integrator(name, **options)
    sim = Simulator(model, integrator, control)
    steps = max(1, round(0.25 / sim.dt))
    simulate_frames(sim, steps)
    v = sim.state.particle_qd.numpy().astype(np.float64)
    y = sim.state.particle_q.numpy()[:, 1]
    assert np.abs(y - 0.005).max() < 1e-4, f"{name}: left the surface by {np.abs(y - 0.005).max():.3g} m"
    want = steps * sim.dt * G * math.sin(theta)
    rel = integrator.free_motion_rtol
    assert v[:, 0].mean() == pytest.approx(want, rel=rel), (
        f"{name}: slides at {v[:, 0].mean():.5f} m/s, expected {want:.5f} m/s"
    )


@pytest.mark.parametrize("name", NAMES)
def test_free_cloth_keeps_its_momentum(name):
    """A free, symmetric 16 x 16 cloth (kd 0, no gravity, no drag) released stretched by 5 %: its
    linear momentum |sum m v| stays <= 1e-4 kg m/s, sampled every 1/60 s over 0.5 s at the scheme's
    default dt (the total |m v| of the oscillation is ~1e-2 kg m/s; vbd made 0.03 kg m/s, and without its
    rigid translation, vbd_rigid_mode 0, still reaches 0.032 kg m/s within these 0.5 s)."""
    sim, m = released_stretched_cloth(name)
    per_frame = max(1, round((1.0 / 60.0) / sim.dt))
    worst, motion = 0.0, 0.0
    for _ in range(30):
        sim.simulate(per_frame)
        p = m * sim.state.particle_qd.numpy().astype(np.float64)
        worst = max(worst, float(np.linalg.norm(p.sum(axis=0))))
        motion = max(motion, float(np.linalg.norm(p, axis=1).sum()))
    assert motion > 1e-3, f"{name}: the stretched cloth did not move ({motion:.3g} kg m/s)"
    assert worst <= 1e-4, f"{name}: |P| reached {worst:.3g} kg m/s"
