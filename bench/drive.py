"""Cost of driving a simulation from your own loop: ms per 1/60 s frame of xpbd on an N x N sheet
with its whole top row pinned and a sphere under it, in three ways of moving them each frame:

* ``replay``: nothing set (the captured frame replayed as it is): the floor;
* ``driven``: every pin's target and the sphere's pose set each frame (``PinTrack.driven``,
  ``ColliderTrack.driven``: copies into the arrays the captured frame reads; docs/driving.md);
* ``new track`` (``--recapture``): a new ``PinTrack`` and a moved ``Sphere`` each frame, as a
  user would without the driven tracks: every frame captures a new graph.

The variants alternate within one process, ``--repeats`` windows of ``--frames`` frames each;
the figure is the median ms per frame with its range (min-max) over the windows, and driven /
replay with its range.

    python bench/drive.py [--sizes 16 64] [--frames 30] [--repeats 7] [--device cpu] [--recapture]
"""

import argparse
import statistics
import time

import numpy as np
import warp as wp

from warpcloth import Control, Simulator, Sphere, build_grid_cloth
from warpcloth.io.provenance import machine
from warpcloth.sim.colliders import ColliderTrack
from warpcloth.sim.pins import PinTrack

FRAME = 1.0 / 60.0


def build(size, device, mode):
    top = list(range(size))  # the top row of the hanging sheet
    model = build_grid_cloth(size, size, pins=top, device=device)
    rest = model.host.q.astype(np.float64)
    ball = dict(center=(0.5, -0.6, -0.2), radius=0.15)
    if mode == "new track":
        tracks, sphere = (PinTrack.keyframes(top, [0.0], [[0.0, 0.0, 0.0]]),), Sphere(**ball)
    else:
        tracks, sphere = (PinTrack.driven(top),), Sphere(**ball, track=ColliderTrack.driven())
    sim = Simulator(model, "xpbd", Control(device=device, pin_tracks=tracks, colliders=(sphere,)))
    steps = max(1, round(FRAME / sim.dt))
    return sim, rest[top], steps


def frame(sim, pins, steps, mode, k):
    """One frame of the loop: move the pins and the sphere (or not), then simulate it."""
    t = sim.sim_time + steps * sim.dt
    swing = np.array([0.1 * np.sin(3 * t), 0.0, 0.1 * np.sin(2 * t)])
    offset = (0.0, 0.0, 0.2 * np.sin(2 * t))
    if mode == "driven":
        sim.set_pin_targets(pins + swing)
        sim.set_collider_pose(0, offset=offset)
    elif mode == "new track":
        top = list(range(len(pins)))
        sim.set_pin_track(PinTrack.keyframes(top, [sim.sim_time, t], np.stack([pins + swing * 0.99, pins + swing])))
        sim.control.colliders = (Sphere(center=np.add((0.5, -0.6, -0.2), offset), radius=0.15),)
    sim.simulate(steps)


def window(sim, pins, steps, mode, frames):
    wp.synchronize_device(sim.model.device)
    t0 = time.perf_counter()
    for k in range(frames):
        frame(sim, pins, steps, mode, k)
    wp.synchronize_device(sim.model.device)
    return 1e3 * (time.perf_counter() - t0) / frames


def spread(values):
    return f"{statistics.median(values):.3f} [{min(values):.3f}-{max(values):.3f}]"


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[16, 64])
    parser.add_argument("--frames", type=int, default=30)
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--recapture", action="store_true", help="also time a new PinTrack and Sphere per frame (slow)")
    args = parser.parse_args()
    wp.init()
    print(f"# {time.strftime('%Y-%m-%d %H:%M')} {machine()}; warp {wp.config.version}; device {args.device}")
    print(
        f"# xpbd, top row pinned, one sphere; ms per 1/60 s frame, median [min-max] of {args.repeats} windows of "
        f"{args.frames} frames"
    )
    modes = ["replay", "driven"] + (["new track"] if args.recapture else [])
    for size in args.sizes:
        sims = {m: build(size, args.device, m) for m in modes}
        for m in modes:  # warm-up: compile, capture
            window(*sims[m], m, 2)
        times = {m: [] for m in modes}
        for _ in range(args.repeats):
            for m in modes:
                frames = args.frames if m != "new track" else max(2, args.frames // 10)
                times[m].append(window(*sims[m], m, frames))
        sim, _, steps = sims["driven"]
        ratio = [d / r for d, r in zip(times["driven"], times["replay"])]
        print(f"{size}x{size} ({size} pins, {steps} steps/frame, graph {sim.graph_enabled}):")
        for m in modes:
            print(f"  {m:<10} {spread(times[m])} ms/frame")
        print(f"  driven / replay {spread(ratio)}")
        if args.recapture:
            slow = statistics.median(times["new track"]) / statistics.median(times["replay"])
            print(f"  new track / replay {slow:.0f}x")


if __name__ == "__main__":
    main()
