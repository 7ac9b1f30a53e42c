"""The implicit system of a mass-spring step (Baraff & Witkin 1998; seed eq. 2.19-2.23), shared by
implicit Euler (its linear system) and vbd (h^2 times its Hessian, for the multigrid correction):

    A = M - h df/dv - h^2 df/dx.

Per spring s = (i, j), d = x_j - x_i, L = |d|, n = d / L, the Jacobian blocks are

    K_s = df_i/dx_j = ks [ n n^T + max(0, 1 - L0/L) (I - n n^T) ],   df_i/dx_i = -K_s,
    D_s = df_i/dv_j = kd n n^T,                                       df_i/dv_i = -D_s,

so with B_s = h^2 K_s + h D_s, row i of A is A_ii = m_i (1 + h c) I + sum_s B_s, A_ij = -B_s
(c the linear air drag rate). Pinned particles (inverse mass 0) get identity rows and zero
columns, so their dv is 0. The row kernels gather over a particle's springs through a
particle -> (spring, neighbour, block) adjacency built once at bind: no atomics.
"""

import warp as wp

from warpcloth.kernels.linalg import inverse_block, inverse_diagonal
from warpcloth.kernels.springs import SpringAdjacency, spring_damping_block, spring_stiffness_block

# forward only: no adjoints (half the compile time; warpcloth differentiates nothing)
wp.set_module_options({"enable_backward": False})


@wp.kernel
def eval_spring_jacobians(
    x: wp.array(dtype=wp.vec3),
    spring_indices: wp.array(dtype=wp.vec2i),
    spring_rest_length: wp.array(dtype=float),
    spring_stiffness: wp.array(dtype=float),
    spring_damping: wp.array(dtype=float),
    spring_compression: wp.array(dtype=float),
    h: float,
    spring_K: wp.array(dtype=wp.mat33),
    spring_B: wp.array(dtype=wp.mat33),
):
    # K_s = k [n n^T + max(0, 1 - L0/L)(I - n n^T)] (k = ks, phi ks if L < L0),  B_s = h^2 K_s + h kd n n^T  (full)
    s = wp.tid()
    ij = spring_indices[s]
    xi = x[ij[0]]
    xj = x[ij[1]]
    K = spring_stiffness_block(xi, xj, spring_rest_length[s], spring_stiffness[s], spring_compression[s])
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


@wp.kernel
def assemble_system_rows(
    springs: SpringAdjacency,
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
    row_part: wp.array(dtype=wp.mat33),
    row_part_solve: wp.array(dtype=wp.mat33),
):
    # row i of A: A_ii = m (1 + h c) I + sum_s B_s,  A_ij = -B_s;  pinned: identity row, zero column;
    # inv_diag = 1 / diag(A_ii)  (Jacobi); row_part = E_i = A_ii + sum_(j != i) A_ij = m (1 + h c) I +
    # the B_s of springs to pinned particles, formed from the mass (not from the rounded A_ii), for
    # block_gemv_split (also copied to row_part_solve, which the contact filter overwrites)
    i = wp.tid()
    for b in range(row_offsets[i], row_offsets[i + 1]):
        values[b] = wp.mat33(0.0)
    if particle_inv_mass[i] == 0.0:
        values[diag_block[i]] = wp.identity(n=3, dtype=float)
        inv_diag[i] = wp.vec3(1.0)
        row_part[i] = wp.identity(n=3, dtype=float)
        row_part_solve[i] = wp.identity(n=3, dtype=float)
        return
    mass = (particle_mass[i] * (1.0 + h * drag_rate)) * wp.identity(n=3, dtype=float)
    diag = mass
    pinned = wp.mat33(0.0)
    for a in range(springs.offsets[i], springs.offsets[i + 1]):
        block = spring_B[springs.spring[a]]
        diag = diag + block
        if particle_inv_mass[springs.other[a]] != 0.0:
            b = adjacency_block[a]
            values[b] = values[b] - block
        else:
            pinned = pinned + block
    values[diag_block[i]] = diag
    inv_diag[i] = inverse_diagonal(diag)
    row_part[i] = mass + pinned
    row_part_solve[i] = mass + pinned


