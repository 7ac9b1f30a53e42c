"""The per-vertex pieces of the solvers that solve a step for the increment dx = x_new - x (vbd,
projective): the inertial prediction, vertex i's local Newton step on the incremental potential

    G(dx) = sum_i m_i / (2 h^2) |dx_i - dy_i|^2 + sum_s E_s(x + dx),   dy = h v + h^2 f_ext / m,

(its gradient g_i and Hessian H_i with its neighbours fixed, see :mod:`warpcloth.kernels.vbd`),
the projection of x + dx out of the colliders with Coulomb friction in the metric of H_i, and the
update v = dx / h, x += dx. Positions are carried as the increment dx: the kernels form
x_j - x_i and dx_j - dx_i apart, never x + dx.
"""

import warp as wp

from warpcloth.kernels.bending import HingeAdjacency, hinge_angle_gradient, hinge_force_scale, pick_vec3
from warpcloth.kernels.collide import (
    MESH,
    Collider,
    Colliders,
    contact_band,
    in_box,
    plane_contact,
    shape_contact,
    surface_velocity,
    swept_mesh_contact,
)
from warpcloth.kernels.self_contact import CONTACTS, penalty_depth
from warpcloth.kernels.springs import SpringAdjacency, spring_gradient_hessian

# forward only: no adjoints (half the compile time; warpcloth differentiates nothing)
wp.set_module_options({"enable_backward": False})


@wp.struct
class Inertia:
    """The inertial term m / (2 h^2) |dx - dy|^2 of a step's potential: filled once at bind."""

    dy: wp.array(dtype=wp.vec3)  # the inertial target y - x = h v + h^2 f_ext / m [m], shape (particle_count,)
    mass: wp.array(dtype=float)  # particle mass [kg]
    inv_mass: wp.array(dtype=float)  # 1 / mass [1/kg]; 0: pinned (its dx is prescribed)


@wp.struct
class ContactState:
    """Per particle, what the last contact pass of an increment solve found: filled once at bind."""

    normal: wp.array(dtype=wp.vec3)  # the contact's normal (0: none)
    velocity: wp.array(dtype=wp.vec3)  # the collider's velocity there [m/s]
    force: wp.array(dtype=wp.vec3)  # the colliders' force on the vertex in its local problem [N]
    state: wp.array(dtype=int)  # 0 free, 1 sliding, 2 sticking
    friction: wp.array(dtype=float)  # mu m a_n of a contact the rigid translation slides (sliding_friction) [N]
    resting: wp.array(dtype=int)  # 1: on a collider at the end of the last step, else 0
    held: wp.array(dtype=int)  # [1]: contacts the last sweep held (sticking, or sliding_friction 0 with mu > 0)


@wp.kernel
def predict_inertia(
    v: wp.array(dtype=wp.vec3),
    f_ext: wp.array(dtype=wp.vec3),
    particle_inv_mass: wp.array(dtype=float),
    h: float,
    dy: wp.array(dtype=wp.vec3),
    dx: wp.array(dtype=wp.vec3),
):
    # dy = h v + h^2 f_ext / m (inertial target y - x);  dx = h v (initial guess x + h v);  pinned: 0
    # (the increments that vbd and projective solve for)
    i = wp.tid()
    w = particle_inv_mass[i]
    if w == 0.0:
        dy[i] = wp.vec3(0.0)
        dx[i] = wp.vec3(0.0)
        return
    dy[i] = h * v[i] + (h * h * w) * f_ext[i]
    dx[i] = h * v[i]


@wp.func
def vertex_gradient_hessian(
    i: int,
    x: wp.array(dtype=wp.vec3),
    dx: wp.array(dtype=wp.vec3),
    inertia: Inertia,
    springs: SpringAdjacency,
    h: float,
):
    # vertex i's local problem with its neighbours fixed: the gradient g = m / h^2 (dx_i - dy_i) -
    # sum f and Hessian H = m / h^2 I + sum K of the step's potential at its increment dx_i
    xi = x[i]
    dxi = dx[i]
    mh2 = inertia.mass[i] / (h * h)
    g = mh2 * (dxi - inertia.dy[i])
    H = mh2 * wp.identity(n=3, dtype=float)
    for a in range(springs.offsets[i], springs.offsets[i + 1]):
        s = springs.spring[a]
        j = springs.other[a]
        f, K = spring_gradient_hessian(
            x[j] - xi,
            dx[j] - dxi,
            springs.rest_length[s],
            springs.stiffness[s],
            springs.damping[s],
            springs.compression[s],
            h,
        )
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


