"""Provot's deformation constraints (Provot 1995; seed 2.1.3.3): springs stretched beyond
(1 + tau) L0 are shortened to that length by moving their free ends, then velocities are
made consistent with the corrected positions."""

import warp as wp

# forward only: no adjoints (half the compile time; warpcloth differentiates nothing)
wp.set_module_options({"enable_backward": False})


@wp.func
def strain_limit_correction(xi: wp.vec3, xj: wp.vec3, wi: float, wj: float, max_length: float):
    # c = (L - L_max) / (w_i + w_j) n  if L > L_max, else 0;  x_i += w_i c,  x_j -= w_j c
    w = wi + wj
    d = xj - xi
    length = wp.length(d)
    if w == 0.0 or length <= max_length:
        return wp.vec3(0.0)
    return ((length - max_length) / (w * length)) * d


@wp.kernel
def solve_strain_limit(
    x: wp.array(dtype=wp.vec3),
    spring_indices: wp.array(dtype=wp.vec2i),
    spring_max_length: wp.array(dtype=float),
    particle_inv_mass: wp.array(dtype=float),
    offset: int,
):
    # one colour of springs (no two share a particle): shorten those longer than L_max = (1 + tau) L0
    s = offset + wp.tid()
    ij = spring_indices[s]
    wi = particle_inv_mass[ij[0]]
    wj = particle_inv_mass[ij[1]]
    c = strain_limit_correction(x[ij[0]], x[ij[1]], wi, wj, spring_max_length[s])
    if wi != 0.0:
        x[ij[0]] = x[ij[0]] + wi * c
    if wj != 0.0:
        x[ij[1]] = x[ij[1]] - wj * c


@wp.kernel
def apply_position_correction_velocity(
    x: wp.array(dtype=wp.vec3),
    x_before: wp.array(dtype=wp.vec3),
    particle_inv_mass: wp.array(dtype=float),
    inv_dt: float,
    v: wp.array(dtype=wp.vec3),
):
    # v += (x - x_before) / dt   (free particles; pinned ones never moved)
    i = wp.tid()
    if particle_inv_mass[i] != 0.0:
        v[i] = v[i] + inv_dt * (x[i] - x_before[i])


@wp.kernel
def solve_long_range_attachment(
    x: wp.array(dtype=wp.vec3),
    attachment_pin: wp.array(dtype=int),
    attachment_max_length: wp.array(dtype=float),
    particle_inv_mass: wp.array(dtype=float),
):
    # |x_i - x_pin| <= (1 + tau) g_i, g_i the rest path length to the nearest pin: pull x_i onto that sphere
    i = wp.tid()
    pin = attachment_pin[i]
    if pin < 0 or particle_inv_mass[i] == 0.0:
        return
    d = x[i] - x[pin]
    length = wp.length(d)
    max_length = attachment_max_length[i]
    if length > max_length:
        x[i] = x[pin] + (max_length / length) * d


@wp.kernel
def reset_strain_limit_loop(condition: wp.array(dtype=wp.int32), passes: wp.array(dtype=wp.int32)):
    # start the pass loop: run at least one pass
    condition[0] = 1
    passes[0] = 0


@wp.kernel
def begin_strain_limit_check(condition: wp.array(dtype=wp.int32), passes: wp.array(dtype=wp.int32)):
    # one more pass done; the check below sets condition = 1 if another is needed
    passes[0] = passes[0] + 1
    condition[0] = 0


@wp.kernel
def check_strain_limit(
    x: wp.array(dtype=wp.vec3),
    spring_indices: wp.array(dtype=wp.vec2i),
    spring_max_length: wp.array(dtype=float),
    tau: float,
    tolerance: float,
    max_passes: int,
    passes: wp.array(dtype=wp.int32),
    condition: wp.array(dtype=wp.int32),
):
    # another pass while some spring has strain > tau + tolerance, i.e. L > L_max + tolerance L0
    s = wp.tid()
    ij = spring_indices[s]
    max_length = spring_max_length[s]
    if wp.length(x[ij[1]] - x[ij[0]]) > max_length + tolerance * max_length / (1.0 + tau):
        if passes[0] < max_passes:
            condition[0] = 1


@wp.kernel
def mark_strain_limit_engaged(
    x: wp.array(dtype=wp.vec3),
    x_before: wp.array(dtype=wp.vec3),
    engaged: wp.array(dtype=wp.int32),
):
    # the limit engaged this step where it moved a particle (x != the step's result); every writer writes 1
    i = wp.tid()
    a = x[i]
    b = x_before[i]
    if a[0] != b[0] or a[1] != b[1] or a[2] != b[2]:
        engaged[0] = 1


@wp.kernel
def count_strain_limit_step(
    engaged: wp.array(dtype=wp.int32),
    passes: wp.array(dtype=wp.int32),
    max_passes: int,
    counts: wp.array(dtype=wp.int64),
):
    # counts = [steps, steps the limit engaged in, steps that ran all max_passes passes]; one thread
    counts[0] = counts[0] + wp.int64(1)
    counts[1] = counts[1] + wp.int64(engaged[0])
    if passes[0] >= max_passes:
        counts[2] = counts[2] + wp.int64(1)
    engaged[0] = 0
