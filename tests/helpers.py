"""Small models with analytic answers, and a float64 NumPy reference of the force model."""

import numpy as np

from warpcloth import Control, Simulator, SpringParams, SpringType, build_grid_cloth, make_integrator
from warpcloth.sim.model import DEFAULT_STIFFNESS, build_model


def spring_params(ks: float, kd: float = 0.0) -> dict:
    return {t: SpringParams(ks, kd) for t in SpringType}


def single_spring(ks=40.0, mass=0.1, rest=0.5, stretch=0.05, kd=0.0, device="cpu"):
    """Particle 0 pinned at the origin, particle 1 hanging on one spring, stretched by ``stretch``
    along the spring. Without gravity it oscillates with period 2 pi sqrt(m / ks)."""
    q = [[0.0, 0.0, 0.0], [0.0, -rest, 0.0]]
    model = build_model(
        q, [[0, 1]], [SpringType.STRUCTURAL], [mass, mass], spring_params(ks, kd), pins=[0], device=device
    )
    return model


def displace(sim, index: int, offset) -> None:
    q = sim.state.particle_q.numpy()
    q[index] += np.asarray(offset, dtype=np.float32)
    sim.state.particle_q.assign(q)


def small_grid(ks=5.0, kd=0.0, rows=3, cols=3, pins=(0,), device="cpu"):
    """A 3 x 3 Provot grid of 0.1 kg particles, soft springs, one pin: a smooth nonlinear problem."""
    return build_grid_cloth(
        rows, cols, 1.0, 1.0, 0.1 * rows * cols, spring_params=spring_params(ks, kd), pins=list(pins), device=device
    )


def reference_forces(model, x, v, gravity=(0.0, -9.81, 0.0), drag=0.0):
    """f = m g - m c v + sum of Provot spring forces, in float64 NumPy (design.md formula)."""
    h = model.host
    p = h.pairs
    x = np.asarray(x, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64)
    rest = np.linalg.norm(h.q[p[:, 1]].astype(np.float64) - h.q[p[:, 0]], axis=1)
    ks = model.spring_stiffness.numpy().astype(np.float64)
    kd = model.spring_damping.numpy().astype(np.float64)
    m = h.mass.astype(np.float64)
    d = x[p[:, 1]] - x[p[:, 0]]
    length = np.linalg.norm(d, axis=1)
    n = d / length[:, None]
    fs = (ks * (length - rest) + kd * np.einsum("ij,ij->i", v[p[:, 1]] - v[p[:, 0]], n))[:, None] * n
    f = np.outer(m, gravity) - drag * m[:, None] * v
    np.add.at(f, p[:, 0], fs)
    np.add.at(f, p[:, 1], -fs)
    return f


def reference_rk4(model, duration, steps, gravity=(0.0, -9.81, 0.0)):
    """Positions after ``duration`` from rest, by float64 RK4 with ``steps`` steps."""
    h = model.host
    free = (h.inv_mass > 0)[:, None]
    m = h.mass.astype(np.float64)[:, None]

    def acc(x, v):
        return np.where(free, reference_forces(model, x, v, gravity) / m, 0.0)

    x = h.q.astype(np.float64).copy()
    v = np.zeros_like(x)
    dt = duration / steps
    for _ in range(steps):
        k1x, k1v = v, acc(x, v)
        k2x, k2v = v + dt / 2 * k1v, acc(x + dt / 2 * k1x, v + dt / 2 * k1v)
        k3x, k3v = v + dt / 2 * k2v, acc(x + dt / 2 * k2x, v + dt / 2 * k2v)
        k4x, k4v = v + dt * k3v, acc(x + dt * k3x, v + dt * k3v)
        x = x + dt / 6 * (k1x + 2 * k2x + 2 * k3x + k4x)
        v = v + dt / 6 * (k1v + 2 * k2v + 2 * k3v + k4v)
    return x


def simulate(model, integrator, dt, duration, control=None):
    sim = Simulator(model, integrator, control or Control(device=model.device), dt=dt)
    sim.simulate(int(round(duration / dt)))
    return sim