#: IPC's smooth static friction (Li et al. 2020, eq. 14; Chen et al. 2024): below this tangential speed
#: [m/s] relative to the collider, the rigid translation's friction is a stiff spring (lagged_friction)
FRICTION_SPEED = wp.constant(1.0e-5)


@wp.func(inline=True)
def contact_response(
    colliders: wp.array(dtype=Collider),
    k: int,
    p: wp.vec3,
    d: wp.vec3,
    phi: float,
    n: wp.vec3,
    h: float,
    H: wp.mat33,
    Hinv: wp.mat33,
):
    # the vertex's local problem min 1/2 e^T H e - c^T e (e = its displacement from d, the unconstrained
    # minimiser; c the collider's force) with p = x + d within collider k's thickness, the surface
    # linearised at p with normal n. Stick: e takes p to the surface at the collider's motion over the
    # step (h v_c, the pose at the step's end); its force c = H e held if |c_t| <= mu c_n (Coulomb).
    # Slide: c = lambda (n + mu t), t along the sticking force's tangential part, lambda such that
    # p + H^-1 c is on the surface. With H isotropic this is the projection along n and friction as
    # position-based solvers' (up to mu times the depth); an anisotropic H (stiff springs along the
    # surface) needs the solve: projecting along n alone lets the normal force's H^-1 coupling slide
    # the contact. Returns d, hit (1: sliding, 2: sticking) and v_c
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
def project_increment(xi: wp.vec3, d: wp.vec3, colliders: Colliders, h: float, H: wp.mat33, Hinv: wp.mat33):
    # x_i + d out of every collider with friction (contact_response, the vertex's local Hessian H):
    # planes first, the others when x_i + d is in the box around them (as kernels.collide's
    # responses); returns d, the last contact's normal (0: none), its collider velocity, the
    # colliders' force on the vertex, the state (0: free, 1: sliding, 2: sticking) and the last
    # contact's mu where it slides (else 0; vbd's rigid translation may take its friction, sliding_friction)
    normal = wp.vec3(0.0)
    velocity = wp.vec3(0.0)
    force = wp.vec3(0.0)
    state = int(0)
    mu = float(0.0)
    records = colliders.records
    for k in range(colliders.plane_count):
        p = xi + d
        phi, n = plane_contact(p, records[k].a, records[k].b)
        d, hit, vc, c = contact_response(records, k, p, d, phi, n, h, H, Hinv)
        if hit != 0:
            normal = n
            velocity = vc
            force = force + c
            state = hit
            mu = float(0.0)
            if hit == 1:
                mu = records[k].mu
    if in_box(xi + d, colliders.box):
        for k in range(colliders.plane_count, records.shape[0]):
            p = xi + d
            phi, n = shape_contact(records, k, p, contact_band(records, k))
            if records[k].kind == MESH:  # the side it came from (its step's increment d)
                phi, n = swept_mesh_contact(records, k, p, d, h, phi, n)
            d, hit, vc, c = contact_response(records, k, p, d, phi, n, h, H, Hinv)
            if hit != 0:
                normal = n
                velocity = vc
                force = force + c
                state = hit
                mu = float(0.0)
                if hit == 1:
                    mu = records[k].mu
    return d, normal, velocity, force, state, mu


@wp.func
def sliding_friction(mu: float, resting: int, dy: wp.vec3, vc: wp.vec3, n: wp.vec3, h: float, mass: float):
    # the kinetic friction mu m a_n [N] with which vbd's rigid translation slides a contact the sweep found
    # sliding (mu > 0), or 0 (the translation holds it): only a contact that rested on its collider at
    # the step's start (no normal velocity relative to it) and whose own free motion over the step, u =
    # dy - h v_c, leaves the Coulomb cone (|T u| > mu a_n h^2, a_n h^2 = -u.n its load: the cloth as a rigid
    # body, its springs not acting). A landing contact, or one only its neighbours drag, is held as before
    # (taking those in made the 64 x 64 tablecloth's landing peak strain 0.18-0.28; docs/solvers.md)
    u = dy - h * vc
    load = -wp.dot(u, n)
    if mu == 0.0 or resting == 0 or load <= 0.0 or wp.length(u + load * n) <= mu * load:
        return 0.0
    return mu * mass * load / (h * h)


@wp.func
def translation_friction(i: int, contact: ContactState):
    # contact i's kinetic friction in the rigid translation (sliding_friction), where the last sweep held
    # no contact (sticking, or sliding with a friction the translation does not take: a rigid body slides
    # only where none of its contacts holds it; with one held, every contact with friction is held in the
    # translation, as before: the tablecloth's landing, docs/solvers.md), else 0
    if contact.held[0] != 0:
        return 0.0
    return contact.friction[i]


