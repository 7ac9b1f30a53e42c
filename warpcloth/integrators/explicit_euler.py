"""Explicit (semi-implicit, symplectic) Euler, Provot 1995 (seed eq. 2.15).

a = f(x, v) / m ;  v <- v + dt a ;  x <- x + dt v
"""

import warp as wp

from warpcloth.integrators.base import EXPLICIT_STUDY_GRID, Integrator
from warpcloth.integrators.forces import eval_forces
from warpcloth.kernels import integrate as ik


class ExplicitEuler(Integrator):
    name = "explicit_euler"
    explicit = True
    study_grid = EXPLICIT_STUDY_GRID
    force_evals_per_step = 1
    default_dt_factor = 0.9

    def step(self, state, control, dt):
        model = self.model
        eval_forces(model, state.particle_q, state.particle_qd, control, state.particle_f)
        wp.launch(
            ik.integrate_explicit_euler,
            dim=model.particle_count,
            inputs=[state.particle_q, state.particle_qd, state.particle_f, model.particle_inv_mass, float(dt)],
            device=model.device,
        )
