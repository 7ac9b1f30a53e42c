"""Cost of collision handling: ms/step of explicit_euler on an N x N cloth without colliders and
with a plane, a sphere, a capsule and a box (one fused launch per step), medians of repeats
alternated within one process, in two configurations:

* ``apart``: the hanging sheet with the colliders below it (no particle near one: the broad phase);
* ``contact``: a 1 m horizontal cloth resting on the ground plane (every particle in contact every
  step), alone (``contact plane``: a floor) and with the sphere, capsule and box just under it,
  so a third of the particles also run the exact tests of at least one of them (the narrow phase).

    python bench/colliders.py [--size 128] [--steps 200] [--repeats 7] [--device cpu] [--mesh-triangles 10000]

``--mesh-triangles T`` adds a static triangle mesh (a sphere of about T triangles) under the
horizontal cloth, alone: its cost against the same cloth with no collider.

``--kernel`` also times the contact launch alone on the resting cloth's state (restored before
each launch), for the ground alone and for all four, against a minimal kernel that does only
what any contact response must (one plane held in a vec4, Coulomb friction with a constant mu, no
loop, no record): the floor of the ground's cost on this backend; and against a minimal kernel
for the four colliders (their values in registers, an axis-aligned box, a squared-distance rejection
per round collider, the same response): the floor of the all-four case.
"""

import argparse
import statistics
import time

import numpy as np
import warp as wp

from warpcloth import Box, Capsule, Control, Plane, Simulator, Sphere, build_grid_cloth
from warpcloth.scenarios import sheet

APART = (
    Plane(point=(0, -5, 0)),
    Sphere(center=(0, -3, 0), radius=0.5),
    Capsule(a=(-1, -4, 0), b=(1, -4, 0), radius=0.2),
    Box(center=(0, -6, 0), half_extents=(0.5, 0.5, 0.5)),
)
THICKNESS = 0.002
CONTACT = (
    Plane(thickness=THICKNESS, friction=0.3),
    Sphere(center=(0.0, -0.25, 0.0), radius=0.25, thickness=THICKNESS, friction=0.3),
    Capsule(a=(-0.4, -0.1, 0.3), b=(0.4, -0.1, 0.3), radius=0.1, thickness=THICKNESS, friction=0.3),
    Box(center=(0.3, -0.2, -0.3), half_extents=(0.2, 0.2, 0.2), thickness=THICKNESS, friction=0.3),
)


def simulator(config, colliders, size, device):
    if config == "apart":
        sim = sheet.build(rows=size, cols=size, device=device)
        sim.control.colliders = colliders
        return sim
    model = build_grid_cloth(
        size, size, 1.0, 1.0, 0.2, plane="horizontal", origin=(-0.5, THICKNESS, -0.5), device=device
    )
    return Simulator(model, "explicit_euler", Control(colliders=colliders, device=device))


@wp.func
def minimal_response(xi: wp.vec3, vi: wp.vec3, phi: float, n: wp.vec3, thickness: float, mu: float, dt: float):
    # out of a collider to its thickness along n, approaching v removed, tangential v reduced by mu dv_n
    depth = thickness - phi
    if depth <= 0.0:
        return xi, vi, 0
    vn = wp.dot(vi, n)
    dvn = wp.max(0.0, -vn)
    vt = vi - vn * n
    lt2 = wp.dot(vt, vt)
    s = float(1.0)
    if mu * dvn * mu * dvn < lt2:
        s = mu * dvn / wp.sqrt(lt2)
    return xi + depth * n - (dt * s) * vt, (vn + dvn) * n + (1.0 - s) * vt, 1


@wp.kernel(enable_backward=False)
def minimal_plane(
    x: wp.array(dtype=wp.vec3),
    v: wp.array(dtype=wp.vec3),
    inv_mass: wp.array(dtype=float),
    plane: wp.vec4,
    mu: float,
    dt: float,
):
    # x onto the plane n.x >= w, approaching v removed, tangential v reduced by mu dv_n (Coulomb)
    i = wp.tid()
    xi = x[i]
    n = wp.vec3(plane[0], plane[1], plane[2])
    xi, vi, hit = minimal_response(xi, v[i], wp.dot(xi, n) - plane[3], n, 0.0, mu, dt)
    if hit != 0 and inv_mass[i] != 0.0:
        x[i] = xi
        v[i] = vi


