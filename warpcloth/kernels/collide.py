"""Collision kernels: particles against planes, spheres, capsules, oriented boxes and static
triangle meshes, each with a thickness (cloth offset) [m] and a Coulomb friction coefficient mu.
Pinned particles (inverse mass 0) are left alone: pins win over contacts.

Every collider is one :class:`Collider` record in one array, planes first, and one launch per
response loops over all of them per particle, with cheap exact rejections before each signed
distance phi(x) and outward unit normal n (pure ``@wp.func``; the hot helpers are forced inline
because Warp's CPU code passes array arguments by value to a function that is not). A collider
moves rigidly with a velocity field v_c(y) = u + w x (y - o) (zero when static); the responses use
the particle's velocity relative to it:

* after a force-based step (velocity level): a particle with phi < thickness is moved out along n
  by the depth, its approaching relative normal velocity removed (dv_n = max(0, -(v - v_c).n)) and
  its relative tangential velocity reduced by mu dv_n, at most to zero (Coulomb); the tangential
  change is applied to the position too (x += dt dv_t; dt/2 dv_t for the Runge-Kutta schemes), so a
  sticking particle does not creep. Verlet's displacement d is set to v dt.
* inside the position-based solver loop: the predicted displacement dp is moved out along n, and
  after the iterations the tangential part of dp relative to v_c h is cancelled up to mu times the
  accumulated normal correction (Macklin et al. 2014).

Poses: :func:`eval_collider_pose` moves a collider's rest record along its track (keyframed
offsets, or a rigid motion c + u t + R(axis, theta(t))(y - c)) in float64 from the float64 time,
rounding to float32 once; :func:`eval_collider_driven_pose` does the same for a pose the host sets
each frame. Details: docs/colliders.md.
"""

import warp as wp

from warpcloth.kernels.pins import rotate_axis_angle, track_keyframes

wp.set_module_options({"enable_backward": False})

PLANE = wp.constant(0)
SPHERE = wp.constant(1)
CAPSULE = wp.constant(2)
BOX = wp.constant(3)
MESH = wp.constant(4)
#: phi of a collider a cheap test shows the particle is not near (no contact)
NOT_NEAR = wp.constant(1.0e30)


@wp.struct
class Collider:
    kind: int  # PLANE, SPHERE, CAPSULE, BOX, MESH
    a: wp.vec3  # plane point / sphere centre / capsule end a / box centre / mesh box centre (posed) [m]
    b: wp.vec3  # plane normal / - / capsule end b / box half extents / mesh box half size (+ thickness) [m]
    radius: float  # sphere, capsule radius; a mesh's reach (deepest inside still pushed out) [m]
    mesh: wp.uint64  # a MESH's wp.Mesh id
    rotation: wp.mat33  # box, mesh: world from the collider's own frame
    thickness: float  # the cloth's offset from the surface [m]
    mu: float  # Coulomb friction coefficient
    bound_center: wp.vec3  # centre of the collider's axis-aligned bounding box (half_size) [m]
    velocity: wp.vec3  # u: velocity of the point `origin` [m/s]
    omega: wp.vec3  # w: angular velocity [rad/s]
    origin: wp.vec3  # o [m]
    rest_center: wp.vec3  # a MESH's box centre in the mesh's own frame (its BVH's), where a = its posed centre [m]
    moving: int  # 1: on a track (velocity, omega, origin set by eval_collider_pose); 0: static, v_c = 0
    rounding: float  # a BOX's edges and corners (a MESH's convex creases) held at thickness + rounding [m]
    crease_bvh: wp.uint64  # a MESH's convex creases and open edges: a wp.Bvh of their boxes (0: none)
    crease_a: wp.array(dtype=wp.vec3)  # their ends, in the mesh's own frame [m]
    crease_b: wp.array(dtype=wp.vec3)
    deforming: int  # 1: a MESH whose points the step moves (world frame, moving = 0; v_c from its vertices' velocities)
    motion: wp.array(
        dtype=wp.vec3
    )  # a deforming MESH's vertices' mean velocity over the (sub)step ending at its pose [m/s]
    speed: float  # the largest of those [m/s] (swept_mesh_contact's bound on the surface's motion; else 0)


@wp.struct
class Colliders:
    """A control's colliders as one kernel argument (the solvers that hold contacts themselves): no
    colliders is an empty ``records``."""

    records: wp.array(dtype=Collider)  # every collider's record, planes first
    box: wp.array(dtype=wp.vec3)  # [min, max] around the non-plane colliders (eval_collider_bounds)
    plane_count: int  # planes at the front of records


@wp.func(inline=True)
def plane_contact(x: wp.vec3, point: wp.vec3, normal: wp.vec3):
    # phi = (x - p).n, outward normal n
    return wp.dot(x - point, normal), normal


@wp.func(inline=True)
def sphere_contact(x: wp.vec3, center: wp.vec3, radius: float):
    # phi = |x - c| - r, n = (x - c)/|x - c|
    d = x - center
    length = wp.length(d)
    if length == 0.0:
        return -radius, wp.vec3(0.0, 1.0, 0.0)
    return length - radius, d / length


@wp.func(inline=True)
def box_contact(x: wp.vec3, center: wp.vec3, rotation: wp.mat33, half: wp.vec3):
    # signed distance of an oriented box (p = R^T (x - c)); n the gradient (the nearest face's normal inside)
    p = wp.transpose(rotation) * (x - center)
    q = wp.vec3(wp.abs(p[0]) - half[0], wp.abs(p[1]) - half[1], wp.abs(p[2]) - half[2])
    s = wp.vec3(wp.sign(p[0]), wp.sign(p[1]), wp.sign(p[2]))
    outside = wp.vec3(wp.max(q[0], 0.0), wp.max(q[1], 0.0), wp.max(q[2], 0.0))
    lo = wp.length(outside)
    if lo > 0.0:
        n_local = wp.cw_mul(outside / lo, s)
        return lo, rotation * n_local
    k = int(0)
    if q[1] > q[k]:
        k = 1
    if q[2] > q[k]:
        k = 2
    n_local = wp.vec3(0.0)
    n_local[k] = s[k]
    return q[k], rotation * n_local


