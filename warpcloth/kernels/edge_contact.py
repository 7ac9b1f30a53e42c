"""Collider edges and corners against the cloth's edges and triangles: box and triangle-mesh
colliders have edges that can pass between cloth vertices (a table's top edge under a tablecloth),
which the per-vertex contacts of :mod:`warpcloth.kernels.collide` do not see.

After the per-vertex response of a step, for each collider feature near the cloth:

* a collider edge (p, q) and a cloth edge (a, b), closest points P = a + s (b - a) and
  Q = p + t (q - p), gap d = |P - Q|: where d < thickness, P is moved out to the thickness along
  n = (P - Q) / d, its approaching normal velocity relative to the collider removed. Where P lies
  behind the edge's outward bisector o ((P - Q) . o < 0), the collider's own surface holds it, by its
  signed distance and normal at P (P in the collider, where the cloth edge cuts across its edge, goes
  out through the nearest face);
* a collider corner c and a cloth triangle (a, b, c), closest point P = sum w_i x_i: likewise.

The point P moves by the least change of its vertices (weights W_i, inverse masses w_i): dx_i =
W_i w_i / sum W^2 w delta n, the same for the velocity; pinned vertices take none of it. A contact
whose closest cloth point is a cloth vertex is left to that vertex's own collider contact (an
interior parameter: 1e-4 < s < 1 - 1e-4, every triangle weight > 1e-4). Changes are averaged
over the contacts of a vertex (Jacobi: :func:`apply_edge_contacts`).

Box features come from the posed record (12 edges, 8 corners, outward directions the edge's
bisector and the corner's diagonal). A mesh's features (its unique edges, its vertices, their
outward directions the mean of their faces' normals) are stored in the mesh's own frame with a
static ``wp.Bvh`` each; the cloth feature is taken into that frame, y0 = rest_center + R^T (y - a).
"""

import warp as wp

from warpcloth.kernels.collide import BOX, MESH, Collider, box_contact, mesh_contact, surface_velocity
from warpcloth.kernels.self_contact import boxes_overlap, closest_point_triangle, closest_points_edge_edge

wp.set_module_options({"enable_backward": False})

#: over-relaxation of the averaged corrections (a vertex between several contacts converges slowly otherwise)
RELAX = wp.constant(1.0)
VELOCITY = wp.constant(1.0)
#: a contact's closest cloth point is interior beyond this parameter (else the vertex's own contact holds it)
INTERIOR = wp.constant(1.0e-4)


@wp.struct
class MeshFeatures:
    """Every mesh collider's edges and vertices, in the mesh's own frame, with their BVHs."""

    edge_bvh: wp.array(dtype=wp.uint64)  # per collider record: the BVH of its edges (0: none)
    edge_offset: wp.array(dtype=int)  # per collider record: its first edge in the arrays below
    edge_p: wp.array(dtype=wp.vec3)
    edge_q: wp.array(dtype=wp.vec3)
    edge_out: wp.array(dtype=wp.vec3)  # unit outward direction (the mean of the two faces' normals)
    vertex_bvh: wp.array(dtype=wp.uint64)
    vertex_offset: wp.array(dtype=int)
    vertex: wp.array(dtype=wp.vec3)
    vertex_out: wp.array(dtype=wp.vec3)


@wp.func
def box_corner_local(c: Collider, j: int):
    # corner j (bits: x, y, z sign) of a box in its own frame
    h = c.b
    p = -h
    if (j & 4) != 0:
        p[0] = h[0]
    if (j & 2) != 0:
        p[1] = h[1]
    if (j & 1) != 0:
        p[2] = h[2]
    return p


@wp.func
def signs(v: wp.vec3):
    # the componentwise sign of v (0 where 0): the sum of the unit face normals meeting at a box feature
    return wp.vec3(wp.sign(v[0]), wp.sign(v[1]), wp.sign(v[2]))


@wp.func
def box_edge_corners(j: int):
    # the corner indices of box edge j (4 along each axis)
    axis = j // 4
    m = j % 4
    bit = 4 >> axis  # the bit of the edge's own axis
    lo = int(0)
    k = int(0)
    for b in range(3):
        mask = 4 >> b
        if mask != bit:
            if ((m >> k) & 1) != 0:
                lo = lo | mask
            k += 1
    return lo, lo | bit


