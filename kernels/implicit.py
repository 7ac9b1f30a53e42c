"""Implicit Euler (Baraff & Witkin 1998; seed eq. 2.19-2.23): spring Jacobians, system assembly,
right-hand side and the velocity update.

The linear system of one step is

    A dv = b,   A = M - h df/dv - h^2 df/dx,   b = h (f + h df/dx v).

Per spring s = (i, j), d = x_j - x_i, L = |d|, n = d / L, the Jacobian blocks are

    K_s = df_i/dx_j = ks [ n n^T + max(0, 1 - L0/L) (I - n n^T) ],   df_i/dx_i = -K_s,
    D_s = df_i/dv_j = kd n n^T,                                       df_i/dv_i = -D_s,

so with B_s = h^2 K_s + h D_s, row i of A is A_ii = m_i (1 + h c) I + sum_s B_s, A_ij = -B_s
(c the linear air drag rate). Pinned particles (inverse mass 0) get identity rows and zero
columns, so their dv is 0. The row kernels gather over a particle's springs through a
particle -> (spring, neighbour, block) adjacency built once at bind: no atomics.
"""

import warp as wp

from warpcloth.kernels.collide import Collider, collider_contact, surface_velocity

# forward only: no adjoints (half the compile time; warpcloth differentiates nothing)
wp.set_module_options({"enable_backward": False})


@wp.func
def spring_stiffness_block(xi: wp.vec3, xj: wp.vec3, rest: float, ks: float):
    """K = df_i/dx_j = ks [n n^T + max(0, 1 - L0/L) (I - n n^T)] [N/m] (design.md).

    The exact geometric term (1 - L0/L)(I - n n^T) is negative for a compressed spring
    (L < L0) and can make A indefinite; clamping it at 0 keeps K positive semi-definite, so
    A = M - h df/dv - h^2 df/dx stays symmetric positive definite and CG applies. For a
    stretched spring K is the exact Jacobian.
    """
    d = xj - xi
    length = wp.length(d)
    if length == 0.0:
        return wp.mat33(0.0)
    n = d / length
    nnt = wp.outer(n, n)
    geometric = wp.max(0.0, 1.0 - rest / length)
    return ks * (nnt + geometric * (wp.identity(n=3, dtype=float) - nnt))


@wp.func
def spring_damping_block(xi: wp.vec3, xj: wp.vec3, kd: float):
    """D = df_i/dv_j = kd n n^T [N s/m] (the damping force acts along the spring)."""
    d = xj - xi
    length = wp.length(d)
    if length == 0.0:
        return wp.mat33(0.0)
    n = d / length
    return kd * wp.outer(n, n)


@wp.kernel
def eval_spring_jacobians(
    x: wp.array(dtype=wp.vec3),
    spring_indices: wp.array(dtype=wp.vec2i),
    spring_rest_length: wp.array(dtype=float),
    spring_stiffness: wp.array(dtype=float),
    spring_damping: wp.array(dtype=float),
    h: float,
    spring_K: wp.array(dtype=wp.mat33),
    spring_B: wp.array(dtype=wp.mat33),
):
    # K_s = ks [n n^T + max(0, 1 - L0/L)(I - n n^T)],  B_s = h^2 K_s + h kd n n^T   (full Jacobian)
    s = wp.tid()
    ij = spring_indices[s]
    xi = x[ij[0]]
    xj = x[ij[1]]
    K = spring_stiffness_block(xi, xj, spring_rest_length[s], spring_stiffness[s])
    spring_K[s] = K
    spring_B[s] = (h * h) * K + h * spring_damping_block(xi, xj, spring_damping[s])


@wp.kernel
def eval_spring_jacobians_approx(
    spring_stiffness: wp.array(dtype=float),
    spring_damping: wp.array(dtype=float),
    h: float,
    spring_K: wp.array(dtype=wp.mat33),
    spring_B: wp.array(dtype=wp.mat33),
):
    # K_s = ks I,  B_s = (h^2 ks + h kd) I   (seed eq. 2.23: H_ij = k_ij, H_ii = -sum_j k_ij; constant)
    s = wp.tid()
    eye = wp.identity(n=3, dtype=float)
    spring_K[s] = spring_stiffness[s] * eye
    spring_B[s] = (h * h * spring_stiffness[s] + h * spring_damping[s]) * eye


