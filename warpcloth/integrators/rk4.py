"""Classic fourth-order Runge-Kutta on the whole state (x, v) (seed eq. 2.17).

k1 = (v, a(x, v)),  k2 = F(s + dt/2 k1),  k3 = F(s + dt/2 k2),  k4 = F(s + dt k3)
s <- s + dt/6 (k1 + 2 k2 + 2 k3 + k4),   s = (x, v)
"""

import warp as wp

from warpcloth.integrators.base import EXPLICIT_STUDY_GRID, Integrator, scratch_like
from warpcloth.integrators.forces import eval_forces
from warpcloth.kernels import integrate as ik
from warpcloth.sim.pins import apply_pins


class RK4(Integrator):
    name = "rk4"
    explicit = True
    study_grid = EXPLICIT_STUDY_GRID
    free_fall = "exact"
    velocity_position_weight = 0.5  # x_new = x + dt v + dt^2/2 a: an acceleration moves x with weight 1/2
    force_evals_per_step = 4
    default_dt_factor = 1.0

    def _allocate(self, model):
        self.x_s, self.v_s, self.acc_x, self.acc_v = scratch_like(model, 4)

    def step(self, state, control, dt):
        m, x, v, f = self.model, state.particle_q, state.particle_qd, state.particle_f
        xs, vs = self.x_s, self.v_s
        n, w = m.particle_count, m.particle_inv_mass

        def stage(v_stage, h, weight, first):
            # acc += weight k(stage) ; (xs, vs) = (x, v) + h k(stage)
            wp.launch(
                ik.integrate_rk4_stage,
                dim=n,
                inputs=[x, v, v_stage, f, w, h, weight, first, self.acc_x, self.acc_v],
                outputs=[xs, vs],
                device=m.device,
            )
            apply_pins(control, xs, vs, h)  # kinematic pins at the stage time t + h

        eval_forces(m, x, v, control, f)  # k1
        stage(v, 0.5 * dt, 1.0, 1)
        eval_forces(m, xs, vs, control, f)  # k2
        stage(vs, 0.5 * dt, 2.0, 0)
        eval_forces(m, xs, vs, control, f)  # k3
        stage(vs, float(dt), 2.0, 0)
        eval_forces(m, xs, vs, control, f)  # k4
        wp.launch(
            ik.integrate_rk4_final, dim=n, inputs=[x, v, vs, f, w, self.acc_x, self.acc_v, float(dt)], device=m.device
        )
