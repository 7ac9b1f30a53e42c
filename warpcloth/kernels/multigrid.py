"""Geometric multigrid of 3 x 3 block systems (:mod:`warpcloth.integrators.multigrid`): the
Galerkin coarse operator P^T A P, the grid transfers P and P^T, and the (damped, l1) block-Jacobi
smoothers."""

import warp as wp

from warpcloth.kernels.linalg import inverse_block

# forward only: no adjoints (half the compile time; warpcloth differentiates nothing)
wp.set_module_options({"enable_backward": False})


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
    # one damped block-Jacobi sweep, fused with its residual: z = alpha (x + omega D^-1 (b - A x)) + beta y  (z must not
    # alias x)
    i = wp.tid()
    res = b[i]
    for e in range(offsets[i], offsets[i + 1]):
        res = res - values[e] * x[columns[e]]
    out = alpha * (x[i] + omega * (inv_block[i] * res))
    if beta != 0.0:
        out = out + beta * y[i]
    z[i] = out


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