@wp.func
def face_planes_met(lo: wp.vec3, hi: wp.vec3, origin: wp.vec3, h: wp.vec3):
    # how many axes i of a box (centre ``origin``, half extents h, in its own frame) have a face plane
    # x_i = origin_i +- h_i within [lo_i, hi_i]: a box edge can meet the box [lo, hi] only where 2 do, a corner
    # only where 3 do (the planes are the same floats as the corners' coordinates, origin + box_corner_local)
    met = int(0)
    for i in range(3):
        p = origin[i] + h[i]
        q = origin[i] + (-h[i])
        if (lo[i] <= p and hi[i] >= p) or (lo[i] <= q and hi[i] >= q):
            met += 1
    return met


@wp.func
def push(
    i: int,
    weight: float,
    inv_mass: wp.array(dtype=float),
    lam: float,
    mu_v: wp.vec3,
    n: wp.vec3,
    dx: wp.array(dtype=wp.vec3),
    dv: wp.array(dtype=wp.vec3),
    count: wp.array(dtype=int),
):
    # vertex i's share of a contact: dx_i = W_i w_i lam n, dv_i = W_i w_i mu_v
    w = inv_mass[i]
    if w > 0.0 and weight != 0.0:
        wp.atomic_add(dx, i, (weight * w * lam) * n)
        wp.atomic_add(dv, i, (weight * w) * mu_v)
        wp.atomic_add(count, i, 1)


@wp.func
def contact_velocity_change(vp: wp.vec3, n: wp.vec3, mu: float, denom: float):
    # the contact point's velocity change (relative to the collider) over sum W^2 w: its approaching
    # normal part removed, its tangential part reduced by mu times that (Coulomb, at most to zero)
    vn = wp.dot(vp, n)
    dvn = wp.max(0.0, -vn)
    vt = vp - vn * n
    lt = wp.length(vt)
    change = dvn * n
    if lt > 0.0:
        change = change - (wp.min(mu * dvn, lt) / lt) * vt
    return change / denom


@wp.func
def behind(y: wp.vec3, d: float, reach: float, thickness: float, c: Collider, origin: wp.vec3):
    # a cloth point y behind a feature's outward direction o, d from it: (n, depth). Only near the feature
    # (d < reach + thickness, reach half the cloth feature's size: farther features leave it to the near
    # ones). There the collider's own surface holds it, by its signed distance and normal at y (in the
    # collider's frame): a point in a box or a mesh, where a cloth edge cuts across one of its edges, goes
    # out through the nearest face; one beside it, within the thickness, to the thickness
    if d >= reach + thickness:
        return wp.vec3(0.0), 0.0
    if c.kind == BOX:
        phi, n = box_contact(y, origin, wp.identity(n=3, dtype=float), c.b)
        return n, thickness - phi
    phi, n = mesh_contact(y, c.mesh, thickness, c.radius)
    return n, thickness - phi


@wp.func
def edge_response(
    a: wp.vec3,
    b: wp.vec3,
    va: wp.vec3,
    vb: wp.vec3,
    wa: float,
    wb: float,
    p: wp.vec3,
    q: wp.vec3,
    out: wp.vec3,
    thickness: float,
    c: Collider,
    origin: wp.vec3,
):
    # cloth edge (a, b) against collider edge (p, q) (outward o): (s, lam, mu_v, n) with lam, mu_v the
    # position and velocity multipliers of dx_i = W_i w_i lam n (0: no contact); velocities relative
    # to the collider. Behind o (diff . o < 0): see behind
    st = closest_points_edge_edge(a, b, p, q)
    s = st[0]
    if s <= INTERIOR or s >= 1.0 - INTERIOR:
        return s, 0.0, wp.vec3(0.0), wp.vec3(0.0)
    y = a + s * (b - a)
    diff = y - (p + st[1] * (q - p))
    d = wp.length(diff)
    n = out
    depth = float(0.0)
    if d > 1.0e-9 and wp.dot(diff, out) >= 0.0:
        n = diff / d
        depth = thickness - d
    else:
        n, depth = behind(y, d, 0.5 * wp.length(b - a), thickness, c, origin)
    if depth <= 0.0:
        return s, 0.0, wp.vec3(0.0), n
    denom = (1.0 - s) * (1.0 - s) * wa + s * s * wb
    if denom <= 0.0:
        return s, 0.0, wp.vec3(0.0), n
    return s, depth / denom, contact_velocity_change((1.0 - s) * va + s * vb, n, c.mu, denom), n