@wp.func
def inverse_diagonal(a: wp.mat33):
    # the Jacobi preconditioner of one row block: 1 / diag(A_ii)
    return wp.vec3(1.0 / a[0, 0], 1.0 / a[1, 1], 1.0 / a[2, 2])


@wp.kernel
def assemble_system_rows(
    adjacency_offsets: wp.array(dtype=int),
    adjacency_spring: wp.array(dtype=int),
    adjacency_other: wp.array(dtype=int),
    adjacency_block: wp.array(dtype=int),
    row_offsets: wp.array(dtype=int),
    diag_block: wp.array(dtype=int),
    spring_B: wp.array(dtype=wp.mat33),
    particle_mass: wp.array(dtype=float),
    particle_inv_mass: wp.array(dtype=float),
    drag_rate: float,
    h: float,
    values: wp.array(dtype=wp.mat33),
    inv_diag: wp.array(dtype=wp.vec3),
):
    # row i of A: A_ii = m (1 + h c) I + sum_s B_s,  A_ij = -B_s;  pinned: identity row, zero column;
    # inv_diag = 1 / diag(A_ii)  (Jacobi)
    i = wp.tid()
    for b in range(row_offsets[i], row_offsets[i + 1]):
        values[b] = wp.mat33(0.0)
    if particle_inv_mass[i] == 0.0:
        values[diag_block[i]] = wp.identity(n=3, dtype=float)
        inv_diag[i] = wp.vec3(1.0)
        return
    diag = (particle_mass[i] * (1.0 + h * drag_rate)) * wp.identity(n=3, dtype=float)
    for a in range(adjacency_offsets[i], adjacency_offsets[i + 1]):
        block = spring_B[adjacency_spring[a]]
        diag = diag + block
        if particle_inv_mass[adjacency_other[a]] != 0.0:
            b = adjacency_block[a]
            values[b] = values[b] - block
    values[diag_block[i]] = diag
    inv_diag[i] = inverse_diagonal(diag)


@wp.kernel
def eval_system_diagonal(
    adjacency_offsets: wp.array(dtype=int),
    adjacency_spring: wp.array(dtype=int),
    spring_B: wp.array(dtype=wp.mat33),
    particle_mass: wp.array(dtype=float),
    particle_inv_mass: wp.array(dtype=float),
    drag_rate: float,
    h: float,
    mass_term: wp.array(dtype=float),
    inv_diag: wp.array(dtype=wp.vec3),
):
    # matrix-free: mass_term = m (1 + h c) (1 on pins),  inv_diag = 1 / diag(m (1 + h c) I + sum_s B_s)
    i = wp.tid()
    if particle_inv_mass[i] == 0.0:
        mass_term[i] = 1.0
        inv_diag[i] = wp.vec3(1.0)
        return
    md = particle_mass[i] * (1.0 + h * drag_rate)
    diag = md * wp.identity(n=3, dtype=float)
    for a in range(adjacency_offsets[i], adjacency_offsets[i + 1]):
        diag = diag + spring_B[adjacency_spring[a]]
    mass_term[i] = md
    inv_diag[i] = inverse_diagonal(diag)


@wp.func
def inverse_block(a: wp.mat33):
    # the block-Jacobi preconditioner of one row block: A_ii^-1 (SPD, so det > 0)
    det = wp.determinant(a)
    if det <= 0.0:
        return wp.identity(n=3, dtype=float)
    return wp.inverse(a)


@wp.kernel
def eval_inverse_diagonal_blocks(
    adjacency_offsets: wp.array(dtype=int),
    adjacency_spring: wp.array(dtype=int),
    spring_B: wp.array(dtype=wp.mat33),
    particle_mass: wp.array(dtype=float),
    particle_inv_mass: wp.array(dtype=float),
    drag_rate: float,
    h: float,
    inv_block: wp.array(dtype=wp.mat33),
):
    # block Jacobi: inv_block_i = (m (1 + h c) I + sum_s B_s)^-1;  pinned: I
    i = wp.tid()
    if particle_inv_mass[i] == 0.0:
        inv_block[i] = wp.identity(n=3, dtype=float)
        return
    diag = (particle_mass[i] * (1.0 + h * drag_rate)) * wp.identity(n=3, dtype=float)
    for a in range(adjacency_offsets[i], adjacency_offsets[i + 1]):
        diag = diag + spring_B[adjacency_spring[a]]
    inv_block[i] = inverse_block(diag)


