"""Self-contact kernels: vertex-triangle and edge-edge proximity of a cloth with itself, with a
thickness h [m] and a Coulomb friction coefficient mu (Bridson, Fedkiw & Anderson 2002).

Every contact is one record of four vertices k with weights W_k that sum to zero, a unit normal
n and the gap d = n . sum_k W_k x_k at detection:

* vertex p over triangle (a, b, c), closest point q = w0 a + w1 b + w2 c: vertices (p, a, b, c),
  W = (1, -w0, -w1, -w2), n = (p - q) / |p - q|;
* edge (a, b) near edge (c, d), closest points a + s (b - a) and c + t (d - c): vertices
  (a, b, c, d), W = (1 - s, s, t - 1, -t), n from the second closest point to the first (a pair
  whose closest point is an edge's end is left to that vertex's vertex-triangle contact).

An impulse J along n changes v_k by W_k J n / m_k, so sum_k m_k dv_k = J n sum_k W_k = 0: every
response is equal and opposite (momentum conserved to float32 rounding); a pinned vertex (1/m = 0)
takes none of it. Broad phase: a spatial hash made by kernels and a Verlet list of candidate pairs
within h + skin + per-vertex motion margins, rebuilt on the device only when motion since the build
asks for it, so a captured frame replays the adaptive schedule; lists have fixed capacities and an
overflow is counted, never silent. Response (Bridson et al. 2002, Sec. 7.2): a velocity filter of
inelastic impulses, the repulsion impulse min(dt k (h - d), m (0.1 (h - d)/dt - v_n)), a minimum-gap
impulse and Coulomb friction |dv_t| <= mu dv_n, Jacobi over the contacts with mass splitting; the
repulsion is also available as a force. Contacts run in grid-stride loops, so their cost is the
contact count, not the capacity. The margins, bounds and settings: docs/self-collision.md, "How it works".
"""

import warp as wp

from warpcloth.kernels.collide import Collider, collider_contact, segment_parameter

wp.set_module_options({"enable_backward": False})

#: Outside Warp's deterministic mode (warpcloth.sim.device.set_deterministic): its kernels read the
#: scalars they update with atomics, and its hash buckets are linked lists in thread order, which
#: the mode cannot reorder; a self-colliding run on CUDA is reproducible to rounding only.
NOT_DETERMINISTIC = "self-collision's candidate lists and contacts are built in the GPU's thread order"

Vec3Array = wp.array(dtype=wp.vec3)
FloatArray = wp.array(dtype=float)
IntArray = wp.array(dtype=int)
Vec2iArray = wp.array(dtype=wp.vec2i)
Vec3iArray = wp.array(dtype=wp.vec3i)
Vec4iArray = wp.array(dtype=wp.vec4i)
Vec4Array = wp.array(dtype=wp.vec4)
Vec2Array = wp.array(dtype=wp.vec2)

# -- indices of the integer counters (``counts``) -------------------------------------------------
CAND_VT = wp.constant(0)  # vertex-triangle candidates in the Verlet list
CAND_EE = wp.constant(1)  # edge-edge candidates in the Verlet list
CONTACTS = wp.constant(2)  # active contacts this step
REBUILD = wp.constant(3)  # 1 while this detect rebuilds the list
REBUILDS = wp.constant(4)  # list builds so far
OVERFLOW_CANDIDATES = wp.constant(5)  # candidate pairs that did not fit, so far
OVERFLOW_CONTACTS = wp.constant(6)  # contacts that did not fit, so far
TRUNCATED = wp.constant(7)  # queries whose radius exceeded the cells searched, so far
UNRESOLVED = wp.constant(8)  # contacts left closer than the minimum gap after a filter, so far
BUILT = wp.constant(9)  # 0 until the first build (or after an invalidate)
DETECTS = wp.constant(10)  # detect calls so far
CONTACTS_MAX = wp.constant(11)  # largest contact count of a step so far
CANDIDATES_MAX = wp.constant(12)  # largest candidate count of a build so far
FAST = wp.constant(13)  # vertices whose margin (two steps of their motion) was cut to skin_max at a build, so far
CCD_HITS = wp.constant(14)  # continuous collisions recorded in this pass (kernels/ccd.py)
CCD_COLLISIONS = wp.constant(15)  # continuous collisions found by a step's first pass, so far
CCD_ROLLBACKS = wp.constant(16)  # vertices the fail-safe moved back to their step's start, so far
CCD_UNRESOLVED = wp.constant(17)  # continuous collisions left after the fail-safe, so far
CCD_ACTIVE = wp.constant(18)  # vertices the last continuous pass moved or found in a collision (0: this pass has none)
CCD_CHANGED = wp.constant(19)  # the same, counted by this pass
SWEPT_REBUILDS = wp.constant(20)  # rebuilds over a step's swept motion, before its continuous response, so far
CCD_SAVED = wp.constant(21)  # CCD_CHANGED kept over a later round of the continuous response that does not run
COUNT_SLOTS = 22

# -- indices of the float scalars (``scalars``) ---------------------------------------------------
MOTION = wp.constant(0)  # max_i D_i = |x_i - x_build_i - u| + |v_i - w| dt this detect, u, w the mean motion [m]
SPEED = wp.constant(1)  # max |v - w| this detect [m/s]
R_BUILD = wp.constant(2)  # radius of the Verlet list without margins: h + skin [m]
R_ACTIVE = wp.constant(3)  # a candidate whose gap may be below 1.25 h + 3 |v|_max dt is evaluated [m]
SKIN = wp.constant(4)  # the skin of the current list [m]
R_BUILD_EE = wp.constant(5)  # radius of the edge-edge list without margins: h_e + skin [m], h_e = edge_fraction h
R_ACTIVE_EE = wp.constant(6)  # R_ACTIVE of the edge-edge candidates: 1.25 h_e + 3 |v|_max dt [m]
EXCESS = wp.constant(7)  # max_i (D_i - margin_i) this detect: the list is rebuilt when 2 EXCESS > skin [m]
MARGIN_MAX = wp.constant(8)  # largest vertex margin at the build [m]
INV_CELL = wp.constant(9)  # 1 / the hash's cell size at the build [1/m]
SPEED_ABS = wp.constant(10)  # max |v| this detect [m/s]
SWEPT_EXCESS = wp.constant(
    11
)  # max_i (|x_i - x_build_i - u| - margin_i) at a step's end, before its continuous response [m]
#: per axis (three slots from here), the largest half extent of a triangle's box grown by its margin at the
#: build [m]: a box that meets a query's has its centre within the query's box grown by as much
TRI_HALF = wp.constant(12)
EDGE_HALF = wp.constant(15)  # the same for the edges' boxes [m]
SCALAR_SLOTS = 18

#: an edge-edge contact whose closest point is within this parameter of an edge's end is left to that end's
#: vertex-triangle contact (the vertex is at least as near the edge's triangles as the edge)
END_PARAMETER = wp.constant(1.0e-4)
#: a vertex's margin covers this many steps of its motion relative to the mean (1: the list holds for the
#: step of its build while the vertex moves fast, and it is rebuilt at the next; a wider margin lists more
#: pairs of fast parts, most of them far apart)
MARGIN_STEPS = wp.constant(1.0)
#: a contact's normal found anew is turned to its detection side only where it points against it by more
#: than this cosine (a pair found side by side, its normal nearly across the detection's, keeps its own)
SIDE_COS = wp.constant(0.5)
#: the narrow phase's bound per pair is raised by this times (1 m + the pair's largest coordinate) [m/m]: its
#: gaps at the build and at x are float32 distances of positions rounded at ~6e-8 of their size, so the bound
#: never skips a pair that the full test would take
NARROW_SLACK = wp.constant(1.0e-6)
#: cells searched per axis at most by one query (a larger radius is counted in TRUNCATED)
MAX_CELLS_PER_AXIS = wp.constant(8)


