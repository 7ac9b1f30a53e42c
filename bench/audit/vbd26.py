# ruff: noqa
# One-off audit script of issues 26, 30 and 31 (2026-12-03, branch audit); outputs in bench/results/audit-26-30-31.txt.
"""My own checks of issue 26 items 1-3 (vbd at its defaults, dt = 1/60 s)."""

import math
import sys

import numpy as np
import warp as wp

wp.config.quiet = True
from warpcloth import (
    Control,
    Plane,
    Simulator,
    SpringParams,
    build_grid_cloth,
    build_mesh_cloth,
    make_integrator,
)
from warpcloth.sim.grid import grid_triangles

G = 9.81
H = 1.0 / 60.0
name = sys.argv[1] if len(sys.argv) > 1 else "vbd"


def be_ratio(n):  # backward Euler discrete fall / (g t^2/2)
    return (n + 1) / n


def fall(plane, grav, n=16):
    model = build_grid_cloth(n, n, 1.0, 1.0, 0.2, plane=plane, origin=(0, 3, 0), device="cpu")
    sim = Simulator(model, make_integrator(name), Control(gravity=grav, drag_rate=0.0, device="cpu"), dt=H)
    x0 = sim.state.particle_q.numpy().astype(np.float64)
    steps = 30
    sim.simulate(steps)
    x = sim.state.particle_q.numpy().astype(np.float64)
    g = np.asarray(grav) / G
    d = (x - x0) @ g
    t = steps * H
    return d.mean() / (0.5 * G * t * t), d.max() - d.min(), be_ratio(steps)


for n in (16, 32):
    r, spread, be = fall("vertical", (0, -G, 0), n)
    print(
        f"{name} {n}^2 along the plane (vertical cloth, g -y): fall/(g t^2/2) {r:.5f}, BE {be:.5f}, ratio {r / be:.5f}, spread {spread * 1e3:.3f} mm"
    )
    r, spread, be = fall("horizontal", (0, -G, 0), n)
    print(
        f"{name} {n}^2 across the plane (horizontal cloth, g -y): fall/(g t^2/2) {r:.5f}, BE {be:.5f}, ratio {r / be:.5f}, spread {spread * 1e3:.3f} mm"
    )

# slope: an 8x8 cloth lying on a real tilted frictionless plane (mesh model of rotated grid vertices) and the grid under tilted gravity
th = math.radians(30)
base = build_grid_cloth(8, 8, 0.3, 0.3, 0.05, plane="horizontal", origin=(0, 0, 0), device="cpu")
q = base.host.q.astype(np.float64)
c, s = math.cos(th), math.sin(th)
R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])  # rotate about z: x axis tilts up
normal = R @ np.array([0, 1, 0])
qr = (q @ R.T) + normal * 0.005 + np.array([0, 1, 0])
for mu in (0.0,):
    for kind in ("grid-tilted-gravity", "mesh-on-tilted-plane"):
        if kind == "mesh-on-tilted-plane":
            model = build_mesh_cloth(
                qr.astype(np.float32),
                grid_triangles(8, 8),
                total_mass=0.05,
                mass_mode="uniform",
                quads=True,
                device="cpu",
                spring_params=base.spring_params,
            )
            ctl = Control(
                gravity=(0, -G, 0),
                colliders=(Plane(point=(0, 1, 0), normal=tuple(normal), thickness=0.005, friction=mu),),
                device="cpu",
            )
            down = np.array([-c, -s, 0])  # down the slope
        else:
            model = build_grid_cloth(8, 8, 0.3, 0.3, 0.05, plane="horizontal", origin=(0, 0.005, 0), device="cpu")
            ctl = Control(gravity=(G * s, -G * c, 0), colliders=(Plane(thickness=0.005, friction=mu),), device="cpu")
            down = np.array([1, 0, 0])
        sim = Simulator(model, make_integrator(name), ctl, dt=H)
        steps = 30
        sim.simulate(steps)
        v = sim.state.particle_qd.numpy().astype(np.float64) @ down
        print(
            f"{name} slope 30deg mu={mu} {kind}: mean v / (n h g sin) {v.mean() / (steps * H * G * s):.5f} (min {v.min() / (steps * H * G * s):.5f}, max {v.max() / (steps * H * G * s):.5f})"
        )

# momentum: free symmetric 16x16, kd 0, no gravity, no drag, released stretched 5 %
params = {t: SpringParams(p.stiffness, 0.0) for t, p in build_grid_cloth(16, 16, device="cpu").spring_params.items()}
model = build_grid_cloth(
    16, 16, 1.0, 1.0, 0.2, spring_params=params, plane="vertical", origin=(-0.5, 1.0, 0), device="cpu"
)
sim = Simulator(model, make_integrator(name), Control(gravity=(0, 0, 0), drag_rate=0.0, device="cpu"), dt=H)
x = sim.state.particle_q.numpy().astype(np.float64)
cen = x.mean(axis=0)
sim.state.particle_q.assign(((x - cen) * 1.05 + cen).astype(np.float32))
m = model.host.mass.astype(np.float64)
worst = 0.0
for f in range(120):
    sim.simulate(1)
    v = sim.state.particle_qd.numpy().astype(np.float64)
    worst = max(worst, float(np.linalg.norm((m[:, None] * v).sum(axis=0))))
xe = sim.state.particle_q.numpy().astype(np.float64)
print(
    f"{name} momentum 16^2 free, kd 0, stretched 5%, 2 s: max |P| {worst:.3e} kg m/s; centroid moved {np.linalg.norm(xe.mean(0) - cen):.2e} m; max |v| at end {np.abs(v).max():.3f}"
)