@wp.func
def corner_response(
    corner: wp.vec3,
    out: wp.vec3,
    a: wp.vec3,
    b: wp.vec3,
    c: wp.vec3,
    va: wp.vec3,
    vb: wp.vec3,
    vc: wp.vec3,
    wa: float,
    wb: float,
    wc: float,
    thickness: float,
    col: Collider,
    origin: wp.vec3,
):
    # collider corner (outward o) against cloth triangle (a, b, c): (W, lam, mu_v, n) as edge_response
    q, w = closest_point_triangle(corner, a, b, c)
    if w[0] <= INTERIOR or w[1] <= INTERIOR or w[2] <= INTERIOR:
        return w, 0.0, wp.vec3(0.0), wp.vec3(0.0)
    diff = q - corner
    d = wp.length(diff)
    n = out
    depth = float(0.0)
    if d > 1.0e-9 and wp.dot(diff, out) >= 0.0:
        n = diff / d
        depth = thickness - d
    else:
        reach = 0.5 * wp.max(wp.max(wp.length(b - a), wp.length(c - b)), wp.length(a - c))
        n, depth = behind(q, d, reach, thickness, col, origin)
    denom = w[0] * w[0] * wa + w[1] * w[1] * wb + w[2] * w[2] * wc
    if depth <= 0.0 or denom <= 0.0:
        return w, 0.0, wp.vec3(0.0), n
    return w, depth / denom, contact_velocity_change(w[0] * va + w[1] * vb + w[2] * vc, n, col.mu, denom), n


@wp.func(inline=True)
def collide_cloth_edge(
    e: int,
    edges: wp.array(dtype=wp.vec2i),
    x: wp.array(dtype=wp.vec3),
    v: wp.array(dtype=wp.vec3),
    inv_mass: wp.array(dtype=float),
    colliders: wp.array(dtype=Collider),
    first: int,
    meshes: MeshFeatures,
    dx: wp.array(dtype=wp.vec3),
    dv: wp.array(dtype=wp.vec3),
    count: wp.array(dtype=int),
):
    # cloth edge e against the edges of every box and mesh collider (records from ``first``)
    ia = edges[e][0]
    ib = edges[e][1]
    wa = inv_mass[ia]
    wb = inv_mass[ib]
    if wa + wb == 0.0:
        return
    a = x[ia]
    b = x[ib]
    for k in range(first, colliders.shape[0]):
        c = colliders[k]
        if (c.kind != BOX and c.kind != MESH) or c.moving != 0:
            continue
        # into the collider's own frame (a box: about its centre; a mesh: its rest frame)
        origin = c.a
        if c.kind == MESH:
            origin = c.rest_center
        la = origin + wp.transpose(c.rotation) * (a - c.a)
        lb = origin + wp.transpose(c.rotation) * (b - c.a)
        mid = 0.5 * (la + lb) - origin
        reach = 0.5 * wp.length(lb - la) + c.thickness
        h = c.b
        grow = wp.vec3(reach)  # as far as edge_response looks (behind: half the cloth edge + thickness)
        lo_e = wp.min(la, lb) - grow
        hi_e = wp.max(la, lb) + grow
        # most cloth edges are far from the box, or over one face only (a cloth on a table): no box edge's box
        # meets theirs, nothing more to do (before the velocities)
        if c.kind == BOX:
            if wp.abs(mid[0]) > h[0] + reach or wp.abs(mid[1]) > h[1] + reach or wp.abs(mid[2]) > h[2] + reach:
                continue
            if face_planes_met(lo_e, hi_e, origin, h) < 2:
                continue
        vc = surface_velocity(colliders, k, 0.5 * (a + b))
        lva = wp.transpose(c.rotation) * (v[ia] - vc)
        lvb = wp.transpose(c.rotation) * (v[ib] - vc)
        if c.kind == BOX:
            for j in range(12):
                c0, c1 = box_edge_corners(j)
                p = origin + box_corner_local(c, c0)
                q = origin + box_corner_local(c, c1)
                if not boxes_overlap(wp.min(p, q), wp.max(p, q), lo_e, hi_e):  # most cloth edges: none near
                    continue
                out = wp.normalize(signs(0.5 * (p + q) - origin))  # the sum of its two faces' normals
                s, lam, mu_v, n = edge_response(la, lb, lva, lvb, wa, wb, p, q, out, c.thickness, c, origin)
                if lam > 0.0:
                    nw = c.rotation * n
                    vw = c.rotation * mu_v
                    push(ia, 1.0 - s, inv_mass, lam, vw, nw, dx, dv, count)
                    push(ib, s, inv_mass, lam, vw, nw, dx, dv, count)
        else:
            bvh = meshes.edge_bvh[k]
            if bvh == wp.uint64(0):
                continue
            query = wp.bvh_query_aabb(bvh, lo_e, hi_e)  # as far as edge_response looks
            j = int(0)
            while wp.bvh_query_next(query, j):
                g = meshes.edge_offset[k] + j
                s, lam, mu_v, n = edge_response(
                    la,
                    lb,
                    lva,
                    lvb,
                    wa,
                    wb,
                    meshes.edge_p[g],
                    meshes.edge_q[g],
                    meshes.edge_out[g],
                    c.thickness,
                    c,
                    origin,
                )
                if lam > 0.0:
                    nw = c.rotation * n
                    vw = c.rotation * mu_v
                    push(ia, 1.0 - s, inv_mass, lam, vw, nw, dx, dv, count)
                    push(ib, s, inv_mass, lam, vw, nw, dx, dv, count)


