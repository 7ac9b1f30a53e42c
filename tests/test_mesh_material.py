"""A mesh cloth's material (issues 49 and 51): a flat mesh with a grid's uv has the grid cloth's
springs and masses for every preset; a mesh without uv takes its quads' own side directions (a
tube without uv is exact, as with uv); a spring the fit leaves at 0 N/m is warned about by family,
naming the mesh and the material (polyester on a coarse cone); quads whose side families cannot be
followed (a cube) warn for an anisotropic material. docs/meshes.md, "A material on a mesh"."""

from __future__ import annotations

import math

import numpy as np
import pytest

from warpcloth.scenarios.character import tube
from warpcloth.sim.grid import grid_triangles, grid_uvs
from warpcloth.sim.material import PRESETS, material, material_grid_cloth, material_mesh_cloth, mesh_spring_params
from warpcloth.sim.mesh import TriangleMesh, mesh_springs
from warpcloth.sim.model import SpringType


def by_pair(pairs, values):
    return {(min(int(a), int(b)), max(int(a), int(b))): float(v) for (a, b), v in zip(pairs, values)}


def rotation(about_x_deg, about_z_deg):
    a, b = math.radians(about_x_deg), math.radians(about_z_deg)
    rx = np.array([[1, 0, 0], [0, math.cos(a), -math.sin(a)], [0, math.sin(a), math.cos(a)]])
    rz = np.array([[math.cos(b), -math.sin(b), 0], [math.sin(b), math.cos(b), 0], [0, 0, 1]])
    return rx @ rz


def springs_of(model):
    pairs = model.spring_indices.numpy()
    return by_pair(pairs, model.spring_stiffness.numpy())


@pytest.mark.parametrize("name", list(PRESETS))
def test_flat_mesh_with_grid_uv_has_the_grid_cloths_springs_and_masses(name):
    # a 6 x 8 sheet as a triangle mesh, turned in 3-D (70 deg about x, 20 deg about z): with the grid's
    # uv, and without (its quads' sides), the model's springs and masses are the grid cloth's. (With Provot
    # bend springs a boundary face splits their membrane share between its two parallel sides where the
    # grid takes it from the spanned spring alone: the same energy, springs apart by O(k_b);
    # tests/test_material.py compares those bend springs.)
    rows, cols, w, h = 6, 8, 0.5, 0.3
    grid = material_grid_cloth(name, rows, cols, w, h, bend="none", device="cpu")
    q = grid.host.q.astype(np.float64) @ rotation(70.0, 20.0).T
    t = grid_triangles(rows, cols)
    expected, mass = springs_of(grid), grid.particle_mass.numpy()
    assert len(expected) > 0
    for uv in (grid_uvs(rows, cols), None):
        mesh = material_mesh_cloth(name, q, t, uv=uv, quads=True, bend=False, device="cpu")
        assert springs_of(mesh) == pytest.approx(expected, rel=1e-5)
        m = mesh.particle_mass.numpy()
        # vertex areas: a third of each triangle on a mesh, a quarter cell on a grid: the same except at the
        # two corners cut by a diagonal (2/3 of a quarter cell) and the two that are not (4/3); equal totals
        corners = [0, cols - 1, (rows - 1) * cols, rows * cols - 1]
        np.testing.assert_allclose(np.delete(m, corners), np.delete(mass, corners), rtol=1e-6)
        assert sorted(m[corners] / mass[corners]) == pytest.approx([2 / 3, 2 / 3, 4 / 3, 4 / 3], rel=1e-6)
        assert float(m.sum()) == pytest.approx(float(mass.sum()), rel=1e-6)


