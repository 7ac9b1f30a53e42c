"""A material in physical units (warpcloth.sim.material), the cantilever elastica
(warpcloth.sim.elastica) and the Cusick drape measurements (warpcloth.run.drape): hand-computed
spring values, the uniform-strain energy identity, masses, size independence, errors, the
elastica's limits and the drape coefficient and node count of known shapes."""

from __future__ import annotations

import math

import numpy as np
import pytest

from warpcloth.errors import WarpclothError
from warpcloth.sim.grid import grid_springs, grid_triangles
from warpcloth.sim.material import (
    PRESETS,
    Material,
    bend_spring_stiffness,
    grid_spring_params,
    material,
    mesh_spring_params,
)
from warpcloth.sim.mesh import mesh_springs
from warpcloth.sim.model import SpringParams, SpringType, build_model

TEST = Material("test", 0.2, 1000.0, 800.0, 50.0, 1e-3, 2e-4)


def grid_rest(rows, cols, width, height):
    """Rest positions in the grid's cloth frame (x = +col, y = -row; float64)."""
    r, c = np.meshgrid(np.arange(rows), np.arange(cols), indexing="ij")
    return np.stack([c.ravel() * width / (cols - 1), -r.ravel() * height / (rows - 1), np.zeros(r.size)], axis=1)


def lattice_energy(q, pairs, ks, strain):
    """Linearised spring energy sum 1/2 ks (d . eps d / L)^2 of a uniform in-plane strain."""
    d = (q[pairs[:, 1]] - q[pairs[:, 0]])[:, :2]
    stretch = np.einsum("si,ij,sj->s", d, strain, d) / np.linalg.norm(d, axis=1)
    return 0.5 * float(np.sum(ks * stretch**2))


def random_strains(count, seed=0, size=1e-3):
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(count):
        e11, e22, e12 = rng.uniform(-size, size, 3)
        out.append(np.array([[e11, e12], [e12, e22]]))
    # and the three pure states
    out += [np.diag([size, 0.0]), np.diag([0.0, size]), np.array([[0.0, size], [size, 0.0]])]
    return out


def by_pair(pairs, values):
    return {(min(int(a), int(b)), max(int(a), int(b))): float(v) for (a, b), v in zip(pairs, values)}


# -- mapping: hand-computed values -------------------------------------------------------------


def test_grid_3x3_hand_values_without_bend_springs():
    # hx = 0.1, hy = 0.05, d^2 = 0.0125: shear G d^2 / (2 hx hy) = 50 * 0.0125 / 0.01 = 62.5;
    # x per cell 1/2 (hy/hx)(S_w - G hx^2/hy^2) = 0.25 (1000 - 200) = 200 (interior row: 400);
    # y per cell 1/2 (hx/hy)(S_f - G hy^2/hx^2) = 1.0 (800 - 12.5) = 787.5 (interior column: 1575).
    r = grid_spring_params(TEST, 3, 3, 0.2, 0.1, bend="none")
    pairs, types = grid_springs(3, 3, "none")
    assert np.array_equal(r.pairs, pairs) and np.array_equal(r.types, types)
    expected = [787.5, 1575.0, 787.5] * 2 + [200.0, 200.0, 400.0, 400.0, 200.0, 200.0] + [62.5] * 8
    np.testing.assert_allclose(r.stiffness, expected, rtol=1e-13)
    a = 0.1 * 0.05 * 0.2  # rho hx hy
    np.testing.assert_allclose(r.mass, a * np.array([0.25, 0.5, 0.25, 0.5, 1.0, 0.5, 0.25, 0.5, 0.25]), rtol=1e-13)
    assert r.membrane_error < 1e-12 and r.clamped == 0


def test_grid_3x3_hand_values_with_provot_bend_springs():
    # gravity 5 m/s^2 makes w = rho g = 1 N/m^2: k_b = 9 B^(5/3) / h^4
    r = grid_spring_params(TEST, 3, 3, 0.2, 0.1, bend="provot", gravity=5.0)
    kbx = 9.0 * 1e-3 ** (5 / 3) / 0.1**4  # x-bend springs (curvature along the warp), h = hx: 0.9 N/m
    kby = 9.0 * 2e-4 ** (5 / 3) / 0.05**4  # y-bend springs (weft), h = hy
    assert kbx == pytest.approx(0.9, rel=1e-12)
    # every structural spring of a 3 x 3 grid is spanned by one bend spring: 2 k_b off each
    expected = (
        [787.5 - 2 * kby, 1575.0 - 2 * kby, 787.5 - 2 * kby] * 2
        + [200.0 - 2 * kbx, 200.0 - 2 * kbx, 400.0 - 2 * kbx, 400.0 - 2 * kbx, 200.0 - 2 * kbx, 200.0 - 2 * kbx]
        + [62.5] * 8
        + [kby] * 3
        + [kbx] * 3
    )
    np.testing.assert_allclose(r.stiffness, expected, rtol=1e-12)
    assert r.membrane_error < 1e-12


