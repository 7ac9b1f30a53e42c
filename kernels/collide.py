"""Collision kernels: particles against planes, spheres, capsules and oriented boxes, each with a
thickness (cloth offset) and a Coulomb friction coefficient mu. Pinned particles (inverse mass
0) are left alone: pins win over contacts.

Each collider kind has a signed distance phi(x) and an outward unit normal n (pure ``@wp.func``
below). Two responses share them:

* after a force-based step (velocity level): a particle with phi < thickness is moved out along
  n by the depth, its approaching normal velocity is removed (dv_n = max(0, -v.n)), and its
  tangential velocity is reduced by mu dv_n, at most to zero (Coulomb); the tangential change
  is applied to the position too, as the step would have (x += dt dv_t where x += dt v_new;
  dt/2 dv_t for the Runge-Kutta schemes, whose x feels a step's acceleration with weight 1/2),
  so a sticking particle does not creep. Verlet's displacement d is set to v dt for such particles.
* inside the position-based solver loop: the predicted displacement dp is moved out along n
  (normal corrections accumulated per substep), and after the iterations the tangential part of
  dp is cancelled up to mu times the accumulated normal correction (static/kinetic friction of
  Macklin et al. 2014).
"""

import warp as wp

wp.set_module_options({"enable_backward": False})


@wp.func
def plane_contact(x: wp.vec3, point: wp.vec3, normal: wp.vec3):
    # phi = (x - p).n, outward normal n
    return wp.dot(x - point, normal), normal


@wp.func
def sphere_contact(x: wp.vec3, center: wp.vec3, radius: float):
    # phi = |x - c| - r, n = (x - c)/|x - c|
    d = x - center
    length = wp.length(d)
    if length == 0.0:
        return -radius, wp.vec3(0.0, 1.0, 0.0)
    return length - radius, d / length


@wp.func
def capsule_contact(x: wp.vec3, a: wp.vec3, b: wp.vec3, radius: float):
    # phi = |x - q| - r, q the closest point of the segment ab
    ab = b - a
    t = wp.clamp(wp.dot(x - a, ab) / wp.max(wp.dot(ab, ab), 1.0e-20), 0.0, 1.0)
    return sphere_contact(x, a + t * ab, radius)


@wp.func
def box_contact(x: wp.vec3, center: wp.vec3, rotation: wp.quat, half: wp.vec3):
    # signed distance of an oriented box; n the gradient (the nearest face's normal inside)
    p = wp.quat_rotate_inv(rotation, x - center)
    q = wp.vec3(wp.abs(p[0]) - half[0], wp.abs(p[1]) - half[1], wp.abs(p[2]) - half[2])
    s = wp.vec3(wp.sign(p[0]), wp.sign(p[1]), wp.sign(p[2]))
    outside = wp.vec3(wp.max(q[0], 0.0), wp.max(q[1], 0.0), wp.max(q[2], 0.0))
    lo = wp.length(outside)
    if lo > 0.0:
        n_local = wp.cw_mul(outside / lo, s)
        return lo, wp.quat_rotate(rotation, n_local)
    k = int(0)
    if q[1] > q[k]:
        k = 1
    if q[2] > q[k]:
        k = 2
    n_local = wp.vec3(0.0)
    n_local[k] = s[k]
    return q[k], wp.quat_rotate(rotation, n_local)


@wp.func
def respond_velocity(x: wp.vec3, v: wp.vec3, phi: float, n: wp.vec3, thickness: float, mu: float, dt: float):
    # x += depth n ; v_n >= 0 ; |v_t| -= mu dv_n (>= 0) ; x += dt dv_t
    depth = thickness - phi
    if depth <= 0.0:
        return x, v, 0
    x = x + depth * n
    vn = wp.dot(v, n)
    dvn = wp.max(0.0, -vn)
    v = v + dvn * n
    vt = v - wp.dot(v, n) * n
    lt = wp.length(vt)
    if lt > 0.0:
        dvt = -(wp.min(mu * dvn, lt) / lt) * vt
        v = v + dvt
        x = x + dt * dvt
    return x, v, 1


