"""Continuous collision of the cloth against itself over a step's motion (Provot 1997; Bridson, Fedkiw &
Anderson 2002, Sec. 6-7): each listed vertex-triangle and edge-edge pair moves linearly from its positions
at the step's start to those at its end; the four points lie in one plane at the real roots in [0, 1] of a
cubic, and the pair collides at the first such root where the vertex lies on the triangle (the edges on
each other) within a tolerance. :class:`~warpcloth.sim.self_collision.SelfCollision` answers a collision by
a push of the pair's end positions along the collision's normal, equal and opposite (Jacobi passes, masses
split over the pushes at a vertex) and, for a pair those passes left crossing, by moving its free vertices
back to the step's start (a fail-safe that keeps no momentum).

Every difference is taken relative to one vertex of the pair (a, or the first edge's first end), so the
cubic's coefficients are of the pair's size, not of its positions' (float32 positions of 1-2 m have ulps
of 1e-7 m; a 1 cm pair's relative coordinates have ulps of 1e-9 m).
"""

import warp as wp

from warpcloth.kernels.collide import Collider, collider_contact
from warpcloth.kernels.self_contact import (
    CAND_EE,
    CAND_VT,
    CCD_ACTIVE,
    CCD_CHANGED,
    CCD_COLLISIONS,
    CCD_HITS,
    CCD_ROLLBACKS,
    CCD_SAVED,
    CCD_UNRESOLVED,
    REBUILD,
    FloatArray,
    IntArray,
    SelfContactGrid,
    SelfContactMesh,
    SelfContactSettings,
    Vec3Array,
    Vec4Array,
    Vec4iArray,
    any_perpendicular,
    boxes_overlap,
    capped_for_held,
    closest_point_triangle,
    closest_points_edge_edge,
    rounding_slack,
)

wp.set_module_options({"enable_backward": False})

NOT_DETERMINISTIC = "the continuous response's collision lists are built in the GPU's thread order"

#: the pushes' over-relaxation where a vertex's mass is split over c > 1 pushes (Jacobi passes then reach at
#: least 1/c of a pair's depth a pass; 1.5 left no pair of the 24 x 8 fold under the minimum gap in 8
#: passes where 1 left one); a pair whose vertices have no other push takes its depth exactly
OVER_RELAXATION = wp.constant(1.5)

#: bisection steps for a root of the coplanarity cubic on one monotone piece of [0, 1] (2^-30 of the step)
BISECTIONS = wp.constant(30)

MODE_PUSH = wp.constant(0)  # record each collision for a push
MODE_ROLLBACK = wp.constant(1)  # mark the free vertices of each collision for the fail-safe
MODE_COUNT = wp.constant(2)  # count the collisions left


@wp.struct
class CcdState:
    """The continuous response's arrays, bound once (warpcloth.sim.self_collision): per vertex whether its pairs
    are tested in the next pass (``moved``), whether it was in a collision of this pass (``touched``), the
    fail-safe's mark, the pushes acting on it, a holding collider's outward normal (``held``, else 0) and its
    straight motion over the step relative to the mean (``swept_length``); this pass's collisions (pair, W, n,
    depth; capacity ``capacity``); the coplanarity tolerance eta [m]."""

    moved: IntArray
    touched: IntArray
    rollback: IntArray
    acting: IntArray
    held: Vec3Array
    swept_length: FloatArray
    hit_idx: Vec4iArray
    hit_w: Vec4Array
    hit_n: Vec3Array
    hit_depth: FloatArray
    capacity: int
    eta: float


@wp.func
def coplanarity_cubic(e1: wp.vec3, d1: wp.vec3, e2: wp.vec3, d2: wp.vec3, e3: wp.vec3, d3: wp.vec3):
    # (c0, c1, c2, c3) of f(t) = ((e1 + t d1) x (e2 + t d2)) . (e3 + t d3) = c0 + c1 t + c2 t^2 + c3 t^3:
    # zero where o, e1, e2, e3 (each moving linearly in t) lie in one plane
    k0 = wp.cross(e1, e2)
    k1 = wp.cross(e1, d2) + wp.cross(d1, e2)
    k2 = wp.cross(d1, d2)
    return wp.vec4(wp.dot(k0, e3), wp.dot(k0, d3) + wp.dot(k1, e3), wp.dot(k1, d3) + wp.dot(k2, e3), wp.dot(k2, d3))


