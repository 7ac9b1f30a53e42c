"""Dihedral bending (discrete shells: Grinspun et al. 2003; Bridson et al. 2003): the hinge angle, its
gradient, forces, the Gauss-Newton Hessian and position-based projections (material-design.md section 2).

Hinge e = (x0, x1, x2, x3): edge x0-x1, x2 opposite in triangle A = (x0, x1, x2), x3 in
triangle B = (x1, x0, x3) (:mod:`warpcloth.sim.hinges` builds them). With

    e = x1 - x0,  nA = e x (x2 - x0),  nB = (x0 - x1) x (x3 - x1)       (|n| = 2 area),
    theta = atan2((nA x nB) . e / |e|, nA . nB)                          in (-pi, pi],

the energy is E = 1/2 k (theta - theta0)^2 with theta - theta0 wrapped into (-pi, pi], and the
gradient g_a = d theta / d x_a (Tamstorf & Grinspun 2013; Bridson's u1..u4 up to scale):

    g2 = -nA / (|nA| hA),  g3 = -nB / (|nB| hB),  hA = |nA| / |e|,  hB = |nB| / |e|,
    g0 = -(1 - tA) g2 - (1 - tB) g3,  g1 = -tA g2 - tB g3,  tA = (x2 - x0).e / |e|^2, tB likewise,

so sum g_a = 0 and sum x_a x g_a = 0 (no net force or torque). Forces f_a = -k (theta - theta0) g_a
- kd (sum_b g_b . v_b) g_a (Rayleigh damping along the hinge mode). Gauss-Newton Hessian:
d^2 E / dx_a dx_b ~ k g_a g_b^T (rank 1, positive semi-definite; exact at theta = theta0).
atan2 needs no normalisation and keeps full precision near 0 and near pi. Guards: a hinge whose
edge is shorter than 1e-9 m or whose |nA| or |nB| is below 1e-12 m^2 gives no force, no Hessian,
no energy and no correction; the heights are clamped below at 1e-3 |e| (ARCSim).
Float32 (``float``) throughout, like the rest of warpcloth's kernels.
"""

import warp as wp

# forward only: no adjoints (half the compile time; warpcloth differentiates nothing)
wp.set_module_options({"enable_backward": False})

EDGE_EPS = wp.constant(1.0e-9)
AREA_EPS = wp.constant(1.0e-12)
HEIGHT_FLOOR = wp.constant(1.0e-3)
TWO_PI = wp.constant(6.283185307179586)


@wp.func
def wrap_angle(a: float):
    # a into (-pi, pi]
    return a - TWO_PI * wp.ceil((a - wp.pi) / TWO_PI)


@wp.func
def hinge_angle(x0: wp.vec3, x1: wp.vec3, x2: wp.vec3, x3: wp.vec3):
    # theta = atan2((nA x nB) . e / |e|, nA . nB);  0 for a degenerate hinge
    e = x1 - x0
    le = wp.length(e)
    na = wp.cross(e, x2 - x0)
    nb = wp.cross(x0 - x1, x3 - x1)
    if le < EDGE_EPS or wp.length(na) < AREA_EPS or wp.length(nb) < AREA_EPS:
        return 0.0
    return wp.atan2(wp.dot(wp.cross(na, nb), e) / le, wp.dot(na, nb))


@wp.func
def hinge_angle_gradient(x0: wp.vec3, x1: wp.vec3, x2: wp.vec3, x3: wp.vec3):
    # (theta, g0, g1, g2, g3, valid): g_a = d theta / d x_a (module docstring); valid 0 = degenerate, all zero
    e = x1 - x0
    le = wp.length(e)
    na = wp.cross(e, x2 - x0)
    nb = wp.cross(x0 - x1, x3 - x1)
    la = wp.length(na)
    lb = wp.length(nb)
    if le < EDGE_EPS or la < AREA_EPS or lb < AREA_EPS:
        return 0.0, wp.vec3(0.0), wp.vec3(0.0), wp.vec3(0.0), wp.vec3(0.0), 0
    theta = wp.atan2(wp.dot(wp.cross(na, nb), e) / le, wp.dot(na, nb))
    ha = wp.max(la / le, HEIGHT_FLOOR * le)
    hb = wp.max(lb / le, HEIGHT_FLOOR * le)
    g2 = na * (-1.0 / (la * ha))
    g3 = nb * (-1.0 / (lb * hb))
    ta = wp.dot(x2 - x0, e) / (le * le)
    tb = wp.dot(x3 - x0, e) / (le * le)
    g0 = -(1.0 - ta) * g2 - (1.0 - tb) * g3
    g1 = -ta * g2 - tb * g3
    return theta, g0, g1, g2, g3, 1


