"""Projective dynamics, Liu, Bargteil, O'Brien & Kavan 2013 ("Fast simulation of mass-spring
systems"), solved for the increment dx = x_new - x.

Local step: each spring s = (i, j) is projected to its rest length, d_s = L0 e / |e| with
e = x_j - x_i + dx_j - dx_i. Global step: with S = M + h D + h^2 L (L = sum_s ks A_s^T A_s and
D = sum_s kd A_s^T A_s, scalar graph Laplacians, constant for fixed h and topology; the same for
x, y and z), one local-global iteration solves S delta = r and sets dx += delta, with

    r_i = m_i (dy_i - dx_i) + h^2 sum_s ks (|e| - L0) n + h sum_s kd ((dx_j - dx_i) . n) n,

the residual of the backward-Euler step at the current dx (the projection term is the gradient
of the PD objective; the damping is along each spring, as in the force-based integrators, with
S's isotropic h D as its approximate Jacobian, so the iteration converges to axial damping and a
rigid rotation is not damped; solving for delta from 0 is PCG warm-started at the previous dx). Pinned
particles have identity rows and zero columns (their dx is 0). The solve is Jacobi-preconditioned
CG with a fixed number of iterations: scalars (r.z, p.Ap) live in device arrays, one per
iteration, so a step never reads back to the host. Dot products are reduced in a fixed order
(per-particle terms, sums over fixed chunks, then the chunks' sum by one thread), not with
atomics, so results are bit-identical run to run and between launches and graph replay on CUDA
too.
"""

import warp as wp

from warpcloth.kernels.bending import HingeAdjacency, vertex_hinge_terms
from warpcloth.kernels.collide import Colliders
from warpcloth.kernels.increment import (
    ContactState,
    Inertia,
    newton_increment,
    project_increment,
    vertex_gradient_hessian,
)
from warpcloth.kernels.springs import SpringAdjacency, compressed_stiffness

# forward only: no adjoints (half the compile time; warpcloth differentiates nothing)
wp.set_module_options({"enable_backward": False})


@wp.func
def spring_increment_residual(e: wp.vec3, ddx: wp.vec3, rest: float, ks: float, kd: float, phi: float, h: float):
    # h^2 k (e - d), d = L0 e / |e| (the spring projected to its rest length) = h^2 k (|e| - L0) n (k = ks, or
    # phi ks where |e| < L0: the projection d moved back towards e by 1 - phi), and
    # the damping along the spring, h kd ((dx_j - dx_i) . n) n (as the force-based integrators'): S's
    # isotropic h D only approximates its Jacobian, so a rigid rotation is not damped
    length = wp.length(e)
    if length == 0.0:
        return wp.vec3(0.0)
    n = e / length
    k = compressed_stiffness(length, rest, ks, phi)
    return (h * h) * (k * (length - rest) / length * e) + (h * kd * wp.dot(ddx, n)) * n


@wp.func
def restart_cg(
    i: int,
    res: wp.vec3,
    inv: float,
    r: wp.array(dtype=wp.vec3),
    z: wp.array(dtype=wp.vec3),
    p: wp.array(dtype=wp.vec3),
    dot_terms: wp.array(dtype=float),
):
    # r_i = res and CG's start from it: z = P^-1 r (inv: P^-1 at i), p = z, dot_terms = r.z
    zi = inv * res
    r[i] = res
    z[i] = zi
    p[i] = zi
    dot_terms[i] = wp.dot(res, zi)


@wp.kernel
def assemble_global_matrix(
    springs: SpringAdjacency,
    row_offsets: wp.array(dtype=int),
    particle_mass: wp.array(dtype=float),
    particle_inv_mass: wp.array(dtype=float),
    h: float,
    values: wp.array(dtype=float),
    inv_diag: wp.array(dtype=float),
):
    # row i of S = M + h D + h^2 L (CSR: diagonal first, then one entry per adjacent spring, then the
    # dihedral hinges' other pairs, left alone here): S_ii = m_i + sum_s w_s, S_ij = -w_s, w_s = h^2 ks + h kd;
    # pinned: identity row, zero column
    i = wp.tid()
    row = row_offsets[i]
    if particle_inv_mass[i] == 0.0:
        values[row] = 1.0
        for a in range(springs.offsets[i], springs.offsets[i + 1]):
            values[row + 1 + a - springs.offsets[i]] = 0.0
        inv_diag[i] = 1.0
        return
    diag = particle_mass[i]
    for a in range(springs.offsets[i], springs.offsets[i + 1]):
        s = springs.spring[a]
        w = h * h * springs.stiffness[s] + h * springs.damping[s]
        diag = diag + w
        off = -w
        if particle_inv_mass[springs.other[a]] == 0.0:
            off = 0.0
        values[row + 1 + a - springs.offsets[i]] = off
    values[row] = diag
    inv_diag[i] = 1.0 / diag


