"""Position-based constraint kernels: PBD (Müller et al. 2007) and XPBD (Macklin et al. 2016).

Each spring (i, j) of the cloth is a distance constraint C(p) = |p_j - p_i| - L0 (bend springs
too). The constraint math lives in pure ``@wp.func`` helpers that return corrections; the
kernels only index, predict and scatter.

**Parallel projection: graph colouring, Gauss-Seidel colour by colour.** The springs are split
at bind time (:mod:`warpcloth.sim.coloring`) into colours in which no two springs share a
particle; one launch projects one colour in parallel without atomics, equal to a sequential
Gauss-Seidel sweep in colour order: it converges like Gauss-Seidel, is deterministic and conserves
the mass-weighted sum of corrections per constraint (docs/solvers.md, "Graph colouring").

**Increments, not positions.** The predicted positions are carried as the displacement
dp = p - x of the (sub)step: the constraint sees p_j - p_i = (x_j - x_i) + (dp_j - dp_i), the
corrections add to dp, and the update is v = dp / h, x += dp. Forming p = x + h v and
v = (p - x) / h in float32 rounds h v to a multiple of ulp(x) (~1.2e-7 m at 1.5 m), which many
substeps accumulate (docs/stability.md, "Float32: increments, not rounded differences").

**Angular momentum: the substep's edge direction (SHAKE).** With v = dp / h, a correction c changes
L = sum m x_new x v_new by sum m x x c / h = -sum m dp x c / h: zero for c along the substep's start
edge r = x_j - x_i (SHAKE, Ryckaert et al. 1977), not for c along the predicted d = p_j - p_i (PBD's
gradient), which turns a free cloth (docs/solvers.md). ``along_start`` picks r, scaled so that the
linearised C falls as PBD's / XPBD's does (n.r in place of |d| and of n.n = 1).
"""

import warp as wp

from warpcloth.kernels.springs import compressed_stiffness

# forward only: no adjoints (half the compile time; warpcloth differentiates nothing)
wp.set_module_options({"enable_backward": False})


@wp.func
def distance_correction_pbd(d: wp.vec3, wi: float, wj: float, rest: float, stiffness: float, phi: float):
    # C = |d| - L0, d = p_j - p_i, n = d/|d|, k = stiffness (phi stiffness where C < 0: compression factor)
    # dp_i = +k w_i/(w_i + w_j) C n,  dp_j = -k w_j/(w_i + w_j) C n   (Müller et al. 2007, section 3.3)
    length = wp.length(d)
    w = wi + wj
    if length == 0.0 or w == 0.0:
        return wp.vec3(0.0), wp.vec3(0.0)
    s = compressed_stiffness(length, rest, stiffness, phi) * (length - rest) / (length * w)
    return (s * wi) * d, (-s * wj) * d


@wp.func
def distance_correction_pbd_along(
    d: wp.vec3, r: wp.vec3, wi: float, wj: float, rest: float, stiffness: float, phi: float
):
    # PBD's step along the substep's start edge r = x_j - x_i (SHAKE): dp_i = +s w_i r, dp_j = -s w_j r,
    # s = k C / (w n.r), so that the linearised C(p + dp) = C - k C as PBD's; nothing where n.r <= 0
    length = wp.length(d)
    w = wi + wj
    nr = wp.dot(d, r)
    if length == 0.0 or w == 0.0 or nr <= 0.0:
        return wp.vec3(0.0), wp.vec3(0.0)
    s = compressed_stiffness(length, rest, stiffness, phi) * (length - rest) * length / (nr * w)
    return (s * wi) * r, (-s * wj) * r


@wp.func
def distance_correction_xpbd(
    d: wp.vec3,
    dpi: wp.vec3,
    dpj: wp.vec3,
    wi: float,
    wj: float,
    rest: float,
    ks: float,
    kd: float,
    phi: float,
    lam: float,
    h: float,
):
    # C = |d| - L0, d = p_j - p_i, n = d/|d|, dp = p - x (the displacement of this substep); ks -> phi ks where C < 0
    # dlam = -(ks h^2 C + kd h gradC.(p - x) + lam) / ((ks h^2 + kd h)(w_i + w_j) + 1)
    # (Macklin et al. 2016, eq. 18 and 26, times 1/alpha_tilde = ks h^2, gamma = kd/(ks h));
    # dp_i = -w_i n dlam, dp_j = +w_j n dlam   (gradC = (-n, n))
    length = wp.length(d)
    w = wi + wj
    if length == 0.0 or w == 0.0:
        return wp.vec3(0.0), wp.vec3(0.0), 0.0
    n = d / length
    c = length - rest
    c_dot_h = wp.dot(n, dpj - dpi)
    ks = compressed_stiffness(length, rest, ks, phi)
    dlam = -(ks * h * h * c + kd * h * c_dot_h + lam) / ((ks * h * h + kd * h) * w + 1.0)
    return (-wi * dlam) * n, (wj * dlam) * n, dlam


@wp.func
def distance_correction_xpbd_along(
    d: wp.vec3,
    r: wp.vec3,
    dpi: wp.vec3,
    dpj: wp.vec3,
    wi: float,
    wj: float,
    rest: float,
    ks: float,
    kd: float,
    phi: float,
    lam: float,
    h: float,
):
    # XPBD's step along the substep's start edge, e = r/|r| (SHAKE): dp_i = -w_i e dlam, dp_j = +w_j e dlam,
    # dlam as distance_correction_xpbd's with gradC(p) M^-1 e^T = w n.e in place of w; nothing where n.e <= 0
    length = wp.length(d)
    rl = wp.length(r)
    w = wi + wj
    if length == 0.0 or rl == 0.0 or w == 0.0:
        return wp.vec3(0.0), wp.vec3(0.0), 0.0
    n = d / length
    e = r / rl
    ne = wp.dot(n, e)
    if ne <= 0.0:
        return wp.vec3(0.0), wp.vec3(0.0), 0.0
    c = length - rest
    c_dot_h = wp.dot(n, dpj - dpi)
    ks = compressed_stiffness(length, rest, ks, phi)
    dlam = -(ks * h * h * c + kd * h * c_dot_h + lam) / ((ks * h * h + kd * h) * w * ne + 1.0)
    return (-wi * dlam) * e, (wj * dlam) * e, dlam


