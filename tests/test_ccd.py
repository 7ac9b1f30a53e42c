"""Continuous collision of the cloth against itself (kernels/ccd.py): the coplanarity cubic's roots, the
vertex-triangle and edge-edge tests along a straight motion against hand-made cases with known times,
and the response at the end of a step: a vertex shot through a pinned triangle in one step stays on its
side, equal and opposite where both sides are free."""

import numpy as np
import pytest
import warp as wp

from warpcloth import Control, Plane
from warpcloth.errors import WarpclothError
from warpcloth.kernels import ccd
from warpcloth.lab import intersections as ix
from warpcloth.sim.model import SpringParams, SpringType, build_model
from warpcloth.sim.self_collision import SelfCollision

ETA = 1.0e-6


@wp.kernel
def _roots(q: wp.array(dtype=wp.vec4), out: wp.array(dtype=wp.vec3)):
    i = wp.tid()
    out[i] = ccd.unit_roots(q[i])


@wp.kernel
def _vertex_triangle(x0: wp.array(dtype=wp.vec3), x1: wp.array(dtype=wp.vec3), out: wp.array(dtype=float)):
    hit, t, _w, n, r0, r1 = ccd.vertex_triangle_ccd(x0[0], x0[1], x0[2], x0[3], x1[0], x1[1], x1[2], x1[3], ETA, ETA)
    out[0] = float(hit)
    out[1] = t
    out[2] = wp.dot(n, r0)
    out[3] = wp.dot(n, r1)


@wp.kernel
def _edge_edge(x0: wp.array(dtype=wp.vec3), x1: wp.array(dtype=wp.vec3), out: wp.array(dtype=float)):
    hit, t, w, _n, _r0, _r1 = ccd.edge_edge_ccd(x0[0], x0[1], x0[2], x0[3], x1[0], x1[1], x1[2], x1[3], ETA, ETA)
    out[0] = float(hit)
    out[1] = t
    out[2] = w[1]
    out[3] = -w[3]


def _run(kernel, x0, x1):
    out = wp.zeros(4, dtype=float, device="cpu")
    a0 = wp.array(np.asarray(x0, np.float32), dtype=wp.vec3, device="cpu")
    a1 = wp.array(np.asarray(x1, np.float32), dtype=wp.vec3, device="cpu")
    wp.launch(kernel, dim=1, inputs=[a0, a1, out], device="cpu")
    return out.numpy()


def test_the_cubic_roots_in_the_unit_interval_are_found_in_order():
    """Three roots in [0, 1]; one of three; a quadratic's two (the cubic's leading coefficient 0)."""
    cases = [np.poly1d([0.2, 0.5, 0.9], r=True), np.poly1d([-0.5, 0.3, 3.0], r=True), np.poly1d([0.25, 0.75], r=True)]
    q = np.array([np.pad(c.coeffs[::-1], (0, 4 - len(c.coeffs))) for c in cases], np.float32)
    out = wp.zeros(len(cases), dtype=wp.vec3, device="cpu")
    wp.launch(_roots, dim=len(cases), inputs=[wp.array(q, dtype=wp.vec4, device="cpu"), out], device="cpu")
    roots = out.numpy()
    np.testing.assert_allclose(roots[0], [0.2, 0.5, 0.9], atol=1e-6)
    assert abs(roots[1][roots[1] <= 1.0][0] - 0.3) < 1e-6 and (roots[1] <= 1.0).sum() == 1
    np.testing.assert_allclose(np.sort(roots[2][roots[2] <= 1.0]), [0.25, 0.75], atol=1e-6)


TRIANGLE = [(0.0, 0.0, 0.0), (0.02, 0.0, 0.0), (0.0, 0.0, 0.02)]