@wp.kernel
def eval_system_diagonal(
    springs: SpringAdjacency,
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
    for a in range(springs.offsets[i], springs.offsets[i + 1]):
        diag = diag + spring_B[springs.spring[a]]
    mass_term[i] = md
    inv_diag[i] = inverse_diagonal(diag)


@wp.kernel
def eval_inverse_diagonal_blocks(
    springs: SpringAdjacency,
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
    for a in range(springs.offsets[i], springs.offsets[i + 1]):
        diag = diag + spring_B[springs.spring[a]]
    inv_block[i] = inverse_block(diag)


@wp.kernel
def apply_system_matrix(
    x: wp.array(dtype=wp.vec3),
    y: wp.array(dtype=wp.vec3),
    springs: SpringAdjacency,
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
        for a in range(springs.offsets[i], springs.offsets[i + 1]):
            j = springs.other[a]
            xj = wp.vec3(0.0)
            if particle_inv_mass[j] != 0.0:
                xj = x[j]
            ax = ax + spring_B[springs.spring[a]] * (xi - xj)
    out = alpha * ax
    if beta != 0.0:
        out = out + beta * y[i]
    z[i] = out


# -- dihedral hinges (warpcloth.kernels.bending assembles their rows; these refresh the preconditioners) --------
@wp.kernel
def refresh_inverse_diagonal(
    values: wp.array(dtype=wp.mat33),
    diag_block: wp.array(dtype=int),
    particle_inv_mass: wp.array(dtype=float),
    inv_diag: wp.array(dtype=wp.vec3),
):
    # inv_diag = 1 / diag(A_ii) from the assembled values (after the hinge rows were added); pins keep 1
    i = wp.tid()
    if particle_inv_mass[i] != 0.0:
        inv_diag[i] = inverse_diagonal(values[diag_block[i]])


@wp.kernel
def add_hinge_diagonal_blocks(
    adjacency_offsets: wp.array(dtype=int),
    adjacency_hinge: wp.array(dtype=int),
    adjacency_slot: wp.array(dtype=int),
    hinge_gradient: wp.array2d(dtype=wp.vec3),
    hinge_stiffness: wp.array(dtype=float),
    hinge_damping: wp.array(dtype=float),
    particle_inv_mass: wp.array(dtype=float),
    alpha: float,
    beta: float,
    blocks: wp.array(dtype=wp.mat33),
):
    # blocks_i += sum_e (alpha k + beta kd) g_slot g_slot^T  (the hinges' diagonal block of A, matrix-free); pins 0
    i = wp.tid()
    if particle_inv_mass[i] == 0.0:
        return
    acc = wp.mat33(0.0)
    for a in range(adjacency_offsets[i], adjacency_offsets[i + 1]):
        e = adjacency_hinge[a]
        g = hinge_gradient[e, adjacency_slot[a]]
        acc = acc + (alpha * hinge_stiffness[e] + beta * hinge_damping[e]) * wp.outer(g, g)
    blocks[i] = blocks[i] + acc


@wp.kernel
def add_to_inverse_diagonal(
    extra: wp.array(dtype=wp.mat33),
    particle_inv_mass: wp.array(dtype=float),
    inv_diag: wp.array(dtype=wp.vec3),
):
    # inv_diag = 1 / (1 / inv_diag + diag(extra)): Jacobi with the hinges' diagonal blocks added; pins keep 1
    i = wp.tid()
    if particle_inv_mass[i] == 0.0:
        return
    d = inv_diag[i]
    x = extra[i]
    inv_diag[i] = wp.vec3(1.0 / (1.0 / d[0] + x[0, 0]), 1.0 / (1.0 / d[1] + x[1, 1]), 1.0 / (1.0 / d[2] + x[2, 2]))


@wp.kernel
def add_to_inverse_blocks(
    extra: wp.array(dtype=wp.mat33),
    particle_inv_mass: wp.array(dtype=float),
    inv_block: wp.array(dtype=wp.mat33),
):
    # inv_block = (inv_block^-1 + extra)^-1: block Jacobi with the hinges' diagonal blocks added (matrix-free); pins I
    i = wp.tid()
    if particle_inv_mass[i] != 0.0:
        inv_block[i] = inverse_block(inverse_block(inv_block[i]) + extra[i])
