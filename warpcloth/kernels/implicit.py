"""Implicit Euler (Baraff & Witkin 1998; seed eq. 2.19-2.22): the right-hand side, the velocity
update, CG statistics, and the contacts the solve sees (Baraff & Witkin's filter, with sticking).

The linear system of one step is

    A dv = b,   A = M - h df/dv - h^2 df/dx,   b = h (f + h df/dx v),

A assembled or applied by :mod:`warpcloth.kernels.system` (its spring Jacobians K_s, B_s),
solved by the preconditioned CG of :mod:`warpcloth.kernels.linalg`. Pinned particles (inverse
mass 0) get identity rows and zero columns, so their dv is 0.
"""

import warp as wp

from warpcloth.kernels.collide import Collider, collider_contact, surface_velocity
from warpcloth.kernels.linalg import inverse_diagonal
from warpcloth.kernels.self_contact import weighted_sum
from warpcloth.kernels.springs import SpringAdjacency

# forward only: no adjoints (half the compile time; warpcloth differentiates nothing)
wp.set_module_options({"enable_backward": False})


@wp.kernel
def eval_rhs(
    f: wp.array(dtype=wp.vec3),
    v: wp.array(dtype=wp.vec3),
    springs: SpringAdjacency,
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
    for a in range(springs.offsets[i], springs.offsets[i + 1]):
        kv = kv + spring_K[springs.spring[a]] * (v[springs.other[a]] - vi)
    b[i] = h * (f[i] + h * kv)


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
    # a NaN residual counts as capped); a solve's iterations are its passes' (stats[11]: the
    # earlier passes' of this step, from add_cg_iterations), as on the CPU
    it = wp.float64(iterations[0]) + stats[11]
    stats[11] = wp.float64(0.0)
    res = wp.float64(tol * wp.sqrt(residual_sq[0] / wp.max(tolerance_sq[0], 1.0e-30)))
    stats[0] = stats[0] + wp.float64(1.0)
    stats[1] = stats[1] + it
    stats[2] = wp.max(stats[2], it)
    stats[3] = stats[3] + res
    stats[4] = wp.max(stats[4], res)
    if not (residual_sq[0] <= tolerance_sq[0]):
        stats[5] = stats[5] + wp.float64(1.0)


@wp.kernel
def record_true_residual(partial: wp.array(dtype=wp.vec3d), tol: float, stats: wp.array(dtype=wp.float64)):
    # from the chunk sums of (|b - A dv|^2, |b|^2, |A delta|^2) (kernels.linalg.residual_terms): stats[6] +=
    # the true |b - A dv| / |b|, stats[7] = its max, stats[8] = max floor estimate |A delta| / |b|,
    # stats[9] += 1 where the true residual is above tol (or NaN), stats[10] += the floor estimate (one thread)
    acc = wp.vec3d(0.0)
    for c in range(partial.shape[0]):
        acc = acc + partial[c]
    true = wp.float64(0.0)
    floor = wp.float64(0.0)
    if acc[1] > wp.float64(0.0):
        true = wp.sqrt(acc[0] / acc[1])
        floor = wp.sqrt(acc[2] / acc[1])
    elif acc[0] > wp.float64(0.0):
        true = wp.float64(1.0)
    stats[6] = stats[6] + true
    stats[7] = wp.max(stats[7], true)
    stats[8] = wp.max(stats[8], floor)
    if not (true <= wp.float64(tol)):
        stats[9] = stats[9] + wp.float64(1.0)
    stats[10] = stats[10] + floor


@wp.kernel
def add_cg_iterations(iterations: wp.array(dtype=int), stats: wp.array(dtype=wp.float64)):
    # a restarted solve's earlier pass: its iterations held for the step (CUDA; record_cg_stats adds
    # the last pass and counts the step's total in the sum and the max)
    stats[11] = stats[11] + wp.float64(iterations[0])


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
    gravity: wp.vec3,
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
    # momentum it would have, |p| = |m v_r,t + h m g_t| < mu J_n with J_n the larger of
    # m max(0, -v_r . n) and its weight's -h m g . n (a landing particle, whose approach the
    # projection already stopped, has v_r,t = 0 to rounding); the next solve tells whether the cone
    # held. Not the explicit force f: in a stiff cloth its springs' part is ~1000 times the weight
    # and the implicit solve balances it; sized by it, a new contact of the fold pressed by the
    # hand got a friction impulse 300 times its own momentum, which the solve passed on to its
    # neighbours (4-7 m/s; tests/test_implicit_contact.py). A sliding
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
            jn = wp.max(wp.max(jn_prev, m * wp.max(0.0, -vrn)), -h * m * wp.dot(gravity, n))
            # tangential momentum a new contact would have after the step without friction
            p = m * vt + h * m * (gravity - wp.dot(gravity, n) * n)
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
    mode: wp.array(dtype=int),
    normal: wp.array(dtype=wp.vec3),
    collider_v: wp.array(dtype=wp.vec3),
    v: wp.array(dtype=wp.vec3),
    z: wp.array(dtype=wp.vec3),
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
    # (Coulomb's cap; mode STOPPED: it sticks next step). STICK past the cone (|J_t| > mu J_n, J_n = max(0, J . n)): the
    # tangential
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
    x: wp.array(dtype=wp.vec3),
    inv_mass: wp.array(dtype=float),
    colliders: wp.array(dtype=Collider),
    mode: wp.array(dtype=int),
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
        phi, _n = collider_contact(colliders, k, x[i], colliders[k].thickness)
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
    row_part: wp.array(dtype=wp.mat33),
    values: wp.array(dtype=wp.mat33),
    inv_diag: wp.array(dtype=wp.vec3),
    row_part_solve: wp.array(dtype=wp.mat33),
):
    # A <- S A S + P A_ii P (P = I - S) on the diagonal, S_i A_ij S_j off it: the prescribed
    # directions leave the solve (P A_ii P keeps them nonsingular and uncoupled; for SLIDE it is
    # (n^T A_ii n) n n^T); inv_diag = 1 / diag(A_ii) of the filtered A (Jacobi). row_part_solve =
    # the filtered E'_i = A'_ii + sum_j A'_ij = S_i E_i S_i + P_i A_ii P_i + sum_j S_i A_ij (S_j - S_i),
    # from the unfiltered E_i (row_part) and blocks: terms vanish where S_i = S_j (block_gemv_split)
    i = wp.tid()
    Si = contact_filter(mode[i], normal[i])
    Pi = wp.identity(n=3, dtype=float) - Si
    d = diag_block[i]
    E = Si * row_part[i] * Si
    for e in range(row_offsets[i], row_offsets[i + 1]):
        if e == d:
            block = values[e]
            values[e] = Si * block * Si + Pi * block * Pi
            E = E + Pi * block * Pi
        else:
            j = columns[e]
            Sj = contact_filter(mode[j], normal[j])
            E = E + Si * values[e] * (Sj - Si)
            values[e] = Si * values[e] * Sj
    inv_diag[i] = inverse_diagonal(values[d])
    row_part_solve[i] = E