@wp.kernel
def apply_block_diagonal(
    x: wp.array(dtype=wp.vec3),
    y: wp.array(dtype=wp.vec3),
    blocks: wp.array(dtype=wp.mat33),
    alpha: float,
    beta: float,
    z: wp.array(dtype=wp.vec3),
):
    # z = alpha P x + beta y, P block diagonal (block Jacobi: P_ii = A_ii^-1)
    i = wp.tid()
    out = alpha * (blocks[i] * x[i])
    if beta != 0.0:
        out = out + beta * y[i]
    z[i] = out


@wp.kernel
def smooth_jacobi(
    residual: wp.array(dtype=wp.vec3),
    inv_block: wp.array(dtype=wp.mat33),
    omega: float,
    from_zero: int,
    x: wp.array(dtype=wp.vec3),
):
    # damped block Jacobi: x <- x + omega D^-1 (b - A x)  (residual = b - A x given; from_zero: x = 0 before)
    i = wp.tid()
    step = omega * (inv_block[i] * residual[i])
    if from_zero != 0:
        x[i] = step
    else:
        x[i] = x[i] + step


@wp.kernel
def scale_add(x: wp.array(dtype=wp.vec3), y: wp.array(dtype=wp.vec3), alpha: float, beta: float, z: wp.array(dtype=wp.vec3)):
    # z = alpha x + beta y
    i = wp.tid()
    out = alpha * x[i]
    if beta != 0.0:
        out = out + beta * y[i]
    z[i] = out


@wp.kernel
def galerkin_product(
    term_offsets: wp.array(dtype=int),
    term_source: wp.array(dtype=int),
    term_weight: wp.array(dtype=float),
    fine_values: wp.array(dtype=wp.mat33),
    coarse_values: wp.array(dtype=wp.mat33),
):
    # (P^T A P)_IJ = sum_(f, g) P_fI A_fg P_gJ: a gather over a fixed list of (fine block, P_fI P_gJ)
    c = wp.tid()
    acc = wp.mat33(0.0)
    for t in range(term_offsets[c], term_offsets[c + 1]):
        acc = acc + term_weight[t] * fine_values[term_source[t]]
    coarse_values[c] = acc


@wp.kernel
def eval_rhs(
    f: wp.array(dtype=wp.vec3),
    v: wp.array(dtype=wp.vec3),
    adjacency_offsets: wp.array(dtype=int),
    adjacency_spring: wp.array(dtype=int),
    adjacency_other: wp.array(dtype=int),
    spring_K: wp.array(dtype=wp.mat33),
    particle_inv_mass: wp.array(dtype=float),
    h: float,
    b: wp.array(dtype=wp.vec3),
):
    # b_i = h (f_i + h (df/dx v)_i),  (df/dx v)_i = sum_s K_s (v_j - v_i);  b = 0 on pins
    i = wp.tid()
    if particle_inv_mass[i] == 0.0:
        b[i] = wp.vec3(0.0)
        return
    vi = v[i]
    kv = wp.vec3(0.0)
    for a in range(adjacency_offsets[i], adjacency_offsets[i + 1]):
        kv = kv + spring_K[adjacency_spring[a]] * (v[adjacency_other[a]] - vi)
    b[i] = h * (f[i] + h * kv)


@wp.kernel
def apply_system_matrix(
    x: wp.array(dtype=wp.vec3),
    y: wp.array(dtype=wp.vec3),
    adjacency_offsets: wp.array(dtype=int),
    adjacency_spring: wp.array(dtype=int),
    adjacency_other: wp.array(dtype=int),
    spring_B: wp.array(dtype=wp.mat33),
    mass_term: wp.array(dtype=float),
    particle_inv_mass: wp.array(dtype=float),
    alpha: float,
    beta: float,
    z: wp.array(dtype=wp.vec3),
):
    # z = alpha A x + beta y, matrix-free: (A x)_i = m (1 + h c) x_i + sum_s B_s (x_i - x_j), x_j = 0 on pins
    i = wp.tid()
    xi = x[i]
    ax = mass_term[i] * xi
    if particle_inv_mass[i] != 0.0:
        for a in range(adjacency_offsets[i], adjacency_offsets[i + 1]):
            j = adjacency_other[a]
            xj = wp.vec3(0.0)
            if particle_inv_mass[j] != 0.0:
                xj = x[j]
            ax = ax + spring_B[adjacency_spring[a]] * (xi - xj)
    out = alpha * ax
    if beta != 0.0:
        out = out + beta * y[i]
    z[i] = out


