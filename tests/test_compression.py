"""The compression factor phi (a material's, docs/materials.md): a spring shorter than its rest length
acts with phi ks, in every integrator's spring terms; phi = 1 is the model of before."""

import numpy as np
import pytest
import warp as wp
from test_pbd import project_once

from warpcloth.errors import WarpclothError
from warpcloth.integrators import Integrator, integrator_class, integrator_names, make_integrator
from warpcloth.kernels import forces as fk
from warpcloth.kernels import system as sk
from warpcloth.sim.control import Control
from warpcloth.sim.model import build_model
from warpcloth.simulator import Simulator

L, KS, MASS, G = 0.1, 100.0, 0.01, 9.81


def one_spring_force(xj, phi, rest=1.0, ks=KS):
    with wp.ScopedDevice("cpu"):
        x = wp.array(np.array([[0.0, 0.0, 0.0], xj], dtype=np.float32), dtype=wp.vec3)
        v = wp.zeros(2, dtype=wp.vec3)
        f = wp.zeros(2, dtype=wp.vec3)
        one = [wp.array([[0, 1]], dtype=wp.vec2i), wp.array([rest], dtype=float), wp.array([ks], dtype=float)]
        wp.launch(fk.eval_springs, 1, [x, v, *one, wp.array([0.0], dtype=float), wp.array([phi], dtype=float), f])
        K, B = wp.zeros(1, dtype=wp.mat33), wp.zeros(1, dtype=wp.mat33)
        args = [x, *one, wp.array([0.0], dtype=float), wp.array([phi], dtype=float), 1.0]
        wp.launch(sk.eval_spring_jacobians, 1, args, [K, B])
        return f.numpy()[0].astype(np.float64), K.numpy()[0].astype(np.float64)


def test_spring_force_and_jacobian_take_phi_in_compression_only():
    # compressed by 0.2: f_0 = phi ks (L - L0) n = 0.25 * 100 * (-0.2) (+x); K = phi ks n n^T
    f, K = one_spring_force([0.8, 0.0, 0.0], 0.25)
    np.testing.assert_allclose(f, [-5.0, 0.0, 0.0], rtol=1e-6)
    np.testing.assert_allclose(K, np.diag([25.0, 0.0, 0.0]), rtol=1e-6, atol=1e-6)
    # stretched by 0.2: phi plays no role, K has the geometric term ks (1 - L0 / L) = 100 / 6 across
    f, K = one_spring_force([1.2, 0.0, 0.0], 0.25)
    np.testing.assert_allclose(f, [20.0, 0.0, 0.0], rtol=1e-6)
    np.testing.assert_allclose(K, np.diag([100.0, 100.0 / 6.0, 100.0 / 6.0]), rtol=1e-5)


def line_of_two_springs(name: str, phi: float) -> Simulator:
    """A free particle between two pinned ones on the x axis, gravity along -x: the left spring is
    compressed and the right one stretched by delta = m g / (ks (1 + phi)) at rest."""
    q = np.array([[0.0, 0.0, 0.0], [L, 0.0, 0.0], [2 * L, 0.0, 0.0]])
    model = build_model(
        q,
        [[0, 1], [1, 2]],
        [0, 0],
        [MASS] * 3,
        pins=[0, 2],
        spring_stiffness=[KS, KS],
        spring_damping=[0.0, 0.0],
        spring_compression=[phi, phi],
        device="cpu",
    )
    return Simulator(model, make_integrator(name), Control(gravity=(-G, 0.0, 0.0), drag_rate=20.0, device="cpu"))


#: The schemes whose spring stiffness is in N/m: those that keep the base class's m g / k rest extension
#: (pbd's k has no unit, and its rest_extension says so).
NEWTON_SPRINGS = [n for n in integrator_names() if integrator_class(n).rest_extension is Integrator.rest_extension]


@pytest.mark.parametrize("name", NEWTON_SPRINGS)
def test_every_integrator_rests_where_the_compressed_spring_is_softer(name):
    sim = line_of_two_springs(name, 0.25)
    sim.simulate(int(round(2.0 / sim.dt)))
    delta = L - float(sim.state.particle_q.numpy()[1, 0])
    want = MASS * G / (KS * 1.25)  # phi = 1 would give m g / (2 ks), 37.5 % less
    assert delta == pytest.approx(want, rel=2e-4)


def test_pbd_projection_scales_a_compressed_constraint_by_phi():
    stretched = project_once([[0.0, 0, 0], [1.2, 0, 0]], [1.0, 1.0], 1.0, phi=0.25)
    compressed = project_once([[0.0, 0, 0], [0.8, 0, 0]], [1.0, 1.0], 1.0, phi=0.25)
    np.testing.assert_allclose(stretched[1] - stretched[0], [1.0, 0, 0], atol=1e-6)  # k = 1: fully projected
    np.testing.assert_allclose(compressed[1] - compressed[0], [0.85, 0, 0], atol=1e-6)  # 0.8 + 0.25 * 0.2


def test_build_model_checks_the_compression_factors():
    q = [[0.0, 0, 0], [1.0, 0, 0]]
    common = dict(spring_stiffness=[1.0], spring_damping=[0.0], device="cpu")
    with pytest.raises(WarpclothError, match=r"spring_compression of spring 0 must be in \[0, 1\], got 1.5"):
        build_model(q, [[0, 1]], [0], [1.0, 1.0], spring_compression=[1.5], **common)
    with pytest.raises(WarpclothError, match="spring_compression of spring 0 must be a finite number"):
        build_model(q, [[0, 1]], [0], [1.0, 1.0], spring_compression=[float("nan")], **common)
    model = build_model(q, [[0, 1]], [0], [1.0, 1.0], **common)
    assert model.spring_compression.numpy().tolist() == [1.0] and not model.has_compression


def test_the_float64_reference_refuses_a_compression_factor():
    from warpcloth.lab.reference import Float64Model

    q = [[0.0, 0, 0], [1.0, 0, 0]]
    common = dict(spring_stiffness=[1.0], spring_damping=[0.0], device="cpu")
    with pytest.raises(WarpclothError, match="cannot judge a model with a compression factor below 1"):
        Float64Model.from_model(build_model(q, [[0, 1]], [0], [1.0, 1.0], spring_compression=[0.5], **common))
    Float64Model.from_model(build_model(q, [[0, 1]], [0], [1.0, 1.0], **common))  # phi = 1: as before
