"""Linear algebra on vec3 fields and 3 x 3 blocks, shared by the linear solvers: CSR block
products (also in the split form that keeps a smooth vector's mass term), diagonal and block-diagonal (Jacobi)
preconditioners, axpy, and dot products summed in a
fixed order (per-element terms, sums over fixed chunks, then the chunks' sum by one thread; no
atomics, so results are bit-identical run to run, between launches and graph replay). The
preconditioned CG whose scalars live on the device (implicit Euler's solver on the CPU) is here
too."""

import warp as wp

# forward only: no adjoints (half the compile time; warpcloth differentiates nothing)
wp.set_module_options({"enable_backward": False})


@wp.func
def inverse_diagonal(a: wp.mat33):
    # the Jacobi preconditioner of one row block: 1 / diag(A_ii)
    return wp.vec3(1.0 / a[0, 0], 1.0 / a[1, 1], 1.0 / a[2, 2])


@wp.func
def inverse_block(a: wp.mat33):
    # the block-Jacobi preconditioner of one row block: A_ii^-1 (SPD, so det > 0)
    det = wp.determinant(a)
    if det <= 0.0:
        return wp.identity(n=3, dtype=float)
    return wp.inverse(a)


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
def block_gemv_split(
    offsets: wp.array(dtype=int),
    columns: wp.array(dtype=int),
    values: wp.array(dtype=wp.mat33),
    row_part: wp.array(dtype=wp.mat33),
    x: wp.array(dtype=wp.vec3),
    y: wp.array(dtype=wp.vec3),
    alpha: float,
    beta: float,
    z: wp.array(dtype=wp.vec3),
):
    # z = alpha A x + beta y as (A x)_i = E_i x_i + sum_(j != i) A_ij (x_j - x_i), E_i = A_ii + sum_j A_ij
    # (row_part, formed from the masses at assembly; the stored A_ii is not read). The same A as
    # block_gemv in exact arithmetic, but a smooth x does not cancel: the stored A_ii = m I + sum B_s
    # keeps m only to ulp(|sum B_s|) -- at 256^2 on the peers' sheet h^2 ks / m ~ 2e4, so the mass
    # kept ~1e-2 of its digits -- and the product's sum_s B_s x_i - sum_s B_s x_j cancels as much.
    # The matrix-free product sums B_s (x_i - x_j) likewise. y may alias z
    # (the diagonal block is in the loop too, times x_i - x_i = 0 exactly: no branch per block)
    i = wp.tid()
    xi = x[i]
    acc = row_part[i] * xi
    for e in range(offsets[i], offsets[i + 1]):
        acc = acc + values[e] * (x[columns[e]] - xi)
    out = alpha * acc
    if beta != 0.0:
        out = out + beta * y[i]
    z[i] = out


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
def invert_diagonal_blocks(
    values: wp.array(dtype=wp.mat33), diag_index: wp.array(dtype=int), inverse: wp.array(dtype=wp.mat33)
):
    # inverse_i = A_ii^-1 (I where singular), A_ii = values[diag_index[i]]: the smoother of a multigrid level
    i = wp.tid()
    inverse[i] = inverse_block(values[diag_index[i]])


@wp.kernel
def scale_add(
    x: wp.array(dtype=wp.vec3), y: wp.array(dtype=wp.vec3), alpha: float, beta: float, z: wp.array(dtype=wp.vec3)
):
    # z = alpha x + beta y
    i = wp.tid()
    out = alpha * x[i]
    if beta != 0.0:
        out = out + beta * y[i]
    z[i] = out


@wp.kernel
def dot_terms(a: wp.array(dtype=wp.vec3), b: wp.array(dtype=wp.vec3), terms: wp.array(dtype=float)):
    # terms_i = a_i . b_i  (summed in a fixed order by sum_chunks / sum_partials)
    i = wp.tid()
    terms[i] = wp.dot(a[i], b[i])


@wp.kernel
def sum_chunks(terms: wp.array(dtype=float), chunk: int, count: int, partial: wp.array(dtype=float)):
    # partial[c] = sum of terms[c chunk : (c + 1) chunk], in index order
    c = wp.tid()
    acc = float(0.0)
    for i in range(c * chunk, wp.min((c + 1) * chunk, count)):
        acc = acc + terms[i]
    partial[c] = acc


