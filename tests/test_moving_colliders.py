"""Moving colliders (ColliderTrack) against exact answers: a sphere moving into a particle carries
it on its surface at its own speed; a ground sliding in its own plane drags a particle by Coulomb
friction (accelerating at mu g until it sticks); the device pose equals the track at every step
time; captured and plain runs agree to the bit; bad tracks name the value."""

import math

import numpy as np
import pytest
from helpers import free_particles
from test_contract import simulate_frames

from warpcloth import Box, Capsule, Control, Plane, Simulator, Sphere, WarpclothError, build_grid_cloth
from warpcloth.sim.colliders import ColliderTrack, quat_matrix

G = 9.81
INTEGRATORS = ["explicit_euler", "midpoint", "rk4", "verlet", "implicit_euler", "pbd", "xpbd", "vbd", "projective"]
POSITION_BASED = ("pbd", "xpbd")


@pytest.mark.parametrize("integrator", INTEGRATORS)
def test_a_moving_sphere_carries_a_particle_on_its_surface(integrator):
    # no gravity, mu = 0: the sphere (r 0.2, thickness 0.01) moving at 1 m/s along x reaches the
    # particle at x = 0.5 at t = 0.29 s and pushes it: x = c(t) + r + thickness, v = 1 m/s exactly
    sphere = Sphere(radius=0.2, thickness=0.01, track=ColliderTrack.rigid(velocity=(1.0, 0.0, 0.0)))
    dt = 1.0 / 60.0 if integrator in POSITION_BASED else 1e-3
    sim = Simulator(
        free_particles([[0.5, 0.0, 0.0]]),
        integrator,
        Control(gravity=(0, 0, 0), colliders=(sphere,), device="cpu"),
        dt=dt,
    )
    sim.simulate(int(round(0.6 / dt)))
    x, v = sim.state.particle_q.numpy()[0], sim.state.particle_qd.numpy()[0]
    assert sim.sim_time == pytest.approx(0.6)
    assert x[0] == pytest.approx(0.6 + 0.21, abs=1e-5)
    assert v[0] == pytest.approx(1.0, abs=2e-5)  # all the sphere's momentum direction, none sideways
    assert abs(x[1]) + abs(x[2]) + abs(v[1]) + abs(v[2]) == 0.0


@pytest.mark.parametrize("integrator", INTEGRATORS)
def test_a_sliding_ground_drags_a_particle_by_friction(integrator):
    # the ground moves along itself at u; friction on the relative velocity accelerates the particle
    # at mu g until it moves with the ground (at t = u / (mu g)): x(t) = u t - u^2 / (2 mu g)
    mu, u, duration = 0.5, 0.5, 0.25  # it sticks at 0.102 s: both phases inside the run
    ground = Plane(friction=mu, track=ColliderTrack.rigid(velocity=(u, 0.0, 0.0)))
    dt = 1.0 / 600.0 if integrator in POSITION_BASED else 1e-3
    sim = Simulator(free_particles([[0.0, 0.0, 0.0]]), integrator, Control(colliders=(ground,), device="cpu"), dt=dt)
    simulate_frames(sim, int(round(duration / dt)))
    x, v = sim.state.particle_q.numpy()[0], sim.state.particle_qd.numpy()[0]
    assert x[0] == pytest.approx(
        u * duration - u * u / (2 * mu * G), rel=0.02
    )  # 99.5 mm; a still ground gives 0, mu 1 112 mm
    assert v[0] == pytest.approx(u, abs=1e-4)  # stuck to it
    assert abs(x[1]) < 1e-6


