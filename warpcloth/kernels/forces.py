"""Force kernels: springs (Hooke + damping, Provot), gravity, air drag, wind on triangles."""

import warp as wp

from warpcloth.kernels.springs import spring_force

# forward only: no adjoints (half the compile time; warpcloth differentiates nothing)
wp.set_module_options({"enable_backward": False})


@wp.kernel
def eval_springs(
    x: wp.array(dtype=wp.vec3),
    v: wp.array(dtype=wp.vec3),
    spring_indices: wp.array(dtype=wp.vec2i),
    spring_rest_length: wp.array(dtype=float),
    spring_stiffness: wp.array(dtype=float),
    spring_damping: wp.array(dtype=float),
    spring_compression: wp.array(dtype=float),
    f: wp.array(dtype=wp.vec3),
):
    s = wp.tid()
    ij = spring_indices[s]
    fi = spring_force(
        x[ij[0]],
        x[ij[1]],
        v[ij[0]],
        v[ij[1]],
        spring_rest_length[s],
        spring_stiffness[s],
        spring_damping[s],
        spring_compression[s],
    )
    wp.atomic_add(f, ij[0], fi)
    wp.atomic_sub(f, ij[1], fi)


@wp.kernel
def eval_particle_forces(
    v: wp.array(dtype=wp.vec3),
    particle_mass: wp.array(dtype=float),
    gravity: wp.vec3,
    drag_rate: float,
    f: wp.array(dtype=wp.vec3),
):
    # f = m g - m c v   (overwrites f: this launch also clears the accumulator)
    i = wp.tid()
    m = particle_mass[i]
    f[i] = m * (gravity - drag_rate * v[i])


@wp.func
def wind_force(xa: wp.vec3, xb: wp.vec3, xc: wp.vec3, v_mean: wp.vec3, wind: wp.vec3, coefficient: float):
    # f = c_w A (n . u) n,  u = W - v_mean   (seed eq. 2.6 with relative air velocity)
    c = wp.cross(xb - xa, xc - xa)
    twice_area = wp.length(c)
    if twice_area == 0.0:
        return wp.vec3(0.0)
    n = c / twice_area
    return coefficient * 0.5 * twice_area * wp.dot(n, wind - v_mean) * n


@wp.kernel
def eval_wind(
    x: wp.array(dtype=wp.vec3),
    v: wp.array(dtype=wp.vec3),
    tri_indices: wp.array(dtype=wp.vec3i),
    wind: wp.array(dtype=wp.vec3),
    coefficient: float,
    f: wp.array(dtype=wp.vec3),
):
    t = wp.tid()
    abc = tri_indices[t]
    v_mean = (v[abc[0]] + v[abc[1]] + v[abc[2]]) / 3.0
    ft = wind_force(x[abc[0]], x[abc[1]], x[abc[2]], v_mean, wind[0], coefficient) / 3.0
    wp.atomic_add(f, abc[0], ft)
    wp.atomic_add(f, abc[1], ft)
    wp.atomic_add(f, abc[2], ft)


@wp.kernel
def eval_wind_schedule(
    time: wp.array(dtype=wp.float64),
    schedule_start: wp.array(dtype=wp.float64),
    schedule_wind: wp.array(dtype=wp.vec3),
    period: wp.float64,
    wind: wp.array(dtype=wp.vec3),
):
    # W(t) = schedule_wind[k] for the last k with schedule_start[k] <= t (mod period if period > 0);
    # in float64, as WindSchedule.__call__ on the host: a float32 t switched a step late at exact times
    t = time[0]
    if period > wp.float64(0.0):
        t = wp.mod(t, period)
    w = wp.vec3(0.0)
    for k in range(schedule_start.shape[0]):
        if schedule_start[k] <= t:
            w = schedule_wind[k]
    wind[0] = w


@wp.kernel
def advance_time(
    time: wp.array(dtype=wp.float64),
    time_base: wp.array(dtype=wp.float64),
    clock: wp.array(dtype=wp.int64),
    dt: wp.float64,
):
    # t = t_base + n dt after n steps of dt (not a running sum: n dt lands exactly on switch times)
    n = clock[0] + wp.int64(1)
    clock[0] = n
    time[0] = time_base[0] + wp.float64(n) * dt


@wp.kernel
def rebase_time(
    time: wp.array(dtype=wp.float64), time_base: wp.array(dtype=wp.float64), clock: wp.array(dtype=wp.int64)
):
    # t_base = t, n = 0 (before stepping with a new dt)
    time_base[0] = time[0]
    clock[0] = wp.int64(0)
