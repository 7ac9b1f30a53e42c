"""Dihedral bending: warpcloth.sim.hinges (topology, rest values, stiffness, colouring) and
warpcloth.kernels.bending (angle, gradient, forces, Gauss-Newton Hessian, VBD term, XPBD/PBD
projections), against float64 NumPy, finite differences and closed forms (material-design.md 2)."""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp

from warpcloth.kernels import bending as K
from warpcloth.kernels.forces import eval_particle_forces, eval_springs
from warpcloth.kernels.integrate import integrate_explicit_euler
from warpcloth.sim import hinges as H
from warpcloth.sim.grid import build_grid_cloth, grid_springs, grid_triangles
from warpcloth.sim.model import SpringParams, SpringType

DEVICE = "cpu"


# -- helpers ---------------------------------------------------------------------------------------
def vec3(a):
    return wp.array(np.asarray(a, dtype=np.float32).reshape(-1, 3), dtype=wp.vec3, device=DEVICE)


def launch(kernel, dim, *inputs):
    wp.launch(kernel, dim, list(inputs), device=DEVICE)


def hinge_inputs(d):
    """The four hinge arrays in the kernels' order (indices, rest angle, stiffness, damping)."""
    return d.hinge_indices, d.hinge_rest_angle, d.hinge_stiffness, d.hinge_damping


def one_hinge(x, rest=0.0, k=1.0, kd=0.0) -> H.Hinges:
    """A Hinges of the single hinge (0, 1, 2, 3) with given rest angle, k and kd (rest geometry from x)."""
    h = H.build_hinges(x, [[0, 1, 2, 3]], 1.0)
    return H.Hinges(
        h.indices,
        np.array([rest], float),
        h.rest_length,
        h.rest_area,
        h.weight,
        h.rigidity,
        np.array([k], float),
        np.array([kd], float),
    )


def kernel_forces(x, hinges: H.Hinges, v=None) -> np.ndarray:
    d = hinges.to_device(DEVICE)
    n = len(x)
    f = wp.zeros(n, dtype=wp.vec3, device=DEVICE)
    vv = vec3(np.zeros((n, 3)) if v is None else v)
    wp.launch(K.eval_hinge_forces, hinges.hinge_count, [vec3(x), vv, *hinge_inputs(d), f], device=DEVICE)
    return f.numpy().astype(np.float64)


def kernel_energies(x, hinges: H.Hinges) -> np.ndarray:
    d = hinges.to_device(DEVICE)
    out = wp.zeros(hinges.hinge_count, dtype=float, device=DEVICE)
    launch(K.eval_hinge_energies, hinges.hinge_count, vec3(x), *hinge_inputs(d)[:3], out)
    return out.numpy().astype(np.float64)


def kernel_blocks(x, hinges: H.Hinges, alpha=1.0, beta=0.0) -> np.ndarray:
    """(H, 4, 4, 3, 3) Gauss-Newton blocks from the kernel."""
    d = hinges.to_device(DEVICE)
    blocks = wp.zeros((hinges.hinge_count, 16), dtype=wp.mat33, device=DEVICE)
    wp.launch(
        K.eval_hinge_hessian_blocks,
        hinges.hinge_count,
        [vec3(x), d.hinge_indices, d.hinge_stiffness, d.hinge_damping, alpha, beta, blocks],
        device=DEVICE,
    )
    return blocks.numpy().astype(np.float64).reshape(-1, 4, 4, 3, 3)


def dense(blocks: np.ndarray) -> np.ndarray:
    """One hinge's (4, 4, 3, 3) blocks as a 12 x 12 matrix."""
    return blocks.transpose(0, 2, 1, 3).reshape(12, 12)


def energy64(x, hinges: H.Hinges) -> float:
    return float(H.hinge_energies(x, hinges).sum())


def random_hinge(rng, spread=0.25):
    """A non-degenerate hinge: edge ~ unit length, heights >= 0.4, angle away from +-pi, randomly placed."""
    while True:
        x = np.array([[0.0, 0, 0], [1.0, 0, 0], [0.3, 1.0, 0], [0.6, -1.0, 0]]) + rng.uniform(-spread, spread, (4, 3))
        _, area = H.hinge_geometry(x, [[0, 1, 2, 3]])
        theta = H.hinge_angles(x, [[0, 1, 2, 3]])[0]
        # fold x3 about the edge by a random angle
        phi = rng.uniform(-2.5, 2.5)
        c, s = np.cos(phi), np.sin(phi)
        e = (x[1] - x[0]) / np.linalg.norm(x[1] - x[0])
        r = x[3] - x[0]
        x[3] = x[0] + r * c + np.cross(e, r) * s + e * np.dot(e, r) * (1 - c)
        theta = H.hinge_angles(x, [[0, 1, 2, 3]])[0]
        if area.min() > 0.2 and abs(theta) < 2.8:
            q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
            return x @ q.T + rng.normal(size=3)


