"""The integrator contract: what every registered integrator must do, one test each over
``integrator_names()`` (a new integrator is in it the moment it is registered).

- pinned particles do not move by one bit, while the rest of the cloth does;
- a mass hanging on one spring at y ~ 1.5 m rests at the extension its scheme's material gives
  (m g / k for every scheme with a spring stiffness; pbd's stiffness is dimensionless per substep,
  its stationary extension (1 - k)/k g h^2 per Müller et al. 2007);
- a cloth at rest, without gravity, stays at rest;
- a captured frame graph replays bit-identically to plain launches;
- a step allocates no memory (plain and captured).
"""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp

from warpcloth import Control, Simulator, SpringType, make_integrator
from warpcloth.integrators import integrator_names
from warpcloth.scenarios import flag
from warpcloth.sim.model import build_model
from warpcloth.simulator import graph_capture_supported

from conftest import DEVICES
from helpers import spring_params

NAMES = integrator_names()
G = 9.81


def test_the_contract_covers_every_scheme():
    assert {"explicit_euler", "midpoint", "rk4", "verlet", "implicit_euler", "pbd", "xpbd", "vbd", "projective"} <= set(NAMES)


@pytest.mark.parametrize("name", NAMES)
def test_pins_do_not_move_by_one_bit(name):
    sim = flag.build(rows=6, cols=8, integrator=name)
    pins = sim.model.pinned
    before = sim.state.particle_q.numpy()[pins].copy()
    sim.simulate(60)
    after = sim.state.particle_q.numpy()
    assert np.array_equal(after[pins], before)
    assert np.array_equal(sim.state.particle_qd.numpy()[pins], np.zeros((len(pins), 3), np.float32))
    moved = np.abs(np.delete(after, pins, axis=0) - np.delete(sim.model.particle_q.numpy(), pins, axis=0)).max()
    assert moved > 1e-3, f"{name}: the free cloth moved {moved:.3g} m (a frozen cloth fails here)"


def hanging_mass(ks: float, mass: float, kd: float):
    """Particle 0 pinned at y = 2 m, particle 1 hanging 0.5 m below it on one spring."""
    q = [[0.0, 2.0, 0.0], [0.0, 1.5, 0.0]]
    return build_model(q, [[0, 1]], [SpringType.STRUCTURAL], [mass, mass], spring_params(ks, kd), pins=[0], device="cpu")


def expected_extension(integrator, mass: float, ks: float, dt: float) -> float:
    if integrator.name == "pbd":
        k, h = integrator.pbd_stiffness, dt / integrator.substeps
        return (1.0 - k) / k * G * h * h if k > 0 else float("inf")
    return mass * G / ks


@pytest.mark.parametrize("name", NAMES)
def test_hanging_mass_rests_at_its_schemes_extension(name):
    """m g / k = 0.0196 m at y ~ 1.5 m (float32 spacing 1.2e-7 m there) to 2e-5 m after 12 s, at
    each integrator's default dt (a missing factor of dt or a wrong sign is off by far more)."""
    ks, mass = 50.0, 0.1
    options = {"pbd_stiffness": 0.5} if name == "pbd" else {}
    integrator = make_integrator(name, **options)
    sim = Simulator(hanging_mass(ks, mass, kd=0.5), integrator, Control(drag_rate=2.0, device="cpu"))
    sim.simulate(max(1, round(12.0 / sim.dt)))
    y = sim.state.particle_q.numpy()[:, 1].astype(np.float64)
    extension = (y[0] - y[1]) - 0.5
    want = expected_extension(integrator, mass, ks, sim.dt)
    assert abs(extension - want) < 2e-5, f"{name}: extension {extension:.7f} m, expected {want:.7f} m (dt {sim.dt:.3g} s)"
    assert np.abs(sim.state.particle_qd.numpy()).max() < 1e-3


@pytest.mark.parametrize("name", NAMES)
def test_rest_stays_at_rest(name):
    """Without gravity or wind, a cloth built at its rest shape does not move (to float32 rounding
    of the rest lengths at ~1 m: far below a millimetre)."""
    sim = flag.build(rows=6, cols=8, integrator=name)
    sim.control.gravity = (0.0, 0.0, 0.0)
    sim.control.wind_coefficient = 0.0
    x0 = sim.state.particle_q.numpy().copy()
    sim.simulate(120)
    x = sim.state.particle_q.numpy()
    assert np.all(np.isfinite(x))
    assert np.abs(x - x0).max() < 1e-5, f"{name} moved a cloth at rest by {np.abs(x - x0).max():.3g} m"
    assert np.abs(sim.state.particle_qd.numpy()).max() < 1e-4


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("name", NAMES)
def test_graph_replay_is_bit_identical_to_launches(name, device):
    if not graph_capture_supported(device):
        pytest.skip(f"Warp {wp.config.version} cannot capture on {device}")
    a = flag.build(rows=6, cols=7, integrator=name, device=device)
    b = flag.build(rows=6, cols=7, integrator=name, device=device)
    if not b.integrator.capturable_on(device):
        pytest.skip(f"{name} is not capturable on {device}")
    a.use_graph, b.use_graph = False, True
    assert not a.graph_enabled and b.graph_enabled
    for n in (7, 7, 3, 7):  # replays of a cached graph, and a second step count
        a.simulate(n)
        b.simulate(n)
    assert a.steps == b.steps == 24
    assert np.array_equal(a.state.particle_q.numpy(), b.state.particle_q.numpy())
    assert np.array_equal(a.state.particle_qd.numpy(), b.state.particle_qd.numpy())
    assert np.array_equal(a.control.time.numpy(), b.control.time.numpy())
    assert np.abs(a.state.particle_q.numpy() - a.model.particle_q.numpy()).max() > 1e-4  # it moved


@pytest.fixture
def count_allocations(monkeypatch):
    """A list that collects the size of every CPU device allocation while the fixture is live."""
    from warp._src.context import CpuDefaultAllocator

    created = []
    original = CpuDefaultAllocator.allocate

    def counting(self, size_in_bytes):
        created.append(size_in_bytes)
        return original(self, size_in_bytes)

    def start():
        created.clear()
        monkeypatch.setattr(CpuDefaultAllocator, "allocate", counting)
        return created

    def stop():
        monkeypatch.setattr(CpuDefaultAllocator, "allocate", original)

    return start, stop


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
    sim.simulate(5)
    sim.simulate(3)
    created = start()
    sim.simulate(5)
    sim.simulate(3)
    stop()
    assert created == [], f"{name} allocated {len(created)} buffers in 8 steps"


def test_the_allocation_counter_sees_an_allocation(count_allocations):
    start, stop = count_allocations
    created = start()
    wp.zeros(3, device="cpu")
    stop()
    assert created, "allocation counter saw nothing"