@wp.func
def edge_offset(y: wp.vec3, half: wp.vec3, i: int):
    # y (|p|, the box's own frame folded into its positive octant) less its nearest point on the box
    # edge along axis i there (the segment at +half in the two other axes)
    w = y - half
    w[i] = wp.max(w[i], 0.0)
    return w


@wp.func
def out_of_rounded_box(p: wp.vec3, half: wp.vec3, radius: float, thickness: float):
    # p (the box's own frame) moved out of the box grown by the thickness and out of the capsules of
    # `radius` along its edges: three rounds of a projection out of each term (the capsules of the
    # three edges nearest the point, then the box, folded into its octant anew each round, so that a
    # push across a thin box's mid-plane meets the edges on that side)
    y = p
    for _round in range(3):
        s = wp.vec3(1.0, 1.0, 1.0)
        for i in range(3):
            if y[i] < 0.0:
                s[i] = -1.0
        u = wp.cw_mul(y, s)
        q = u - half
        if q[0] <= 0.0 and q[1] <= 0.0 and q[2] <= 0.0:  # inside: out through the nearest face first
            k = int(0)
            if q[1] > q[k]:
                k = 1
            if q[2] > q[k]:
                k = 2
            u[k] = half[k] + thickness
        for i in range(3):
            w = edge_offset(u, half, i)
            d = wp.length(w)
            if d < radius and d > 0.0:
                u = u + (radius - d) / d * w
        q = u - half
        outside = wp.vec3(wp.max(q[0], 0.0), wp.max(q[1], 0.0), wp.max(q[2], 0.0))
        lo = wp.length(outside)
        if lo < thickness and lo > 0.0:
            u = u + (thickness - lo) / lo * outside
        y = wp.cw_mul(u, s)
    return y


@wp.func
def rounded_box_contact(
    x: wp.vec3, center: wp.vec3, rotation: wp.mat33, half: wp.vec3, rounding: float, thickness: float
):
    # box_contact with capsules of radius R = thickness + rounding along the box's 12 edges: contact
    # where x is within the thickness of the box or within R of an edge. Where no term holds x:
    # phi = min(phi_box, d_edge - rounding) and its normal (d_edge: the nearest edge's distance), at
    # least the thickness. Where one does: the point y out of every term (out_of_rounded_box: the
    # capsules meet in concave creases, at a corner between two edges' capsules and where a capsule
    # meets a face, and one term's projection alone lands in the next: a particle on the table's corner
    # cycled between the two edges, 0.5 mm a frame); then phi = thickness - |y - x| and
    # n = (y - x) / |y - x|, so a response x + (thickness - phi) n reaches y. Away from the capsules the
    # box's own (phi, n), exact for a particle resting on a face. A particle inside the box: the box's own
    # too (out through its nearest face; the capsule holds it at the next pass: a push out of both at once
    # from deep inside tilted vbd's contacts and its 64 x 64 tablecloth blew up landing, 0.98 at 0.15 s,
    # measured), but for a box of thickness 0, whose resting particles sit at phi <= 0: those go out of
    # the face and the capsules at once (else a sharp edge stood between them).
    phi, n = box_contact(x, center, rotation, half)
    if rounding <= 0.0 or (phi <= 0.0 and thickness > 0.0):
        return phi, n
    p = wp.transpose(rotation) * (x - center)
    s = wp.vec3(1.0, 1.0, 1.0)
    for i in range(3):
        if p[i] < 0.0:
            s[i] = -1.0
    u = wp.cw_mul(p, s)
    near = float(1.0e30)
    w_near = wp.vec3(0.0)
    for i in range(3):
        w = edge_offset(u, half, i)
        d = wp.length(w)
        if d < near:
            near = d
            w_near = w
    if near - rounding >= thickness:  # no capsule holds x: the box's own contact, or the nearer surface's distance
        if phi >= thickness and near - rounding < phi and near > 0.0:
            return near - rounding, rotation * wp.cw_mul(w_near / near, s)
        return phi, n
    move = out_of_rounded_box(p, half, thickness + rounding, thickness) - p
    length = wp.length(move)
    if length < 1.0e-6 and near > 0.0:
        # x on its capsule to within a micrometre: that capsule's own (phi, n). move / length there is float32's
        # rounding of x (~3e-8 m at 0.5 m), not a direction, and a move of 0 is a contact at the thickness (the
        # box's own phi, centimetres, turned the position-based friction pass off for that substep)
        return near - rounding, rotation * wp.cw_mul(w_near / near, s)
    return thickness - length, rotation * (move / length)


@wp.func
def mesh_contact(x: wp.vec3, mesh: wp.uint64, thickness: float, reach: float):
    # nearest surface point q within thickness + reach, sign s by its face normal (< 0 inside);
    # q inside a face: n = the face normal, phi = (x - q).n (exact even when x - q is a rounding
    # error away from q); on an edge or vertex: n = s (x - q)/|x - q|, phi = s |x - q|; none: phi = inf
    query = wp.mesh_query_point_sign_normal(mesh, x, thickness + reach)
    if not query.result:
        return 1.0e30, wp.vec3(0.0, 1.0, 0.0)
    q = wp.mesh_eval_position(mesh, query.face, query.u, query.v)
    d = x - q
    w = 1.0 - query.u - query.v
    length = wp.length(d)
    if (query.u > 1.0e-5 and query.v > 1.0e-5 and w > 1.0e-5) or length < 1.0e-9:
        n = wp.mesh_eval_face_normal(mesh, query.face)
        return wp.dot(d, n), n
    return query.sign * length, (query.sign / length) * d


