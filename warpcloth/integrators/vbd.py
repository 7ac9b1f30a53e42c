"""Vertex Block Descent, Chen, Liu, Yang & Yuksel 2024 (SIGGRAPH), on the mass-spring energy.

    dy = h v + h^2 f_ext / m ;  dx = h v              (initial guess x + h v)
    repeat vbd_iterations times:
        [every vbd_multigrid_every-th iteration: dx <- dx + V(-h^2 grad G(dx))]
        [first and last iteration, before and after its sweep: dx <- dx + P t]   (rigid translation)
        colour by colour (Gauss-Seidel over vertex colours):
        dx_i <- dx_i - H_i^-1 g_i      (3 x 3 Newton step on vertex i's local energy)
        [Chebyshev: dx <- omega_n (dx - dx^(n-2)) + dx^(n-2)]
    [free cloth: dx <- dx + w x r]; v = dx / h ;  x += dx      (w: angular momentum, rotation_correction)

g_i and H_i are the gradient and Hessian of the incremental potential m/(2h^2)|dx - dy|^2 + springs
in dx_i (:mod:`warpcloth.kernels.vbd`): inertia, the spring forces with their clamped (PSD) Hessian,
and the spring damping kd along the spring taken implicitly (the paper's kd / h term); gravity, drag
and wind are explicit. Vertices are coloured so that no two of one colour share a spring or a hinge
(:func:`warpcloth.sim.coloring.color_vertices`). Converged, a step is nonlinear backward Euler; from
the guess x + h v a rest state is the exact static equilibrium whatever the iteration count.

Local sweeps alone resolve a large sheet's long, stiff modes very slowly and never move the cloth
as a whole, so two corrections that are zero where the gradient is zero (the converged answer is
unchanged) are applied: a multigrid V-cycle of h^2 times implicit Euler's A
(``vbd_multigrid_every``; on non-grid models an aggregation hierarchy, ``vbd_mesh_multigrid``) and
the exact Galerkin step of the rigid translation (``vbd_rigid_mode``, before the first sweep and
after the last). Measurements behind each: docs/solvers.md, "vbd".
"""

from __future__ import annotations

import math
from fractions import Fraction
from typing import ClassVar

import numpy as np
import warp as wp

from warpcloth.integrators.base import Option, scratch_like
from warpcloth.integrators.increment import IncrementSolver, at_least_one
from warpcloth.integrators.multigrid import MIN_COARSE_SIDE, GridMultigrid, grid_structure_reason
from warpcloth.integrators.system import ImplicitSystem
from warpcloth.kernels import increment as nk
from warpcloth.kernels import linalg as lk
from warpcloth.kernels import vbd as vk
from warpcloth.sim.coloring import VertexColoring, color_model
from warpcloth.sim.hinges import hinge_pairs

#: Fewest particles of a model that gets the aggregation multigrid (models that are not grids): the
#: smallest grid the geometric hierarchy coarsens, 7 x 7. Below it the sweeps and the rigid correction
#: suffice, and a two-level V-cycle on a 6 x 6 cloth left a tilted free fall's shape 1.5e-4 m off
#: (2.6e-7 m without it).
MIN_AGGREGATION_PARTICLES = (2 * MIN_COARSE_SIDE - 1) ** 2


def _spectral_radius(value) -> str | None:
    return None if 0.0 <= value < 1.0 else "must be in [0, 1) (0 disables Chebyshev acceleration)"


def chebyshev_weights(iterations: int, rho: float) -> list[float]:
    """omega_1 = 1, omega_2 = 2 / (2 - rho^2), omega_n = 4 / (4 - rho^2 omega_(n-1))
    (Wang 2015; Chen et al. 2024, eq. 17); all 1 when rho = 0."""
    weights = []
    for n in range(1, iterations + 1):
        if n == 1:
            w = 1.0
        elif n == 2:
            w = 2.0 / (2.0 - rho * rho)
        else:
            w = 4.0 / (4.0 - rho * rho * weights[-1])
        weights.append(w)
    return weights


