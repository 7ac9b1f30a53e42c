"""Provot deformation constraints (seed 2.1.3.3) as a Simulator option."""

import numpy as np
import pytest
import warp as wp

from warpcloth.cli import main as cli_main
from warpcloth.errors import WarpclothError
from warpcloth.integrators.strain_limit import StrainLimiter
from warpcloth.scenarios import sheet
from warpcloth.sim.coloring import greedy_spring_colors as color_springs
from warpcloth.sim.grid import build_grid_cloth
from warpcloth.sim.model import SpringType
from warpcloth.simulator import Simulator

TAU = 0.1
TOL = 1.0e-4  # the limiter's stopping tolerance on strain (DEFAULT_TOLERANCE)
SOFT = (20.0, 20.0, 2.0)  # structural, shear, bend ks [N/m]: this sheet stretches ~40 % unlimited


def limited_strains(sim):
    m = sim.model
    q = sim.state.particle_q.numpy().astype(np.float64)
    pairs, rest = m.host.pairs, m.host.rest.astype(np.float64)
    strain = (np.linalg.norm(q[pairs[:, 1]] - q[pairs[:, 0]], axis=1) - rest) / rest
    return strain[np.isin(m.spring_type, [SpringType.STRUCTURAL, SpringType.SHEAR])]


@pytest.mark.parametrize(
    "integrator, dt, steps", [("implicit_euler", 1.0 / 60.0, 60), ("explicit_euler", None, 200), ("verlet", None, 200)]
)
def test_no_structural_or_shear_spring_ends_a_step_beyond_tau_and_pins_stay_put(integrator, dt, steps):
    bare = {"strain_cap": 0.0} if integrator == "implicit_euler" else {}  # implicit_euler's own limit off
    unlimited = sheet.build(rows=10, cols=10, integrator=integrator, dt=dt, stiffness=SOFT, integrator_options=bare)
    unlimited.simulate(steps)
    assert limited_strains(unlimited).max() > 2 * TAU  # without the limit the cloth overstretches

    sim = sheet.build(rows=10, cols=10, integrator=integrator, dt=dt, stiffness=SOFT, strain_limit=TAU)
    pins = sim.model.pinned
    q_pins = sim.state.particle_q.numpy()[pins].copy()
    worst = 0.0
    for _ in range(steps):
        sim.step()
        worst = max(worst, limited_strains(sim).max())
        np.testing.assert_array_equal(sim.state.particle_q.numpy()[pins], q_pins)  # bit-exact
    assert worst <= TAU + TOL + 2e-6  # 2e-6: float32 rounding of lengths
    assert worst > TAU - 0.01  # the limit was active
    assert np.all(np.isfinite(sim.state.particle_qd.numpy()))


def _one_spring(inv_mass, stretch):
    """A model of two particles and one structural spring of rest 1 m, and its state stretched
    to ``stretch`` m along x with some velocity."""
    from types import SimpleNamespace

    from warpcloth.sim.state import State

    q = np.array([[0.0, 2.0, 0.0], [stretch, 2.0, 0.0]], dtype=np.float32)
    model = SimpleNamespace(
        device="cpu",
        particle_count=2,
        spring_type=np.array([SpringType.STRUCTURAL]),
        pinned=np.flatnonzero(np.asarray(inv_mass) == 0.0),
        particle_inv_mass=wp.array(np.asarray(inv_mass, dtype=np.float32), dtype=float),
        host=SimpleNamespace(pairs=np.array([[0, 1]], dtype=np.int32), rest=np.array([1.0], dtype=np.float32)),
    )
    v = np.array([[0.1, 0.2, 0.3], [0.0, -0.1, 0.0]], dtype=np.float32)
    state = State(wp.array(q, dtype=wp.vec3), wp.array(v, dtype=wp.vec3), wp.zeros(2, dtype=wp.vec3))
    return model, state, q.astype(np.float64), v.astype(np.float64)


def test_one_spring_is_shortened_to_its_limit_mass_weighted_with_consistent_velocity():
    model, state, q, v = _one_spring([1.0, 3.0], 1.5)  # 50 % strain
    dt = 0.01
    StrainLimiter(model, TAU).apply(state, dt)
    q1 = state.particle_q.numpy().astype(np.float64)
    assert np.linalg.norm(q1[1] - q1[0]) == pytest.approx(1.0 + TAU, abs=1e-6)
    dx = q1 - q
    # mass-weighted: the 0.4 m correction split w0 : w1 = 1 : 3, along the spring
    np.testing.assert_allclose(dx, [[0.1, 0.0, 0.0], [-0.3, 0.0, 0.0]], atol=1e-6)
    np.testing.assert_allclose(state.particle_qd.numpy(), v + dx / dt, atol=1e-4)


def test_a_spring_within_its_limit_is_left_alone():
    model, state, q, v = _one_spring([1.0, 1.0], 1.09)
    StrainLimiter(model, TAU).apply(state, 0.01)
    np.testing.assert_array_equal(state.particle_q.numpy(), q.astype(np.float32))
    np.testing.assert_array_equal(state.particle_qd.numpy(), v.astype(np.float32))


def test_a_pinned_end_does_not_move():
    model, state, q, _v = _one_spring([0.0, 1.0], 3.0)
    StrainLimiter(model, TAU).apply(state, 0.01)
    q1 = state.particle_q.numpy()
    np.testing.assert_array_equal(q1[0], q[0].astype(np.float32))
    assert np.linalg.norm(q1[1] - q1[0]) == pytest.approx(1.0 + TAU, abs=1e-6)