@wp.func(inline=True)
def posed_mesh_contact(
    x: wp.vec3,
    center: wp.vec3,
    rotation: wp.mat33,
    half: wp.vec3,
    rest_center: wp.vec3,
    mesh: wp.uint64,
    thickness: float,
    reach: float,
    moving: int,
):
    # a mesh moved rigidly (y = center + R (y0 - rest_center)): x taken into the mesh's own frame,
    # rejected outside its box (half: half size grown by the thickness), queried there, n turned
    # back; a static mesh is queried at x itself (no rounding of x through the frame change)
    if moving == 0:
        d = x - center
        if wp.abs(d[0]) > half[0] or wp.abs(d[1]) > half[1] or wp.abs(d[2]) > half[2]:
            return NOT_NEAR, wp.vec3(0.0)
        return mesh_contact(x, mesh, thickness, reach)
    p = wp.transpose(rotation) * (x - center)
    if wp.abs(p[0]) > half[0] or wp.abs(p[1]) > half[1] or wp.abs(p[2]) > half[2]:
        return NOT_NEAR, wp.vec3(0.0)
    phi, n = mesh_contact(rest_center + p, mesh, thickness, reach)
    return phi, rotation * n


@wp.func
def segment_parameter(p: wp.vec3, a: wp.vec3, b: wp.vec3):
    # t in [0, 1] of the point a + t (b - a) nearest p
    ab = b - a
    l2 = wp.dot(ab, ab)
    if l2 <= 0.0:
        return 0.0
    return wp.clamp(wp.dot(p - a, ab) / l2, 0.0, 1.0)


@wp.func
def nearest_crease(bvh: wp.uint64, a: wp.array(dtype=wp.vec3), b: wp.array(dtype=wp.vec3), y: wp.vec3, radius: float):
    # (distance, y less its nearest point) of the nearest crease segment within `radius` of y (1e30: none)
    best = float(1.0e30)
    w_best = wp.vec3(0.0)
    query = wp.bvh_query_aabb(bvh, y - wp.vec3(radius), y + wp.vec3(radius))
    e = int(0)
    while wp.bvh_query_next(query, e):
        w = y - (a[e] + segment_parameter(y, a[e], b[e]) * (b[e] - a[e]))
        d = wp.length(w)
        if d < best:
            best = d
            w_best = w
    return best, w_best


@wp.func
def out_of_creases(bvh: wp.uint64, a: wp.array(dtype=wp.vec3), b: wp.array(dtype=wp.vec3), y: wp.vec3, radius: float):
    # y pushed out of the capsule of `radius` of each crease segment whose box meets y's (one after another)
    query = wp.bvh_query_aabb(bvh, y - wp.vec3(radius), y + wp.vec3(radius))
    e = int(0)
    while wp.bvh_query_next(query, e):
        w = y - (a[e] + segment_parameter(y, a[e], b[e]) * (b[e] - a[e]))
        d = wp.length(w)
        if d < radius and d > 0.0:
            y = y + (radius - d) / d * w
    return y


@wp.func
def rounded_mesh_contact(colliders: wp.array(dtype=Collider), k: int, x: wp.vec3, phi: float, n: wp.vec3):
    # a mesh's (phi, n) with capsules of radius R = thickness + rounding about its convex creases (as
    # rounded_box_contact): where no capsule holds x, the mesh's own (or the nearer capsule's distance
    # where that is smaller and x is free); where one does, three rounds of a push out of each capsule
    # near it and then out of the surface's shell, in the mesh's own frame, and phi = thickness - |move|
    rounding = colliders[k].rounding
    thickness = colliders[k].thickness
    if rounding <= 0.0 or colliders[k].crease_bvh == wp.uint64(0) or (phi <= 0.0 and thickness > 0.0):
        return phi, n
    rotation = wp.identity(n=3, dtype=float)
    y0 = x
    if colliders[k].moving != 0:
        rotation = colliders[k].rotation
        y0 = colliders[k].rest_center + wp.transpose(rotation) * (x - colliders[k].a)
    radius = thickness + rounding
    bvh = colliders[k].crease_bvh
    ca = colliders[k].crease_a
    cb = colliders[k].crease_b
    d, w = nearest_crease(bvh, ca, cb, y0, radius)
    if d >= radius:
        if phi >= thickness and d - rounding < phi and d < 1.0e29:
            return d - rounding, rotation * (w / d)
        return phi, n
    mesh = colliders[k].mesh
    reach = wp.max(colliders[k].radius, rounding)
    y = y0
    for _round in range(3):
        y = out_of_creases(bvh, ca, cb, y, radius)
        ph, nn = mesh_contact(y, mesh, thickness, reach)
        if ph < thickness:
            y = y + (thickness - ph) * nn
    move = y - y0
    length = wp.length(move)
    if length == 0.0:
        return phi, n
    return thickness - length, rotation * (move / length)


@wp.func
def half_size(c: Collider):
    # half extents of the collider's axis-aligned bounding box, grown by its thickness
    if c.kind == SPHERE:
        return wp.vec3(c.radius + c.thickness)
    if c.kind == CAPSULE:
        d = 0.5 * (c.b - c.a)
        return wp.vec3(wp.abs(d[0]), wp.abs(d[1]), wp.abs(d[2])) + wp.vec3(c.radius + c.thickness)
    r = c.rotation  # a box's or a mesh's
    h = c.b
    grow = c.thickness + c.rounding
    if c.kind == MESH:  # b: a mesh's half size, already grown by its thickness and reach
        grow = 0.0
    return wp.vec3(
        wp.abs(r[0, 0]) * h[0] + wp.abs(r[0, 1]) * h[1] + wp.abs(r[0, 2]) * h[2],
        wp.abs(r[1, 0]) * h[0] + wp.abs(r[1, 1]) * h[1] + wp.abs(r[1, 2]) * h[2],
        wp.abs(r[2, 0]) * h[0] + wp.abs(r[2, 1]) * h[1] + wp.abs(r[2, 2]) * h[2],
    ) + wp.vec3(grow)