@wp.kernel
def integrate_predict(
    v: wp.array(dtype=wp.vec3),
    f: wp.array(dtype=wp.vec3),
    particle_inv_mass: wp.array(dtype=float),
    dt: float,
    velocity_keep: float,
    dp: wp.array(dtype=wp.vec3),
):
    # v <- (1 - k_damp)(v + dt w f_ext) ;  dp = p - x = dt v   (Müller et al. 2007, Alg. 1 lines 5-11)
    i = wp.tid()
    w = particle_inv_mass[i]
    if w == 0.0:
        dp[i] = wp.vec3(0.0)
        return
    vi = velocity_keep * (v[i] + (dt * w) * f[i])
    v[i] = vi
    dp[i] = dt * vi


@wp.kernel
def solve_springs_pbd(
    spring_order: wp.array(dtype=wp.int32),
    start: int,
    spring_indices: wp.array(dtype=wp.vec2i),
    spring_rest_length: wp.array(dtype=float),
    spring_type: wp.array(dtype=wp.int32),
    type_stiffness: wp.vec3,
    spring_compression: wp.array(dtype=float),
    particle_inv_mass: wp.array(dtype=float),
    x: wp.array(dtype=wp.vec3),
    along_start: int,
    dp: wp.array(dtype=wp.vec3),
):
    # one colour: dp_i += dp_i', dp_j += dp_j' with k' of the spring's type, p - p = (x_j - x_i) + (dp_j - dp_i);
    # along_start: along x_j - x_i (SHAKE, keeps a free cloth's angular momentum), else along p_j - p_i
    s = spring_order[start + wp.tid()]
    ij = spring_indices[s]
    i = ij[0]
    j = ij[1]
    r = x[j] - x[i]
    d = r + (dp[j] - dp[i])
    wi = particle_inv_mass[i]
    wj = particle_inv_mass[j]
    k = type_stiffness[spring_type[s]]
    ci = wp.vec3(0.0)
    cj = wp.vec3(0.0)
    if along_start != 0:
        ci, cj = distance_correction_pbd_along(d, r, wi, wj, spring_rest_length[s], k, spring_compression[s])
    else:
        ci, cj = distance_correction_pbd(d, wi, wj, spring_rest_length[s], k, spring_compression[s])
    dp[i] = dp[i] + ci
    dp[j] = dp[j] + cj


@wp.kernel
def solve_springs_xpbd(
    spring_order: wp.array(dtype=wp.int32),
    start: int,
    spring_indices: wp.array(dtype=wp.vec2i),
    spring_rest_length: wp.array(dtype=float),
    spring_stiffness: wp.array(dtype=float),
    spring_damping: wp.array(dtype=float),
    spring_compression: wp.array(dtype=float),
    particle_inv_mass: wp.array(dtype=float),
    x: wp.array(dtype=wp.vec3),
    h: float,
    along_start: int,
    lam: wp.array(dtype=float),
    dp: wp.array(dtype=wp.vec3),
):
    # one colour: lam += dlam, dp_i += dp_i', dp_j += dp_j'  (compliance alpha = 1/ks, damping beta = kd);
    # along_start: along x_j - x_i (SHAKE, keeps a free cloth's angular momentum), else along gradC(p)
    s = spring_order[start + wp.tid()]
    ij = spring_indices[s]
    i = ij[0]
    j = ij[1]
    dpi = dp[i]
    dpj = dp[j]
    r = x[j] - x[i]
    d = r + (dpj - dpi)
    wi = particle_inv_mass[i]
    wj = particle_inv_mass[j]
    ks = spring_stiffness[s]
    kd = spring_damping[s]
    rest = spring_rest_length[s]
    phi = spring_compression[s]
    ci = wp.vec3(0.0)
    cj = wp.vec3(0.0)
    dlam = float(0.0)
    if along_start != 0:
        ci, cj, dlam = distance_correction_xpbd_along(d, r, dpi, dpj, wi, wj, rest, ks, kd, phi, lam[s], h)
    else:
        ci, cj, dlam = distance_correction_xpbd(d, dpi, dpj, wi, wj, rest, ks, kd, phi, lam[s], h)
    lam[s] = lam[s] + dlam
    dp[i] = dpi + ci
    dp[j] = dpj + cj


@wp.kernel
def clear_lambda(lam: wp.array(dtype=float)):
    # lam = 0 at the start of each (sub)step   (Macklin et al. 2016, Algorithm 1)
    lam[wp.tid()] = 0.0


@wp.kernel
def update_velocities(
    x: wp.array(dtype=wp.vec3),
    v: wp.array(dtype=wp.vec3),
    dp: wp.array(dtype=wp.vec3),
    particle_inv_mass: wp.array(dtype=float),
    dt: float,
):
    # v = (p - x) / dt = dp / dt ;  x = p = x + dp   (Müller et al. 2007, Alg. 1 lines 18-21); pins keep x and v
    i = wp.tid()
    if particle_inv_mass[i] == 0.0:
        return
    d = dp[i]
    v[i] = d / dt
    x[i] = x[i] + d