@wp.kernel
def eval_local_residual(
    x: wp.array(dtype=wp.vec3),
    dx: wp.array(dtype=wp.vec3),
    inertia: Inertia,
    springs: SpringAdjacency,
    inv_diag: wp.array(dtype=float),
    h: float,
    contact: ContactState,
    r: wp.array(dtype=wp.vec3),
    z: wp.array(dtype=wp.vec3),
    p: wp.array(dtype=wp.vec3),
    dot_terms: wp.array(dtype=float),
):
    # local step + residual (module docstring); CG start: z = P^-1 r, p = z, dot_terms = r.z; a
    # particle stuck on a collider (contact state 2, from the last contact pass) is fixed in the solve,
    # as a pin; a sliding one's collider force (normal and kinetic friction) enters its residual
    i = wp.tid()
    if inertia.inv_mass[i] == 0.0 or contact.state[i] == 2:
        r[i] = wp.vec3(0.0)
        z[i] = wp.vec3(0.0)
        p[i] = wp.vec3(0.0)
        dot_terms[i] = 0.0
        return
    xi = x[i]
    dxi = dx[i]
    res = inertia.mass[i] * (inertia.dy[i] - dxi)
    for a in range(springs.offsets[i], springs.offsets[i + 1]):
        s = springs.spring[a]
        j = springs.other[a]
        ddx = dx[j] - dxi
        res = res + spring_increment_residual(
            (x[j] - xi) + ddx,
            ddx,
            springs.rest_length[s],
            springs.stiffness[s],
            springs.damping[s],
            springs.compression[s],
            h,
        )
    if contact.state[i] == 1:
        res = res + (h * h) * contact.force[i]
    restart_cg(i, res, inv_diag[i], r, z, p, dot_terms)


@wp.kernel
def add_hinge_matrix_terms(
    row_offsets: wp.array(dtype=int),
    hinge_K: wp.array(dtype=float),
    hinge_D: wp.array(dtype=float),
    particle_inv_mass: wp.array(dtype=float),
    h: float,
    values: wp.array(dtype=float),
    inv_diag: wp.array(dtype=float),
):
    # S += h^2 sum_e k_e c c^T + h sum_e kd_e c c^T (constant, per CSR entry; 0 on pinned rows and columns),
    # then the Jacobi inverse diagonal of the new rows
    i = wp.tid()
    for e in range(row_offsets[i], row_offsets[i + 1]):
        values[e] = values[e] + (h * h) * hinge_K[e] + h * hinge_D[e]
    if particle_inv_mass[i] != 0.0:
        inv_diag[i] = 1.0 / values[row_offsets[i]]


@wp.kernel
def add_hinge_residual(
    x: wp.array(dtype=wp.vec3),
    dx: wp.array(dtype=wp.vec3),
    inertia: Inertia,
    hinges: HingeAdjacency,
    inv_diag: wp.array(dtype=float),
    h: float,
    contact: ContactState,
    r: wp.array(dtype=wp.vec3),
    z: wp.array(dtype=wp.vec3),
    p: wp.array(dtype=wp.vec3),
    dot_terms: wp.array(dtype=float),
):
    # after eval_local_residual: r_i += h^2 f_i of the dihedral hinges (their true forces, damping with the dx / h
    # rate as the springs'; S's constant h^2 k c c^T + h kd c c^T approximates their Jacobian), and CG's start again
    i = wp.tid()
    if inertia.inv_mass[i] == 0.0 or contact.state[i] == 2:
        return
    f, _H = vertex_hinge_terms(i, x, dx, hinges, h)
    res = r[i] + (h * h) * f
    restart_cg(i, res, inv_diag[i], r, z, p, dot_terms)