@wp.kernel
def eval_collider_bounds(colliders: wp.array(dtype=Collider), plane_count: int, box: wp.array(dtype=wp.vec3)):
    # box = [min, max] around every non-plane collider grown by its thickness (empty: min > max),
    # with a margin so that float32 rounding never rejects a contact
    lo = wp.vec3(1.0e30)
    hi = wp.vec3(-1.0e30)
    for k in range(plane_count, colliders.shape[0]):
        c = colliders[k]
        e = half_size(c) * (1.0 + 1.0e-5) + wp.vec3(1.0e-6 + 1.0e-6 * wp.length(c.bound_center))
        lo = wp.min(lo, c.bound_center - e)
        hi = wp.max(hi, c.bound_center + e)
    box[0] = lo
    box[1] = hi


@wp.func(inline=True)
def respond_velocity(x: wp.vec3, v: wp.vec3, vc: wp.vec3, depth: float, n: wp.vec3, mu: float, dt: float):
    # x += depth n ; (v - v_c).n >= 0 ; |v_t - v_c,t| -= mu dv_n (>= 0) ; x += dt dv_t
    vr = v - vc
    vn = wp.dot(vr, n)
    dvn = wp.max(0.0, -vn)
    vt = vr - vn * n
    lt2 = wp.dot(vt, vt)
    s = float(0.0)
    if mu * dvn * mu * dvn >= lt2:  # sticks: dv_t = -v_t (exactly)
        s = 1.0
    else:  # slides: |dv_t| = mu dv_n
        s = mu * dvn / wp.sqrt(lt2)
    dvt = -s * vt
    return x + depth * n + dt * dvt, vc + (vn + dvn) * n + vt + dvt


@wp.func(inline=True)
def in_box(x: wp.vec3, box: wp.array(dtype=wp.vec3)):
    # x inside the box around every non-plane collider (empty box: min > max)
    lo = box[0]
    hi = box[1]
    return x[0] >= lo[0] and x[1] >= lo[1] and x[2] >= lo[2] and x[0] <= hi[0] and x[1] <= hi[1] and x[2] <= hi[2]


@wp.func(inline=True)
def shape_contact(colliders: wp.array(dtype=Collider), k: int, x: wp.vec3, band: float):
    # (phi, n) of non-plane collider k, reading only the fields its kind needs (no record copy);
    # phi = NOT_NEAR where a cheap test shows phi > band (squared distances, the box's slabs)
    kind = colliders[k].kind
    reach = band
    if kind == SPHERE:
        r = colliders[k].radius
        d = x - colliders[k].a
        if wp.dot(d, d) >= (r + reach) * (r + reach):
            return NOT_NEAR, wp.vec3(0.0)
        return sphere_contact(x, colliders[k].a, r)
    if kind == CAPSULE:
        r = colliders[k].radius
        a = colliders[k].a
        ab = colliders[k].b - a
        t = wp.clamp(wp.dot(x - a, ab) / wp.max(wp.dot(ab, ab), 1.0e-20), 0.0, 1.0)
        d = x - (a + t * ab)
        if wp.dot(d, d) >= (r + reach) * (r + reach):
            return NOT_NEAR, wp.vec3(0.0)
        return sphere_contact(x, a + t * ab, r)
    c = colliders[k].a
    h = colliders[k].b
    rotation = colliders[k].rotation
    if kind == MESH:  # its box (b: half size grown by the thickness and rounding), then the BVH
        phi, n = posed_mesh_contact(
            x,
            c,
            rotation,
            h,
            colliders[k].rest_center,
            colliders[k].mesh,
            colliders[k].thickness,
            wp.max(colliders[k].radius, colliders[k].rounding),  # its reach, or its creases' capsules' if larger
            colliders[k].moving,
        )
        if phi == NOT_NEAR:
            return phi, n
        return rounded_mesh_contact(colliders, k, x, phi, n)
    p = wp.transpose(rotation) * (x - c)
    rounding = colliders[k].rounding
    reach = reach + rounding
    if wp.abs(p[0]) >= h[0] + reach or wp.abs(p[1]) >= h[1] + reach or wp.abs(p[2]) >= h[2] + reach:
        return NOT_NEAR, wp.vec3(0.0)
    return rounded_box_contact(x, c, rotation, h, rounding, colliders[k].thickness)


@wp.func(inline=True)
def contact_band(colliders: wp.array(dtype=Collider), k: int):
    # the largest phi the responses need exactly: the thickness, and 1e-5 m more so that a particle
    # resting at the thickness, to rounding, is still found (the position-based friction pass)
    return colliders[k].thickness + 1.0e-5


@wp.func
def collider_contact(colliders: wp.array(dtype=Collider), k: int, x: wp.vec3, band: float):
    # (phi, n) of collider k of any kind; NOT_NEAR where phi > band is sure (see shape_contact)
    if colliders[k].kind == PLANE:
        return plane_contact(x, colliders[k].a, colliders[k].b)
    return shape_contact(colliders, k, x, band)


@wp.func
def deformed_surface_velocity(colliders: wp.array(dtype=Collider), k: int, y: wp.vec3):
    # a deforming mesh's velocity at the surface point nearest y: its vertices' velocities
    # interpolated barycentrically there (0 where no surface is within the contact's reach)
    reach = colliders[k].thickness + wp.max(colliders[k].radius, colliders[k].rounding) + 1.0e-3
    query = wp.mesh_query_point_no_sign(colliders[k].mesh, y, reach)
    if not query.result:
        return wp.vec3(0.0)
    return wp.mesh_eval_velocity(colliders[k].mesh, query.face, query.u, query.v)


