"""Reductions for run metrics: strain, speeds, net force, finiteness. Read once per frame."""

import warp as wp

# forward only: no adjoints (half the compile time; warpcloth differentiates nothing)
wp.set_module_options({"enable_backward": False})

# slots of the metrics buffer
MAX_STRAIN = 0
MAX_SPEED = 1
MAX_FORCE_PER_WEIGHT = 2
NON_FINITE = 3
METRIC_COUNT = 4


@wp.kernel
def clear_metrics(metrics: wp.array(dtype=float)):
    metrics[wp.tid()] = 0.0


@wp.kernel
def reduce_spring_strain(
    x: wp.array(dtype=wp.vec3),
    spring_indices: wp.array(dtype=wp.vec2i),
    spring_rest_length: wp.array(dtype=float),
    metrics: wp.array(dtype=float),
):
    # strain = (L - L0) / L0, max over springs (a non-finite length raises the non-finite flag)
    s = wp.tid()
    ij = spring_indices[s]
    length = wp.length(x[ij[1]] - x[ij[0]])
    strain = (length - spring_rest_length[s]) / spring_rest_length[s]
    if wp.isfinite(strain):
        wp.atomic_max(metrics, 0, strain)
    else:
        metrics[3] = 1.0


@wp.kernel
def reduce_particle_motion(
    x: wp.array(dtype=wp.vec3),
    v: wp.array(dtype=wp.vec3),
    f: wp.array(dtype=wp.vec3),
    particle_mass: wp.array(dtype=float),
    particle_inv_mass: wp.array(dtype=float),
    gravity_magnitude: float,
    metrics: wp.array(dtype=float),
):
    # max |v| and max |f| / (m |g|) over free particles
    i = wp.tid()
    if not (wp.isfinite(x[i]) and wp.isfinite(v[i])):
        metrics[3] = 1.0
        return
    if particle_inv_mass[i] == 0.0:
        return
    wp.atomic_max(metrics, 1, wp.length(v[i]))
    weight = particle_mass[i] * wp.max(gravity_magnitude, 1.0e-6)
    fw = wp.length(f[i]) / weight
    if wp.isfinite(fw):
        wp.atomic_max(metrics, 2, fw)
    else:
        metrics[3] = 1.0


@wp.kernel
def reduce_energy(
    x: wp.array(dtype=wp.vec3),
    v: wp.array(dtype=wp.vec3),
    particle_mass: wp.array(dtype=float),
    spring_indices: wp.array(dtype=wp.vec2i),
    spring_rest_length: wp.array(dtype=float),
    spring_stiffness: wp.array(dtype=float),
    gravity: wp.vec3,
    energy: wp.array(dtype=wp.float64),
):
    # E = sum 1/2 m |v|^2 - m g.x  (particles, tid < n)  +  sum 1/2 ks (L - L0)^2  (springs)
    tid = wp.tid()
    n = x.shape[0]
    if tid < n:
        m = particle_mass[tid]
        e = 0.5 * m * wp.dot(v[tid], v[tid]) - m * wp.dot(gravity, x[tid])
        wp.atomic_add(energy, 0, wp.float64(e))
    s = tid - n
    if s >= 0 and s < spring_indices.shape[0]:
        ij = spring_indices[s]
        stretch = wp.length(x[ij[1]] - x[ij[0]]) - spring_rest_length[s]
        wp.atomic_add(energy, 0, wp.float64(0.5 * spring_stiffness[s] * stretch * stretch))