def central_difference(fun, x, eps):
    x = np.asarray(x, dtype=np.float64)
    out = np.zeros(x.shape + np.shape(fun(x)))
    for idx in np.ndindex(x.shape):
        xp, xm = x.copy(), x.copy()
        xp[idx] += eps
        xm[idx] -= eps
        out[idx] = (np.asarray(fun(xp)) - np.asarray(fun(xm))) / (2 * eps)
    return out


def fold(phi: float) -> np.ndarray:
    """Hinge (0, 1, 2, 3) with angle phi exactly: flat at phi = 0, x3 turned about the edge (x axis)."""
    x3 = np.array([0.6, -1.0, 0.0])
    c, s = np.cos(phi), np.sin(phi)
    x3 = np.array([x3[0], c * x3[1] - s * x3[2], s * x3[1] + c * x3[2]])
    x = np.array([[0.0, 0, 0], [1.0, 0, 0], [0.3, 1.0, 0], x3])
    if H.hinge_angles(x, [[0, 1, 2, 3]])[0] * phi < 0:  # turn the other way for the hinge's sign convention
        x[3, 2] = -x[3, 2]
    return x


def cylinder(points2d, radius, phi):
    """Wrap flat material points (X, Y) isometrically on a cylinder whose curvature runs along
    direction phi in the (X, Y) plane (the axis is perpendicular to it)."""
    d = np.array([np.cos(phi), np.sin(phi)])
    dn = np.array([-np.sin(phi), np.cos(phi)])
    p = points2d - points2d.mean(axis=0)
    s, t = p @ d, p @ dn
    out = np.zeros((len(p), 3))
    out[:, :2] = np.outer(t, dn) + np.outer(radius * np.sin(s / radius), d)
    out[:, 2] = radius * (1.0 - np.cos(s / radius))
    return out


def grid_points(rows, cols, h):
    r, c = np.meshgrid(np.arange(rows), np.arange(cols), indexing="ij")
    return np.stack([c.ravel() * h, r.ravel() * h], axis=1)


# -- angle and gradient ----------------------------------------------------------------------------
def test_gradient_matches_central_differences():
    rng = np.random.default_rng(7)
    for _ in range(12):
        x = random_hinge(rng)
        hinge = one_hinge(x, rest=rng.uniform(-1.0, 1.0), k=rng.uniform(0.5, 3.0))
        fd = central_difference(lambda y: energy64(y, hinge), x, 1e-6)
        f = kernel_forces(x, hinge)
        assert np.abs(f + fd).max() < 2e-5 * np.abs(fd).max()
        # the float64 mirror, against the FD of the angle
        _, g, valid = H.hinge_angle_gradients(x, hinge.indices)
        fd_theta = central_difference(lambda y: H.hinge_angles(y, hinge.indices)[0], x, 1e-6)
        assert valid[0] and np.abs(g[0] - fd_theta).max() < 1e-8 * np.abs(fd_theta).max()


def test_gauss_newton_hessian_is_exact_at_the_rest_angle_and_psd_elsewhere():
    rng = np.random.default_rng(3)

    def gradient64(y, hinge):  # dE/dx = k wrap(theta - theta0) g, float64
        theta, g, _ = H.hinge_angle_gradients(y, hinge.indices)
        return hinge.stiffness[0] * H.wrap_angle(theta[0] - hinge.rest_angle[0]) * g[0]

    for _ in range(6):
        x = random_hinge(rng)
        theta = H.hinge_angles(x, [[0, 1, 2, 3]])[0]
        at_rest = one_hinge(x, rest=theta, k=1.3)
        exact = central_difference(lambda y: gradient64(y, at_rest), x, 1e-6).reshape(12, 12).T
        gn = dense(kernel_blocks(x, at_rest)[0])
        assert np.abs(gn - exact).max() < 1e-4 * np.abs(exact).max()
        assert np.abs(gn - gn.T).max() < 1e-6 * np.abs(gn).max()
        # away from the rest angle the Hessian drops k (theta - theta0) d2theta, but stays PSD
        bent = one_hinge(x, rest=theta - 0.8, k=1.3)
        gn_bent = dense(kernel_blocks(x, bent)[0])
        exact_bent = central_difference(lambda y: gradient64(y, bent), x, 1e-6).reshape(12, 12).T
        assert np.abs(gn_bent - exact_bent).max() > 0.05 * np.abs(exact_bent).max()
        assert np.linalg.eigvalsh(0.5 * (gn_bent + gn_bent.T)).min() > -1e-6 * np.abs(gn_bent).max()
        # alpha k + beta kd scaling (implicit Euler's h^2 K + h D)
        damped = one_hinge(x, rest=theta, k=1.3, kd=0.2)
        scaled = dense(kernel_blocks(x, damped, alpha=0.01, beta=0.1)[0])
        assert np.allclose(scaled, (0.01 * 1.3 + 0.1 * 0.2) / 1.3 * gn, rtol=1e-5, atol=1e-7 * np.abs(gn).max())