@wp.func(inline=True)
def surface_velocity(colliders: wp.array(dtype=Collider), k: int, y: wp.vec3):
    # v_c(y) = u + w x (y - o) of collider k (0 for a static one; a deforming mesh's from its vertices)
    if colliders[k].moving == 0:
        if colliders[k].deforming != 0:
            return deformed_surface_velocity(colliders, k, y)
        return wp.vec3(0.0)
    return colliders[k].velocity + wp.cross(colliders[k].omega, y - colliders[k].origin)


@wp.func
def deformed_surface_motion(colliders: wp.array(dtype=Collider), k: int, y: wp.vec3):
    # a deforming mesh's mean velocity over the (sub)step at the surface point nearest y: its vertices'
    # (motion) interpolated barycentrically there, as wp.mesh_eval_velocity does (0: no surface within reach)
    reach = colliders[k].thickness + wp.max(colliders[k].radius, colliders[k].rounding) + 1.0e-3
    mesh = colliders[k].mesh
    query = wp.mesh_query_point_no_sign(mesh, y, reach)
    if not query.result:
        return wp.vec3(0.0)
    motion = colliders[k].motion
    a = motion[wp.mesh_get_index(mesh, 3 * query.face)]
    b = motion[wp.mesh_get_index(mesh, 3 * query.face + 1)]
    c = motion[wp.mesh_get_index(mesh, 3 * query.face + 2)]
    return a * query.u + b * query.v + c * (1.0 - query.u - query.v)


@wp.func
def swept_mesh_contact(
    colliders: wp.array(dtype=Collider), k: int, x: wp.vec3, r: wp.vec3, h: float, phi: float, n: wp.vec3
):
    # mesh collider k's (phi, n) at x (shape_contact's), its side told by the particle's path: r its
    # displacement over the (sub)step of h seconds that ends at x, s = r - h v_c relative to the surface,
    # so it started at y = x - s on the surface as posed now. Where the ray y -> x first enters a face
    # (s.n_f < 0), the particle crossed the surface there: its contact is the crossing point c lifted
    # by the thickness, x -> c + thickness n_f (phi = thickness - |c + thickness n_f - x|, n along that
    # move: the response stops it where it crossed, as a continuous check would), not the nearest
    # point's, which past a thin limb's medial axis lies on its far side. Cast only where the nearest
    # point can be wrong: in contact and moving along its n (entering through a face moves against its
    # normal), or out of contact with |s| > phi (it may have gone through)
    thickness = colliders[k].thickness
    reach = wp.max(colliders[k].radius, colliders[k].rounding)
    rotation = colliders[k].rotation
    moving = colliders[k].moving
    local = x - colliders[k].a
    if moving != 0:
        local = wp.transpose(rotation) * local
    half = colliders[k].b
    if wp.abs(local[0]) > half[0] or wp.abs(local[1]) > half[1] or wp.abs(local[2]) > half[2]:
        return phi, n  # outside its box (grown by thickness and reach): no surface it could have crossed
    contact = phi < thickness
    far = wp.min(phi, thickness + reach)  # x's distance to the surface, or more (none within the query's reach)
    vc = wp.vec3(0.0)
    if moving != 0:
        vc = colliders[k].velocity + wp.cross(colliders[k].omega, x - colliders[k].origin)
    elif colliders[k].deforming != 0:
        if contact or wp.length(r) + h * colliders[k].speed > far:  # else |s| <= far: not cast
            vc = deformed_surface_motion(colliders, k, x)
    s = r - h * vc
    length = wp.length(s)
    if length == 0.0:
        return phi, n
    if contact:
        if wp.dot(s, n) <= 0.0:
            return phi, n
    elif length <= far:
        return phi, n
    end = x
    d = s
    if moving != 0:  # the mesh's own frame (its BVH's)
        end = colliders[k].rest_center + local
        d = wp.transpose(rotation) * s
    d = d / length
    query = wp.mesh_query_ray(colliders[k].mesh, end - length * d, d, length)
    if not query.result:
        return phi, n
    if wp.dot(d, query.normal) >= 0.0:  # it leaves a face first: it started inside (the nearest point stands)
        return phi, n
    move = thickness * query.normal - (length - query.t) * d  # from x to the crossing point lifted
    if moving != 0:
        move = rotation * move
    distance = wp.length(move)
    if distance == 0.0:
        return phi, n
    return thickness - distance, move / distance


@wp.func(inline=True)
def velocity_response(
    colliders: wp.array(dtype=Collider), k: int, x: wp.vec3, v: wp.vec3, phi: float, n: wp.vec3, dt: float
):
    # respond_velocity against collider k where it is penetrated (phi < thickness); hit = 1 then
    depth = colliders[k].thickness - phi
    if depth > 0.0:
        x, v = respond_velocity(x, v, surface_velocity(colliders, k, x), depth, n, colliders[k].mu, dt)
        return x, v, 1
    return x, v, 0