# -- what a SelfCollision binds (warpcloth.sim.self_collision): arrays and scalars fixed after its bind ---------
# A struct is passed by value, so a captured frame holds its arrays' pointers and its scalars as they were at
# capture: what changes between steps lives in the arrays (``counts``, ``scalars``), never in a struct's scalar.
@wp.struct
class SelfContactMesh:
    """The cloth's topology: triangles, unique edges and the neighbour exclusion tables (CSR, sorted rows)."""

    tris: Vec3iArray
    edges: Vec2iArray
    vt_exclude_offsets: IntArray  # per vertex, its row of vt_exclude (the triangles it does not collide with)
    vt_exclude: IntArray
    ee_exclude_offsets: IntArray  # per edge, its row of ee_exclude (the edges it does not collide with)
    ee_exclude: IntArray
    group: IntArray  # per vertex, its collision group: pairs of two groups are no candidates (pieces apart)


@wp.struct
class SelfContactGrid:
    """The broad phase: the spatial hash (``mask`` + 1 buckets; per triangle and edge its next item in the
    bucket, its box grown by its margin, its cell and margin at the build), per vertex its position and margin
    at the build and its motion since (``motion_speed``), and the Verlet lists of candidate pairs with their
    gaps at the build (capacities ``vt_capacity``, ``ee_capacity``). ``ordered`` != 0: each bucket's list
    runs in decreasing item order (Warp's CPU backend)."""

    mask: int
    ordered: int
    head_tri: IntArray
    next_tri: IntArray
    tri_lo: Vec3Array
    tri_hi: Vec3Array
    tri_cell: Vec3iArray
    tri_margin: FloatArray
    head_edge: IntArray
    next_edge: IntArray
    edge_lo: Vec3Array
    edge_hi: Vec3Array
    edge_cell: Vec3iArray
    edge_margin: FloatArray
    x_build: Vec3Array
    margin: FloatArray
    motion_speed: Vec3Array
    cand_vt: Vec2iArray
    cand_vt_gap: FloatArray
    cand_ee: Vec2iArray
    cand_ee_gap: FloatArray
    vt_capacity: int
    ee_capacity: int


@wp.struct
class SelfContactList:
    """This step's contacts (capacity ``capacity``): per contact its vertices, weights W, normal n, gap d at
    detection and thickness h; per vertex the number of its contacts (``splits``: mass splitting)."""

    idx: Vec4iArray
    w: Vec4Array
    n: Vec3Array
    d: FloatArray
    h: FloatArray
    splits: IntArray
    capacity: int


@wp.struct
class SelfContactFilter:
    """A response pass's work arrays: per contact its change (W, n, (dv_n, velocity target)) found by the
    pass's count; per vertex the contacts acting on it, the velocity change dv, over a collision interval the
    end velocity's change dv_end and the interval's mean velocity."""

    f_w: Vec4Array
    f_n: Vec3Array
    f_change: Vec2Array
    acting: IntArray
    dv: Vec3Array
    dv_end: Vec3Array
    v_average: Vec3Array


@wp.struct
class SelfContactSettings:
    """The bound settings [m]: thickness h, edge pairs' h_e, the list's skin and largest vertex margin, the
    hash's least cell size, the filter's minimum gap; Coulomb mu of cloth on cloth."""

    thickness: float
    edge_thickness: float
    skin: float
    skin_max: float
    cell_size: float
    min_gap: float
    friction: float


# -- geometry ---------------------------------------------------------------------------------------
@wp.func
def rounding_slack(p: wp.vec3):
    # NARROW_SLACK (1 m + the largest coordinate of p) [m]: what a bound per pair near p is raised by
    size = wp.max(wp.max(wp.abs(p[0]), wp.abs(p[1])), wp.abs(p[2]))
    return NARROW_SLACK * (1.0 + size)


@wp.func
def boxes_overlap(lo_a: wp.vec3, hi_a: wp.vec3, lo_b: wp.vec3, hi_b: wp.vec3):
    # whether two axis-aligned boxes meet (closed; a point is the box [p, p])
    if lo_a[0] > hi_b[0] or lo_a[1] > hi_b[1] or lo_a[2] > hi_b[2]:
        return False
    return not (hi_a[0] < lo_b[0] or hi_a[1] < lo_b[1] or hi_a[2] < lo_b[2])


@wp.func
def closest_point_sides(p: wp.vec3, a: wp.vec3, b: wp.vec3, c: wp.vec3):
    # the point of the three sides ab, bc, ca nearest p, with its weights (a degenerate triangle's)
    t0 = segment_parameter(p, a, b)
    t1 = segment_parameter(p, b, c)
    t2 = segment_parameter(p, c, a)
    q0 = a + t0 * (b - a)
    q1 = b + t1 * (c - b)
    q2 = c + t2 * (a - c)
    d0 = wp.length_sq(p - q0)
    d1 = wp.length_sq(p - q1)
    d2 = wp.length_sq(p - q2)
    if d0 <= d1 and d0 <= d2:
        return q0, wp.vec3(1.0 - t0, t0, 0.0)
    if d1 <= d2:
        return q1, wp.vec3(0.0, 1.0 - t1, t1)
    return q2, wp.vec3(t2, 0.0, 1.0 - t2)


@wp.func
def closest_point_triangle(p: wp.vec3, a: wp.vec3, b: wp.vec3, c: wp.vec3):
    # q = w0 a + w1 b + w2 c, the point of the closed triangle nearest p (Ericson 2005, 5.1.5)
    ab = b - a
    ac = c - a
    if wp.length_sq(wp.cross(ab, ac)) <= 1.0e-12 * wp.dot(ab, ab) * wp.dot(ac, ac):
        return closest_point_sides(p, a, b, c)  # (nearly) degenerate: the nearest side
    ap = p - a
    d1 = wp.dot(ab, ap)
    d2 = wp.dot(ac, ap)
    if d1 <= 0.0 and d2 <= 0.0:
        return a, wp.vec3(1.0, 0.0, 0.0)
    bp = p - b
    d3 = wp.dot(ab, bp)
    d4 = wp.dot(ac, bp)
    if d3 >= 0.0 and d4 <= d3:
        return b, wp.vec3(0.0, 1.0, 0.0)
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        v = d1 / (d1 - d3)
        return a + v * ab, wp.vec3(1.0 - v, v, 0.0)
    cp = p - c
    d5 = wp.dot(ab, cp)
    d6 = wp.dot(ac, cp)
    if d6 >= 0.0 and d5 <= d6:
        return c, wp.vec3(0.0, 0.0, 1.0)
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        w = d2 / (d2 - d6)
        return a + w * ac, wp.vec3(1.0 - w, 0.0, w)
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        return b + w * (c - b), wp.vec3(0.0, 1.0 - w, w)
    denom = va + vb + vc
    v = vb / denom
    w = vc / denom
    return a + v * ab + w * ac, wp.vec3(1.0 - v - w, v, w)