@wp.func
def lagged_friction(i: int, dx: wp.array(dtype=wp.vec3), contact: ContactState, h: float):
    # the kinetic friction of vertex i's sliding contact (sliding_friction: contact.friction = mu lambda)
    # as a function of its slip over the step, for vbd's rigid translation (IPC's lagged smooth Coulomb
    # friction, Li et al. 2020; Chen et al. 2024): D(u) = mu lambda f0(|u|), u = T (dx_i - h v_c), T = I
    # - n n^T, f0' = f1 = 2 y / e - y^2 / e^2 below e = FRICTION_SPEED h, 1 above. Returns -grad D =
    # -mu lambda f1 / y u and its Hessian mu lambda (f1' u^ u^T + f1 / y (T - u^ u^T)) (positive
    # semi-definite: f1' >= 0)
    ml = contact.friction[i]
    n = contact.normal[i]
    T = wp.identity(n=3, dtype=float) - wp.outer(n, n)
    u = T * (dx[i] - h * contact.velocity[i])
    y = wp.length(u)
    e = FRICTION_SPEED * h
    f1_y = float(0.0)
    df1 = float(0.0)
    if y >= e:
        f1_y = 1.0 / y
    else:
        f1_y = (2.0 - y / e) / e
        df1 = 2.0 / e - 2.0 * y / (e * e)
    K = (ml * f1_y) * T
    if y > 0.0:
        uh = u / y
        K = K + (ml * (df1 - f1_y)) * wp.outer(uh, uh)
    return (-ml * f1_y) * u, K


@wp.kernel
def project_increments(
    x: wp.array(dtype=wp.vec3),
    particle_inv_mass: wp.array(dtype=float),
    colliders: Colliders,
    h: float,
    dx: wp.array(dtype=wp.vec3),
    contact: ContactState,
):
    # every free particle's x + dx out of the colliders with friction (after a Chebyshev extrapolation,
    # or projective dynamics' global step), its contact's normal (0: none), collider velocity, force,
    # state and sliding mu kept; pinned particles stay
    i = wp.tid()
    if particle_inv_mass[i] == 0.0:
        return
    eye = wp.identity(n=3, dtype=float)
    d, n, vc, c, state, _mu = project_increment(x[i], dx[i], colliders, h, eye, eye)
    dx[i] = d
    contact.normal[i] = n
    contact.velocity[i] = vc
    contact.force[i] = c
    contact.state[i] = state
    contact.friction[i] = 0.0


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
def update_from_increment_contact(
    x: wp.array(dtype=wp.vec3),
    v: wp.array(dtype=wp.vec3),
    dx: wp.array(dtype=wp.vec3),
    particle_inv_mass: wp.array(dtype=float),
    h: float,
    contact: ContactState,
):
    # v = dx / h ;  x += dx, and a particle the last solve held on a collider leaves with no normal
    # velocity relative to it ((v - v_c).n = 0: dx / h rounds it by ~ulp(x) / h, which at small h
    # would carry it off a moving collider); pinned particles untouched
    i = wp.tid()
    if particle_inv_mass[i] == 0.0:
        return
    d = dx[i]
    vi = d / h
    n = contact.normal[i]
    resting = int(0)
    if wp.dot(n, n) > 0.0:
        vi = vi - wp.dot(vi - contact.velocity[i], n) * n
        resting = 1
    contact.resting[i] = resting
    v[i] = vi
    x[i] = x[i] + d


# -- the rigid translation mode of a step's potential (vbd's correction; issue 26) ------------------
@wp.func
def rigid_mode_projector(i: int, inv_mass: wp.array(dtype=float), contact: ContactState):
    # how particle i takes part in a rigid translation t of the cloth: P_i t with P_i = I (free),
    # I - n n^T (sliding on a frictionless collider, or one whose kinetic friction the translation takes,
    # sliding_friction, lagged_friction: along its surface), 0 (pinned, sticking, or sliding with the
    # sweep's friction force -- the mode cannot see the contacts' Coulomb cones as a whole, and
    # translating them let the drape slide for good, measured)
    if inv_mass[i] == 0.0:
        return wp.mat33(0.0)
    state = contact.state[i]
    if state == 2:
        return wp.mat33(0.0)
    eye = wp.identity(n=3, dtype=float)
    if state == 1:
        n = contact.normal[i]
        c = contact.force[i]
        cn = wp.dot(c, n)
        if translation_friction(i, contact) == 0.0 and wp.length(c - cn * n) > 1.0e-4 * wp.abs(cn):
            return wp.mat33(0.0)
        return eye - wp.outer(n, n)
    return eye