@pytest.mark.parametrize("offset", [(0.0, 0.0, 0.0), (1.3, 0.7, -0.4)])
def test_a_vertex_through_a_triangle_collides_at_the_time_it_crosses(offset):
    """A vertex 1 cm above a 2 cm triangle moving 4 cm down in the step (the triangle 0.5 cm up) meets it at
    t = 1 / 4.5, at positions near 1.5 m (relative coordinates: no loss to the positions' ulps); the start's
    side has a positive gap along the normal, the end's a negative one."""
    o = np.array(offset)
    x0 = np.array([(0.005, 0.01, 0.005), *TRIANGLE]) + o
    x1 = x0 + np.array([(0.0, -0.04, 0.0)] + [(0.0, 0.005, 0.0)] * 3)
    hit, t, g0, g1 = _run(_vertex_triangle, x0, x1)
    assert hit == 1 and abs(t - 1.0 / 4.5) < 1e-5
    assert g0 * g1 < 0.0


def test_a_vertex_beside_a_triangle_and_one_that_stops_short_do_not_collide():
    x0 = np.array([(0.03, 0.01, 0.03), *TRIANGLE])
    assert _run(_vertex_triangle, x0, x0 + np.array([(0.0, -0.04, 0.0)] + [(0.0, 0.0, 0.0)] * 3))[0] == 0  # beside
    x0 = np.array([(0.005, 0.01, 0.005), *TRIANGLE])
    assert _run(_vertex_triangle, x0, x0 + np.array([(0.0, -0.009, 0.0)] + [(0.0, 0.0, 0.0)] * 3))[0] == 0  # short


def test_a_triangle_turning_through_a_still_vertex_collides():
    """The triangle rotates about its x edge through the vertex (the four points coplanar where the
    triangle's far corner has come up 1 cm): a root of the cubic that no endpoint shows."""
    p = (0.004, 0.004, 0.004)
    x0 = np.array([p, *TRIANGLE])
    x1 = np.array([p, TRIANGLE[0], TRIANGLE[1], (0.0, 0.02, 0.0)])  # the third corner swung up 90 degrees
    hit, t, _, _ = _run(_vertex_triangle, x0, x1)
    # at t the corner is (0, 0.02 t, 0.02 (1 - t)): the plane through the x axis and it holds p where t = 1/2
    assert hit == 1 and abs(t - 0.5) < 1e-5


def test_two_crossing_edges_collide_and_parallel_ones_do_not():
    """An edge along x moving 2 cm down through a still edge along z 0.5 cm below meets it at t = 1/4,
    at the middle of both."""
    x0 = np.array([(-0.01, 0.005, 0.0), (0.01, 0.005, 0.0), (0.0, 0.0, -0.01), (0.0, 0.0, 0.01)])
    x1 = x0 + np.array([(0.0, -0.02, 0.0)] * 2 + [(0.0, 0.0, 0.0)] * 2)
    hit, t, s, u = _run(_edge_edge, x0, x1)
    assert hit == 1 and abs(t - 0.25) < 1e-5 and abs(s - 0.5) < 1e-5 and abs(u - 0.5) < 1e-5
    beside = x0 + np.array([(0.0, 0.0, 0.02)] * 2 + [(0.0, 0.0, 0.0)] * 2)  # the moving edge 1 cm past the still one
    beside[2:] = [(0.0, 0.0, -0.01), (0.0, 0.0, 0.005)]
    assert _run(_edge_edge, beside, beside + np.array([(0.0, -0.02, 0.0)] * 2 + [(0.0, 0.0, 0.0)] * 2))[0] == 0


