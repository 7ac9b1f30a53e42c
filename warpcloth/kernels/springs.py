"""Spring math shared by every scheme: the spring force (Hooke + damping along the spring, Provot;
seed eq. 2.7-2.8), its stiffness and damping blocks with the compression clamp (implicit Euler's
Jacobian, design.md), and the force and Hessian block of a spring in an increment solve (vbd,
projective's contact step)."""

import warp as wp

# forward only: no adjoints (half the compile time; warpcloth differentiates nothing)
wp.set_module_options({"enable_backward": False})


@wp.struct
class SpringAdjacency:
    """Each particle's springs, grouped by particle (CSR), with the springs' parameters: filled once
    at bind. Particle i's entries are offsets[i]:offsets[i + 1]; entry a is spring spring[a], whose
    other particle is other[a]."""

    offsets: wp.array(dtype=int)  # shape (particle_count + 1,)
    spring: wp.array(dtype=int)  # the spring of each entry, shape (2 spring_count,)
    other: wp.array(dtype=int)  # the spring's other particle, shape (2 spring_count,)
    rest_length: wp.array(dtype=float)  # L0 per spring [m], shape (spring_count,)
    stiffness: wp.array(dtype=float)  # ks per spring [N/m]
    damping: wp.array(dtype=float)  # kd per spring [N s/m]
    compression: wp.array(dtype=float)  # phi per spring: ks in tension, phi ks in compression


@wp.func
def compressed_stiffness(length: float, rest: float, ks: float, phi: float):
    # ks where L >= L0, phi ks where L < L0 (compression factor; Choi & Ko 2002); phi = 1 gives ks bit for bit
    if length < rest:
        return phi * ks
    return ks


@wp.func
def spring_force(xi: wp.vec3, xj: wp.vec3, vi: wp.vec3, vj: wp.vec3, rest: float, ks: float, kd: float, phi: float):
    # f_i = k (L - L0) n + kd ((v_j - v_i) . n) n,  n = (x_j - x_i) / L,  k = ks (phi ks if L < L0)  (seed eq. 2.7-2.8)
    d = xj - xi
    length = wp.length(d)
    if length == 0.0:
        return wp.vec3(0.0)
    n = d / length
    return (compressed_stiffness(length, rest, ks, phi) * (length - rest) + kd * wp.dot(vj - vi, n)) * n


@wp.func
def spring_stiffness_block(xi: wp.vec3, xj: wp.vec3, rest: float, ks: float, phi: float):
    """K = df_i/dx_j = k [n n^T + max(0, 1 - L0/L) (I - n n^T)] [N/m] (design.md), k = ks, or phi ks
    for a compressed spring (L < L0; then the geometric term is clamped to 0 anyway).

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
    return compressed_stiffness(length, rest, ks, phi) * (nnt + geometric * (wp.identity(n=3, dtype=float) - nnt))


@wp.func
def spring_damping_block(xi: wp.vec3, xj: wp.vec3, kd: float):
    """D = df_i/dv_j = kd n n^T [N s/m] (the damping force acts along the spring)."""
    d = xj - xi
    length = wp.length(d)
    if length == 0.0:
        return wp.mat33(0.0)
    n = d / length
    return kd * wp.outer(n, n)


@wp.func
def spring_gradient_hessian(xij: wp.vec3, dxij: wp.vec3, rest: float, ks: float, kd: float, phi: float, h: float):
    # force on i from spring (i, j): f = k (L - L0) n + kd / h (n.(dx_j - dx_i)) n  (k = ks, phi ks if L < L0);
    # its Hessian block w.r.t. x_i: K (clamped) + kd / h n n^T   (d = x_j - x_i + dx_j - dx_i)
    d = xij + dxij
    length = wp.length(d)
    if length == 0.0:
        return wp.vec3(0.0), wp.mat33(0.0)
    n = d / length
    nnt = wp.outer(n, n)
    force = compressed_stiffness(length, rest, ks, phi) * (length - rest) * n + (kd / h) * wp.dot(n, dxij) * n
    hessian = spring_stiffness_block(wp.vec3(0.0), d, rest, ks, phi) + (kd / h) * nnt
    return force, hessian