@wp.func(inline=True)
def collide_cloth_triangle(
    t: int,
    tris: wp.array(dtype=wp.vec3i),
    x: wp.array(dtype=wp.vec3),
    v: wp.array(dtype=wp.vec3),
    inv_mass: wp.array(dtype=float),
    colliders: wp.array(dtype=Collider),
    first: int,
    meshes: MeshFeatures,
    dx: wp.array(dtype=wp.vec3),
    dv: wp.array(dtype=wp.vec3),
    count: wp.array(dtype=int),
):
    # cloth triangle t against the corners of every box and the vertices of every mesh collider
    i0 = tris[t][0]
    i1 = tris[t][1]
    i2 = tris[t][2]
    w0 = inv_mass[i0]
    w1 = inv_mass[i1]
    w2 = inv_mass[i2]
    if w0 + w1 + w2 == 0.0:
        return
    for k in range(first, colliders.shape[0]):
        c = colliders[k]
        if (c.kind != BOX and c.kind != MESH) or c.moving != 0:
            continue
        origin = c.a
        if c.kind == MESH:
            origin = c.rest_center
        rt = wp.transpose(c.rotation)
        a = origin + rt * (x[i0] - c.a)
        b = origin + rt * (x[i1] - c.a)
        cc = origin + rt * (x[i2] - c.a)
        reach = c.thickness + 0.5 * wp.max(wp.max(wp.length(b - a), wp.length(cc - b)), wp.length(a - cc))
        lo = wp.min(wp.min(a, b), cc) - wp.vec3(reach)  # as far as corner_response looks
        hi = wp.max(wp.max(a, b), cc) + wp.vec3(reach)
        h = c.b
        if c.kind == BOX:  # most triangles are far from every corner: nothing more to do (before the velocities)
            if face_planes_met(lo, hi, origin, h) < 3:
                continue
        vcol = surface_velocity(colliders, k, x[i0])
        va = rt * (v[i0] - vcol)
        vb = rt * (v[i1] - vcol)
        vc = rt * (v[i2] - vcol)
        if c.kind == BOX:
            for j in range(8):
                p = box_corner_local(c, j)
                if not boxes_overlap(origin + p, origin + p, lo, hi):
                    continue
                w, lam, mu_v, n = corner_response(
                    origin + p, wp.normalize(signs(p)), a, b, cc, va, vb, vc, w0, w1, w2, c.thickness, c, origin
                )
                if lam > 0.0:
                    nw = c.rotation * n
                    vw = c.rotation * mu_v
                    push(i0, w[0], inv_mass, lam, vw, nw, dx, dv, count)
                    push(i1, w[1], inv_mass, lam, vw, nw, dx, dv, count)
                    push(i2, w[2], inv_mass, lam, vw, nw, dx, dv, count)
        else:
            bvh = meshes.vertex_bvh[k]
            if bvh == wp.uint64(0):
                continue
            query = wp.bvh_query_aabb(bvh, lo, hi)
            j = int(0)
            while wp.bvh_query_next(query, j):
                g = meshes.vertex_offset[k] + j
                w, lam, mu_v, n = corner_response(
                    meshes.vertex[g],
                    meshes.vertex_out[g],
                    a,
                    b,
                    cc,
                    va,
                    vb,
                    vc,
                    w0,
                    w1,
                    w2,
                    c.thickness,
                    c,
                    origin,
                )
                if lam > 0.0:
                    nw = c.rotation * n
                    vw = c.rotation * mu_v
                    push(i0, w[0], inv_mass, lam, vw, nw, dx, dv, count)
                    push(i1, w[1], inv_mass, lam, vw, nw, dx, dv, count)
                    push(i2, w[2], inv_mass, lam, vw, nw, dx, dv, count)


