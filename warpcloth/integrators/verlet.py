"""Position Verlet (Jakobsen 2001; seed eq. 2.18).

    x_new = 2 x - x_prev + a(x, v) dt^2,   v = (x_new - x) / dt  (the velocity used for damping)

carried as an increment: the displacement d = x - x_prev is kept, and a step is
d <- d + a dt^2, x <- x + d, v = d / dt, equal to the update above in exact arithmetic. The
two-position form rounds x_new - x to a multiple of ulp(x), so in float32 a velocity change
a dt^2 below half an ulp (~6e-8 m at 1.5 m) is lost every step (docs/stability.md, "Float32").
:meth:`Verlet.begin` starts the history from the current (x, v) with the second-order Taylor value
d = dt v - dt^2/2 a, so the scheme keeps its second order from the first step; it runs after a bind,
a switch or a change of dt.
"""

import warp as wp

from warpcloth.integrators.base import EXPLICIT_STUDY_GRID, Integrator, scratch_like
from warpcloth.integrators.forces import eval_forces
from warpcloth.kernels import integrate as ik


class Verlet(Integrator):
    name = "verlet"
    explicit = True
    study_grid = EXPLICIT_STUDY_GRID
    free_fall = "exact"  # primed with d = h v - h^2 a / 2
    force_evals_per_step = 1
    default_dt_factor = 0.9

    def _allocate(self, model):
        self.displacement = scratch_like(model)

    def position_history(self):
        return self.displacement

    def begin(self, state, control, dt):
        m = self.model
        eval_forces(m, state.particle_q, state.particle_qd, control, state.particle_f)
        wp.launch(
            ik.verlet_prime,
            dim=m.particle_count,
            inputs=[state.particle_qd, state.particle_f, m.particle_inv_mass, float(dt)],
            outputs=[self.displacement],
            device=m.device,
        )

    def step(self, state, control, dt):
        m = self.model
        eval_forces(m, state.particle_q, state.particle_qd, control, state.particle_f)
        wp.launch(
            ik.integrate_verlet,
            dim=m.particle_count,
            inputs=[
                state.particle_q,
                self.displacement,
                state.particle_qd,
                state.particle_f,
                m.particle_inv_mass,
                float(dt),
            ],
            device=m.device,
        )