@wp.func
def closest_points_edge_edge(p1: wp.vec3, q1: wp.vec3, p2: wp.vec3, q2: wp.vec3):
    # (s, t) of the closest points p1 + s (q1 - p1), p2 + t (q2 - p2) of two closed segments
    # (Ericson 2005, 5.1.9); (nearly) parallel segments (sin^2 of their angle < 1e-6) take the
    # middle of their overlap, so the contact sits where they overlap, not at an end
    d1 = q1 - p1
    d2 = q2 - p2
    r = p1 - p2
    a = wp.dot(d1, d1)
    e = wp.dot(d2, d2)
    f = wp.dot(d2, r)
    eps = float(1.0e-20)
    if a <= eps and e <= eps:
        return wp.vec2(0.0, 0.0)
    if a <= eps:
        return wp.vec2(0.0, wp.clamp(f / e, 0.0, 1.0))
    c = wp.dot(d1, r)
    if e <= eps:
        return wp.vec2(wp.clamp(-c / a, 0.0, 1.0), 0.0)
    b = wp.dot(d1, d2)
    denom = a * e - b * b
    s = float(0.0)
    if denom > 1.0e-6 * a * e:
        s = wp.clamp((b * f - c * e) / denom, 0.0, 1.0)
    else:
        sp = -c / a  # p2 and q2 projected on segment 1
        sq = (b - c) / a
        lo = wp.max(0.0, wp.min(sp, sq))
        hi = wp.min(1.0, wp.max(sp, sq))
        if lo <= hi:
            s = 0.5 * (lo + hi)
        else:
            s = wp.clamp(0.5 * (sp + sq), 0.0, 1.0)
    t = (b * s + f) / e
    if t < 0.0:
        t = 0.0
        s = wp.clamp(-c / a, 0.0, 1.0)
    elif t > 1.0:
        t = 1.0
        s = wp.clamp((b - c) / a, 0.0, 1.0)
    return wp.vec2(s, t)


@wp.func
def any_perpendicular(u: wp.vec3):
    # a unit vector perpendicular to u (u need not be unit; zero u gives +y)
    a = wp.vec3(0.0, 1.0, 0.0)
    if wp.abs(u[1]) > wp.abs(u[0]) and wp.abs(u[1]) > wp.abs(u[2]):
        a = wp.vec3(1.0, 0.0, 0.0)
    w = wp.cross(u, a)
    lw = wp.length(w)
    if lw == 0.0:
        return wp.vec3(0.0, 1.0, 0.0)
    return w / lw


@wp.func
def vertex_triangle_record(p: wp.vec3, a: wp.vec3, b: wp.vec3, c: wp.vec3):
    # weights W = (1, -w0, -w1, -w2), normal n = (p - q)/|p - q| (the face normal when p is on
    # the triangle) and gap d = |p - q|
    q, w = closest_point_triangle(p, a, b, c)
    diff = p - q
    d = wp.length(diff)
    n = wp.vec3(0.0)
    if d > 1.0e-9:
        n = diff / d
    else:
        face = wp.cross(b - a, c - a)
        lf = wp.length(face)
        if lf > 0.0:
            n = face / lf
        else:
            n = any_perpendicular(b - a)
    return wp.vec4(1.0, -w[0], -w[1], -w[2]), n, d


@wp.func
def edge_edge_record(a: wp.vec3, b: wp.vec3, c: wp.vec3, d: wp.vec3):
    # weights W = (1 - s, s, t - 1, -t), normal from the second closest point to the first (the
    # normal of both edges when they touch), gap = the distance between the closest points
    st = closest_points_edge_edge(a, b, c, d)
    s = st[0]
    t = st[1]
    diff = (a + s * (b - a)) - (c + t * (d - c))
    gap = wp.length(diff)
    n = wp.vec3(0.0)
    if gap > 1.0e-9:
        n = diff / gap
    else:
        m = wp.cross(b - a, d - c)
        lm = wp.length(m)
        if lm > 0.0:
            n = m / lm
        else:
            n = any_perpendicular(b - a)
    return wp.vec4(1.0 - s, s, t - 1.0, -t), n, gap


@wp.func
def weighted_sum(x: Vec3Array, idx: wp.vec4i, w: wp.vec4):
    # sum_k W_k x_k: the relative position (or, with v, velocity) of a contact's two sides
    return w[0] * x[idx[0]] + w[1] * x[idx[1]] + w[2] * x[idx[2]] + w[3] * x[idx[3]]


@wp.func
def penalty_depth(x: Vec3Array, dx: Vec3Array, idx: wp.vec4i, w: wp.vec4, n: wp.vec3, h: float):
    # delta = h - n . sum W (x + dx): how far a contact's record (W, n, thickness h) is within its thickness
    # at x + dx, the depth of vbd's penalty k delta^2 / 2 (> 0: acting)
    return h - wp.dot(n, weighted_sum(x, idx, w) + weighted_sum(dx, idx, w))


@wp.func
def contact_geometry(xa: wp.vec3, xb: wp.vec3, xc: wp.vec3, xd: wp.vec3, w_detect: wp.vec4, n_detect: wp.vec3):
    # a contact's weights, normal and signed gap at the positions given (the closest points found anew:
    # a pair that slid tangentially keeps its true distance), on the side of its detection: a pair that
    # passed through each other has a negative gap. Vertex-triangle records have W_0 = 1 exactly
    # (an edge-edge one 1 - s < 1)
    w = wp.vec4()
    n = wp.vec3()
    d = float(0.0)
    if w_detect[0] == 1.0:
        w, n, d = vertex_triangle_record(xa, xb, xc, xd)
    else:
        w, n, d = edge_edge_record(xa, xb, xc, xd)
    if wp.dot(n, n_detect) < -SIDE_COS:
        n = -n
        d = -d
    return w, n, d


@wp.func
def split_inverse_mass(idx: wp.vec4i, w: wp.vec4, inv_mass: FloatArray, splits: IntArray):
    # sum_k W_k^2 c_k / m_k: the contact's inverse effective mass, each vertex's mass split over its c_k contacts
    s = float(0.0)
    for k in range(4):
        c = wp.max(splits[idx[k]], 1)
        s += w[k] * w[k] * inv_mass[idx[k]] * float(c)
    return s


@wp.func
def capped_for_held(w: wp.vec4, inv_m4: wp.vec4, c4: wp.vec4, inv_m: float):
    # a contact with a held vertex (1/m = 0 and W != 0: pinned, or on a collider in the filter) moves only its
    # free ones, and where their weights are small the impulse dv_n / sum W^2 c / m threw them at ~ dv_n / W
    # (the 64 x 64 fold: an edge pair 97 % at a vertex on the ground, its free end W = 0.029, took 24 m/s in
    # one filter pass and went through the layer below). Capped: max(inv_m, max_k |W_k| c_k / m_k / 2) over
    # the free vertices (inv_m4: their 1/m, c4: their contact counts), so that no vertex takes more than twice
    # the contact's own change (split over its c_k contacts). The cap is never reached where c / m is the same
    # at every free vertex and the one of largest |W| has |W| >= 1/2 (sum W^2 >= W^2 >= |W| / 2), nor in a
    # vertex-triangle contact of uniform c / m; where c / m differs it may scale the impulse down (to 0.9 in a
    # review's example), never a vertex's change up
    held = int(0)
    share = float(0.0)
    for k in range(4):
        if w[k] != 0.0:
            if inv_m4[k] == 0.0:
                held = 1
            else:
                share = wp.max(share, wp.abs(w[k]) * inv_m4[k] * c4[k])
    if held != 0:
        return wp.max(inv_m, 0.5 * share)
    return inv_m


@wp.func
def held_capped_inverse_mass(idx: wp.vec4i, w: wp.vec4, inv_mass: FloatArray, splits: IntArray):
    # split_inverse_mass, capped where the contact has a held vertex (capped_for_held)
    inv_m4 = wp.vec4()
    c4 = wp.vec4()
    for k in range(4):
        inv_m4[k] = inv_mass[idx[k]]
        c4[k] = float(wp.max(splits[idx[k]], 1))
    return capped_for_held(w, inv_m4, c4, split_inverse_mass(idx, w, inv_mass, splits))


# -- the spatial hash -------------------------------------------------------------------------------
@wp.func
def cell_of(p: wp.vec3, inv_cell: float):
    return wp.vec3i(int(wp.floor(p[0] * inv_cell)), int(wp.floor(p[1] * inv_cell)), int(wp.floor(p[2] * inv_cell)))


