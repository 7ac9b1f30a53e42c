"""The integrator contract, angular momentum (issue 51): a free cloth's L = sum m (x - x_cm) x v about
its centre of mass, in float64 from the state, is kept by every registered integrator, as
tests/test_contract.py holds its linear momentum.

- falling along its own plane in gravity (no torque about the centre of mass): L stays ~0 (vbd turned
  the cloth by -0.32 degrees in 0.5 s, |L| 8.1e-4 kg m^2/s, before its rotation correction);
- stretched by 5 % and released without gravity (L = 0 by symmetry, the motion is not: Gauss-Seidel
  sweeps and projections visit the particles in an order): L stays ~0 (vbd 1.9e-5 kg m^2/s before;
  pbd 5.3e-4 and xpbd 2.6e-4 while they projected along the predicted edge, 3e-9 along the substep's
  start edge, SHAKE: :mod:`warpcloth.kernels.constraints`).

The bound, 1e-6 kg m^2/s, is from what the schemes that keep it reach (float32 state, 1 s): implicit
Euler, projective and vbd <= 3.5e-8; the explicit schemes <= 1.5e-7 over their ~5e4 steps of 2e-5 s.
No scheme declares a looser one: a rigid translation or rotation of a free cloth is not resisted by
its springs, so a converged step of any of the schemes exerts no torque on it. (A rigid spin is not
tested: backward Euler itself turns h sum m v_new x v_old of L a step, 1.6 % in 1 s at 1 rad/s, and
more where it is linearised.)
"""

from __future__ import annotations

import numpy as np
import pytest
from helpers import released_stretched_cloth

from warpcloth import Control, Simulator, build_grid_cloth, make_integrator
from warpcloth.integrators import integrator_names

NAMES = integrator_names()
G = 9.81
#: |L| about the centre of mass [kg m^2/s] that a free cloth's step may leave (module docstring)
L_BOUND = 1.0e-6


def angular_momentum(sim, mass: np.ndarray) -> np.ndarray:
    """L = sum m (x - x_cm) x v [kg m^2/s], float64 from the state (``mass``: shape (n, 1))."""
    x = sim.state.particle_q.numpy().astype(np.float64)
    v = sim.state.particle_qd.numpy().astype(np.float64)
    c = (mass * x).sum(axis=0) / mass.sum()
    return (mass * np.cross(x - c, v)).sum(axis=0)


@pytest.mark.parametrize("name", NAMES)
def test_free_cloth_falling_along_its_plane_does_not_turn(name):
    """The unpinned 16 x 16 cloth (1 m, 0.2 kg, horizontal, no drag) of the contract's free fall,
    gravity along its plane, 0.5 s at the scheme's default dt, sampled every 1/60 s: |L| <= 1e-6
    (its sum m |r x v| reaches ~0.4 kg m^2/s)."""
    model = build_grid_cloth(16, 16, 1.0, 1.0, 0.2, plane="horizontal", origin=(0.0, 1.5, 0.0), device="cpu")
    sim = Simulator(model, make_integrator(name), Control(gravity=(-G, 0.0, 0.0), drag_rate=0.0, device="cpu"))
    m = model.host.mass.astype(np.float64)[:, None]
    x0 = sim.state.particle_q.numpy().astype(np.float64)[:, 0].mean()
    per_frame = max(1, round((1.0 / 60.0) / sim.dt))
    worst = 0.0
    for _ in range(30):
        sim.simulate(per_frame)
        worst = max(worst, float(np.linalg.norm(angular_momentum(sim, m))))
    fell = x0 - sim.state.particle_q.numpy().astype(np.float64)[:, 0].mean()
    assert fell > 1.0, f"{name}: the cloth fell {fell:.3g} m along its plane"  # g t^2 / 2 = 1.23 m
    assert worst <= L_BOUND, f"{name}: |L| reached {worst:.3g} kg m^2/s falling along its plane"


@pytest.mark.parametrize("name", NAMES)
def test_free_cloth_released_stretched_keeps_its_angular_momentum(name):
    """The contract's momentum cloth (16 x 16, kd 0, no gravity, no drag) released stretched by 5 %:
    |L - L0| <= 1e-6 kg m^2/s (L0 = 0), sampled every 1/60 s over 1 s at the scheme's default dt,
    while it moves (sum m |r| |v| > 1e-4 kg m^2/s)."""
    sim, m = released_stretched_cloth(name)
    L0 = angular_momentum(sim, m)
    per_frame = max(1, round((1.0 / 60.0) / sim.dt))
    worst, motion = 0.0, 0.0
    for _ in range(60):
        sim.simulate(per_frame)
        worst = max(worst, float(np.linalg.norm(angular_momentum(sim, m) - L0)))
        x = sim.state.particle_q.numpy().astype(np.float64)
        v = sim.state.particle_qd.numpy().astype(np.float64)
        r = x - (m * x).sum(axis=0) / m.sum()
        motion = max(motion, float((m[:, 0] * np.linalg.norm(r, axis=1) * np.linalg.norm(v, axis=1)).sum()))
    assert motion > 1e-4, f"{name}: the stretched cloth did not move ({motion:.3g} kg m^2/s)"
    assert worst <= L_BOUND, f"{name}: |L - L0| reached {worst:.3g} kg m^2/s"