@wp.kernel
def integrate_implicit_euler(
    x: wp.array(dtype=wp.vec3),
    v: wp.array(dtype=wp.vec3),
    dv: wp.array(dtype=wp.vec3),
    particle_inv_mass: wp.array(dtype=float),
    h: float,
):
    # v <- v + dv ;  x <- x + h v   (pinned particles never move)
    i = wp.tid()
    if particle_inv_mass[i] == 0.0:
        return
    v_new = v[i] + dv[i]
    v[i] = v_new
    x[i] = x[i] + h * v_new


@wp.kernel
def record_cg_stats(
    iterations: wp.array(dtype=int),
    residual_sq: wp.array(dtype=float),
    tolerance_sq: wp.array(dtype=float),
    tol: float,
    stats: wp.array(dtype=wp.float64),
):
    # stats = [solves, sum iterations, max iterations, sum residual, max residual, capped solves],
    # residual = |r| / |b| = tol sqrt(r.r / atol^2) with atol = tol |b|; a solve is capped when it
    # ended above its tolerance (CG stops early only when r.r <= atol^2, as warp's cg tests it;
    # a NaN residual counts as capped)
    it = wp.float64(iterations[0])
    res = wp.float64(tol * wp.sqrt(residual_sq[0] / wp.max(tolerance_sq[0], 1.0e-30)))
    stats[0] = stats[0] + wp.float64(1.0)
    stats[1] = stats[1] + it
    stats[2] = wp.max(stats[2], it)
    stats[3] = stats[3] + res
    stats[4] = wp.max(stats[4], res)
    if not (residual_sq[0] <= tolerance_sq[0]):
        stats[5] = stats[5] + wp.float64(1.0)


@wp.kernel
def block_gemv(
    offsets: wp.array(dtype=int),
    columns: wp.array(dtype=int),
    values: wp.array(dtype=wp.mat33),
    x: wp.array(dtype=wp.vec3),
    y: wp.array(dtype=wp.vec3),
    alpha: float,
    beta: float,
    z: wp.array(dtype=wp.vec3),
):
    # z = alpha A x + beta y, A in CSR of 3 x 3 blocks (row i: blocks offsets[i]:offsets[i + 1]); y may alias z
    i = wp.tid()
    acc = wp.vec3(0.0)
    for e in range(offsets[i], offsets[i + 1]):
        acc = acc + values[e] * x[columns[e]]
    out = alpha * acc
    if beta != 0.0:
        out = out + beta * y[i]
    z[i] = out


@wp.kernel
def weight_gemv(
    offsets: wp.array(dtype=int),
    columns: wp.array(dtype=int),
    weights: wp.array(dtype=float),
    x: wp.array(dtype=wp.vec3),
    beta: float,
    z: wp.array(dtype=wp.vec3),
):
    # z = W x + beta z, W in CSR of scalars (blocks w I: the grid transfers P and P^T)
    i = wp.tid()
    acc = wp.vec3(0.0)
    for e in range(offsets[i], offsets[i + 1]):
        acc = acc + weights[e] * x[columns[e]]
    if beta != 0.0:
        acc = acc + beta * z[i]
    z[i] = acc


@wp.kernel
def smooth_jacobi_block(
    offsets: wp.array(dtype=int),
    columns: wp.array(dtype=int),
    values: wp.array(dtype=wp.mat33),
    inv_block: wp.array(dtype=wp.mat33),
    b: wp.array(dtype=wp.vec3),
    x: wp.array(dtype=wp.vec3),
    omega: float,
    alpha: float,
    beta: float,
    y: wp.array(dtype=wp.vec3),
    z: wp.array(dtype=wp.vec3),
):
    # one damped block-Jacobi sweep, fused with its residual: z = alpha (x + omega D^-1 (b - A x)) + beta y  (z must not alias x)
    i = wp.tid()
    res = b[i]
    for e in range(offsets[i], offsets[i + 1]):
        res = res - values[e] * x[columns[e]]
    out = alpha * (x[i] + omega * (inv_block[i] * res))
    if beta != 0.0:
        out = out + beta * y[i]
    z[i] = out


@wp.kernel
def invert_diagonal_blocks(values: wp.array(dtype=wp.mat33), diag_index: wp.array(dtype=int), inverse: wp.array(dtype=wp.mat33)):
    # inverse_i = A_ii^-1 (I where singular), A_ii = values[diag_index[i]]: the smoother of a multigrid level
    i = wp.tid()
    inverse[i] = inverse_block(values[diag_index[i]])