def test_bend_rule_reproduces_the_cotton_example():
    # cotton, 1 m cloth: 2.6 N/m at 64^2 and 44 N/m at 128^2 (ks = 9 B / (kappa_ref^2 h^4))
    cotton = material("cotton")
    w = cotton.weight()
    assert float(bend_spring_stiffness(cotton.bend_warp, 1 / 63, w)) == pytest.approx(2.6, rel=0.03)
    assert float(bend_spring_stiffness(cotton.bend_warp, 1 / 127, w)) == pytest.approx(44.0, rel=0.03)
    # equal energy at kappa_ref = 1 / c: per area ks kappa^4 h^4 / 18 = B kappa^2 / 2
    h, c = 0.01, cotton.bending_length()
    ks = float(bend_spring_stiffness(cotton.bend_warp, h, w))
    assert ks * h**4 / c**4 / 18.0 == pytest.approx(cotton.bend_warp / c**2 / 2.0, rel=1e-12)


def test_two_triangle_mesh_hand_values():
    # two equilateral triangles of side a; an isotropic Cauchy material (G = S / 3) fits exactly:
    # c = 8 S / 9 per edge, share ks = c A / a^2 = (8/9)(sqrt(3)/4) S per triangle
    a, s = 0.1, 900.0
    v = np.array([[0, 0, 0], [a, 0, 0], [a / 2, a * math.sqrt(3) / 2, 0], [a / 2, -a * math.sqrt(3) / 2, 0]])
    t = np.array([[0, 1, 2], [1, 0, 3]])
    pairs, types = mesh_springs(v, t, bend=False)
    iso = Material("iso", 0.3, s, s, s / 3.0, 0.0, 0.0)
    r = mesh_spring_params(iso, v, t, pairs, types)
    share = 8.0 / 9.0 * math.sqrt(3) / 4.0 * s
    ks = by_pair(pairs, r.stiffness)
    assert ks[(0, 1)] == pytest.approx(2 * share, rel=1e-12)
    for edge in [(0, 2), (1, 2), (0, 3), (1, 3)]:
        assert ks[edge] == pytest.approx(share, rel=1e-12)
    assert r.membrane_error < 1e-9
    area = a * a * math.sqrt(3) / 4
    np.testing.assert_allclose(r.mass, 0.3 * area / 3 * np.array([2, 2, 1, 1]), rtol=1e-12)


def test_two_triangle_quad_equals_the_grid_cell_rule():
    # a 0.2 x 0.1 rectangle as two triangles, quads=True: both diagonals are shear springs and the
    # values are the grid rule's (one cell: every structural spring a boundary one)
    hx, hy = 0.2, 0.1
    v = np.array([[0, 0, 0], [hx, 0, 0], [0, -hy, 0], [hx, -hy, 0]], dtype=float)
    t = np.array([[0, 2, 1], [1, 2, 3]])
    pairs, types = mesh_springs(v, t, quads=True, bend=False)
    r = mesh_spring_params(TEST, v, t, pairs, types)
    ks = by_pair(pairs, r.stiffness)
    x_side = 0.5 * (hy / hx) * (1000.0 - 50.0 * hx**2 / hy**2)  # 150
    y_side = 0.5 * (hx / hy) * (800.0 - 50.0 * hy**2 / hx**2)  # 787.5
    diag = 50.0 * (hx * hx + hy * hy) / (2 * hx * hy)  # 62.5
    assert ks[(0, 1)] == pytest.approx(x_side, rel=1e-10) and ks[(2, 3)] == pytest.approx(x_side, rel=1e-10)
    assert ks[(0, 2)] == pytest.approx(y_side, rel=1e-10) and ks[(1, 3)] == pytest.approx(y_side, rel=1e-10)
    assert ks[(1, 2)] == pytest.approx(diag, rel=1e-10) and ks[(0, 3)] == pytest.approx(diag, rel=1e-10)
    g = grid_spring_params(TEST, 2, 2, hx, hy, bend="none")
    assert by_pair(g.pairs, g.stiffness) == pytest.approx(ks, rel=1e-10)