def test_rigid_motion_keeps_energy_and_rotates_forces_with_no_net_force_or_torque():
    rng = np.random.default_rng(11)
    for _ in range(8):
        x = random_hinge(rng)
        hinge = one_hinge(x, rest=rng.uniform(-1.0, 1.0), k=2.0)
        q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        q *= np.sign(np.linalg.det(q))  # a rotation
        y = x @ q.T + rng.normal(size=3) * 3.0
        e_x, e_y = energy64(x, hinge), energy64(y, hinge)
        assert abs(e_y - e_x) < 1e-10 * e_x  # float64
        # float32 kernel: positions ~3 m carry ulp 2.4e-7 m, so bound the change as an angle error
        c = H.wrap_angle(H.hinge_angles(x, hinge.indices)[0] - hinge.rest_angle[0])
        assert abs(kernel_energies(y, hinge)[0] - kernel_energies(x, hinge)[0]) < 2.0 * abs(c) * 2e-6
        fx, fy = kernel_forces(x, hinge), kernel_forces(y, hinge)
        scale = np.abs(fx).max()
        assert np.abs(fy - fx @ q.T).max() < 2e-5 * scale
        for pos, f in ((x, fx), (y, fy)):
            assert np.abs(f.sum(axis=0)).max() < 1e-5 * scale
            torque = np.cross(pos - pos.mean(axis=0), f).sum(axis=0)
            assert np.abs(torque).max() < 1e-5 * scale * np.abs(pos - pos.mean(axis=0)).max()


def test_angle_is_exact_and_signed_near_the_fold():
    idx = [[0, 1, 2, 3]]
    for phi in (np.pi - 1e-2, np.pi - 1e-4, -(np.pi - 1e-3), 1e-5, -1e-5, 0.5):
        x = fold(phi)
        assert abs(H.hinge_angles(x, idx)[0] - phi) < 1e-12
        out = wp.zeros(1, dtype=float, device=DEVICE)
        grad = wp.zeros((1, 4), dtype=wp.vec3, device=DEVICE)
        indices = wp.array(np.array(idx, np.int32), dtype=wp.vec4i, device=DEVICE)
        launch(K.eval_hinge_gradients, 1, vec3(x), indices, out, grad)
        assert abs(out.numpy()[0] - phi) < 2e-6
        assert np.all(np.isfinite(grad.numpy()))
    # crossing pi: rest at pi - 0.01, now at -pi + 0.01: the wrapped difference is 0.02, not 2 pi - 0.02
    x = fold(-(np.pi - 0.01))
    hinge = one_hinge(x, rest=np.pi - 0.01, k=1.0)
    assert abs(kernel_energies(x, hinge)[0] - 0.5 * 0.02**2) < 1e-6
    fd = central_difference(lambda y: energy64(y, hinge), x, 1e-7)
    f = kernel_forces(x, hinge)
    assert np.abs(f + fd).max() < 1e-3 * np.abs(fd).max()


# -- rest states, degenerate hinges ---------------------------------------------------------------
def test_rest_state_has_zero_force():
    rng = np.random.default_rng(5)
    rows = cols = 9
    flat = np.zeros((rows * cols, 3))
    flat[:, :2] = grid_points(rows, cols, 0.1) + rng.uniform(-0.02, 0.02, (rows * cols, 2))  # jittered, still flat
    hinges = H.grid_hinges(flat, rows, cols, 1e-3, damping_time=0.01)
    assert np.all(hinges.rest_angle == 0.0)
    assert np.all(kernel_forces(flat, hinges) == 0.0)
    # a curved rest state (theta0 != 0) is at rest too; bend it further and the force is not small
    curved = cylinder(grid_points(rows, cols, 0.1), 0.3, 0.4)
    hinges = H.grid_hinges(curved, rows, cols, 1e-3)
    assert np.abs(hinges.rest_angle).max() > 0.1
    moved = kernel_forces(cylinder(grid_points(rows, cols, 0.1), 0.25, 0.4), hinges)
    assert np.abs(kernel_forces(curved, hinges)).max() < 1e-4 * np.abs(moved).max()


@pytest.mark.parametrize("case", ["x2_on_edge", "x3_on_edge", "zero_edge", "all_coincident", "x2_is_x0"])
def test_degenerate_hinges_give_zero_finite_terms(case):
    x = np.array([[0.0, 0, 0], [1.0, 0, 0], [0.3, 1.0, 0.2], [0.6, -1.0, 0.3]])
    if case == "x2_on_edge":
        x[2] = [0.4, 0.0, 0.0]
    elif case == "x3_on_edge":
        x[3] = [1.7, 0.0, 0.0]
    elif case == "zero_edge":
        x[1] = x[0]
    elif case == "all_coincident":
        x[:] = 0.25
    elif case == "x2_is_x0":
        x[2] = x[0]
    hinge = one_hinge(np.array([[0.0, 0, 0], [1.0, 0, 0], [0.3, 1.0, 0], [0.6, -1.0, 0]]), rest=0.3, k=1.0, kd=0.5)
    v = np.ones((4, 3))
    f = kernel_forces(x, hinge, v)
    assert np.all(np.isfinite(f)) and np.all(f == 0.0)
    assert np.all(kernel_blocks(x, hinge, 1.0, 1.0) == 0.0)
    assert kernel_energies(x, hinge)[0] == 0.0
    theta, g, valid = H.hinge_angle_gradients(x, hinge.indices)
    assert not valid[0] and theta[0] == 0.0 and np.all(g == 0.0)
    dp = solve_one(x, hinge, np.ones(4), h=0.01, xpbd=True)[0]
    assert np.all(dp == 0.0)
    dp = solve_one(x, hinge, np.ones(4), h=0.01, xpbd=False)[0]
    assert np.all(dp == 0.0)