@pytest.mark.parametrize("angle", [1.0e-4, 5.0e-4, 9.0e-4, 2.0e-3])
def test_nearly_parallel_edges_that_cross_collide(angle):
    """Two 2 cm edges in one plane at t = 1/2, crossing at an angle of 1e-4 to 2e-3 rad: below ~1e-3 rad
    float32 cannot resolve where they cross (its closest points fall in the overlap's middle, up to 1e-5 m
    off), so the crossing is found in float64 (a review's trial missed 5e-4 and 9e-4 rad)."""
    p = np.array([0.008, 0.0, 0.0])
    direction = np.array([np.cos(angle), 0.0, np.sin(angle)])
    x0 = np.array([(-0.01, 0.005, 0.0), (0.01, 0.005, 0.0), p - 0.018 * direction, p + 0.002 * direction])
    x1 = x0 - np.array([(0.0, 0.01, 0.0)] * 2 + [(0.0, 0.0, 0.0)] * 2)
    hit, t, s, u = _run(_edge_edge, x0, x1)
    assert hit == 1 and abs(t - 0.5) < 1e-5, (hit, t)
    xt = x0 + t * (x1 - x0)
    gap = np.linalg.norm(xt[0] + s * (xt[1] - xt[0]) - (xt[2] + u * (xt[3] - xt[2])))
    assert gap <= ETA, (s, u, gap)  # its closest points where the edges meet (x = 8 mm), within the tolerance


# -- the response at a step's end ------------------------------------------------------------------------
def triangle_and_vertex(pinned: bool):
    """A 5 cm triangle (pinned, or free and 4 times heavier than the vertex) at y = 0.3 m and a vertex
    1 cm above it, with a SelfCollision (h = 5 mm) bound to them."""
    q = np.array([(0.01, 0.31, 0.01), (0.0, 0.3, 0.0), (0.05, 0.3, 0.0), (0.0, 0.3, 0.05), (0.3, 0.5, 0.3)])
    pairs = np.array([[1, 2], [2, 3], [3, 1], [0, 4]])  # the vertex tied to a far fifth one (a model needs springs)
    types = np.array([int(SpringType.STRUCTURAL)] * 4)
    mass = np.array([0.01, 0.04, 0.04, 0.04, 0.01])
    params = {t: SpringParams(1.0, 0.0) for t in SpringType}
    model = build_model(
        q, pairs, types, mass, params, pins=[1, 2, 3] if pinned else [], triangles=np.array([[1, 2, 3]]), device="cpu"
    )
    return model, SelfCollision(model, thickness=0.005, friction=0.0, stiffness=10.0)


def moved_through(model, sc, motion, position_weight=1.0, colliders=None):
    """Positions at the step's start (detect), then the vertex moved by ``motion`` [m] in the step with the
    velocity that does so; prevent_crossings. Returns (x at the start, x moved, x after, v before, v after)."""
    dt = 1.0 / 60.0
    q0 = model.host.q.astype(np.float32)
    v = np.zeros_like(q0)
    v[0] = np.array(motion) / dt
    x = wp.array(q0, dtype=wp.vec3, device="cpu")
    vel = wp.array(v, dtype=wp.vec3, device="cpu")
    sc.detect(x, vel, dt)
    x1 = q0 + dt * v
    x.assign(x1)
    sc.prevent_crossings(x, vel, dt, position_weight, colliders=colliders)
    return q0, x1, x.numpy(), v, vel.numpy()


@pytest.mark.parametrize("pinned", [True, False])
@pytest.mark.parametrize("motion", [(0.0, -0.04, 0.0), (0.03, -0.04, 0.03)])
@pytest.mark.parametrize("position_weight", [1.0, 0.5])
def test_a_vertex_moved_through_a_triangle_ends_the_step_on_its_side(pinned, motion, position_weight):
    """The vertex moved 4 cm down through the triangle in one step (straight down, or out past its long
    side): prevent_crossings leaves it on its start's side, at least the minimum gap from the triangle's
    plane and less than twice that (not thrown past it: a lone pair takes its depth exactly; the free
    triangle tilts under its push), still moving down (no bounce, whatever the
    scheme's position weight: 1/2 once bounced it back at 1.3 times its speed), x and v changed alike
    (dx = dt dv), and, the triangle free, momentum unchanged."""
    model, sc = triangle_and_vertex(pinned)
    dt = 1.0 / 60.0
    q0, x1, xe, v, ve = moved_through(model, sc, motion, position_weight)
    a, b, c = xe[1:4].astype(np.float64)
    normal = np.cross(b - a, c - a)
    normal *= np.sign(np.dot(normal, (0.0, 1.0, 0.0))) / np.linalg.norm(normal)  # up, the start's side
    gap = np.dot(xe[0] - a, normal)
    assert 0.99 * sc.min_gap <= gap <= 2.0 * sc.min_gap, gap  # above the triangle's plane, not thrown past it
    assert ve[0, 1] < 0.0, ve[0]
    np.testing.assert_allclose(xe - x1, dt * (ve - v), atol=1e-6)
    stats = sc.stats()
    assert stats["ccd_collisions"] >= 1 and stats["ccd_unresolved"] == 0 and stats["ccd_rollbacks"] == 0, stats
    if pinned:
        np.testing.assert_array_equal(xe[1:4], q0[1:4])
    else:
        dp = (model.host.mass[:, None] * (ve - v)).sum(axis=0)
        assert np.abs(dp).max() <= 1e-7, dp
    assert ix.count_self_intersections(xe, model.host.tris) == 0


