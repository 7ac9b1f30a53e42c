"""The Provot grid: spring counts (seed eq. 2.2), topology, masses, pins, forces vs NumPy."""

import numpy as np
import pytest
import warp as wp
from helpers import reference_forces, spring_params

from warpcloth import SpringType, WarpclothError, build_grid_cloth, expected_spring_counts
from warpcloth.integrators.forces import eval_forces
from warpcloth.sim.control import Control
from warpcloth.sim.grid import grid_springs


def eq_2_2(m, n):
    """Seed eq. 2.2, written out independently of the library."""
    return (
        2 * (m - 1) * (n - 1) + (m - 1) + (n - 1),
        2 * (m - 1) * (n - 1),
        2 * (m - 2) * (n - 2) + 2 * ((m - 2) + (n - 2)),
    )


@pytest.mark.parametrize("rows,cols", [(3, 3), (4, 7), (10, 5), (50, 50)])
def test_spring_counts_match_seed_eq_2_2(rows, cols):
    model = build_grid_cloth(rows, cols)
    counts = model.spring_counts()
    assert (counts["structural"], counts["shear"], counts["bend"]) == eq_2_2(rows, cols)
    assert counts == expected_spring_counts(rows, cols)


def test_fifty_by_fifty_has_14502_springs():
    model = build_grid_cloth(50, 50)
    assert model.spring_counts() == {"structural": 4900, "shear": 4802, "bend": 4800}
    assert model.spring_count == 14502


def test_choi_ko_adds_diagonal_bend_springs():
    m, n = 6, 9
    model = build_grid_cloth(m, n, bend="choi_ko")
    assert model.spring_counts()["bend"] == eq_2_2(m, n)[2] + 2 * (m - 2) * (n - 2)
    pairs, types = grid_springs(m, n, "choi_ko")
    bend = pairs[types == SpringType.BEND]
    # every Choi-Ko diagonal bend joins [r,c]-[r+2,c+/-2]
    r0, c0 = np.divmod(bend[:, 0], n)
    r1, c1 = np.divmod(bend[:, 1], n)
    dr, dc = np.abs(r1 - r0), np.abs(c1 - c0)
    assert set(zip(dr.tolist(), dc.tolist())) == {(2, 0), (0, 2), (2, 2)}


def test_springs_are_unique_and_join_the_right_neighbours():
    rows, cols = 5, 6
    pairs, types = grid_springs(rows, cols)
    keys = {tuple(sorted(p)) for p in pairs.tolist()}
    assert len(keys) == len(pairs)
    r0, c0 = np.divmod(pairs[:, 0], cols)
    r1, c1 = np.divmod(pairs[:, 1], cols)
    offsets = {SpringType.STRUCTURAL: {(1, 0), (0, 1)}, SpringType.SHEAR: {(1, 1)}, SpringType.BEND: {(2, 0), (0, 2)}}
    for t, allowed in offsets.items():
        sel = types == t
        got = set(zip(np.abs(r1 - r0)[sel].tolist(), np.abs(c1 - c0)[sel].tolist()))
        assert got == allowed


def test_rest_lengths_triangles_mass_and_pins():
    rows, cols, w, h, mass = 4, 5, 2.0, 1.5, 0.6
    model = build_grid_cloth(rows, cols, w, h, mass, pins=[0, cols - 1])
    rest = model.spring_rest_length.numpy()
    types = model.spring_type
    dx, dy = w / (cols - 1), h / (rows - 1)
    structural = rest[types == SpringType.STRUCTURAL]
    assert np.allclose(np.unique(np.round(structural, 6)), sorted([dx, dy]))
    assert np.allclose(rest[types == SpringType.SHEAR], np.hypot(dx, dy))
    assert model.tri_count == 2 * (rows - 1) * (cols - 1)
    tris = model.tri_indices.numpy()
    assert np.all(np.sort(np.unique(tris)) == np.arange(rows * cols))
    m = model.particle_mass.numpy()
    assert np.allclose(m, mass / (rows * cols)) and np.isclose(m.sum(), mass, rtol=1e-6)
    inv = model.particle_inv_mass.numpy()
    assert inv[0] == 0.0 and inv[cols - 1] == 0.0
    assert np.count_nonzero(inv == 0.0) == 2


def test_internal_spring_forces_sum_to_zero():
    rng = np.random.default_rng(3)
    model = build_grid_cloth(9, 11, spring_params=spring_params(800.0, 2.0))
    x = model.particle_q.numpy() + rng.normal(scale=0.02, size=(model.particle_count, 3)).astype(np.float32)
    v = rng.normal(scale=0.5, size=(model.particle_count, 3)).astype(np.float32)
    f = wp.zeros(model.particle_count, dtype=wp.vec3)
    control = Control(gravity=(0.0, 0.0, 0.0))
    eval_forces(model, wp.array(x, dtype=wp.vec3), wp.array(v, dtype=wp.vec3), control, f)
    fn = f.numpy().astype(np.float64)
    scale = np.abs(fn).max()
    assert scale > 1.0  # the springs really pull
    assert np.abs(fn.sum(axis=0)).max() < 1e-5 * scale * np.sqrt(model.spring_count)