@wp.func
def cubic_value(q: wp.vec4, t: float):
    return q[0] + t * (q[1] + t * (q[2] + t * q[3]))


@wp.func
def unit_or_one(r: float):
    # r where it lies inside (0, 1), else 1 (a piece of no length at the end)
    if r > 0.0 and r < 1.0:
        return r
    return 1.0


@wp.func
def cubic_stationary(q: wp.vec4):
    # the cubic's stationary points (roots of c1 + 2 c2 t + 3 c3 t^2) in (0, 1), ascending, 1 where none
    a = 3.0 * q[3]
    b = 2.0 * q[2]
    c = q[1]
    r0 = float(1.0)
    r1 = float(1.0)
    if wp.abs(a) <= 1.0e-7 * (wp.abs(b) + wp.abs(c)):  # (nearly) a quadratic: one stationary point
        if b != 0.0:
            r0 = unit_or_one(-c / b)
        return r0, r1
    disc = b * b - 4.0 * a * c
    if disc < 0.0:
        return r0, r1
    root = wp.sqrt(disc)
    half = -0.5 * (b + wp.sign(b) * root)  # the root of larger magnitude without cancellation
    if b == 0.0:
        half = -0.5 * root
    if half != 0.0:
        r0 = unit_or_one(half / a)
        r1 = unit_or_one(c / half)
    else:
        r0 = unit_or_one(0.0)
    if r1 < r0:
        return r1, r0
    return r0, r1


@wp.func
def piece_root(q: wp.vec4, lo: float, hi: float, flo: float, fhi: float, last: int):
    # the root of the cubic on the monotone piece [lo, hi] (its values flo, fhi), or 2 where it has none;
    # a root at hi belongs to the next piece, but for the last one ending at 1
    if hi <= lo:
        return 2.0
    if flo == 0.0:
        return lo
    if (flo < 0.0 and fhi > 0.0) or (flo > 0.0 and fhi < 0.0):
        a = lo
        b = hi
        fa = flo
        for _k in range(BISECTIONS):
            mid = 0.5 * (a + b)
            fm = cubic_value(q, mid)
            if (fm < 0.0) == (fa < 0.0) and fm != 0.0:
                a = mid
                fa = fm
            else:
                b = mid
        return 0.5 * (a + b)
    if last != 0 and fhi == 0.0:
        return hi
    return 2.0


@wp.func
def unit_roots(q: wp.vec4):
    # the cubic's real roots in [0, 1], one per monotone piece, ascending (2: none)
    s0, s1 = cubic_stationary(q)
    f0 = cubic_value(q, 0.0)
    fs0 = cubic_value(q, s0)
    fs1 = cubic_value(q, s1)
    f1 = cubic_value(q, 1.0)
    return wp.vec3(
        piece_root(q, 0.0, s0, f0, fs0, int(s0 >= 1.0)),
        piece_root(q, s0, s1, fs0, fs1, int(s1 >= 1.0)),
        piece_root(q, s1, 1.0, fs1, f1, 1),
    )


@wp.func
def unit_normal(n: wp.vec3, edge: wp.vec3):
    # n normalised, or a unit vector perpendicular to edge where n is zero (a degenerate triangle, parallel edges)
    ln = wp.length(n)
    if ln > 0.0:
        return n / ln
    return any_perpendicular(edge)