def test_nearly_degenerate_triangle_stays_finite():
    # triangle A with height 1e-6 |e| (area above the guard): the height floor bounds the gradient
    x = np.array([[0.0, 0, 0], [1.0, 0, 0], [0.5, 1e-6, 1e-7], [0.6, -1.0, 0.3]])
    hinge = one_hinge(np.array([[0.0, 0, 0], [1.0, 0, 0], [0.3, 1.0, 0], [0.6, -1.0, 0]]), rest=0.0, k=1.0)
    f = kernel_forces(x, hinge)
    assert np.all(np.isfinite(f))
    assert np.abs(f).max() < 4.0 / H.HEIGHT_FLOOR  # |g2| <= 1 / (1e-3 |e|), |theta| <= pi


# -- damping ---------------------------------------------------------------------------------------
def test_damping_force_is_along_the_hinge_mode_and_dissipates():
    rng = np.random.default_rng(2)
    x = random_hinge(rng)
    theta = H.hinge_angles(x, [[0, 1, 2, 3]])[0]
    hinge = one_hinge(x, rest=theta, k=1.0, kd=0.7)
    v = rng.normal(size=(4, 3))
    _, g, _ = H.hinge_angle_gradients(x, hinge.indices)
    expected = -0.7 * np.sum(g[0] * v) * g[0]
    f = kernel_forces(x, hinge, v)
    assert np.abs(f - expected).max() < 1e-5 * np.abs(expected).max()
    assert np.sum(f * v) < 0.0


# -- stiffness calibration: the cylinder ---------------------------------------------------------
@pytest.mark.parametrize("phi_deg", [0.0, 90.0, 45.0, 22.5, 135.0])
def test_grid_on_a_cylinder_stores_b_kappa_squared_over_two(phi_deg):
    rows = cols = 32
    hh = 1.0 / (cols - 1)
    flat2d = grid_points(rows, cols, hh)
    flat = np.c_[flat2d, np.zeros(len(flat2d))]
    radius = 0.5
    phi = np.radians(phi_deg)
    wrapped = cylinder(flat2d, radius, phi)
    area = (rows - 1) * (cols - 1) * hh * hh
    area_x = (rows - 2) * (cols - 1) * hh * hh  # cells that x-edge hinges span (no hinge on a boundary row)
    area_y = (rows - 1) * (cols - 2) * hh * hh
    # isotropic
    b = 2.5e-5
    hinges = H.grid_hinges(flat, rows, cols, b)
    energy = kernel_energies(wrapped, hinges).sum()
    target = 0.5 * b / radius**2
    supported = area_x * np.sin(phi) ** 2 + area_y * np.cos(phi) ** 2
    assert abs(energy / (target * supported) - 1.0) < 0.005
    assert abs(energy / (target * area) - (cols - 2) / (cols - 1)) < 0.005  # 0.968: the free boundary's half cell
    assert abs(energy64(wrapped, hinges) / energy - 1.0) < 1e-4
    # warp/weft: B(phi) = B_warp cos^2 + B_weft sin^2, y-edges carry warp
    bw, bf = 4e-5, 1e-5
    hinges = H.grid_hinges(flat, rows, cols, bw, bf)
    energy = kernel_energies(wrapped, hinges).sum()
    expected = 0.5 / radius**2 * (bw * np.cos(phi) ** 2 * area_y + bf * np.sin(phi) ** 2 * area_x)
    assert abs(energy / expected - 1.0) < 0.005
    # warp at 90 degrees to the grid swaps them
    hinges = H.grid_hinges(flat, rows, cols, bf, bw, warp_angle=np.pi / 2)
    assert abs(kernel_energies(wrapped, hinges).sum() / expected - 1.0) < 0.005


def test_single_diagonal_mesh_hinges_are_stiff_across_the_diagonal():
    # the reason for the symmetrised grid: the mesh's own hinges (one diagonal) are exact along the
    # axes and ~3x too stiff at 45 degrees (material-design.md 2.1)
    rows = cols = 32
    hh = 1.0 / (cols - 1)
    flat2d = grid_points(rows, cols, hh)
    flat = np.c_[flat2d, np.zeros(len(flat2d))]
    mesh = H.mesh_hinges(flat, grid_triangles(rows, cols), 2.5e-5)
    ratios = []
    for phi_deg in (0.0, 45.0, 135.0):
        wrapped = cylinder(flat2d, 0.5, np.radians(phi_deg))
        ratios.append(kernel_energies(wrapped, mesh).sum() / (0.5 * 2.5e-5 / 0.25 * (rows - 1) * (cols - 1) * hh * hh))
    along, diagonals = ratios[0], sorted(ratios[1:])
    assert 0.95 < along < 1.0 and 0.99 < diagonals[0] < 1.01 and diagonals[1] > 2.5, ratios


