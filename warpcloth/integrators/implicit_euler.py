"""Linearised implicit (backward) Euler, Baraff & Witkin 1998 (seed eq. 2.19-2.22).

    (M - h df/dv - h^2 df/dx) dv = h (f + h df/dx v) ;  v <- v + dv ;  x <- x + h v

One Newton step of backward Euler per step h [s] (stable for stiff springs at large h). df/dx is
the spring Jacobian with the compression clamp that keeps A SPD (:mod:`warpcloth.kernels.springs`), or
with ``jacobian="approx"`` the seed's constant eq. 2.23 (assembled once per dt); df/dv the spring
damping and air drag Jacobian; wind is explicit; hinges add Gauss-Newton blocks (:mod:`~warpcloth.integrators.system`);
pinned particles have identity rows and zero columns (dv = 0).

A is applied assembled (``matrix="bsr"``, the default, in the split form (A x)_i = E_i x_i +
sum_j A_ij (x_j - x_i), E_i = m (1 + h c) I + the pinned springs' B_s, so a smooth dv keeps its mass
term in float32) or matrix-free (``matrix="free"``); both give the same A. The solve is preconditioned
CG (``preconditioner``: ``jacobi``, the seed's and the default; ``block_jacobi``; ``multigrid``, a
grid's V-cycle that falls back to block_jacobi elsewhere): ``warp.optim.linear.cg`` with device-side
convergence on CUDA, :class:`~warpcloth.integrators.linalg.DevicePCG` in captured chunks of
``cg_check_every`` on the CPU; warm-started from the previous dv, restarted ``cg_restarts`` times from
the true residual b - A dv, which the statistics judge (:meth:`ImplicitEuler.convergence`).

Contacts (``matrix="bsr"``) enter the solve as Baraff & Witkin's filter (sec. 5.3): S = I - n n^T with
kinetic friction for a sliding contact, S = 0 for a sticking one. ``strain_cap`` (default 0.1) applies
Provot's limit after each step where no ``strain_limit`` is given: one Newton step has no stiffness
across a spring at its rest length, so a landing cloth could stretch without bound. Measurements
behind these choices: docs/solvers.md, "implicit_euler --preconditioner jacobi|block_jacobi|multigrid".
"""

from __future__ import annotations

import math
import sys
from fractions import Fraction
from typing import ClassVar

import warp as wp
from warp.optim.linear import cg

from warpcloth.integrators.base import Integrator, Option, scratch_like
from warpcloth.integrators.forces import eval_forces
from warpcloth.integrators.linalg import DevicePCG, TranslationSolve
from warpcloth.integrators.multigrid import grid_structure_reason
from warpcloth.integrators.system import JACOBIANS, MATRICES, PRECONDITIONERS, ImplicitSystem
from warpcloth.kernels import implicit as ik
from warpcloth.kernels import linalg as lk
from warpcloth.kernels import pins as pk
from warpcloth.kernels import self_contact as sk
from warpcloth.sim.pins import has_pin_tracks


def _check_tol(value: float):
    return None if 0.0 < value < 1.0 else "must be in (0, 1)"


def _check_max_iter(value: int):
    return None if value >= 1 else "must be >= 1"


def _sci(x: float) -> str:
    """Two significant digits, exponents unpadded: 3.7, 0.00055, 1e-5."""
    mantissa, _, exponent = f"{x:.2g}".partition("e")
    return f"{mantissa}e{int(exponent)}" if exponent else mantissa