def test_a_moving_box_pushes_a_cloth_along_its_motion():
    # a box sweeping along +z through a hanging-free cloth (no gravity) hands it momentum along +z only
    box = Box(
        center=(0.5, 0.0, -0.3),
        half_extents=(0.2, 0.2, 0.1),
        friction=0.3,
        track=ColliderTrack.rigid(velocity=(0.0, 0.0, 1.0)),
    )
    model = build_grid_cloth(
        9, 9, 1.0, 1.0, 0.2, plane="vertical", origin=(0.0, 0.5, 0.0), device="cpu"
    )  # x in [0, 1], y in [-0.5, 0.5], z = 0
    sim = Simulator(model, "explicit_euler", Control(gravity=(0, 0, 0), colliders=(box,), device="cpu"))
    sim.simulate(int(round(0.5 / sim.dt)))
    m = model.host.mass.astype(np.float64)
    p = (m[:, None] * sim.state.particle_qd.numpy().astype(np.float64)).sum(axis=0)
    assert (
        p[2] > 0.25 * 0.2 * 1.0
    )  # at least a quarter of the cloth's 0.2 kg at the box's 1 m/s (measured 0.33 kg m/s: it recoils ahead)
    assert abs(p[0]) < 1e-3 * p[2] and abs(p[1]) < 1e-3 * p[2]  # symmetric cloth, centred box: nothing sideways


def _posed(sim):
    """The device pose of the (non-plane) colliders, as (a, b, rotation) arrays."""
    rec = sim.control.collision.params.numpy()
    return rec["a"].astype(np.float64), rec["b"].astype(np.float64), rec["rotation"].astype(np.float64)


@pytest.mark.parametrize("integrator", ["explicit_euler", "rk4", "pbd"])
def test_the_pose_equals_the_track_at_every_step_time(integrator):
    keys = ColliderTrack.keyframes(
        [0.0, 0.1, 0.25, 0.4],
        [[0, 0, 0], [0.1, 0.05, 0], [0.2, 0.0, -0.1], [0.2, 0.1, 0.0]],
        interpolation="catmull_rom",
    )
    spin = ColliderTrack.rigid(
        center=(0.0, -1.0, 0.0),
        axis=(0.0, 1.0, 0.0),
        angular_velocity=2.0,
        swing_amplitude=0.3,
        swing_frequency=1.5,
        velocity=(0.1, 0.0, 0.2),
    )
    colliders = (
        Capsule(a=(-0.2, -2.0, 0.0), b=(0.2, -2.0, 0.0), radius=0.1, track=keys),
        Box(
            center=(0.5, -2.0, 0.0),
            half_extents=(0.1, 0.2, 0.3),
            rotation=(0.0, 0.0, math.sin(0.2), math.cos(0.2)),
            track=spin,
        ),
    )
    dt = 1.0 / 60.0 if integrator == "pbd" else 1.0 / 240.0
    sim = Simulator(free_particles([[0.0, 1.0, 0.0]]), integrator, Control(colliders=colliders, device="cpu"), dt=dt)
    for _ in range(30):
        sim.simulate(3)
        a, b, rot = _posed(sim)
        capsule, box = (c.at(sim.sim_time) for c in colliders)
        np.testing.assert_allclose(a[0], capsule.a, atol=2e-7)
        np.testing.assert_allclose(b[0], capsule.b, atol=2e-7)
        np.testing.assert_allclose(a[1], box.center, atol=3e-7)
        np.testing.assert_allclose(rot[1], quat_matrix(box.rotation), atol=3e-7)
    assert sim.sim_time == pytest.approx(90 * dt)
    assert not np.allclose(colliders[1].at(sim.sim_time).center, colliders[1].center)  # it did move