@wp.func
def cell_bucket(i: int, j: int, k: int, mask: int):
    # bucket of cell (i, j, k): a multiplicative hash (Teschner et al. 2003), wrapped in uint32
    h = wp.uint32(i) * wp.uint32(73856093)
    h = h ^ (wp.uint32(j) * wp.uint32(19349663))
    h = h ^ (wp.uint32(k) * wp.uint32(83492791))
    return int(h & wp.uint32(mask))


@wp.func
def sorted_contains(values: IntArray, start: int, end: int, key: int):
    # whether the sorted values[start:end] hold key (binary search)
    lo = start
    hi = end
    while lo < hi:
        mid = (lo + hi) // 2
        v = values[mid]
        if v == key:
            return True
        if v < key:
            lo = mid + 1
        else:
            hi = mid
    return False


@wp.func
def append_index(counts: IntArray, slot: int, overflow_slot: int, capacity: int):
    # the next free index of a fixed-capacity list, or -1 (counted as overflow) when it is full
    k = wp.atomic_add(counts, slot, 1)
    if k >= capacity:
        wp.atomic_add(counts, overflow_slot, 1)
        return -1
    return k


# -- detect: motion, rebuild decision, broad phase, narrow phase ------------------------------------
@wp.kernel
def invalidate_self_contact_list(counts: IntArray):
    # the next detect rebuilds the candidate list
    counts[BUILT] = 0


@wp.kernel
def begin_self_contact_detect(counts: IntArray, scalars: FloatArray, sums: Vec3Array):
    # a detect starts: no contacts yet, motion and speed maxima and the sums of the means from zero
    counts[CONTACTS] = 0
    counts[DETECTS] = counts[DETECTS] + 1
    scalars[MOTION] = 0.0
    scalars[SPEED] = 0.0
    scalars[EXCESS] = -1.0e30
    scalars[SPEED_ABS] = 0.0
    sums[0] = wp.vec3(0.0)
    sums[1] = wp.vec3(0.0)


@wp.kernel
def sum_self_contact_motion(x: Vec3Array, v: Vec3Array, x_build: Vec3Array, sums: Vec3Array):
    # sums of the displacements since the build and of the velocities (their means: a common motion)
    i = wp.tid()
    wp.atomic_add(sums, 0, x[i] - x_build[i])
    wp.atomic_add(sums, 1, v[i])


@wp.kernel
def eval_self_contact_motion(
    x: Vec3Array,
    v: Vec3Array,
    grid: SelfContactGrid,
    sums: Vec3Array,
    dt: float,
    contacts: SelfContactList,
    scalars: FloatArray,
    x_start: Vec3Array,
):
    # motion relative to a common one (u, w: the mean displacement and velocity; a common motion
    # changes no gap, and any u, w bound it): D_i = |x_i - x_build_i - u| + |v_i - w| dt;
    # MOTION = max D_i, SPEED = max |v_i - w|, EXCESS = max (D_i - margin_i); contact counts from zero;
    # x_start = x (the collision interval's start); motion_speed_i = (|x_i - x_build_i - u|, |v_i - w|, |v_i|)
    # (the narrow phase's bound per pair)
    i = wp.tid()
    x_start[i] = x[i]
    scale = 1.0 / float(x.shape[0])
    speed = wp.length(v[i] - scale * sums[1])
    moved = wp.length(x[i] - grid.x_build[i] - scale * sums[0])
    motion = moved + speed * dt
    grid.motion_speed[i] = wp.vec3(moved, speed, wp.length(v[i]))
    wp.atomic_max(scalars, MOTION, motion)
    wp.atomic_max(scalars, SPEED, speed)
    wp.atomic_max(scalars, EXCESS, motion - grid.margin[i])
    wp.atomic_max(scalars, SPEED_ABS, wp.length(v[i]))
    contacts.splits[i] = 0


@wp.func
def begin_rebuild(counts: IntArray, scalars: FloatArray, settings: SelfContactSettings):
    # this detect (or swept check) rebuilds the list: its radii, maxima and lengths from zero
    scalars[SKIN] = settings.skin
    scalars[R_BUILD] = settings.thickness + settings.skin
    scalars[R_BUILD_EE] = settings.edge_thickness + settings.skin
    for k in range(3):
        scalars[TRI_HALF + k] = 0.0
        scalars[EDGE_HALF + k] = 0.0
    scalars[MARGIN_MAX] = 0.0
    counts[REBUILD] = 1
    counts[BUILT] = 1
    counts[REBUILDS] = counts[REBUILDS] + 1
    counts[CAND_VT] = 0
    counts[CAND_EE] = 0


@wp.kernel
def decide_self_contact_rebuild(counts: IntArray, scalars: FloatArray, settings: SelfContactSettings, dt: float):
    # rebuild when never built or when a vertex moved more than half the skin beyond its own margin
    # since the build (2 max_i (D_i - margin_i) > skin: an unlisted pair may be within h)
    scalars[R_ACTIVE] = 1.25 * settings.thickness + 3.0 * scalars[SPEED_ABS] * dt
    scalars[R_ACTIVE_EE] = 1.25 * settings.edge_thickness + 3.0 * scalars[SPEED_ABS] * dt
    if counts[BUILT] != 0 and 2.0 * scalars[EXCESS] <= settings.skin:
        counts[REBUILD] = 0
        return
    begin_rebuild(counts, scalars, settings)


# -- the list over a step's swept motion (before the continuous response) ---------------------------
@wp.kernel
def begin_swept_check(scalars: FloatArray, sums: Vec3Array):
    scalars[SWEPT_EXCESS] = -1.0e30
    sums[0] = wp.vec3(0.0)
    sums[1] = wp.vec3(0.0)


@wp.kernel
def sum_swept_motion(x: Vec3Array, x_start: Vec3Array, x_build: Vec3Array, sums: Vec3Array):
    # sums of the end's displacements since the build and of the step's (interval's) displacements
    i = wp.tid()
    wp.atomic_add(sums, 0, x[i] - x_build[i])
    wp.atomic_add(sums, 1, x[i] - x_start[i])


@wp.kernel
def eval_swept_motion(
    x: Vec3Array,
    x_start: Vec3Array,
    grid: SelfContactGrid,
    sums: Vec3Array,
    scalars: FloatArray,
    settings: SelfContactSettings,
    skip_capped: int,
    swept: Vec3Array,
    swept_length: FloatArray,
):
    # the end's excess over each vertex's margin, relative to the mean displacement u since the build:
    # SWEPT_EXCESS = max_i (|x_i - x_build_i - u| - margin_i); swept = x - x_start (the step's motion).
    # skip_capped: not over vertices whose margin is skin_max (counted in FAST at its build; a rebuild
    # cannot cover them either: the check after the continuous response's first round)
    i = wp.tid()
    swept[i] = x[i] - x_start[i]
    swept_length[i] = wp.length(swept[i] - sums[1] / float(x.shape[0]))  # relative to the mean (the CCD's bound)
    if skip_capped != 0 and grid.margin[i] >= settings.skin_max:
        return
    u = sums[0] / float(x.shape[0])
    wp.atomic_max(scalars, SWEPT_EXCESS, wp.length(x[i] - grid.x_build[i] - u) - grid.margin[i])


@wp.kernel
def decide_swept_rebuild(counts: IntArray, scalars: FloatArray, settings: SelfContactSettings):
    # the detect covered the step's start; the list covers the straight motion to the end as well where the end
    # is within skin / 2 of every margin (|d_i(t)| relative to the build is convex along the motion, so at most
    # its value at an end); else rebuild over the swept motion
    if 2.0 * scalars[SWEPT_EXCESS] <= settings.skin:
        counts[REBUILD] = 0
        return
    begin_rebuild(counts, scalars, settings)
    counts[SWEPT_REBUILDS] = counts[SWEPT_REBUILDS] + 1