@wp.func
def hinge_energy(x0: wp.vec3, x1: wp.vec3, x2: wp.vec3, x3: wp.vec3, rest: float, k: float):
    # E = 1/2 k wrap(theta - theta0)^2 [J];  0 for a degenerate hinge
    theta, _g0, _g1, _g2, _g3, valid = hinge_angle_gradient(x0, x1, x2, x3)
    if valid == 0:
        return 0.0
    c = wrap_angle(theta - rest)
    return 0.5 * k * c * c


@wp.func
def hinge_force_scale(
    theta: float,
    rest: float,
    k: float,
    kd: float,
    g0: wp.vec3,
    g1: wp.vec3,
    g2: wp.vec3,
    g3: wp.vec3,
    v0: wp.vec3,
    v1: wp.vec3,
    v2: wp.vec3,
    v3: wp.vec3,
):
    # s with f_a = s g_a:  s = -k wrap(theta - theta0) - kd (sum_b g_b . v_b)
    rate = wp.dot(g0, v0) + wp.dot(g1, v1) + wp.dot(g2, v2) + wp.dot(g3, v3)
    return -k * wrap_angle(theta - rest) - kd * rate


@wp.func
def pick_vec3(slot: int, a0: wp.vec3, a1: wp.vec3, a2: wp.vec3, a3: wp.vec3):
    # a_slot (slot 0..3)
    if slot == 0:
        return a0
    if slot == 1:
        return a1
    if slot == 2:
        return a2
    return a3


@wp.kernel
def eval_hinge_forces(
    x: wp.array(dtype=wp.vec3),
    v: wp.array(dtype=wp.vec3),
    hinge_indices: wp.array(dtype=wp.vec4i),
    hinge_rest_angle: wp.array(dtype=float),
    hinge_stiffness: wp.array(dtype=float),
    hinge_damping: wp.array(dtype=float),
    f: wp.array(dtype=wp.vec3),
):
    # f_a += -(k wrap(theta - theta0) + kd sum_b g_b . v_b) g_a   (atomics: hinges share vertices)
    e = wp.tid()
    q = hinge_indices[e]
    theta, g0, g1, g2, g3, valid = hinge_angle_gradient(x[q[0]], x[q[1]], x[q[2]], x[q[3]])
    if valid == 0:
        return
    s = hinge_force_scale(
        theta,
        hinge_rest_angle[e],
        hinge_stiffness[e],
        hinge_damping[e],
        g0,
        g1,
        g2,
        g3,
        v[q[0]],
        v[q[1]],
        v[q[2]],
        v[q[3]],
    )
    wp.atomic_add(f, q[0], s * g0)
    wp.atomic_add(f, q[1], s * g1)
    wp.atomic_add(f, q[2], s * g2)
    wp.atomic_add(f, q[3], s * g3)


@wp.kernel
def eval_hinge_energies(
    x: wp.array(dtype=wp.vec3),
    hinge_indices: wp.array(dtype=wp.vec4i),
    hinge_rest_angle: wp.array(dtype=float),
    hinge_stiffness: wp.array(dtype=float),
    energy: wp.array(dtype=float),
):
    # energy[e] = 1/2 k wrap(theta - theta0)^2 [J]
    e = wp.tid()
    q = hinge_indices[e]
    energy[e] = hinge_energy(x[q[0]], x[q[1]], x[q[2]], x[q[3]], hinge_rest_angle[e], hinge_stiffness[e])


@wp.kernel
def eval_hinge_gradients(
    x: wp.array(dtype=wp.vec3),
    hinge_indices: wp.array(dtype=wp.vec4i),
    hinge_angle_out: wp.array(dtype=float),
    hinge_gradient: wp.array2d(dtype=wp.vec3),
):
    # theta [rad] and g_a = d theta / d x_a [1/m] per hinge, gradient shape (hinge_count, 4); zeros if degenerate
    e = wp.tid()
    q = hinge_indices[e]
    theta, g0, g1, g2, g3, _valid = hinge_angle_gradient(x[q[0]], x[q[1]], x[q[2]], x[q[3]])
    hinge_angle_out[e] = theta
    hinge_gradient[e, 0] = g0
    hinge_gradient[e, 1] = g1
    hinge_gradient[e, 2] = g2
    hinge_gradient[e, 3] = g3