def backward_euler_step(model, x, v, h, gravity=(0.0, -9.81, 0.0), damping="axial"):
    """Nonlinear backward Euler of the mass-spring energy, m (dx - h v) / h^2 = f_ext + f_s(x + dx,
    dx / h), in float64 (fsolve); spring damping along the spring (``"axial"``, kd ((v_j - v_i).n) n)
    or of the whole relative velocity (``"isotropic"``, kd (v_j - v_i))."""
    from scipy.optimize import fsolve

    host = model.host
    pairs = host.pairs
    rest = np.linalg.norm(host.q[pairs[:, 1]].astype(np.float64) - host.q[pairs[:, 0]], axis=1)
    ks = model.spring_stiffness.numpy().astype(np.float64)
    kd = model.spring_damping.numpy().astype(np.float64)
    m = host.mass.astype(np.float64)
    free = host.inv_mass > 0

    def residual(flat):
        dx = np.zeros_like(x)
        dx[free] = flat.reshape(-1, 3)
        d = (x[pairs[:, 1]] - x[pairs[:, 0]]) + (dx[pairs[:, 1]] - dx[pairs[:, 0]])
        length = np.linalg.norm(d, axis=1)
        n = d / length[:, None]
        rel = (dx[pairs[:, 1]] - dx[pairs[:, 0]]) / h
        if damping == "axial":
            fs = (ks * (length - rest) + kd * np.einsum("ij,ij->i", rel, n))[:, None] * n
        else:
            fs = (ks * (length - rest))[:, None] * n + kd[:, None] * rel
        f = np.outer(m, gravity)
        np.add.at(f, pairs[:, 0], fs)
        np.add.at(f, pairs[:, 1], -fs)
        r = m[:, None] * (dx - h * v) / h**2 - f
        return r[free].ravel()

    sol = fsolve(residual, (h * v[free]).ravel(), xtol=1e-13)
    dx = np.zeros_like(x)
    dx[free] = sol.reshape(-1, 3)
    return x + dx


def free_particles(positions, mass: float = 0.1, device="cpu"):
    """Particles of ``mass`` [kg] each and no springs: a colliders' test body."""
    free = {t: SpringParams(0.0, 0.0) for t in SpringType}
    return build_model(positions, np.zeros((0, 2)), np.zeros(0), [mass] * len(positions), free, device=device)


def sphere_depth(sphere, x):
    """How far each point of ``x`` is inside ``sphere`` grown by its thickness [m] (< 0: outside)."""
    return (
        sphere.thickness
        + sphere.radius
        - np.linalg.norm(np.asarray(x, dtype=np.float64) - np.asarray(sphere.center), axis=1)
    )


def drape_sphere_depth(x):
    """How far each particle is inside the drape scenario's sphere grown by its thickness [m] (< 0: outside)."""
    from warpcloth.scenarios import drape

    return (
        drape.THICKNESS
        + drape.RADIUS
        - np.linalg.norm(np.asarray(x, dtype=np.float64) - np.array([0.0, drape.RADIUS, 0.0]), axis=1)
    )


def deepest_in_drape(sim, steps: int):
    """Step the drape ``steps`` times; the deepest any particle went into its sphere or ground at a
    step's end [m] and the last positions."""
    from warpcloth.scenarios import drape

    deepest, x = -1.0, None
    for _ in range(steps):
        sim.simulate(1)
        x = sim.state.particle_q.numpy().astype(np.float64)
        deepest = max(deepest, drape_sphere_depth(x).max(), drape.THICKNESS - x[:, 1].min())
    return deepest, x


def parse_collider(text: str):
    """The collider a command line's ``--collider TEXT`` makes (its mesh file read, as a run reads it)."""
    from warpcloth.io.meshio import load_mesh_collider
    from warpcloth.run.parse import parse_collider_spec

    return parse_collider_spec(text).collider(load_mesh_collider)


