"""Kinematic pin tracks evaluated on the device at the simulated time (float64 time and weights,
one rounding to float32 at the end)."""

import warp as wp

from warpcloth.kernels.springs import SpringAdjacency

# forward only: no adjoints (half the compile time; warpcloth differentiates nothing)
wp.set_module_options({"enable_backward": False})


@wp.func
def track_keyframes(
    t: wp.float64,
    times: wp.array(dtype=wp.float64),
    values: wp.array(dtype=wp.vec3d),
    tangents: wp.array(dtype=wp.vec3d),
    cubic: int,
    p: int,
    count: int,
):
    # before the first / after the last key: hold it (velocity 0); between keys k, k+1 with
    # s = (t - t_k) / h: linear p = a + s (b - a), or cubic Hermite
    # p = h00 a + h10 h m_a + h01 b + h11 h m_b (h00 = 2s^3 - 3s^2 + 1, h10 = s^3 - 2s^2 + s,
    # h01 = -2s^3 + 3s^2, h11 = s^3 - s^2); velocity dp/dt
    last = times.shape[0] - 1
    zero = wp.vec3d(wp.float64(0.0), wp.float64(0.0), wp.float64(0.0))
    if t <= times[0]:
        return values[p], zero
    if t >= times[last]:
        return values[last * count + p], zero
    k = int(0)
    for j in range(last):
        if times[j] <= t:
            k = j
    h = times[k + 1] - times[k]
    s = (t - times[k]) / h
    a = values[k * count + p]
    b = values[(k + 1) * count + p]
    one = wp.float64(1.0)
    two = wp.float64(2.0)
    three = wp.float64(3.0)
    if cubic == 0:
        return a + s * (b - a), (b - a) / h
    ma = tangents[k * count + p] * h
    mb = tangents[(k + 1) * count + p] * h
    s2 = s * s
    s3 = s2 * s
    pos = (two * s3 - three * s2 + one) * a + (s3 - two * s2 + s) * ma + (three * s2 - two * s3) * b + (s3 - s2) * mb
    dpos = (
        (wp.float64(6.0) * s2 - wp.float64(6.0) * s) * (a - b)
        + (three * s2 - wp.float64(4.0) * s + one) * ma
        + (three * s2 - two * s) * mb
    )
    return pos, dpos / h


@wp.func
def rotate_axis_angle(axis: wp.vec3d, angle: wp.float64, r: wp.vec3d):
    # Rodrigues: R r = r cos + (a x r) sin + a (a . r)(1 - cos)
    c = wp.cos(angle)
    s = wp.sin(angle)
    return r * c + wp.cross(axis, r) * s + axis * (wp.dot(axis, r) * (wp.float64(1.0) - c))


@wp.func
def track_rigid(t: wp.float64, rest: wp.vec3d, center: wp.vec3d, axis: wp.vec3d, velocity: wp.vec3d, motion: wp.vec4d):
    # theta(t) = omega t + A sin(2 pi f t + phi), motion = (omega, A, f, phi);
    # p = c + u t + R(axis, theta)(p0 - c),  v = u + theta' axis x R(p0 - c)
    two_pi = wp.float64(6.283185307179586)
    phase = two_pi * motion[2] * t + motion[3]
    theta = motion[0] * t + motion[1] * wp.sin(phase)
    theta_dot = motion[0] + motion[1] * two_pi * motion[2] * wp.cos(phase)
    r = rotate_axis_angle(axis, theta, rest - center)
    return center + velocity * t + r, velocity + theta_dot * wp.cross(axis, r)


@wp.kernel
def apply_pin_keyframes(
    time: wp.array(dtype=wp.float64),
    offset: wp.float64,
    particle: wp.array(dtype=int),
    times: wp.array(dtype=wp.float64),
    values: wp.array(dtype=wp.vec3d),
    tangents: wp.array(dtype=wp.vec3d),
    cubic: int,
    x: wp.array(dtype=wp.vec3),
    v: wp.array(dtype=wp.vec3),
):
    # x_i = track(t + offset), v_i = track'(t + offset) for the track's particles
    p = wp.tid()
    pos, vel = track_keyframes(time[0] + offset, times, values, tangents, cubic, p, particle.shape[0])
    i = particle[p]
    x[i] = wp.vec3(pos)
    v[i] = wp.vec3(vel)