def test_quad_mesh_of_a_grid_equals_grid_spring_params():
    rows, cols, w, h = 5, 7, 0.3, 0.2
    q = grid_rest(rows, cols, w, h)
    t = grid_triangles(rows, cols)
    pairs, types = mesh_springs(q, t, quads=True, bend=False)
    mesh = mesh_spring_params(TEST, q, t, pairs, types)
    grid = grid_spring_params(TEST, rows, cols, w, h, bend="none")
    assert by_pair(mesh.pairs, mesh.stiffness) == pytest.approx(by_pair(grid.pairs, grid.stiffness), rel=1e-10)
    # with bend springs (polyester: B_warp != B_weft) the bend springs are the grid's, warp along x
    pairs, types = mesh_springs(q, t, quads=True, bend=True)
    mesh = mesh_spring_params("polyester", q, t, pairs, types)
    grid = grid_spring_params("polyester", rows, cols, w, h, bend="provot")
    bends = by_pair(grid.pairs[grid.types == SpringType.BEND], grid.stiffness[grid.types == SpringType.BEND])
    mesh_bends = by_pair(mesh.pairs[mesh.types == SpringType.BEND], mesh.stiffness[mesh.types == SpringType.BEND])
    assert mesh_bends == pytest.approx(bends, rel=1e-10)
    assert len(set(np.round(list(bends.values()), 9))) == 2  # two values: along x (warp) and along y (weft)


# -- the uniform-strain energy identity ---------------------------------------------------------


@pytest.mark.parametrize("bend", ["none", "provot", "choi_ko"])
@pytest.mark.parametrize("name", ["test", "cotton", "denim", "polyester_light", "rotated"])
def test_grid_energy_equals_the_membrane_energy_under_uniform_strain(name, bend):
    mat = {"test": TEST, "rotated": PRESETS["polyester_light"].replace(warp_angle=math.pi / 2)}.get(name) or material(
        name
    )
    rows, cols, w, h = 7, 9, 0.3, 0.2  # hx = 0.0375 != hy = 0.0333
    r = grid_spring_params(mat, rows, cols, w, h, bend=bend)
    assert r.clamped == 0
    q = grid_rest(rows, cols, w, h)
    for eps in random_strains(12, seed=1):
        lattice = lattice_energy(q, r.pairs, r.stiffness, eps)
        membrane = float(mat.membrane_energy_density(eps)) * w * h
        assert lattice == pytest.approx(membrane, rel=1e-9)


def test_grid_energy_with_real_spring_lengths():
    # the same with the springs' nonlinear lengths at 1e-6 strain (linearisation error ~ strain)
    rows, cols, w, h = 6, 5, 0.25, 0.2
    r = grid_spring_params("wool", rows, cols, w, h)
    q = grid_rest(rows, cols, w, h)
    for eps in random_strains(4, seed=2, size=1e-6):
        x = q.copy()
        x[:, :2] = q[:, :2] @ (np.eye(2) + eps).T
        length = np.linalg.norm(x[r.pairs[:, 1]] - x[r.pairs[:, 0]], axis=1)
        rest = np.linalg.norm(q[r.pairs[:, 1]] - q[r.pairs[:, 0]], axis=1)
        energy = 0.5 * float(np.sum(r.stiffness * (length - rest) ** 2))
        assert energy == pytest.approx(float(material("wool").membrane_energy_density(eps)) * w * h, rel=1e-4)


@pytest.mark.parametrize("bend", [False, True])
def test_quad_mesh_energy_equals_the_membrane_energy(bend):
    rows, cols, w, h = 6, 8, 0.35, 0.25
    q = grid_rest(rows, cols, w, h)
    t = grid_triangles(rows, cols)
    pairs, types = mesh_springs(q, t, quads=True, bend=bend)
    r = mesh_spring_params("cotton", q, t, pairs, types)
    assert r.membrane_error < 1e-9
    for eps in random_strains(8, seed=3):
        assert lattice_energy(q, r.pairs, r.stiffness, eps) == pytest.approx(
            float(material("cotton").membrane_energy_density(eps)) * w * h, rel=1e-9
        )


def hex_mesh(n=6, a=0.05):
    """An equilateral triangle mesh: n rows of n vertices, odd rows shifted by half a side."""
    pts = np.array([[(i + 0.5 * (j % 2)) * a, j * a * math.sqrt(3) / 2, 0.0] for j in range(n) for i in range(n)])
    tris = []
    for j in range(n - 1):
        for i in range(n - 1):
            p, q, r, s = j * n + i, j * n + i + 1, (j + 1) * n + i, (j + 1) * n + i + 1
            tris += [[p, q, r], [q, s, r]] if j % 2 == 0 else [[p, q, s], [p, s, r]]
    return pts, np.array(tris)