@wp.func
def vertex_triangle_ccd(
    p0: wp.vec3,
    a0: wp.vec3,
    b0: wp.vec3,
    c0: wp.vec3,
    p1: wp.vec3,
    a1: wp.vec3,
    b1: wp.vec3,
    c1: wp.vec3,
    eta: float,
    end_gap: float,
):
    # the first t in [0, 1] where vertex p comes within eta of triangle abc (all four moving linearly from
    # their 0 to their 1 positions) with the four in one plane: (hit, t, W = (1, -w0, -w1, -w2) at t, the
    # triangle's unit normal at t, r0 = sum W x at the start, r1 = at the end)
    e1 = b0 - a0
    e2 = c0 - a0
    e3 = p0 - a0
    d1 = (b1 - a1) - e1
    d2 = (c1 - a1) - e2
    d3 = (p1 - a1) - e3
    roots = unit_roots(coplanarity_cubic(e1, d1, e2, d2, e3, d3))
    for r in range(3):
        t = roots[r]
        if t <= 1.0:
            bt = e1 + t * d1
            ct = e2 + t * d2
            pt = e3 + t * d3
            q, w = closest_point_triangle(pt, wp.vec3(0.0), bt, ct)
            if wp.length(pt - q) <= eta:
                n = unit_normal(wp.cross(bt, ct), bt)
                r0 = e3 - w[1] * e1 - w[2] * e2
                r1 = (e3 + d3) - w[1] * (e1 + d1) - w[2] * (e2 + d2)
                return 1, t, wp.vec4(1.0, -w[0], -w[1], -w[2]), n, r0, r1
    # no crossing of the plane, but the end within end_gap (t = 1: a vertex a collider laid into the
    # triangle's plane, or one left nearer than the minimum gap)
    b1r = e1 + d1
    c1r = e2 + d2
    p1r = e3 + d3
    q1, w1 = closest_point_triangle(p1r, wp.vec3(0.0), b1r, c1r)
    if wp.length(p1r - q1) <= end_gap:
        r0 = e3 - w1[1] * e1 - w1[2] * e2
        n = unit_normal(wp.cross(b1r, c1r), b1r)
        return 1, 1.0, wp.vec4(1.0, -w1[0], -w1[1], -w1[2]), n, r0, p1r - q1
    return 0, 2.0, wp.vec4(0.0), wp.vec3(0.0), wp.vec3(0.0), wp.vec3(0.0)


@wp.func
def to_double(u: wp.vec3):
    return wp.vec3d(wp.float64(u[0]), wp.float64(u[1]), wp.float64(u[2]))


@wp.func
def closest_points_near_parallel(a: wp.vec3, b: wp.vec3, c: wp.vec3, d: wp.vec3):
    # (s, u, distance) of the closest points a + s (b - a), c + u (d - c) of two segments in float64
    # (Ericson 2005, 5.1.9, with no parallel fallback but an exactly parallel one): for edges parallel to
    # within ~1e-3 rad, where float32 cannot resolve where they cross (sin^2 of their angle is below its
    # rounding of a e - b^2) and closest_points_edge_edge takes the middle of their overlap
    p1 = to_double(a)
    p2 = to_double(c)
    d1 = to_double(b) - p1
    d2 = to_double(d) - p2
    r = p1 - p2
    aa = wp.dot(d1, d1)
    e = wp.dot(d2, d2)
    f = wp.dot(d2, r)
    cc = wp.dot(d1, r)
    bb = wp.dot(d1, d2)
    zero = wp.float64(0.0)
    one = wp.float64(1.0)
    if aa <= wp.float64(1.0e-30) or e <= wp.float64(1.0e-30):
        return 0.0, 0.0, 1.0e30
    denom = aa * e - bb * bb
    sd = zero
    if denom > zero:
        sd = wp.clamp((bb * f - cc * e) / denom, zero, one)
    ud = (bb * sd + f) / e
    if ud < zero:
        ud = zero
        sd = wp.clamp(-cc / aa, zero, one)
    elif ud > one:
        ud = one
        sd = wp.clamp((bb - cc) / aa, zero, one)
    gap = wp.length((p1 + sd * d1) - (p2 + ud * d2))
    return float(sd), float(ud), float(gap)