@wp.kernel
def collide_velocity(
    x: wp.array(dtype=wp.vec3),
    v: wp.array(dtype=wp.vec3),
    inv_mass: wp.array(dtype=float),
    dt: float,
    position_weight: float,
    displacement: wp.array(dtype=wp.vec3),
    has_displacement: int,
    colliders: wp.array(dtype=Collider),
    box: wp.array(dtype=wp.vec3),
    plane_count: int,
):
    # after a force-based step: every collider, respond_velocity (the tangential change moves x by
    # position_weight dt dv_t: 1 where x += dt v_new, 1/2 for RK); Verlet's d = v dt. Planes first
    # (one half-space test each), the other colliders when x is in the box around them; x, v
    # written only on contact, and never for a pinned particle (pins win)
    i = wp.tid()
    xi = x[i]
    vi = v[i]
    h = position_weight * dt
    hit = int(0)
    for k in range(plane_count):
        phi, n = plane_contact(xi, colliders[k].a, colliders[k].b)
        xi, vi, got = velocity_response(colliders, k, xi, vi, phi, n, h)
        hit = hit + got
    if in_box(xi, box):
        for k in range(plane_count, colliders.shape[0]):
            phi, n = shape_contact(colliders, k, xi, contact_band(colliders, k))
            if colliders[k].kind == MESH:  # the side it came from (its step's displacement dt v)
                phi, n = swept_mesh_contact(colliders, k, xi, dt * vi, dt, phi, n)
            xi, vi, got = velocity_response(colliders, k, xi, vi, phi, n, h)
            hit = hit + got
    if hit != 0:
        if inv_mass[i] != 0.0:
            x[i] = xi
            v[i] = vi
            if has_displacement != 0:
                displacement[i] = dt * vi


@wp.func(inline=True)
def respond_displacement(dp: wp.vec3, phi: float, n: wp.vec3, thickness: float):
    # dp += depth n (p = x + dp out of the collider); returns the normal correction
    depth = thickness - phi
    if depth <= 0.0:
        return dp, 0.0
    return dp + depth * n, depth


@wp.func(inline=True)
def friction_displacement(dp: wp.vec3, motion: wp.vec3, n: wp.vec3, normal_correction: float, mu: float):
    # cancel the tangential dp - motion (the collider's) up to mu times the normal correction; returns the
    # normal correction left unspent (Coulomb: |tangential correction| <= mu x normal correction, summed over
    # the substep's friction passes)
    r = dp - motion
    dpt = r - wp.dot(r, n) * n
    lt = wp.length(dpt)
    if lt == 0.0 or mu <= 0.0:
        return dp, normal_correction
    used = wp.min(mu * normal_correction, lt)
    return dp - (used / lt) * dpt, wp.max(normal_correction - used / mu, 0.0)


@wp.func(inline=True)
def displacement_response(
    colliders: wp.array(dtype=Collider),
    k: int,
    p: wp.vec3,
    d: wp.vec3,
    nc: float,
    phi: float,
    n: wp.vec3,
    friction: int,
    motion_time: float,
):
    # the solver pass (friction = 0): d out of collider k, nc += the normal correction; the
    # friction pass: d's tangential motion relative to the collider's over the substep reduced;
    # hit = 1 where d changed
    if friction == 0:
        d, dn = respond_displacement(d, phi, n, colliders[k].thickness)
        return d, nc + dn, int(dn > 0.0)
    if phi <= colliders[k].thickness + 1.0e-6:
        d, nc = friction_displacement(d, motion_time * surface_velocity(colliders, k, p), n, nc, colliders[k].mu)
        return d, nc, 1
    return d, nc, 0


@wp.kernel
def collide_displacement(
    friction: int,
    x: wp.array(dtype=wp.vec3),
    dp: wp.array(dtype=wp.vec3),
    inv_mass: wp.array(dtype=float),
    normal_correction: wp.array(dtype=float),
    colliders: wp.array(dtype=Collider),
    box: wp.array(dtype=wp.vec3),
    plane_count: int,
    step_dt: wp.array(dtype=wp.float64),
    substep: wp.array(dtype=int),
):
    # position-based solvers: p = x + dp out of every collider (friction = 0), or the friction pass
    # after the iterations (friction = 1; the collider moves v_c h over the substep h = dt / S)
    i = wp.tid()
    nc = normal_correction[i]
    if friction != 0 and nc == 0.0:
        return
    if inv_mass[i] == 0.0:
        return
    motion_time = float(step_dt[0] / wp.float64(substep[1]))
    xi = x[i]
    d = dp[i]
    hit = int(0)
    for k in range(plane_count):
        p = xi + d
        phi, n = plane_contact(p, colliders[k].a, colliders[k].b)
        d, nc, got = displacement_response(colliders, k, p, d, nc, phi, n, friction, motion_time)
        hit = hit + got
    if in_box(xi + d, box):
        for k in range(plane_count, colliders.shape[0]):
            p = xi + d
            phi, n = shape_contact(colliders, k, p, contact_band(colliders, k))
            if colliders[k].kind == MESH:  # the side it came from (its substep's displacement d)
                phi, n = swept_mesh_contact(colliders, k, p, d, motion_time, phi, n)
            d, nc, got = displacement_response(colliders, k, p, d, nc, phi, n, friction, motion_time)
            hit = hit + got
    if hit != 0:  # written only where a collider moved d (a small correction on a large nc counts too)
        dp[i] = d
        normal_correction[i] = nc


@wp.func
def move_point(y: wp.vec3, center: wp.vec3d, offset: wp.vec3d, axis: wp.vec3d, theta: wp.float64):
    # c + d + R(axis, theta)(y - c), in float64, rounded once
    return wp.vec3(center + offset + rotate_axis_angle(axis, theta, wp.vec3d(y) - center))


@wp.func
def rotation_matrix(axis: wp.vec3d, theta: wp.float64):
    # R = cos I + sin [a]x + (1 - cos) a a^T
    c = wp.cos(theta)
    s = wp.sin(theta)
    one = wp.float64(1.0)
    a = wp.vec3(axis)
    return wp.mat33(float(c) * wp.identity(n=3, dtype=float) + float(s) * wp.skew(a) + float(one - c) * wp.outer(a, a))


@wp.kernel
def begin_collider_step(substep: wp.array(dtype=int)):
    # substep = (k, S): S = the substeps the last step counted (kept if it counted none), k = 0
    if substep[0] > 0:
        substep[1] = substep[0]
    substep[1] = wp.max(substep[1], 1)
    substep[0] = 0


