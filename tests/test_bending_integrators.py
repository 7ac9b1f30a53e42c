"""Dihedral bending (``bend="dihedral"``) in every integrator: the model, the implicit system against a
dense float64 backward Euler, the explicit default dt, a flat cloth falling flat, and the cantilever
strip against the inextensible elastica (warpcloth/sim/elastica.py)."""

from __future__ import annotations

import numpy as np
import pytest
from test_contract import simulate_frames
from test_implicit import dense_system

from warpcloth import Control, Simulator
from warpcloth.errors import WarpclothError
from warpcloth.integrators import integrator_names, make_integrator
from warpcloth.lab.cantilever import (
    COTTON_DENSITY,
    COTTON_RIGIDITY,
    cantilever_strip,
    elastica_tip_drop,
    strip_tip_drop,
)
from warpcloth.scenarios import flag, sheet
from warpcloth.sim.grid import build_grid_cloth, expected_spring_counts
from warpcloth.sim.hinges import DEFAULT_BEND_RIGIDITY, grid_hinge_indices, hinge_angle_gradients
from warpcloth.sim.material import PRESETS
from warpcloth.sim.mesh import build_mesh_cloth
from warpcloth.sim.model import BendModel
from warpcloth.simulator import graph_capture_supported

NAMES = integrator_names()


# -- the model -------------------------------------------------------------------------------------
def test_dihedral_grid_has_hinges_and_no_bend_springs():
    rows, cols = 6, 7
    model = build_grid_cloth(rows, cols, bend="dihedral", bend_rigidity=2e-4, device="cpu")
    assert model.bend == BendModel.DIHEDRAL
    assert (
        model.spring_counts()
        == expected_spring_counts(rows, cols, "dihedral")
        == {**expected_spring_counts(rows, cols, "none")}
    )
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
    model = build_mesh_cloth(
        grid_positions(rows, cols, 1.0, 1.0),
        grid_triangles(rows, cols),
        bend="dihedral",
        bend_rigidity=1e-4,
        device="cpu",
    )
    interior = 3 * (rows - 1) * (cols - 1) - (rows - 1) - (cols - 1)  # edges of the triangulated grid not on its border
    assert model.hinge_count == interior and model.spring_counts()["bend"] == 0
    assert model.bend == BendModel.DIHEDRAL


def test_float64_reference_refuses_hinges():
    from warpcloth.lab.reference import Float64Model

    with pytest.raises(WarpclothError, match="no dihedral bending"):
        Float64Model.from_model(build_grid_cloth(4, 4, bend="dihedral", device="cpu"))


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
    c = hinge_rest_coefficients(model.host.q, hinges.indices)
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
                dfdx[3 * q[a] : 3 * q[a] + 3, 3 * q[bb] : 3 * q[bb] + 3] -= k[e] * blk
                dfdv[3 * q[a] : 3 * q[a] + 3, 3 * q[bb] : 3 * q[bb] + 3] -= kd[e] * blk
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
    sim = sheet.build(
        rows=5,
        cols=6,
        integrator="implicit_euler",
        bend="dihedral",
        bend_rigidity=0.2,
        device="cpu",
        integrator_options={"matrix": matrix, "jacobian": jacobian, "cg_tol": 1e-6, "strain_cap": 0.0},  # bare scheme
    )
    m = sim.model
    x = m.host.q.astype(np.float64) + rng.normal(scale=0.03, size=(m.particle_count, 3))
    v = rng.normal(scale=0.5, size=(m.particle_count, 3))
    x[m.pinned], v[m.pinned] = m.host.q[m.pinned], 0.0
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


# -- the explicit schemes' default dt ---------------------------------------------------------------
@pytest.mark.parametrize("size", [16, 32])
@pytest.mark.parametrize("name", ["explicit_euler", "midpoint", "rk4", "verlet"])
def test_default_dt_is_stable_with_stiff_hinges(name, size):
    """B = 2 N m on the 1 m sheet puts the hinges' limit (dt ~ h^2 sqrt(rho / B) / 4) below the
    springs' at 32^2: the default dt must take the hinges' Gershgorin rows into account (without them
    the default dt is 2-3x too large and the sheet blows up within 200 steps)."""
    sim = sheet.build(rows=size, cols=size, bend="dihedral", bend_rigidity=2.0, integrator=name, device="cpu")
    springs_only = sheet.build(rows=size, cols=size, bend="none", integrator=name, device="cpu")
    assert sim.dt < springs_only.dt
    x0 = sim.state.particle_q.numpy().copy()
    sim.control.wind_coefficient = 0.0
    sim.simulate(300)
    x = sim.state.particle_q.numpy()
    assert np.all(np.isfinite(x)) and np.abs(x - x0).max() < 0.5
    assert np.abs(sim.state.particle_qd.numpy()).max() < 5.0