# -- preconditioned CG with its scalars on the device (implicit_euler's CPU solver) -----------
# scalars: [r.z, r.z (new), p.Ap, r.r, b.b, tolerance^2 = tol^2 b.b, iterations, done]
CG_RZ = wp.constant(0)
CG_RZ_NEW = wp.constant(1)
CG_PAP = wp.constant(2)
CG_RR = wp.constant(3)
CG_BB = wp.constant(4)
CG_TOL2 = wp.constant(5)
CG_ITER = wp.constant(6)
CG_DONE = wp.constant(7)


@wp.kernel
def dot_terms(a: wp.array(dtype=wp.vec3), b: wp.array(dtype=wp.vec3), terms: wp.array(dtype=float)):
    # terms_i = a_i . b_i  (summed in a fixed order by sum_chunks / sum_partials)
    i = wp.tid()
    terms[i] = wp.dot(a[i], b[i])


@wp.kernel
def cg_start(tol: float, scalars: wp.array(dtype=float), p: wp.array(dtype=wp.vec3), z: wp.array(dtype=wp.vec3), x: wp.array(dtype=wp.vec3)):
    # p = z ;  tolerance^2 = tol^2 b.b ;  iterations = 0 ;  done when r.r <= tolerance^2 already;
    # b = 0 exactly: x = 0 is the solution (a relative tolerance cannot be met from a warm start)
    i = wp.tid()
    p[i] = z[i]
    bb = scalars[CG_BB]
    if bb == 0.0:
        x[i] = wp.vec3(0.0)
    if i == 0:
        if bb == 0.0:
            scalars[CG_RR] = 0.0
        tol2 = tol * tol * scalars[CG_BB]
        scalars[CG_TOL2] = tol2
        scalars[CG_ITER] = 0.0
        scalars[CG_DONE] = 0.0
        if scalars[CG_RR] <= tol2:
            scalars[CG_DONE] = 1.0


@wp.kernel
def cg_update_solution(
    scalars: wp.array(dtype=float),
    p: wp.array(dtype=wp.vec3),
    Ap: wp.array(dtype=wp.vec3),
    x: wp.array(dtype=wp.vec3),
    r: wp.array(dtype=wp.vec3),
    terms: wp.array(dtype=float),
):
    # alpha = r.z / p.Ap ;  x += alpha p ;  r -= alpha Ap ;  terms = r.r   (nothing once done)
    i = wp.tid()
    ri = r[i]
    if scalars[CG_DONE] == 0.0 and scalars[CG_PAP] > 0.0:
        alpha = scalars[CG_RZ] / scalars[CG_PAP]
        x[i] = x[i] + alpha * p[i]
        ri = ri - alpha * Ap[i]
        r[i] = ri
    terms[i] = wp.dot(ri, ri)


@wp.kernel
def cg_count(max_iter: int, scalars: wp.array(dtype=float)):
    # one iteration more; done when r.r <= tolerance^2 (warp's cg test) or at the cap
    if scalars[CG_DONE] == 0.0:
        it = scalars[CG_ITER] + 1.0
        scalars[CG_ITER] = it
        if scalars[CG_RR] <= scalars[CG_TOL2] or it >= float(max_iter):
            scalars[CG_DONE] = 1.0


@wp.kernel
def cg_update_direction(scalars: wp.array(dtype=float), z: wp.array(dtype=wp.vec3), p: wp.array(dtype=wp.vec3)):
    # beta = r.z (new) / r.z ;  p = z + beta p   (nothing once done)
    i = wp.tid()
    if scalars[CG_DONE] == 0.0:
        beta = float(0.0)
        if scalars[CG_RZ] > 0.0:
            beta = scalars[CG_RZ_NEW] / scalars[CG_RZ]
        p[i] = z[i] + beta * p[i]


@wp.kernel
def cg_shift(scalars: wp.array(dtype=float)):
    # r.z <- r.z (new), for the next iteration
    if scalars[CG_DONE] == 0.0:
        scalars[CG_RZ] = scalars[CG_RZ_NEW]


