"""Dihedral bending (``bend="dihedral"``) in every integrator: the model, the implicit system against a
dense float64 backward Euler, the explicit default dt, a flat cloth falling flat, and the cantilever
strip against the inextensible elastica (warpcloth/lab/elastica.py)."""

from __future__ import annotations

import numpy as np
import pytest

from warpcloth import Control, Simulator
from warpcloth.errors import WarpclothError
from warpcloth.integrators import integrator_names, make_integrator
from warpcloth.scenarios import sheet
from warpcloth.sim.grid import build_grid_cloth, expected_spring_counts
from warpcloth.sim.hinges import DEFAULT_BEND_RIGIDITY, grid_hinge_indices, hinge_angle_gradients
from warpcloth.sim.material import PRESETS
from warpcloth.sim.mesh import build_mesh_cloth
from warpcloth.sim.model import BendModel

from test_implicit import dense_system

NAMES = integrator_names()


# -- the model -------------------------------------------------------------------------------------
def test_dihedral_grid_has_hinges_and_no_bend_springs():
    rows, cols = 6, 7
    model = build_grid_cloth(rows, cols, bend="dihedral", bend_rigidity=2e-4, device="cpu")
    assert model.bend == BendModel.DIHEDRAL
    assert model.spring_counts() == expected_spring_counts(rows, cols, "dihedral") == {
        **expected_spring_counts(rows, cols, "none")}
    assert model.hinge_count == 2 * ((rows - 2) * (cols - 1) + (rows - 1) * (cols - 2))
    np.testing.assert_array_equal(model.host.hinges.indices, grid_hinge_indices(rows, cols)[0])
    np.testing.assert_array_equal(model.hinge_indices.numpy(), model.host.hinges.indices)
    np.testing.assert_allclose(model.host.hinges.rigidity, 2e-4)
    assert np.all(model.host.hinges.damping > 0)  # the default damping ratio
    assert build_grid_cloth(6, 7, device="cpu").hinge_count == 0


def test_default_rigidity_is_cottons():
    assert DEFAULT_BEND_RIGIDITY == PRESETS["cotton"].bend_warp == PRESETS["cotton"].bend_weft
    np.testing.assert_allclose(build_grid_cloth(4, 4, bend="dihedral", device="cpu").host.hinges.rigidity, 31.4e-6)


def test_bend_rigidity_belongs_to_the_dihedral_model():
    with pytest.raises(WarpclothError, match="dihedral model"):
        build_grid_cloth(4, 4, bend="provot", bend_rigidity=1e-4, device="cpu")
    with pytest.raises(WarpclothError, match="bend_rigidity must be >= 0"):
        build_grid_cloth(4, 4, bend="dihedral", bend_rigidity=-1.0, device="cpu")


def test_mesh_cloth_takes_dihedral_hinges_on_interior_edges():
    from warpcloth.sim.grid import grid_positions, grid_triangles

    rows, cols = 5, 6
    model = build_mesh_cloth(grid_positions(rows, cols, 1.0, 1.0), grid_triangles(rows, cols), bend="dihedral",
                             bend_rigidity=1e-4, device="cpu")
    interior = 3 * (rows - 1) * (cols - 1) - (rows - 1) - (cols - 1)  # edges of the triangulated grid not on its border
    assert model.hinge_count == interior and model.spring_counts()["bend"] == 0
    assert model.bend == BendModel.DIHEDRAL


def test_scenario_parameter_reaches_the_model():
    sim = sheet.build(rows=5, cols=5, bend="dihedral", bend_rigidity=3e-3, device="cpu")
    np.testing.assert_allclose(sim.model.host.hinges.rigidity, 3e-3)