@wp.kernel
def eval_hinge_hessian_blocks(
    x: wp.array(dtype=wp.vec3),
    hinge_indices: wp.array(dtype=wp.vec4i),
    hinge_stiffness: wp.array(dtype=float),
    hinge_damping: wp.array(dtype=float),
    alpha: float,
    beta: float,
    blocks: wp.array2d(dtype=wp.mat33),
):
    # blocks[e, 4 a + b] = (alpha k + beta kd) g_a g_b^T: alpha = 1, beta = 0 is the Gauss-Newton
    # d^2E/dx_a dx_b (= -df_a/dx_b); alpha = h^2, beta = h the block implicit Euler's A gains (PSD)
    e = wp.tid()
    q = hinge_indices[e]
    _theta, g0, g1, g2, g3, _valid = hinge_angle_gradient(x[q[0]], x[q[1]], x[q[2]], x[q[3]])
    s = alpha * hinge_stiffness[e] + beta * hinge_damping[e]
    for a in range(4):
        ga = pick_vec3(a, g0, g1, g2, g3)
        for b in range(4):
            blocks[e, 4 * a + b] = s * wp.outer(ga, pick_vec3(b, g0, g1, g2, g3))


@wp.kernel
def add_hinge_system_rows(
    adjacency_offsets: wp.array(dtype=int),
    adjacency_hinge: wp.array(dtype=int),
    adjacency_slot: wp.array(dtype=int),
    adjacency_block: wp.array2d(dtype=int),
    hinge_indices: wp.array(dtype=wp.vec4i),
    hinge_gradient: wp.array2d(dtype=wp.vec3),
    hinge_stiffness: wp.array(dtype=float),
    hinge_damping: wp.array(dtype=float),
    particle_inv_mass: wp.array(dtype=float),
    alpha: float,
    beta: float,
    values: wp.array(dtype=wp.mat33),
    row_part: wp.array(dtype=wp.mat33),
    row_part_solve: wp.array(dtype=wp.mat33),
):
    # row i of a BSR matrix: values[(i, x_b)] += (alpha k + beta kd) g_slot g_b^T over i's hinges, after the
    # spring assembly (gather, no atomics); pinned rows and pinned columns are left alone (identity/zero).
    # The row's sum of the added blocks goes into row_part and row_part_solve too (E_i = sum_j A_ij of the
    # split product, kernels.linalg.block_gemv_split)
    i = wp.tid()
    if particle_inv_mass[i] == 0.0:
        return
    added = wp.mat33(0.0)
    for a in range(adjacency_offsets[i], adjacency_offsets[i + 1]):
        e = adjacency_hinge[a]
        q = hinge_indices[e]
        s = alpha * hinge_stiffness[e] + beta * hinge_damping[e]
        ga = hinge_gradient[e, adjacency_slot[a]]
        for b in range(4):
            if particle_inv_mass[q[b]] != 0.0:
                k = adjacency_block[a, b]
                block = s * wp.outer(ga, hinge_gradient[e, b])
                values[k] = values[k] + block
                added = added + block
    row_part[i] = row_part[i] + added
    row_part_solve[i] = row_part_solve[i] + added


@wp.kernel
def add_hinge_matrix_product(
    adjacency_offsets: wp.array(dtype=int),
    adjacency_hinge: wp.array(dtype=int),
    adjacency_slot: wp.array(dtype=int),
    hinge_indices: wp.array(dtype=wp.vec4i),
    hinge_gradient: wp.array2d(dtype=wp.vec3),
    hinge_stiffness: wp.array(dtype=float),
    hinge_damping: wp.array(dtype=float),
    particle_inv_mass: wp.array(dtype=float),
    alpha: float,
    beta: float,
    zero_pinned_columns: int,
    y: wp.array(dtype=wp.vec3),
    z: wp.array(dtype=wp.vec3),
):
    # z_i += sum_e (alpha k + beta kd) g_slot (sum_b g_b . y_b), matrix-free; pinned rows untouched; y_b = 0 on pins
    # when zero_pinned_columns != 0 (the CG operator), pins' y kept otherwise (the rhs term -h^2 K v of moving pins)
    i = wp.tid()
    if particle_inv_mass[i] == 0.0:
        return
    acc = wp.vec3(0.0)
    for a in range(adjacency_offsets[i], adjacency_offsets[i + 1]):
        e = adjacency_hinge[a]
        q = hinge_indices[e]
        gy = float(0.0)
        for b in range(4):
            if zero_pinned_columns == 0 or particle_inv_mass[q[b]] != 0.0:
                gy = gy + wp.dot(hinge_gradient[e, b], y[q[b]])
        acc = acc + ((alpha * hinge_stiffness[e] + beta * hinge_damping[e]) * gy) * hinge_gradient[e, adjacency_slot[a]]
    z[i] = z[i] + acc