@wp.kernel
def next_collider_substep(substep: wp.array(dtype=int)):
    # k += 1 after a position-based substep's friction pass
    substep[0] = substep[0] + 1


@wp.func
def posed_collider(
    r: Collider, c: wp.vec3d, d: wp.vec3d, dd: wp.vec3d, axis: wp.vec3d, theta: wp.float64, theta_dot: wp.float64
):
    # the rest record r moved by y -> c + d + R(axis, theta)(y - c), with v_c(y) = d' + theta' axis x (y - c - d)
    m = r
    rot = rotation_matrix(axis, theta)
    if r.kind == PLANE:
        m.a = move_point(r.a, c, d, axis, theta)
        m.b = rot * r.b
    else:
        m.a = move_point(r.a, c, d, axis, theta)
        if r.kind == CAPSULE:
            m.b = move_point(r.b, c, d, axis, theta)
    m.rotation = rot * r.rotation
    m.bound_center = move_point(r.bound_center, c, d, axis, theta)
    m.origin = wp.vec3(c + d)
    m.velocity = wp.vec3(dd)
    m.omega = float(theta_dot) * wp.vec3(axis)
    m.moving = 1
    return m


@wp.func
def pose_time(
    time: wp.array(dtype=wp.float64),
    offset: wp.float64,
    step_dt: wp.array(dtype=wp.float64),
    substep: wp.array(dtype=int),
    use_substep: int,
):
    # the time a moving collider is posed at: the clock + offset, and where substeps pose it, the end of
    # the coming substep (substep[0] of substep[1]) within the step of length step_dt
    t = time[0] + offset
    if use_substep != 0:
        t = t + step_dt[0] * wp.float64(wp.min(substep[0] + 1, substep[1])) / wp.float64(substep[1])
    return t


@wp.func
def pose_start_time(
    time: wp.array(dtype=wp.float64),
    offset: wp.float64,
    step_dt: wp.array(dtype=wp.float64),
    substep: wp.array(dtype=int),
    use_substep: int,
):
    # the start of the (sub)step whose end pose_time gives: the clock (a pose at an offset from it), or
    # where substeps pose, the coming substep's start
    t = time[0]
    if use_substep != 0:
        t = t + step_dt[0] * wp.float64(wp.min(substep[0] + 1, substep[1]) - 1) / wp.float64(substep[1])
    return t


@wp.func
def turn_point(y: wp.vec3, center: wp.vec3d, offset: wp.vec3d, start: wp.quatd, axis: wp.vec3d, theta: wp.float64):
    # c + d + R(axis, theta) R0 (y - c), R0 the rotation of the quaternion `start`, in float64, rounded once
    return wp.vec3(center + offset + rotate_axis_angle(axis, theta, wp.quat_rotate(start, wp.vec3d(y) - center)))


@wp.kernel
def eval_collider_pose(
    time: wp.array(dtype=wp.float64),
    offset: wp.float64,
    step_dt: wp.array(dtype=wp.float64),
    substep: wp.array(dtype=int),
    use_substep: int,
    index: int,
    rest: wp.array(dtype=Collider),
    rigid: int,
    center: wp.vec3d,
    axis: wp.vec3d,
    velocity: wp.vec3d,
    motion: wp.vec4d,
    times: wp.array(dtype=wp.float64),
    values: wp.array(dtype=wp.vec3d),
    tangents: wp.array(dtype=wp.vec3d),
    cubic: int,
    colliders: wp.array(dtype=Collider),
):
    # collider `index` at t = time + offset (+ dt min(k + 1, S) / S, the end of substep k of S, with
    # use_substep): rigid y -> c + u t + R(axis, theta(t))(y - c), theta = omega t + A sin(2 pi f t + phi),
    # motion = (omega, A, f, phi); or keyframed translation y -> y + d(t); v_c(y) = d' + theta' axis x (y - c - d)
    t = pose_time(time, offset, step_dt, substep, use_substep)
    zero = wp.float64(0.0)
    d = wp.vec3d(zero, zero, zero)
    dd = wp.vec3d(zero, zero, zero)
    c = wp.vec3d(zero, zero, zero)
    theta = zero
    theta_dot = zero
    if rigid != 0:
        two_pi = wp.float64(6.283185307179586)
        phase = two_pi * motion[2] * t + motion[3]
        theta = motion[0] * t + motion[1] * wp.sin(phase)
        theta_dot = motion[0] + motion[1] * two_pi * motion[2] * wp.cos(phase)
        c = center
        d = velocity * t
        dd = velocity
    else:
        d, dd = track_keyframes(t, times, values, tangents, cubic, 0, 1)
    colliders[index] = posed_collider(rest[index], c, d, dd, axis, theta, theta_dot)