@wp.kernel
def filter_rhs(
    mode: wp.array(dtype=int),
    normal: wp.array(dtype=wp.vec3),
    Az: wp.array(dtype=wp.vec3),
    friction_impulse: wp.array(dtype=wp.vec3),
    b: wp.array(dtype=wp.vec3),
    dv: wp.array(dtype=wp.vec3),
):
    # b <- S (b + F - A z) (a sliding contact's friction impulse F added, the prescribed dv moved
    # to the right side);  dv <- S dv (the warm start)
    i = wp.tid()
    S = contact_filter(mode[i], normal[i])
    b[i] = S * (b[i] + friction_impulse[i] - Az[i])
    dv[i] = S * dv[i]


@wp.kernel
def unfilter_dv(
    mode: wp.array(dtype=int), normal: wp.array(dtype=wp.vec3), z: wp.array(dtype=wp.vec3), dv: wp.array(dtype=wp.vec3)
):
    # dv = S y + z (S y: CG's solution without what rounding and the preconditioner left in the
    # prescribed directions)
    i = wp.tid()
    dv[i] = contact_filter(mode[i], normal[i]) * dv[i] + z[i]


# -- self-contact in the solve (warpcloth.sim.self_collision) --------------------------------------
@wp.kernel
def add_self_contact_rhs(
    stride: int,
    counts: wp.array(dtype=int),
    count_slot: int,
    x: wp.array(dtype=wp.vec3),
    v: wp.array(dtype=wp.vec3),
    inv_mass: wp.array(dtype=float),
    c_idx: wp.array(dtype=wp.vec4i),
    c_w: wp.array(dtype=wp.vec4),
    c_n: wp.array(dtype=wp.vec3),
    c_h: wp.array(dtype=float),
    stiffness: float,
    h: float,
    b: wp.array(dtype=wp.vec3),
):
    # the repulsion f_a = k delta W_a n of every contact with delta = h_c - n . sum W x > 0 in
    # b = h (f + h df/dx v): b_a += h k W_a (delta - h n . sum W v) n on free a (df_a/dx_b = -k W_a W_b n n^T)
    tid = wp.tid()
    for k in range(tid, counts[count_slot], stride):
        idx = c_idx[k]
        w = c_w[k]
        n = c_n[k]
        delta = c_h[k] - wp.dot(n, weighted_sum(x, idx, w))
        if delta > 0.0:
            s = h * stiffness * (delta - h * wp.dot(n, weighted_sum(v, idx, w)))
            for j in range(4):
                if inv_mass[idx[j]] > 0.0:
                    wp.atomic_add(b, idx[j], (w[j] * s) * n)