def test_equilateral_mesh_is_exact_for_an_isotropic_cauchy_material():
    v, t = hex_mesh()
    pairs, types = mesh_springs(v, t, bend=False)
    iso = Material("iso", 0.2, 600.0, 600.0, 200.0, 1e-5, 1e-5)
    r = mesh_spring_params(iso, v, t, pairs, types)
    assert r.membrane_error < 1e-9
    area = float(np.sum(np.linalg.norm(np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]]), axis=1) / 2))
    for eps in random_strains(6, seed=4):
        membrane = float(iso.membrane_energy_density(eps)) * area
        assert lattice_energy(v, pairs, r.stiffness, eps) == pytest.approx(membrane, rel=1e-9)


@pytest.mark.parametrize("name", ["cotton", "denim"])
def test_triangle_mesh_energy_within_the_reported_bound(name):
    # a jittered Delaunay mesh: the per-face fit is not exact (a triangle cannot carry G << S / 3);
    # the relative energy error of every uniform strain stays within membrane_error
    from scipy.spatial import Delaunay

    rng = np.random.default_rng(5)
    g = np.stack(np.meshgrid(np.linspace(0, 0.3, 9), np.linspace(0, 0.2, 7)), -1).reshape(-1, 2)
    inner = (g[:, 0] > 0) & (g[:, 0] < 0.3) & (g[:, 1] > 0) & (g[:, 1] < 0.2)
    g[inner] += rng.uniform(-0.008, 0.008, (int(inner.sum()), 2))
    t = Delaunay(g).simplices
    v = np.column_stack([g, np.zeros(len(g))])
    pairs, types = mesh_springs(v, t, bend=True)
    mat = material(name)
    r = mesh_spring_params(mat, v, t, pairs, types)
    assert 0.01 < r.membrane_error < 100.0
    worst = 0.0
    for eps in random_strains(40, seed=6):
        ratio = lattice_energy(v, pairs, r.stiffness, eps) / (float(mat.membrane_energy_density(eps)) * 0.06)
        worst = max(worst, abs(ratio - 1.0))
    assert worst <= r.membrane_error * (1 + 1e-9)
    assert worst > 0.2 * r.membrane_error  # the bound is not vacuous


def quadratic_form(q, pairs, ks, area):
    """The lattice's membrane matrix D (W = 1/2 e^T D e, e = (e11, e22, 2 e12)) from its energies."""

    def energy(e):
        return lattice_energy(q, pairs, ks, np.array([[e[0], e[2] / 2], [e[2] / 2, e[1]]])) / area

    basis = np.eye(3)
    d = np.zeros((3, 3))
    for i in range(3):
        d[i, i] = 2 * energy(basis[i])
        for j in range(i):
            d[i, j] = d[j, i] = energy(basis[i] + basis[j]) - 0.5 * (d[i, i] + d[j, j])
    return d


def test_membrane_error_is_the_worst_strain_for_congruent_faces():
    # the one-diagonal grid as a triangle mesh: every face has the same fit, so the reported bound
    # is reached by the worst uniform strain (a generalized eigenvector)
    rows, cols, w, h = 5, 6, 0.25, 0.2
    q = grid_rest(rows, cols, w, h)
    t = grid_triangles(rows, cols)
    pairs, types = mesh_springs(q, t, bend=False)
    mat = material("wool")
    r = mesh_spring_params(mat, q, t, pairs, types)
    d_lat, d_mat = quadratic_form(q, pairs, r.stiffness, w * h), mat.membrane_voigt()
    chol_inv = np.linalg.inv(np.linalg.cholesky(d_mat))
    worst = float(np.max(np.abs(np.linalg.eigvalsh(chol_inv @ (d_lat - d_mat) @ chol_inv.T))))
    assert worst == pytest.approx(r.membrane_error, rel=1e-6)
    assert r.membrane_error > 0.1  # a right triangle leaves a shear-stretch coupling


def test_bend_springs_across_edges_are_taken_from_the_membrane():
    # hex mesh, bend springs across every interior edge, stiff enough to matter (k_b ~ 5 % of S):
    # their membrane energy is taken from the fit, and the total stays within the reported bound
    v, t = hex_mesh()
    pairs, types = mesh_springs(v, t, bend=True)
    iso = Material("iso", 0.2, 600.0, 600.0, 200.0, 2e-3, 2e-3)
    r = mesh_spring_params(iso, v, t, pairs, types)
    bend = r.types == SpringType.BEND
    assert 0.02 * 600 < float(np.median(r.stiffness[bend])) < 0.2 * 600
    area = float(np.sum(np.linalg.norm(np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]]), axis=1) / 2))
    d_lat, d_mat = quadratic_form(v, pairs, r.stiffness, area), iso.membrane_voigt()
    chol_inv = np.linalg.inv(np.linalg.cholesky(d_mat))
    worst = float(np.max(np.abs(np.linalg.eigvalsh(chol_inv @ (d_lat - d_mat) @ chol_inv.T))))
    assert 1e-4 < worst <= r.membrane_error * (1 + 1e-9)


