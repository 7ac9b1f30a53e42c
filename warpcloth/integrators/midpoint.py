"""Explicit midpoint (RK2) on the whole state (x, v) (seed eq. 2.16).

    (x, v)_mid = (x, v) + dt/2 (v, a(x, v)) ;  (x, v) <- (x, v) + dt (v_mid, a(x_mid, v_mid))

Its stability function R(z) = 1 + z + z^2/2 has |R(i h omega)| = sqrt(1 + (h omega)^4 / 4) > 1 on
the imaginary axis: without damping every oscillation grows at every dt. The default dt is
therefore taken from the stability region with the model's damping
(:func:`~warpcloth.integrators.base.runge_kutta_stable_dt`), and a model with neither spring
damping nor drag has no stable dt.
"""

import warp as wp

from warpcloth.integrators.base import (
    EXPLICIT_STUDY_GRID,
    Integrator,
    model_spectrum,
    runge_kutta_stable_dt,
    scratch_like,
)
from warpcloth.integrators.forces import eval_forces
from warpcloth.kernels import integrate as ik
from warpcloth.sim.pins import apply_pins


def rk2_amplification(z):
    """R(z) = 1 + z + z^2 / 2, the stability function of the explicit midpoint rule."""
    return 1.0 + z + 0.5 * z * z


class Midpoint(Integrator):
    name = "midpoint"
    explicit = True
    study_grid = EXPLICIT_STUDY_GRID
    free_fall = "exact"
    velocity_position_weight = 0.5  # x_new = x + dt v + dt^2/2 a: an acceleration moves x with weight 1/2
    force_evals_per_step = 2
    default_dt_factor = 0.8

    def default_dt(self, model, drag_rate: float = 0.0) -> float:
        """:attr:`default_dt_factor` times the largest dt in RK2's stability region for the
        model's stiffness and damping (0.0 when there is none), capped at one frame."""
        return min(
            self.default_dt_cap, self.default_dt_factor * runge_kutta_stable_dt(rk2_amplification, model, drag_rate)
        )

    def no_stable_dt_reason(self, model, drag_rate: float = 0.0) -> str | None:
        if runge_kutta_stable_dt(rk2_amplification, model, drag_rate) > 0.0:
            return None
        _, alpha, beta = model_spectrum(model, drag_rate)
        what = "no spring damping and no drag" if alpha == 0.0 and beta == 0.0 else "too little damping"
        return (
            f"midpoint (RK2) has no stable time step on this model ({what}): it amplifies every undamped "
            f"oscillation by sqrt(1 + (h omega)^4 / 4) per step; add spring damping or drag"
        )

    def _allocate(self, model):
        self.x_mid, self.v_mid = scratch_like(model, 2)

    def step(self, state, control, dt):
        m, x, v, f = self.model, state.particle_q, state.particle_qd, state.particle_f
        stage = ik.integrate_rk_stage
        eval_forces(m, x, v, control, f)
        wp.launch(
            stage,
            dim=m.particle_count,
            inputs=[x, v, v, f, m.particle_inv_mass, 0.5 * dt],
            outputs=[self.x_mid, self.v_mid],
            device=m.device,
        )
        apply_pins(control, self.x_mid, self.v_mid, 0.5 * dt)  # kinematic pins at the stage time
        eval_forces(m, self.x_mid, self.v_mid, control, f)
        wp.launch(
            stage,
            dim=m.particle_count,
            inputs=[x, v, self.v_mid, f, m.particle_inv_mass, float(dt)],
            outputs=[x, v],
            device=m.device,
        )