@wp.kernel
def add_self_contact_product(
    stride: int,
    counts: wp.array(dtype=int),
    count_slot: int,
    x: wp.array(dtype=wp.vec3),
    inv_mass: wp.array(dtype=float),
    c_idx: wp.array(dtype=wp.vec4i),
    c_w: wp.array(dtype=wp.vec4),
    c_n: wp.array(dtype=wp.vec3),
    c_h: wp.array(dtype=float),
    mode: wp.array(dtype=int),
    normal: wp.array(dtype=wp.vec3),
    filtered: int,
    scale: float,
    y: wp.array(dtype=wp.vec3),
    z: wp.array(dtype=wp.vec3),
):
    # z += scale C y, C = sum over contacts with delta > 0 of the block W_a W_b n n^T (A's contact part
    # h^2 k W W^T n n^T with scale = alpha h^2 k); pinned rows and columns left out; with ``filtered``
    # the colliders' filter S on both sides (S C S, as the solve's A)
    tid = wp.tid()
    for k in range(tid, counts[count_slot], stride):
        idx = c_idx[k]
        w = c_w[k]
        n = c_n[k]
        if c_h[k] - wp.dot(n, weighted_sum(x, idx, w)) > 0.0:
            u = float(0.0)
            for j in range(4):
                a = idx[j]
                if inv_mass[a] > 0.0:
                    ya = y[a]
                    if filtered != 0:
                        ya = contact_filter(mode[a], normal[a]) * ya
                    u += w[j] * wp.dot(n, ya)
            for j in range(4):
                a = idx[j]
                if inv_mass[a] > 0.0:
                    za = (scale * w[j] * u) * n
                    if filtered != 0:
                        za = contact_filter(mode[a], normal[a]) * za
                    wp.atomic_add(z, a, za)


@wp.kernel
def translation_basis(
    mode: wp.array(dtype=int),
    normal: wp.array(dtype=wp.vec3),
    inv_mass: wp.array(dtype=float),
    filtered: int,
    t0: wp.array(dtype=wp.vec3),
    t1: wp.array(dtype=wp.vec3),
    t2: wp.array(dtype=wp.vec3),
):
    # T's columns T_k,i = S_i e_k (the solve's unknowns moved rigidly along axis k: S = I free, I - n n^T
    # sliding, 0 sticking, with ``filtered``); pinned particles 0
    i = wp.tid()
    S = wp.identity(n=3, dtype=float)
    if inv_mass[i] == 0.0:
        S = wp.mat33(0.0)
    elif filtered != 0:
        S = contact_filter(mode[i], normal[i])
    t0[i] = S * wp.vec3(1.0, 0.0, 0.0)
    t1[i] = S * wp.vec3(0.0, 1.0, 0.0)
    t2[i] = S * wp.vec3(0.0, 0.0, 1.0)


@wp.kernel
def translation_terms(
    t0: wp.array(dtype=wp.vec3),
    t1: wp.array(dtype=wp.vec3),
    t2: wp.array(dtype=wp.vec3),
    a0: wp.array(dtype=wp.vec3),
    a1: wp.array(dtype=wp.vec3),
    a2: wp.array(dtype=wp.vec3),
    r: wp.array(dtype=wp.vec3),
    b: wp.array(dtype=wp.vec3),
    A: wp.array(dtype=wp.mat33),
):
    # particle i's share of T^T r and T^T A T (a_k = A T_k, r = b - A dv): summed in a fixed order by
    # TranslationSolve
    i = wp.tid()
    b[i] = wp.vec3(wp.dot(t0[i], r[i]), wp.dot(t1[i], r[i]), wp.dot(t2[i], r[i]))
    A[i] = wp.mat33(
        wp.dot(t0[i], a0[i]),
        wp.dot(t0[i], a1[i]),
        wp.dot(t0[i], a2[i]),
        wp.dot(t1[i], a0[i]),
        wp.dot(t1[i], a1[i]),
        wp.dot(t1[i], a2[i]),
        wp.dot(t2[i], a0[i]),
        wp.dot(t2[i], a1[i]),
        wp.dot(t2[i], a2[i]),
    )


@wp.kernel
def add_translation(
    translation: wp.array(dtype=wp.vec3),
    t0: wp.array(dtype=wp.vec3),
    t1: wp.array(dtype=wp.vec3),
    t2: wp.array(dtype=wp.vec3),
    dv: wp.array(dtype=wp.vec3),
):
    # dv += T t (the Galerkin translation correction)
    i = wp.tid()
    t = translation[0]
    dv[i] = dv[i] + t[0] * t0[i] + t[1] * t1[i] + t[2] * t2[i]
