"""Vertex Block Descent (Chen, Liu, Yang & Yuksel, SIGGRAPH 2024) on the mass-spring energy.

A time step minimises the incremental potential over the displacement dx = x_new - x

    G(dx) = sum_i m_i / (2 h^2) |dx_i - dy_i|^2 + sum_s E_s(x + dx),   dy = h v + h^2 f_ext / m,

E_s = ks (L - L0)^2 / 2 per spring. Vertex i's local Newton step (its neighbours fixed) is

    dx_i <- dx_i - H_i^-1 g_i,
    g_i = m_i / h^2 (dx_i - dy_i) - sum_s [ ks (L - L0) n + kd / h n n^T (dx_j - dx_i) ],
    H_i = m_i / h^2 I + sum_s [ K_s + kd / h n n^T ],

with n = (x_j + dx_j - x_i - dx_i) / L, K_s the spring Hessian with the compression clamp of
:func:`warpcloth.kernels.implicit.spring_stiffness_block` (positive semi-definite, so H_i is SPD),
and the spring's damping force kd ((v_j - v_i) . n) n taken implicitly with v = dx / h (the
paper's damping term kd / h H in the gradient and Hessian, here along the spring as in the
force-based integrators). Vertices of one colour share no spring: one launch per colour is a
Gauss-Seidel sweep. Positions are carried as the increment dx: the kernels form
x_j - x_i and dx_j - dx_i apart, never x + dx.
"""

import warp as wp

from warpcloth.kernels.collide import Collider, contact_band, in_box, plane_contact, shape_contact, surface_velocity
from warpcloth.kernels.implicit import spring_stiffness_block

# forward only: no adjoints (half the compile time; warpcloth differentiates nothing)
wp.set_module_options({"enable_backward": False})


@wp.func
def spring_gradient_hessian(xij: wp.vec3, dxij: wp.vec3, rest: float, ks: float, kd: float, h: float):
    # force on i from spring (i, j): f = ks (L - L0) n + kd / h (n.(dx_j - dx_i)) n ;
    # its Hessian block w.r.t. x_i: K (clamped) + kd / h n n^T   (d = x_j - x_i + dx_j - dx_i)
    d = xij + dxij
    length = wp.length(d)
    if length == 0.0:
        return wp.vec3(0.0), wp.mat33(0.0)
    n = d / length
    nnt = wp.outer(n, n)
    force = ks * (length - rest) * n + (kd / h) * wp.dot(n, dxij) * n
    hessian = spring_stiffness_block(wp.vec3(0.0), d, rest, ks) + (kd / h) * nnt
    return force, hessian


@wp.func
def vertex_gradient_hessian(
    i: int, x: wp.array(dtype=wp.vec3), dx: wp.array(dtype=wp.vec3), dy: wp.array(dtype=wp.vec3), particle_mass: wp.array(dtype=float),
    adjacency_offsets: wp.array(dtype=int), adjacency_spring: wp.array(dtype=int), adjacency_other: wp.array(dtype=int),
    spring_rest_length: wp.array(dtype=float), spring_stiffness: wp.array(dtype=float), spring_damping: wp.array(dtype=float), h: float,
):
    # vertex i's local problem with its neighbours fixed: the gradient g = m / h^2 (dx_i - dy_i) -
    # sum f and Hessian H = m / h^2 I + sum K of the step's potential at its increment dx_i
    xi = x[i]
    dxi = dx[i]
    inertia = particle_mass[i] / (h * h)
    g = inertia * (dxi - dy[i])
    H = inertia * wp.identity(n=3, dtype=float)
    for a in range(adjacency_offsets[i], adjacency_offsets[i + 1]):
        s = adjacency_spring[a]
        j = adjacency_other[a]
        f, K = spring_gradient_hessian(x[j] - xi, dx[j] - dxi, spring_rest_length[s], spring_stiffness[s], spring_damping[s], h)
        g = g - f
        H = H + K
    return g, H


@wp.func
def newton_increment(g: wp.vec3, H: wp.mat33):
    # -H^-1 g, or 0 where H is singular
    det = wp.determinant(H)
    if wp.abs(det) < 1.0e-30:
        return wp.vec3(0.0)
    return -(wp.inverse(H) * g)