@wp.func
def moves_freely(i: int, inv_mass: wp.array(dtype=float), contact: ContactState):
    # rigid_mode_projector(i) is the identity (a free particle out of contact): tested before building
    # the 3 x 3 projectors, as most of a cloth's springs and hinges join two such particles, whose
    # difference P_i - P_j is exactly 0 (the terms' loops skip them; the same sums, fewer operations)
    return inv_mass[i] != 0.0 and contact.state[i] == 0


@wp.func
def rigid_mode_hinge_terms(
    i: int,
    Pi: wp.mat33,
    x: wp.array(dtype=wp.vec3),
    dx: wp.array(dtype=wp.vec3),
    inv_mass: wp.array(dtype=float),
    hinges: HingeAdjacency,
    h: float,
    contact: ContactState,
):
    # the dihedral hinges' share of particle i's rigid-mode terms: for each hinge of i whose four vertices
    # do not all move alike in the mode, P_i f_i (f_i its force on i, as vbd's vertex step sees it) and
    # (k + kd/h) (P_i g_i) (sum_b P_b g_b)^T (its Gauss-Newton block; summed over the hinge's vertices this is
    # (sum P g)(sum P g)^T). A hinge whose vertices share P adds sum_b f_b = 0 and nothing to T^T A T
    xi = x[i]
    dxi = dx[i]
    f = wp.vec3(0.0)
    H = wp.mat33(0.0)
    i_free = moves_freely(i, inv_mass, contact)
    for a in range(hinges.offsets[i], hinges.offsets[i + 1]):
        e = hinges.hinge[a]
        q = hinges.indices[e]
        if i_free:
            if moves_freely(q[0], inv_mass, contact) and moves_freely(q[1], inv_mass, contact):
                if moves_freely(q[2], inv_mass, contact) and moves_freely(q[3], inv_mass, contact):
                    continue
        P0 = rigid_mode_projector(q[0], inv_mass, contact)
        P1 = rigid_mode_projector(q[1], inv_mass, contact)
        P2 = rigid_mode_projector(q[2], inv_mass, contact)
        P3 = rigid_mode_projector(q[3], inv_mass, contact)
        D0 = P0 - Pi
        D1 = P1 - Pi
        D2 = P2 - Pi
        D3 = P3 - Pi
        if wp.ddot(D0, D0) + wp.ddot(D1, D1) + wp.ddot(D2, D2) + wp.ddot(D3, D3) > 0.0:
            d0 = dx[q[0]] - dxi
            d1 = dx[q[1]] - dxi
            d2 = dx[q[2]] - dxi
            d3 = dx[q[3]] - dxi
            theta, g0, g1, g2, g3, valid = hinge_angle_gradient(
                (x[q[0]] - xi) + d0, (x[q[1]] - xi) + d1, (x[q[2]] - xi) + d2, (x[q[3]] - xi) + d3
            )
            if valid != 0:
                k = hinges.stiffness[e]
                kd = hinges.damping[e]
                s = hinge_force_scale(theta, hinges.rest_angle[e], k, kd / h, g0, g1, g2, g3, d0, d1, d2, d3)
                gi = pick_vec3(hinges.slot[a], g0, g1, g2, g3)
                f = f + Pi * (s * gi)
                H = H + (k + kd / h) * wp.outer(Pi * gi, P0 * g0 + P1 * g1 + P2 * g2 + P3 * g3)
    return f, H


