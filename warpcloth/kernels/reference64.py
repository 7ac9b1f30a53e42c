"""Float64 kernels of the Warp reference (``warpcloth.lab.reference_warp``): the model of
``kernels/forces.py`` in double precision, evaluated per particle by adjacency (a gather, no
atomics: the sums have a fixed order, so a run is bit-reproducible on every device), fused with
the RK4 stage update."""

import warp as wp

from warpcloth.kernels.pins import track_keyframes, track_rigid

# forward only: no adjoints (half the compile time; warpcloth differentiates nothing)
wp.set_module_options({"enable_backward": False})


@wp.struct
class Cloth64:
    # per particle: mass [kg], 1 where the particle does not move (pinned), and the CSR slices
    # of its springs (spring_offsets[i] .. spring_offsets[i+1]: spring_slot = s where i is the
    # spring's first particle, -1 - s where it is the second) and of its triangles; per spring:
    # its particles, L0 [m], ks [N/m], kd [N s/m]
    mass: wp.array(dtype=wp.float64)
    pinned: wp.array(dtype=wp.int32)
    spring_offsets: wp.array(dtype=wp.int32)
    spring_slot: wp.array(dtype=wp.int32)
    tri_offsets: wp.array(dtype=wp.int32)
    tri_slot: wp.array(dtype=wp.int32)
    springs: wp.array(dtype=wp.vec2i)
    spring_rest: wp.array(dtype=wp.float64)
    spring_ks: wp.array(dtype=wp.float64)
    spring_kd: wp.array(dtype=wp.float64)
    tris: wp.array(dtype=wp.vec3i)
    gravity: wp.vec3d
    drag_rate: wp.float64
    wind_coefficient: wp.float64


@wp.func
def spring_force64(
    xi: wp.vec3d, xj: wp.vec3d, vi: wp.vec3d, vj: wp.vec3d, rest: wp.float64, ks: wp.float64, kd: wp.float64
):
    # f_i = ks (L - L0) n + kd ((v_j - v_i) . n) n,  n = (x_j - x_i) / L; seen from j the same
    # expression gives exactly -f_i (d, n and the dot product change sign exactly)
    d = xj - xi
    length = wp.length(d)
    if length == wp.float64(0.0):
        return wp.vec3d()
    n = d / length
    return (ks * (length - rest) + kd * wp.dot(vj - vi, n)) * n


@wp.func
def wind_force64(xa: wp.vec3d, xb: wp.vec3d, xc: wp.vec3d, v_mean: wp.vec3d, wind: wp.vec3d, coefficient: wp.float64):
    # f = c_w A (n . u) n,  u = W - v_mean, on the whole triangle
    c = wp.cross(xb - xa, xc - xa)
    twice_area = wp.length(c)
    if twice_area == wp.float64(0.0):
        return wp.vec3d()
    n = c / twice_area
    return coefficient * wp.float64(0.5) * twice_area * wp.dot(n, wind - v_mean) * n


@wp.kernel
def eval_springs64(
    cloth: Cloth64, x: wp.array(dtype=wp.vec3d), v: wp.array(dtype=wp.vec3d), f_spring: wp.array(dtype=wp.vec3d)
):
    # f_spring[s] = the force on spring s's first particle (its second gets -f_spring[s])
    s = wp.tid()
    ij = cloth.springs[s]
    f_spring[s] = spring_force64(
        x[ij[0]], x[ij[1]], v[ij[0]], v[ij[1]], cloth.spring_rest[s], cloth.spring_ks[s], cloth.spring_kd[s]
    )


@wp.kernel
def eval_wind64(
    cloth: Cloth64,
    x: wp.array(dtype=wp.vec3d),
    v: wp.array(dtype=wp.vec3d),
    wind: wp.vec3d,
    f_tri: wp.array(dtype=wp.vec3d),
):
    # f_tri[t] = a third of triangle t's wind force: what each of its vertices gets
    t = wp.tid()
    abc = cloth.tris[t]
    v_mean = (v[abc[0]] + v[abc[1]] + v[abc[2]]) / wp.float64(3.0)
    f = wind_force64(x[abc[0]], x[abc[1]], x[abc[2]], v_mean, wind, cloth.wind_coefficient)
    f_tri[t] = f / wp.float64(3.0)


@wp.func
def acceleration64(
    cloth: Cloth64,
    i: int,
    v: wp.array(dtype=wp.vec3d),
    f_spring: wp.array(dtype=wp.vec3d),
    f_tri: wp.array(dtype=wp.vec3d),
):
    # a_i = (m g - m c v_i + its springs' forces + its triangles' thirds) / m, summed in a fixed
    # order (no atomics: the same bits on every device and every run)
    m = cloth.mass[i]
    f = m * (cloth.gravity - cloth.drag_rate * v[i])
    for a in range(cloth.spring_offsets[i], cloth.spring_offsets[i + 1]):
        e = cloth.spring_slot[a]
        if e >= 0:
            f = f + f_spring[e]
        else:
            f = f - f_spring[-1 - e]
    for a in range(cloth.tri_offsets[i], cloth.tri_offsets[i + 1]):
        f = f + f_tri[cloth.tri_slot[a]]
    return f / m


