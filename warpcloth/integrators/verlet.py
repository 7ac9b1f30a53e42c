"""Position Verlet (Jakobsen 2001; seed eq. 2.18).

    x_new = 2 x - x_prev + a(x, v) dt^2,   v = (x_new - x) / dt  (the velocity used for damping)

The previous positions are kept here. :meth:`Verlet.begin` starts the history from the current
(x, v) with the second-order Taylor value x_prev = x - dt v + dt^2/2 a, so the scheme keeps
its second order from the first step; it runs after a bind, a switch or a change of dt.
"""

import warp as wp

from warpcloth.kernels import integrate as ik

from ..forces import eval_forces
from .base import Integrator, scratch_like


class Verlet(Integrator):
    name = "verlet"
    force_evals_per_step = 1
    default_dt_factor = 0.9

    def _allocate(self, model):
        self.x_prev = scratch_like(model)

    def begin(self, state, control, dt):
        m = self.model
        eval_forces(m, state.particle_q, state.particle_qd, control, state.particle_f)
        wp.launch(ik.verlet_prime, dim=m.particle_count, inputs=[state.particle_q, state.particle_qd, state.particle_f, m.particle_inv_mass, float(dt)], outputs=[self.x_prev], device=m.device)

    def step(self, state, control, dt):
        m = self.model
        eval_forces(m, state.particle_q, state.particle_qd, control, state.particle_f)
        wp.launch(ik.integrate_verlet, dim=m.particle_count, inputs=[state.particle_q, self.x_prev, state.particle_qd, state.particle_f, m.particle_inv_mass, float(dt)], device=m.device)