@wp.kernel
def clear_self_contact_cells(
    counts: IntArray,
    x: Vec3Array,
    v: Vec3Array,
    sums: Vec3Array,
    dt: float,
    settings: SelfContactSettings,
    grid: SelfContactGrid,
    scalars: FloatArray,
):
    # (rebuild only) empty buckets; x_build = x; each vertex's margin = MARGIN_STEPS |v - w| dt (its
    # motion relative to the mean, at most skin_max: beyond, counted in FAST), MARGIN_MAX their largest;
    # motion_speed_i's displacement since this build 0 (x = x_build) (launched over max(buckets, particles))
    i = wp.tid()
    if counts[REBUILD] == 0:
        return
    if i < grid.head_tri.shape[0]:
        grid.head_tri[i] = -1
        grid.head_edge[i] = -1
    if i < x.shape[0]:
        grid.x_build[i] = x[i]
        ms = grid.motion_speed[i]
        grid.motion_speed[i] = wp.vec3(0.0, ms[1], ms[2])
        m = MARGIN_STEPS * dt * wp.length(v[i] - sums[1] / float(x.shape[0]))
        if m > settings.skin_max:
            m = settings.skin_max
            wp.atomic_add(counts, FAST, 1)
        grid.margin[i] = m
        wp.atomic_max(scalars, MARGIN_MAX, m)


@wp.kernel
def size_self_contact_cells(counts: IntArray, settings: SelfContactSettings, scalars: FloatArray):
    # (rebuild only) cells of the least cell size + the largest margin: a query spans a few cells whatever the
    # motion
    if counts[REBUILD] != 0:
        scalars[INV_CELL] = 1.0 / (settings.cell_size + scalars[MARGIN_MAX])


@wp.kernel
def insert_self_contact_triangles(
    counts: IntArray, x: Vec3Array, mesh: SelfContactMesh, grid: SelfContactGrid, scalars: FloatArray
):
    # (rebuild only) triangle t into the bucket of its box centre (its box grown by its margin, the
    # largest of its vertices', its cell and margin, kept for the queries); TRI_HALF: the grown boxes'
    # largest half extent per axis
    t = wp.tid()
    if counts[REBUILD] == 0:
        return
    tri = mesh.tris[t]
    a = x[tri[0]]
    b = x[tri[1]]
    c = x[tri[2]]
    lo = wp.min(wp.min(a, b), c)
    hi = wp.max(wp.max(a, b), c)
    cell = cell_of(0.5 * (lo + hi), scalars[INV_CELL])
    m = wp.max(wp.max(grid.margin[tri[0]], grid.margin[tri[1]]), grid.margin[tri[2]])
    grid.tri_lo[t] = lo - wp.vec3(m)
    grid.tri_hi[t] = hi + wp.vec3(m)
    grid.tri_cell[t] = cell
    grid.tri_margin[t] = m
    grid.next_tri[t] = wp.atomic_exch(grid.head_tri, cell_bucket(cell[0], cell[1], cell[2], grid.mask), t)
    for k in range(3):
        wp.atomic_max(scalars, TRI_HALF + k, 0.5 * (hi[k] - lo[k]) + m)


@wp.kernel
def insert_self_contact_edges(
    counts: IntArray, x: Vec3Array, mesh: SelfContactMesh, grid: SelfContactGrid, scalars: FloatArray
):
    # (rebuild only) edge e into the bucket of its midpoint (its box grown by its margin, its cell and
    # margin kept); EDGE_HALF: the grown boxes' largest half extent per axis
    e = wp.tid()
    if counts[REBUILD] == 0:
        return
    a = x[mesh.edges[e][0]]
    b = x[mesh.edges[e][1]]
    cell = cell_of(0.5 * (a + b), scalars[INV_CELL])
    m = wp.max(grid.margin[mesh.edges[e][0]], grid.margin[mesh.edges[e][1]])
    grid.edge_lo[e] = wp.min(a, b) - wp.vec3(m)
    grid.edge_hi[e] = wp.max(a, b) + wp.vec3(m)
    grid.edge_cell[e] = cell
    grid.edge_margin[e] = m
    grid.next_edge[e] = wp.atomic_exch(grid.head_edge, cell_bucket(cell[0], cell[1], cell[2], grid.mask), e)
    for k in range(3):
        wp.atomic_max(scalars, EDGE_HALF + k, 0.5 * wp.abs(b[k] - a[k]) + m)


@wp.func
def half_extents(scalars: FloatArray, slot: int, radius: float, p: wp.vec3):
    # a query's reach per axis: its radius + the inserted boxes' largest half extent on the axis (their centres'
    # cells: a box that meets the query's box has its centre within as much of it), + float32 rounding near p
    slack = radius + rounding_slack(p)
    return wp.vec3(scalars[slot] + slack, scalars[slot + 1] + slack, scalars[slot + 2] + slack)


@wp.func
def cell_range(lo_p: wp.vec3, hi_p: wp.vec3, inv_cell: float, counts: IntArray):
    # the cells of the box [lo_p, hi_p], at most MAX_CELLS_PER_AXIS per axis (a cut is counted)
    lo = cell_of(lo_p, inv_cell)
    hi = cell_of(hi_p, inv_cell)
    cut = int(0)
    for k in range(3):
        if hi[k] - lo[k] + 1 > MAX_CELLS_PER_AXIS:
            mid = (lo[k] + hi[k]) // 2
            lo[k] = mid - MAX_CELLS_PER_AXIS // 2
            hi[k] = lo[k] + MAX_CELLS_PER_AXIS - 1
            cut = 1
    if cut != 0:
        wp.atomic_add(counts, TRUNCATED, 1)
    return lo, hi


@wp.kernel
def find_vertex_triangle_candidates(
    counts: IntArray, scalars: FloatArray, x: Vec3Array, mesh: SelfContactMesh, grid: SelfContactGrid
):
    # (rebuild only) every triangle t within R_BUILD + margin_i + margin_t of vertex i, not its own and not
    # excluded, with its gap
    i = wp.tid()
    if counts[REBUILD] == 0:
        return
    p = x[i]
    r_i = scalars[R_BUILD] + grid.margin[i]
    inv_cell = scalars[INV_CELL]
    reach = half_extents(scalars, TRI_HALF, r_i, p)  # a box centre within r + its half extent, per axis
    lo, hi = cell_range(p - reach, p + reach, inv_cell, counts)
    e0 = mesh.vt_exclude_offsets[i]
    e1 = mesh.vt_exclude_offsets[i + 1]
    lo_p = p - wp.vec3(r_i)  # the vertex's box grown by its own radius (the triangles' hold their margins)
    hi_p = p + wp.vec3(r_i)
    for ci in range(lo[0], hi[0] + 1):
        for cj in range(lo[1], hi[1] + 1):
            for ck in range(lo[2], hi[2] + 1):
                t = grid.head_tri[cell_bucket(ci, cj, ck, grid.mask)]
                while t >= 0:
                    # a bucket holds one cell's triangles and other cells' that hash alike: a triangle
                    # is taken from the cell of its box centre only, so it is found once
                    if boxes_overlap(lo_p, hi_p, grid.tri_lo[t], grid.tri_hi[t]):
                        if grid.tri_cell[t] == wp.vec3i(ci, cj, ck):
                            tri = mesh.tris[t]
                            excluded = sorted_contains(mesh.vt_exclude, e0, e1, t)
                            excluded = excluded or mesh.group[tri[0]] != mesh.group[i]
                            if tri[0] != i and tri[1] != i and tri[2] != i and not excluded:
                                q, _w = closest_point_triangle(p, x[tri[0]], x[tri[1]], x[tri[2]])
                                gap = wp.length(p - q)
                                if gap <= r_i + grid.tri_margin[t]:
                                    k = append_index(counts, CAND_VT, OVERFLOW_CANDIDATES, grid.vt_capacity)
                                    if k >= 0:
                                        grid.cand_vt[k] = wp.vec2i(i, t)
                                        grid.cand_vt_gap[k] = gap
                    t = grid.next_tri[t]