@wp.func(inline=True)
def contact_response(colliders: wp.array(dtype=Collider), k: int, p: wp.vec3, d: wp.vec3, phi: float, n: wp.vec3, h: float,
                     H: wp.mat33, Hinv: wp.mat33):
    # the vertex's local problem min 1/2 e^T H e - c^T e (e = its displacement from d, the unconstrained
    # minimiser; c the collider's force) with p = x + d within collider k's thickness, the surface
    # linearised at p with normal n. Stick: e takes p to the surface at the collider's motion over the
    # step (h v_c, the pose at the step's end); its force c = H e held if |c_t| <= mu c_n (Coulomb).
    # Slide: c = lambda (n + mu t), t along the sticking force's tangential part, lambda such that
    # p + H^-1 c is on the surface. With H isotropic this is the projection along n and friction as
    # position-based solvers' (up to mu times the depth); an anisotropic H (stiff springs along the
    # surface) needs the solve: projecting along n alone lets the normal force's H^-1 coupling slide
    # the contact. Returns d, hit (1: a contact) and v_c
    depth = colliders[k].thickness - phi
    if depth <= 0.0:
        return d, 0, wp.vec3(0.0), wp.vec3(0.0)
    vc = surface_velocity(colliders, k, p)
    r = d + depth * n - h * vc
    stick = depth * n - (r - wp.dot(r, n) * n)
    c = H * stick
    cn = wp.dot(c, n)
    ct = c - cn * n
    lt = wp.length(ct)
    mu = colliders[k].mu
    if lt <= mu * cn:
        return d + stick, 2, vc, c
    w = n + (mu / lt) * ct
    q = Hinv * w
    denom = wp.dot(n, q)
    if denom <= 0.0:  # not expected (H SPD, mu moderate): the projection along n
        return d + depth * n, 1, vc, depth * (H * n)
    return d + (depth / denom) * q, 1, vc, (depth / denom) * w


@wp.func
def project_increment(xi: wp.vec3, d: wp.vec3, colliders: wp.array(dtype=Collider), box: wp.array(dtype=wp.vec3), plane_count: int, h: float,
                      H: wp.mat33, Hinv: wp.mat33):
    # x_i + d out of every collider with friction (contact_response, the vertex's local Hessian H):
    # planes first, the others when x_i + d is in the box around them (as kernels.collide's
    # responses); returns d, the last contact's normal (0: none), its collider velocity, the
    # colliders' force on the vertex and the state (0: free, 1: sliding, 2: sticking)
    normal = wp.vec3(0.0)
    velocity = wp.vec3(0.0)
    force = wp.vec3(0.0)
    state = int(0)
    for k in range(plane_count):
        p = xi + d
        phi, n = plane_contact(p, colliders[k].a, colliders[k].b)
        d, hit, vc, c = contact_response(colliders, k, p, d, phi, n, h, H, Hinv)
        if hit != 0:
            normal = n
            velocity = vc
            force = force + c
            state = hit
    if in_box(xi + d, box):
        for k in range(plane_count, colliders.shape[0]):
            p = xi + d
            phi, n = shape_contact(colliders, k, p, contact_band(colliders, k))
            d, hit, vc, c = contact_response(colliders, k, p, d, phi, n, h, H, Hinv)
            if hit != 0:
                normal = n
                velocity = vc
                force = force + c
                state = hit
    return d, normal, velocity, force, state