@pytest.mark.parametrize("pieces", [1, 4])
@pytest.mark.parametrize("integrator", ["explicit_euler", "xpbd"])
def test_captured_and_plain_runs_agree_to_the_bit(integrator, pieces, monkeypatch):
    import warpcloth.simulator as simulator

    monkeypatch.setattr(simulator, "CPU_GRAPH_STEPS", pieces)  # graphs of one step (the default) or of four

    def run(graph):
        ground = Plane(friction=0.4, track=ColliderTrack.keyframes([0.0, 0.5], [[0, 0, 0], [0.3, 0.1, 0]]))
        ball = Sphere(
            center=(0.5, 0.7, 0.5), radius=0.2, friction=0.3, track=ColliderTrack.rigid(velocity=(0.0, -0.5, 0.0))
        )
        model = build_grid_cloth(6, 6, 1.0, 1.0, 0.2, plane="horizontal", origin=(0.0, 0.3, 0.0), device="cpu")
        sim = Simulator(model, integrator, Control(colliders=(ground, ball), device="cpu"), dt=1.0 / 120.0)
        sim.use_graph = graph
        for _ in range(6):
            sim.simulate(10)
        sim.simulate(37)  # more than a chunk holds: chunks of GRAPH_CHUNK steps, and the rest
        if graph:  # on the CPU chunks cut into graphs of up to P steps: P = 4: 10 = 4 + 4 + 2, 37 = 16 + 16 + 5 (4 + 1)
            assert sorted(len(key[0]) for key in sim._graphs) == ([1] if pieces == 1 else [1, 2, 4])
        return sim.state.particle_q.numpy()

    np.testing.assert_array_equal(run(True), run(False))


def test_tracks_from_a_scenario_file(tmp_path):
    from warpcloth.scenarios import get_scenario

    (tmp_path / "grid.obj").write_text("v 0 1 0\nv 1 1 0\nv 0 1 1\nv 1 1 1\nf 1 3 4 2\n")
    path = tmp_path / "s.toml"
    path.write_text(
        '[cloth]\nmesh = "grid.obj"\n[[colliders]]\nkind = "sphere"\ncenter = [0.5, 0.5, 0.5]\nradius = 0.3\n'
        'track = { kind = "keyframes", times = [0, 1], offsets = [[0, 0, 0], [0, 0.2, 0]] }\n'
        '[[colliders]]\nkind = "plane"\ntrack = { kind = "rigid", velocity = [0.5, 0, 0] }\n'
        '[[colliders]]\nkind = "mesh"\npath = "grid.obj"\ntrack = { kind = "rigid", velocity = [0, -0.1, 0] }\n'
    )
    sphere, plane, mesh = get_scenario(str(path)).build().control.colliders
    assert sphere.at(0.5).center == pytest.approx((0.5, 0.6, 0.5))
    assert plane.at(2.0).point == pytest.approx((1.0, 0.0, 0.0))
    assert mesh.at(2.0).vertices[:, 1] == pytest.approx([0.8] * 4)  # a mesh moves too
    path.write_text(
        '[cloth]\nmesh = "grid.obj"\n[[colliders]]\nkind = "sphere"\nradius = 0.3\ntrack = { kind = "rigid", speed = 1 '
        "}\n"
    )
    with pytest.raises(WarpclothError, match=r"\[\[colliders\]\] #1: collider track \(rigid\): unknown key 'speed'"):
        get_scenario(str(path))


@pytest.mark.parametrize(
    "make,match",
    [
        (lambda: Sphere(track="up"), "sphere track must be a ColliderTrack"),
        (
            lambda: ColliderTrack.keyframes([0.0, 1.0, 0.5], [[0, 0, 0]] * 3),
            "collider track keyframes out of order: time 0.5 s",
        ),
        (
            lambda: ColliderTrack.keyframes([0.0, 1.0], [[0, 0]] * 2),
            r"collider track positions must have shape \(K, 3\)",
        ),
        (lambda: ColliderTrack.rigid(axis=(0, 0, 0)), "collider track axis must be a non-zero 3-vector"),
        (
            lambda: ColliderTrack.from_table({"kind": "spline"}),
            "collider track kind must be 'keyframes' or 'rigid', got 'spline'",
        ),
        (
            lambda: ColliderTrack.from_table({"kind": "keyframes", "times": [0]}),
            r"collider track \(keyframes\) needs offsets",
        ),
    ],
)
def test_bad_tracks_name_the_value(make, match):
    with pytest.raises(WarpclothError, match=match):
        make()