@wp.kernel
def sum_partials(partial: wp.array(dtype=float), k: int, out: wp.array(dtype=float)):
    # out[k] = sum of the chunk sums, in order (one thread)
    acc = float(0.0)
    for c in range(partial.shape[0]):
        acc = acc + partial[c]
    out[k] = acc


@wp.kernel
def sum_block_chunks(
    b: wp.array(dtype=wp.vec3),
    A: wp.array(dtype=wp.mat33),
    chunk: int,
    count: int,
    b_partial: wp.array(dtype=wp.vec3),
    A_partial: wp.array(dtype=wp.mat33),
):
    # chunk sums of b and A in index order (a fixed order: results do not depend on scheduling)
    c = wp.tid()
    bs = wp.vec3(0.0)
    As = wp.mat33(0.0)
    for i in range(c * chunk, wp.min((c + 1) * chunk, count)):
        bs = bs + b[i]
        As = As + A[i]
    b_partial[c] = bs
    A_partial[c] = As


@wp.kernel
def solve_block_sum(
    b_partial: wp.array(dtype=wp.vec3), A_partial: wp.array(dtype=wp.mat33), regular: float, t: wp.array(dtype=wp.vec3)
):
    # t = (sum A + regular I)^-1 sum b from the chunk sums, in order (one thread); 0 where singular.
    # A 3-unknown Galerkin problem (the rigid translation mode of vbd and projective): where every free
    # particle slides on one plane (or sticks), sum A is singular along the normal, and a small regular
    # term (1e-6 of the free mass) keeps it invertible without changing t elsewhere
    bs = wp.vec3(0.0)
    As = wp.mat33(0.0)
    for c in range(b_partial.shape[0]):
        bs = bs + b_partial[c]
        As = As + A_partial[c]
    As = As + regular * wp.identity(n=3, dtype=float)
    out = wp.vec3(0.0)
    if wp.abs(wp.determinant(As)) > 0.0:
        out = wp.inverse(As) * bs
    t[0] = out


@wp.kernel
def rounding_perturbation(x: wp.array(dtype=wp.vec3), seed: int, delta: wp.array(dtype=wp.vec3)):
    # delta_i = (u - 1/2) ulp(x_i) per component, u uniform in [0, 1): a random float32 rounding of x.
    # |A delta| / |b| estimates the residual of the exact solution rounded to float32 (the reachable
    # floor): within 3 % of it on the 32 x 32 sheet (issue 26)
    i = wp.tid()
    state = wp.rand_init(seed, i)
    d = x[i]
    out = wp.vec3(0.0)
    for k in range(3):
        a = wp.abs(d[k])
        if a > 0.0:
            out[k] = (wp.randf(state) - 0.5) * wp.pow(2.0, wp.floor(wp.log2(a)) - 23.0)
    delta[i] = out


@wp.kernel
def residual_terms(
    b: wp.array(dtype=wp.vec3), r: wp.array(dtype=wp.vec3), q: wp.array(dtype=wp.vec3), terms: wp.array(dtype=wp.vec3d)
):
    # terms_i = (|r_i|^2, |b_i|^2, |q_i|^2) in float64 (summed in a fixed order by sum_chunks3)
    i = wp.tid()
    ri = wp.vec3d(r[i])
    bi = wp.vec3d(b[i])
    qi = wp.vec3d(q[i])
    terms[i] = wp.vec3d(wp.dot(ri, ri), wp.dot(bi, bi), wp.dot(qi, qi))


@wp.kernel
def sum_chunks3(terms: wp.array(dtype=wp.vec3d), chunk: int, count: int, partial: wp.array(dtype=wp.vec3d)):
    # partial[c] = sum of terms[c chunk : (c + 1) chunk], in index order (float64)
    c = wp.tid()
    acc = wp.vec3d(0.0)
    for i in range(c * chunk, wp.min((c + 1) * chunk, count)):
        acc = acc + terms[i]
    partial[c] = acc


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
def cg_start(
    tol: float,
    scalars: wp.array(dtype=float),
    p: wp.array(dtype=wp.vec3),
    z: wp.array(dtype=wp.vec3),
    x: wp.array(dtype=wp.vec3),
):
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