def test_a_vertex_that_no_push_can_move_goes_back_to_the_steps_start():
    """The fail-safe: the triangle pinned and the vertex held by a collider above it (a plane facing down,
    which a push up would enter): the vertex goes back to its start, with the velocity of no motion."""
    model, sc = triangle_and_vertex(True)
    ceiling = Control(colliders=[Plane(point=(0.0, 0.2705, 0.0), normal=(0.0, -1.0, 0.0))], device="cpu").collision
    q0, _x1, xe, _v, ve = moved_through(model, sc, (0.0, -0.04, 0.0), colliders=ceiling)
    np.testing.assert_allclose(xe[0], q0[0], atol=1e-7)
    np.testing.assert_allclose(ve[0], 0.0, atol=1e-5)
    stats = sc.stats()
    assert stats["ccd_rollbacks"] == 1 and stats["ccd_unresolved"] == 0, stats


def test_two_edges_crossing_in_a_step_end_apart():
    """A free edge (a two-vertex strip's) shot 3 cm down through a pinned triangle's edge beside it, its ends
    outside the triangle (so no vertex-triangle pair sees it): the edges end apart on their start's side."""
    q = np.array([(0.04, 0.31, -0.02), (0.04, 0.31, 0.02), (0.0, 0.3, 0.0), (0.05, 0.3, 0.0), (0.0, 0.3, -0.05)])
    # the triangle (2, 3, 4) lies at z <= 0 with its edge 2-3 along x; the free edge 0-1 crosses over it at x = 4 cm
    pairs = np.array([[0, 1], [2, 3], [3, 4], [4, 2]])
    types = np.array([int(SpringType.STRUCTURAL)] * 4)
    mass = np.array([0.01, 0.01, 0.04, 0.04, 0.04])
    params = {t: SpringParams(1.0, 0.0) for t in SpringType}
    tris = np.array([[2, 3, 4], [0, 1, 1]])[:1]
    model = build_model(q, pairs, types, mass, params, pins=[2, 3, 4], triangles=tris, device="cpu")
    # the free edge needs a triangle to be an edge of the mesh: a thin one with a far third vertex
    model = build_model(
        np.vstack([q, [(0.04, 0.5, 0.0)]]),
        np.vstack([pairs, [[0, 5], [1, 5]]]),
        np.array([int(SpringType.STRUCTURAL)] * 6),
        np.append(mass, 0.01),
        params,
        pins=[2, 3, 4],
        triangles=np.array([[2, 3, 4], [0, 1, 5]]),
        device="cpu",
    )
    sc = SelfCollision(model, thickness=0.005, friction=0.0, stiffness=10.0)
    dt = 1.0 / 60.0
    q0 = model.host.q.astype(np.float32)
    v = np.zeros_like(q0)
    v[[0, 1, 5], 1] = -0.03 / dt
    x = wp.array(q0, dtype=wp.vec3, device="cpu")
    vel = wp.array(v, dtype=wp.vec3, device="cpu")
    sc.detect(x, vel, dt)
    x.assign(q0 + dt * v)
    sc.prevent_crossings(x, vel, dt)
    xe = x.numpy()
    assert xe[0, 1] > 0.3 and xe[1, 1] > 0.3, xe[:2]  # the free edge above the triangle's edge (y = 0.3)
    assert sc.stats()["ccd_collisions"] >= 1