@wp.kernel
def solve_contacts(
    x: wp.array(dtype=wp.vec3),
    dx: wp.array(dtype=wp.vec3),
    inertia: Inertia,
    springs: SpringAdjacency,
    hinges: HingeAdjacency,
    h: float,
    colliders: Colliders,
    out: wp.array(dtype=wp.vec3),
    contact: ContactState,
):
    # after a global step: a particle in contact (the last pass's) takes VBD's local Newton step on
    # the same potential (its 3 x 3 Hessian, neighbours fixed; Jacobi: reads dx, writes out),
    # constrained by the colliders with Coulomb friction (kernels.increment.project_increment); a free one
    # that the global step took into a collider is projected out (isotropic: its H is not formed).
    # The contact's normal (0: released), collider velocity, force and state are kept for the next
    # global step (stuck: fixed in it; sliding: its force in the residual)
    i = wp.tid()
    d = dx[i]
    if inertia.inv_mass[i] == 0.0:
        out[i] = d
        return
    xi = x[i]
    eye = wp.identity(n=3, dtype=float)
    H = eye
    Hinv = eye
    if contact.state[i] != 0:
        g, H = vertex_gradient_hessian(i, x, dx, inertia, springs, h)
        if hinges.indices.shape[0] > 0:
            fb, Hb = vertex_hinge_terms(i, x, dx, hinges, h)
            g = g - fb
            H = H + Hb
        d = d + newton_increment(g, H)
        if wp.abs(wp.determinant(H)) >= 1.0e-30:
            Hinv = wp.inverse(H)
        else:
            H = eye
    d, n, vc, c, state, _mu = project_increment(xi, d, colliders, h, H, Hinv)
    out[i] = d
    contact.normal[i] = n
    contact.velocity[i] = vc
    contact.force[i] = c
    contact.state[i] = state


@wp.kernel
def csr_matvec_dot(
    row_offsets: wp.array(dtype=int),
    columns: wp.array(dtype=int),
    values: wp.array(dtype=float),
    p: wp.array(dtype=wp.vec3),
    weight: wp.array(dtype=float),
    Ap: wp.array(dtype=wp.vec3),
    dot_terms: wp.array(dtype=float),
):
    # Ap = (S + W) p (scalar CSR on vec3: the same matrix for x, y and z; W the self-contacts' diagonal
    # weights, 0 without them);  dot_terms = p.Ap
    i = wp.tid()
    acc = wp.vec3(0.0)
    for e in range(row_offsets[i], row_offsets[i + 1]):
        acc = acc + values[e] * p[columns[e]]
    acc = acc + weight[i] * p[i]
    Ap[i] = acc
    dot_terms[i] = wp.dot(p[i], acc)


@wp.kernel
def cg_update_solution(
    p: wp.array(dtype=wp.vec3),
    Ap: wp.array(dtype=wp.vec3),
    inv_diag: wp.array(dtype=float),
    rz: wp.array(dtype=float),
    pAp: wp.array(dtype=float),
    k: int,
    contact_state: wp.array(dtype=int),
    dx: wp.array(dtype=wp.vec3),
    r: wp.array(dtype=wp.vec3),
    z: wp.array(dtype=wp.vec3),
    dot_terms: wp.array(dtype=float),
):
    # alpha = r.z / p.Ap ;  dx += alpha p ;  r -= alpha Ap ;  z = P^-1 r ;  dot_terms = r.z (new);
    # a stuck particle's z stays 0 (CG on the others only: its p stays 0)
    i = wp.tid()
    alpha = float(0.0)
    if pAp[k] > 0.0:
        alpha = rz[k] / pAp[k]
    dx[i] = dx[i] + alpha * p[i]
    ri = r[i] - alpha * Ap[i]
    zi = inv_diag[i] * ri
    if contact_state[i] == 2:
        ri = wp.vec3(0.0)
        zi = wp.vec3(0.0)
    r[i] = ri
    z[i] = zi
    dot_terms[i] = wp.dot(ri, zi)


@wp.kernel
def cg_update_direction(z: wp.array(dtype=wp.vec3), rz: wp.array(dtype=float), k: int, p: wp.array(dtype=wp.vec3)):
    # beta = r.z (new) / r.z (old) ;  p = z + beta p
    i = wp.tid()
    beta = float(0.0)
    if rz[k] > 0.0:
        beta = rz[k + 1] / rz[k]
    p[i] = z[i] + beta * p[i]


# -- the global system's rigid translation, solved exactly before CG (issue 26) ---------------------
@wp.func
def free_row_sum(
    i: int,
    row_offsets: wp.array(dtype=int),
    columns: wp.array(dtype=int),
    values: wp.array(dtype=float),
    particle_inv_mass: wp.array(dtype=float),
):
    # sum_j S_ij over the free columns of row i (pinned columns hold 0): S applied to a translation
    acc = float(0.0)
    for e in range(row_offsets[i], row_offsets[i + 1]):
        if particle_inv_mass[columns[e]] != 0.0:
            acc = acc + values[e]
    return acc


