"""Vertex Block Descent (Chen, Liu, Yang & Yuksel, SIGGRAPH 2024) on the mass-spring energy.

A time step minimises the incremental potential over the displacement dx = x_new - x

    G(dx) = sum_i m_i / (2 h^2) |dx_i - dy_i|^2 + sum_s E_s(x + dx),   dy = h v + h^2 f_ext / m,

E_s = ks (L - L0)^2 / 2 per spring. Vertex i's local Newton step (its neighbours fixed) is

    dx_i <- dx_i - H_i^-1 g_i,
    g_i = m_i / h^2 (dx_i - dy_i) - sum_s [ ks (L - L0) n + kd / h n n^T (dx_j - dx_i) ],
    H_i = m_i / h^2 I + sum_s [ K_s + kd / h n n^T ],

with n = (x_j + dx_j - x_i - dx_i) / L, K_s the spring Hessian with the compression clamp of
:func:`warpcloth.kernels.springs.spring_stiffness_block` (positive semi-definite, so H_i is SPD),
and the spring's damping force kd ((v_j - v_i) . n) n taken implicitly with v = dx / h (the
paper's damping term kd / h H in the gradient and Hessian, here along the spring as in the
force-based integrators). Vertices of one colour share no spring: one launch per colour is a
Gauss-Seidel sweep. The pieces vbd shares with projective dynamics (the local Newton step, the
contact projection, the update from dx) are in :mod:`warpcloth.kernels.increment`.
"""

import warp as wp

from warpcloth.kernels.bending import HingeAdjacency, vertex_hinge_terms
from warpcloth.kernels.collide import Colliders, contact_band, in_box, plane_contact, shape_contact
from warpcloth.kernels.increment import (
    ContactState,
    Inertia,
    newton_increment,
    project_increment,
    sliding_friction,
    vertex_gradient_hessian,
)
from warpcloth.kernels.springs import SpringAdjacency, spring_gradient_hessian

# forward only: no adjoints (half the compile time; warpcloth differentiates nothing)
wp.set_module_options({"enable_backward": False})


@wp.kernel
def solve_vertices_vbd(
    order: wp.array(dtype=int),
    start: int,
    x: wp.array(dtype=wp.vec3),
    inertia: Inertia,
    springs: SpringAdjacency,
    hinges: HingeAdjacency,
    h: float,
    colliders: Colliders,
    self_force: wp.array(dtype=wp.vec3),
    self_hessian: wp.array(dtype=wp.mat33),
    dx: wp.array(dtype=wp.vec3),
    contact: ContactState,
):
    # one colour: dx_i <- dx_i - H_i^-1 g_i  (module docstring; dihedral hinges add -f_i to g_i and their
    # Gauss-Newton (k + kd/h) g g^T to H_i; self-contacts (self_force non-empty) their penalty's force and
    # Hessian, evaluated before the sweep), then out of the colliders with friction (project_increment;
    # no colliders: empty records), the contact's normal (0: none), collider velocity, force, state and
    # the rigid translation's friction (sliding_friction) kept; pinned particles stay
    i = order[start + wp.tid()]
    if inertia.inv_mass[i] == 0.0:
        return
    xi = x[i]
    dxi = dx[i]
    g, H = vertex_gradient_hessian(i, x, dx, inertia, springs, h)
    if hinges.indices.shape[0] > 0:
        fb, Hb = vertex_hinge_terms(i, x, dx, hinges, h)
        g = g - fb
        H = H + Hb
    if self_force.shape[0] > 0:
        g = g - self_force[i]
        H = H + self_hessian[i]
    d = dxi + newton_increment(g, H)
    if colliders.records.shape[0] > 0:
        Hinv = wp.mat33(0.0)
        if wp.abs(wp.determinant(H)) >= 1.0e-30:
            Hinv = wp.inverse(H)
        d, n, vc, c, state, mu = project_increment(xi, d, colliders, h, H, Hinv)
        contact.normal[i] = n
        contact.velocity[i] = vc
        contact.force[i] = c
        contact.state[i] = state
        f = sliding_friction(mu, contact.resting[i], inertia.dy[i], vc, n, h, inertia.mass[i])
        contact.friction[i] = f
        if state == 2 or (mu > 0.0 and f == 0.0):  # held (translation_friction)
            wp.atomic_add(contact.held, 0, 1)
    dx[i] = d