@wp.func
def hinge_vertex_force_hessian(
    i: int,
    x: wp.array(dtype=wp.vec3),
    dx: wp.array(dtype=wp.vec3),
    adjacency_offsets: wp.array(dtype=int),
    adjacency_hinge: wp.array(dtype=int),
    adjacency_slot: wp.array(dtype=int),
    hinge_indices: wp.array(dtype=wp.vec4i),
    hinge_rest_angle: wp.array(dtype=float),
    hinge_stiffness: wp.array(dtype=float),
    hinge_damping: wp.array(dtype=float),
    h: float,
):
    # vertex i's hinge terms at x + dx (VBD): f_i = sum_e -(k wrap(theta - theta0) + kd/h sum_b g_b . dx_b) g_i,
    # H_i = sum_e (k + kd/h) g_i g_i^T; positions relative to x_i, increments relative to dx_i (translation invariant)
    xi = x[i]
    dxi = dx[i]
    f = wp.vec3(0.0)
    H = wp.mat33(0.0)
    for a in range(adjacency_offsets[i], adjacency_offsets[i + 1]):
        e = adjacency_hinge[a]
        q = hinge_indices[e]
        d0 = dx[q[0]] - dxi
        d1 = dx[q[1]] - dxi
        d2 = dx[q[2]] - dxi
        d3 = dx[q[3]] - dxi
        theta, g0, g1, g2, g3, valid = hinge_angle_gradient(
            (x[q[0]] - xi) + d0, (x[q[1]] - xi) + d1, (x[q[2]] - xi) + d2, (x[q[3]] - xi) + d3
        )
        if valid != 0:
            k = hinge_stiffness[e]
            kd = hinge_damping[e]
            s = hinge_force_scale(theta, hinge_rest_angle[e], k, kd / h, g0, g1, g2, g3, d0, d1, d2, d3)
            gi = pick_vec3(adjacency_slot[a], g0, g1, g2, g3)
            f = f + s * gi
            H = H + (k + kd / h) * wp.outer(gi, gi)
    return f, H


@wp.struct
class HingeAdjacency:
    """Each particle's hinges (CSR: particle i's entries offsets[i]:offsets[i + 1], the hinge and the
    particle's slot 0..3 in it) with the hinges' arrays, as one kernel argument (vbd, projective);
    made once at bind. Without hinges every array is empty but ``offsets`` (zeros)."""

    offsets: wp.array(dtype=int)
    hinge: wp.array(dtype=int)
    slot: wp.array(dtype=int)
    indices: wp.array(dtype=wp.vec4i)
    rest_angle: wp.array(dtype=float)
    stiffness: wp.array(dtype=float)
    damping: wp.array(dtype=float)


@wp.func
def vertex_hinge_terms(
    i: int, x: wp.array(dtype=wp.vec3), dx: wp.array(dtype=wp.vec3), hinges: HingeAdjacency, h: float
):
    # (f_i, H_i) of vertex i's hinges at x + dx with the dx / h damping rate (hinge_vertex_force_hessian)
    return hinge_vertex_force_hessian(
        i,
        x,
        dx,
        hinges.offsets,
        hinges.hinge,
        hinges.slot,
        hinges.indices,
        hinges.rest_angle,
        hinges.stiffness,
        hinges.damping,
        h,
    )


@wp.kernel
def eval_hinge_vertex_terms(
    x: wp.array(dtype=wp.vec3),
    dx: wp.array(dtype=wp.vec3),
    adjacency_offsets: wp.array(dtype=int),
    adjacency_hinge: wp.array(dtype=int),
    adjacency_slot: wp.array(dtype=int),
    hinge_indices: wp.array(dtype=wp.vec4i),
    hinge_rest_angle: wp.array(dtype=float),
    hinge_stiffness: wp.array(dtype=float),
    hinge_damping: wp.array(dtype=float),
    h: float,
    force: wp.array(dtype=wp.vec3),
    hessian: wp.array(dtype=wp.mat33),
):
    # per vertex: (f_i, H_i) = hinge_vertex_force_hessian (what VBD adds to its local 3x3 problem)
    i = wp.tid()
    f, H = hinge_vertex_force_hessian(
        i,
        x,
        dx,
        adjacency_offsets,
        adjacency_hinge,
        adjacency_slot,
        hinge_indices,
        hinge_rest_angle,
        hinge_stiffness,
        hinge_damping,
        h,
    )
    force[i] = f
    hessian[i] = H


@wp.func
def hinge_weighted_norm(w0: float, w1: float, w2: float, w3: float, g0: wp.vec3, g1: wp.vec3, g2: wp.vec3, g3: wp.vec3):
    # sum_b w_b |g_b|^2
    return w0 * wp.dot(g0, g0) + w1 * wp.dot(g1, g1) + w2 * wp.dot(g2, g2) + w3 * wp.dot(g3, g3)