@pytest.mark.parametrize("name", list(PRESETS))
def test_cylinder_without_uv_has_the_grid_rule_of_its_rectangles(name):
    # a closed cylinder of 6 rings x 24, its axis turned 20 deg from y towards x (and tilted 30 deg about x):
    # its quads are hx (chord) x hy rectangles, so the fit is the grid rule with the warp around (the side
    # family nearer +x); the old rule (global +x projected into each face) turned the frame off the sides
    mat = material(name)
    rings, around, radius, length = 6, 24, 0.2, 0.3
    q, t, uv = tube(rings, around, radius, radius, length)
    q = q @ rotation(30.0, 20.0).T
    pairs, types = mesh_springs(q, t, quads=True, bend=False)
    hx, hy = 2.0 * radius * math.sin(math.pi / around), length / (rings - 1)
    c11, c22, g = mat.stretch_warp, mat.stretch_weft, mat.shear
    for given in (None, uv):
        r = mesh_spring_params(mat, q, t, pairs, types, uv=given)
        assert r.membrane_error < 1e-9 and r.clamped == 0
        for (a, b), ks, ty in zip(pairs, r.stiffness, types):
            if ty == SpringType.SHEAR:
                want = g * (hx * hx + hy * hy) / (2 * hx * hy)
            elif a // around == b // around:  # around a ring (warp): the end rings have one cell
                cells = 1 if a // around in (0, rings - 1) else 2
                want = cells * 0.5 * (hy / hx) * (c11 - g * hx * hx / (hy * hy))
            else:  # along the length (weft): two cells on a closed tube
                want = 2 * 0.5 * (hx / hy) * (c22 - g * hy * hy / (hx * hx))
            assert ks == pytest.approx(want, rel=1e-9)


@pytest.mark.parametrize("name", list(PRESETS))
def test_a_cone_without_uv_has_the_springs_it_has_with_uv(name, capsys):
    # the skirt's cone (16 rings x 32, waist 0.16 m, hem 0.38 m) without texture coordinates: its quads' own
    # sides, the rings as warp, give the springs of the uv (u around) to 1e-9, none at 0; the old rule
    # (+x projected into each face: along the length on the cone's sides) put 184 of 992 structural
    # springs of the 16 x 32 skirt at 0 N/m, silently, and its hem stretched 110 %
    q, t, uv = tube(16, 32, 0.16, 0.38, 0.5)
    pairs, types = mesh_springs(q, t, quads=True)
    capsys.readouterr()
    with_uv = mesh_spring_params(name, q, t, pairs, types, uv=uv)
    without = mesh_spring_params(name, q, t, pairs, types)
    np.testing.assert_allclose(without.stiffness, with_uv.stiffness, rtol=1e-9)
    assert without.clamped == 0 and without.membrane_error < 1e-9
    assert np.all(without.stiffness[types == SpringType.STRUCTURAL] > 0.1 * material(name).stretch_weft)
    assert capsys.readouterr().err == ""


def test_polyester_on_a_coarse_cone_warns_by_family_naming_mesh_and_material(capsys):
    # 8 rings x 16 around from a 0.16 m waist to a 0.38 m hem (the character's skirt at 8 x 8): each
    # quad is a trapezoid whose sides lean ~5 deg, and sides leaning by theta carry shear ~ C theta^2 >
    # polyester's G = 9.6 N/m (sqrt(G / C) = 2.8 deg): the fit needs negative diagonals, NNLS puts them
    # at 0, and the lattice is stiffer in shear than the material: said, counted, not silent
    q, t, uv = tube(8, 16, 0.16, 0.38, 0.5)
    capsys.readouterr()
    material_mesh_cloth("polyester", TriangleMesh(q, t, uv=uv, source="skirt"), quads=True, device="cpu")
    err = capsys.readouterr().err
    assert "material 'polyester' on mesh 'skirt': 224 of 224 shear springs got stiffness 0 N/m" in err
    assert "closer to squares" in err and "structural" not in err
    pairs, types = mesh_springs(q, t, quads=True)
    r = mesh_spring_params("polyester", q, t, pairs, types, uv=uv)
    shear = types == SpringType.SHEAR
    assert r.clamped == int(np.sum(r.stiffness[shear] == 0.0)) == int(shear.sum())
    assert r.membrane_error > 1.0
    capsys.readouterr()
    quiet = mesh_spring_params("polyester", q, t, pairs, types, uv=uv, warn_fit=False)  # a caller that mends them
    assert quiet.clamped == r.clamped and capsys.readouterr().err == ""
    for name in ("cotton", "silk", "denim"):  # more shear: the same cone is exact, nothing to say
        r = mesh_spring_params(name, q, t, pairs, types, uv=uv)
        assert r.clamped == 0 and r.membrane_error < 1e-9 and np.all(r.stiffness[types != SpringType.BEND] > 0)
    assert capsys.readouterr().err == ""