@wp.kernel
def add_contact_forces(contact: ContactState, h: float, r: wp.array(dtype=wp.vec3)):
    # the multigrid residual where the last sweep held a contact: r = 0 (the collider holds it: a
    # correction must neither pull it in nor slide it along). Measured on the 16 x 16 drape: with
    # only r's inward normal part removed it slid off the sphere (the correction moved the contacts by
    # the tangential force friction holds); adding a sliding contact's collider force (h^2 c, normal
    # and kinetic friction) instead of zeroing it, it settled 1.8 cm off centre; with r = 0 at 7.0 s,
    # 5 mm off. (h: kept for that variant, with contact.force)
    i = wp.tid()
    if contact.state[i] != 0:
        r[i] = wp.vec3(0.0)


@wp.kernel
def copy_increment(dx: wp.array(dtype=wp.vec3), prev1: wp.array(dtype=wp.vec3), prev2: wp.array(dtype=wp.vec3)):
    # prev1 = prev2 = dx (the Chebyshev history starts at the initial guess)
    i = wp.tid()
    prev1[i] = dx[i]
    prev2[i] = dx[i]


@wp.kernel
def apply_chebyshev(
    omega: float, dx: wp.array(dtype=wp.vec3), prev1: wp.array(dtype=wp.vec3), prev2: wp.array(dtype=wp.vec3)
):
    # x^(n) = omega_n (xbar^(n) - x^(n-2)) + x^(n-2)   (Chen et al. 2024, eq. 17; Wang 2015)
    i = wp.tid()
    accelerated = omega * (dx[i] - prev2[i]) + prev2[i]
    prev2[i] = prev1[i]
    prev1[i] = accelerated
    dx[i] = accelerated


@wp.kernel
def eval_increment_residual(
    x: wp.array(dtype=wp.vec3),
    dx: wp.array(dtype=wp.vec3),
    inertia: Inertia,
    springs: SpringAdjacency,
    hinges: HingeAdjacency,
    h: float,
    r: wp.array(dtype=wp.vec3),
):
    # r_i = -h^2 g_i = m_i (dy_i - dx_i) + h^2 (sum_s f_s + sum_e f_e)  (the whole potential's negative gradient,
    # times h^2; f_e the dihedral hinges');  pinned: 0
    i = wp.tid()
    if inertia.inv_mass[i] == 0.0:
        r[i] = wp.vec3(0.0)
        return
    xi = x[i]
    dxi = dx[i]
    force = wp.vec3(0.0)
    for a in range(springs.offsets[i], springs.offsets[i + 1]):
        s = springs.spring[a]
        j = springs.other[a]
        f, _K = spring_gradient_hessian(
            x[j] - xi,
            dx[j] - dxi,
            springs.rest_length[s],
            springs.stiffness[s],
            springs.damping[s],
            springs.compression[s],
            h,
        )
        force = force + f
    if hinges.indices.shape[0] > 0:
        fb, _Hb = vertex_hinge_terms(i, x, dx, hinges, h)
        force = force + fb
    r[i] = inertia.mass[i] * (inertia.dy[i] - dxi) + (h * h) * force


@wp.kernel
def correction_dots(
    delta: wp.array(dtype=wp.vec3),
    r: wp.array(dtype=wp.vec3),
    q: wp.array(dtype=wp.vec3),
    sums: wp.array(dtype=float),
):
    # sums[0] += delta . r, sums[1] += delta . q  (q = A delta: the quadratic model along delta)
    i = wp.tid()
    d = delta[i]
    wp.atomic_add(sums, 0, wp.dot(d, r[i]))
    wp.atomic_add(sums, 1, wp.dot(d, q[i]))


#: correction_stretch_cap: a spring already past the cap may still lengthen by this factor a correction
CAP_SLACK = wp.constant(1.01)


@wp.kernel
def correction_stretch_cap(
    x: wp.array(dtype=wp.vec3),
    dx: wp.array(dtype=wp.vec3),
    delta: wp.array(dtype=wp.vec3),
    springs: wp.array(dtype=wp.vec2i),
    rest: wp.array(dtype=float),
    max_strain: float,
    cap: wp.array(dtype=float),
):
    # cap[0] = min (from 1) over springs of the largest alpha in [0, 1] with |a + alpha b| <= (1 + s) L0,
    # a = the spring's vector at x + dx, b = its change along delta: no spring stretched past the cap by
    # the correction; one already past it may lengthen by 1 % (CAP_SLACK). Held where it was, one such
    # spring stopped every correction for the rest of the tablecloth's run; left free, the landing blew
    # up (both measured). The quadratic model's A is the step's start's: a spring at its rest length
    # has no stiffness across its axis there, so a correction that turns it (a kink where the masked
    # correction drops to zero at a held particle) looks free to the model and stretches it by
    # d^2 / 2 L0 (the 64 x 64 tablecloth caught on its table's rounded edges: 106 %). a is the start's
    # difference plus the increments' (not a difference of the rounded x + dx)
    k = wp.tid()
    i = springs[k][0]
    j = springs[k][1]
    a = (x[j] - x[i]) + (dx[j] - dx[i])
    b = delta[j] - delta[i]
    bb = wp.dot(b, b)
    aa = wp.dot(a, a)
    c = wp.max((1.0 + max_strain) * rest[k], CAP_SLACK * wp.sqrt(aa))
    if bb == 0.0:
        return
    ab = wp.dot(a, b)
    alpha = (-ab + wp.sqrt(wp.max(ab * ab - bb * (aa - c * c), 0.0))) / bb
    if alpha < 1.0:
        wp.atomic_min(cap, 0, wp.max(alpha, 0.0))