@wp.kernel
def invert_l1_diagonal_blocks(
    offsets: wp.array(dtype=int),
    values: wp.array(dtype=wp.mat33),
    diag_index: wp.array(dtype=int),
    inverse: wp.array(dtype=wp.mat33),
):
    # l1 block Jacobi: inverse_i = (A_ii + sum_(j != i) |A_ij|_F I)^-1 (I where singular). For SPD A the
    # sweep x += D_l1^-1 (b - A x) converges whatever the coupling (A <= D_l1 block-wise), where plain
    # damped Jacobi needs omega < 2 / lambda_max(D^-1 A), which Galerkin coarse operators can break.
    i = wp.tid()
    d = diag_index[i]
    extra = float(0.0)
    for e in range(offsets[i], offsets[i + 1]):
        if e != d:
            extra = extra + wp.sqrt(wp.ddot(values[e], values[e]))
    inverse[i] = inverse_block(values[d] + extra * wp.identity(n=3, dtype=float))


# -- contacts seen by the solve (Baraff & Witkin's filter, with sticking) ----------------------
# Per particle and step: mode 0 (no contact: S = I), SLIDE (S = I - n n^T, the normal dv prescribed,
# kinetic friction as a known impulse in the solve) or STICK (S = 0, the tangential dv too: it moves
# with the collider). The mode is chosen at the step's start from the previous step's constraint
# impulse J = A dv - b (hysteresis: a contact stays while J pushes, J . n > 0; a stuck one stays
# while |J_t| <= mu J_n) or, for the others, from the velocity; see eval_contact_modes.
SLIDE = wp.constant(1)
STICK = wp.constant(2)
STOPPED = wp.constant(3)  # after the solve: a SLIDE contact that friction stopped (it sticks next step)


@wp.func
def contact_proximity(phi: float, thickness: float):
    # touching: the projection leaves a resting particle at phi = thickness, to rounding (the
    # absolute 1e-6 m lets a zero thickness count too)
    return phi < 1.1 * thickness + 1.0e-6


@wp.func
def effective_mass(a: wp.mat33, t: wp.vec3, m: float):
    # t^T A_ii t of a unit direction t (m where t = 0): the inertia a tangential impulse meets with
    # the particle's springs' implicit stiffness (the neighbours held), the local Gauss-Seidel
    # estimate (m alone overstates an impulse's effect in a stiff cloth, where A_ii >> m: 1.1 kg
    # against 3.5e-4 kg in the 24 x 24 drape)
    if wp.dot(t, t) == 0.0:
        return m
    return wp.dot(t, a * t)


