"""Position based dynamics, Müller, Heidelberger, Hennix & Ratcliff 2007 (seed 2, Algorithm 1).

Each of the ``substeps`` substeps of length h = dt / substeps runs Algorithm 1:

    v <- (1 - k_damp)^(1/substeps) (v + h w f_ext) ;  p = x + h v
    repeat n times, colour by colour:  p_i += k' w_i/(w_i + w_j) C n,  p_j -= k' w_j/(w_i + w_j) C n
    v = (p - x) / h ;  x = p

(p is carried as the increment dp = p - x, so float32 keeps h v and the corrections whatever
the substep: see :mod:`warpcloth.kernels.constraints`)

with C = |p_j - p_i| - L0, n = (p_j - p_i)/|p_j - p_i| for every spring (bend springs too) and
the iteration-count correction k' = 1 - (1 - k)^(1/n) (section 3.3), so that after n iterations
a lone constraint keeps the fraction (1 - k) of its error whatever n is. ``substeps=1`` is the
paper's algorithm; more substeps (Macklin et al. 2019) make an unconverged solve stiffer. The
stiffness k in [0, 1] is per substep and not a material constant: it does not map to ks (use
``xpbd`` for that).

**The cloth's stiffness depends on the iteration and substep counts** (and on the mesh size): the
k' correction holds for a lone constraint, not for a network of them, so more iterations or more
substeps give a stiffer cloth. Static sag of the scenario sheet at dt = 1/60 s against the float64
equilibrium of the model's ks (``python bench/solver_checks/xpbd_table.py --integrator pbd``):
24 x 24: 10 x 1 +4007 %, 10 x 4 (the defaults) +197 %, 10 x 8 -25 %, 10 x 16 -81 %, 20 x 4 +47 %,
40 x 4 -29 %; 32 x 32: 10 x 4 +431 %, 10 x 8 +36 %, 40 x 4 +32 % (iterations x substeps).
Changing either changes the material, not only the accuracy.

Dihedral hinges (``bend="dihedral"``) are constraints C = theta - theta0 with ``pbd_bend_stiffness``
(dp_b = -k' w_b C g_b / sum w |g|^2, :func:`warpcloth.kernels.bending.solve_hinges_pbd`), swept by their
own colouring after the springs: the rigidity B plays no role (docs/materials.md).
"""

from __future__ import annotations

from typing import ClassVar

import warp as wp

from warpcloth.integrators.base import Option
from warpcloth.integrators.position_based import (
    ITERATIONS,
    SUBSTEPS,
    VELOCITY_DAMPING,
    PositionBasedIntegrator,
    in_unit_interval,
)
from warpcloth.kernels import bending as bk
from warpcloth.kernels import constraints as ck
from warpcloth.sim.model import SpringType


def iteration_stiffness(stiffness: float, iterations: int) -> float:
    """k' = 1 - (1 - k)^(1/n): the per-iteration stiffness whose n-fold application removes the
    fraction k of a constraint's error (Müller et al. 2007, section 3.3)."""
    return 1.0 - (1.0 - float(stiffness)) ** (1.0 / int(iterations))


class PBD(PositionBasedIntegrator):
    """Position based dynamics (Müller et al. 2007), distance constraints with stiffness in [0, 1]."""

    name: ClassVar[str] = "pbd"
    options = (
        ITERATIONS,
        SUBSTEPS,
        Option(
            "pbd_stiffness",
            float,
            1.0,
            "PBD stiffness k of structural and shear constraints, in [0, 1]",
            check=in_unit_interval,
        ),
        Option(
            "pbd_bend_stiffness",
            float,
            1.0,
            "PBD stiffness k of bend constraints (bend springs, or the dihedral hinges' C = theta - theta0), in [0, 1]",
            check=in_unit_interval,
        ),
        VELOCITY_DAMPING,
    )

    #: Apply k' = 1 - (1 - k)^(1/n) (the paper's form). False uses k per iteration, for studies
    #: and tests that show the stiffness then depends on the iteration count.
    iteration_correction: bool = True

    def type_stiffness(self) -> wp.vec3:
        """Per-iteration stiffness of (structural, shear, bend) constraints."""
        k = {
            SpringType.STRUCTURAL: self.pbd_stiffness,
            SpringType.SHEAR: self.pbd_stiffness,
            SpringType.BEND: self.pbd_bend_stiffness,
        }
        if self.iteration_correction:
            k = {t: iteration_stiffness(v, self.iterations) for t, v in k.items()}
        return wp.vec3(*(k[t] for t in SpringType))

    def step(self, state, control, dt):
        m = self.model
        h = dt / self.substeps
        keep = self.velocity_keep()
        params = [
            m.spring_indices,
            m.spring_rest_length,
            self.spring_type,
            self.type_stiffness(),
            m.spring_compression,
            m.particle_inv_mass,
            state.particle_q,
        ]
        sweep = self.color_sweep(ck.solve_springs_pbd, params, [self.particle_dp])
        if m.hinge_count:  # dihedral hinges: C = theta - theta0 at the bend stiffness (no unit, like the springs')
            k = float(self.type_stiffness()[int(SpringType.BEND)])
            hinge = [m.hinge_indices, m.hinge_rest_angle, k, m.particle_inv_mass, state.particle_q]
            sweep = sweep + self.hinge_sweep(bk.solve_hinges_pbd, hinge, [self.particle_dp])
        for k in range(self.substeps):
            self.predict(state, control, h, keep, (k + 1) * h)
            self.solve(state, control, sweep)
            self.update(state, h, control, (k + 1) * h)

    def stats(self) -> dict:
        return {**super().stats(), "iterations": self.iterations, "substeps": self.substeps}
