"""Explicit midpoint (RK2) on the whole state (x, v) (seed eq. 2.16).

    (x, v)_mid = (x, v) + dt/2 (v, a(x, v)) ;  (x, v) <- (x, v) + dt (v_mid, a(x_mid, v_mid))
"""

import warp as wp

from warpcloth.kernels import integrate as ik

from ..forces import eval_forces
from .base import Integrator, scratch_like


class Midpoint(Integrator):
    name = "midpoint"
    force_evals_per_step = 2
    default_dt_factor = 0.5

    def _allocate(self, model):
        self.x_mid, self.v_mid = scratch_like(model, 2)

    def step(self, state, control, dt):
        m, x, v, f = self.model, state.particle_q, state.particle_qd, state.particle_f
        stage = ik.integrate_rk_stage
        eval_forces(m, x, v, control, f)
        wp.launch(stage, dim=m.particle_count, inputs=[x, v, v, f, m.particle_inv_mass, 0.5 * dt], outputs=[self.x_mid, self.v_mid], device=m.device)
        eval_forces(m, self.x_mid, self.v_mid, control, f)
        wp.launch(stage, dim=m.particle_count, inputs=[x, v, self.v_mid, f, m.particle_inv_mass, float(dt)], outputs=[x, v], device=m.device)
