"""Cost of the dihedral hinge kernels against the spring force kernel on one device.

    python bench/bending_cost.py [--device cpu] [--sizes 64 128] [--repeats 200]

Per grid size n x n (Provot springs, symmetrised grid hinges), the median over 7 windows of the
wall time per launch [ms] of kernels.forces.eval_springs, kernels.bending.eval_hinge_forces,
eval_hinge_gradients and eval_hinge_hessian_blocks, and the host build time of grid_hinges and
greedy_hinge_colors [s]. Kernels are compiled before timing; CPU launches are synchronous, CUDA
timings synchronise at the end of each window.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import warp as wp

from warpcloth.kernels import bending
from warpcloth.kernels.forces import eval_springs
from warpcloth.sim import hinges as hinge_lib
from warpcloth.sim.grid import grid_positions, grid_springs


def timed(launch, repeats: int, device) -> float:
    """Median [ms] per launch over 7 windows of ``repeats`` launches."""
    launch()
    wp.synchronize_device(device)
    windows = []
    for _ in range(7):
        t = time.perf_counter()
        for _ in range(repeats):
            launch()
        wp.synchronize_device(device)
        windows.append((time.perf_counter() - t) / repeats * 1e3)
    return float(np.median(windows))


def measure(n: int, repeats: int, device) -> dict:
    rng = np.random.default_rng(0)
    q0 = grid_positions(n, n, 1.0, 1.0, plane="horizontal").astype(np.float64)
    t = time.perf_counter()
    hinges = hinge_lib.grid_hinges(q0, n, n, 3e-5, damping_time=1e-3)
    build_s = time.perf_counter() - t
    t = time.perf_counter()
    colors = hinge_lib.greedy_hinge_colors(hinges.indices, n * n)
    color_s = time.perf_counter() - t
    pairs, _ = grid_springs(n, n)
    x_np = q0 + rng.normal(scale=1e-3, size=q0.shape)
    with wp.ScopedDevice(device):
        x = wp.array(x_np.astype(np.float32), dtype=wp.vec3)
        v = wp.array(rng.normal(scale=1e-2, size=q0.shape).astype(np.float32), dtype=wp.vec3)
        f = wp.zeros(n * n, dtype=wp.vec3)
        springs = wp.array(pairs, dtype=wp.vec2i)
        rest = wp.array(np.linalg.norm(q0[pairs[:, 1]] - q0[pairs[:, 0]], axis=1).astype(np.float32), dtype=float)
        ks = wp.full(len(pairs), 100.0, dtype=float)
        kd = wp.full(len(pairs), 0.1, dtype=float)
        ones = wp.ones(len(pairs), dtype=float)
        d = hinges.to_device(device)
        theta = wp.zeros(hinges.hinge_count, dtype=float)
        grad = wp.zeros((hinges.hinge_count, 4), dtype=wp.vec3)
        blocks = wp.zeros((hinges.hinge_count, 16), dtype=wp.mat33)
    count = hinges.hinge_count
    hinge_in = (d.hinge_indices, d.hinge_rest_angle, d.hinge_stiffness, d.hinge_damping)

    def launch(kernel, dim, *inputs):
        return lambda: wp.launch(kernel, dim, list(inputs), device=device)

    return {
        "n": n,
        "springs": len(pairs),
        "hinges": count,
        "colors": int(colors.max()) + 1,
        "grid_hinges_s": build_s,
        "greedy_hinge_colors_s": color_s,
        "eval_springs_ms": timed(
            launch(eval_springs, len(pairs), x, v, springs, rest, ks, kd, ones, f), repeats, device
        ),
        "eval_hinge_forces_ms": timed(launch(bending.eval_hinge_forces, count, x, v, *hinge_in, f), repeats, device),
        "eval_hinge_gradients_ms": timed(
            launch(bending.eval_hinge_gradients, count, x, d.hinge_indices, theta, grad), repeats, device
        ),
        "eval_hinge_hessian_blocks_ms": timed(
            launch(
                bending.eval_hinge_hessian_blocks,
                count,
                x,
                d.hinge_indices,
                d.hinge_stiffness,
                d.hinge_damping,
                1.0,
                0.0,
                blocks,
            ),
            max(repeats // 4, 1),
            device,
        ),
    }


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--sizes", type=int, nargs="+", default=[64, 128])
    parser.add_argument("--repeats", type=int, default=200)
    args = parser.parse_args(argv)
    wp.init()
    for n in args.sizes:
        r = measure(n, args.repeats, args.device)
        ratio = r["eval_hinge_forces_ms"] / r["eval_springs_ms"]
        print(
            f"{r['n']}^2: {r['springs']} springs, {r['hinges']} hinges ({r['colors']} colours); "
            f"eval_springs {r['eval_springs_ms']:.3f} ms, eval_hinge_forces {r['eval_hinge_forces_ms']:.3f} ms "
            f"({ratio:.2f}x), eval_hinge_gradients {r['eval_hinge_gradients_ms']:.3f} ms, "
            f"eval_hinge_hessian_blocks {r['eval_hinge_hessian_blocks_ms']:.3f} ms; "
            f"host: grid_hinges {r['grid_hinges_s']:.3f} s, greedy_hinge_colors {r['greedy_hinge_colors_s']:.3f} s"
        )


if __name__ == "__main__":
    main()
