"""Per-particle integrator updates. Pinned particles (inverse mass 0) never change position."""

import warp as wp

# forward only: no adjoints (half the compile time; warpcloth differentiates nothing)
wp.set_module_options({"enable_backward": False})


@wp.kernel
def integrate_explicit_euler(
    x: wp.array(dtype=wp.vec3),
    v: wp.array(dtype=wp.vec3),
    f: wp.array(dtype=wp.vec3),
    particle_inv_mass: wp.array(dtype=float),
    dt: float,
):
    # v <- v + dt f/m ;  x <- x + dt v_new   (seed eq. 2.15, semi-implicit form)
    i = wp.tid()
    w = particle_inv_mass[i]
    if w == 0.0:
        return
    v_new = v[i] + dt * w * f[i]
    v[i] = v_new
    x[i] = x[i] + dt * v_new


@wp.kernel
def integrate_rk_stage(
    x0: wp.array(dtype=wp.vec3),
    v0: wp.array(dtype=wp.vec3),
    v_stage: wp.array(dtype=wp.vec3),
    f_stage: wp.array(dtype=wp.vec3),
    particle_inv_mass: wp.array(dtype=float),
    h: float,
    x_out: wp.array(dtype=wp.vec3),
    v_out: wp.array(dtype=wp.vec3),
):
    # (x, v)_out = (x0, v0) + h (v_stage, f_stage / m)   (one explicit Runge-Kutta stage)
    i = wp.tid()
    w = particle_inv_mass[i]
    if w == 0.0:
        x_out[i] = x0[i]
        v_out[i] = v0[i]
        return
    x_out[i] = x0[i] + h * v_stage[i]
    v_out[i] = v0[i] + h * w * f_stage[i]


@wp.kernel
def integrate_rk4_stage(
    x0: wp.array(dtype=wp.vec3),
    v0: wp.array(dtype=wp.vec3),
    v_stage: wp.array(dtype=wp.vec3),
    f_stage: wp.array(dtype=wp.vec3),
    particle_inv_mass: wp.array(dtype=float),
    h: float,
    weight: float,
    first: int,
    acc_x: wp.array(dtype=wp.vec3),
    acc_v: wp.array(dtype=wp.vec3),
    x_out: wp.array(dtype=wp.vec3),
    v_out: wp.array(dtype=wp.vec3),
):
    # acc += weight k ;  (x, v)_out = (x0, v0) + h k,  k = (v_stage, f_stage / m)   (seed eq. 2.17)
    i = wp.tid()
    w = particle_inv_mass[i]
    kx = v_stage[i]
    kv = w * f_stage[i]
    if first != 0:
        acc_x[i] = weight * kx
        acc_v[i] = weight * kv
    else:
        acc_x[i] = acc_x[i] + weight * kx
        acc_v[i] = acc_v[i] + weight * kv
    if w == 0.0:
        x_out[i] = x0[i]
        v_out[i] = v0[i]
        return
    x_out[i] = x0[i] + h * kx
    v_out[i] = v0[i] + h * kv


@wp.kernel
def integrate_rk4_final(
    x: wp.array(dtype=wp.vec3),
    v: wp.array(dtype=wp.vec3),
    v_stage: wp.array(dtype=wp.vec3),
    f_stage: wp.array(dtype=wp.vec3),
    particle_inv_mass: wp.array(dtype=float),
    acc_x: wp.array(dtype=wp.vec3),
    acc_v: wp.array(dtype=wp.vec3),
    dt: float,
):
    # (x, v) <- (x, v) + dt/6 (k1 + 2 k2 + 2 k3 + k4),  acc = k1 + 2 k2 + 2 k3
    i = wp.tid()
    w = particle_inv_mass[i]
    if w == 0.0:
        return
    x[i] = x[i] + (dt / 6.0) * (acc_x[i] + v_stage[i])
    v[i] = v[i] + (dt / 6.0) * (acc_v[i] + w * f_stage[i])


@wp.kernel
def integrate_verlet(
    x: wp.array(dtype=wp.vec3),
    displacement: wp.array(dtype=wp.vec3),
    v: wp.array(dtype=wp.vec3),
    f: wp.array(dtype=wp.vec3),
    particle_inv_mass: wp.array(dtype=float),
    dt: float,
):
    # d = x - x_prev ;  d <- d + a dt^2 ;  x <- x + d ;  v = d / dt   (seed eq. 2.18 carried as an
    # increment: x_new = 2 x - x_prev + a dt^2 in exact arithmetic, without rounding a dt^2 to ulp(x))
    i = wp.tid()
    w = particle_inv_mass[i]
    if w == 0.0:
        return
    d = displacement[i] + (dt * dt * w) * f[i]
    displacement[i] = d
    x[i] = x[i] + d
    v[i] = d / dt


@wp.kernel
def verlet_prime(
    v: wp.array(dtype=wp.vec3),
    f: wp.array(dtype=wp.vec3),
    particle_inv_mass: wp.array(dtype=float),
    dt: float,
    displacement: wp.array(dtype=wp.vec3),
):
    # d = x - x_prev = dt v - dt^2/2 a   (second-order start from the current x, v)
    i = wp.tid()
    displacement[i] = dt * v[i] - (0.5 * dt * dt * particle_inv_mass[i]) * f[i]