# -- rigid motion -----------------------------------------------------------------------------------
@pytest.mark.parametrize("name", NAMES)  # (vbd fell 74 % of it before its rigid translation correction, issue 26)
def test_flat_cloth_falling_under_gravity_stays_flat(name):
    """A free, tilted flat cloth with stiff hinges (B = 0.05 N m) falls as a rigid body: its hinges
    stay at their rest angle (no spurious bending moment from a translation) and it falls g t^2 / 2
    to the scheme's accuracy (a cloth that never moved fails)."""
    model = build_grid_cloth(
        6,
        6,
        0.5,
        0.5,
        0.1,
        origin=(0.0, 2.0, 0.0),
        plane="horizontal",
        bend="dihedral",
        bend_rigidity=0.05,
        device="cpu",
    )
    q = model.host.q.astype(np.float64)
    c, s = np.cos(0.5), np.sin(0.5)  # tilt the plane by 0.5 rad about x
    q[:, 1], q[:, 2] = 2.0 + s * (q[:, 2] - 0.25), c * (q[:, 2] - 0.25)
    options = {"iterations": 4} if name in ("pbd", "xpbd") else {}  # (fewer launches: a faster test)
    sim = Simulator(model, make_integrator(name, **options), Control(device="cpu"))
    sim.set_dt(min(sim.dt, 1.0 / 60.0))
    sim.state.particle_q.assign(q.astype(np.float32))
    steps = int(np.ceil(0.4 / sim.dt))  # >= 24: a first-order scheme's (n + 1) / n stays within 5 %
    simulate_frames(sim, steps)
    x = sim.state.particle_q.numpy().astype(np.float64)
    t = steps * sim.dt
    fall = (q[:, 1] - x[:, 1]).mean()
    assert abs(fall / (0.5 * 9.81 * t * t) - 1.0) < 0.05, f"{name}: fell {fall:.4f} m in {t:.3f} s"
    theta = hinge_angle_gradients(x, model.host.hinges.indices)[0]
    assert np.abs(theta).max() < 1e-4, f"{name}: a hinge bent to {np.abs(theta).max():.2g} rad"
    np.testing.assert_allclose(x - x.mean(axis=0), q - q.mean(axis=0), atol=1e-4)


# -- the cantilever strip against the elastica ------------------------------------------------------
#: Cotton (warpcloth.sim.material PRESETS); the strip: 2 x COLS particles, OVERHANG [m] from the clamp to the tip.
RHO, RIGIDITY = COTTON_DENSITY, COTTON_RIGIDITY
COLS, OVERHANG = 32, 0.05


def cantilever(name: str, options=None, dt=None, rigidity: float = RIGIDITY, drag=None):
    """The clamped cotton strip (warpcloth.lab.cantilever: the clamp midway between the two pinned
    columns, masses by vertex area, drag 2 omega_1) with integrator ``name``."""
    return cantilever_strip(
        make_integrator(name, **(options or {})), cols=COLS, overhang=OVERHANG, rigidity=rigidity, drag=drag, dt=dt
    )


def tip_drop(sim) -> float:
    return strip_tip_drop(sim)


def elastica_drop() -> float:
    return elastica_tip_drop(OVERHANG, RIGIDITY, RHO)