@wp.kernel
def eval_pin_keyframes_delta(
    time: wp.array(dtype=wp.float64),
    offset: wp.float64,
    particle: wp.array(dtype=int),
    times: wp.array(dtype=wp.float64),
    values: wp.array(dtype=wp.vec3d),
    tangents: wp.array(dtype=wp.vec3d),
    cubic: int,
    x: wp.array(dtype=wp.vec3),
    v: wp.array(dtype=wp.vec3),
    scale: float,
    velocity_weight: float,
    out: wp.array(dtype=wp.vec3),
):
    # out_i = scale (track(t + offset) - x_i) - velocity_weight v_i  (dp = target - x; dv = (target - x)/h - v)
    p = wp.tid()
    pos, _vel = track_keyframes(time[0] + offset, times, values, tangents, cubic, p, particle.shape[0])
    i = particle[p]
    out[i] = scale * (wp.vec3(pos - wp.vec3d(x[i]))) - velocity_weight * v[i]


@wp.kernel
def apply_pin_rigid(
    time: wp.array(dtype=wp.float64),
    offset: wp.float64,
    particle: wp.array(dtype=int),
    rest: wp.array(dtype=wp.vec3d),
    center: wp.vec3d,
    axis: wp.vec3d,
    velocity: wp.vec3d,
    motion: wp.vec4d,
    x: wp.array(dtype=wp.vec3),
    v: wp.array(dtype=wp.vec3),
):
    p = wp.tid()
    pos, vel = track_rigid(time[0] + offset, rest[p], center, axis, velocity, motion)
    i = particle[p]
    x[i] = wp.vec3(pos)
    v[i] = wp.vec3(vel)


@wp.kernel
def eval_pin_rigid_delta(
    time: wp.array(dtype=wp.float64),
    offset: wp.float64,
    particle: wp.array(dtype=int),
    rest: wp.array(dtype=wp.vec3d),
    center: wp.vec3d,
    axis: wp.vec3d,
    velocity: wp.vec3d,
    motion: wp.vec4d,
    x: wp.array(dtype=wp.vec3),
    v: wp.array(dtype=wp.vec3),
    scale: float,
    velocity_weight: float,
    out: wp.array(dtype=wp.vec3),
):
    p = wp.tid()
    pos, _vel = track_rigid(time[0] + offset, rest[p], center, axis, velocity, motion)
    i = particle[p]
    out[i] = scale * (wp.vec3(pos - wp.vec3d(x[i]))) - velocity_weight * v[i]


@wp.kernel
def eval_frame_times(
    time: wp.array(dtype=wp.float64),
    time_base: wp.array(dtype=wp.float64),
    clock: wp.array(dtype=wp.int64),
    dt: wp.float64,
    steps: int,
    frame_times: wp.array(dtype=wp.float64),
):
    # the keys of a frame driven from the host, (t0 - 1, t0, t1, t1 + 1): t0 = t now, t1 = the time
    # after `steps` steps, as advance_time will compute it (t_base + n dt)
    t0 = time[0]
    t1 = time_base[0] + wp.float64(clock[0] + wp.int64(steps)) * dt
    frame_times[0] = t0 - wp.float64(1.0)
    frame_times[1] = t0
    frame_times[2] = t1
    frame_times[3] = t1 + wp.float64(1.0)


@wp.kernel
def add_pinned_coupling(
    springs: SpringAdjacency,
    spring_B: wp.array(dtype=wp.mat33),
    particle_inv_mass: wp.array(dtype=float),
    pin_dv: wp.array(dtype=wp.vec3),
    b: wp.array(dtype=wp.vec3),
):
    # b_i += sum over pinned neighbours j of B_s dv_j  (the known dv_j of a kinematic pin moved to the right side)
    i = wp.tid()
    if particle_inv_mass[i] == 0.0:
        return
    acc = wp.vec3(0.0)
    for a in range(springs.offsets[i], springs.offsets[i + 1]):
        j = springs.other[a]
        if particle_inv_mass[j] == 0.0:
            acc = acc + spring_B[springs.spring[a]] * pin_dv[j]
    b[i] = b[i] + acc