@wp.kernel
def find_edge_edge_candidates(
    counts: IntArray, scalars: FloatArray, x: Vec3Array, mesh: SelfContactMesh, grid: SelfContactGrid
):
    # (rebuild only) every edge f > e within R_BUILD_EE + margin_e + margin_f of edge e, sharing no vertex and
    # not excluded, with its gap. ``ordered`` != 0: each bucket's list runs in decreasing edge order (the
    # insertion ran its threads in order: Warp's CPU backend), so a bucket's walk stops at the first f <= e
    # (half the visits); else (CUDA: any order) it walks the whole list
    e = wp.tid()
    if counts[REBUILD] == 0:
        return
    ea = mesh.edges[e][0]
    eb = mesh.edges[e][1]
    a = x[ea]
    b = x[eb]
    r_e = scalars[R_BUILD_EE] + grid.edge_margin[e]
    reach = half_extents(scalars, EDGE_HALF, r_e, a)  # a midpoint within r + its half extent, per axis
    lo, hi = cell_range(wp.min(a, b) - reach, wp.max(a, b) + reach, scalars[INV_CELL], counts)
    e0 = mesh.ee_exclude_offsets[e]
    e1 = mesh.ee_exclude_offsets[e + 1]
    lo_e = wp.min(a, b) - wp.vec3(r_e)  # the edge's box grown by its own radius (the others' hold their margins)
    hi_e = wp.max(a, b) + wp.vec3(r_e)
    for ci in range(lo[0], hi[0] + 1):
        for cj in range(lo[1], hi[1] + 1):
            for ck in range(lo[2], hi[2] + 1):
                f = grid.head_edge[cell_bucket(ci, cj, ck, grid.mask)]
                while f >= 0:
                    if grid.ordered != 0 and f <= e:
                        break
                    # (nested tests: Warp evaluates both sides of an `and`) found once: from its midpoint's cell
                    if f > e:
                        if boxes_overlap(grid.edge_lo[f], grid.edge_hi[f], lo_e, hi_e):
                            if grid.edge_cell[f] == wp.vec3i(ci, cj, ck):
                                fc = mesh.edges[f][0]
                                fd = mesh.edges[f][1]
                                if fc != ea and fc != eb and fd != ea and fd != eb:
                                    apart = mesh.group[fc] != mesh.group[ea]
                                    if not sorted_contains(mesh.ee_exclude, e0, e1, f) and not apart:
                                        c = x[fc]
                                        d = x[fd]
                                        st = closest_points_edge_edge(a, b, c, d)
                                        gap = wp.length((a + st[0] * (b - a)) - (c + st[1] * (d - c)))
                                        if gap <= r_e + grid.edge_margin[f]:
                                            k = append_index(counts, CAND_EE, OVERFLOW_CANDIDATES, grid.ee_capacity)
                                            if k >= 0:
                                                grid.cand_ee[k] = wp.vec2i(e, f)
                                                grid.cand_ee_gap[k] = gap
                    f = grid.next_edge[f]


@wp.kernel
def eval_self_contacts(
    stride: int,
    counts: IntArray,
    scalars: FloatArray,
    x: Vec3Array,
    v: Vec3Array,
    dt: float,
    mesh: SelfContactMesh,
    grid: SelfContactGrid,
    contacts: SelfContactList,
    settings: SelfContactSettings,
):
    # narrow phase (grid-stride over the candidates): a record (vertices, W, n, d) for every pair whose
    # gap d at x is below 1.25 h + dt (2 |sum W v| + max_k |v_k . n|) (it may come within h in this step:
    # its own relative speed, and its fastest vertex's speed along the pair's normal, which a collider may
    # stop within the step while the other side goes on: a layer falling onto one that lands on the
    # ground; across the normal that speed closes no gap, so a falling sheet's side-by-side pairs are not
    # contacts for it); per vertex, the number of its contacts (mass splitting). A pair whose gap at the
    # build, less twice the largest motion since, is not below R_ACTIVE (the same bound with the largest
    # speed) is not evaluated (its gap cannot have fallen below it); nor one whose gap at the build, less its
    # sides' largest displacements D_a + D_b since (relative to the mean: the gap of two convex hulls moves by
    # at most as much), is not below its own bound 1.25 h + dt (2 (r_a + r_b) + max(s_a, s_b)) (motion_speed:
    # r a side's largest |v - w|, so |sum W v| = |sum W (v - w)| <= r_a + r_b as sum W = 0; s its largest
    # |v|), nor one whose gap at x is not below it (its velocities are then not read): the same contacts,
    # fewer evaluated (a folded strip at rest beside its fast edges)
    tid = wp.tid()
    n_vt = wp.min(counts[CAND_VT], grid.cand_vt.shape[0])
    total = n_vt + wp.min(counts[CAND_EE], grid.cand_ee.shape[0])
    reach = 2.0 * scalars[MOTION]
    for k in range(tid, total, stride):
        idx = wp.vec4i()
        w = wp.vec4()
        n = wp.vec3()
        d = float(0.0)
        h = settings.thickness
        gap_build = float(0.0)
        first_side = 1  # vertices of the first side: (p) against (a, b, c), or (a, b) against (c, d)
        if k < n_vt:
            gap_build = grid.cand_vt_gap[k]
            if gap_build - reach >= scalars[R_ACTIVE]:
                continue
            pair = grid.cand_vt[k]
            tri = mesh.tris[pair[1]]
            idx = wp.vec4i(pair[0], tri[0], tri[1], tri[2])
        else:
            gap_build = grid.cand_ee_gap[k - n_vt]
            if gap_build - reach >= scalars[R_ACTIVE_EE]:
                continue
            pair = grid.cand_ee[k - n_vt]
            ea = mesh.edges[pair[0]]
            eb = mesh.edges[pair[1]]
            idx = wp.vec4i(ea[0], ea[1], eb[0], eb[1])
            h = settings.edge_thickness
            first_side = 2
        side_a = wp.vec3(0.0)
        side_b = wp.vec3(0.0)
        for j in range(4):
            ms = grid.motion_speed[idx[j]]
            if j < first_side:
                side_a = wp.max(side_a, ms)
            else:
                side_b = wp.max(side_b, ms)
        bound = 1.25 * h + dt * (2.0 * (side_a[1] + side_b[1]) + wp.max(side_a[2], side_b[2]))
        bound = bound + rounding_slack(x[idx[0]])
        if gap_build - (side_a[0] + side_b[0]) >= bound:
            continue
        if first_side == 1:
            w, n, d = vertex_triangle_record(x[idx[0]], x[idx[1]], x[idx[2]], x[idx[3]])
        else:
            w, n, d = edge_edge_record(x[idx[0]], x[idx[1]], x[idx[2]], x[idx[3]])
            # closest points at an end of either edge: that end's vertex-triangle contact holds it
            s = w[1]
            t = -w[3]
            if wp.min(s, t) <= END_PARAMETER or wp.max(s, t) >= 1.0 - END_PARAMETER:
                d = 1.0e30
        if d >= bound:
            continue
        speed = wp.max(
            wp.max(wp.abs(wp.dot(v[idx[0]], n)), wp.abs(wp.dot(v[idx[1]], n))),
            wp.max(wp.abs(wp.dot(v[idx[2]], n)), wp.abs(wp.dot(v[idx[3]], n))),
        )
        if d < 1.25 * h + dt * (2.0 * wp.length(weighted_sum(v, idx, w)) + speed):
            slot = append_index(counts, CONTACTS, OVERFLOW_CONTACTS, contacts.capacity)
            if slot >= 0:
                contacts.idx[slot] = idx
                contacts.w[slot] = w
                contacts.n[slot] = n
                contacts.d[slot] = d
                contacts.h[slot] = h
                for j in range(4):
                    wp.atomic_add(contacts.splits, idx[j], 1)