@wp.func
def respond_displacement(x: wp.vec3, dp: wp.vec3, phi: float, n: wp.vec3, thickness: float):
    # dp += depth n (p = x + dp out of the collider); returns the normal correction
    depth = thickness - phi
    if depth <= 0.0:
        return dp, 0.0
    return dp + depth * n, depth


@wp.func
def friction_displacement(dp: wp.vec3, n: wp.vec3, normal_correction: float, mu: float):
    # cancel the tangential dp up to mu times the normal correction (static if smaller)
    dpt = dp - wp.dot(dp, n) * n
    lt = wp.length(dpt)
    if lt == 0.0:
        return dp
    return dp - (wp.min(mu * normal_correction, lt) / lt) * dpt


@wp.func
def contact_of(kind: int, p: wp.vec3, c: int, a: wp.array(dtype=wp.vec3), b: wp.array(dtype=wp.vec3),
               radius: wp.array(dtype=float), rotation: wp.array(dtype=wp.quat)):
    # one signature for every kind: a = point/center/a/center, b = normal/-/b/half extents
    if kind == 0:
        return plane_contact(p, a[c], b[c])
    if kind == 1:
        return sphere_contact(p, a[c], radius[c])
    if kind == 2:
        return capsule_contact(p, a[c], b[c], radius[c])
    return box_contact(p, a[c], rotation[c], b[c])


@wp.kernel
def collide_velocity(
    kind: int, x: wp.array(dtype=wp.vec3), v: wp.array(dtype=wp.vec3), inv_mass: wp.array(dtype=float), dt: float,
    position_weight: float, displacement: wp.array(dtype=wp.vec3), has_displacement: int,
    a: wp.array(dtype=wp.vec3), b: wp.array(dtype=wp.vec3), radius: wp.array(dtype=float), rotation: wp.array(dtype=wp.quat),
    material: wp.array(dtype=wp.vec2),
):
    # after a force-based step: every collider of one kind, respond_velocity (the tangential
    # change moves x by position_weight dt dv_t: 1 where x += dt v_new, 1/2 for RK); Verlet's d = v dt
    i = wp.tid()
    if inv_mass[i] == 0.0:
        return
    xi = x[i]
    vi = v[i]
    hit = int(0)
    for c in range(material.shape[0]):
        phi, n = contact_of(kind, xi, c, a, b, radius, rotation)
        xi, vi, h = respond_velocity(xi, vi, phi, n, material[c][0], material[c][1], position_weight * dt)
        hit = hit + h
    if hit != 0:
        x[i] = xi
        v[i] = vi
        if has_displacement != 0:
            displacement[i] = dt * vi


@wp.kernel
def collide_displacement(
    kind: int, friction: int, x: wp.array(dtype=wp.vec3), dp: wp.array(dtype=wp.vec3), inv_mass: wp.array(dtype=float),
    normal_correction: wp.array(dtype=float),
    a: wp.array(dtype=wp.vec3), b: wp.array(dtype=wp.vec3), radius: wp.array(dtype=float), rotation: wp.array(dtype=wp.quat),
    material: wp.array(dtype=wp.vec2),
):
    # position-based solvers: p = x + dp out of the colliders of one kind (friction = 0), or the
    # friction pass after the iterations (friction = 1), with the normal corrections accumulated
    i = wp.tid()
    if inv_mass[i] == 0.0:
        return
    xi = x[i]
    d = dp[i]
    for c in range(material.shape[0]):
        phi, n = contact_of(kind, xi + d, c, a, b, radius, rotation)
        if friction == 0:
            d, dn = respond_displacement(xi, d, phi, n, material[c][0])
            normal_correction[i] = normal_correction[i] + dn
        elif normal_correction[i] > 0.0 and phi <= material[c][0] + 1.0e-6:
            d = friction_displacement(d, n, normal_correction[i], material[c][1])
    dp[i] = d