@wp.kernel
def eval_collider_driven_pose(
    time: wp.array(dtype=wp.float64),
    offset: wp.float64,
    step_dt: wp.array(dtype=wp.float64),
    substep: wp.array(dtype=int),
    use_substep: int,
    index: int,
    rest: wp.array(dtype=Collider),
    frame_times: wp.array(dtype=wp.float64),
    values: wp.array(dtype=wp.vec3d),
    tangents: wp.array(dtype=wp.vec3d),
    cubic: int,
    turn: wp.array(dtype=wp.vec4d),
    colliders: wp.array(dtype=Collider),
):
    # a collider posed from the host each frame: its offset d(t) keyframed over the frame's keys
    # (frame_times, values: as a ColliderTrack's keyframes), and its turn about its own centre c,
    # R(t) = R(axis, s angle) R0 with s = (t - t0) / (t1 - t0), turn = (R0 as x y z w, (axis, angle));
    # y -> c + d + R(t)(y - c), v_c(y) = d' + (angle / (t1 - t0)) axis x (y - c - d)
    t = pose_time(time, offset, step_dt, substep, use_substep)
    d, dd = track_keyframes(t, frame_times, values, tangents, cubic, 0, 1)
    r = rest[index]
    q = turn[0]
    a = turn[1]
    zero = wp.float64(0.0)
    axis = wp.vec3d(a[0], a[1], a[2])
    if a[3] == zero and q[0] == zero and q[1] == zero and q[2] == zero:
        # not turned: a translation, the same arithmetic as eval_collider_pose's keyframes
        z_axis = wp.vec3d(zero, zero, wp.float64(1.0))
        colliders[index] = posed_collider(r, wp.vec3d(zero, zero, zero), d, dd, z_axis, zero, zero)
        return
    h = frame_times[2] - frame_times[1]
    theta = (t - frame_times[1]) / h * a[3]
    start = wp.quatd(q[0], q[1], q[2], q[3])
    c = wp.vec3d(r.bound_center)
    m = r
    rot = rotation_matrix(axis, theta) * wp.quat_to_matrix(wp.quat(float(q[0]), float(q[1]), float(q[2]), float(q[3])))
    m.a = turn_point(r.a, c, d, start, axis, theta)
    if r.kind == PLANE:
        m.b = rot * r.b
    elif r.kind == CAPSULE:
        m.b = turn_point(r.b, c, d, start, axis, theta)
    m.rotation = rot * r.rotation
    m.bound_center = turn_point(r.bound_center, c, d, start, axis, theta)
    m.origin = wp.vec3(c + d)
    m.velocity = wp.vec3(dd)
    m.omega = float(a[3] / h) * wp.vec3(axis)
    m.moving = 1
    colliders[index] = m


@wp.kernel
def store_step(value: wp.float64, out: wp.array(dtype=wp.float64)):
    # out = dt of the step just taken (the next step poses the moving colliders with it)
    out[0] = value


@wp.kernel
def eval_mesh_points(
    time: wp.array(dtype=wp.float64),
    offset: wp.float64,
    step_dt: wp.array(dtype=wp.float64),
    substep: wp.array(dtype=int),
    use_substep: int,
    times: wp.array(dtype=wp.float64),
    values: wp.array(dtype=wp.vec3d),
    tangents: wp.array(dtype=wp.vec3d),
    cubic: int,
    points: wp.array(dtype=wp.vec3),
    velocities: wp.array(dtype=wp.vec3),
    motion: wp.array(dtype=wp.vec3),
    lo: wp.array(dtype=wp.vec3),
    hi: wp.array(dtype=wp.vec3),
    fastest: wp.array(dtype=float),
):
    # a deforming mesh's vertex j at t (as eval_collider_pose's t): its keys interpolated in float64
    # and rounded once, its velocity dp/dt, and its mean velocity over the (sub)step ending at t,
    # (p(t) - p(t0)) / (t - t0) (dp/dt where t0 = t: swept_mesh_contact's surface motion; a key's end
    # within the step moved the surface though dp/dt after it is 0); lo[0], hi[0] = min, max over the
    # vertices, fastest[0] the largest mean velocity (reset before; an array each, so that Warp's
    # deterministic mode reduces each with one operation)
    t = pose_time(time, offset, step_dt, substep, use_substep)
    t0 = pose_start_time(time, offset, step_dt, substep, use_substep)
    j = wp.tid()
    p, dp = track_keyframes(t, times, values, tangents, cubic, j, points.shape[0])
    mean = dp
    if t0 < t:
        p0, _dp0 = track_keyframes(t0, times, values, tangents, cubic, j, points.shape[0])
        mean = (p - p0) / (t - t0)
    q = wp.vec3(p)
    points[j] = q
    velocities[j] = wp.vec3(dp)
    motion[j] = wp.vec3(mean)
    wp.atomic_min(lo, 0, q)
    wp.atomic_max(hi, 0, q)
    wp.atomic_max(fastest, 0, wp.length(motion[j]))


@wp.kernel
def reset_bounds(lo: wp.array(dtype=wp.vec3), hi: wp.array(dtype=wp.vec3), fastest: wp.array(dtype=float)):
    lo[0] = wp.vec3(1.0e30)
    hi[0] = wp.vec3(-1.0e30)
    fastest[0] = 0.0


@wp.kernel
def gather_creases(
    points: wp.array(dtype=wp.vec3),
    ends: wp.array(dtype=wp.vec2i),
    a: wp.array(dtype=wp.vec3),
    b: wp.array(dtype=wp.vec3),
    lo: wp.array(dtype=wp.vec3),
    hi: wp.array(dtype=wp.vec3),
):
    # a deforming mesh's crease segments (their ends' vertices) and their boxes, for the crease BVH's refit
    e = wp.tid()
    p = points[ends[e][0]]
    q = points[ends[e][1]]
    a[e] = p
    b[e] = q
    lo[e] = wp.min(p, q)
    hi[e] = wp.max(p, q)


@wp.kernel
def eval_deformed_record(
    index: int,
    rest: wp.array(dtype=Collider),
    bounds_lo: wp.array(dtype=wp.vec3),
    bounds_hi: wp.array(dtype=wp.vec3),
    fastest: wp.array(dtype=float),
    colliders: wp.array(dtype=Collider),
):
    # a deforming mesh's record: its box (the cheap rejection) around its points now, grown by its
    # thickness, its reach and its creases' rounding, with _mesh_half's float32 margin; its fastest
    # vertex's speed
    lo = bounds_lo[0]
    hi = bounds_hi[0]
    r = rest[index]
    half = 0.5 * (hi - lo) + wp.vec3(r.thickness + r.radius + r.rounding)
    m = colliders[index]
    m.a = 0.5 * (lo + hi)
    m.bound_center = m.a
    m.b = half * (1.0 + 1.0e-5) + wp.vec3(1.0e-6)
    m.rounding = r.rounding
    m.speed = fastest[0]
    colliders[index] = m
