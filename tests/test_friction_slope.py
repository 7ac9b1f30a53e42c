"""Coulomb friction of a cloth on a slope, every registered integrator at its default dt (issue 51: vbd
slid at 0.6 % of g (sin - mu cos) at 1/60 s, its friction-sliding contacts held out of its rigid
translation, which alone moves a stiff cloth as a whole).

The single particle of tests/test_solver_contact.py has no neighbours to hold it; a cloth's Gauss-Seidel
sweeps move each vertex with its neighbours fixed, so a scheme that slides a particle may still hold
a cloth. vbd's rigid translation now slides a contact that rested on its collider and whose own free
motion leaves the Coulomb cone, where no contact with friction is held, with its kinetic friction as
IPC's lagged smooth Coulomb friction
(:func:`warpcloth.kernels.increment.sliding_friction`, ``lagged_friction``): it slides at 1.000005 of
the rate and does not move at mu 0.7 (docs/solvers.md, "Friction on a slope").
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from test_contract import simulate_frames

from warpcloth import Control, Plane, Simulator, build_grid_cloth, make_integrator
from warpcloth.integrators import integrator_names

G = 9.81
THETA = math.radians(30.0)  # tan = 0.577
DURATION = 0.25  # [s]: vbd slid at 0.6 % of the rate, and a held cloth that creeps moves > 1e-5 m by then


def slide(name: str, mu: float) -> Simulator:
    """An 8 x 8 cloth (0.3 m, 50 g) at rest on a plane with friction mu, gravity tilted by 30 degrees,
    0.25 s at the scheme's default dt (the contract's frictionless slope, tests/test_contract.py)."""
    model = build_grid_cloth(8, 8, 0.3, 0.3, 0.05, plane="horizontal", origin=(0.0, 0.005, 0.0), device="cpu")
    control = Control(
        gravity=(G * math.sin(THETA), -G * math.cos(THETA), 0.0),
        colliders=(Plane(thickness=0.005, friction=mu),),
        device="cpu",
    )
    sim = Simulator(model, make_integrator(name), control)
    simulate_frames(sim, max(1, round(DURATION / sim.dt)))
    return sim


@pytest.mark.parametrize("name", integrator_names())
def test_cloth_slides_down_a_slope_at_g_sin_minus_mu_cos(name):
    """mu = 0.3: on the surface, mean velocity along the slope n h g (sin 30 - 0.3 cos 30) to the
    scheme's free-motion tolerance (1e-3 for the exact schemes, 2 % for the solvers); mu = 0.7 > tan 30:
    it does not move."""
    sim = slide(name, 0.3)
    steps = max(1, round(DURATION / sim.dt))
    v = sim.state.particle_qd.numpy().astype(np.float64)
    y = sim.state.particle_q.numpy()[:, 1]
    assert np.abs(y - 0.005).max() < 1e-4, f"{name}: left the surface by {np.abs(y - 0.005).max():.3g} m"
    want = steps * sim.dt * G * (math.sin(THETA) - 0.3 * math.cos(THETA))
    assert v[:, 0].mean() == pytest.approx(want, rel=sim.integrator.free_motion_rtol), (
        f"{name}: slides at {v[:, 0].mean():.5f} m/s, expected {want:.5f} m/s"
    )
    held = slide(name, 0.7)
    moved = np.abs(held.state.particle_q.numpy() - held.model.particle_q.numpy()).max()
    assert moved < 1e-5, f"{name}: mu 0.7 > tan 30, yet it moved {moved:.3g} m"