#: Per integrator: options, dt [s] (None: its default) and simulated time [s] to rest. lambda =
#: rho g L^3 / B = 8.6 (the chord 44 deg below the horizontal, near ASTM D1388's 41.5): a large deflection.
CANTILEVER = {
    "explicit_euler": ({}, None, 0.45),
    "verlet": ({}, None, 0.45),
    "midpoint": ({}, None, 0.45),
    "rk4": ({}, None, 0.45),
    "implicit_euler": ({"preconditioner": "block_jacobi"}, 1.0 / 60.0, 0.67),
    # vbd's vertex Newton steps stall where a hinge's stiffness k |g|^2 dwarfs m / h^2 (at dt = 1/60 the strip is
    # still 94 % short of its drop after 1 s): a step with h omega_e ~ 2 (omega_e a hinge's own frequency)
    "vbd": ({"vbd_iterations": 4}, 1.0 / 4800.0, 0.5),
    # projective's constant matrix carries the membrane springs' isotropic h^2 L across the strip too, where the flat
    # strip has no membrane stiffness: an iteration moves the soft bending mode by a tiny fraction (dt 1/60, 10 x 10:
    # -42 % after 1 s); at dt 1/2400 the inertia dominates and 2 x 10 iterations converge
    "projective": ({"pd_iterations": 2, "pd_cg_iterations": 10}, 1.0 / 2400.0, 0.7),
    # xpbd's rest shape depends on its substep h (an unconverged solve is softer: +21, +8.8, +2.8, +1.35 %
    # at 10, 20, 40, 60 substeps of dt = 1/600, ~ (h omega_e)^2, omega_e a hinge's own frequency; +67 % at its
    # defaults): "enough" substeps converge to the elastica
    "xpbd": ({"substeps": 60, "iterations": 1}, 1.0 / 600.0, 0.45),
}


@pytest.mark.parametrize("name", list(CANTILEVER))
def test_cantilever_strip_rests_at_the_elastica(name):
    """The tip drop at rest within 2 % of the inextensible elastica's (warpcloth/sim/elastica.py) with
    32 particles along the strip. Without hinges the strip hangs (drop ~ the overhang); a rigidity 10 %
    off moves the drop by 4 % (half: +22 %, twice: -32 %)."""
    options, dt, duration = CANTILEVER[name]
    sim = cantilever(name, options, dt)
    sim.simulate(int(round(duration / sim.dt)))
    drop, want = tip_drop(sim), elastica_drop()
    assert abs(drop / want - 1.0) < 0.02, f"{name}: tip drop {drop * 1e3:.3f} mm, elastica {want * 1e3:.3f} mm"
    assert np.abs(sim.state.particle_qd.numpy()).max() < 2e-3  # at rest (the tip fell ~33 mm)


def test_xpbd_converges_to_the_elastica_as_its_substep_shrinks():
    """The same strip at 10 substeps of dt = 1/600 s rests far softer than at 60 (the cantilever test):
    xpbd's static answer depends on its substep, and the error shrinks about as h^2."""
    sim = cantilever("xpbd", {"substeps": 10, "iterations": 1}, 1.0 / 600.0)
    sim.simulate(int(round(0.3 / sim.dt)))
    assert 0.1 < tip_drop(sim) / elastica_drop() - 1.0 < 0.4


# -- pbd: a dimensionless stiffness ---------------------------------------------------------------
def test_pbd_rest_shape_ignores_the_rigidity_and_stiffens_with_iterations():
    """pbd projects C = theta - theta0 with its dimensionless pbd_bend_stiffness: the strip's motion is
    bit-identical at 10x the rigidity, and more iterations make it stiffer (an unconverged Gauss-Seidel
    sweep along a 30-hinge chain is soft: after 0.2 s +55 % off the elastica's drop at 5 iterations, +39 % at 20)."""

    def strip(options, rigidity=RIGIDITY):
        return cantilever("pbd", options, rigidity=rigidity, drag=34.0)  # the same drag for both rigidities

    a, b = strip({}), strip({}, rigidity=10 * RIGIDITY)
    a.simulate(3)
    b.simulate(3)
    np.testing.assert_array_equal(a.state.particle_q.numpy(), b.state.particle_q.numpy())
    drops = []
    for iterations in (5, 20):
        sim = strip({"iterations": iterations})
        sim.simulate(12)
        drops.append(tip_drop(sim) / elastica_drop())
    assert drops[1] < drops[0] - 0.1, drops


def test_pbd_hinges_flatten_a_bent_strip():
    """Without a load, a short bent strip (2 x 6, clamped, 0.1 rad per hinge) is flattened: the hinge
    constraints are satisfied at rest."""
    cols = 6
    pins = [r * cols + c for r in range(2) for c in (0, 1)]
    model = build_grid_cloth(2, cols, 0.5, 0.1, 0.12, plane="horizontal", pins=pins, bend="dihedral", device="cpu")
    sim = Simulator(model, make_integrator("pbd"), Control(gravity=(0.0, 0.0, 0.0), device="cpu"))
    q = model.host.q.astype(np.float64)
    s = q[:, 0] - q[1, 0]
    bent = s > 0
    q[bent, 0] = q[1, 0] + np.sin(s[bent])  # an arc of curvature 1 / m: 0.1 rad per 0.1 m cell
    q[bent, 1] = q[1, 1] - (1.0 - np.cos(s[bent]))
    sim.state.particle_q.assign(q.astype(np.float32))
    before = np.abs(hinge_angle_gradients(q, model.host.hinges.indices)[0]).max()
    sim.simulate(30)
    after = np.abs(hinge_angle_gradients(sim.state.particle_q.numpy(), model.host.hinges.indices)[0]).max()
    assert before > 0.09 and after < 1e-5, (before, after)