@wp.kernel
def add_scaled_increment(
    delta: wp.array(dtype=wp.vec3),
    sums: wp.array(dtype=float),
    cap: wp.array(dtype=float),
    capped: int,
    dx: wp.array(dtype=wp.vec3),
):
    # dx += alpha delta, alpha = (delta . r) / (delta^T A delta) clamped to [0, 1]: the step along the
    # masked correction that minimises the step's quadratic model (0 where it does not descend). With
    # contacts the masked V-cycle is a poor direction (alpha 0.05-0.3 after the tablecloth lands; ~1
    # and above in free fall), and taken whole it stretched the cloth by 60 % in one correction
    i = wp.tid()
    num = sums[0]
    den = sums[1]
    alpha = float(0.0)
    if den > 0.0 and num > 0.0:
        alpha = wp.min(num / den, 1.0)
        if capped != 0:  # vbd_correction_strain > 0: correction_stretch_cap's bound
            alpha = wp.min(alpha, cap[0])
    dx[i] = dx[i] + alpha * delta[i]


@wp.func
def push_out(xi: wp.vec3, d: wp.vec3, colliders: Colliders):
    # x_i + d out of every collider it is within the thickness of, along the normal, no friction (planes
    # first, the others when x_i + d is in the box around them, as project_increment); returns d and
    # whether any collider held it
    records = colliders.records
    hit = int(0)
    for k in range(colliders.plane_count):
        phi, n = plane_contact(xi + d, records[k].a, records[k].b)
        depth = records[k].thickness - phi
        if depth > 0.0:
            d = d + depth * n
            hit = 1
    if in_box(xi + d, colliders.box):
        for k in range(colliders.plane_count, records.shape[0]):
            phi, n = shape_contact(records, k, xi + d, contact_band(records, k))
            depth = records[k].thickness - phi
            if depth > 0.0:
                d = d + depth * n
                hit = 1
    return d, hit


@wp.kernel
def mask_contacts(
    x: wp.array(dtype=wp.vec3),
    dx: wp.array(dtype=wp.vec3),
    contact: ContactState,
    colliders: Colliders,
    delta: wp.array(dtype=wp.vec3),
):
    # the multigrid correction delta = 0 where the last sweep held a contact, and where x + dx + delta
    # would be within a collider's thickness. The V-cycle's A (the step's start) has neither the
    # contacts' constraints nor their stiffness: its correction moved held particles along the
    # collider and free ones into it, which the next sweep projected back with friction, a kink of the
    # correction's size (the 64 x 64 tablecloth and drape blew up on landing; only the inward normal
    # part removed at held contacts, the tablecloth still blew up at 0.7 s, measured)
    i = wp.tid()
    if contact.state[i] != 0:
        delta[i] = wp.vec3(0.0)
        return
    _pushed, hit = push_out(x[i] + dx[i], delta[i], colliders)
    if hit != 0:
        delta[i] = wp.vec3(0.0)


@wp.kernel
def push_out_increment(
    x: wp.array(dtype=wp.vec3), inv_mass: wp.array(dtype=float), colliders: Colliders, dx: wp.array(dtype=wp.vec3)
):
    # x + dx out of every collider it is within the thickness of, along the normal (no friction; the
    # contact states of the last sweep kept); pinned particles stay
    i = wp.tid()
    if inv_mass[i] == 0.0:
        return
    d, _hit = push_out(x[i], dx[i], colliders)
    dx[i] = d