@wp.kernel
def eval_contact_modes(
    x: wp.array(dtype=wp.vec3),
    v: wp.array(dtype=wp.vec3),
    f: wp.array(dtype=wp.vec3),
    particle_mass: wp.array(dtype=float),
    inv_mass: wp.array(dtype=float),
    colliders: wp.array(dtype=Collider),
    h: float,
    entered: wp.array(dtype=int),
    impulse: wp.array(dtype=wp.vec3),
    mode: wp.array(dtype=int),
    normal: wp.array(dtype=wp.vec3),
    friction: wp.array(dtype=float),
    collider_v: wp.array(dtype=wp.vec3),
    friction_impulse: wp.array(dtype=wp.vec3),
):
    # For particle i touching collider k (the last such wins), with v_r = v - v_c relative to it:
    # in contact if the force at the step's start pushes it in (f . n < 0), or it was in contact
    # last step and the constraint pushed (J_n = J . n > 0: the release waits for the solve to
    # pull, Baraff & Witkin's test; the explicit f . n misses the implicit coupling and made the
    # set flip every other step), or last step's solve moved it inside (entered). It STICKs if it
    # stuck last step and the friction cone held the solve's impulse (|J_t| <= mu J_n), if friction
    # stopped it last step (STOPPED), or, as a new contact, if friction can cancel the tangential
    # momentum it would have, |p| = |m v_r,t + h f_t| < mu J_n with J_n the larger of
    # m max(0, -v_r . n) and -h f . n (a landing particle, whose approach the projection already
    # stopped, has v_r,t = 0 to rounding); the next solve tells whether the cone held. A sliding
    # contact slides on until friction stops it (the explicit f_t is no guide there: in the stiff
    # drape it is ~1000 times the weight, balanced by the implicit response). Else it SLIDEs, with
    # the kinetic friction impulse F = mu J_n against p (new), v_r,t (sliding) or, just released
    # from sticking, along the J_t that held it (against the slip to come), added to the solve's
    # right side, so the neighbours feel it. Reads and writes only particle i's entries (impulse, mode: last step's
    # on entry).
    i = wp.tid()
    previous = mode[i]
    mode[i] = 0
    normal[i] = wp.vec3(0.0)
    friction_impulse[i] = wp.vec3(0.0)
    if inv_mass[i] == 0.0:
        return
    J = impulse[i]
    m = particle_mass[i]
    for k in range(colliders.shape[0]):
        c = colliders[k]
        # a moving collider is posed at the step's end (Control.update): the contact is that of x
        # carried along with it over the step, x + h v_c (x itself for a still one); with x, a
        # particle resting on a moving sphere's trailing side looked u h away from it and dropped
        # out of the solve every step
        vc = surface_velocity(colliders, k, x[i])
        phi, n = collider_contact(colliders, k, x[i] + h * vc, 1.1 * c.thickness + 1.0e-5)
        if not contact_proximity(phi, c.thickness):
            continue
        jn_prev = float(0.0)
        if previous != 0:
            jn_prev = wp.dot(J, n)
        if wp.dot(f[i], n) < 0.0 or jn_prev > 0.0 or entered[i] != 0:
            friction_impulse[i] = wp.vec3(0.0)  # a later collider's contact replaces an earlier one's, impulse included
            vr = v[i] - vc
            vrn = wp.dot(vr, n)
            held = previous == STICK and jn_prev > 0.0 and wp.length(J - jn_prev * n) <= c.mu * jn_prev
            vt = vr - vrn * n
            lt = wp.length(vt)
            t = wp.vec3(0.0)
            if lt > 0.0:
                t = vt / lt
            jn = wp.max(wp.max(jn_prev, m * wp.max(0.0, -vrn)), -h * wp.dot(f[i], n))
            # tangential momentum a new contact would have after the step without friction
            p = m * vt + h * (f[i] - wp.dot(f[i], n) * n)
            lp = wp.length(p)
            cancellable = previous == STOPPED or (previous == 0 and lp < c.mu * jn)
            if held or cancellable:
                mode[i] = STICK
            else:
                mode[i] = SLIDE
                jt = J - jn_prev * n
                if previous == 0 and lp > 0.0:
                    friction_impulse[i] = -(c.mu * jn / lp) * p
                elif lt > 0.0:
                    friction_impulse[i] = -(c.mu * jn) * t
                elif previous == STICK and wp.length(jt) > 0.0:
                    friction_impulse[i] = (c.mu * jn / wp.length(jt)) * jt
            normal[i] = n
            friction[i] = c.mu
            collider_v[i] = vc


@wp.kernel
def eval_contact_dv(
    mode: wp.array(dtype=int), normal: wp.array(dtype=wp.vec3), collider_v: wp.array(dtype=wp.vec3),
    v: wp.array(dtype=wp.vec3), z: wp.array(dtype=wp.vec3),
):
    # prescribed dv of a contact particle, v_r = v - v_c: the normal z_n = -min(0, v_r . n) n (it
    # stops approaching the collider) and, for STICK, the tangential -v_r,t too (it moves with the
    # collider); 0 elsewhere
    i = wp.tid()
    z[i] = wp.vec3(0.0)
    if mode[i] == 0:
        return
    n = normal[i]
    vr = v[i] - collider_v[i]
    vrn = wp.dot(vr, n)
    z[i] = -wp.min(0.0, vrn) * n
    if mode[i] == STICK:
        z[i] = z[i] - (vr - vrn * n)


@wp.kernel
def apply_contact_friction(
    mode: wp.array(dtype=int),
    normal: wp.array(dtype=wp.vec3),
    friction: wp.array(dtype=float),
    collider_v: wp.array(dtype=wp.vec3),
    residual: wp.array(dtype=wp.vec3),
    v: wp.array(dtype=wp.vec3),
    particle_mass: wp.array(dtype=float),
    values: wp.array(dtype=wp.mat33),
    diag_block: wp.array(dtype=int),
    friction_impulse: wp.array(dtype=wp.vec3),
    dv: wp.array(dtype=wp.vec3),
    impulse: wp.array(dtype=wp.vec3),
):
    # the constraint impulse J = -(b - A dv)_i (unfiltered A, b) of each particle, kept for the
    # next step's modes. SLIDE: where the solve's friction F reversed the tangential velocity
    # (v_r,t . F > 0 after it: F is against the sliding), friction stops the particle instead
    # (Coulomb's cap; mode STOPPED: it sticks next step). STICK past the cone (|J_t| > mu J_n, J_n = max(0, J . n)): the tangential
    # impulse friction cannot give is taken back, dv_t -= (|J_t| - mu J_n) / m_t along J_t (it
    # slips; next step it slides), m_t the effective_mass along J_t.
    i = wp.tid()
    J = -residual[i]
    impulse[i] = J
    n = normal[i]
    jn = wp.max(0.0, wp.dot(J, n))
    mu = friction[i]
    m = particle_mass[i]
    a = values[diag_block[i]]
    if mode[i] == SLIDE:
        F = friction_impulse[i]
        vr = v[i] + dv[i] - collider_v[i]
        vt = vr - wp.dot(vr, n) * n
        if wp.dot(vt, F) > 0.0:
            dv[i] = dv[i] - vt
            mode[i] = STOPPED
    elif mode[i] == STICK:
        jt = J - wp.dot(J, n) * n
        lt = wp.length(jt)
        if lt > mu * jn:
            t = jt / lt
            dv[i] = dv[i] - ((lt - mu * jn) / effective_mass(a, t, m)) * t