def test_colours_share_no_particle():
    model = build_grid_cloth(6, 7)
    pairs = model.host.pairs
    colors = color_springs(pairs, model.particle_count)
    for c in np.unique(colors):
        ends = pairs[colors == c].ravel()
        assert len(ends) == len(np.unique(ends))
    assert colors.max() + 1 <= 2 * 12 - 1  # greedy bound 2 max_degree - 1


@pytest.mark.parametrize("tau", [0.0, -0.1, float("nan"), "x"])
def test_bad_tau_is_a_clear_error(tau):
    model = build_grid_cloth(4, 4)
    with pytest.raises(WarpclothError, match="strain limit must be"):
        Simulator(model, "explicit_euler", strain_limit=tau)
    with pytest.raises(WarpclothError, match="strain limit must be"):
        sheet.build(rows=4, cols=4, strain_limit=tau)


def test_limit_off_by_default_and_cli_flag(capsys):
    assert sheet.build(rows=4, cols=4).strain_limiter is None
    import json

    rc = cli_main(
        [
            "run",
            "sheet",
            "--rows",
            "8",
            "--cols",
            "8",
            "--stiffness",
            "20,20,2",
            "-i",
            "implicit_euler",
            "--num-frames",
            "30",
            "--strain-limit",
            "0.1",
            "--json",
        ]
    )
    assert rc == 0
    out = json.loads(capsys.readouterr().out)
    assert out["max_strain"] <= TAU + TOL + 2e-6
    assert cli_main(["run", "sheet", "--rows", "8", "--cols", "8", "--strain-limit", "0"]) == 2
    assert "strain limit must be > 0" in capsys.readouterr().err


def test_limit_applies_only_to_force_based_integrators():
    class PositionBased(type(sheet.build(rows=4, cols=4).integrator)):
        name = "position_based"
        force_based = False

    sim = sheet.build(rows=4, cols=4, strain_limit=TAU)
    with pytest.raises(WarpclothError, match="force-based"):
        sim.set_integrator(PositionBased())


def test_implicit_euler_limits_at_its_strain_cap_unless_the_user_limits_or_turns_it_off(capsys):
    """implicit_euler's own limit (``strain_cap``, 0.1 by default) acts where the user gives no
    strain_limit; the user's replaces it; 0 turns it off; the other integrators have none."""
    assert sheet.build(rows=4, cols=4, integrator="explicit_euler").active_limiter is None

    def run(**kw):
        sim = sheet.build(rows=10, cols=10, integrator="implicit_euler", dt=1.0 / 60.0, stiffness=SOFT, **kw)
        worst = 0.0
        for _ in range(60):
            sim.step()
            worst = max(worst, limited_strains(sim).max())
        return sim, worst

    sim, worst = run()
    assert sim.strain_limiter is None and sim.integrator_limiter.tau == pytest.approx(0.1)
    assert TAU - 0.01 < worst <= TAU + TOL + 2e-6  # the soft sheet would stretch ~40 %: the cap held it
    sim, worst = run(integrator_options={"strain_cap": 0.25})
    assert 0.24 < worst <= 0.25 + TOL + 2e-6
    sim, worst = run(strain_limit=0.05)
    assert sim.integrator_limiter is None and sim.active_limiter.tau == 0.05 and worst <= 0.05 + TOL + 2e-6
    sim, worst = run(integrator_options={"strain_cap": 0.0})
    assert sim.active_limiter is None and worst > 2 * TAU
    sim.set_integrator("explicit_euler", dt=1e-4)  # switching integrators drops implicit_euler's cap
    assert sim.active_limiter is None
    sim.set_integrator("implicit_euler", dt=1.0 / 60.0)  # and a fresh implicit_euler brings it back
    assert sim.active_limiter.tau == pytest.approx(0.1)
    model = sim.model.with_spring_params(sim.model.spring_params)  # a new model (the same values): rebound to it
    sim.set_model(model)
    assert sim.active_limiter.model is model
    sim.integrator.strain_cap = 0.2  # an option set between steps counts from the next one
    sim.step()
    assert sim.active_limiter.tau == pytest.approx(0.2)
    assert cli_main(["run", "sheet", "--rows", "4", "--cols", "4", "-i", "implicit_euler", "--strain-cap", "-1"]) == 2
    assert "strain_cap" in capsys.readouterr().err


def test_nearest_pin_paths_on_a_small_graph():
    """A chain 0-1-2-3 (rest 1, 2, 1; the 1-2 spring listed twice, once at 5), pins 0 and 3, and a
    particle 4 with no spring: each particle's nearest pin along the springs and the path's rest length."""
    from warpcloth.integrators.strain_limit import nearest_pin_paths

    pairs = np.array([[0, 1], [2, 1], [1, 2], [3, 2]])
    rest = np.array([1.0, 2.0, 5.0, 1.0])
    source, dist = nearest_pin_paths(pairs, rest, 5, [0, 3])
    assert source.tolist() == [0, 0, 3, 3, -1]
    assert dist[:4].tolist() == [0.0, 1.0, 1.0, 0.0] and np.isinf(dist[4])
    source, dist = nearest_pin_paths(pairs, rest, 5, [0])  # 0 -> 1 -> 2 over the duplicate's shorter rest
    assert source.tolist() == [0, 0, 0, 0, -1] and dist[:4].tolist() == [0.0, 1.0, 3.0, 4.0]
    source, dist = nearest_pin_paths(pairs, rest, 5, [])
    assert source.tolist() == [-1] * 5 and np.all(np.isinf(dist))