@wp.kernel
def collide_cloth_features(
    stride: int,
    active: wp.array(dtype=int),
    read: int,
    write: int,
    first_pass: int,
    edges: wp.array(dtype=wp.vec2i),
    tris: wp.array(dtype=wp.vec3i),
    x: wp.array(dtype=wp.vec3),
    v: wp.array(dtype=wp.vec3),
    inv_mass: wp.array(dtype=float),
    colliders: wp.array(dtype=Collider),
    first: int,
    meshes: MeshFeatures,
    dx: wp.array(dtype=wp.vec3),
    dv: wp.array(dtype=wp.vec3),
    count: wp.array(dtype=int),
):
    # one pass (grid-stride over ``stride`` threads): every cloth edge against the box and mesh colliders'
    # edges, every cloth triangle against their corners and vertices. active[read]: the vertices the pass
    # before moved (0: nothing to do, the pass returns at once; not read by a ``first_pass``); active[write],
    # which this pass's apply counts into, from zero
    tid = wp.tid()
    if tid == 0:
        active[write] = 0
    if first_pass == 0 and active[read] == 0:
        return
    for e in range(tid, edges.shape[0], stride):
        collide_cloth_edge(e, edges, x, v, inv_mass, colliders, first, meshes, dx, dv, count)
    for t in range(tid, tris.shape[0], stride):
        collide_cloth_triangle(t, tris, x, v, inv_mass, colliders, first, meshes, dx, dv, count)


@wp.kernel
def eval_positions(x: wp.array(dtype=wp.vec3), dp: wp.array(dtype=wp.vec3), p: wp.array(dtype=wp.vec3)):
    # p = x + dp (a position-based solver's predicted positions)
    i = wp.tid()
    p[i] = x[i] + dp[i]


@wp.kernel
def apply_edge_increments(
    dx: wp.array(dtype=wp.vec3),
    dv: wp.array(dtype=wp.vec3),
    count: wp.array(dtype=int),
    dp: wp.array(dtype=wp.vec3),
):
    # dp += dx / c (inside a solver: positions only); the accumulators to zero
    i = wp.tid()
    c = count[i]
    if c == 0:
        return
    dp[i] = dp[i] + (RELAX / float(c)) * dx[i]
    dx[i] = wp.vec3(0.0)
    dv[i] = wp.vec3(0.0)
    count[i] = 0


@wp.kernel
def apply_edge_contacts(
    stride: int,
    dt_x: float,
    with_displacement: int,
    dx: wp.array(dtype=wp.vec3),
    dv: wp.array(dtype=wp.vec3),
    count: wp.array(dtype=int),
    active: wp.array(dtype=int),
    read: int,
    write: int,
    first_pass: int,
    x: wp.array(dtype=wp.vec3),
    v: wp.array(dtype=wp.vec3),
    displacement: wp.array(dtype=wp.vec3),
    held: wp.array(dtype=wp.vec3),
):
    # (grid-stride over the vertices) x += dx / c + dt_x dv / c, v += dv / c (c: the vertex's contacts; the
    # velocity change moves x as the step would have, so friction does not creep; Verlet's displacement
    # follows); the accumulators to zero; active[write] counts the vertices moved (collide_cloth_features);
    # held: the direction a vertex was pushed out in, for the self-collision's continuous response after
    if first_pass == 0 and active[read] == 0:
        return
    for i in range(wp.tid(), x.shape[0], stride):
        c = count[i]
        if c != 0:
            s = RELAX / float(c)
            if wp.length_sq(dx[i]) > 0.0:
                held[i] = wp.normalize(dx[i])
            x[i] = x[i] + s * dx[i] + (dt_x * s) * dv[i]
            v[i] = v[i] + (s * VELOCITY) * dv[i]
            if with_displacement != 0:
                displacement[i] = displacement[i] + s * dx[i] + (dt_x * s) * dv[i]
            dx[i] = wp.vec3(0.0)
            dv[i] = wp.vec3(0.0)
            count[i] = 0
            wp.atomic_add(active, write, 1)