@wp.func
def edge_edge_ccd(
    a0: wp.vec3,
    b0: wp.vec3,
    c0: wp.vec3,
    d0: wp.vec3,
    a1: wp.vec3,
    b1: wp.vec3,
    c1: wp.vec3,
    d1: wp.vec3,
    eta: float,
    end_gap: float,
):
    # the first t in [0, 1] where edges ab and cd come within eta of each other in one plane: (hit, t,
    # W = (1 - s, s, u - 1, -u) of their closest points at t, the edges' unit normal at t, r0, r1)
    e1 = b0 - a0
    e2 = c0 - a0
    e3 = d0 - a0
    g1 = (b1 - a1) - e1
    g2 = (c1 - a1) - e2
    g3 = (d1 - a1) - e3
    roots = unit_roots(coplanarity_cubic(e1, g1, e2, g2, e3, g3))
    for r in range(3):
        t = roots[r]
        if t <= 1.0:
            bt = e1 + t * g1
            ct = e2 + t * g2
            dt = e3 + t * g3
            su = closest_points_edge_edge(wp.vec3(0.0), bt, ct, dt)
            s = su[0]
            u = su[1]
            gap = wp.length(s * bt - (ct + u * (dt - ct)))
            side = dt - ct
            if gap > eta and wp.length_sq(wp.cross(bt, side)) < 1.0e-5 * wp.length_sq(bt) * wp.length_sq(side):
                s, u, gap = closest_points_near_parallel(wp.vec3(0.0), bt, ct, dt)  # where they cross
            if gap <= eta:
                n = unit_normal(wp.cross(bt, dt - ct), bt)
                r0 = s * e1 - (e2 + u * (e3 - e2))
                r1 = s * (e1 + g1) - ((e2 + g2) + u * ((e3 + g3) - (e2 + g2)))
                return 1, t, wp.vec4(1.0 - s, s, u - 1.0, -u), n, r0, r1
    # the end within end_gap without a crossing of the plane
    b1r = e1 + g1
    c1r = e2 + g2
    d1r = e3 + g3
    su1 = closest_points_edge_edge(wp.vec3(0.0), b1r, c1r, d1r)
    s1 = su1[0]
    u1 = su1[1]
    r1 = s1 * b1r - (c1r + u1 * (d1r - c1r))
    if wp.length(r1) <= end_gap:
        n = unit_normal(wp.cross(b1r, d1r - c1r), b1r)
        r0 = s1 * e1 - (e2 + u1 * (e3 - e2))
        return 1, 1.0, wp.vec4(1.0 - s1, s1, u1 - 1.0, -u1), n, r0, r1
    return 0, 2.0, wp.vec4(0.0), wp.vec3(0.0), wp.vec3(0.0), wp.vec3(0.0)


@wp.func
def swept_boxes_apart(x0: Vec3Array, x1: Vec3Array, idx: wp.vec4i, first: int, margin: float):
    # whether the boxes swept by the pair's two sides (the first `first` vertices: 1 for a vertex-triangle
    # pair's vertex, 2 for an edge-edge pair's first edge; the others), relative to the pair's first vertex
    # (a common motion moves no box), lie more than margin apart: they cannot meet within margin on the way
    o0 = x0[idx[0]]
    o1 = x1[idx[0]]
    lo_a = wp.vec3(0.0)
    hi_a = wp.vec3(0.0)
    if first == 2:
        a0 = x0[idx[1]] - o0
        a1 = x1[idx[1]] - o1
        lo_a = wp.min(lo_a, wp.min(a0, a1))
        hi_a = wp.max(hi_a, wp.max(a0, a1))
    b0 = x0[idx[3]] - o0
    b1 = x1[idx[3]] - o1
    c0 = x0[idx[2]] - o0
    c1 = x1[idx[2]] - o1
    lo_b = wp.min(wp.min(b0, b1), wp.min(c0, c1))
    hi_b = wp.max(wp.max(b0, b1), wp.max(c0, c1))
    if first == 1:
        d0 = x0[idx[1]] - o0
        d1 = x1[idx[1]] - o1
        lo_b = wp.min(lo_b, wp.min(d0, d1))
        hi_b = wp.max(hi_b, wp.max(d0, d1))
    pad = wp.vec3(margin)
    return not boxes_overlap(lo_a - pad, hi_a + pad, lo_b, hi_b)


@wp.func
def cannot_close(x0: Vec3Array, x1: Vec3Array, idx: wp.vec4i, vertex_triangle: int, margin: float):
    # whether the pair's distance at the start, less twice its vertices' largest motion relative to its first
    # one's (the distance is 1-Lipschitz in each side), exceeds margin: it cannot come within margin
    o0 = x0[idx[0]]
    o1 = x1[idx[0]]
    motion = float(0.0)
    for k in range(1, 4):
        motion = wp.max(motion, wp.length((x1[idx[k]] - o1) - (x0[idx[k]] - o0)))
    a = x0[idx[1]] - o0
    b = x0[idx[2]] - o0
    c = x0[idx[3]] - o0
    d = float(0.0)
    if vertex_triangle != 0:
        q, _w = closest_point_triangle(wp.vec3(0.0), a, b, c)
        d = wp.length(q)
    else:
        st = closest_points_edge_edge(wp.vec3(0.0), a, b, c)
        d = wp.length(st[0] * a - (b + st[1] * (c - b)))
    return d - 2.0 * motion > margin