def test_force_kernel_matches_numpy_reference():
    rng = np.random.default_rng(7)
    model = build_grid_cloth(6, 7, spring_params=spring_params(500.0, 1.5))
    x = model.particle_q.numpy() + rng.normal(scale=0.01, size=(model.particle_count, 3)).astype(np.float32)
    v = rng.normal(scale=0.3, size=(model.particle_count, 3)).astype(np.float32)
    f = wp.zeros(model.particle_count, dtype=wp.vec3)
    control = Control(drag_rate=0.7)
    eval_forces(model, wp.array(x, dtype=wp.vec3), wp.array(v, dtype=wp.vec3), control, f)
    ref = reference_forces(model, x, v, drag=0.7)
    assert np.allclose(f.numpy(), ref, rtol=1e-4, atol=1e-4 * np.abs(ref).max())


def test_wind_force_on_a_flat_triangle_pair():
    """f = c_w A (n . W) n summed over the cloth: a 1 m x 1 m sheet facing +z in wind (0, 0, 3)."""
    from warpcloth.sim.control import WindSchedule

    model = build_grid_cloth(3, 3, 1.0, 1.0, 0.9, spring_params=spring_params(0.0), plane="vertical")
    control = Control(
        gravity=(0.0, 0.0, 0.0), wind_coefficient=0.5, wind_schedule=WindSchedule.constant((0.0, 0.0, 3.0))
    )
    control.update()
    f = wp.zeros(model.particle_count, dtype=wp.vec3)
    state = model.state()
    eval_forces(model, state.particle_q, state.particle_qd, control, f)
    total = f.numpy().sum(axis=0)
    assert np.allclose(total, [0.0, 0.0, 0.5 * 1.0 * 3.0], atol=1e-5)


def test_wind_schedule_gusts_switch_on_and_off():
    from warpcloth.sim.control import WindSchedule

    s = WindSchedule.gusts((5.0, 0.0, 1.0), on=1.0, off=0.5, base=(1.0, 0.0, 0.0))
    assert np.allclose(s(0.2), [5, 0, 1]) and np.allclose(s(1.2), [1, 0, 0]) and np.allclose(s(1.6), [5, 0, 1])
    control = Control(wind_coefficient=1.0, wind_schedule=s)
    for t, expected in [(0.2, s(0.2)), (1.2, s(1.2)), (3.1, s(3.1))]:
        control.set_time(t)
        assert np.allclose(control.wind.numpy()[0], expected)


@pytest.mark.parametrize(
    "kwargs,match",
    [
        (dict(rows=2, cols=5), "rows must be an integer >= 3"),
        (dict(rows=5, cols=0), "cols must be an integer >= 3"),
        (dict(rows=2, cols=2, bend="none", total_mass=-1.0), "mass must be > 0"),
        (dict(rows=4, cols=4, width=0.0), "width must be > 0"),
        (dict(rows=4, cols=4, pins=[99]), "pin index 99 is out of range"),
        (dict(rows=4, cols=4, bend="twisty"), "bend must be one of"),
        (dict(rows=4, cols=4, spring_params=spring_params(-3.0)), "stiffness must be >= 0"),
    ],
)
def test_bad_model_input_names_the_value(kwargs, match):
    with pytest.raises(WarpclothError, match=match):
        build_grid_cloth(**kwargs)


def test_two_by_two_is_allowed_without_bend_springs():
    model = build_grid_cloth(2, 2, bend="none")
    assert model.spring_counts() == {"structural": 4, "shear": 2, "bend": 0}


def test_with_spring_params_returns_a_new_model_and_a_simulator_rebinds():
    # the model is immutable: new parameters give a new model; a Simulator continues on it
    from helpers import single_spring, spring_params

    from warpcloth import Control, Simulator

    model = single_spring(ks=40.0, mass=0.1)
    stiffer = model.with_spring_params(spring_params(160.0))
    assert stiffer is not model and float(model.spring_stiffness.numpy()[0]) == 40.0
    assert float(stiffer.spring_stiffness.numpy()[0]) == 160.0 and stiffer.spring_indices is model.spring_indices
    for integrator in ("explicit_euler", "implicit_euler"):
        sim = Simulator(model, integrator, Control(drag_rate=20.0, device="cpu"), dt=1e-3)
        sim.simulate(2000)
        assert -float(sim.state.particle_q.numpy()[1, 1]) - 0.5 == pytest.approx(0.1 * 9.81 / 40.0, rel=1e-3)
        sim.set_model(stiffer)
        assert sim.integrator.model is stiffer
        sim.simulate(2000)
        assert -float(sim.state.particle_q.numpy()[1, 1]) - 0.5 == pytest.approx(0.1 * 9.81 / 160.0, rel=1e-3)
