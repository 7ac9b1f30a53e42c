"""Cost of collision handling: ms/step of explicit_euler on an N x N sheet with no collider, and
with a plane, a sphere, a capsule and a box (one launch per kind per step), medians of repeats.

    python bench/colliders.py [--size 128] [--steps 200] [--repeats 5] [--device cpu]
"""

import argparse
import statistics
import time

import warp as wp

from warpcloth import Box, Capsule, Plane, Sphere
from warpcloth.scenarios import sheet

COLLIDERS = (Plane(point=(0, -5, 0)), Sphere(center=(0, -3, 0), radius=0.5), Capsule(a=(-1, -4, 0), b=(1, -4, 0), radius=0.2),
             Box(center=(0, -6, 0), half_extents=(0.5, 0.5, 0.5)))


def ms_per_step(colliders, size, steps, device):
    sim = sheet.build(rows=size, cols=size, device=device)
    sim.control.colliders = colliders
    sim.warm_up()
    sim.simulate(steps)  # capture
    wp.synchronize_device(device)
    t = time.perf_counter()
    sim.simulate(steps)
    wp.synchronize_device(device)
    return 1000.0 * (time.perf_counter() - t) / steps


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--size", type=int, default=128)
    p.add_argument("--steps", type=int, default=200)
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--device", default="cpu")
    a = p.parse_args(argv)
    runs = {"none": [], "plane+sphere+capsule+box": []}
    for _ in range(a.repeats):  # alternate, so machine noise falls on both
        runs["none"].append(ms_per_step((), a.size, a.steps, a.device))
        runs["plane+sphere+capsule+box"].append(ms_per_step(COLLIDERS, a.size, a.steps, a.device))
    base = statistics.median(runs["none"])
    for name, r in runs.items():
        m = statistics.median(r)
        print(f"{a.size}x{a.size} {a.device} colliders={name:26s} {m:8.4f} ms/step [{min(r):.4f}-{max(r):.4f}]  {100 * (m / base - 1):+.1f} %")


if __name__ == "__main__":
    main()