@wp.kernel
def translation_terms(
    r: wp.array(dtype=wp.vec3),
    row_offsets: wp.array(dtype=int),
    columns: wp.array(dtype=int),
    values: wp.array(dtype=float),
    particle_inv_mass: wp.array(dtype=float),
    weight: wp.array(dtype=float),
    target: wp.array(dtype=wp.vec3),
    dx: wp.array(dtype=wp.vec3),
    b: wp.array(dtype=wp.vec3),
    A: wp.array(dtype=wp.mat33),
):
    # the global system's Galerkin problem on the rigid translation T (free particles move by t):
    # T^T r = sum r_i, T^T S T = sum_i sum_(j free) S_ij (times I: S is scalar); pinned rows 0. The
    # self-contacts' linear terms W (target - dx) are taken out of r, and W out of T^T S T: the contacts
    # are equal and opposite, translation-invariant (their true terms sum to 0 at any dx), which the
    # diagonal W with fixed targets is not (add_self_contact_terms)
    i = wp.tid()
    if particle_inv_mass[i] == 0.0:
        b[i] = wp.vec3(0.0)
        A[i] = wp.mat33(0.0)
        return
    b[i] = r[i] - weight[i] * (target[i] - dx[i])
    A[i] = free_row_sum(i, row_offsets, columns, values, particle_inv_mass) * wp.identity(n=3, dtype=float)


@wp.kernel
def apply_translation(
    translation: wp.array(dtype=wp.vec3),
    row_offsets: wp.array(dtype=int),
    columns: wp.array(dtype=int),
    values: wp.array(dtype=float),
    particle_inv_mass: wp.array(dtype=float),
    weight: wp.array(dtype=float),
    inv_diag: wp.array(dtype=float),
    dx: wp.array(dtype=wp.vec3),
    r: wp.array(dtype=wp.vec3),
    z: wp.array(dtype=wp.vec3),
    p: wp.array(dtype=wp.vec3),
    dot_terms: wp.array(dtype=float),
):
    # dx += t, r -= (S + W) T t = (sum_(j free) S_ij + W_i) t on the free particles (the linear system CG
    # goes on with); CG's start again: z = P^-1 r, p = z, r.z
    i = wp.tid()
    if particle_inv_mass[i] == 0.0:
        return
    t = translation[0]
    dx[i] = dx[i] + t
    res = r[i] - (free_row_sum(i, row_offsets, columns, values, particle_inv_mass) + weight[i]) * t
    restart_cg(i, res, inv_diag[i], r, z, p, dot_terms)


# -- self-contacts in the global system (issue 29) ----------------------------------------------------
@wp.kernel
def add_self_contact_terms(
    dx: wp.array(dtype=wp.vec3),
    target: wp.array(dtype=wp.vec3),
    inertia: Inertia,
    contact_state: wp.array(dtype=int),
    weight_per_mass: float,
    inv_diag: wp.array(dtype=float),
    weight: wp.array(dtype=float),
    precond: wp.array(dtype=float),
    r: wp.array(dtype=wp.vec3),
    z: wp.array(dtype=wp.vec3),
    p: wp.array(dtype=wp.vec3),
    dot_terms: wp.array(dtype=float),
):
    # after the local step: a vertex the self-contacts' projection moved (target != dx) is drawn to its
    # projected position by a projective constraint of weight W_i = weight_per_mass m_i: r_i += W_i
    # (target_i - dx_i), S_ii += W_i (W proportional to m, so sum_i W_i (target_i - dx_i) = 0 where no vertex is
    # held: the projection's corrections are equal and opposite in momentum; the translation steps take these
    # terms out of r anyway, translation_terms); the Jacobi preconditioner 1 / (S_ii + W_i) and CG's start again
    i = wp.tid()
    w = float(0.0)
    if inertia.inv_mass[i] != 0.0 and contact_state[i] != 2:
        d = target[i] - dx[i]
        if wp.length_sq(d) > 0.0:
            w = weight_per_mass * inertia.mass[i]
            r[i] = r[i] + w * d
    weight[i] = w
    inv = inv_diag[i]
    if w > 0.0:
        inv = 1.0 / (1.0 / inv + w)
    precond[i] = inv
    restart_cg(i, r[i], inv, r, z, p, dot_terms)
