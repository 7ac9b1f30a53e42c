"""vbd's free fall along and across the cloth's plane: an unpinned N x N grid cloth (no drag, no
colliders) falls for 0.5 s with gravity along its plane or across it; printed is the mean
displacement over g t^2 / 2 (implicit Euler's discrete value at these dt is ~1.008).

    python bench/vbd_in_plane.py
"""

import numpy as np
import warp as wp

from warpcloth import Control, Simulator, build_grid_cloth

G = 9.81
DURATION = 0.5


def fall(integrator: str, n: int, dt: float, gravity) -> float:
    model = build_grid_cloth(n, n, 1.0, 1.0, 0.2, plane="horizontal", origin=(0.0, 1.5, 0.0), device="cpu")
    sim = Simulator(model, integrator, Control(gravity=gravity, drag_rate=0.0, device="cpu"), dt=dt)
    x0 = sim.state.particle_q.numpy().astype(np.float64).mean(axis=0)
    sim.simulate(int(round(DURATION / dt)))
    d = sim.state.particle_q.numpy().astype(np.float64).mean(axis=0) - x0
    g = np.asarray(gravity, dtype=np.float64)
    return float(np.dot(d, g) / np.dot(g, g) / (0.5 * DURATION**2))


def main():
    wp.config.quiet = True
    print(f"# mean displacement / (g t^2/2) after {DURATION} s of free fall, horizontal N x N cloth, no pins")
    for integrator in ("vbd", "implicit_euler"):
        for n in (4, 16):
            for dt in (1.0 / 60.0, 1.0 / 240.0):
                along = fall(integrator, n, dt, (-G, 0.0, 0.0))
                across = fall(integrator, n, dt, (0.0, -G, 0.0))
                print(
                    f"{integrator:15s} {n:3d}x{n:<3d} dt=1/{round(1 / dt):<4d} along the plane {along:7.4f}   across "
                    f"it {across:7.4f}"
                )


if __name__ == "__main__":
    main()