def test_without_the_continuous_response_the_vertex_stays_through():
    """The negative control: ccd_passes 0 leaves the vertex of the test above where the motion put it."""
    model, _ = triangle_and_vertex(True)
    sc = SelfCollision(model, thickness=0.005, ccd_passes=0)
    q0 = model.host.q.astype(np.float32)
    x = wp.array(q0, dtype=wp.vec3, device="cpu")
    vel = wp.zeros(len(q0), dtype=wp.vec3, device="cpu")
    sc.detect(x, vel, 1.0 / 60.0)
    x1 = q0.copy()
    x1[0, 1] -= 0.04
    x.assign(x1)
    sc.prevent_crossings(x, vel, 1.0 / 60.0)
    np.testing.assert_array_equal(x.numpy(), x1)


def test_ccd_passes_must_be_a_count():
    model, _ = triangle_and_vertex(True)
    with pytest.raises(WarpclothError, match="ccd_passes"):
        SelfCollision(model, thickness=0.005, ccd_passes=-1)


def edge_crossing_near_a_pin():
    """Edge c-d (c pinned) swept by its free end d 2 cm down through a pinned edge a-b that it crosses 3 % of
    the way from c (a-b the top of a pinned vertical triangle, 3 mm from c). Only d can move the crossing point,
    with weight W_d = 0.03. Returns (model, SelfCollision, x at the step's start, x moved)."""
    q = np.array(
        [
            (0.003, 0.3, -0.05),  # a (pinned)
            (0.003, 0.3, 0.05),  # b (pinned)
            (0.003, 0.25, 0.0),  # f (pinned): the triangle a-b-f hangs below a-b in the plane x = 3 mm
            (0.0, 0.3, 0.0),  # c (pinned)
            (0.1, 0.31, 0.0),  # d (free), 1 cm above c's height
            (0.05, 0.31, 0.08),  # e (pinned)
        ]
    )
    pairs = np.array([[0, 1], [1, 2], [2, 0], [3, 4], [4, 5], [5, 3]])
    model = build_model(
        q,
        pairs,
        np.array([int(SpringType.STRUCTURAL)] * 6),
        np.array([0.04, 0.04, 0.04, 0.04, 0.01, 0.04]),
        {t: SpringParams(1.0, 0.0) for t in SpringType},
        pins=[0, 1, 2, 3, 5],
        triangles=np.array([[0, 1, 2], [3, 4, 5]]),
        device="cpu",
    )
    x0 = model.host.q.astype(np.float32)
    x1 = x0.copy()
    x1[4, 1] -= 0.02  # c-d now passes 0.3 mm under a-b where they cross
    return model, SelfCollision(model, thickness=0.005, friction=0.0, stiffness=10.0), x0, x1


def swept(sc, x0, x1, passes=None, rollbacks=None):
    """detect at x0, prevent_crossings at x1 (one step of 1/60 s); the end positions."""
    if passes is not None:
        sc.ccd_passes = passes
    if rollbacks is not None:
        sc.CCD_ROLLBACK_ROUNDS = rollbacks
    dt = 1.0 / 60.0
    x = wp.array(x0, dtype=wp.vec3, device="cpu")
    vel = wp.array((x1 - x0) / dt, dtype=wp.vec3, device="cpu")
    sc.detect(x, vel, dt)
    x.assign(x1)
    sc.prevent_crossings(x, vel, dt)
    return x.numpy()