# -- the integrator contract with hinges (tests/test_contract.py's, on the dihedral flag) ------------------
def dihedral_flag(name, **overrides):
    """The 6 x 8 flag with stiff hinges (B = 1e-3 N m: they shape its motion) instead of bend springs."""
    return flag.build(rows=6, cols=8, integrator=name, bend="dihedral", bend_rigidity=1e-3, device="cpu", **overrides)


@pytest.mark.parametrize("name", NAMES)
def test_pins_do_not_move_by_one_bit_with_hinges(name):
    sim = dihedral_flag(name)
    pins = sim.model.pinned
    before = sim.state.particle_q.numpy()[pins].copy()
    simulate_frames(sim, 20)
    after = sim.state.particle_q.numpy()
    assert np.all(np.isfinite(after))
    assert np.array_equal(after[pins], before)
    assert np.array_equal(sim.state.particle_qd.numpy()[pins], np.zeros((len(pins), 3), np.float32))
    assert np.abs(np.delete(after, pins, axis=0) - np.delete(sim.model.particle_q.numpy(), pins, axis=0)).max() > 1e-3


@pytest.mark.parametrize("name", NAMES)
def test_rest_stays_at_rest_with_hinges(name):
    """The flat flag at its rest shape, without gravity or wind, does not move: every scheme keeps it to
    the bit (measured: 0 m and 0 m/s after 30 steps); the bounds allow one float32 ulp at 1 m. A rest angle
    1e-3 rad off moves it 3.4e-7-1.4e-3 m at 1.4e-5-3.4e-4 m/s (midpoint the least, pbd's speed the
    least), which the old bounds of 1e-5 m and 1e-4 m/s let through for the explicit schemes and projective."""
    sim = dihedral_flag(name)
    sim.control.gravity = (0.0, 0.0, 0.0)
    sim.control.wind_coefficient = 0.0
    x0 = sim.state.particle_q.numpy().copy()
    simulate_frames(sim, 30)
    assert np.abs(sim.state.particle_q.numpy() - x0).max() < 1e-7
    assert np.abs(sim.state.particle_qd.numpy()).max() < 1e-6


@pytest.mark.parametrize("name", NAMES)
def test_graph_replay_is_bit_identical_with_hinges(name):
    if not graph_capture_supported("cpu"):
        pytest.skip("no CPU capture")
    a, b = dihedral_flag(name), dihedral_flag(name)
    if not b.integrator.capturable_on("cpu"):
        pytest.skip(f"{name} is not capturable on the CPU")
    a.use_graph, b.use_graph = False, True
    for n in (4, 2, 4):  # a captured count, a second one, the first replayed
        a.simulate(n)
        b.simulate(n)
    assert np.array_equal(a.state.particle_q.numpy(), b.state.particle_q.numpy())
    assert np.array_equal(a.state.particle_qd.numpy(), b.state.particle_qd.numpy())
    assert np.abs(a.state.particle_q.numpy() - a.model.particle_q.numpy()).max() > 1e-4


@pytest.mark.parametrize("graph", [False, True], ids=["plain", "captured"])
@pytest.mark.parametrize("name", NAMES)
def test_step_with_hinges_allocates_no_memory(name, graph, count_allocations):
    start, stop = count_allocations
    sim = flag.build(rows=5, cols=6, integrator=name, bend="dihedral", device="cpu")
    if graph and not (graph_capture_supported("cpu") and sim.integrator.capturable_on("cpu")):
        pytest.skip("no CPU capture")
    sim.use_graph = graph
    sim.simulate(2)
    sim.simulate(3)
    sim.simulate(2)
    created = start()  # counted: replays (or launches) of the two step counts run above, 5 steps
    sim.simulate(3)
    sim.simulate(2)
    stop()
    assert created == [], f"{name} allocated {len(created)} buffers in 5 steps"