# -- topology, colouring, adjacency ---------------------------------------------------------------
def canonical(indices):
    q = np.asarray(indices)
    swap = q[:, 0] > q[:, 1]  # (x0, x1, x2, x3) and (x1, x0, x3, x2) are the same hinge
    q = np.where(swap[:, None], q[:, [1, 0, 3, 2]], q)
    return {tuple(r) for r in q}


def test_hinge_topology_of_grid_and_mesh():
    rows, cols = 5, 7
    q, axis = H.grid_hinge_indices(rows, cols)
    assert len(q) == 2 * ((rows - 2) * (cols - 1) + (rows - 1) * (cols - 2))
    assert np.count_nonzero(axis == 0) == 2 * (rows - 2) * (cols - 1)
    mesh = H.triangle_hinges(grid_triangles(rows, cols))
    # interior edges of the triangulation: structural interior edges plus every diagonal
    assert len(mesh) == (rows - 2) * (cols - 1) + (rows - 1) * (cols - 2) + (rows - 1) * (cols - 1)
    assert len(canonical(mesh)) == len(mesh)
    # the first diagonal family of the grid hinges is the mesh's own hinges on the structural edges
    half = (rows - 2) * (cols - 1)
    first = np.concatenate([q[:half], q[2 * half : 2 * half + (rows - 1) * (cols - 2)]])
    assert canonical(first) <= canonical(mesh)
    # orientation: a flat grid's hinges all have angle 0 (not pi), triangle A = (x0, x1, x2) in mesh order
    flat = np.c_[grid_points(rows, cols, 0.1), np.zeros(rows * cols)]
    assert np.all(H.hinge_angles(flat, mesh) == 0.0) and np.all(H.hinge_angles(flat, q) == 0.0)
    tris = {tuple(np.roll(t, -k)) for t in grid_triangles(rows, cols) for k in range(3)}
    assert all((a, b, c) in tris and (b, a, d) in tris for a, b, c, d in mesh)
    with pytest.raises(Exception, match="more than two triangles"):
        H.triangle_hinges([[0, 1, 2], [1, 0, 3], [0, 1, 4]])


def test_greedy_hinge_colouring_is_valid():
    rows, cols = 20, 24
    q, _ = H.grid_hinge_indices(rows, cols)
    colors = H.greedy_hinge_colors(q, rows * cols)
    assert H.is_valid_hinge_coloring(q, colors, rows * cols)
    for k in range(colors.max() + 1):  # the definition, directly
        members = q[colors == k].ravel()
        assert np.unique(members).size == members.size
    assert colors.max() + 1 <= 30  # a vertex touches at most 16 hinges; greedy stays near that
    bad = colors.copy()
    bad[1] = bad[0]  # hinges 0 and 1 share the edge's vertices
    assert not H.is_valid_hinge_coloring(q, bad, rows * cols)
    coloring = H.color_hinges(q, rows * cols)
    assert sum(coloring.counts) == len(q)


def test_mesh_hinges_anisotropy_follows_the_uv_warp_axis():
    rows, cols = 4, 5
    pts = grid_points(rows, cols, 0.1)
    flat = np.c_[pts[:, 0], np.zeros(len(pts)), pts[:, 1]]  # horizontal x-z plane
    uv = np.c_[pts[:, 1], pts[:, 0]]  # u along the grid's Y: warp runs along the rows' direction
    mesh = H.mesh_hinges(flat, grid_triangles(rows, cols), 3.0, 1.0, uv=uv)
    x0, x1 = flat[mesh.indices[:, 0]], flat[mesh.indices[:, 1]]
    along_x = np.abs(x1 - x0)[:, 2] < 1e-12  # edges along X: m along Y = warp
    along_z = np.abs(x1 - x0)[:, 0] < 1e-12
    assert np.allclose(mesh.rigidity[along_x], 3.0) and np.allclose(mesh.rigidity[along_z], 1.0)
    assert np.allclose(mesh.rigidity[~along_x & ~along_z], 2.0)  # diagonals: m at 45 degrees
    no_uv = H.mesh_hinges(flat, grid_triangles(rows, cols), 3.0, 1.0)  # warp = global x
    assert np.allclose(no_uv.rigidity[along_x], 1.0) and np.allclose(no_uv.rigidity[along_z], 3.0)


# -- VBD per-vertex term, implicit assembly, matrix-free product -----------------------------------
def grid_case(rows=5, cols=6, seed=0):
    rng = np.random.default_rng(seed)
    flat = np.c_[grid_points(rows, cols, 0.1), np.zeros(rows * cols)]
    hinges = H.grid_hinges(flat, rows, cols, 2e-3, 1e-3, damping_time=0.02)
    x = flat + rng.normal(scale=0.02, size=flat.shape)
    return rows * cols, hinges, x, rng