def test_polyester_on_a_finer_cone_keeps_its_shear(capsys):
    # 16 rings x 32 around: the sides lean 2.5 deg, below polyester's 2.8: every shear spring > 0, exact
    q, t, uv = tube(16, 32, 0.16, 0.38, 0.5)
    pairs, types = mesh_springs(q, t, quads=True)
    capsys.readouterr()
    for given in (uv, None):
        r = mesh_spring_params("polyester", q, t, pairs, types, uv=given)
        assert r.clamped == 0 and r.membrane_error < 1e-9
        assert float(np.min(r.stiffness[types == SpringType.SHEAR])) > 0.3 * PRESETS["polyester"].shear
    assert capsys.readouterr().err == ""


def test_triangles_that_cannot_carry_the_shear_warn_with_quads_as_the_fix(capsys):
    # equilateral triangles: three spring directions per triangle give an isotropic lattice with G = S / 3;
    # cotton (G = 52.4 << S / 3 = 1357 N/m) gets a lattice ~16x too stiff in shear: no spring at 0, but said
    a = 0.05
    v = np.array([[(i + 0.5 * (j % 2)) * a, j * a * math.sqrt(3) / 2, 0.0] for j in range(5) for i in range(5)])
    t = []
    for j in range(4):
        for i in range(4):
            p, q, r, s = j * 5 + i, j * 5 + i + 1, (j + 1) * 5 + i, (j + 1) * 5 + i + 1
            t += [[p, q, r], [q, s, r]] if j % 2 == 0 else [[p, q, s], [p, s, r]]
    t = np.array(t)
    pairs, types = mesh_springs(v, t, bend=False)
    capsys.readouterr()
    r = mesh_spring_params("cotton", v, t, pairs, types, name="hex")
    err = capsys.readouterr().err
    assert r.membrane_error > 10.0 and r.clamped == 0
    assert f"material 'cotton' on mesh 'hex': the lattice's energy is up to {100 * r.membrane_error:.3g} % above" in err
    assert "use quads=True" in err


def cube_surface(n):
    """The surface of a unit cube, n x n squares per side, each two triangles (a closed quad mesh
    whose 8 corners have 3 quads: the side families cannot be followed around them)."""
    index, q, tris = {}, [], []

    def vid(p):
        key = tuple(np.round(p, 9))
        if key not in index:
            index[key] = len(q)
            q.append(p)
        return index[key]

    for axis in range(3):
        for side in (0.0, 1.0):
            u_ax, v_ax = [a for a in range(3) if a != axis]
            for i in range(n):
                for j in range(n):
                    corners = []
                    for di, dj in ((0, 0), (1, 0), (1, 1), (0, 1)):
                        p = np.zeros(3)
                        p[axis], p[u_ax], p[v_ax] = side, (i + di) / n, (j + dj) / n
                        corners.append(vid(p))
                    a, b, c, d = corners
                    tris += [(a, b, c), (a, c, d)]
    return np.array(q), np.array(tris, dtype=np.int64)


def test_quads_whose_families_cannot_be_followed_warn_for_an_anisotropic_material(capsys):
    q, t = cube_surface(2)
    pairs, types = mesh_springs(q, t, quads=True, bend=False)
    assert int(np.sum(types == SpringType.SHEAR)) == 2 * 24  # every square is a quad
    capsys.readouterr()
    r = mesh_spring_params("wool", q, t, pairs, types, name="cube")  # C11 2132 != C22 1671 N/m
    err = capsys.readouterr().err
    assert "material 'wool' on mesh 'cube': without texture coordinates the warp of 24 quads" in err
    assert r.membrane_error < 1e-9  # each square is still fitted in its own frame
    iso = material("wool").replace(name="iso", stretch_weft=2132.0, bend_weft=material("wool").bend_warp)
    mesh_spring_params(iso, q, t, pairs, types, name="cube")  # warp = weft: nothing to say
    assert capsys.readouterr().err == ""