class VBD(IncrementSolver):
    """Vertex Block Descent (Chen et al. 2024): per-vertex 3 x 3 Newton, Gauss-Seidel by colour."""

    name: ClassVar[str] = "vbd"
    study_grid: ClassVar[dict] = {
        "full": ({"vbd_iterations": (1, 2, 4, 10, 20)}, (Fraction(1, 2), 1, 2, 4, 8)),
        "quick": ({"vbd_iterations": (1, 4, 20)}, (Fraction(1, 2), 1, 4)),
    }
    free_motion_rtol: ClassVar[float] = 0.02  # the centroid moves by Gauss-Seidel sweeps and a correction

    @classmethod
    def relative_work(cls, options: dict) -> float:
        """Sweeps per step against the default's."""
        return options["vbd_iterations"] / cls.option_defaults()["vbd_iterations"]

    self_contact_filter: ClassVar[str] = "gap"  # contacts are constraints of its iterations
    options = (
        # 4 with a multigrid correction before each sweep (grid models): the 128 x 128 sheet's sag
        # within 0.5 % of the float64 equilibrium after 0.5 s and the 128 x 128 flag stable for 3 s
        # with 3 or 5 (docs/solvers.md). Sweeps alone (vbd_multigrid_every 0) need 20 on the 64 x 64
        # flag and still leave the 128 x 128 sheet's sag -68 % off after 10 s.
        Option(
            "vbd_iterations",
            int,
            4,
            "VBD iterations (sweeps over every vertex colour) per time step (>= 1)",
            check=at_least_one,
        ),
        Option(
            "vbd_multigrid_every",
            int,
            1,
            "a multigrid V-cycle of the step's Hessian corrects dx before every k-th sweep (0: never; models that "
            "are not grids: an aggregation hierarchy, see vbd_mesh_multigrid)",
            check=lambda v: None if v >= 0 else "must be an integer >= 0",
        ),
        Option(
            "vbd_mesh_multigrid",
            int,
            1,
            "models that are not grids: the multigrid correction on an aggregation hierarchy of the Hessian's graph "
            "(1) or none (0)",
            check=lambda v: None if v in (0, 1) else "must be 0 or 1",
        ),
        Option(
            "vbd_rigid_mode",
            int,
            3,
            "rigid translation correction (the cloth's mean motion solved exactly, conserves momentum): 3 before the "
            "first sweep and after the last, 1 after every sweep and before the first, 2 before and after every "
            "sweep (with colliders 1 and 3: before every sweep), 0 off",
            check=lambda v: None if v in (0, 1, 2, 3) else "must be 0, 1, 2 or 3",
        ),
        Option(
            "vbd_contact_scale",
            float,
            4.0,
            "self-collision: the contacts' penalty stiffness in the vertices' Newton steps, times the self-collision "
            "stiffness (by default a quarter of the stiffest structural spring, for the explicit schemes' stability: "
            "4 makes it as stiff as that spring)",
            check=lambda v: None if 0.0 < v < math.inf else "must be > 0 and finite",
        ),
        Option(
            "vbd_correction_strain",
            float,
            0.1,
            "with colliders: the multigrid correction goes no further than stretches a spring this far past its rest "
            "length (or further than it already is); 0: no limit (a 5 m/s sphere through a hanging sheet then "
            "stretched springs 48-fold and the sheet flew apart at 600 m/s; docs/solvers.md)",
            check=lambda v: None if 0.0 <= v < math.inf else "must be >= 0 and finite",
        ),
        Option(
            "vbd_chebyshev_rho",
            float,
            0.0,
            "spectral radius estimate for Chebyshev acceleration of the VBD iterations (Wang 2015), in [0, 1); 0 "
            "disables it",
            check=_spectral_radius,
        ),
    )

    coloring: VertexColoring

    def _allocate_solver(self, model) -> None:
        pairs = model.host.pairs
        if model.hinge_count:  # no two vertices of a colour share a hinge either
            pairs = np.concatenate([pairs, hinge_pairs(model.host.hinges.indices)])
        self.coloring = color_model(pairs, model, vertices=True)
        self.vertex_order = wp.array(self.coloring.order, dtype=int)
        self.dx_prev1, self.dx_prev2 = scratch_like(model, 2)  # the Chebyshev history
        # the rigid rotation of a free cloth's step (rotation_correction): float64 chunk sums, w and cm
        n = model.particle_count
        self.rotation_free = len(model.pinned) == 0
        self.rotation_chunk = max(1, -(-n // 128))
        chunks = -(-n // self.rotation_chunk)
        self.rotation_scalars = wp.zeros(2 * chunks, dtype=wp.float64, device=model.device)
        self.rotation_vectors = wp.zeros(3 * chunks, dtype=wp.vec3d, device=model.device)
        self.rotation_matrices = wp.zeros(2 * chunks, dtype=wp.mat33d, device=model.device)
        self.rotation = wp.zeros(2, dtype=wp.vec3, device=model.device)
        self._sweep_key, self._sweep = None, []
        # no self-contacts: empty per-vertex terms (the sweep kernel skips them)
        self.no_self_force, self.no_self_hessian = wp.zeros(0, dtype=wp.vec3), wp.zeros(0, dtype=wp.mat33)
        self.hessian = self.multigrid = None
        if self.vbd_multigrid_every > 0 and grid_structure_reason(model) is None:
            # h^2 times the potential's Hessian is implicit Euler's A = M + h D + h^2 K (drag aside)
            self.hessian = ImplicitSystem(model, jacobian="full", matrix="bsr", preconditioner="multigrid")
            self.multigrid = self.hessian.multigrid
        elif (
            self.vbd_multigrid_every > 0
            and self.vbd_mesh_multigrid
            and model.particle_count >= MIN_AGGREGATION_PARTICLES
        ):
            # any other mesh: the same V-cycle on an aggregation hierarchy of A's graph (issue 26)
            self.hessian = ImplicitSystem(model, jacobian="full", matrix="bsr", preconditioner="jacobi")
            self.multigrid = GridMultigrid(self.hessian.A, 0, 0, model.pinned, model.device, aggregation=True)
            if self.multigrid.levels < 2:  # nothing to coarsen (no springs): the sweeps suffice
                self.hessian = self.multigrid = None
        if self.multigrid is not None:
            # l1 smoothing: with damped block Jacobi (omega 0.7, the CG preconditioner's) the
            # 64 x 64 flag blew up in its first step (measured); with l1 it did not
            self.multigrid.l1_smoother = True
            self.residual, self.delta, self.delta_image = scratch_like(model, 3)
            self.line_sums = wp.zeros(2, dtype=float, device=model.device)
            self.stretch_cap = wp.ones(1, dtype=float, device=model.device)  # the correction's largest step

    def step(self, state, control, dt):
        h = float(dt)
        x = state.particle_q
        # the contact states cleared without colliders where the rigid mode reads them
        colliders = self.predict(state, control, h, clear_contacts=self.vbd_rigid_mode > 0)
        sweep = self.color_sweep(x, h, colliders)
        self.begin_iterations(x, h)
        for it, omega in enumerate(chebyshev_weights(self.vbd_iterations, self.vbd_chebyshev_rho)):
            self.before_sweep(x, h, it)
            for color in sweep:
                color.launch()
            self.after_sweep(x, h, it)
            self.accelerate(x, h, omega)
        if self.vbd_rigid_mode >= 1 and self.rotation_free and colliders is None and self.self_collision is None:
            self.rotation_correction(x)
        self.finish(state, control, h)

    def begin_iterations(self, x, h: float) -> None:
        """Before the first sweep: with self-collision the guess dx = h v projected once onto the step's
        self-contacts as constraints (equal and opposite, as after every sweep), the Chebyshev history
        dx^(n-1) = dx^(n-2) = dx, and h^2 times the step's-start Hessian with its multigrid levels (where a
        coarse correction is on). Why the projection: the self-contacts' penalty is linear in the contact's
        detection normal, so a guess that has carried two layers through each other (2 x 7.5 m/s closing
        over 2 cm at 1/60 s: 0.23 m deep) meets it at that depth, and the sweeps threw the layers apart
        with 5.9 times the impact's kinetic energy and left 4 crossing pairs (docs/self-collision.md,
        "Fast impacts"); the projected guess starts them at their gap."""
        m = self.model
        if self.self_collision is not None:  # the guess x + h v held by the step's self-contacts (below)
            self.self_collision.project_increment(x, self.dx)
        if self.vbd_chebyshev_rho > 0.0:
            wp.launch(
                vk.copy_increment,
                dim=m.particle_count,
                inputs=[self.dx],
                outputs=[self.dx_prev1, self.dx_prev2],
                device=m.device,
            )
        if self.hessian is not None:
            self.hessian.assemble(x, h, 0.0)
            self.hessian.update_preconditioner(h, 0.0)
            if self.multigrid is not self.hessian.multigrid:  # the aggregation hierarchy (not the system's own)
                self.multigrid.update()

    def before_sweep(self, x, h: float, it: int) -> None:
        """Before sweep ``it``: the coarse correction (every ``vbd_multigrid_every``-th), the rigid
        translation (with colliders before every sweep, a step ends on a sweep, which holds the contacts;
        without, before the first one too: a first sweep from a guess whose mean lags leaves a shape error;
        mode 2 before every sweep), and the self-contacts' penalty at the sweep's start."""
        colliders, mode = self.contacts.colliders, self.vbd_rigid_mode
        if self.hessian is not None and it % self.vbd_multigrid_every == 0:
            self.coarse_correction(x, h, colliders)
        if mode == 2 or (mode in (1, 3) and (colliders is not None or it == 0)):
            self.rigid_correction(x, h)
        if colliders is not None:  # the sweep counts the contacts with friction it holds (translation_friction)
            self.contacts.held.zero_()
        if self.self_collision is not None:
            self.self_collision.eval_vertex_terms(x, self.dx, self._contact_stiffness())

    def after_sweep(self, x, h: float, it: int) -> None:
        """After sweep ``it``: the self-contacts as constraints on dx (the next sweep holds the colliders;
        after the last one the colliders push out along their normals: the self-contacts' equal and opposite
        corrections pushed a lower layer into the ground, the fold ended 0.4 mm in, the stacked sheets entered
        it; measured), the colliders' edges, and without colliders the rigid translation (then the
        self-contacts again: the translation sees their penalty, not their constraints; equal and opposite,
        so the momentum it made exact stays; without, a free sheet went into the pinned one it lay on)."""
        m, sc, colliders = self.model, self.self_collision, self.contacts.colliders
        if sc is not None:
            sc.project_increment(x, self.dx)
            if colliders is not None and it == self.vbd_iterations - 1:
                wp.launch(
                    vk.push_out_increment,
                    dim=m.particle_count,
                    inputs=[x, m.particle_inv_mass, colliders],
                    outputs=[self.dx],
                    device=m.device,
                )
        self.contacts.after_iteration(x, self.dx)
        mode = self.vbd_rigid_mode
        if mode >= 1 and colliders is None and (mode != 3 or it == self.vbd_iterations - 1):
            self.rigid_correction(x, h)
            if sc is not None:
                sc.project_increment(x, self.dx)

    def accelerate(self, x, h: float, omega: float) -> None:
        """Chebyshev: dx <- omega (dx - dx^(n-2)) + dx^(n-2) (nothing where ``vbd_chebyshev_rho`` is 0),
        then dx out of the colliders (the extrapolation may reach into one)."""
        if self.vbd_chebyshev_rho <= 0.0:
            return
        m = self.model
        wp.launch(
            vk.apply_chebyshev,
            dim=m.particle_count,
            inputs=[omega],
            outputs=[self.dx, self.dx_prev1, self.dx_prev2],
            device=m.device,
        )
        self.contacts.project(x, self.dx, h)

    def coarse_correction(self, x, h: float, contacts=None) -> None:
        """dx += V(r): r = -h^2 grad G at dx, V one multigrid V-cycle of A = h^2 Hessian.

        With colliders r = 0 where the last sweep held a contact, V(r) = 0 there and where it would
        take a particle into a collider (:func:`~warpcloth.kernels.vbd.mask_contacts`), and dx +=
        alpha V(r) with alpha in [0, 1] minimising the quadratic model along it
        (:func:`~warpcloth.kernels.vbd.add_scaled_increment`, no host read-back). The levels do not see
        the contacts and A is the step's start's: on the 64 x 64 tablecloth the whole masked correction
        stretched the cloth 60 % as it landed and the run blew up at 0.15 s; masked and scaled, it runs
        stable. (The exact constrained solve of the step's-start A, contacts held, blew up as well: a
        landing's kinks make that A a poor model.) Without colliders the step is unchanged."""
        m = self.model
        wp.launch(
            vk.eval_increment_residual,
            dim=m.particle_count,
            inputs=[x, self.dx, self.inertia, self.springs, self.hinges, h],
            outputs=[self.residual],
            device=m.device,
        )
        if contacts is None:  # dx <- V(r) + dx: written by the V-cycle's last smoothing (no pass of its own)
            self.multigrid.apply(self.residual, self.dx, self.dx, 1.0, 1.0)
            return
        # contacts (the last sweep's, or the last step's) hold their normal force
        wp.launch(
            vk.add_contact_forces,
            dim=m.particle_count,
            inputs=[self.contact, h],
            outputs=[self.residual],
            device=m.device,
        )
        self.multigrid.apply(self.residual, self.delta, self.delta, 1.0, 0.0)
        wp.launch(
            vk.mask_contacts,
            dim=m.particle_count,
            inputs=[x, self.dx, self.contact, contacts],
            outputs=[self.delta],
            device=m.device,
        )
        # the step along the masked correction that minimises the step's quadratic model
        offsets, columns, _ = self.multigrid.csr[0]
        wp.launch(
            lk.block_gemv,
            dim=m.particle_count,
            inputs=[offsets, columns, self.multigrid.A[0].values, self.delta, self.delta_image, 1.0, 0.0],
            outputs=[self.delta_image],
            device=m.device,
        )
        self.line_sums.zero_()
        wp.launch(
            vk.correction_dots,
            dim=m.particle_count,
            inputs=[self.delta, self.residual, self.delta_image],
            outputs=[self.line_sums],
            device=m.device,
        )
        if self.vbd_correction_strain > 0.0:  # without it add_scaled_increment ignores the cap
            self.stretch_cap.fill_(1.0)
            wp.launch(
                vk.correction_stretch_cap,
                dim=m.spring_count,
                inputs=[x, self.dx, self.delta, m.spring_indices, m.spring_rest_length, self.vbd_correction_strain],
                outputs=[self.stretch_cap],
                device=m.device,
            )
        wp.launch(
            vk.add_scaled_increment,
            dim=m.particle_count,
            inputs=[self.delta, self.line_sums, self.stretch_cap, int(self.vbd_correction_strain > 0.0)],
            outputs=[self.dx],
            device=m.device,
        )

    def _contact_stiffness(self) -> float:
        """The self-contacts' penalty stiffness of the sweeps and the rigid mode [N/m]: ``vbd_contact_scale``
        times the self-collision's (a quarter of the stiffest structural spring by default, bounded by the
        explicit schemes' stability; a local Newton step is not). At 1 the 48 x 16 fold went unstable at 1.5 s
        (the sweeps' springs and the constraints after them fought at the hand's row) and the 64 x 64 drape at
        0.23 s; at 4 both stay stable; at 16 the 24 x 8 fold let three triangle pairs through (all measured)."""
        return self.vbd_contact_scale * self.self_collision.stiffness

    def rigid_correction(self, x, h: float) -> None:
        """dx += P t: the Galerkin correction of the rigid translation mode (3 unknowns), t =
        (T^T A T)^-1 T^T r, r = -h^2 grad G at dx (colliders' forces of the last sweep included),
        A = h^2 times the potential's Hessian at dx, T's columns P_i e_k (P_i: I free, the tangent
        projector sliding without friction or with its kinetic friction in the mode (sliding_friction), 0 pinned,
        sticking or sliding with the sweep's friction;
        :func:`~warpcloth.kernels.increment.rigid_mode_terms`; with self-collision the contacts' penalty
        too, :func:`~warpcloth.kernels.increment.add_self_contact_rigid_terms`). Springs between free particles do
        not resist a translation, so on a free cloth T^T A T = M I and afterwards sum m dx = sum m dy
        exactly: the step's momentum change is h F_ext, as backward Euler's. Zero where r is zero.

        Called before the first sweep and after the last (mode 3, the default: the one after the last
        makes the momentum exact; after every sweep too, mode 1, cost 9 more per 10 sweeps and changed
        little, docs/solvers.md); with colliders before every sweep instead,
        so that a step ends on a sweep, which holds the contacts (after it, the translation moved
        free particles near the sphere 5.5e-5 m into it on the 16 x 16 drape; projecting them out
        there with an identity Hessian, as after a Chebyshev extrapolation, lost the sweeps' contact
        states and the drape did not settle: both measured)."""
        m, rigid = self.model, self.rigid
        wp.launch(
            nk.rigid_mode_terms,
            dim=m.particle_count,
            inputs=[x, self.dx, self.inertia, self.springs, self.hinges, h, self.contact],
            outputs=[rigid.b, rigid.A],
            device=m.device,
        )
        sc = self.self_collision
        if sc is not None:  # the self-contacts' penalty, as the sweeps see it (pinned, sticking and sliding parties)
            n = m.particle_count
            records = [sc.contact_indices, sc.contact_weights, sc.contact_normals, sc.contact_thickness]
            wp.launch(
                nk.add_self_contact_rigid_terms,
                dim=n,
                inputs=[
                    n,
                    sc.counts,
                    x,
                    self.dx,
                    m.particle_inv_mass,
                    self.contact,
                    *records,
                    self._contact_stiffness(),
                    h,
                ],
                outputs=[rigid.b, rigid.A],
                device=m.device,
            )
        rigid.solve()
        wp.launch(
            nk.apply_rigid_mode,
            dim=m.particle_count,
            inputs=[rigid.translation, m.particle_inv_mass, self.contact],
            outputs=[self.dx],
            device=m.device,
        )

    def rotation_correction(self, x) -> None:
        """dx_i += w x r_i, r_i from the mass centre of x + dx: the rigid rotation after which
        sum m r x (dx - dy) = 0 exactly (:func:`~warpcloth.kernels.vbd.solve_rotation_mode`), backward
        Euler's angular momentum law, which the converged step meets (springs and hinges exert no
        torque on the cloth). The sweeps' Gauss-Seidel order leaves a torque in an unconverged step that
        the translation correction does not see (a free cloth falling along its plane turned by -0.32 degrees
        in 0.5 s). Zero at convergence, momentum unchanged; only on a free cloth (no pins, colliders or
        self-collision: those exert torques of their own), at the step's end (after a Chebyshev step)."""
        m = self.model
        wp.launch(
            vk.rotation_mode_chunks,
            dim=self.rotation_matrices.shape[0] // 2,
            inputs=[x, self.dx, self.inertia, self.rotation_chunk, m.particle_count],
            outputs=[self.rotation_scalars, self.rotation_vectors, self.rotation_matrices],
            device=m.device,
        )
        wp.launch(
            vk.solve_rotation_mode,
            dim=1,
            inputs=[self.rotation_scalars, self.rotation_vectors, self.rotation_matrices],
            outputs=[self.rotation],
            device=m.device,
        )
        wp.launch(
            vk.apply_rotation_mode, dim=m.particle_count, inputs=[x, self.rotation], outputs=[self.dx], device=m.device
        )

    def color_sweep(self, x, h: float, contacts=None) -> list:
        """One Gauss-Seidel sweep: a recorded launch of the local Newton kernel per colour
        (``contacts``: the colliders' struct, or None), rebuilt only when the positions array, h or
        the colliders change (cuts the Python cost of colours x iterations launches; a recorded
        launch keeps the struct arguments' values of its recording)."""
        colliders = contacts if contacts is not None else self.contacts.none
        sc = self.self_collision
        force, hessian = (
            (sc.vertex_force, sc.vertex_hessian) if sc is not None else (self.no_self_force, self.no_self_hessian)
        )
        key = (x.ptr, h, colliders.records.ptr, colliders.box.ptr, colliders.plane_count, force.ptr)
        if key != self._sweep_key:
            m = self.model
            self._sweep = [
                wp.launch(
                    vk.solve_vertices_vbd,
                    dim=count,
                    inputs=[
                        self.vertex_order,
                        start,
                        x,
                        self.inertia,
                        self.springs,
                        self.hinges,
                        h,
                        colliders,
                        force,
                        hessian,
                    ],
                    outputs=[self.dx, self.contact],
                    device=m.device,
                    record_cmd=True,
                )
                for start, count in zip(self.coloring.starts, self.coloring.counts)
            ]
            self._sweep_key = key
        return self._sweep

    def stats(self) -> dict:
        return {
            "colors": self.coloring.color_count if self.model is not None else 0,
            "vbd_iterations": self.vbd_iterations,
            "vbd_chebyshev_rho": self.vbd_chebyshev_rho,
        }