@wp.kernel
def integrate_rk4_stage64(
    cloth: Cloth64,
    x0: wp.array(dtype=wp.vec3d),
    v0: wp.array(dtype=wp.vec3d),
    vs: wp.array(dtype=wp.vec3d),
    f_spring: wp.array(dtype=wp.vec3d),
    f_tri: wp.array(dtype=wp.vec3d),
    h: wp.float64,
    weight: wp.float64,
    first: int,
    pin_x: wp.array(dtype=wp.vec3d),
    pin_v: wp.array(dtype=wp.vec3d),
    acc_x: wp.array(dtype=wp.vec3d),
    acc_v: wp.array(dtype=wp.vec3d),
    x_out: wp.array(dtype=wp.vec3d),
    v_out: wp.array(dtype=wp.vec3d),
):
    # k = (v_s, a(x_s, v_s)) (f_spring, f_tri evaluated at (x_s, v_s)); acc (+)= weight k;
    # (x, v)_out = (x0, v0) + h k; a pinned particle takes its position and velocity at the
    # next stage's time (pin_x, pin_v)
    i = wp.tid()
    if cloth.pinned[i] != 0:
        x_out[i] = pin_x[i]
        v_out[i] = pin_v[i]
        return
    kx = vs[i]
    kv = acceleration64(cloth, i, vs, f_spring, f_tri)
    if first != 0:
        acc_x[i] = weight * kx
        acc_v[i] = weight * kv
    else:
        acc_x[i] = acc_x[i] + weight * kx
        acc_v[i] = acc_v[i] + weight * kv
    x_out[i] = x0[i] + h * kx
    v_out[i] = v0[i] + h * kv


@wp.kernel
def integrate_rk4_final64(
    cloth: Cloth64,
    vs: wp.array(dtype=wp.vec3d),
    f_spring: wp.array(dtype=wp.vec3d),
    f_tri: wp.array(dtype=wp.vec3d),
    h: wp.float64,
    pin_x: wp.array(dtype=wp.vec3d),
    pin_v: wp.array(dtype=wp.vec3d),
    acc_x: wp.array(dtype=wp.vec3d),
    acc_v: wp.array(dtype=wp.vec3d),
    x: wp.array(dtype=wp.vec3d),
    v: wp.array(dtype=wp.vec3d),
):
    # (x, v) += h/6 (k1 + 2 k2 + 2 k3 + k4), acc = k1 + 2 k2 + 2 k3, k4 at (xs, vs); in place
    # (x and v are read only at i); a pinned particle ends the step on its pin (pin_x, pin_v)
    i = wp.tid()
    if cloth.pinned[i] != 0:
        x[i] = pin_x[i]
        v[i] = pin_v[i]
        return
    kv = acceleration64(cloth, i, vs, f_spring, f_tri)
    sixth = h / wp.float64(6.0)
    x[i] = x[i] + sixth * (acc_x[i] + vs[i])
    v[i] = v[i] + sixth * (acc_v[i] + kv)


@wp.kernel
def eval_pin_keyframes64(
    t: wp.float64,
    particle: wp.array(dtype=int),
    times: wp.array(dtype=wp.float64),
    values: wp.array(dtype=wp.vec3d),
    tangents: wp.array(dtype=wp.vec3d),
    cubic: int,
    pin_x: wp.array(dtype=wp.vec3d),
    pin_v: wp.array(dtype=wp.vec3d),
):
    # pin_x_i = track(t), pin_v_i = track'(t), float64 throughout (kernels/pins.py's track)
    p = wp.tid()
    pos, vel = track_keyframes(t, times, values, tangents, cubic, p, particle.shape[0])
    pin_x[particle[p]] = pos
    pin_v[particle[p]] = vel


@wp.kernel
def eval_pin_rigid64(
    t: wp.float64,
    particle: wp.array(dtype=int),
    rest: wp.array(dtype=wp.vec3d),
    center: wp.vec3d,
    axis: wp.vec3d,
    velocity: wp.vec3d,
    motion: wp.vec4d,
    pin_x: wp.array(dtype=wp.vec3d),
    pin_v: wp.array(dtype=wp.vec3d),
):
    p = wp.tid()
    pos, vel = track_rigid(t, rest[p], center, axis, velocity, motion)
    pin_x[particle[p]] = pos
    pin_v[particle[p]] = vel


@wp.kernel
def apply_pins64(
    pinned: wp.array(dtype=wp.int32),
    pin_x: wp.array(dtype=wp.vec3d),
    pin_v: wp.array(dtype=wp.vec3d),
    x: wp.array(dtype=wp.vec3d),
    v: wp.array(dtype=wp.vec3d),
):
    # (x, v)_i = (pin_x, pin_v)_i for every pinned particle (a run starts with its tracks at t = 0)
    i = wp.tid()
    if pinned[i] != 0:
        x[i] = pin_x[i]
        v[i] = pin_v[i]