@wp.kernel
def mark_entered(
    x: wp.array(dtype=wp.vec3), inv_mass: wp.array(dtype=float), colliders: wp.array(dtype=Collider), mode: wp.array(dtype=int),
    entered: wp.array(dtype=int),
):
    # after the step's integration (moving colliders posed at its end): 1 where a particle the
    # solve left unconstrained ended inside a
    # collider's thickness (the projection will push it out; next step it is a contact whatever its
    # force). A constrained one ends at its start's distance, to rounding: its own J decides.
    i = wp.tid()
    entered[i] = 0
    if inv_mass[i] == 0.0 or mode[i] != 0:
        return
    for k in range(colliders.shape[0]):
        phi, n = collider_contact(colliders, k, x[i], colliders[k].thickness)
        if phi < colliders[k].thickness:
            entered[i] = 1


@wp.func
def contact_filter(mode: int, n: wp.vec3):
    # S = I - n n^T (SLIDE; I without a contact, n = 0), 0 (STICK)
    if mode == STICK:
        return wp.mat33(0.0)
    return wp.identity(n=3, dtype=float) - wp.outer(n, n)


@wp.kernel
def filter_system_rows(
    row_offsets: wp.array(dtype=int),
    columns: wp.array(dtype=int),
    diag_block: wp.array(dtype=int),
    mode: wp.array(dtype=int),
    normal: wp.array(dtype=wp.vec3),
    values: wp.array(dtype=wp.mat33),
    inv_diag: wp.array(dtype=wp.vec3),
):
    # A <- S A S + P A_ii P (P = I - S) on the diagonal, S_i A_ij S_j off it: the prescribed
    # directions leave the solve (P A_ii P keeps them nonsingular and uncoupled; for SLIDE it is
    # (n^T A_ii n) n n^T); inv_diag = 1 / diag(A_ii) of the filtered A (Jacobi)
    i = wp.tid()
    Si = contact_filter(mode[i], normal[i])
    Pi = wp.identity(n=3, dtype=float) - Si
    d = diag_block[i]
    for e in range(row_offsets[i], row_offsets[i + 1]):
        if e == d:
            block = values[e]
            values[e] = Si * block * Si + Pi * block * Pi
        else:
            j = columns[e]
            values[e] = Si * values[e] * contact_filter(mode[j], normal[j])
    inv_diag[i] = inverse_diagonal(values[d])


@wp.kernel
def filter_rhs(
    mode: wp.array(dtype=int), normal: wp.array(dtype=wp.vec3), Az: wp.array(dtype=wp.vec3), friction_impulse: wp.array(dtype=wp.vec3),
    b: wp.array(dtype=wp.vec3), dv: wp.array(dtype=wp.vec3),
):
    # b <- S (b + F - A z) (a sliding contact's friction impulse F added, the prescribed dv moved
    # to the right side);  dv <- S dv (the warm start)
    i = wp.tid()
    S = contact_filter(mode[i], normal[i])
    b[i] = S * (b[i] + friction_impulse[i] - Az[i])
    dv[i] = S * dv[i]


@wp.kernel
def unfilter_dv(mode: wp.array(dtype=int), normal: wp.array(dtype=wp.vec3), z: wp.array(dtype=wp.vec3), dv: wp.array(dtype=wp.vec3)):
    # dv = S y + z (S y: CG's solution without what rounding and the preconditioner left in the
    # prescribed directions)
    i = wp.tid()
    dv[i] = contact_filter(mode[i], normal[i]) * dv[i] + z[i]
