"""Reductions for run metrics: strain, speeds, net force, finiteness. Read once per frame."""

import warp as wp

from warpcloth.kernels.bending import hinge_energy
from warpcloth.kernels.springs import compressed_stiffness

# forward only: no adjoints (half the compile time; warpcloth differentiates nothing)
wp.set_module_options({"enable_backward": False})

# slots of the metrics buffer
MAX_STRAIN = wp.constant(0)
MAX_SPEED = wp.constant(1)
MAX_FORCE_PER_WEIGHT = wp.constant(2)
NON_FINITE = wp.constant(3)
METRIC_COUNT = 4

# slots of the float64 energy buffer
ENERGY_TOTAL = wp.constant(0)
ENERGY_KINETIC = wp.constant(1)
ENERGY_COUNT = 2


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
        wp.atomic_max(metrics, MAX_STRAIN, strain)
    else:
        wp.atomic_max(metrics, NON_FINITE, 1.0)  # deterministic mode refuses a store beside atomics


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
        wp.atomic_max(metrics, NON_FINITE, 1.0)  # deterministic mode refuses a store beside atomics
        return
    if particle_inv_mass[i] == 0.0:
        return
    wp.atomic_max(metrics, MAX_SPEED, wp.length(v[i]))
    weight = particle_mass[i] * wp.max(gravity_magnitude, 1.0e-6)
    fw = wp.length(f[i]) / weight
    if wp.isfinite(fw):
        wp.atomic_max(metrics, MAX_FORCE_PER_WEIGHT, fw)
    else:
        wp.atomic_max(metrics, NON_FINITE, 1.0)  # deterministic mode refuses a store beside atomics


@wp.kernel
def reduce_patch_force(
    f: wp.array(dtype=wp.vec3),
    offsets: wp.array(dtype=int),
    members: wp.array(dtype=int),
    patch_force: wp.array(dtype=wp.vec3),
):
    # the net force of patch k: sum of f over its members offsets[k]:offsets[k + 1], in order (no atomics)
    k = wp.tid()
    acc = wp.vec3(0.0)
    for e in range(offsets[k], offsets[k + 1]):
        acc = acc + f[members[e]]
    patch_force[k] = acc


@wp.kernel
def reduce_energy(
    x: wp.array(dtype=wp.vec3),
    v: wp.array(dtype=wp.vec3),
    particle_mass: wp.array(dtype=float),
    spring_indices: wp.array(dtype=wp.vec2i),
    spring_rest_length: wp.array(dtype=float),
    spring_stiffness: wp.array(dtype=float),
    spring_compression: wp.array(dtype=float),
    gravity: wp.vec3,
    energy: wp.array(dtype=wp.float64),
):
    # E = sum 1/2 m |v|^2 - m g.x  (particles, tid < n)  +  sum 1/2 k (L - L0)^2  (springs; k = phi ks if L < L0);
    # the kinetic part alone goes to ENERGY_KINETIC
    tid = wp.tid()
    n = x.shape[0]
    if tid < n:
        m = particle_mass[tid]
        kinetic = 0.5 * m * wp.dot(v[tid], v[tid])
        wp.atomic_add(energy, ENERGY_TOTAL, wp.float64(kinetic - m * wp.dot(gravity, x[tid])))
        wp.atomic_add(energy, ENERGY_KINETIC, wp.float64(kinetic))
    s = tid - n
    if s >= 0 and s < spring_indices.shape[0]:
        ij = spring_indices[s]
        length = wp.length(x[ij[1]] - x[ij[0]])
        stretch = length - spring_rest_length[s]
        k = compressed_stiffness(length, spring_rest_length[s], spring_stiffness[s], spring_compression[s])
        wp.atomic_add(energy, ENERGY_TOTAL, wp.float64(0.5 * k * stretch * stretch))


@wp.kernel
def reduce_hinge_energy(
    x: wp.array(dtype=wp.vec3),
    hinge_indices: wp.array(dtype=wp.vec4i),
    hinge_rest_angle: wp.array(dtype=float),
    hinge_stiffness: wp.array(dtype=float),
    energy: wp.array(dtype=wp.float64),
):
    # E += sum_e 1/2 k_e wrap(theta - theta0)^2  (dihedral hinges)
    e = wp.tid()
    q = hinge_indices[e]
    value = hinge_energy(x[q[0]], x[q[1]], x[q[2]], x[q[3]], hinge_rest_angle[e], hinge_stiffness[e])
    wp.atomic_add(energy, ENERGY_TOTAL, wp.float64(value))