@wp.kernel
def solve_vertices_vbd(
    order: wp.array(dtype=int),
    start: int,
    x: wp.array(dtype=wp.vec3),
    dy: wp.array(dtype=wp.vec3),
    particle_mass: wp.array(dtype=float),
    particle_inv_mass: wp.array(dtype=float),
    adjacency_offsets: wp.array(dtype=int),
    adjacency_spring: wp.array(dtype=int),
    adjacency_other: wp.array(dtype=int),
    spring_rest_length: wp.array(dtype=float),
    spring_stiffness: wp.array(dtype=float),
    spring_damping: wp.array(dtype=float),
    h: float,
    colliders: wp.array(dtype=Collider),
    box: wp.array(dtype=wp.vec3),
    plane_count: int,
    dx: wp.array(dtype=wp.vec3),
    contact_normal: wp.array(dtype=wp.vec3),
    contact_velocity: wp.array(dtype=wp.vec3),
    contact_force: wp.array(dtype=wp.vec3),
    contact_state: wp.array(dtype=int),
):
    # one colour: dx_i <- dx_i - H_i^-1 g_i  (module docstring), then out of the colliders with
    # friction (project_increment; no colliders: an empty array), the contact's normal (0: none)
    # and collider velocity kept; pinned particles stay
    i = order[start + wp.tid()]
    if particle_inv_mass[i] == 0.0:
        return
    xi = x[i]
    dxi = dx[i]
    g, H = vertex_gradient_hessian(i, x, dx, dy, particle_mass, adjacency_offsets, adjacency_spring, adjacency_other,
                                   spring_rest_length, spring_stiffness, spring_damping, h)
    d = dxi + newton_increment(g, H)
    if colliders.shape[0] > 0:
        Hinv = wp.mat33(0.0)
        if wp.abs(wp.determinant(H)) >= 1.0e-30:
            Hinv = wp.inverse(H)
        d, n, vc, c, state = project_increment(xi, d, colliders, box, plane_count, h, H, Hinv)
        contact_normal[i] = n
        contact_velocity[i] = vc
        contact_force[i] = c
        contact_state[i] = state
    dx[i] = d


@wp.kernel
def project_increments(
    x: wp.array(dtype=wp.vec3),
    particle_inv_mass: wp.array(dtype=float),
    colliders: wp.array(dtype=Collider),
    box: wp.array(dtype=wp.vec3),
    plane_count: int,
    h: float,
    dx: wp.array(dtype=wp.vec3),
    contact_normal: wp.array(dtype=wp.vec3),
    contact_velocity: wp.array(dtype=wp.vec3),
    contact_force: wp.array(dtype=wp.vec3),
    contact_state: wp.array(dtype=int),
):
    # every free particle's x + dx out of the colliders with friction (after a Chebyshev extrapolation,
    # or projective dynamics' global step), its contact's normal (0: none) and collider velocity
    # kept; pinned particles stay
    i = wp.tid()
    if particle_inv_mass[i] == 0.0:
        return
    eye = wp.identity(n=3, dtype=float)
    d, n, vc, c, state = project_increment(x[i], dx[i], colliders, box, plane_count, h, eye, eye)
    dx[i] = d
    contact_normal[i] = n
    contact_velocity[i] = vc
    contact_force[i] = c
    contact_state[i] = state


@wp.kernel
def update_from_increment_contact(
    x: wp.array(dtype=wp.vec3),
    v: wp.array(dtype=wp.vec3),
    dx: wp.array(dtype=wp.vec3),
    particle_inv_mass: wp.array(dtype=float),
    h: float,
    contact_normal: wp.array(dtype=wp.vec3),
    contact_velocity: wp.array(dtype=wp.vec3),
):
    # v = dx / h ;  x += dx, and a particle the last solve held on a collider leaves with no normal
    # velocity relative to it ((v - v_c).n = 0: dx / h rounds it by ~ulp(x) / h, which at small h
    # would carry it off a moving collider); pinned particles untouched
    i = wp.tid()
    if particle_inv_mass[i] == 0.0:
        return
    d = dx[i]
    vi = d / h
    n = contact_normal[i]
    if wp.dot(n, n) > 0.0:
        vi = vi - wp.dot(vi - contact_velocity[i], n) * n
    v[i] = vi
    x[i] = x[i] + d