@wp.func
def pushable(inv_mass: FloatArray, held: Vec3Array, i: int, direction: wp.vec3):
    # 1/m of vertex i for a push along direction, 0 where it is pinned or where a collider holds it
    # (held: the collider's outward normal there, else 0) and the push goes into that collider
    if wp.dot(direction, held[i]) < 0.0:
        return 0.0
    return inv_mass[i]


@wp.kernel
def eval_ccd_held(x: Vec3Array, colliders: wp.array(dtype=Collider), margin: float, held: Vec3Array):
    # per vertex the outward normal of a collider whose thickness + margin it lies within (the last such
    # collider's), else 0: a push of the continuous response may move it out of that collider, not in
    i = wp.tid()
    held[i] = wp.vec3(0.0)
    for k in range(colliders.shape[0]):
        band = colliders[k].thickness + margin
        phi, n = collider_contact(colliders, k, x[i], band)
        if phi < band:
            held[i] = n


@wp.kernel
def merge_ccd_held(extra: Vec3Array, held: Vec3Array):
    # a vertex no collider holds takes the direction of ``extra`` (a collider edge's push this step), if any
    i = wp.tid()
    if wp.length_sq(held[i]) == 0.0:
        held[i] = extra[i]


@wp.kernel
def begin_ccd_round(counts: IntArray, moved: IntArray):
    # a later round of passes: every pair is tested again where the list was just rebuilt over the motion so
    # far (the round before's pushes moved a vertex beyond it); else the round does nothing (its passes return
    # at once) and the marks of the round before are kept for the fail-safe after it (end_ccd_round)
    i = wp.tid()
    rebuilt = counts[REBUILD]
    if rebuilt != 0:
        moved[i] = 1
    if i == 0:
        if rebuilt != 0:
            counts[CCD_CHANGED] = 1
        else:
            counts[CCD_SAVED] = counts[CCD_CHANGED]
            counts[CCD_CHANGED] = 0


@wp.kernel
def end_ccd_round(counts: IntArray):
    # a round that did not run leaves CCD_CHANGED as the round before left it
    if counts[REBUILD] == 0:
        counts[CCD_CHANGED] = counts[CCD_SAVED]


@wp.kernel
def begin_ccd_pass(counts: IntArray, first: int):
    # a pass starts: no collision recorded; it tests pairs only where the last pass changed a vertex (the
    # first: every pair)
    counts[CCD_HITS] = 0
    if first != 0:
        counts[CCD_CHANGED] = 1
    counts[CCD_ACTIVE] = counts[CCD_CHANGED]
    counts[CCD_CHANGED] = 0


