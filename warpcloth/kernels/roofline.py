"""The speed-of-light reference: the least memory traffic a force evaluation must make.

One pass reads every particle's x and v once, every spring's endpoints and parameters once
(springs grouped by their first particle, CSR), and writes every particle's force once: no
gathers of neighbours, no atomics. Its time is the floor a force evaluation is measured against.
"""

import warp as wp

# forward only: no adjoints (half the compile time; warpcloth differentiates nothing)
wp.set_module_options({"enable_backward": False})


@wp.kernel
def roofline_stream(
    x: wp.array(dtype=wp.vec3),
    v: wp.array(dtype=wp.vec3),
    spring_offsets: wp.array(dtype=int),
    spring_indices: wp.array(dtype=wp.vec2i),
    spring_rest_length: wp.array(dtype=float),
    spring_stiffness: wp.array(dtype=float),
    spring_damping: wp.array(dtype=float),
    f: wp.array(dtype=wp.vec3),
):
    # f_i = x_i + v_i + sum over springs s owned by i of (j_s + L0_s + ks_s + kd_s) e_x  (touch everything once)
    i = wp.tid()
    acc = float(0.0)
    for s in range(spring_offsets[i], spring_offsets[i + 1]):
        ij = spring_indices[s]
        acc += float(ij[1]) + spring_rest_length[s] + spring_stiffness[s] + spring_damping[s]
    f[i] = x[i] + v[i] + wp.vec3(acc, 0.0, 0.0)
