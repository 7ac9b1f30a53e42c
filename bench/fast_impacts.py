"""Fast impacts (issue 51), every integrator at its defaults (or those named), the cases of
tests/test_fast_impacts.py printed per step instead of asserted:

- ``strip``: a 4 x 16 strip (0.4 x 0.1 m, 0.02 kg) folded into two layers 2 cm apart closing at 2 x 7.5 m/s,
  no gravity, self-collision (thickness 5 mm, mu 0.3), 0.05 s: the largest kinetic energy over the start's,
  crossing triangle pairs (lab.intersections), the largest |total momentum - start| [kg m/s];
- ``sphere`` / ``sphere-sc``: a 14 x 14 hanging sheet (0.5 m, 0.05 kg, top row pinned) and a 0.15 m sphere
  (thickness 5 mm) driven through it at 5 m/s along z, 0.12 s, without / with self-collision: the deepest
  vertex inside the sphere posed at the state's time [m], vertices inside, the largest speed and strain.

    python bench/fast_impacts.py strip|sphere|sphere-sc [INTEGRATOR ...]
"""

import sys

import numpy as np

from warpcloth import Control, Simulator, Sphere, build_grid_cloth
from warpcloth.integrators import integrator_names
from warpcloth.lab import intersections as ix
from warpcloth.sim.colliders import ColliderTrack

H = 0.005


def strip(integrator: str, speed: float = 7.5, duration: float = 0.05) -> dict:
    model = build_grid_cloth(4, 16, 0.4, 0.1, 0.02, plane="horizontal", device="cpu")
    q = model.host.q.astype(np.float64).copy()
    half = 0.5 * (q[:, 0].min() + q[:, 0].max())
    up = q[:, 0] > half
    q[up, 0] = 2.0 * half - q[up, 0]
    q[up, 1] += 0.02
    v = np.zeros_like(q)
    v[~up, 1], v[up, 1] = speed, -speed
    sim = Simulator(
        model,
        integrator,
        Control(gravity=(0.0, 0.0, 0.0), device="cpu"),
        self_collision={"thickness": H, "friction": 0.3},
        use_graph=False,
    )
    sim.state.particle_q.assign(q.astype(np.float32))
    sim.state.particle_qd.assign(v.astype(np.float32))
    m = model.host.mass.astype(np.float64)
    p0, e0 = (m[:, None] * v).sum(axis=0), 0.5 * (m[:, None] * v * v).sum()
    dp = energy = crossings = 0.0
    for _ in range(max(3, round(duration / sim.dt))):
        sim.simulate(1)
        x, u = sim.state.particle_q.numpy(), sim.state.particle_qd.numpy().astype(np.float64)
        dp = max(dp, float(np.abs((m[:, None] * u).sum(axis=0) - p0).max()))
        energy = max(energy, 0.5 * float((m[:, None] * u * u).sum()) / e0)
        crossings = max(crossings, ix.count_self_intersections(x, model.host.tris))
    return {"dt": sim.dt, "energy_max/start": energy, "crossings": crossings, "momentum_drift": dp}


def sphere(integrator: str, self_collision: bool, n: int = 14, duration: float = 0.12) -> dict:
    model = build_grid_cloth(
        n, n, 0.5, 0.5, 0.05, plane="vertical", origin=(-0.25, 0.25, 0.0), pins=list(range(n)), device="cpu"
    )
    ball = Sphere(center=(0.0, 0.0, -0.2), radius=0.15, thickness=H, track=ColliderTrack.rigid(velocity=(0, 0, 5.0)))
    sim = Simulator(
        model,
        integrator,
        Control(colliders=(ball,), device="cpu"),
        self_collision={"thickness": H} if self_collision else None,
        use_graph=False,
    )
    pairs, q0 = model.host.pairs, model.host.q.astype(np.float64)
    rest = np.linalg.norm(q0[pairs[:, 0]] - q0[pairs[:, 1]], axis=1)
    depth, inside, speed, strain = 0.0, 0, 0.0, 0.0
    for _ in range(max(3, round(duration / sim.dt))):
        sim.simulate(1)
        x = sim.state.particle_q.numpy().astype(np.float64)
        phi = np.linalg.norm(x - np.array([0.0, 0.0, -0.2 + 5.0 * sim.sim_time]), axis=1) - 0.15
        depth, inside = max(depth, float(-phi.min())), max(inside, int((phi < 0).sum()))
        speed = max(speed, float(np.abs(sim.state.particle_qd.numpy()).max()))
        strain = max(strain, float((np.linalg.norm(x[pairs[:, 0]] - x[pairs[:, 1]], axis=1) / rest - 1.0).max()))
    crossings = ix.count_self_intersections(sim.state.particle_q.numpy(), model.host.tris)
    return {
        "dt": sim.dt,
        "deepest": depth,
        "inside": inside,
        "speed_max": speed,
        "strain_max": strain,
        "crossings": crossings,
    }


if __name__ == "__main__":
    case, names = sys.argv[1], sys.argv[2:] or integrator_names()
    for name in names:
        result = strip(name) if case == "strip" else sphere(name, case == "sphere-sc")
        print(name, {k: round(v, 9) if isinstance(v, float) else v for k, v in result.items()}, flush=True)