@wp.kernel
def finish_self_contact_detect(counts: IntArray, grid: SelfContactGrid, contacts: SelfContactList):
    # list lengths capped at their capacities (a full list counted on, for the overflow count);
    # the largest so far
    if counts[REBUILD] != 0:
        counts[CAND_VT] = wp.min(counts[CAND_VT], grid.vt_capacity)
        counts[CAND_EE] = wp.min(counts[CAND_EE], grid.ee_capacity)
        counts[CANDIDATES_MAX] = wp.max(counts[CANDIDATES_MAX], counts[CAND_VT] + counts[CAND_EE])
    counts[CONTACTS] = wp.min(counts[CONTACTS], contacts.capacity)
    counts[CONTACTS_MAX] = wp.max(counts[CONTACTS_MAX], counts[CONTACTS])


# -- response ---------------------------------------------------------------------------------------
@wp.kernel
def eval_self_contact_forces(
    stride: int,
    counts: IntArray,
    x: Vec3Array,
    v: Vec3Array,
    inv_mass: FloatArray,
    contacts: SelfContactList,
    stiffness: float,
    dt: float,
    f: Vec3Array,
):
    # repulsion F = min(k (h - d), m_eff (0.1 (h - d)/dt - v_n)/dt) >= 0 along n, f_k += W_k F n
    # (Bridson et al. 2002, Sec. 7.2), d = n . sum W x at x, v_n = n . sum W v, h the contact's thickness
    tid = wp.tid()
    for k in range(tid, counts[CONTACTS], stride):
        idx = contacts.idx[k]
        w = contacts.w[k]
        n = contacts.n[k]
        overlap = contacts.h[k] - wp.dot(n, weighted_sum(x, idx, w))
        if overlap > 0.0:
            inv_m = split_inverse_mass(idx, w, inv_mass, contacts.splits)
            if inv_m > 0.0:
                vn = wp.dot(n, weighted_sum(v, idx, w))
                force = wp.min(stiffness * overlap, (0.1 * overlap / dt - vn) / (inv_m * dt))
                if force > 0.0:
                    for j in range(4):
                        wp.atomic_add(f, idx[j], (w[j] * force) * n)


@wp.func
def filter_change(
    k: int,
    x: Vec3Array,
    v: Vec3Array,
    inv_mass: FloatArray,
    contacts: SelfContactList,
    min_gap: float,
    inelastic: int,
    stiffness: float,
    dt: float,
    dt_x: float,
):
    # contact k at the step's end (x, v), its weights W, normal n and signed gap d found anew there
    # (contact_geometry), d0 its gap at detection, h its thickness (h, or h_e for an edge pair),
    # delta = h - d0: the normal relative velocity v_n = n . sum W v is to be raised to
    #   max(0 [inelastic, d0 < h], min(0.1 delta / dt, dt k delta / m_eff) [repulsion, stiffness > 0],
    #       v_n + (min_gap - d) / dt_x [the gap kept >= min_gap])
    # (Bridson et al. 2002, Sec. 7.2); returns W, n, sum W v, the change dv_n (acting where > 0) and the
    # velocity target without the gap's term (-1e30: none)
    idx = contacts.idx[k]
    w, n, d = contact_geometry(x[idx[0]], x[idx[1]], x[idx[2]], x[idx[3]], contacts.w[k], contacts.n[k])
    vr = weighted_sum(v, idx, w)
    vn = wp.dot(n, vr)
    target = -1.0e30
    delta = contacts.h[k] - contacts.d[k]
    if delta > 0.0 and inelastic != 0:
        target = 0.0
        if stiffness > 0.0:
            full = float(0.0)
            for j in range(4):
                full += w[j] * w[j] * inv_mass[idx[j]]
            target = wp.min(0.1 * delta / dt, dt * stiffness * delta * full)
    velocity_target = target
    target = wp.max(target, vn + (min_gap - d) / dt_x)
    return w, n, vr, target - vn, velocity_target


@wp.func
def count_acting(idx: wp.vec4i, w: wp.vec4, inv_mass: FloatArray, acting: IntArray):
    # one more acting contact at each of the contact's free vertices (mass splitting over acting contacts)
    for j in range(4):
        if inv_mass[idx[j]] > 0.0 and w[j] != 0.0:
            wp.atomic_add(acting, idx[j], 1)


@wp.kernel
def count_filter_contacts(
    stride: int,
    counts: IntArray,
    x: Vec3Array,
    v: Vec3Array,
    inv_mass: FloatArray,
    contacts: SelfContactList,
    settings: SelfContactSettings,
    inelastic: int,
    stiffness: float,
    dt: float,
    dt_x: float,
    work: SelfContactFilter,
):
    # per vertex, the contacts of this filter pass that act on it (dv_n > 0); per contact its filter_change
    # (dv_n and the velocity target; W and n where dv_n > 0) for the pass's filter_self_contact_velocities
    tid = wp.tid()
    for k in range(tid, counts[CONTACTS], stride):
        w, n, _vr, dvn, tv = filter_change(
            k, x, v, inv_mass, contacts, settings.min_gap, inelastic, stiffness, dt, dt_x
        )
        work.f_change[k] = wp.vec2(dvn, tv)
        if dvn > 0.0:
            work.f_w[k] = w
            work.f_n[k] = n
            count_acting(contacts.idx[k], w, inv_mass, work.acting)


@wp.kernel
def filter_self_contact_velocities(
    stride: int,
    counts: IntArray,
    inv_mass: FloatArray,
    contacts: SelfContactList,
    work: SelfContactFilter,
    settings: SelfContactSettings,
    v_slip: Vec3Array,
    interval: int,
):
    # per contact the normal change dv_n of filter_change where > 0 (found by this pass's count_filter_contacts,
    # from the same x and v), friction |dv_t| = min(mu dv_n, |v_t|)
    # against the tangential relative velocity of v_slip (v; over a collision interval the end velocity,
    # which the step goes on with: friction on the interval's mean could reverse it);
    # impulse J = dv / sum W^2 c / m; dv_k += W_k J / m_k (Jacobi, masses split over the c contacts acting
    # on a vertex in this pass: count_filter_contacts)
    tid = wp.tid()
    for k in range(tid, counts[CONTACTS], stride):
        change = work.f_change[k]
        dvn = change[0]
        if dvn > 0.0:
            tv = change[1]
            w = work.f_w[k]
            n = work.f_n[k]
            idx = contacts.idx[k]
            inv_m = held_capped_inverse_mass(idx, w, inv_mass, work.acting)
            if inv_m > 0.0:
                vs = weighted_sum(v_slip, idx, w)
                vn_end = wp.dot(n, vs)
                # over an interval the end velocity takes only what its own normal velocity lacks of the
                # inelastic and repulsion target (the gap's term moves x alone); every step the same change
                dvn_end = dvn
                if interval != 0:
                    dvn_end = wp.max(0.0, tv - vn_end)
                vt = vs - vn_end * n
                lt = wp.length(vt)
                friction = wp.vec3(0.0)
                if lt > 0.0:
                    friction = (wp.min(settings.friction * dvn_end, lt) / lt) * vt
                impulse = (dvn * n - friction) / inv_m
                for j in range(4):
                    wp.atomic_add(work.dv, idx[j], (w[j] * inv_mass[idx[j]]) * impulse)
                if interval != 0:
                    impulse_end = (dvn_end * n - friction) / inv_m
                    for j in range(4):
                        wp.atomic_add(work.dv_end, idx[j], (w[j] * inv_mass[idx[j]]) * impulse_end)


