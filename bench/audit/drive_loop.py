# ruff: noqa
# One-off audit script of issues 26, 30 and 31 (2026-12-03, branch audit); outputs in bench/results/audit-26-30-31.txt.
"""My own frame loop: every pin (top row) and a sphere moved each frame vs the same sim replayed with nothing set.
Alternating windows of 20 frames, 9 windows each; ms/frame median [min-max] and the per-window ratio."""

import statistics
import sys
import time

import numpy as np
import warp as wp

wp.config.quiet = True
from warpcloth import ColliderTrack, Control, PinTrack, Simulator, Sphere, build_grid_cloth

integ = sys.argv[1]
for n in map(int, sys.argv[2:]):
    top = list(range(n))
    model = build_grid_cloth(n, n, pins=top, device="cpu")
    rest = model.host.q.astype(np.float64)[top]
    sim = Simulator(
        model,
        integ,
        Control(
            device="cpu",
            pin_tracks=(PinTrack.driven(top),),
            colliders=(Sphere(center=(0.5, -0.5, -0.25), radius=0.2, friction=0.3, track=ColliderTrack.driven()),),
        ),
    )
    steps = max(1, round(1 / 60 / sim.dt))

    def frame(drive):
        if drive:
            t = sim.sim_time + steps * sim.dt
            sim.set_pin_targets(rest + np.array([0.05 * np.sin(4 * t), 0.02 * np.sin(3 * t), 0.1 * np.sin(2 * t)]))
            sim.set_collider_pose(0, offset=(0.1 * np.sin(t), 0.0, 0.15 * np.sin(3 * t)))
        sim.simulate(steps)
        wp.synchronize()

    for _ in range(10):
        frame(True)
        frame(False)
    res = {True: [], False: []}
    ratios = []
    for w in range(9):
        for drive in (False, True):
            t0 = time.perf_counter()
            for _ in range(20):
                frame(drive)
            res[drive].append((time.perf_counter() - t0) / 20 * 1e3)
        ratios.append(res[True][-1] / res[False][-1])
    q = lambda a: f"{statistics.median(a):.3f} [{min(a):.3f}-{max(a):.3f}]"
    assert np.isfinite(sim.state.particle_q.numpy()).all()
    print(
        f"{integ} {n}x{n} ({len(top)} pins + sphere, {steps} steps/frame, graph {sim.graph_capture if hasattr(sim, 'graph_capture') else '?'}): replay {q(res[False])} ms, driven {q(res[True])} ms, driven/replay {q(ratios)}",
        flush=True,
    )