# -- the rigid rotation of a free cloth's step (vbd's angular momentum; issue 51) -------------------
@wp.kernel
def rotation_mode_chunks(
    x: wp.array(dtype=wp.vec3),
    dx: wp.array(dtype=wp.vec3),
    inertia: Inertia,
    chunk: int,
    count: int,
    scalars: wp.array(dtype=wp.float64),
    vectors: wp.array(dtype=wp.vec3d),
    matrices: wp.array(dtype=wp.mat33d),
):
    # chunk c's float64 sums in index order (a fixed order), with p = (x_i - x_0) + dx_i (the step's end
    # relative to particle 0's start: no float32 cancellation of |x|) and e = dx - dy:
    # scalars[2c..] = sum m, sum m p.e;  vectors[3c..] = sum m p, sum m p x e, sum m e;
    # matrices[2c..] = sum m p p^T, sum m p e^T
    c = wp.tid()
    sm = wp.float64(0.0)
    spe = wp.float64(0.0)
    sp = wp.vec3d()
    spxe = wp.vec3d()
    se = wp.vec3d()
    spp = wp.mat33d()
    spet = wp.mat33d()
    x0 = x[0]
    for i in range(c * chunk, wp.min((c + 1) * chunk, count)):
        m = wp.float64(inertia.mass[i])
        p = wp.vec3d((x[i] - x0) + dx[i])
        e = wp.vec3d(dx[i]) - wp.vec3d(inertia.dy[i])
        sm = sm + m
        spe = spe + m * wp.dot(p, e)
        sp = sp + m * p
        spxe = spxe + m * wp.cross(p, e)
        se = se + m * e
        spp = spp + m * wp.outer(p, p)
        spet = spet + m * wp.outer(p, e)
    scalars[2 * c] = sm
    scalars[2 * c + 1] = spe
    vectors[3 * c] = sp
    vectors[3 * c + 1] = spxe
    vectors[3 * c + 2] = se
    matrices[2 * c] = spp
    matrices[2 * c + 1] = spet


@wp.kernel
def solve_rotation_mode(
    scalars: wp.array(dtype=wp.float64),
    vectors: wp.array(dtype=wp.vec3d),
    matrices: wp.array(dtype=wp.mat33d),
    out: wp.array(dtype=wp.vec3),
):
    # the rotation w about the mass centre cm of x + dx (relative to x_0) for which dx_i += w x r_i,
    # r_i = p_i - cm, gives sum m r x (dx - dy) = 0: backward Euler's angular momentum law, met by the
    # converged step (internal forces are central or rotation invariant; f_ext's torque is in dy).
    # Exactly linear in w ((w x r) x (w x r) = 0): (J + sum m (r e^T - (r.e) I)) w = -sum m r x e,
    # J = sum m (|r|^2 I - r r^T). sum m (w x r) = w x sum m r = 0: the momentum is unchanged.
    # out[0] = w, out[1] = cm; w = 0 where the matrix is singular (a cloth on a line)
    sm = wp.float64(0.0)
    spe = wp.float64(0.0)
    sp = wp.vec3d()
    spxe = wp.vec3d()
    se = wp.vec3d()
    spp = wp.mat33d()
    spet = wp.mat33d()
    for c in range(scalars.shape[0] // 2):
        sm = sm + scalars[2 * c]
        spe = spe + scalars[2 * c + 1]
        sp = sp + vectors[3 * c]
        spxe = spxe + vectors[3 * c + 1]
        se = se + vectors[3 * c + 2]
        spp = spp + matrices[2 * c]
        spet = spet + matrices[2 * c + 1]
    eye = wp.identity(n=3, dtype=wp.float64)
    cm = sp / sm
    rxe = spxe - wp.cross(cm, se)  # sum m r x e
    rr = spp - sm * wp.outer(cm, cm)  # sum m r r^T
    re = spet - wp.outer(cm, se)  # sum m r e^T
    A = (wp.trace(rr) * eye - rr) + (re - wp.trace(re) * eye)
    w = wp.vec3d()
    det = wp.determinant(A)
    scale = wp.trace(rr)
    if wp.abs(det) > wp.float64(1.0e-9) * scale * scale * scale:
        w = -(wp.inverse(A) * rxe)
    out[0] = wp.vec3(w)
    out[1] = wp.vec3(cm)


@wp.kernel
def apply_rotation_mode(x: wp.array(dtype=wp.vec3), rotation: wp.array(dtype=wp.vec3), dx: wp.array(dtype=wp.vec3)):
    # dx_i += w x (p_i - cm), p_i = (x_i - x_0) + dx_i  (w, cm: solve_rotation_mode)
    i = wp.tid()
    d = dx[i]
    r = ((x[i] - x[0]) + d) - rotation[1]
    dx[i] = d + wp.cross(rotation[0], r)
