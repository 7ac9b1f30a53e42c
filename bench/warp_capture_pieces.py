"""Which of Warp's spatial structures a CPU graph capture records (Warp 1.19): each is built or
refitted inside a ``wp.ScopedCapture`` with a query kernel after it, its input points are moved,
the graph is replayed, and the replay's answer is compared with a plain build + query.

    python bench/warp_capture_pieces.py

Measured (Warp 1.19.0, CPU): ``wp.HashGrid.build`` and ``wp.Bvh.refit`` are recorded (the replay
equals the plain answer); ``wp.Mesh.refit`` is not (the replay queries the tree as it was at
capture time). warpcloth's self-contact broad phase uses neither: its hash is built by kernels
(kernels/self_contact.py), whose launches a rebuild that is not due skips on the device.
"""

import numpy as np
import warp as wp


@wp.kernel(enable_backward=False)
def count_grid(grid: wp.uint64, x: wp.array(dtype=wp.vec3), r: float, out: wp.array(dtype=int)):
    i = wp.tid()
    q = wp.hash_grid_query(grid, x[i], r)
    k = int(0)
    j = int(0)
    while wp.hash_grid_query_next(q, j):
        if wp.length(x[j] - x[i]) < r:
            k += 1
    out[i] = k


@wp.kernel(enable_backward=False)
def nearest_face(mesh: wp.uint64, p: wp.array(dtype=wp.vec3), out: wp.array(dtype=int)):
    i = wp.tid()
    out[i] = wp.mesh_query_point_no_sign(mesh, p[i], 10.0).face


@wp.kernel(enable_backward=False)
def count_boxes(bvh: wp.uint64, p: wp.array(dtype=wp.vec3), out: wp.array(dtype=int)):
    i = wp.tid()
    q = wp.bvh_query_aabb(bvh, p[i] - wp.vec3(0.2), p[i] + wp.vec3(0.2))
    k = int(0)
    t = int(0)
    while wp.bvh_query_next(q, t):
        k += 1
    out[i] = k


def replay_matches(build, query, move, out) -> bool:
    query()  # module load outside the capture
    with wp.ScopedCapture(device="cpu") as capture:
        build()
        query()
    move()
    wp.capture_launch(capture.graph)
    replay = out.numpy().copy()
    build()
    query()
    return bool(np.array_equal(replay, out.numpy()))


def main():
    wp.init()
    rng = np.random.default_rng(0)
    out = wp.zeros(500, dtype=int, device="cpu")
    with wp.ScopedDevice("cpu"):
        x = wp.array(rng.random((500, 3)).astype(np.float32), dtype=wp.vec3)
        grid = wp.HashGrid(16, 16, 16)
        grid.reserve(500)
        grid.build(x, 0.1)
        ok = replay_matches(
            lambda: grid.build(x, 0.1),
            lambda: wp.launch(count_grid, 500, [grid.id, x, 0.1, out]),
            lambda: x.assign(rng.random((500, 3)).astype(np.float32)),
            out,
        )
        print(f"wp.HashGrid.build recorded by a CPU capture: {ok}")
        pts = wp.array(rng.random((300, 3)).astype(np.float32), dtype=wp.vec3)
        mesh = wp.Mesh(points=pts, indices=wp.array(rng.integers(0, 300, 1200).astype(np.int32), dtype=int))
        probe = wp.array(rng.random((500, 3)).astype(np.float32), dtype=wp.vec3)
        ok = replay_matches(
            mesh.refit,
            lambda: wp.launch(nearest_face, 500, [mesh.id, probe, out]),
            lambda: pts.assign(3.0 * rng.random((300, 3)).astype(np.float32)),
            out,
        )
        print(f"wp.Mesh.refit recorded by a CPU capture: {ok}")
        lo = wp.array(rng.random((400, 3)).astype(np.float32), dtype=wp.vec3)
        hi = wp.array(lo.numpy() + 0.05, dtype=wp.vec3)
        bvh = wp.Bvh(lo, hi)

        def move_boxes():
            new = rng.random((400, 3)).astype(np.float32)
            lo.assign(new)
            hi.assign(new + 0.05)

        ok = replay_matches(bvh.refit, lambda: wp.launch(count_boxes, 500, [bvh.id, probe, out]), move_boxes, out)
        print(f"wp.Bvh.refit recorded by a CPU capture: {ok}")


if __name__ == "__main__":
    main()
