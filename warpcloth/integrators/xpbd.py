"""Extended position based dynamics, Macklin, Müller & Chentanez 2016, with the substeps of
Macklin, Storey, Lu, Terdiman, Chentanez, Jeschke & Müller 2019 ("Small Steps").

Each of the ``substeps`` substeps of length h = dt / substeps runs

    v <- (1 - k_damp)^(1/substeps) (v + h w f_ext) ;  p = x + h v ;  lambda = 0
    repeat n times, colour by colour (Macklin 2016, eq. 18 and 26):
        dlambda = (-C - alpha~ lambda - gamma gradC (p - x)) / ((1 + gamma)(w_i + w_j) + alpha~)
        lambda += dlambda ;  p_i -= w_i n dlambda ;  p_j += w_j n dlambda
    v = (p - x) / h ;  x = p

for every spring (bend springs too), with C = |p_j - p_i| - L0, compliance alpha = 1/ks,
alpha~ = alpha / h^2 and damping gamma = alpha kd / h: the spring's own ks [N/m] and kd [N s/m]
(the kernels multiply through by ks h^2, so ks = 0 exerts nothing and nothing divides by ks).
p is carried as the increment dp = p - x, so float32 keeps h v (:mod:`warpcloth.kernels.constraints`).

The material is the force-based integrators' only where a substep's solve converges: the default
10 iterations x 4 substeps is far from converged on fine sheets, and an unconverged solve acts as a
softer material (sag figures, and the variants tried: docs/solvers.md, "xpbd: its defaults are not
the spring material"). For the spring material's statics use vbd, implicit_euler or projective.

Dihedral hinges (``bend="dihedral"``) are constraints C = theta - theta0, gradC = g, with compliance
1 / k_e and damping kd_e (:func:`warpcloth.kernels.bending.solve_hinges_xpbd`), swept by their own
colouring after the springs, lambda per hinge; the rest shape depends on the substep (docs/materials.md).
"""

from __future__ import annotations

from typing import ClassVar

import warp as wp

from warpcloth.integrators.position_based import ITERATIONS, SUBSTEPS, VELOCITY_DAMPING, PositionBasedIntegrator
from warpcloth.kernels import bending as bk
from warpcloth.kernels import constraints as ck


class XPBD(PositionBasedIntegrator):
    """Extended position based dynamics (Macklin et al. 2016): compliance alpha = 1/ks, substeps."""

    name: ClassVar[str] = "xpbd"
    options = (
        ITERATIONS,
        SUBSTEPS,
        VELOCITY_DAMPING,
    )

    def _allocate(self, model) -> None:
        super()._allocate(model)
        self.spring_lambda = wp.zeros(model.spring_count, dtype=float)
        self.hinge_lambda = wp.zeros(model.hinge_count, dtype=float)

    def step(self, state, control, dt):
        m = self.model
        h = dt / self.substeps
        keep = self.velocity_keep()
        params = [
            m.spring_indices,
            m.spring_rest_length,
            m.spring_stiffness,
            m.spring_damping,
            m.spring_compression,
            m.particle_inv_mass,
            state.particle_q,
            h,
            self.along_start(control),
        ]
        sweep = self.color_sweep(ck.solve_springs_xpbd, params, [self.spring_lambda, self.particle_dp])
        if m.hinge_count:  # dihedral hinges: C = theta - theta0, compliance 1 / k_e, damping kd_e
            hinge = [*m.hinge_arrays(), m.particle_inv_mass, state.particle_q, h]
            sweep = sweep + self.hinge_sweep(bk.solve_hinges_xpbd, hinge, [self.hinge_lambda, self.particle_dp])
        for k in range(self.substeps):
            self.predict(state, control, h, keep, (k + 1) * h)
            self.clear_lambda()
            self.solve(state, control, sweep)
            self.update(state, h, control, (k + 1) * h)

    def clear_lambda(self) -> None:
        """lambda = 0 for every constraint."""
        if self.model.spring_count:
            wp.launch(
                ck.clear_lambda, dim=self.model.spring_count, outputs=[self.spring_lambda], device=self.model.device
            )
        if self.model.hinge_count:
            wp.launch(
                ck.clear_lambda, dim=self.model.hinge_count, outputs=[self.hinge_lambda], device=self.model.device
            )

    def stats(self) -> dict:
        return {**super().stats(), "iterations": self.iterations, "substeps": self.substeps}