# -- implicit Euler against a dense float64 step ----------------------------------------------------
def dense_hinge_system(model, x, v, h, drag, jacobian="full"):
    """dense_system's A and b plus the hinges' Gauss-Newton terms: f_a = -(k C + kd sum g . v) g_a,
    df_a/dx_b = -k g_a g_b^T, df_a/dv_b = -kd g_a g_b^T (approx: -k c_a c_b I, c the rest coefficients)."""
    from warpcloth.sim.hinges import hinge_rest_coefficients, wrap_angle

    A, b = dense_system(model, x, v, h, drag, jacobian)
    hinges = model.host.hinges
    theta, g, valid = hinge_angle_gradients(x, hinges.indices)
    k = hinges.stiffness.astype(np.float32).astype(np.float64)
    kd = hinges.damping.astype(np.float32).astype(np.float64)
    c = hinge_rest_coefficients(model.host["q"], hinges.indices)
    n = model.particle_count
    f = np.zeros((n, 3))
    dfdx = np.zeros((3 * n, 3 * n))
    dfdv = np.zeros((3 * n, 3 * n))
    for e, q in enumerate(hinges.indices):
        if not valid[e]:
            continue
        rate = sum(g[e, a] @ v[q[a]] for a in range(4))
        for a in range(4):
            f[q[a]] += -(k[e] * wrap_angle(theta[e] - hinges.rest_angle[e]) + kd[e] * rate) * g[e, a]
            for bb in range(4):
                blk = np.outer(g[e, a], g[e, bb]) if jacobian == "full" else c[e, a] * c[e, bb] * np.eye(3)
                dfdx[3 * q[a]:3 * q[a] + 3, 3 * q[bb]:3 * q[bb] + 3] -= k[e] * blk
                dfdv[3 * q[a]:3 * q[a] + 3, 3 * q[bb]:3 * q[bb] + 3] -= kd[e] * blk
    Ah = -h * dfdv - h * h * dfdx
    bh = h * (f.ravel() + h * dfdx @ v.ravel())
    for p in model.pinned:
        rows = slice(3 * p, 3 * p + 3)
        Ah[rows, :] = 0.0
        Ah[:, rows] = 0.0
        bh[rows] = 0.0
    return A + Ah, b + bh, Ah


@pytest.mark.parametrize("matrix", ["free", "bsr"])
@pytest.mark.parametrize("jacobian", ["full", "approx"])
def test_one_implicit_step_equals_dense_backward_euler_with_hinges(matrix, jacobian):
    """A stiff hinge set (B = 0.2 N m on a 1 m 5 x 6 sheet: h^2 k_e |g|^2 / m ~ 1) on a perturbed, moving
    sheet: one step equals the dense solve, and dropping the hinge term misses it by far more."""
    rng = np.random.default_rng(3)
    sim = sheet.build(rows=5, cols=6, integrator="implicit_euler", bend="dihedral", bend_rigidity=0.2, device="cpu",
                      integrator_options={"matrix": matrix, "jacobian": jacobian, "cg_tol": 1e-6})
    m = sim.model
    x = m.host["q"].astype(np.float64) + rng.normal(scale=0.03, size=(m.particle_count, 3))
    v = rng.normal(scale=0.5, size=(m.particle_count, 3))
    x[m.pinned], v[m.pinned] = m.host["q"][m.pinned], 0.0
    sim.state.particle_q.assign(x.astype(np.float32))
    sim.state.particle_qd.assign(v.astype(np.float32))
    x, v = sim.state.particle_q.numpy().astype(np.float64), sim.state.particle_qd.numpy().astype(np.float64)
    h = 1.0 / 60.0
    sim.set_dt(h)
    A, b, Ah = dense_hinge_system(m, x, v, h, float(sim.control.drag_rate), jacobian)
    dv = np.linalg.solve(A, b).reshape(-1, 3)
    A0, b0 = dense_system(m, x, v, h, float(sim.control.drag_rate), jacobian)
    dv0 = np.linalg.solve(A0, b0).reshape(-1, 3)
    sim.step()
    v1 = sim.state.particle_qd.numpy().astype(np.float64)
    tol = 1e-4 * np.abs(dv).max()
    np.testing.assert_allclose(v1, v + dv, atol=tol)
    assert np.abs(dv0 - dv).max() > 20 * tol  # the hinges matter here
    np.testing.assert_allclose(sim.state.particle_q.numpy(), x + h * (v + dv), atol=1e-5)
    if jacobian == "full":  # the Gauss-Newton blocks are PSD: A stays SPD
        assert np.linalg.eigvalsh(0.5 * (Ah + Ah.T)).min() > -1e-9 * np.abs(Ah).max()
    integ = sim.integrator
    if matrix == "bsr":  # Jacobi's diagonal is taken after the hinge blocks
        np.testing.assert_allclose(integ.inv_diag.numpy().ravel(), 1.0 / np.diag(A), rtol=1e-5)