@wp.kernel(enable_backward=False)
def minimal_four(
    x: wp.array(dtype=wp.vec3),
    v: wp.array(dtype=wp.vec3),
    inv_mass: wp.array(dtype=float),
    plane: wp.vec4,
    sphere: wp.vec4,
    capsule_a: wp.vec3,
    capsule_b: wp.vec4,
    box_center: wp.vec3,
    box_half: wp.vec3,
    bound_lo: wp.vec3,
    bound_hi: wp.vec3,
    thickness: float,
    mu: float,
    dt: float,
):
    # the four colliders of CONTACT with nothing general: values in registers, no records, no loop over
    # kinds, an axis-aligned box; the plane, then the others where x is in the box around them (as any
    # broad phase must), each exact (signed distance and normal) with the response above
    i = wp.tid()
    xi = x[i]
    vi = v[i]
    n = wp.vec3(plane[0], plane[1], plane[2])
    xi, vi, hit = minimal_response(xi, vi, wp.dot(xi, n) - plane[3], n, thickness, mu, dt)
    if xi[0] >= bound_lo[0] and xi[1] >= bound_lo[1] and xi[2] >= bound_lo[2]:
        if xi[0] <= bound_hi[0] and xi[1] <= bound_hi[1] and xi[2] <= bound_hi[2]:
            c = wp.vec3(sphere[0], sphere[1], sphere[2])
            d = xi - c
            reach = sphere[3] + thickness
            if wp.dot(d, d) < reach * reach:  # squared first: no root for the far particles
                r = wp.length(d)
                if r > 0.0:
                    xi, vi, got = minimal_response(xi, vi, r - sphere[3], d / r, thickness, mu, dt)
                    hit = hit + got
            ab = wp.vec3(capsule_b[0], capsule_b[1], capsule_b[2]) - capsule_a
            t = wp.clamp(wp.dot(xi - capsule_a, ab) / wp.dot(ab, ab), 0.0, 1.0)
            d = xi - (capsule_a + t * ab)
            reach = capsule_b[3] + thickness
            if wp.dot(d, d) < reach * reach:
                r = wp.length(d)
                if r > 0.0:
                    xi, vi, got = minimal_response(xi, vi, r - capsule_b[3], d / r, thickness, mu, dt)
                    hit = hit + got
            q = xi - box_center
            e = wp.vec3(wp.abs(q[0]) - box_half[0], wp.abs(q[1]) - box_half[1], wp.abs(q[2]) - box_half[2])
            if wp.max(wp.max(e[0], e[1]), e[2]) < thickness:
                outside = wp.vec3(wp.max(e[0], 0.0), wp.max(e[1], 0.0), wp.max(e[2], 0.0))
                lo = wp.length(outside)
                nb = wp.vec3(0.0)
                phi = float(0.0)
                if lo > 0.0:
                    phi = lo
                    nb = (
                        wp.vec3(wp.sign(q[0]) * outside[0], wp.sign(q[1]) * outside[1], wp.sign(q[2]) * outside[2]) / lo
                    )
                else:
                    k = int(0)
                    if e[1] > e[k]:
                        k = 1
                    if e[2] > e[k]:
                        k = 2
                    phi = e[k]
                    nb[k] = wp.sign(q[k])
                xi, vi, got = minimal_response(xi, vi, phi, nb, thickness, mu, dt)
                hit = hit + got
    if hit != 0 and inv_mass[i] != 0.0:
        x[i] = xi
        v[i] = vi


def kernel_alone(size, repeats, device):
    """ms of the contact launch alone on the resting cloth's state after a step's gravity, before
    its projection (x, v restored before each launch)."""

    from warpcloth.sim.contacts import ColliderSet

    sim = simulator("contact", CONTACT, size, device)
    sim.warm_up()
    sim.simulate(100)
    m, dt = sim.model, sim.dt
    g = 9.81
    xs, vs = sim.state.particle_q.numpy(), sim.state.particle_qd.numpy()
    xs[:, 1] -= g * dt * dt  # as a step leaves the resting cloth before its projection: every particle in contact
    vs[:, 1] -= g * dt
    x0, v0 = wp.array(xs, dtype=wp.vec3, device=device), wp.array(vs, dtype=wp.vec3, device=device)
    x, v = wp.clone(x0), wp.clone(v0)
    n = m.particle_count
    sets = {k: ColliderSet(c, m.device) for k, c in (("ground", CONTACT[:1]), ("all four", CONTACT))}
    cases = {
        "restore x, v only": lambda: None,
        "minimal plane kernel": lambda: wp.launch(
            minimal_plane,
            n,
            inputs=[x, v, m.particle_inv_mass, wp.vec4(0.0, 1.0, 0.0, THICKNESS), 0.3, dt],
            device=device,
        ),
    }
    sphere, capsule, box = CONTACT[1], CONTACT[2], CONTACT[3]
    bound = sets["all four"].box.numpy()  # the real kernel's box around the non-plane colliders
    cases["minimal four-collider kernel"] = lambda: wp.launch(
        minimal_four,
        n,
        inputs=[
            x,
            v,
            m.particle_inv_mass,
            wp.vec4(0.0, 1.0, 0.0, 0.0),
            wp.vec4(*sphere.center, sphere.radius),
            wp.vec3(*capsule.a),
            wp.vec4(*capsule.b, capsule.radius),
            wp.vec3(*box.center),
            wp.vec3(*box.half_extents),
            wp.vec3(*bound[0]),
            wp.vec3(*bound[1]),
            THICKNESS,
            0.3,
            dt,
        ],
        device=device,
    )
    for name, cs in sets.items():
        cases[f"collide_velocity, {name}"] = (lambda cs: lambda: cs.project_velocity(m, sim.state, dt))(cs)
    state_x, state_v = sim.state.particle_q, sim.state.particle_qd
    sim.state.particle_q, sim.state.particle_qd = x, v  # project_velocity acts on the restored copies
    times = {k: [] for k in cases}
    for _ in range(repeats):
        for name, f in cases.items():
            wp.synchronize_device(device)
            t = time.perf_counter()
            for _ in range(100):
                wp.copy(x, x0)
                wp.copy(v, v0)
                f()
            wp.synchronize_device(device)
            times[name].append(10.0 * (time.perf_counter() - t))
    sim.state.particle_q, sim.state.particle_qd = state_x, state_v
    base = statistics.median(times.pop("restore x, v only"))
    step = ms_per_step(simulator("contact", (), size, device), 200, device)
    print(
        f"# the contact launch alone (median of {repeats} x 100, restore subtracted), against a no-collider step of "
        f"{step:.3f} ms"
    )
    for name, r in times.items():
        ms = statistics.median(r) - base
        print(f"{size}x{size} {device} {name:36s} {ms:8.4f} ms  {100 * ms / step:5.1f} % of a step")