def test_vbd_vertex_term_equals_forces_and_diagonal_blocks():
    n, hinges, x, rng = grid_case()
    d = hinges.to_device(DEVICE)
    offsets, hinge, slot = H.hinge_adjacency(hinges.indices, n)
    adj = [wp.array(a, dtype=int, device=DEVICE) for a in (offsets, hinge, slot)]
    h = 0.01
    dx = rng.normal(scale=0.003, size=x.shape)
    force = wp.zeros(n, dtype=wp.vec3, device=DEVICE)
    hess = wp.zeros(n, dtype=wp.mat33, device=DEVICE)
    launch(K.eval_hinge_vertex_terms, n, vec3(x), vec3(dx), *adj, *hinge_inputs(d), h, force, hess)
    # = the force kernel at x + dx with v = dx / h; H_i = sum (k + kd/h) g_i g_i^T
    expected = kernel_forces(x + dx, hinges, dx / h)
    assert np.abs(force.numpy() - expected).max() < 1e-4 * np.abs(expected).max()
    blocks = kernel_blocks(x + dx, hinges, 1.0, 1.0 / h)
    diag = np.zeros((n, 3, 3))
    for a in range(4):
        np.add.at(diag, hinges.indices[:, a], blocks[:, a, a])
    assert np.abs(hess.numpy() - diag).max() < 1e-4 * np.abs(diag).max()


def test_implicit_row_gather_and_matrix_free_product_match_the_blocks():
    n, hinges, x, rng = grid_case(seed=1)
    rows, cols = 5, 6
    inv_mass = np.ones(n, np.float32)
    inv_mass[[0, 3]] = 0.0  # pins: rows and columns left alone
    springs, _ = grid_springs(rows, cols)
    pairs = np.concatenate([springs, H.hinge_pairs(hinges.indices)])
    pairs = np.unique(np.sort(pairs, axis=1), axis=0)
    diagonal = np.c_[np.arange(n), np.arange(n)]
    entries = np.unique(np.concatenate([pairs, pairs[:, ::-1], diagonal]), axis=0)  # sorted CSR
    row_offsets = np.r_[0, np.cumsum(np.bincount(entries[:, 0], minlength=n))]
    offsets, hinge, slot = H.hinge_adjacency(hinges.indices, n)
    block = H.hinge_block_index(hinges.indices, offsets, hinge, row_offsets, entries[:, 1])
    d = hinges.to_device(DEVICE)
    theta = wp.zeros(hinges.hinge_count, dtype=float, device=DEVICE)
    grad = wp.zeros((hinges.hinge_count, 4), dtype=wp.vec3, device=DEVICE)
    launch(K.eval_hinge_gradients, hinges.hinge_count, vec3(x), d.hinge_indices, theta, grad)
    values = wp.zeros(len(entries), dtype=wp.mat33, device=DEVICE)
    adj = [wp.array(a, dtype=int, device=DEVICE) for a in (offsets, hinge, slot)]
    w = wp.array(inv_mass, dtype=float, device=DEVICE)
    h = 0.01
    block = wp.array(block, dtype=int, device=DEVICE)
    gathered = (d.hinge_indices, grad, d.hinge_stiffness, d.hinge_damping, w)
    row_part = [wp.zeros(n, dtype=wp.mat33, device=DEVICE) for _ in range(2)]  # E_i of the split product
    launch(K.add_hinge_system_rows, n, *adj, block, *gathered, h * h, h, values, *row_part)
    got = np.zeros((3 * n, 3 * n))
    for (i, j), m in zip(entries, values.numpy()):
        got[3 * i : 3 * i + 3, 3 * j : 3 * j + 3] = m
    expected = np.zeros((3 * n, 3 * n))
    blocks = kernel_blocks(x, hinges, h * h, h)
    for e, q in enumerate(hinges.indices):
        for a in range(4):
            for b in range(4):
                if inv_mass[q[a]] and inv_mass[q[b]]:
                    expected[3 * q[a] : 3 * q[a] + 3, 3 * q[b] : 3 * q[b] + 3] += blocks[e, a, b]
    assert np.abs(got - expected).max() < 1e-5 * np.abs(expected).max()
    assert np.linalg.eigvalsh(expected).min() > -1e-6 * np.abs(expected).max()
    row_sums = expected.reshape(n, 3, n, 3).sum(axis=2)  # sum_j A_ij per row block
    for e in row_part:
        assert np.abs(e.numpy() - row_sums).max() < 1e-5 * np.abs(expected).max()
    # matrix-free: z += A_hinge y
    y = rng.normal(size=(n, 3))
    z = vec3(np.full((n, 3), 1e-3))
    launch(K.add_hinge_matrix_product, n, *adj, *gathered, h * h, h, 1, vec3(y), z)
    ay = (expected @ y.ravel()).reshape(n, 3)
    assert np.abs(z.numpy() - 1e-3 - ay).max() < 1e-5 * np.abs(ay).max()
    # rhs form: pinned columns kept (moving pins), pinned rows still untouched; -h^2 K v
    full = np.zeros((3 * n, 3 * n))
    stiff_blocks = kernel_blocks(x, hinges, 1.0, 0.0)
    for e, q in enumerate(hinges.indices):
        for a in range(4):
            for b in range(4):
                if inv_mass[q[a]]:
                    full[3 * q[a] : 3 * q[a] + 3, 3 * q[b] : 3 * q[b] + 3] += stiff_blocks[e, a, b]
    z = vec3(np.zeros((n, 3)))
    launch(K.add_hinge_matrix_product, n, *adj, *gathered, -h * h, 0.0, 0, vec3(y), z)
    rhs = -h * h * (full @ y.ravel()).reshape(n, 3)
    assert np.abs(z.numpy() - rhs).max() < 1e-5 * np.abs(rhs).max()
    assert np.abs(rhs[[0, 3]]).max() == 0.0 and np.abs(full[:, :3]).max() > 0.0  # pinned row 0 empty, its column not