def test_a_continuous_collision_next_to_a_pin_does_not_throw_the_free_vertex():
    """The push of a collision with a pinned vertex is capped as the filter's impulse is (capped_for_held):
    uncapped, depth / sum W^2 / m moved d by depth / W_d, 33 times the pair's depth (0.8 mm: 27 mm, d thrown
    6.9 mm above its start; measured); capped, a pass moves it at most twice the depth (3 times over-relaxed;
    measured 1.6 mm). The default 8 passes add up to the crossing's undoing: d ends 0.4 mm above c's height, on
    a-b's side, below its start."""
    model, sc, x0, x1 = edge_crossing_near_a_pin()
    assert ix.count_self_intersections(x1, model.host.tris) == 1  # c-d through the pinned triangle
    one = swept(sc, x0, x1, passes=1, rollbacks=0)
    assert sc.stats()["ccd_collisions"] == 1
    push = np.linalg.norm(one[4] - x1[4])
    assert 0.0 < push <= 3.0 * 0.0008, push  # (measured 1.6 mm; uncapped 27 mm)
    np.testing.assert_array_equal(one[[0, 1, 2, 3, 5]], x0[[0, 1, 2, 3, 5]])  # pins win
    model, sc, x0, x1 = edge_crossing_near_a_pin()
    end = swept(sc, x0, x1)
    assert end[4, 1] <= x0[4, 1] + 1e-6, end[4]  # not thrown above its start
    assert ix.count_self_intersections(end, model.host.tris) == 0
    assert sc.stats()["ccd_unresolved"] == 0


@pytest.mark.parametrize("swept_check", [True, False])
def test_a_motion_the_detect_did_not_predict_is_still_followed(swept_check):
    """The vertex 3 cm above the pinned triangle, still at the detect (so its margin is 0 and the list, of
    radius h + skin = 1 cm, holds no pair of it), is moved 4 cm down through the triangle in the step (as a
    solve, a collider's or an edge's projection may move it): the list is rebuilt over the step's swept motion
    before the continuous response, which then leaves the vertex on its side. The negative control: without
    that rebuild (the check replaced by a no-op) the vertex stays through."""
    model, sc = triangle_and_vertex(True)
    if not swept_check:
        sc._cover_swept = lambda x, skip_capped=False: None
    dt = 1.0 / 60.0
    x0 = model.host.q.astype(np.float32)
    x0[0, 1] = 0.33
    x = wp.array(x0, dtype=wp.vec3, device="cpu")
    vel = wp.zeros(len(x0), dtype=wp.vec3, device="cpu")
    sc.detect(x, vel, dt)
    assert len(sc.candidates()[0]) == 0  # the detect listed no pair
    x1 = x0.copy()
    x1[0, 1] -= 0.04
    x.assign(x1)
    sc.prevent_crossings(x, vel, dt)
    xe = x.numpy()
    stats = sc.stats()
    if swept_check:
        assert stats["swept_rebuilds"] == 1 and stats["ccd_collisions"] >= 1, stats
        assert xe[0, 1] >= 0.3 + 0.99 * sc.min_gap, xe[0]  # above the triangle's plane (y = 0.3)
        assert ix.count_self_intersections(xe, model.host.tris) == 0
    else:
        assert stats["swept_rebuilds"] == 0 and stats["ccd_collisions"] == 0, stats
        np.testing.assert_array_equal(xe, x1)


def test_a_motion_the_detect_predicted_does_not_rebuild_the_list():
    """The vertex moved 4 cm by its own velocity at the detect: its margin covers the motion, no rebuild."""
    model, sc = triangle_and_vertex(True)
    moved_through(model, sc, (0.0, -0.04, 0.0))
    stats = sc.stats()
    assert stats["swept_rebuilds"] == 0 and stats["rebuilds"] == 1 and stats["ccd_collisions"] >= 1, stats