@wp.kernel
def rigid_mode_terms(
    x: wp.array(dtype=wp.vec3),
    dx: wp.array(dtype=wp.vec3),
    inertia: Inertia,
    springs: SpringAdjacency,
    hinges: HingeAdjacency,
    h: float,
    contact: ContactState,
    b: wp.array(dtype=wp.vec3),
    A: wp.array(dtype=wp.mat33),
):
    # particle i's share of the Galerkin problem of the rigid translation mode T (columns P_i e_k):
    # T^T r = sum_i P_i r_i, r_i = m_i (dy_i - dx_i) + h^2 (sum_s f_s + c_i) the potential's negative
    # gradient times h^2 (c_i the collider's force of the last sweep), and T^T A T = sum_i m_i P_i +
    # sum_s (P_i - P_j)^T h^2 K_s (P_i - P_j). A spring's forces on its two ends cancel where
    # P_i = P_j (sum P f = sum_s (P_i - P_j) f_s), so only springs whose ends move differently in the
    # mode (a pinned, sticking or sliding end) are evaluated, half at each end (pinned ones too);
    # on a free cloth none: b_i = m_i (dy_i - dx_i), A_i = m_i I, and the springs' forces cancel exactly
    i = wp.tid()
    Pi = rigid_mode_projector(i, inertia.inv_mass, contact)
    bi = wp.vec3(0.0)
    Ai = wp.mat33(0.0)
    h2 = h * h
    if inertia.inv_mass[i] != 0.0:
        c = wp.vec3(0.0)
        if contact.state[i] != 0:
            c = contact.force[i]
        Ai = inertia.mass[i] * Pi
        if translation_friction(i, contact) > 0.0:  # the sweep's friction force replaced by the translation's own
            ff, Kf = lagged_friction(i, dx, contact, h)
            c = ff  # (the normal force is out of P_i's range)
            Ai = Ai + h2 * (Pi * Kf * Pi)
        bi = Pi * (inertia.mass[i] * (inertia.dy[i] - dx[i]) + h2 * c)
    xi = x[i]
    dxi = dx[i]
    i_free = moves_freely(i, inertia.inv_mass, contact)
    for a in range(springs.offsets[i], springs.offsets[i + 1]):
        j = springs.other[a]
        if i_free and moves_freely(j, inertia.inv_mass, contact):
            continue
        Pd = Pi - rigid_mode_projector(j, inertia.inv_mass, contact)
        if wp.ddot(Pd, Pd) > 0.0:
            s = springs.spring[a]
            f, K = spring_gradient_hessian(
                x[j] - xi,
                dx[j] - dxi,
                springs.rest_length[s],
                springs.stiffness[s],
                springs.damping[s],
                springs.compression[s],
                h,
            )
            bi = bi + (0.5 * h2) * (Pd * f)
            Ai = Ai + (0.5 * h2) * (wp.transpose(Pd) * K * Pd)
    if hinges.indices.shape[0] > 0 and inertia.inv_mass[i] != 0.0:
        fh, Hh = rigid_mode_hinge_terms(i, Pi, x, dx, inertia.inv_mass, hinges, h, contact)
        bi = bi + h2 * fh
        Ai = Ai + h2 * Hh
    b[i] = bi
    A[i] = Ai


@wp.kernel
def add_self_contact_rigid_terms(
    stride: int,
    counts: wp.array(dtype=int),
    x: wp.array(dtype=wp.vec3),
    dx: wp.array(dtype=wp.vec3),
    inv_mass: wp.array(dtype=float),
    contact: ContactState,
    c_idx: wp.array(dtype=wp.vec4i),
    c_w: wp.array(dtype=wp.vec4),
    c_n: wp.array(dtype=wp.vec3),
    c_h: wp.array(dtype=float),
    stiffness: float,
    h: float,
    b: wp.array(dtype=wp.vec3),
    A: wp.array(dtype=wp.mat33),
):
    # after rigid_mode_terms: the self-contacts' part of the rigid translation's Galerkin problem (grid-stride
    # over the contacts). A contact's penalty k delta^2 / 2, delta = h_c - n . sum W (x + dx) > 0 (as the
    # sweeps see it, :func:`warpcloth.kernels.self_contact.eval_self_contact_vertex_terms`), pushes vertex a
    # by k delta W_a n: T^T r += h^2 k delta Q n and T^T A T += h^2 k (Q n)(Q n)^T, Q = sum_a W_a P_a (each
    # P_a symmetric). Q = 0 where all four vertices move alike (sum W = 0: equal and opposite); a contact
    # with a pinned, sticking or sliding vertex pushes the translation (without it, a free sheet lying on a
    # pinned one was translated back into it every sweep and fell through: tests/test_self_collision.py).
    # Added to the slot of the contact's first vertex: the solve sums every slot
    tid = wp.tid()
    for k in range(tid, counts[CONTACTS], stride):
        idx = c_idx[k]
        w = c_w[k]
        n = c_n[k]
        d = penalty_depth(x, dx, idx, w, n, c_h[k])
        if d > 0.0:
            Q = wp.mat33(0.0)
            for j in range(4):
                Q = Q + w[j] * rigid_mode_projector(idx[j], inv_mass, contact)
            qn = Q * n
            wp.atomic_add(b, idx[0], (h * h * stiffness * d) * qn)
            wp.atomic_add(A, idx[0], (h * h * stiffness) * wp.outer(qn, qn))


@wp.kernel
def apply_rigid_mode(
    translation: wp.array(dtype=wp.vec3),
    inv_mass: wp.array(dtype=float),
    contact: ContactState,
    dx: wp.array(dtype=wp.vec3),
):
    # dx_i += P_i t  (t = translation[0], rigid_mode_projector)
    i = wp.tid()
    dx[i] = dx[i] + rigid_mode_projector(i, inv_mass, contact) * translation[0]