def ms_per_step(sim, steps, device):
    wp.synchronize_device(device)
    t = time.perf_counter()
    sim.simulate(steps)
    wp.synchronize_device(device)
    return 1000.0 * (time.perf_counter() - t) / steps


def mesh_sphere(triangles: int, radius: float = 0.3):
    """A UV sphere of about ``triangles`` triangles wound outward: (vertices, triangles)."""
    rings = max(2, int(round((triangles / 4) ** 0.5)))  # latitude bands; 2 rings x segments triangles
    seg = 2 * rings
    theta = np.linspace(0, np.pi, rings + 1)[1:-1]
    phi = np.linspace(0, 2 * np.pi, seg, endpoint=False)
    th, ph = np.meshgrid(theta, phi, indexing="ij")
    ring = np.stack([np.sin(th) * np.cos(ph), np.cos(th), np.sin(th) * np.sin(ph)], -1).reshape(-1, 3)
    v = radius * np.concatenate([[[0, 1, 0]], ring, [[0, -1, 0]]])
    idx = 1 + np.arange(len(ring)).reshape(rings - 1, seg)
    nxt = np.roll(idx, -1, axis=1)
    top = np.stack([np.zeros(seg, int), nxt[0], idx[0]], -1)
    bottom = np.stack([np.full(seg, len(v) - 1), idx[-1], nxt[-1]], -1)
    a, b, c, d = idx[:-1], nxt[:-1], nxt[1:], idx[1:]
    quads = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])
    return v, np.concatenate([top, quads, bottom])


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--size", type=int, default=128)
    p.add_argument("--steps", type=int, default=200)
    p.add_argument("--repeats", type=int, default=7)
    p.add_argument("--device", default="cpu")
    p.add_argument("--mesh-triangles", type=int, default=0)
    p.add_argument(
        "--kernel", action="store_true", help="also time the contact launch alone against a minimal plane kernel"
    )
    a = p.parse_args(argv)
    cases = {
        "apart none": simulator("apart", (), a.size, a.device),
        "apart plane+sphere+capsule+box": simulator("apart", APART, a.size, a.device),
        "contact none": simulator("contact", (), a.size, a.device),
        "contact plane": simulator("contact", CONTACT[:1], a.size, a.device),
        "contact plane+sphere+capsule+box": simulator("contact", CONTACT, a.size, a.device),
    }
    if a.mesh_triangles:
        from warpcloth.sim.colliders import MeshCollider

        v, t = mesh_sphere(a.mesh_triangles)
        mesh = MeshCollider(vertices=v - np.array([0.0, 0.3, 0.0]), triangles=t, thickness=THICKNESS, friction=0.3)
        cases[f"contact mesh ({len(t)} triangles)"] = simulator("contact", (mesh,), a.size, a.device)
    for sim in cases.values():
        sim.warm_up()
        sim.simulate(a.steps)  # capture
    runs = {name: [] for name in cases}
    for _ in range(a.repeats):  # alternate, so machine noise falls on every case
        for name, sim in cases.items():
            runs[name].append(ms_per_step(sim, a.steps, a.device))
    print(
        f"# ms/step: median [min-max] of {a.repeats} windows of {a.steps} steps; cost: median [min-max] over the "
        "windows of (this case / the same window's no-collider case - 1) (paired, so machine noise cancels)"
    )
    for name, r in runs.items():
        base = runs[name.split()[0] + " none"]
        ratio = [100 * (x / b - 1) for x, b in zip(r, base)]
        print(
            f"{a.size}x{a.size} {a.device} {name:36s} {statistics.median(r):8.4f} ms/step [{min(r):.4f}-{max(r):.4f}]  "
            f"{statistics.median(ratio):+6.1f} % [{min(ratio):+.1f} to {max(ratio):+.1f}]"
        )
    if a.kernel:
        kernel_alone(a.size, a.repeats, a.device)


if __name__ == "__main__":
    main()