# -- position-based projections --------------------------------------------------------------------
def solve_one(x, hinge, inv_mass, h, xpbd=True, dp0=None, lam0=0.0, stiffness=1.0):
    d = hinge.to_device(DEVICE)
    dp = vec3(np.zeros((4, 3)) if dp0 is None else dp0)
    lam = wp.array(np.array([lam0], np.float32), dtype=float, device=DEVICE)
    order = wp.array(np.array([0], np.int32), dtype=wp.int32, device=DEVICE)
    w = wp.array(np.asarray(inv_mass, np.float32), dtype=float, device=DEVICE)
    if xpbd:
        launch(K.solve_hinges_xpbd, 1, order, 0, *hinge_inputs(d), w, vec3(x), h, lam, dp)
    else:
        launch(K.solve_hinges_pbd, 1, order, 0, d.hinge_indices, d.hinge_rest_angle, stiffness, w, vec3(x), dp)
    return dp.numpy().astype(np.float64), float(lam.numpy()[0])


def test_xpbd_projection_follows_the_closed_form():
    rng = np.random.default_rng(4)
    x = random_hinge(rng)
    theta = H.hinge_angles(x, [[0, 1, 2, 3]])[0]
    c0 = 1e-3
    inv_mass = np.array([2.0, 0.5, 1.0, 3.0])
    _, g, _ = H.hinge_angle_gradients(x, [[0, 1, 2, 3]])
    wg = float(np.sum(inv_mass * np.sum(g[0] ** 2, axis=1)))
    h = 0.01
    k = 1.0 / (h * h * wg)  # k h^2 W = 1: one projection halves C
    hinge = one_hinge(x, rest=theta - c0, k=k)
    dp, lam = solve_one(x, hinge, inv_mass, h)
    dlam = -k * h * h * c0 / (k * h * h * wg + 1.0)
    assert abs(lam - dlam) < 1e-4 * abs(dlam)
    assert np.abs(dp - inv_mass[:, None] * g[0] * dlam).max() < 1e-4 * np.abs(dp).max()
    c1 = H.wrap_angle(H.hinge_angles(x + dp, hinge.indices)[0] - hinge.rest_angle[0])
    assert abs(c1 - c0 / (1.0 + k * h * h * wg)) < 0.01 * c0 / 2
    # a second iteration with the accumulated lambda converges to XPBD's fixed point C = -alpha~ lambda
    dp2, lam2 = solve_one(x, hinge, inv_mass, h, dp0=dp, lam0=lam)
    c2 = H.wrap_angle(H.hinge_angles(x + dp2, hinge.indices)[0] - hinge.rest_angle[0])
    assert abs(c2 + lam2 / (k * h * h)) < 0.02 * c0
    # stiff limit (alpha -> 0): C is gone to first order
    stiff = one_hinge(x, rest=theta - c0, k=1e6 * k)
    dp, _ = solve_one(x, stiff, inv_mass, h)
    assert abs(H.wrap_angle(H.hinge_angles(x + dp, hinge.indices)[0] - stiff.rest_angle[0])) < 0.01 * c0
    # damping term: gamma sum g . dp enters the numerator, (1 + gamma) the denominator
    damped = one_hinge(x, rest=theta, k=k, kd=0.3 * k * h)
    dp0 = rng.normal(scale=1e-4, size=(4, 3))
    theta_p = H.hinge_angles(x + dp0, [[0, 1, 2, 3]])[0]
    _, g_p, _ = H.hinge_angle_gradients(x + dp0, [[0, 1, 2, 3]])
    wg_p = float(np.sum(inv_mass * np.sum(g_p[0] ** 2, axis=1)))
    rate = float(np.sum(g_p[0] * dp0))
    kd = 0.3 * k * h
    expected = -(k * h * h * (theta_p - theta) + kd * h * rate) / ((k * h * h + kd * h) * wg_p + 1.0)
    _, lam_d = solve_one(x, damped, inv_mass, h, dp0=dp0)
    assert abs(lam_d - expected) < 1e-3 * abs(expected)