# -- masses, size independence -----------------------------------------------------------------


def test_masses_sum_to_density_times_area():
    for rows, cols, w, h in [(3, 3, 0.2, 0.1), (16, 9, 1.0, 0.5), (40, 40, 0.7, 0.7)]:
        r = grid_spring_params("denim", rows, cols, w, h)
        assert float(r.mass.sum()) == pytest.approx(0.334 * w * h, rel=1e-12)
    v, t = hex_mesh()
    pairs, types = mesh_springs(v, t)
    r = mesh_spring_params("silk", v, t, pairs, types)
    area = float(np.sum(np.linalg.norm(np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]]), axis=1) / 2))
    assert float(r.mass.sum()) == pytest.approx(0.060 * area, rel=1e-12)


def effective_tensor(rows, cols, mat, w=1.0, h=1.0, bend="provot"):
    """(C11, C22, C_shear) of the lattice from its energy under three unit-ish strains."""
    r = grid_spring_params(mat, rows, cols, w, h, bend=bend)
    q = grid_rest(rows, cols, w, h)
    e = 1e-3
    c11 = 2 * lattice_energy(q, r.pairs, r.stiffness, np.diag([e, 0.0])) / (w * h * e * e)
    c22 = 2 * lattice_energy(q, r.pairs, r.stiffness, np.diag([0.0, e])) / (w * h * e * e)
    c66 = 2 * lattice_energy(q, r.pairs, r.stiffness, np.array([[0.0, e], [e, 0.0]])) / (w * h * 4 * e * e)
    return np.array([c11, c22, c66]), r


def test_same_membrane_response_at_16_and_64():
    cotton = material("cotton")
    small, r16 = effective_tensor(16, 16, cotton)
    large, r64 = effective_tensor(64, 64, cotton)
    np.testing.assert_allclose(small, large, rtol=1e-9)
    np.testing.assert_allclose(small, [cotton.stretch_warp, cotton.stretch_weft, cotton.shear], rtol=1e-9)
    # on a square grid ks does not scale with the spacing: interior structural S - G - 4 k_b, shear G
    for r, n in ((r16, 16), (r64, 64)):
        kb = float(bend_spring_stiffness(cotton.bend_warp, 1 / (n - 1), cotton.weight()))
        structural = r.types == SpringType.STRUCTURAL
        interior_x = structural & (r.pairs[:, 0] // n == n // 2) & (r.pairs[:, 1] - r.pairs[:, 0] == 1)
        assert r.stiffness[interior_x][n // 2] == pytest.approx(cotton.stretch_warp - cotton.shear - 4 * kb, rel=1e-12)
        np.testing.assert_allclose(r.stiffness[r.types == SpringType.SHEAR], cotton.shear, rtol=1e-12)


def test_bend_springs_stiffer_than_the_membrane_are_clamped_with_a_warning(capsys):
    r = grid_spring_params("cotton", 3, 200, 0.002, 0.01, bend="provot")  # h ~ 10 um along x
    assert r.clamped > 0 and np.all(r.stiffness >= 0.0)
    assert r.membrane_error > 0.01
    err = capsys.readouterr().err
    assert "clamped" in err and "--bend dihedral" in err and err.count("\n") == 1


def test_off_axis_warp_warns(capsys):
    r = grid_spring_params(TEST.replace(warp_angle=0.4), 5, 5, 0.1, 0.1)
    assert "off the grid axes" in capsys.readouterr().err
    assert r.membrane_error > 0.01  # the coupling left out shows in the reported error


# -- damping, compression ------------------------------------------------------------------------


def test_damping_and_compression_per_spring():
    mat = TEST.replace(compression=0.25, stretch_damping_ratio=0.1, bend_damping_ratio=0.03, bend_damping_frequency=4.0)
    r = grid_spring_params(mat, 4, 5, 0.3, 0.2)
    m_bar = 0.5 * (r.mass[r.pairs[:, 0]] + r.mass[r.pairs[:, 1]])
    membrane = r.types != SpringType.BEND
    np.testing.assert_allclose(r.damping[membrane], 2 * 0.1 * np.sqrt(r.stiffness * m_bar)[membrane], rtol=1e-13)
    beta = 0.03 / (math.pi * 4.0)
    np.testing.assert_allclose(r.damping[~membrane], beta * r.stiffness[~membrane], rtol=1e-13)
    np.testing.assert_array_equal(r.compression, np.where(membrane, 0.25, 1.0))
    ray = grid_spring_params(mat, 4, 5, 0.3, 0.2, stretch_damping="rayleigh")
    np.testing.assert_allclose(ray.damping[membrane], (0.1 / (math.pi * 4.0)) * r.stiffness[membrane], rtol=1e-13)
    with pytest.raises(WarpclothError, match="stretch_damping must be one of ratio, rayleigh"):
        grid_spring_params(mat, 4, 5, 0.3, 0.2, stretch_damping="viscous")


# -- build_model takes per-spring arrays ------------------------------------------------------------


def test_build_model_takes_per_spring_arrays():
    r = grid_spring_params("polyester", 6, 5, 0.4, 0.5)
    q = grid_rest(6, 5, 0.4, 0.5)
    model = build_model(q, r.pairs, r.types, r.mass, None, device="cpu", **r.build_kwargs())
    np.testing.assert_array_equal(model.spring_stiffness.numpy(), r.stiffness.astype(np.float32))
    np.testing.assert_array_equal(model.spring_damping.numpy(), r.damping.astype(np.float32))
    assert model.total_mass == pytest.approx(0.128 * 0.2, rel=1e-6)
    for t in SpringType:
        assert model.spring_params[t].stiffness == pytest.approx(float(r.stiffness[r.types == t].max()), rel=1e-6)
    assert model.max_stiffness() == pytest.approx(float(r.stiffness.max()), rel=1e-6)
    # one array with per-type params for the other
    params = {t: SpringParams(10.0, 0.5) for t in SpringType}
    half = build_model(q, r.pairs, r.types, r.mass, params, device="cpu", spring_stiffness=r.stiffness)
    np.testing.assert_array_equal(half.spring_damping.numpy(), np.float32(0.5))
    np.testing.assert_array_equal(half.spring_stiffness.numpy(), r.stiffness.astype(np.float32))
    # the per-type path is unchanged
    plain = build_model(q, r.pairs, r.types, r.mass, params, device="cpu")
    np.testing.assert_array_equal(plain.spring_stiffness.numpy(), np.float32(10.0))
    assert plain.spring_params == params


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"spring_stiffness": [1.0, 2.0]}, "spring_stiffness must have one value per spring"),
        ({"spring_stiffness": "bad"}, "spring_stiffness must be numbers"),
        ({"spring_damping": [1.0, -2.0, 1.0]}, "spring_damping of spring 1 must be a finite number >= 0"),
        ({"spring_stiffness": [1.0, float("nan"), 1.0]}, "spring_stiffness of spring 1 must be a finite number >= 0"),
    ],
)
def test_build_model_rejects_bad_per_spring_arrays(kwargs, message):
    q = [[0, 0, 0], [1, 0, 0], [0, 1, 0]]
    params = {t: SpringParams(1.0, 0.0) for t in SpringType}
    with pytest.raises(WarpclothError, match=message):
        build_model(q, [[0, 1], [1, 2], [0, 2]], [0, 0, 1], [1.0] * 3, params, device="cpu", **kwargs)


