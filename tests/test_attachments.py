"""Attachments: pins tied to a mesh collider's triangles (barycentric points found at rest) follow
the deforming mesh exactly: keyframed, driven from a loop, or static (docs/colliders.md)."""

import numpy as np
import pytest

from warpcloth import Control, Simulator, WarpclothError, build_grid_cloth
from warpcloth.sim.colliders import Capsule, MeshCollider, MeshTrack, attach, closest_surface_points

# a bent strip of 4 triangles (a "shoulder") that moves, turns and stretches, non-linearly in time
REST = np.array(
    [[-0.2, 0.0, -0.1], [0.0, 0.05, -0.1], [0.2, 0.0, -0.1], [-0.2, 0.0, 0.1], [0.0, 0.05, 0.1], [0.2, 0.0, 0.1]]
)
TRIANGLES = np.array([[0, 3, 4], [0, 4, 1], [1, 4, 5], [1, 5, 2]])


def deformed(t: float) -> np.ndarray:
    c, s = np.cos(1.5 * t), np.sin(1.5 * t)
    turn = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
    stretch = np.diag([1.0 + 0.3 * np.sin(4.0 * t), 1.0 + 0.5 * t, 1.0])
    return REST @ (turn @ stretch).T + np.array([0.1 * t, 0.4 * t * t, 0.0])


def cloth():
    # a 4 x 4 patch above the strip; its middle row pinned (the "pin group") and attached
    model = build_grid_cloth(
        4, 4, 0.3, 0.15, 0.01, pins=[4, 5, 6, 7], plane="horizontal", origin=(-0.15, 0.06, -0.075), device="cpu"
    )
    return model, model.host.q.astype(np.float64)


def test_attachment_weights_are_the_nearest_surface_points_at_rest():
    _, rest = cloth()
    faces, weights = closest_surface_points(REST, TRIANGLES, rest[[4, 5, 6, 7]])
    assert np.allclose(weights.sum(axis=1), 1.0) and (weights >= -1e-12).all()
    q = np.einsum("pj,pjc->pc", weights, REST[TRIANGLES[faces]])
    for p, near in zip(rest[[4, 5, 6, 7]], q):  # no point of the strip is nearer (dense samples of it)
        u, v = np.meshgrid(np.linspace(0, 1, 41), np.linspace(0, 1, 41))
        ok = (u + v) <= 1.0
        best = min(
            np.linalg.norm(
                REST[a] + u[ok, None] * (REST[b] - REST[a]) + v[ok, None] * (REST[c] - REST[a]) - p, axis=1
            ).min()
            for a, b, c in TRIANGLES
        )
        assert np.linalg.norm(near - p) <= best + 1e-12


@pytest.mark.parametrize("integrator", ["explicit_euler", "xpbd", "implicit_euler"])
@pytest.mark.parametrize("driven", [False, True])
def test_attached_pins_follow_the_moving_triangles_exactly(integrator, driven):
    # every frame end, each attached pin is the float32 rounding of sum_j w_j p_j(t) (float64)
    fps, frames = 60.0, 10
    times = np.arange(frames + 1) / fps
    keys = np.array([deformed(t) for t in times])
    track = MeshTrack.driven() if driven else MeshTrack.keyframes(times, keys)
    body = MeshCollider(vertices=REST, triangles=TRIANGLES, thickness=0.002, friction=0.3, track=track)
    model, rest = cloth()
    pins = attach(body, rest, [4, 5, 6, 7], name="shoulders")
    sim = Simulator(model, integrator, Control(colliders=(body,), pin_tracks=(pins,), device="cpu"))
    sim.set_dt(1.0 / 600.0)
    corners = body.triangles[pins.faces]
    for k in range(1, frames + 1):
        if driven:
            track.set(keys[k])
        sim.simulate(10)
        points, _ = track.evaluate(sim.sim_time, REST)
        expected = np.einsum("pj,pjc->pc", pins.weights, points[corners]).astype(np.float32)
        assert np.array_equal(sim.state.particle_q.numpy()[[4, 5, 6, 7]], expected)
    at_rest = np.einsum("pj,pjc->pc", pins.weights, REST[corners])
    assert np.abs(expected - at_rest).max() > 0.015  # they did move with it (a few cm)


def test_attached_to_a_static_mesh_the_pins_hold_on_its_surface():
    body = MeshCollider(vertices=REST, triangles=TRIANGLES)
    model, rest = cloth()
    pins = attach(body, rest, [4, 5])
    sim = Simulator(model, "xpbd", Control(colliders=(body,), pin_tracks=(pins,), device="cpu"))
    sim.simulate(20)
    q = np.einsum("pj,pjc->pc", pins.weights, REST[TRIANGLES[pins.faces]]).astype(np.float32)
    assert np.array_equal(sim.state.particle_q.numpy()[[4, 5]], q)


def test_attachment_mistakes_name_the_fix():
    _, rest = cloth()
    with pytest.raises(WarpclothError, match=r"must be a MeshCollider"):
        attach(Capsule(), rest, [0])
    with pytest.raises(WarpclothError, match=r"out of range"):
        attach(MeshCollider(vertices=REST, triangles=TRIANGLES), rest, [99])
    with pytest.raises(WarpclothError, match=r"no particles"):
        attach(MeshCollider(vertices=REST, triangles=TRIANGLES), rest, [])