class unblocked_fifo:
    """A FIFO at ``path`` for tests of readers that must refuse it: while the block runs, a
    thread opens its writing end whenever a reader waits on it and closes it at once, so a reader
    that (wrongly) opens it sees an empty file instead of blocking the test forever."""

    def __init__(self, path):
        import os
        import threading

        self.path = str(path)
        os.mkfifo(self.path)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._unblock, daemon=True)
        self.opened = 0  # how often a reader opened it

    def _unblock(self):
        import os

        while not self._stop.wait(0.05):
            try:
                fd = os.open(self.path, os.O_WRONLY | os.O_NONBLOCK)  # ENXIO while no reader waits
            except OSError:
                continue
            self.opened += 1
            os.close(fd)

    def __enter__(self):
        self._thread.start()
        return self

    def __exit__(self, *exc):
        self._stop.set()
        self._thread.join()
        return False


#: The drape and tablecloth of before issue 28 (per-spring parameters, Provot bend springs): the
#: contact tests keep that scene (their measured times and tolerances are its own).
PER_SPRING_SCENE = {"material": "none", "bend": "provot"}


def assert_replay_matches_launches(a, b) -> None:
    """``a`` by plain launches and ``b`` by captured frame graphs, 7, 7, 3 and 7 steps (replays of a
    cached graph and a second step count): the same state to the bit (on CUDA inside
    ``conftest.reproducible``)."""
    a.use_graph, b.use_graph = False, True
    assert not a.graph_enabled and b.graph_enabled
    for n in (7, 7, 3, 7):
        a.simulate(n)
        b.simulate(n)
    assert a.steps == b.steps == 24
    assert np.array_equal(a.state.particle_q.numpy(), b.state.particle_q.numpy())
    assert np.array_equal(a.state.particle_qd.numpy(), b.state.particle_qd.numpy())
    assert np.array_equal(a.control.time.numpy(), b.control.time.numpy())


def box_edge_radius(sim) -> float:
    """R [m] of the first box collider of ``sim`` as its kernels use it (its thickness plus the rounding
    the simulator bound for its cloth: the particles keep R from the box's edges, docs/colliders.md)."""
    colliders = sim.control.colliders
    k = next(k for k, c in enumerate(colliders) if c.kind == "box")
    return float(colliders[k].thickness) + sim.control.collision.roundings()[k]


def sharp_boxes(sim) -> None:
    """Give ``sim``'s box colliders sharp edges (edge_radius 0: their particles at the thickness only)."""
    from dataclasses import replace

    sim.control.colliders = tuple(replace(c, edge_radius=0.0) if c.kind == "box" else c for c in sim.control.colliders)


#: The dt of a scheme with no stable dt on the undamped cloth (:meth:`Integrator.no_stable_dt_reason`):
#: midpoint (RK2) amplifies every undamped mode by sqrt(1 + (h omega)^4 / 4) a step, and at the damped
#: cloth's default dt (2.4e-4 s) this cloth blew up within 0.1 s; at 2e-5 s it stays bounded for 1 s.
UNDAMPED_DT = 2.0e-5


def released_stretched_cloth(name: str):
    """The contract's free momentum cloth: a symmetric 16 x 16 cloth (1 m, 0.2 kg, kd 0, no gravity, no
    drag) under integrator ``name`` at its default dt (UNDAMPED_DT where it has no stable one), stretched
    by 5 % about its centre. Returns (sim, mass column (n, 1) float64)."""
    params = {t: SpringParams(DEFAULT_STIFFNESS[t], 0.0) for t in SpringType}
    model = build_grid_cloth(16, 16, 1.0, 1.0, 0.2, spring_params=params, plane="horizontal", device="cpu")
    integrator = make_integrator(name)
    dt = UNDAMPED_DT if integrator.no_stable_dt_reason(model) else None
    sim = Simulator(model, integrator, Control(gravity=(0.0, 0.0, 0.0), drag_rate=0.0, device="cpu"), dt=dt)
    q = sim.state.particle_q.numpy()
    c = q.mean(axis=0)
    sim.state.particle_q.assign(((q - c) * 1.05 + c).astype(np.float32))
    return sim, model.host.mass.astype(np.float64)[:, None]