def test_pbd_projection_scales_the_violation():
    rng = np.random.default_rng(9)
    x = random_hinge(rng)
    theta = H.hinge_angles(x, [[0, 1, 2, 3]])[0]
    c0 = 2e-3
    hinge = one_hinge(x, rest=theta - c0, k=1.0)
    inv_mass = np.array([1.0, 0.0, 2.0, 0.5])  # a pinned vertex does not move
    for stiffness, left in ((1.0, 0.0), (0.25, 0.75)):
        dp, _ = solve_one(x, hinge, inv_mass, 0.01, xpbd=False, stiffness=stiffness)
        assert np.all(dp[1] == 0.0)
        c1 = H.wrap_angle(H.hinge_angles(x + dp, hinge.indices)[0] - hinge.rest_angle[0])
        assert abs(c1 - left * c0) < 0.01 * c0


# -- a small demo: a clamped strip, explicit Euler, springs + hinges -------------------------------
def test_strip_cantilever_with_springs_and_hinges_sags_like_the_linear_prediction():
    """A 2 x 8 strip (h = 1 cm) clamped by its first two columns, springs from kernels.forces, hinges
    from kernels.bending, symplectic Euler with drag to rest: the tip drop matches the linear static
    solution of the hinge stiffness sum k c c^T (the projective matrix) and the Euler-Bernoulli
    beam q L^4 / (8 B W) to the discretisation's few per cent; without hinges the strip falls."""
    rows, cols, hh = 2, 8, 0.01
    rho, bend, ks = 0.2, 1e-2, 10.0
    width, length = hh * (cols - 1), hh * (rows - 1)
    mass = rho * width * length
    pins = [0, 1, cols, cols + 1]
    params = {t: SpringParams(ks, 0.0) for t in SpringType}
    model = build_grid_cloth(
        rows, cols, width, length, mass, spring_params=params, pins=pins, plane="horizontal", bend="none", device=DEVICE
    )
    x0 = model.host.q.astype(np.float64)
    hinges = H.grid_hinges(x0, rows, cols, bend)
    d = hinges.to_device(DEVICE)
    gravity = wp.vec3(0.0, -9.81, 0.0)
    omega1 = 3.516 * np.sqrt(bend * length / (rho * length * (width - hh) ** 4))
    drag = 2.0 * omega1
    dt, steps = 8e-5, 2000

    def run(with_hinges, n_steps, drag):
        state = model.state()
        for _ in range(n_steps):
            x, v, f = state.particle_q, state.particle_qd, state.particle_f
            launch(eval_particle_forces, model.particle_count, v, model.particle_mass, gravity, drag, f)
            launch(
                eval_springs,
                model.spring_count,
                x,
                v,
                model.spring_indices,
                model.spring_rest_length,
                model.spring_stiffness,
                model.spring_damping,
                model.spring_compression,
                f,
            )
            if with_hinges:
                launch(K.eval_hinge_forces, hinges.hinge_count, x, v, *hinge_inputs(d), f)
            launch(integrate_explicit_euler, model.particle_count, x, v, f, model.particle_inv_mass, dt)
        return state.particle_q.numpy().astype(np.float64), state.particle_qd.numpy()

    q, qd = run(True, steps, drag)
    drop = x0[[cols - 1, 2 * cols - 1], 1].mean() - q[[cols - 1, 2 * cols - 1], 1].mean()
    assert np.all(np.isfinite(q)) and np.abs(qd).max() < 1e-3 * drop * omega1
    # linear statics of the hinges alone (the springs are flat: no transverse stiffness at rest)
    c = H.hinge_rest_coefficients(x0, hinges.indices)
    stiff = np.zeros((model.particle_count, model.particle_count))
    for e, qe in enumerate(hinges.indices):
        stiff[np.ix_(qe, qe)] += hinges.stiffness[e] * np.outer(c[e], c[e])
    free = np.setdiff1d(np.arange(model.particle_count), pins)
    load = model.host.mass[free] * 9.81
    u = np.linalg.solve(stiff[np.ix_(free, free)], load)
    linear = u[np.isin(free, [cols - 1, 2 * cols - 1])].mean()
    assert abs(drop / linear - 1.0) < 0.02
    # the same strip as a 1-D chain: column c's two half-weight hinges are a rotational spring B W / h
    # carrying the moment of the loads beyond it; tip = sum_c theta_c (x_tip - x_c) = 266 F h^3 / (B W)
    # with F = 2 m g per column (6 segments); the continuum q L^4 / (8 B W) is 1.44x smaller at this coarseness
    force = 2.0 * model.host.mass[cols - 1] * 9.81
    assert abs(drop / (266.0 * force * hh**3 / (bend * length)) - 1.0) < 0.03
    q_free, _ = run(False, steps, 0.0)  # no hinges, no drag: it hangs from the clamp
    assert x0[cols - 1, 1] - q_free[cols - 1, 1] > 20 * drop