@wp.kernel
def add_contact_forces(contact_state: wp.array(dtype=int), contact_force: wp.array(dtype=wp.vec3), h: float, r: wp.array(dtype=wp.vec3)):
    # the multigrid residual where the last sweep held a contact: r = 0 (the collider holds it: a
    # correction must neither pull it in nor slide it along). Measured on the 16 x 16 drape: with
    # only r's inward normal part removed it slid off the sphere (the correction moved the contacts by
    # the tangential force friction holds); adding a sliding contact's collider force (h^2 c, normal
    # and kinetic friction) instead of zeroing it, it settled 1.8 cm off centre; with r = 0 at 7.0 s,
    # 5 mm off. (contact_force and h: kept for that variant's signature)
    i = wp.tid()
    if contact_state[i] != 0:
        r[i] = wp.vec3(0.0)


@wp.kernel
def mask_contact_normal(contact_normal: wp.array(dtype=wp.vec3), r: wp.array(dtype=wp.vec3)):
    # r's component into a collider removed where the last sweep held a contact
    i = wp.tid()
    n = contact_normal[i]
    rn = wp.dot(r[i], n)
    if rn < 0.0:
        r[i] = r[i] - rn * n


@wp.kernel
def copy_increment(dx: wp.array(dtype=wp.vec3), prev1: wp.array(dtype=wp.vec3), prev2: wp.array(dtype=wp.vec3)):
    # prev1 = prev2 = dx (the Chebyshev history starts at the initial guess)
    i = wp.tid()
    prev1[i] = dx[i]
    prev2[i] = dx[i]


@wp.kernel
def apply_chebyshev(omega: float, dx: wp.array(dtype=wp.vec3), prev1: wp.array(dtype=wp.vec3), prev2: wp.array(dtype=wp.vec3)):
    # x^(n) = omega_n (xbar^(n) - x^(n-2)) + x^(n-2)   (Chen et al. 2024, eq. 17; Wang 2015)
    i = wp.tid()
    accelerated = omega * (dx[i] - prev2[i]) + prev2[i]
    prev2[i] = prev1[i]
    prev1[i] = accelerated
    dx[i] = accelerated


@wp.kernel
def update_from_increment(
    x: wp.array(dtype=wp.vec3),
    v: wp.array(dtype=wp.vec3),
    dx: wp.array(dtype=wp.vec3),
    particle_inv_mass: wp.array(dtype=float),
    h: float,
):
    # v = dx / h ;  x += dx   (pinned particles untouched)
    i = wp.tid()
    if particle_inv_mass[i] == 0.0:
        return
    d = dx[i]
    v[i] = d / h
    x[i] = x[i] + d


@wp.kernel
def eval_increment_residual(
    x: wp.array(dtype=wp.vec3),
    dy: wp.array(dtype=wp.vec3),
    dx: wp.array(dtype=wp.vec3),
    particle_mass: wp.array(dtype=float),
    particle_inv_mass: wp.array(dtype=float),
    adjacency_offsets: wp.array(dtype=int),
    adjacency_spring: wp.array(dtype=int),
    adjacency_other: wp.array(dtype=int),
    spring_rest_length: wp.array(dtype=float),
    spring_stiffness: wp.array(dtype=float),
    spring_damping: wp.array(dtype=float),
    h: float,
    r: wp.array(dtype=wp.vec3),
):
    # r_i = -h^2 g_i = m_i (dy_i - dx_i) + h^2 sum_s f_s  (the whole potential's negative gradient, times h^2);  pinned: 0
    i = wp.tid()
    if particle_inv_mass[i] == 0.0:
        r[i] = wp.vec3(0.0)
        return
    xi = x[i]
    dxi = dx[i]
    force = wp.vec3(0.0)
    for a in range(adjacency_offsets[i], adjacency_offsets[i + 1]):
        s = adjacency_spring[a]
        j = adjacency_other[a]
        f, K = spring_gradient_hessian(x[j] - xi, dx[j] - dxi, spring_rest_length[s], spring_stiffness[s], spring_damping[s], h)
        force = force + f
    r[i] = particle_mass[i] * (dy[i] - dxi) + (h * h) * force


@wp.kernel
def add_increment(delta: wp.array(dtype=wp.vec3), dx: wp.array(dtype=wp.vec3)):
    # dx += delta  (the multigrid correction; zero on pinned particles)
    i = wp.tid()
    dx[i] = dx[i] + delta[i]