@wp.kernel
def solve_hinges_xpbd(
    hinge_order: wp.array(dtype=wp.int32),
    start: int,
    hinge_indices: wp.array(dtype=wp.vec4i),
    hinge_rest_angle: wp.array(dtype=float),
    hinge_stiffness: wp.array(dtype=float),
    hinge_damping: wp.array(dtype=float),
    particle_inv_mass: wp.array(dtype=float),
    x: wp.array(dtype=wp.vec3),
    h: float,
    lam: wp.array(dtype=float),
    dp: wp.array(dtype=wp.vec3),
):
    # one colour, C = wrap(theta - theta0), gradC = g, alpha = 1/k (Macklin et al. 2016 eq. 18, 26, times k h^2):
    # dlam = -(k h^2 C + kd h sum_b g_b . dp_b + lam) / ((k h^2 + kd h) sum_b w_b |g_b|^2 + 1);  dp_b += w_b g_b dlam
    e = hinge_order[start + wp.tid()]
    q = hinge_indices[e]
    d0 = dp[q[0]]
    d1 = dp[q[1]]
    d2 = dp[q[2]]
    d3 = dp[q[3]]
    p0 = x[q[0]]
    theta, g0, g1, g2, g3, valid = hinge_angle_gradient(
        wp.vec3(0.0), (x[q[1]] - p0) + (d1 - d0), (x[q[2]] - p0) + (d2 - d0), (x[q[3]] - p0) + (d3 - d0)
    )
    if valid == 0:
        return
    w0 = particle_inv_mass[q[0]]
    w1 = particle_inv_mass[q[1]]
    w2 = particle_inv_mass[q[2]]
    w3 = particle_inv_mass[q[3]]
    wg = hinge_weighted_norm(w0, w1, w2, w3, g0, g1, g2, g3)
    if wg == 0.0:
        return
    k = hinge_stiffness[e]
    kd = hinge_damping[e]
    c = wrap_angle(theta - hinge_rest_angle[e])
    rate = wp.dot(g0, d0) + wp.dot(g1, d1) + wp.dot(g2, d2) + wp.dot(g3, d3)
    dlam = -(k * h * h * c + kd * h * rate + lam[e]) / ((k * h * h + kd * h) * wg + 1.0)
    lam[e] = lam[e] + dlam
    dp[q[0]] = d0 + (w0 * dlam) * g0
    dp[q[1]] = d1 + (w1 * dlam) * g1
    dp[q[2]] = d2 + (w2 * dlam) * g2
    dp[q[3]] = d3 + (w3 * dlam) * g3


@wp.kernel
def solve_hinges_pbd(
    hinge_order: wp.array(dtype=wp.int32),
    start: int,
    hinge_indices: wp.array(dtype=wp.vec4i),
    hinge_rest_angle: wp.array(dtype=float),
    stiffness: float,
    particle_inv_mass: wp.array(dtype=float),
    x: wp.array(dtype=wp.vec3),
    dp: wp.array(dtype=wp.vec3),
):
    # one colour, C = wrap(theta - theta0): dp_b += -k_pbd w_b C g_b / sum_c w_c |g_c|^2  (Müller et al. 2007, eq. 8-9)
    e = hinge_order[start + wp.tid()]
    q = hinge_indices[e]
    d0 = dp[q[0]]
    d1 = dp[q[1]]
    d2 = dp[q[2]]
    d3 = dp[q[3]]
    p0 = x[q[0]]
    theta, g0, g1, g2, g3, valid = hinge_angle_gradient(
        wp.vec3(0.0), (x[q[1]] - p0) + (d1 - d0), (x[q[2]] - p0) + (d2 - d0), (x[q[3]] - p0) + (d3 - d0)
    )
    if valid == 0:
        return
    w0 = particle_inv_mass[q[0]]
    w1 = particle_inv_mass[q[1]]
    w2 = particle_inv_mass[q[2]]
    w3 = particle_inv_mass[q[3]]
    wg = hinge_weighted_norm(w0, w1, w2, w3, g0, g1, g2, g3)
    if wg == 0.0:
        return
    s = -stiffness * wrap_angle(theta - hinge_rest_angle[e]) / wg
    dp[q[0]] = d0 + (w0 * s) * g0
    dp[q[1]] = d1 + (w1 * s) * g1
    dp[q[2]] = d2 + (w2 * s) * g2
    dp[q[3]] = d3 + (w3 * s) * g3
