"""Position based dynamics, Müller, Heidelberger, Hennix & Ratcliff 2007 (seed 2, Algorithm 1).

Each of the ``substeps`` substeps of length h = dt / substeps runs Algorithm 1:

    v <- (1 - k_damp)^(1/substeps) (v + h w f_ext) ;  p = x + h v
    repeat n times, colour by colour:  p_i += k' w_i/(w_i + w_j) C n,  p_j -= k' w_j/(w_i + w_j) C n
    v = (p - x) / h ;  x = p

with C = |p_j - p_i| - L0, n = (p_j - p_i)/|p_j - p_i| for every spring (bend springs too) and the
iteration-count correction k' = 1 - (1 - k)^(1/n) (section 3.3), so that a lone constraint keeps the
fraction (1 - k) of its error whatever n is. ``substeps=1`` is the paper's algorithm; more substeps
(Macklin et al. 2019) make an unconverged solve stiffer. p is carried as the increment dp = p - x,
so float32 keeps h v (:mod:`warpcloth.kernels.constraints`).

The stiffness k in [0, 1] is per substep, not a material constant (use ``xpbd`` for ks): **the
cloth's stiffness depends on the iteration and substep counts** and on the mesh size, because k'
holds for a lone constraint, not a network. Changing either changes the material, not only the
accuracy (sag table: docs/solvers.md, "pbd: its stiffness depends on iterations and substeps").

Dihedral hinges (``bend="dihedral"``) are constraints C = theta - theta0 with ``pbd_bend_stiffness``
(dp_b = -k' w_b C g_b / sum w |g|^2, :func:`warpcloth.kernels.bending.solve_hinges_pbd`), swept by their
own colouring after the springs: the rigidity B plays no role (docs/materials.md).
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np
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


def material_bend_stiffness(model, h: float) -> float:
    """The pbd bend stiffness k that takes the model's material: the fraction of a lone bend
    constraint's error that xpbd's compliance 1/ks removes in one substep of length ``h`` [s],
    k = ks h^2 w / (1 + ks h^2 w), w = w_i + w_j (Macklin et al. 2016, eq. 18 with lambda = 0), the
    median over the bend springs between free particles (0 without any: nothing to bend). Rounded to 3
    digits (an option a ``warpcloth run`` reproduces). pbd's own default, 1, is a rigid bend."""
    t = np.asarray(model.spring_type)
    w = model.host.inv_mass.astype(np.float64)
    pairs = model.host.pairs.astype(np.int64).reshape(-1, 2)
    ks = model.spring_stiffness.numpy().astype(np.float64)
    bend = (t == int(SpringType.BEND)) & (w[pairs[:, 0]] > 0) & (w[pairs[:, 1]] > 0)
    if not np.any(bend):
        return 0.0
    x = ks[bend] * h * h * (w[pairs[bend, 0]] + w[pairs[bend, 1]])
    return float(f"{float(np.median(x / (1.0 + x))):.3g}")


def iteration_stiffness(stiffness: float, iterations: int) -> float:
    """k' = 1 - (1 - k)^(1/n): the per-iteration stiffness whose n-fold application removes the
    fraction k of a constraint's error (Müller et al. 2007, section 3.3)."""
    return 1.0 - (1.0 - float(stiffness)) ** (1.0 / int(iterations))


class PBD(PositionBasedIntegrator):
    """Position based dynamics (Müller et al. 2007), distance constraints with stiffness in [0, 1]."""

    name: ClassVar[str] = "pbd"
    #: The study maps ``pbd_bend_stiffness`` from its material at each configuration's substep
    #: (:func:`material_bend_stiffness`): the default 1 is a rigid bend, another material.
    study_bend_from_material: ClassVar[bool] = True

    def rest_extension(self, mass: float, stiffness: float, gravity: float, dt: float) -> float:
        """pbd's stiffness k is a dimensionless fraction of a constraint projected per iteration, not
        N/m: a hanging mass rests where the projection undoes a substep's fall, (1 - k) / k g h^2 with
        h = dt / substeps (Müller et al. 2007); ``mass`` and ``stiffness`` do not enter (inf at k = 0)."""
        k, h = self.pbd_stiffness, dt / self.substeps
        return (1.0 - k) / k * gravity * h * h if k > 0 else float("inf")

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
            self.along_start(control),
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
