"""Projective dynamics: the global matrix, convergence to backward Euler, rest states, options."""

import numpy as np
import pytest
from helpers import backward_euler_step, small_grid

from warpcloth import Control, Simulator, WarpclothError, make_integrator


def numpy_global_matrix(model, h):
    """S = M + h D + h^2 L, dense float64, pinned rows and columns replaced by identity."""
    host = model.host
    ks = model.spring_stiffness.numpy().astype(np.float64)
    kd = model.spring_damping.numpy().astype(np.float64)
    S = np.diag(host.mass.astype(np.float64))
    for (i, j), k, c in zip(host.pairs, ks, kd):
        w = h * h * k + h * c
        S[i, i] += w
        S[j, j] += w
        S[i, j] -= w
        S[j, i] -= w
    for p in model.pinned:
        S[p, :] = 0.0
        S[:, p] = 0.0
        S[p, p] = 1.0
    return S


def test_global_matrix_matches_a_numpy_assembly_and_follows_dt():
    from warpcloth.scenarios import flag

    sim = flag.build(rows=5, cols=6, integrator="projective", dt=1.0 / 60.0)
    sim.simulate(1)
    S = sim.integrator.global_matrix().toarray()
    expected = numpy_global_matrix(sim.model, 1.0 / 60.0)
    assert np.abs(S - expected).max() < 1e-6 * np.abs(expected).max()
    assert np.abs(S - S.T).max() == 0.0
    sim.set_dt(1.0 / 120.0)
    sim.simulate(1)
    assert (
        np.abs(sim.integrator.global_matrix().toarray() - numpy_global_matrix(sim.model, 1.0 / 120.0)).max()
        < 1e-6 * np.abs(expected).max()
    )


def disturbed_grid(seed=3):
    model = small_grid(ks=40.0, kd=0.2)
    rng = np.random.default_rng(seed)
    free = model.host.inv_mass[:, None] > 0
    x0 = model.host.q.astype(np.float64) + np.where(free, rng.normal(0, 0.05, (9, 3)), 0.0)
    v0 = np.where(free, rng.normal(0, 0.5, (9, 3)), 0.0)
    return model, x0, v0


def one_step(model, x0, v0, h, **options):
    sim = Simulator(model, make_integrator("projective", **options), Control(), dt=h)
    sim.state.particle_q.assign(x0.astype(np.float32))
    sim.state.particle_qd.assign(v0.astype(np.float32))
    sim.step()
    return sim.state.particle_q.numpy().astype(np.float64)


def test_converged_step_is_backward_euler_of_the_same_energy():
    """Liu et al. 2013: local/global iterations converge to the backward-Euler step (with spring
    damping along the spring, as the force-based integrators'; S's isotropic h D is only its
    approximate Jacobian). 3 x 3 grid, disturbed: 300 iterations match the float64 solution to
    1e-6 m; 2 iterations miss it by > 1e-4 m, and the isotropic-damping answer differs by > 1e-5 m
    (so the damping model is what is tested)."""
    model, x0, v0 = disturbed_grid()
    h = 1.0 / 60.0
    expected = backward_euler_step(model, x0, v0, h, damping="axial")
    converged = one_step(model, x0, v0, h, pd_iterations=300, pd_cg_iterations=20)
    assert np.abs(converged - expected).max() < 1e-6
    assert np.abs(one_step(model, x0, v0, h, pd_iterations=2, pd_cg_iterations=20) - expected).max() > 1e-4
    assert np.abs(backward_euler_step(model, x0, v0, h, damping="isotropic") - expected).max() > 1e-5


def test_one_iteration_with_exact_cg_is_one_global_solve():
    """pd_iterations=1 with as many CG iterations as unknowns: dx = h v + S^-1 r(h v), r the
    residual of the module docstring, computed in NumPy (float64, dense solve)."""
    model, x0, v0 = disturbed_grid(seed=5)
    h = 1.0 / 60.0
    host = model.host
    pairs = host.pairs
    rest = np.linalg.norm(host.q[pairs[:, 1]].astype(np.float64) - host.q[pairs[:, 0]], axis=1)
    ks = model.spring_stiffness.numpy().astype(np.float64)
    kd = model.spring_damping.numpy().astype(np.float64)
    m = host.mass.astype(np.float64)
    free = host.inv_mass > 0
    x0 = x0.astype(np.float32).astype(np.float64)
    v0 = v0.astype(np.float32).astype(np.float64)
    dy = h * v0 + h * h * np.array([0.0, -9.81, 0.0])
    dx = h * v0
    dy[~free] = dx[~free] = 0.0
    e = (x0[pairs[:, 1]] - x0[pairs[:, 0]]) + (dx[pairs[:, 1]] - dx[pairs[:, 0]])
    length = np.linalg.norm(e, axis=1)
    n = e / length[:, None]
    axial = np.einsum("ij,ij->i", dx[pairs[:, 1]] - dx[pairs[:, 0]], n)  # damping along the spring
    force = (h * h * ks * (length - rest) / length)[:, None] * e + (h * kd * axial)[:, None] * n
    r = m[:, None] * (dy - dx)
    np.add.at(r, pairs[:, 0], force)
    np.add.at(r, pairs[:, 1], -force)
    r[~free] = 0.0
    expected = x0 + dx + np.linalg.solve(numpy_global_matrix(model, h), r)
    got = one_step(model, x0, v0, h, pd_iterations=1, pd_cg_iterations=9)
    assert np.abs(got - expected).max() < 1e-6
    assert np.abs(one_step(model, x0, v0, h, pd_iterations=1, pd_cg_iterations=1) - expected).max() > 1e-5


def test_sheet_settles_on_the_static_equilibrium():
    """16 x 16 scenario sheet, default options, dt = 1/60 s, 10 s: sag within 2 % of the float64
    equilibrium's."""
    from warpcloth.lab.reference import static_equilibrium
    from warpcloth.scenarios import sheet

    sim = sheet.build(rows=16, cols=16, integrator="projective", dt=1.0 / 60.0)
    eq = static_equilibrium(sim.model, sim.control)
    sim.simulate(600)
    y0 = sim.model.host.q[:, 1].astype(np.float64)
    sag = (y0 - sim.state.particle_q.numpy()[:, 1]).max()
    sag_ref = (y0 - eq.x[:, 1]).max()
    assert abs(sag - sag_ref) < 0.02 * sag_ref, (sag, sag_ref)


@pytest.mark.parametrize(
    "options,message",
    [
        ({"pd_iterations": 0}, "pd_iterations must be an integer >= 1"),
        ({"pd_cg_iterations": 0}, "pd_cg_iterations must be an integer >= 1"),
        ({"pd_contact_weight": 0.0}, "pd_contact_weight must be finite and > 0"),
        ({"pd_contact_weight": float("inf")}, "pd_contact_weight must be finite and > 0"),
    ],
)
def test_bad_options(options, message):
    with pytest.raises(WarpclothError, match=message):
        make_integrator("projective", **options)