@wp.kernel
def eval_filter_inverse_mass(
    x: Vec3Array, inv_mass: FloatArray, colliders: wp.array(dtype=Collider), margin: float, out: FloatArray
):
    # 1/m, or 0 where the vertex lies within a collider's thickness + margin: the filter then moves the
    # pair's other side only (a push into the collider would be undone by the collider's projection after
    # it, and a layer pressed onto a cloth lying on the ground would close the gap step by step)
    i = wp.tid()
    w = inv_mass[i]
    if w > 0.0:
        for k in range(colliders.shape[0]):
            band = colliders[k].thickness + margin
            phi, _n = collider_contact(colliders, k, x[i], band)
            if phi < band:
                w = 0.0
    out[i] = w


@wp.kernel
def apply_self_contact_velocities(
    work: SelfContactFilter,
    dt_x: float,
    dt_d: float,
    with_displacement: int,
    with_average: int,
    x: Vec3Array,
    v: Vec3Array,
    displacement: Vec3Array,
):
    # x += dt_x dv; v += dv (and a last step's displacement d += dt_d dv); over an interval the mean
    # velocity += dv, and the velocity the step goes on with (v, d) takes dv_end instead; dv = dv_end = 0,
    # the acting counts 0
    i = wp.tid()
    dvi = work.dv[i]
    dv_on = dvi
    if with_average != 0:
        work.v_average[i] = work.v_average[i] + dvi
        dv_on = work.dv_end[i]
        work.dv_end[i] = wp.vec3(0.0)
    v[i] = v[i] + dv_on
    x[i] = x[i] + dt_x * dvi
    if with_displacement != 0:
        displacement[i] = displacement[i] + dt_d * dv_on
    work.dv[i] = wp.vec3(0.0)
    work.acting[i] = 0


@wp.kernel
def eval_interval_velocity(x: Vec3Array, x_start: Vec3Array, interval: float, v_average: Vec3Array):
    # the collision interval's mean velocity (x - x_start) / interval: what the filter acts on where the
    # interval is longer than a step (Bridson et al. 2002, Sec. 7.1: a step's end velocity may swing
    # with the scheme's fastest mode while its motion does not)
    i = wp.tid()
    v_average[i] = (x[i] - x_start[i]) / interval


@wp.kernel
def count_unresolved_self_contacts(
    stride: int,
    counts: IntArray,
    x: Vec3Array,
    contacts: SelfContactList,
    settings: SelfContactSettings,
    inv_mass: FloatArray,
):
    # contacts (with a free vertex) still closer than 0.99 min_gap after the filter (their gap found anew)
    tid = wp.tid()
    for k in range(tid, counts[CONTACTS], stride):
        idx = contacts.idx[k]
        free = inv_mass[idx[0]] + inv_mass[idx[1]] + inv_mass[idx[2]] + inv_mass[idx[3]]
        _w, _n, d = contact_geometry(x[idx[0]], x[idx[1]], x[idx[2]], x[idx[3]], contacts.w[k], contacts.n[k])
        if free > 0.0 and d < 0.99 * settings.min_gap:
            wp.atomic_add(counts, UNRESOLVED, 1)


# -- inside the solvers ------------------------------------------------------------------------------
@wp.func
def increment_violation(k: int, x: Vec3Array, dp: Vec3Array, contacts: SelfContactList):
    # contact k at p = x + dp: its W, n (found anew, contact_geometry) and C = d - h (< 0: violated)
    idx = contacts.idx[k]
    w, n, d = contact_geometry(
        x[idx[0]] + dp[idx[0]],
        x[idx[1]] + dp[idx[1]],
        x[idx[2]] + dp[idx[2]],
        x[idx[3]] + dp[idx[3]],
        contacts.w[k],
        contacts.n[k],
    )
    return w, n, d - contacts.h[k]


@wp.kernel
def count_violated_contacts(
    stride: int,
    counts: IntArray,
    x: Vec3Array,
    dp: Vec3Array,
    inv_mass: FloatArray,
    contacts: SelfContactList,
    acting: IntArray,
):
    # per vertex, the contacts violated at p = x + dp (mass splitting over acting contacts)
    tid = wp.tid()
    for k in range(tid, counts[CONTACTS], stride):
        w, _n, c = increment_violation(k, x, dp, contacts)
        if c < 0.0:
            count_acting(contacts.idx[k], w, inv_mass, acting)


@wp.kernel
def project_self_contact_increments(
    stride: int,
    counts: IntArray,
    x: Vec3Array,
    dp: Vec3Array,
    inv_mass: FloatArray,
    acting: IntArray,
    contacts: SelfContactList,
    mu: float,
    delta: Vec3Array,
):
    # a contact as a constraint on p = x + dp (position-based solvers, inside their iterations): where
    # C = d - h < 0 (increment_violation), the correction J = (-C n - min(mu |C|, |u_t|) u_t / |u_t|) /
    # sum W^2 c / m, u_t the relative tangential displacement (I - n n^T) sum W dp (Coulomb on positions),
    # and delta_k += W_k J / m_k: equal and opposite, masses split over the c violated contacts of a vertex
    # (count_violated_contacts; Jacobi: apply_increment_corrections)
    tid = wp.tid()
    for k in range(tid, counts[CONTACTS], stride):
        w, n, c = increment_violation(k, x, dp, contacts)
        if c < 0.0:
            idx = contacts.idx[k]
            inv_m = held_capped_inverse_mass(idx, w, inv_mass, acting)
            if inv_m > 0.0:
                u = weighted_sum(dp, idx, w)
                corr = -c * n
                ut = u - wp.dot(u, n) * n
                lt = wp.length(ut)
                if lt > 0.0:
                    corr = corr - (wp.min(-mu * c, lt) / lt) * ut
                corr = corr / inv_m
                for j in range(4):
                    wp.atomic_add(delta, idx[j], (w[j] * inv_mass[idx[j]]) * corr)


@wp.kernel
def apply_increment_corrections(delta: Vec3Array, dp: Vec3Array, acting: IntArray):
    # dp += delta; delta = 0, the acting counts 0
    i = wp.tid()
    dp[i] = dp[i] + delta[i]
    delta[i] = wp.vec3(0.0)
    acting[i] = 0


@wp.kernel
def clear_self_contact_vertex_terms(force: Vec3Array, hessian: wp.array(dtype=wp.mat33)):
    i = wp.tid()
    force[i] = wp.vec3(0.0)
    hessian[i] = wp.mat33(0.0)


@wp.kernel
def eval_self_contact_vertex_terms(
    stride: int,
    counts: IntArray,
    x: Vec3Array,
    dx: Vec3Array,
    inv_mass: FloatArray,
    contacts: SelfContactList,
    stiffness: float,
    force: Vec3Array,
    hessian: wp.array(dtype=wp.mat33),
):
    # the penalty energy k delta^2 / 2 of every contact with delta = h - n . sum W (x + dx) > 0, per free
    # vertex a: its force f_a += k delta W_a n and Gauss-Newton Hessian H_a += k W_a^2 n n^T (vbd's local
    # Newton step; equal and opposite, sum_a f_a = k delta n sum W = 0)
    tid = wp.tid()
    for k in range(tid, counts[CONTACTS], stride):
        idx = contacts.idx[k]
        w = contacts.w[k]
        n = contacts.n[k]
        d = penalty_depth(x, dx, idx, w, n, contacts.h[k])
        if d > 0.0:
            nn = wp.outer(n, n)
            for j in range(4):
                if inv_mass[idx[j]] > 0.0:
                    wp.atomic_add(force, idx[j], (stiffness * d * w[j]) * n)
                    wp.atomic_add(hessian, idx[j], (stiffness * w[j] * w[j]) * nn)