def test_build_model_needs_one_source_of_spring_values():
    q = [[0, 0, 0], [1, 0, 0]]
    with pytest.raises(WarpclothError, match="needs spring_params, or both"):
        build_model(q, [[0, 1]], [0], [1.0, 1.0], None, spring_stiffness=[1.0], device="cpu")
    params = {t: SpringParams(1.0, 0.0) for t in SpringType}
    with pytest.raises(WarpclothError, match="not both"):
        build_model(q, [[0, 1]], [0], [1.0, 1.0], params, spring_stiffness=[1.0], spring_damping=[0.0], device="cpu")


# -- the Material object: presets and errors -------------------------------------------------------


def test_presets_bending_lengths_and_sources():
    table = {
        "cotton": (2.44, 2.44),
        "denim": (2.62, 2.62),
        "polyester": (2.18, 1.84),
        "wool": (1.50, 1.45),
        "silk": (1.37, 1.37),
        "polyester_light": (1.48, 1.66),
    }
    assert set(table) == set(PRESETS)
    for name, (cw, cf) in table.items():
        m = material(name)
        assert m.name == name and m.source
        assert m.bending_length("warp") * 100 == pytest.approx(cw, abs=0.01)
        assert m.bending_length("weft") * 100 == pytest.approx(cf, abs=0.01)
        assert m.compression == 1.0
    assert set(material("silk").estimated) >= {"density", "stretch_warp", "shear", "bend_warp"}
    assert material("denim").estimated == ("stretch_warp", "stretch_weft", "shear", "bend_weft")
    assert all(not PRESETS[n].estimated for n in PRESETS if n not in ("silk", "denim"))
    assert material(" Cotton ") is PRESETS["cotton"] and material(PRESETS["wool"]) is PRESETS["wool"]
    assert Material.from_dict(PRESETS["denim"].to_dict()) == PRESETS["denim"]