@wp.kernel
def find_ccd_collisions(
    stride: int,
    counts: IntArray,
    x0: Vec3Array,
    x1: Vec3Array,
    inv_mass: FloatArray,
    mesh: SelfContactMesh,
    grid: SelfContactGrid,
    settings: SelfContactSettings,
    ccd: CcdState,
    mode: int,
    first: int,
):
    # grid-stride over the candidate pairs: those with no vertex that moved or collided in the last pass
    # (every pair in the first) and those whose two sides' swept boxes lie more than min_gap apart are
    # skipped; the rest are tested along the
    # motion x0 -> x1. A collision at t with weights W and normal n, oriented so that the start's
    # n . sum W x0 > 0, is (MODE_PUSH) recorded with the depth min_gap - n . sum W x1 that a push along n
    # removes, and counted at its free vertices (mass splitting); (MODE_ROLLBACK) its free vertices marked;
    # (MODE_COUNT) counted as unresolved. In the step's first pass (first != 0) a pair is skipped first by a bound
    # that reads no position: its gap at the list's build, less its sides' largest displacements since the build
    # to the step's start (motion_speed[0]: the gap of two convex hulls moves by at most as much) and their
    # largest straight motions over the step (swept_length, both relative to a common motion), above min_gap:
    # it stays min_gap apart all the way (no collision, no end closer than min_gap)
    tid = wp.tid()
    if counts[CCD_ACTIVE] == 0:  # the last pass moved nothing and found nothing: nothing changed
        return
    n_vt = wp.min(counts[CAND_VT], grid.cand_vt.shape[0])
    total = n_vt + wp.min(counts[CAND_EE], grid.cand_ee.shape[0])
    for k in range(tid, total, stride):
        idx = wp.vec4i()
        if k < n_vt:
            pair = grid.cand_vt[k]
            tri = mesh.tris[pair[1]]
            idx = wp.vec4i(pair[0], tri[0], tri[1], tri[2])
        else:
            pair = grid.cand_ee[k - n_vt]
            ea = mesh.edges[pair[0]]
            eb = mesh.edges[pair[1]]
            idx = wp.vec4i(ea[0], ea[1], eb[0], eb[1])
        if ccd.moved[idx[0]] + ccd.moved[idx[1]] + ccd.moved[idx[2]] + ccd.moved[idx[3]] == 0:
            continue
        first_side = 1
        if k >= n_vt:
            first_side = 2
        if first != 0:
            gap = float(0.0)
            if k < n_vt:
                gap = grid.cand_vt_gap[k]
            else:
                gap = grid.cand_ee_gap[k - n_vt]
            reach_a = float(0.0)
            reach_b = float(0.0)
            for j in range(4):
                r = grid.motion_speed[idx[j]][0] + ccd.swept_length[idx[j]]
                if j < first_side:
                    reach_a = wp.max(reach_a, r)
                else:
                    reach_b = wp.max(reach_b, r)
            if gap - (reach_a + reach_b) > settings.min_gap + rounding_slack(x0[idx[0]]):
                continue
        if swept_boxes_apart(x0, x1, idx, first_side, settings.min_gap):
            continue
        if cannot_close(x0, x1, idx, 2 - first_side, settings.min_gap):
            continue
        end_gap = ccd.eta
        if mode == MODE_PUSH:  # the pushes also leave every pair at least min_gap apart at the end
            end_gap = settings.min_gap
        hit = int(0)
        t = float(0.0)
        w = wp.vec4()
        n = wp.vec3()
        r0 = wp.vec3()
        r1 = wp.vec3()
        if k < n_vt:
            hit, t, w, n, r0, r1 = vertex_triangle_ccd(
                x0[idx[0]],
                x0[idx[1]],
                x0[idx[2]],
                x0[idx[3]],
                x1[idx[0]],
                x1[idx[1]],
                x1[idx[2]],
                x1[idx[3]],
                ccd.eta,
                end_gap,
            )
        else:
            hit, t, w, n, r0, r1 = edge_edge_ccd(
                x0[idx[0]],
                x0[idx[1]],
                x0[idx[2]],
                x0[idx[3]],
                x1[idx[0]],
                x1[idx[1]],
                x1[idx[2]],
                x1[idx[3]],
                ccd.eta,
                end_gap,
            )
        if hit == 0:
            continue
        if t == 0.0 and mode != MODE_PUSH:  # touching at the start: moving back to the start cannot help
            continue
        for j in range(4):  # tested again in the next pass, moved or not
            ccd.touched[idx[j]] = 1
        if first != 0 and mode == MODE_PUSH:
            wp.atomic_add(counts, CCD_COLLISIONS, 1)
        if mode == MODE_COUNT:
            wp.atomic_add(counts, CCD_UNRESOLVED, 1)
            continue
        if mode == MODE_ROLLBACK:
            for j in range(4):
                if inv_mass[idx[j]] > 0.0 and w[j] != 0.0:
                    ccd.rollback[idx[j]] = 1
            continue
        g0 = wp.dot(n, r0)
        g1 = wp.dot(n, r1)
        if wp.abs(g0) <= ccd.eta:  # touching at the start: no side to keep, the end's
            if g1 < 0.0:
                n = -n
                g1 = -g1
        elif g0 < 0.0:  # the normal from the start's side
            n = -n
            g1 = -g1
        depth = settings.min_gap - g1
        if depth <= 0.0:
            continue
        slot = wp.atomic_add(counts, CCD_HITS, 1)
        if slot < ccd.capacity:
            ccd.hit_idx[slot] = idx
            ccd.hit_w[slot] = w
            ccd.hit_n[slot] = n
            ccd.hit_depth[slot] = depth
            for j in range(4):
                if w[j] != 0.0 and pushable(inv_mass, ccd.held, idx[j], w[j] * n) > 0.0:
                    wp.atomic_add(ccd.acting, idx[j], 1)