def test_the_first_pass_follows_a_pair_that_closed_since_the_list_was_built():
    """The continuous response's first pass skips a pair by a bound that reads no position: its gap at the list's
    build less its sides' displacements since (to the step's start) and their motion over the step. The vertex,
    1 cm above the pinned triangle at the build, is 2 mm above it at the step's start (the list kept: a 3 cm skin)
    and goes 3 mm through it in the step: the pass still sees the pair (the gap at the build less the step's
    motion alone, 5 mm, would have skipped it) and leaves the vertex on its side."""
    model, _ = triangle_and_vertex(True)
    sc = SelfCollision(model, thickness=0.005, friction=0.0, stiffness=10.0, skin=0.03)
    dt = 1.0 / 60.0
    q = model.host.q.astype(np.float32)
    x = wp.array(q, dtype=wp.vec3, device="cpu")
    vel = wp.zeros(len(q), dtype=wp.vec3, device="cpu")
    sc.detect(x, vel, dt)  # the build: the pair 1 cm apart
    q[0, 1] = 0.302
    x.assign(q)
    sc.detect(x, vel, dt)  # the step's start: 2 mm apart, the list kept
    q[0, 1] = 0.297
    x.assign(q)
    sc.prevent_crossings(x, vel, dt)
    xe = x.numpy()
    stats = sc.stats()
    assert stats["rebuilds"] == 1 and stats["swept_rebuilds"] == 0 and stats["ccd_collisions"] >= 1, stats
    assert xe[0, 1] >= 0.3 + 0.99 * sc.min_gap, xe[0]
    assert ix.count_self_intersections(xe, model.host.tris) == 0


def two_layers_and_a_pinned_vertex():
    """Two free 5 cm triangles 4 cm apart (B at y = 0.3 m, C below it) and a pinned vertex 1 cm above B, with
    a SelfCollision (h = 5 mm) bound to them (a review's case)."""
    q = np.array(
        [
            (0.012, 0.31, 0.012),  # the pinned vertex
            (0.0, 0.3, 0.0),
            (0.05, 0.3, 0.0),
            (0.0, 0.3, 0.05),  # B
            (0.003, 0.26, 0.002),
            (0.053, 0.26, 0.002),
            (0.003, 0.26, 0.052),  # C
            (0.3, 0.5, 0.3),  # pinned, tied to the vertex (a model needs springs)
        ]
    )
    pairs = np.array([[1, 2], [2, 3], [3, 1], [4, 5], [5, 6], [6, 4], [0, 7]])
    model = build_model(
        q,
        pairs,
        np.array([int(SpringType.STRUCTURAL)] * len(pairs)),
        np.full(8, 0.01),
        {t: SpringParams(1.0, 0.0) for t in SpringType},
        pins=[0, 7],
        triangles=np.array([[1, 2, 3], [4, 5, 6]]),
        device="cpu",
    )
    return model, SelfCollision(model, thickness=0.005, friction=0.0, stiffness=10.0)


@pytest.mark.parametrize("rounds", [2, 1])
def test_a_push_that_drives_one_layer_through_another_is_followed_too(rounds):
    """The pinned vertex moved 7 cm down through both layers in one step, still at the detect: the list
    rebuilt over that motion holds the vertex's pairs, not B-C (4 cm apart, neither moving); the pushes drive
    B down through C. A second round, after the list is rebuilt over the motion so far, holds B-C and parts
    them: no intersection. The negative control: one round leaves B through C, uncounted."""
    model, sc = two_layers_and_a_pinned_vertex()
    sc.CCD_ROUNDS = rounds
    dt = 1.0 / 60.0
    x0 = model.host.q.astype(np.float32)
    x = wp.array(x0, dtype=wp.vec3, device="cpu")
    sc.detect(x, wp.zeros(len(x0), dtype=wp.vec3, device="cpu"), dt)
    x1 = x0.copy()
    x1[0, 1] -= 0.07
    x.assign(x1)
    sc.prevent_crossings(x, wp.zeros(len(x0), dtype=wp.vec3, device="cpu"), dt)
    xe = x.numpy()
    stats = sc.stats()
    assert stats["ccd_unresolved"] == 0 and stats["ccd_rollbacks"] == 0, stats
    crossings = ix.count_self_intersections(xe, model.host.tris)
    if rounds == 2:
        assert stats["swept_rebuilds"] == 2 and crossings == 0, (stats, crossings)
    else:
        assert stats["swept_rebuilds"] == 1 and crossings == 1, (stats, crossings)