def test_unknown_preset_is_a_one_line_error():
    with pytest.raises(WarpclothError) as info:
        material("linen")
    msg = str(info.value)
    assert "\n" not in msg and "'linen'" in msg
    for name in PRESETS:
        assert name in msg


@pytest.mark.parametrize(
    "field, value, allowed",
    [
        ("density", -0.2, "must be > 0 kg/m^2"),
        ("density", float("nan"), "must be a finite number"),
        ("stretch_warp", float("inf"), "must be a finite number"),
        ("stretch_weft", 0.0, "must be > 0 N/m"),
        ("shear", -1.0, "must be > 0 N/m"),
        ("shear", 900.0, "must be < sqrt(stretch_warp * stretch_weft)"),
        ("bend_warp", -1e-6, "must be >= 0 N m"),
        ("bend_weft", float("nan"), "must be a finite number"),
        ("compression", 1.5, "must be in [0, 1]"),
        ("compression", -0.1, "must be >= 0"),
        ("stretch_damping_ratio", -0.01, "must be >= 0"),
        ("bend_damping_frequency", 0.0, "must be > 0 Hz"),
        ("warp_angle", 4.0, "must be in [-pi, pi]"),
        ("warp_angle", "x", "must be a number"),
        ("density", True, "must be a number"),
        ("estimated", ("colour",), "unknown field 'colour'"),
    ],
)
def test_bad_material_values_are_one_line_errors(field, value, allowed):
    with pytest.raises(WarpclothError) as info:
        TEST.replace(**{field: value})
    msg = str(info.value)
    assert "\n" not in msg and allowed in msg and field in msg and "'test'" in msg


def test_material_from_dict_errors():
    with pytest.raises(WarpclothError, match="unknown field 'colour'"):
        Material.from_dict({**TEST.to_dict(), "colour": "red"})
    with pytest.raises(WarpclothError, match="field 'shear' is missing"):
        Material.from_dict({k: v for k, v in TEST.to_dict().items() if k != "shear"})


def test_membrane_energy_density_rotates_with_the_warp():
    e = 1e-3
    light = material("polyester_light")
    assert float(light.membrane_energy_density(np.diag([e, 0.0]))) == pytest.approx(0.5 * 343.0 * e * e)
    turned = light.replace(warp_angle=math.pi / 2)  # the warp along the cloth's y
    assert float(turned.membrane_energy_density(np.diag([e, 0.0]))) == pytest.approx(0.5 * 86.0 * e * e)
    shear = np.array([[0.0, e], [e, 0.0]])  # 4 C66 e12^2 / 2
    assert float(light.membrane_energy_density(shear)) == pytest.approx(2 * 7.2 * e * e)


# -- elastica --------------------------------------------------------------------------------------


def test_elastica_small_load_limit():
    from warpcloth.sim.elastica import linear_tip_drop, tip_deflection

    w = 0.15 * 9.81
    for length, rigidity in [(0.1, 1e-2), (0.05, 1e-3)]:  # lambda = 0.147, 0.18
        drop, reach = tip_deflection(length, rigidity, w)
        ratio = drop / linear_tip_drop(length, rigidity, w)
        assert 0.999 < ratio < 1.0  # within 0.1 %, and below: large deflection is softer
        assert reach < length
    drop, _ = tip_deflection(0.1, 1e-4, w)  # lambda = 14.7: far from linear (design: 0.43)
    assert drop / linear_tip_drop(0.1, 1e-4, w) == pytest.approx(0.4255, abs=0.002)


def test_elastica_shape_is_inextensible_and_clamped():
    from warpcloth.sim.elastica import cantilever_elastica

    s, theta, x, y = cantilever_elastica(0.08, 2e-5, 2.0, n=401)
    assert s[0] == 0.0 and s[-1] == pytest.approx(0.08)
    assert theta[0] == pytest.approx(0.0, abs=1e-10) and x[0] == 0.0 and y[0] == 0.0
    arc = float(np.sum(np.hypot(np.diff(x), np.diff(y))))
    assert arc == pytest.approx(0.08, rel=1e-5)
    assert np.all(np.diff(theta) >= 0) and np.all(y <= 1e-15)
    dtheta_tip = (theta[-1] - theta[-2]) / (s[-1] - s[-2])
    dtheta_root = (theta[1] - theta[0]) / (s[1] - s[0])
    assert abs(dtheta_tip) < 1e-2 * dtheta_root  # free end: no moment