@wp.kernel
def push_ccd_collisions(stride: int, counts: IntArray, inv_mass: FloatArray, ccd: CcdState, dx: Vec3Array):
    # each recorded collision's push: dx_k += W_k (depth / sum_j W_j^2 c_j / m_j) n / m_k, equal and
    # opposite (c_j: the pushes acting on vertex j in this pass; 1/m_j = 0 where the push would move j into
    # a collider that holds it or j is pinned; then the sum is at least max_k |W_k| c_k / m_k / 2 over the others,
    # so that a free vertex of small weight is not thrown at depth / W: twice the depth at most, 3 times where
    # over-relaxed. What the passes leave crossing, the fail-safe moves back, but for a pair whose held vertex
    # is a moving pin (the fail-safe moves free vertices only): counted in ccd_unresolved, and the run warns)
    tid = wp.tid()
    for k in range(tid, wp.min(counts[CCD_HITS], ccd.capacity), stride):
        idx = ccd.hit_idx[k]
        w = ccd.hit_w[k]
        depth = ccd.hit_depth[k]
        if depth <= 0.0:
            continue
        n = ccd.hit_n[k]
        m = wp.vec4()
        c = wp.vec4()
        s = float(0.0)
        shared = int(0)
        for j in range(4):
            m[j] = pushable(inv_mass, ccd.held, idx[j], w[j] * n)
            c[j] = float(wp.max(ccd.acting[idx[j]], 1))
            s += w[j] * w[j] * m[j] * c[j]
            if m[j] > 0.0 and ccd.acting[idx[j]] > 1:
                shared = 1
        s = capped_for_held(w, m, c, s)  # as the filter's
        if s > 0.0:
            relax = 1.0
            if shared != 0:  # a vertex's mass split over several pushes: over-relaxed
                relax = OVER_RELAXATION
            impulse = (relax * depth / s) * n
            for j in range(4):
                wp.atomic_add(dx, idx[j], (w[j] * m[j]) * impulse)


@wp.kernel
def roll_back_vertices(stride: int, counts: IntArray, x0: Vec3Array, x1: Vec3Array, rollback: IntArray, dx: Vec3Array):
    # the fail-safe (grid-stride over the vertices): a marked vertex goes back to its step's start
    if counts[CCD_ACTIVE] == 0:
        return
    for i in range(wp.tid(), x0.shape[0], stride):
        if rollback[i] != 0:
            dx[i] = x0[i] - x1[i]


@wp.kernel
def apply_ccd_corrections(
    stride: int,
    dt_v: float,
    dt_d: float,
    with_displacement: int,
    dx: Vec3Array,
    x: Vec3Array,
    v: Vec3Array,
    displacement: Vec3Array,
    ccd: CcdState,
    counts: IntArray,
):
    # x += dx, v += dx / dt_v (dt_v the collision interval: the velocity that moves x by as much over it),
    # a last step's displacement by dt_d / dt_v of it; moved: whether the vertex moved or was in a
    # collision of this pass (the next pass tests its pairs); dx, acting and the marks back to zero
    # (rolled-back vertices counted); grid-stride over the vertices; nothing to do where the pass tested
    # nothing (every mark already 0)
    if counts[CCD_ACTIVE] == 0:
        return
    for i in range(wp.tid(), x.shape[0], stride):
        d = dx[i]
        ccd.moved[i] = ccd.touched[i]
        ccd.touched[i] = 0
        if d[0] != 0.0 or d[1] != 0.0 or d[2] != 0.0:
            ccd.moved[i] = 1
            x[i] = x[i] + d
            v[i] = v[i] + d / dt_v
            if with_displacement != 0:
                displacement[i] = displacement[i] + (dt_d / dt_v) * d
            if ccd.rollback[i] != 0:
                wp.atomic_add(counts, CCD_ROLLBACKS, 1)
        if ccd.moved[i] != 0:
            wp.atomic_add(counts, CCD_CHANGED, 1)
        dx[i] = wp.vec3(0.0)
        ccd.acting[i] = 0
        ccd.rollback[i] = 0