class ImplicitEuler(Integrator):
    """Baraff-Witkin implicit Euler with Jacobi-preconditioned CG (seed eq. 2.19-2.23)."""

    name = "implicit_euler"
    study_grid: ClassVar[dict] = {
        "full": (
            {"preconditioner": ("jacobi", "multigrid"), "cg_tol": (1e-2, 1e-3, 1e-5)},
            (Fraction(1, 2), 1, 2, 4, 8, 16),
        ),
        "quick": ({"preconditioner": ("jacobi", "multigrid"), "cg_tol": (1e-2, 1e-4)}, (Fraction(1, 2), 1, 4)),
    }
    #: The strain cap (default 0.1, for scenes that land on colliders) is off in the study: it would bind
    #: in the swing and the flag (structural and shear strain up to 0.20 at dt 1/30 s and 0.40 at 1/60 s
    #: on the 32 x 32 sheet without it), so a run with it is another configuration than the ones measured
    #: so far; the study measures the bare scheme (a grid over the cap would be its own axis).
    study_fixed_options: ClassVar[dict] = {"strain_cap": 0.0}
    free_motion_rtol = 0.02  # a free cloth's centroid moves by a CG solve to cg_tol

    @classmethod
    def relative_work(cls, options: dict) -> float:
        """CG iterations grow about as log(1 / cg_tol): one more default solve's worth per 1000x below 1e-3."""
        return max(1.0, math.log10(1e-3 / options["cg_tol"]) / 3.0 + 1.0) if options["cg_tol"] < 1e-3 else 1.0

    force_evals_per_step = 1
    self_contact_filter = "inelastic"  # the repulsion is in the solve
    options = (
        Option("cg_tol", float, 1.0e-3, "CG relative residual tolerance |b - A dv| / |b|", _check_tol),
        Option("cg_max_iter", int, 1000, "CG iteration cap per step", _check_max_iter),
        Option(
            "jacobian",
            str,
            "full",
            "spring Jacobian: full (exact, refilled each step) or approx (seed eq. 2.23, constant)",
            choices=JACOBIANS,
        ),
        Option(
            "preconditioner",
            str,
            "jacobi",
            "CG preconditioner: jacobi (1 / diag A), block_jacobi (the inverse 3 x 3 diagonal blocks of A) or "
            "multigrid (geometric V-cycle on grid models; assembles A as BSR; other models fall back to block_jacobi "
            "with a note on stderr)",
            choices=PRECONDITIONERS,
        ),
        Option(
            "cg_check_every",
            int,
            4,
            "CPU: CG iterations run (as one captured chunk) between host convergence checks; iterations past "
            "convergence within a chunk change nothing (CUDA checks on the device)",
            _check_max_iter,
        ),
        Option(
            "cg_restarts",
            int,
            1,
            "CG restarts per step from the true residual b - A dv (residual replacement: float32 CG's recursive "
            "residual drifts from the true one; each restart costs one product when already converged)",
            check=lambda v: None if v >= 0 else "must be an integer >= 0",
        ),
        Option(
            "strain_cap",
            float,
            0.1,
            "Provot's strain limit tau applied after each step where no --strain-limit is given (0: off): one "
            "linearised step cannot turn a spring far, so where a collider stops a landing vertex and its neighbour "
            "falls on (h v, at 1/60 s more than a spring's length), the spring overstretched and the default drape "
            "and tablecloth went unstable (docs/solvers.md)",
            check=lambda v: None if v >= 0.0 else "must be >= 0 (0: off)",
        ),
        Option(
            "matrix",
            str,
            "bsr",
            "system matrix CG applies: bsr (assembled 3 x 3 blocks, refilled each step; the faster on the CPU, see "
            "bench/implicit.py) or free (matrix-free, gathering over each particle's springs)",
            choices=MATRICES,
        ),
    )

    def default_strain_limit(self) -> float | None:
        return self.strain_cap if self.strain_cap > 0.0 else None

    # -- binding -----------------------------------------------------------------------
    def _allocate(self, model):
        n, device = model.particle_count, model.device
        self.b, self.dv = scratch_like(model, 2)
        self.pin_dv = wp.zeros(n, dtype=wp.vec3)  # prescribed dv of kinematic pins (0 elsewhere)
        self.preconditioner_used = self.preconditioner
        if self.preconditioner == "multigrid":
            reason = grid_structure_reason(model)
            if reason:
                print(
                    f"warpcloth: note: implicit_euler: multigrid needs a grid model ({reason}); using block_jacobi",
                    file=sys.stderr,
                )
                self.preconditioner_used = "block_jacobi"
        #: The system A dv = b's matrix, operator and preconditioner (:mod:`warpcloth.integrators.system`).
        self.system = ImplicitSystem(model, self.jacobian, self.matrix, self.preconditioner_used)
        # its pieces, also under the names tests and diagnostics read: the BSR matrix (None with
        # matrix="free" and no multigrid), the preconditioner and the operator CG apply, Jacobi's 1 / diag A
        self.A, self.M, self.A_op, self.inv_diag = self.system.A, self.system.M, self.system.A_op, self.system.inv_diag
        self.multigrid = self.system.multigrid
        #: The colliders' contacts seen by the solve, phase by phase (:class:`FilteredContacts`).
        self.contacts = FilteredContacts(model, self.system, self.b, self.dv, enabled=self.matrix == "bsr")
        # its per-particle arrays under the names the self-contact product, tests and diagnostics read
        self.contact_normal, self.contact_mode = self.contacts.normal, self.contacts.mode
        # device-side convergence needs conditional graph nodes (CUDA driver and toolkit 12.4+)
        is_cuda = wp.get_device(device).is_cuda
        self._device_side = is_cuda and wp.is_conditional_graph_supported()
        # CUDA: warp's cg, convergence checked on the device (conditional graph), no host sync
        self.solver = (
            cg(
                self.A_op,
                self.b,
                self.dv,
                tol=self.cg_tol,
                atol=0.0,
                maxiter=self.cg_max_iter,
                M=self.M,
                check_every=0,
                use_cuda_graph=True,
                run=False,
            )
            if self._device_side
            else None
        )
        # CPU: our own PCG, its scalars on the device, checked on the host every cg_check_every iterations
        self.pcg = (
            None
            if self._device_side
            else DevicePCG(
                self.A_op.matvec,
                self.M.matvec,
                self.b,
                self.dv,
                self.cg_tol,
                self.cg_max_iter,
                self.cg_check_every,
                device,
            )
        )
        # the true residual |b - A dv| / |b| and the float32 floor estimate |A delta| / |b| of each solve, on the device
        self.true_r, self.rounding, self.rounding_Ax = scratch_like(model, 3)
        self.residual_terms = wp.zeros(n, dtype=wp.vec3d)
        self.residual_chunk = max(1, -(-n // 128))
        self.residual_partial = wp.zeros(-(-n // self.residual_chunk), dtype=wp.vec3d)
        self._stats = wp.zeros(12, dtype=wp.float64)  # kernels.implicit.record_cg_stats: slot 11 a step's passes
        # the translation correction after a solve with self-collision (translation_correction): T's columns,
        # A T, and the 3 x 3 Galerkin problem (its regular term as vbd's: 1e-6 of the free mass)
        self.translation_basis = scratch_like(model, 3)
        self.translation_image = scratch_like(model, 3)
        host = model.host
        free_mass = float(host.mass.astype("float64")[host.inv_mass > 0].sum())
        self.translation = TranslationSolve(n, 1.0e-6 * free_mass, device)
        self.reset_stats()

    # -- stepping ------------------------------------------------------------------------
    def capturable_on(self, device) -> bool:
        """On CUDA, CG checks convergence on the device (a conditional graph node), so a frame
        can be captured; on the CPU (or without conditional graph nodes) it reads its residual on
        the host."""
        return wp.get_device(device).is_cuda and wp.is_conditional_graph_supported()

    def set_self_collision(self, self_collision) -> None:
        """Self-contacts in the solve: their repulsion k delta n in b and its Jacobian h^2 k W W^T n n^T
        in A (a product over the contacts after every product with A, filtered by the colliders'
        constraints like A; the preconditioner without it)."""
        super().set_self_collision(self_collision)
        if self.model is None:
            return
        self.system.extra_product = self._self_contact_product if self_collision is not None else None
        if self.pcg is not None:
            self.pcg.reset()  # its captured chunks hold the products

    def _self_contact_product(self, y, z, alpha: float, filtered: bool) -> None:
        """z += alpha h^2 k C y (C: the contacts' blocks W_a W_b n n^T; S C S where ``filtered``)."""
        sc, m = self.self_collision, self.model
        wp.launch(
            ik.add_self_contact_product,
            dim=m.particle_count,
            inputs=[
                m.particle_count,
                sc.counts,
                sk.CONTACTS,
                self._x,
                m.particle_inv_mass,
                sc.contact_indices,
                sc.contact_weights,
                sc.contact_normals,
                sc.contact_thickness,
                self.contact_mode,
                self.contact_normal,
                int(filtered),
                float(alpha) * self.system.h * self.system.h * sc.stiffness,
                y,
            ],
            outputs=[z],
            device=m.device,
        )

    def begin(self, state, control, dt):
        if self.self_collision is not None and self.pcg is not None:
            self.pcg.reset()  # the captured chunks' self-contact product holds h^2 k
        self.dv.zero_()
        self.contacts.reset()  # no contact history across an outside change of the state
        self.system.invalidate()

    def default_dt(self, model, drag_rate: float = 0.0) -> float:
        """One 60 Hz frame, :attr:`default_dt_cap`: the scheme is stable at any dt."""
        return self.default_dt_cap

    def step(self, state, control, dt):
        m, h = self.model, float(dt)
        x, v, f = state.particle_q, state.particle_qd, state.particle_f
        self._x = x  # the positions the self-contact product reads (the step's start)
        eval_forces(m, x, v, control, f)
        self.system.assemble(x, h, float(control.drag_rate))
        self.eval_rhs(x, v, f, h)
        self.add_pinned_rhs(control, x, v, h)
        self.add_self_contact_rhs(x, v, h)
        filtered = self.contacts.before_solve(control, x, v, f, h)  # the colliders' filter on A dv = b
        self.system.update_preconditioner(h, float(control.drag_rate), filtered)
        self._solve()
        self.contacts.after_solve(v)
        wp.launch(
            ik.integrate_implicit_euler,
            dim=m.particle_count,
            inputs=[x, v, self.dv, m.particle_inv_mass, h],
            device=m.device,
        )
        self.contacts.finish(x)

    def eval_rhs(self, x, v, f, h: float) -> None:
        """b = h (f + h df/dx v), the springs' and the dihedral hinges' (-h^2 sum_e k_e g (g . v))."""
        m, s = self.model, self.system
        wp.launch(
            ik.eval_rhs,
            dim=m.particle_count,
            inputs=[f, v, s.springs, s.spring_K, m.particle_inv_mass, h],
            outputs=[self.b],
            device=m.device,
        )
        s.add_hinge_rhs(v, self.b, h)

    def add_pinned_rhs(self, control, x, v, h: float) -> None:
        """Kinematic pins (nothing without): their dv = (track(t + h) - x) / h - v, prescribed, and its
        coupling moved to the free rows' right side, b -= (h^2 K + h D) dv_pin (springs and hinges)."""
        if not has_pin_tracks(control):
            return
        m, s = self.model, self.system
        control.kinematic_pins.delta(control, x, v, h, 1.0 / h, 1.0, self.pin_dv)
        wp.launch(
            pk.add_pinned_coupling,
            dim=m.particle_count,
            inputs=[s.springs, s.spring_B, m.particle_inv_mass, self.pin_dv],
            outputs=[self.b],
            device=m.device,
        )
        s.add_hinge_product(self.pin_dv, self.b, -h * h, -h, 0)  # the hinges' -(h^2 k + h kd) g (g . dv_pin)

    def add_self_contact_rhs(self, x, v, h: float) -> None:
        """The self-contacts' repulsion and their h^2 df/dx v in b (nothing without self-collision)."""
        sc, m = self.self_collision, self.model
        if sc is None:
            return
        wp.launch(
            ik.add_self_contact_rhs,
            dim=m.particle_count,
            inputs=[
                m.particle_count,
                sc.counts,
                sk.CONTACTS,
                x,
                v,
                m.particle_inv_mass,
                sc.contact_indices,
                sc.contact_weights,
                sc.contact_normals,
                sc.contact_thickness,
                sc.stiffness,
                h,
            ],
            outputs=[self.b],
            device=m.device,
        )

    def _solve(self) -> None:
        """dv = A^-1 b by preconditioned CG from the previous dv, restarted ``cg_restarts`` times
        from the true residual; records iterations and the final relative residual |r| / |b| CG
        reports, then the true one (:meth:`_record_true_residual`)."""
        if self._device_side:
            for _ in range(self.cg_restarts):
                iterations, residual_sq, tolerance_sq = self.solver()
                wp.launch(
                    ik.add_cg_iterations, dim=1, inputs=[iterations], outputs=[self._stats], device=self.model.device
                )
            iterations, residual_sq, tolerance_sq = self.solver()
            wp.launch(
                ik.record_cg_stats,
                dim=1,
                inputs=[iterations, residual_sq, tolerance_sq, float(self.cg_tol)],
                outputs=[self._stats],
                device=self.model.device,
            )
        else:
            total = 0
            for _ in range(1 + self.cg_restarts):  # a restart from a converged dv: one product and r.r, no iteration
                iterations, relative, converged = self.pcg.solve()
                total += iterations
                if not converged:  # at the iteration cap: no restart (the cap bounds a step's iterations)
                    break
            s = self._host_stats
            s[0] += 1
            s[1] += total
            s[2] = max(s[2], total)
            s[3] += relative
            s[4] = max(s[4], relative)
            s[5] += not converged  # ended above its tolerance: at the cap (or NaN)
        self.translation_correction()
        self._record_true_residual()

    def translation_correction(self) -> None:
        """With self-collision: dv += T t, t = (T^T A T)^-1 T^T (b - A dv), T's columns the solve's unknowns
        moved rigidly along x, y, z (filtered by the colliders' contacts, pinned particles fixed): the
        Galerkin step of the translation mode, zero where CG converged. Springs, hinges and the self-contacts'
        equal and opposite terms exert no net force, so on a free cloth T^T A T = M I and afterwards
        sum m dv = sum b exactly: the momentum law of backward Euler, which CG's residual broke by its sum
        (a 15 m/s two-layer closing lost 3e-3 kg m/s at cg_tol 1e-3 and 1.8e-6 at 1e-10; docs/self-collision.md).
        Nothing without self-collision (contact-free runs bit-identical)."""
        if self.self_collision is None:
            return
        m, d, rigid = self.model, self.model.device, self.translation
        t0, t1, t2 = self.translation_basis
        a0, a1, a2 = self.translation_image
        c = self.contacts
        wp.launch(
            ik.translation_basis,
            dim=m.particle_count,
            inputs=[c.mode, c.normal, m.particle_inv_mass, int(c.active)],
            outputs=[t0, t1, t2],
            device=d,
        )
        for t, a in zip(self.translation_basis, self.translation_image):
            self.A_op.matvec(t, a, a, 1.0, 0.0)
        self.A_op.matvec(self.dv, self.b, self.true_r, -1.0, 1.0)  # r = b - A dv
        wp.launch(
            ik.translation_terms,
            dim=m.particle_count,
            inputs=[t0, t1, t2, a0, a1, a2, self.true_r],
            outputs=[rigid.b, rigid.A],
            device=d,
        )
        rigid.solve()
        wp.launch(
            ik.add_translation,
            dim=m.particle_count,
            inputs=[rigid.translation, t0, t1, t2],
            outputs=[self.dv],
            device=d,
        )

    def _record_true_residual(self) -> None:
        """The solve's true residual |b - A dv| / |b| (A the solve's operator, contacts filtered;
        float32 products, float64 sums in a fixed order) and the float32 floor estimate
        |A delta| / |b|, delta a random rounding of dv to float32 (the true residual of the exact
        solution rounded to float32, within 3 % on the 32 x 32 sheet), into the device
        statistics: kernel launches only, no host read, nothing allocated."""
        m, d = self.model, self.model.device
        n = m.particle_count
        self.A_op.matvec(self.dv, self.b, self.true_r, -1.0, 1.0)
        wp.launch(lk.rounding_perturbation, dim=n, inputs=[self.dv, 12345], outputs=[self.rounding], device=d)
        self.A_op.matvec(self.rounding, self.rounding_Ax, self.rounding_Ax, 1.0, 0.0)
        wp.launch(
            lk.residual_terms,
            dim=n,
            inputs=[self.b, self.true_r, self.rounding_Ax],
            outputs=[self.residual_terms],
            device=d,
        )
        wp.launch(
            lk.sum_chunks3,
            dim=self.residual_partial.shape[0],
            inputs=[self.residual_terms, self.residual_chunk, n],
            outputs=[self.residual_partial],
            device=d,
        )
        wp.launch(
            ik.record_true_residual,
            dim=1,
            inputs=[self.residual_partial, float(self.cg_tol)],
            outputs=[self._stats],
            device=d,
        )

    # -- statistics ----------------------------------------------------------------------
    def stats(self) -> dict:
        """CG iterations and final relative residual |b - A dv| / |b| per step (mean and max),
        and ``cg_capped_steps``: the steps whose CG ended at ``cg_max_iter`` above ``cg_tol``.
        On CUDA this is the run's one read of the device-side counters. ``cg_true_residual_*``: the
        true |b - A dv| / |b| of each solve, recomputed at its end; ``cg_float32_floor_*``: the
        float32 floor estimate; ``cg_true_above_tol_steps``: the steps whose true residual missed
        ``cg_tol``."""
        device = self._stats.numpy()
        s = device if self._device_side else self._host_stats
        solves = int(s[0])
        return {
            "jacobian": self.jacobian,
            "cg_tol": self.cg_tol,
            "cg_max_iter": self.cg_max_iter,
            "cg_solves": solves,
            "cg_iterations_mean": float(s[1] / solves) if solves else 0.0,
            "cg_iterations_max": int(s[2]),
            "cg_residual_mean": float(s[3] / solves) if solves else 0.0,
            "cg_residual_max": float(s[4]),
            "cg_capped_steps": int(s[5]),
            "cg_restarts": self.cg_restarts,
            "cg_true_residual_mean": float(device[6] / solves) if solves else 0.0,
            "cg_true_residual_max": float(device[7]),
            "cg_true_above_tol_steps": int(device[9]),
            "cg_float32_floor_mean": float(device[10] / solves) if solves else 0.0,
            "cg_float32_floor_max": float(device[8]),
        }

    def convergence(self, stats: dict) -> tuple[bool | None, int, str | None]:
        """Converged when every step's *true* residual |b - A dv| / |b| (recomputed at the end of
        its solve) is within ``cg_tol`` and no CG hit its cap; else the count of those steps and
        one warning line: where the tolerance is below the float32 floor estimate, naming that
        floor; else the iteration-cap count and the worst residuals, or the worst true residual."""
        capped, solves = stats["cg_capped_steps"], stats["cg_solves"]
        above = max(stats["cg_true_above_tol_steps"], capped)
        if not above:
            return True, 0, None
        floor, worst = stats["cg_float32_floor_max"], stats["cg_true_residual_max"]
        if floor >= 0.5 * self.cg_tol:
            return (
                False,
                above,
                (
                    f"{self.name}: cg_tol {_sci(self.cg_tol)} is below what float32 reaches on this model: the exact "
                    f"solution rounded to float32 leaves |b - A dv| / |b| ~ {_sci(floor)} (estimated floor; use a "
                    f"tolerance above it); {above} of {solves} steps ended above the tolerance (worst true residual "
                    f"{_sci(worst)})"
                ),
            )
        if capped:
            return (
                False,
                above,
                (
                    f"{self.name}: CG hit its {self.cg_max_iter}-iteration cap in {capped} of {solves} steps (worst "
                    f"final relative residual {_sci(stats['cg_residual_max'])} > tolerance {_sci(self.cg_tol)}; true "
                    f"|b - A dv| / |b| above it in {stats['cg_true_above_tol_steps']} steps, worst {_sci(worst)}); "
                    "the result does not meet the tolerance asked"
                ),
            )
        return (
            False,
            above,
            (
                f"{self.name}: the true residual |b - A dv| / |b| ended above the tolerance in {above} of {solves} "
                f"steps (worst {_sci(worst)} > tolerance {_sci(self.cg_tol)}; CG's own residual met it; raise "
                "cg_restarts); the result does not meet the tolerance asked"
            ),
        )

    def capped_steps(self, stats: dict) -> int:
        """The steps whose CG ended at ``cg_max_iter`` above ``cg_tol`` (counted on the device on CUDA)."""
        return int(stats["cg_capped_steps"])

    def cap_advice(self) -> list:
        """A larger ``cg_max_iter``; a multigrid preconditioner where the model is a grid and another is
        used (Jacobi's iterations grow as the grid refines; the V-cycle's do not: docs/solvers.md), else
        block Jacobi in place of Jacobi (the refined cantilever strip converged with it, docs/materials.md)."""
        advice = [f"a larger --cg-max-iter (now {self.cg_max_iter}, above --cg-tol {_sci(self.cg_tol)})"]
        used = self.preconditioner_used
        if used != "multigrid" and self.model is not None and not grid_structure_reason(self.model):
            advice.append(f"--preconditioner multigrid (now {used})")
        elif used == "jacobi":
            advice.append("--preconditioner block_jacobi (now jacobi)")
        return advice

    def reset_stats(self) -> None:
        self._host_stats = [0, 0, 0, 0.0, 0.0, 0]
        if self.model is not None:
            self._stats.zero_()


class FilteredContacts:
    """The colliders' contacts seen by implicit Euler's solve (Baraff & Witkin 1998, sec. 5.3), bound once to
    a model and its system A dv = b, by phase of a step:

    - :meth:`before_solve`: each particle's contact mode, and the filter S with the prescribed dv z on A and b;
    - :meth:`after_solve`: dv = S y + z, the constraint impulses kept, Coulomb's caps on friction;
    - :meth:`finish`: which particles ended inside a collider (they become contacts next step);
    - :meth:`reset`: no contact history (an outside change of the state).

    Active only with ``enabled`` (an assembled A, ``matrix="bsr"``) and colliders present; otherwise every
    phase does nothing and the collider projection after the step alone acts. Nothing is allocated after
    binding.
    """

    def __init__(self, model, system: ImplicitSystem, b, dv, enabled: bool):
        n = model.particle_count
        self.model, self.system, self.b, self.dv, self.enabled = model, system, b, dv, enabled
        #: Whether this step's solve sees contacts (set by :meth:`before_solve`).
        self.active = False
        self._collision = None
        # per particle: the contact's normal (0: none), prescribed dv, A z and b before the filter
        self.normal, self.prescribed_dv, self.Az, self.unfiltered_b = scratch_like(model, 4)
        self.friction = wp.zeros(n, dtype=float)
        # collider velocity at the contact, friction impulse; per particle: mode (0 none, 1 slide, 2 stick,
        # 3 slid and stopped), the solve's constraint impulse and "ended inside a collider", each kept for
        # the next step's modes
        self.collider_v, self.impulse, self.friction_impulse = scratch_like(model, 3)
        self.mode = wp.zeros(n, dtype=int)
        self.entered = wp.zeros(n, dtype=int)
        # A before the contact filter (friction impulses)
        self.unfiltered_values = wp.zeros_like(system.A.values) if system.bsr else None

    def reset(self) -> None:
        """No contact history: modes, impulses and "entered" zeroed."""
        self.mode.zero_()
        self.impulse.zero_()
        self.entered.zero_()

    def before_solve(self, control, x, v, f, h: float) -> bool:
        """The contacts seen by the solve (the filter S), chosen per particle by
        :func:`~warpcloth.kernels.implicit.eval_contact_modes`: a sliding contact gets S = I - n n^T, the
        prescribed normal dv z = -min(0, v_r . n) n (it stops approaching; v_r = v - v_c relative to the
        collider) and a kinetic friction impulse F on the right side; a sticking one S = 0 and also
        z_t = -v_r,t (it moves with the collider). CG solves S A S y = S (b + F - A z) for the rest, dv =
        S y + z; :meth:`after_solve` then keeps each contact's impulse for the next step's modes and caps
        friction (Coulomb). Returns whether the solve sees contacts (A's values filtered).

        Why the modes keep history: a contact chosen by the force at the step's start alone
        (f . n < 0) flipped every other step in the 16 x 16 drape, where the implicit coupling
        pushes a particle at the cloth's line of contact in although its explicit force points out
        (f . n = +0.003..0.03 N): unconstrained it fell 1.3 mm (26 % of the thickness) into the
        sphere at 0.08 m/s, the projection pushed it back, and its neighbour rang at ~0.02 m/s
        for good. Now a contact stays while the solve's impulse pushes (J . n > 0), and a particle
        the solve moved inside becomes one. Friction applied after the solve is not seen by the
        neighbours (with it, the drape's stick-slip contacts kept their neighbours moving at up to
        0.05 m/s), so a contact that friction can hold sticks in the solve (released when the
        solve's |J_t| > mu J_n) and a sliding one's friction is in the solve."""
        collision = control.collision
        self.active = self.enabled and collision is not None and len(collision.colliders) > 0
        self._collision = collision if self.active else None
        if not self.active:
            return False
        m, s = self.model, self.system
        wp.launch(
            ik.eval_contact_modes,
            dim=m.particle_count,
            inputs=[
                x,
                v,
                f,
                m.particle_mass,
                m.particle_inv_mass,
                collision.params,
                wp.vec3(*control.gravity),
                h,
                self.entered,
                self.impulse,
            ],
            outputs=[self.mode, self.normal, self.friction, self.collider_v, self.friction_impulse],
            device=m.device,
        )
        wp.launch(
            ik.eval_contact_dv,
            dim=m.particle_count,
            inputs=[self.mode, self.normal, self.collider_v, v],
            outputs=[self.prescribed_dv],
            device=m.device,
        )
        wp.copy(self.unfiltered_values, s.A.values)
        wp.copy(self.unfiltered_b, self.b)
        s.bsr_matvec(self.prescribed_dv, self.Az, self.Az, 1.0, 0.0, row_part=s.row_part)  # A before the filter
        wp.launch(
            ik.filter_system_rows,
            dim=m.particle_count,
            inputs=[s.row_offsets, s.block_columns, s.diag_block, self.mode, self.normal, s.row_part],
            outputs=[s.A.values, s.inv_diag, s.row_part_solve],
            device=m.device,
        )
        wp.launch(
            ik.filter_rhs,
            dim=m.particle_count,
            inputs=[self.mode, self.normal, self.Az, self.friction_impulse],
            outputs=[self.b, self.dv],
            device=m.device,
        )
        s.invalidate()  # A.values now hold this step's filter: reassemble next step
        return True

    def after_solve(self, v) -> None:
        """dv = S y + z, the constraint impulse J = A dv - b of the unfiltered system on each particle
        (kept for the next step's modes), then Coulomb's caps: a sliding contact that friction reversed
        stops; a stuck one past the cone slips by the excess."""
        if not self.active:
            return
        m, s = self.model, self.system
        wp.launch(
            ik.unfilter_dv,
            dim=m.particle_count,
            inputs=[self.mode, self.normal, self.prescribed_dv],
            outputs=[self.dv],
            device=m.device,
        )
        s.bsr_matvec(self.dv, self.unfiltered_b, self.Az, -1.0, 1.0, values=self.unfiltered_values, row_part=s.row_part)
        wp.launch(
            ik.apply_contact_friction,
            dim=m.particle_count,
            inputs=[
                self.mode,
                self.normal,
                self.friction,
                self.collider_v,
                self.Az,
                v,
                m.particle_mass,
                self.unfiltered_values,
                s.diag_block,
                self.friction_impulse,
            ],
            outputs=[self.dv, self.impulse],
            device=m.device,
        )

    def finish(self, x) -> None:
        """Marks the particles the step ended inside a collider (kept for the next step's modes)."""
        if not self.active:
            return
        m = self.model
        wp.launch(
            ik.mark_entered,
            dim=m.particle_count,
            inputs=[x, m.particle_inv_mass, self._collision.params, self.mode],
            outputs=[self.entered],
            device=m.device,
        )