def test_elastica_41_5_degree_relation_and_inverse():
    from warpcloth.sim import elastica as el

    lam = el.lambda_for_chord_angle()
    assert lam == pytest.approx(8.004, abs=0.01)
    assert math.degrees(el.chord_angle_of(8.0)) == pytest.approx(41.487, abs=0.002)
    assert el.peirce_bending_length(1.0) == pytest.approx(0.5093, abs=1e-4)
    # ASTM: a strip whose overhang is twice its bending length droops 41.5 deg
    w, rigidity = 0.22 * 9.81, 31.4e-6
    c = el.bending_length(rigidity, w)
    assert math.degrees(el.tip_chord_angle(2 * c, rigidity, w)) == pytest.approx(41.5, abs=0.02)
    assert el.rigidity_from_bending_length(c, w) == pytest.approx(rigidity, rel=1e-12)
    assert el.rigidity_from_overhang(2 * c, w) == pytest.approx(rigidity, rel=1e-3)
    with pytest.raises(WarpclothError, match="rigidity must be > 0"):
        el.tip_deflection(0.1, 0.0, w)


# -- Cusick drape --------------------------------------------------------------------------------------


def ring_disc(radius, rings=40, lobes=0, amplitude=0.0, phase=0.0, seed=0):
    """A disc (or a flower r = R (1 + a cos(lobes (phi - phase)))) in the x-z plane, y up: rings of
    vertices with random angular offsets, Delaunay-triangulated."""
    from scipy.spatial import Delaunay

    rng = np.random.default_rng(seed)
    pts = [np.zeros((1, 2))]
    for k in range(1, rings + 1):
        m = max(6, round(2 * math.pi * k))
        phi = rng.uniform(0, 2 * math.pi) + np.arange(m) * 2 * math.pi / m
        pts.append(k / rings * np.stack([np.cos(phi), np.sin(phi)], 1))
    p = np.concatenate(pts)
    tri = Delaunay(p).simplices  # triangulated on the disc, then mapped radially onto the flower
    phi = np.arctan2(p[:, 1], p[:, 0])
    p = p * (radius * (1.0 + amplitude * np.cos(lobes * (phi - phase))))[:, None]
    return np.column_stack([p[:, 0], np.zeros(len(p)), p[:, 1]]), tri


def polygon_area(p):
    from scipy.spatial import ConvexHull

    return ConvexHull(p[:, [0, 2]]).volume


def test_flat_disc_has_drape_coefficient_one():
    from warpcloth.run.drape import cusick_drape

    v, t = ring_disc(0.15)
    r = cusick_drape(v, t)
    assert r.coefficient == pytest.approx(1.0, abs=0.01)
    assert r.projected_area == pytest.approx(polygon_area(v), rel=1e-3)  # the raster against the exact polygon
    assert r.nodes == 0
    unit, tu = ring_disc(1.0)  # a unit disc on a 0.6 pedestal, lifted and with y up
    unit[:, 1] += 2.0
    assert cusick_drape(unit, tu, specimen_radius=1.0, pedestal_radius=0.6).coefficient == pytest.approx(1.0, abs=0.01)


def test_disc_of_the_pedestal_size_has_drape_coefficient_zero():
    from warpcloth.run.drape import cusick_drape

    v, t = ring_disc(0.09)
    assert cusick_drape(v, t).coefficient == pytest.approx(0.0, abs=0.01)


@pytest.mark.parametrize("lobes", [7, 5])
def test_node_count_of_a_lobed_outline(lobes):
    from warpcloth.run.drape import cusick_drape, drape_coefficient

    v, t = ring_disc(0.12, lobes=lobes, amplitude=0.15, phase=0.3)
    r = cusick_drape(v, t)
    assert r.nodes == lobes
    exact = math.pi * 0.12**2 * (1 + 0.15**2 / 2)  # the flower's area, sampled by the rings' polygons
    assert r.projected_area == pytest.approx(exact, rel=0.01)
    assert r.coefficient == pytest.approx(drape_coefficient(exact), abs=0.02)
    assert np.argmax(r.radius) * 0.5 % (360 / lobes) == pytest.approx(math.degrees(0.3) % (360 / lobes), abs=2.0)


def test_projected_area_of_a_tilted_square_and_errors():
    from warpcloth.run.drape import projected_area

    v = np.array([[0, 0, 0], [0.1, 0.05, 0], [0.1, 0.05, 0.1], [0, 0, 0.1]], dtype=float)  # tilted about z
    assert projected_area(v, [[0, 1, 2], [0, 2, 3]], pixel=1e-4) == pytest.approx(0.01, rel=5e-3)
    with pytest.raises(WarpclothError, match="triangle indices must be in 0..3"):
        projected_area(v, [[0, 1, 4]])
    with pytest.raises(WarpclothError, match="up must be"):
        projected_area(v, [[0, 1, 2]], up="w")
