"""Projective dynamics for mass-spring systems, Liu, Bargteil, O'Brien & Kavan 2013.

    dy = h v + h^2 f_ext / m ;  dx = h v
    repeat pd_iterations times:
        local:  d_s = L0 e_s / |e_s|                       (each spring projected to its rest length)
        global: (M + h D + h^2 L) dx = M dy + h^2 (J d - L x)   (pd_cg_iterations of Jacobi PCG,
                                                             warm-started at the previous dx)
    v = dx / h ;  x += dx

L = sum_s ks A_s^T A_s [N/m] is the Laplacian of the spring graph weighted by ks, the same for x, y
and z and constant for a fixed dt and topology, so S = M + h D + h^2 L is assembled once per dt (a
scalar CSR matrix, :mod:`warpcloth.kernels.projective`). Converged, a step is backward Euler.

Damping: the residual carries the spring's kd along the spring, kd ((v_j - v_i) . n) n with
v = dx / h, and S its isotropic D = sum_s kd A_s^T A_s as an approximate Jacobian, so the iteration
converges to axial damping and a rigid rotation is not damped. Gravity, drag and wind are explicit;
from x + h v a rest state is the exact static equilibrium; pinned rows are identity (dx = 0).
Dihedral hinges add h^2 sum_e k_e c c^T + h sum_e kd_e c c^T to S and their true forces to the
residual; S's isotropic h^2 L makes bending converge slowly at large dt (docs/materials.md).

Rigid translation (``pd_rigid_mode``, default 1): before each global CG, without colliders, the
Galerkin step on the translation solves the cloth's mean motion exactly (T^T S T is the sum of S's
free rows): a few Jacobi-PCG iterations alone bent a falling cloth and gained energy (docs/solvers.md,
"projective", measures this and the damping form).
"""

from __future__ import annotations

from fractions import Fraction
from typing import ClassVar

import numpy as np
import warp as wp

from warpcloth.integrators.base import Option, scratch_like
from warpcloth.integrators.increment import IncrementSolver, at_least_one
from warpcloth.integrators.linalg import OrderedSum
from warpcloth.kernels import projective as pk
from warpcloth.sim.hinges import hinge_pairs, hinge_rest_coefficients


class Projective(IncrementSolver):
    """Projective dynamics (Liu et al. 2013): local spring projection, global constant-matrix solve."""

    name: ClassVar[str] = "projective"
    study_grid: ClassVar[dict] = {
        "full": ({"pd_iterations": (1, 5, 20), "pd_cg_iterations": (5, 20)}, (Fraction(1, 2), 1, 2, 4, 8)),
        "quick": ({"pd_iterations": (1, 20), "pd_cg_iterations": (5, 20)}, (Fraction(1, 2), 1, 4)),
    }
    free_motion_rtol: ClassVar[float] = 0.02  # the centroid moves by a fixed number of CG iterations

    @classmethod
    def relative_work(cls, options: dict) -> float:
        """Local/global iterations x (a local step and a global one's CG iterations, ~2 + cg)
        against the defaults'."""
        defaults = cls.option_defaults()
        per = lambda it, cg: it * (2.0 + cg)  # noqa: E731 (local step + CG iterations)
        return per(options["pd_iterations"], options["pd_cg_iterations"]) / per(
            defaults["pd_iterations"], defaults["pd_cg_iterations"]
        )

    self_contact_filter: ClassVar[str] = "gap"  # contacts are constraints of its iterations
    options = (
        Option("pd_iterations", int, 10, "local/global iterations per time step (>= 1)", check=at_least_one),
        Option(
            "pd_cg_iterations",
            int,
            10,
            "Jacobi-preconditioned CG iterations per global solve, fixed (>= 1)",
            check=at_least_one,
        ),
        Option(
            "pd_rigid_mode",
            int,
            1,
            "1: each global solve first solves its rigid translation exactly (a Galerkin step on T; without "
            "colliders), then CG; 0: CG alone",
            check=lambda v: None if v in (0, 1) else "must be 0 or 1",
        ),
        Option(
            "pd_contact_weight",
            float,
            0.1,
            "with self-collision: the weight of a self-contact's projective constraint in the global solve, in "
            "units of the largest S_ii / m_i of the springs (finite, > 0)",
            check=lambda v: None if 0 < v < float("inf") else "must be finite and > 0",
        ),
    )

    def _allocate_solver(self, model) -> None:
        n = model.particle_count
        offsets, other = self.springs.offsets.numpy(), self.springs.other.numpy()
        # CSR of S: row i = [diagonal, one entry per adjacent spring (neighbour order), the pairs a dihedral
        # hinge couples that no spring does]
        extra = _hinge_only_pairs(model, offsets, other)
        extra_count = np.bincount(extra[:, 0], minlength=n) if extra.size else np.zeros(n, dtype=np.int64)
        row_offsets = offsets + np.arange(n + 1, dtype=np.int32) + np.concatenate([[0], np.cumsum(extra_count)])
        columns = np.empty(int(row_offsets[-1]), dtype=np.int32)
        starts = row_offsets[:-1]
        columns[starts] = np.arange(n, dtype=np.int32)
        degree = np.diff(offsets)
        spring_slot = np.repeat(starts + 1, degree) + (np.arange(degree.sum()) - np.repeat(offsets[:-1], degree))
        columns[spring_slot] = other
        if extra.size:  # rows sorted by particle: each row's extras after its springs
            order = np.argsort(extra[:, 0], kind="stable")
            rows_e, cols_e = extra[order, 0], extra[order, 1]
            first = np.concatenate([[0], np.cumsum(extra_count)])[:-1]
            columns[(starts + 1 + degree)[rows_e] + (np.arange(rows_e.size) - first[rows_e])] = cols_e
        self.row_offsets = wp.array(row_offsets.astype(np.int32), dtype=int)
        self.columns = wp.array(columns, dtype=int)
        self.values = wp.zeros(columns.size, dtype=float)
        self.hinge_K = self.hinge_D = None
        if model.hinge_count:  # S's constant hinge part, sum_e k_e c c^T and sum_e kd_e c c^T per CSR entry
            self.hinge_K, self.hinge_D = (
                wp.array(a, dtype=float) for a in _hinge_matrix_terms(model, row_offsets, columns)
            )
        self.inv_diag = wp.zeros(n, dtype=float)
        self.r, self.z, self.p, self.Ap = scratch_like(model, 4)
        # the self-contacts in the global system (add_self_contact_terms): the projected dx, the diagonal
        # weights W (0 without contacts) and the Jacobi preconditioner of S + W
        self.contact_target = scratch_like(model, 1)
        self.contact_weight = wp.zeros(n, dtype=float)
        self.precond = wp.zeros(n, dtype=float)
        self._stiffness_per_mass, self._damping_per_mass = _largest_rates_per_mass(model)
        self.rz = wp.zeros(self.pd_cg_iterations + 1, dtype=float)
        self.pAp = wp.zeros(self.pd_cg_iterations, dtype=float)
        self.dot = OrderedSum(n, model.device)  # dot products in a fixed order
        self._assembled_for = None

    def begin(self, state, control, dt):
        self._assembled_for = None
        # no self-contact weight outlives a change of self-collision (set_self_collision(None) between runs:
        # the last iteration's W would stay in S for good, a review found)
        self.contact_weight.zero_()

    def step(self, state, control, dt):
        h = float(dt)
        x = state.particle_q
        self.assemble(h)
        colliders = self.predict(state, control, h)  # a kinematic pin's dx: known, enters the residual
        held = self.held_inverse_mass(x, control)
        for _ in range(self.pd_iterations):
            self.local_step(x, h)
            if self.self_collision is not None:  # the self-contacts as projective constraints of the global solve
                self.self_contact_step(x, h, held)
            # the rigid translation before every global solve (before the first one only, the sheet gained energy)
            if self.pd_rigid_mode and colliders is None:
                self.translation_step()
            self.global_step()
            if self.self_collision is not None:  # self-contacts as constraints on dx, then the colliders (they win)
                self.project_self_contacts(x, held)
            if colliders is not None:
                self.solve_contacts(x, h, colliders)
                self.contacts.after_iteration(x, self.dx)
        self.finish(state, control, h)

    def held_inverse_mass(self, x, control):
        """With self-collision and colliders, the vertices' 1/m with 0 where a layer lies on a collider
        (it stays there: :meth:`SelfCollision.held_inverse_mass
        <warpcloth.sim.self_collision.SelfCollision.held_inverse_mass>`); else None (the model's)."""
        if self.self_collision is None or self.contacts.colliders is None:
            return None
        return self.self_collision.held_inverse_mass(x, control.collision)

    def project_self_contacts(self, x, held) -> None:
        """The self-contacts as constraints on dx after a global solve (``held``: the vertices' 1/m, None the
        model's); without colliders the global system's rigid translation first: the truncated CG's residual
        no longer sums to zero where the contacts bent dx (the total momentum moved by up to 7e-4 kg m/s a
        step in a free two-layer collision)."""
        if self.pd_rigid_mode and self.contacts.colliders is None:
            self.translation_step()
        self.self_collision.project_increment(x, self.dx, held)

    def solve_contacts(self, x, h: float, contacts) -> None:
        """Contacts after a global step (:func:`warpcloth.kernels.projective.solve_contacts`): the
        held particles' constrained local Newton step, the others out of the colliders; the new
        contact set is held in the next global step."""
        m = self.model
        wp.launch(
            pk.solve_contacts,
            dim=m.particle_count,
            inputs=[x, self.dx, self.inertia, self.springs, self.hinges, h, contacts],
            outputs=[self.Ap, self.contact],
            device=m.device,
        )
        wp.copy(self.dx, self.Ap)

    def assemble(self, h: float) -> None:
        """Fill S = M + h D + h^2 L and its inverse diagonal, when h or the model changed."""
        m = self.model
        if self._assembled_for == h:
            return
        if self.hinge_K is not None:
            self.values.zero_()  # the hinge-only entries (assemble_global_matrix writes the springs')
        wp.launch(
            pk.assemble_global_matrix,
            dim=m.particle_count,
            inputs=[self.springs, self.row_offsets, m.particle_mass, m.particle_inv_mass, h],
            outputs=[self.values, self.inv_diag],
            device=m.device,
        )
        if self.hinge_K is not None:
            wp.launch(
                pk.add_hinge_matrix_terms,
                dim=m.particle_count,
                inputs=[self.row_offsets, self.hinge_K, self.hinge_D, m.particle_inv_mass, h],
                outputs=[self.values, self.inv_diag],
                device=m.device,
            )
        self._assembled_for = h

    def local_step(self, x, h: float) -> None:
        """Project every spring to its rest length and form the global residual r (and CG's start)."""
        m = self.model
        wp.launch(
            pk.eval_local_residual,
            dim=m.particle_count,
            inputs=[x, self.dx, self.inertia, self.springs, self.inv_diag, h, self.contact],
            outputs=[self.r, self.z, self.p, self.dot.terms],
            device=m.device,
        )
        if m.hinge_count:  # + h^2 times the hinges' forces
            wp.launch(
                pk.add_hinge_residual,
                dim=m.particle_count,
                inputs=[x, self.dx, self.inertia, self.hinges, self.inv_diag, h, self.contact],
                outputs=[self.r, self.z, self.p, self.dot.terms],
                device=m.device,
            )
        self._reduce(self.rz, 0)

    def self_contact_step(self, x, h: float, held) -> None:
        """The self-contacts in the next global solve (:func:`warpcloth.kernels.projective.add_self_contact_terms`):
        the contacts' projection of the current dx (one Jacobi pass, :meth:`SelfCollision.project_increment
        <warpcloth.sim.self_collision.SelfCollision.project_increment>`) is each moved vertex's target, held
        with a weight W_i = pd_contact_weight (1 + h^2 k_max + h kd_max) m_i on S's diagonal (k_max, kd_max:
        the largest sum of a vertex's spring stiffnesses and dampings per unit mass; 1 + ... is the largest
        S_ii / m_i of the springs, a scale: dihedral hinges are left out). Without it the global solve did not
        see the contacts that the projection after it enforced, and the two fought: two free layers closing
        8 mm a step crumpled by up to 7 cm in y in 0.1 s, worse with more iterations (10 cm at 40); with it
        each layer's y range is 5.7 mm at 0.06 s (13 mm at weight 0.01, 7 mm at 0.03 and 0.3, 9 mm at 1).
        The default 0.1: a stiffer weight fights the pins and the ground where the fold's hand presses a
        layer into another (the fold's peak strain 0.29 for one frame at weight 1, 1.21 at 10; 0.051 at 0.1,
        as without the contacts in the solve)."""
        m = self.model
        wp.copy(self.contact_target, self.dx)
        self.self_collision.project_increment(x, self.contact_target, held)
        per_mass = self.pd_contact_weight * (1.0 + h * h * self._stiffness_per_mass + h * self._damping_per_mass)
        wp.launch(
            pk.add_self_contact_terms,
            dim=m.particle_count,
            inputs=[self.dx, self.contact_target, self.inertia, self.contact_state, per_mass, self.inv_diag],
            outputs=[self.contact_weight, self.precond, self.r, self.z, self.p, self.dot.terms],
            device=m.device,
        )
        self._reduce(self.rz, 0)

    def _system(self):
        """(W, its targets, the Jacobi preconditioner) of the global solve: S's own without self-contacts."""
        if self.self_collision is None:
            return self.contact_weight, self.dx, self.inv_diag
        return self.contact_weight, self.contact_target, self.precond

    def translation_step(self) -> None:
        """The global system's rigid translation solved exactly before CG (issue 26): t =
        (T^T S T)^-1 T^T r, dx += t, r -= S T t, CG restarted from that r (the sums in a fixed
        order, :class:`~warpcloth.integrators.linalg.TranslationSolve`). Jacobi-PCG's first
        directions D^-1 r are not uniform where the diagonal is not (the edges: fewer springs),
        so 10 iterations bent a freely falling 16 x 16 cloth by 2.9 mm in 0.5 s; on a free cloth
        T^T S T = M and r becomes the deformation's part only."""
        m, n, rigid = self.model, self.model.particle_count, self.rigid
        weight, target, precond = self._system()
        wp.launch(
            pk.translation_terms,
            dim=n,
            inputs=[self.r, self.row_offsets, self.columns, self.values, m.particle_inv_mass, weight, target, self.dx],
            outputs=[rigid.b, rigid.A],
            device=m.device,
        )
        rigid.solve()
        wp.launch(
            pk.apply_translation,
            dim=n,
            inputs=[
                rigid.translation,
                self.row_offsets,
                self.columns,
                self.values,
                m.particle_inv_mass,
                weight,
                precond,
            ],
            outputs=[self.dx, self.r, self.z, self.p, self.dot.terms],
            device=m.device,
        )
        self._reduce(self.rz, 0)

    def global_step(self) -> None:
        """dx += S^-1 r by pd_cg_iterations of Jacobi-preconditioned CG from 0."""
        m, n = self.model, self.model.particle_count
        weight, _, precond = self._system()
        for k in range(self.pd_cg_iterations):
            wp.launch(
                pk.csr_matvec_dot,
                dim=n,
                inputs=[self.row_offsets, self.columns, self.values, self.p, weight],
                outputs=[self.Ap, self.dot.terms],
                device=m.device,
            )
            self._reduce(self.pAp, k)
            wp.launch(
                pk.cg_update_solution,
                dim=n,
                inputs=[self.p, self.Ap, precond, self.rz, self.pAp, k, self.contact_state],
                outputs=[self.dx, self.r, self.z, self.dot.terms],
                device=m.device,
            )
            self._reduce(self.rz, k + 1)
            if k + 1 < self.pd_cg_iterations:
                wp.launch(pk.cg_update_direction, dim=n, inputs=[self.z, self.rz, k], outputs=[self.p], device=m.device)

    def _reduce(self, out, k: int) -> None:
        """out[k] = sum of the dot product terms, in a fixed order (deterministic on every device)."""
        self.dot.sum_into(out, k)

    def global_matrix(self):
        """S as a SciPy CSR matrix (host copy; for tests and diagnostics, not for stepping)."""
        import scipy.sparse as sp  # noqa: PLC0415 (SciPy loads only where this solve runs: stepping loads none)

        n = self.model.particle_count
        return sp.csr_matrix(
            (self.values.numpy().astype(np.float64), self.columns.numpy(), self.row_offsets.numpy()), shape=(n, n)
        )

    def stats(self) -> dict:
        return {"pd_iterations": self.pd_iterations, "pd_cg_iterations": self.pd_cg_iterations}


def _largest_rates_per_mass(model) -> tuple[float, float]:
    """max_i sum_s ks_s / m_i and max_i sum_s kd_s / m_i over the free particles and their springs [1/s^2, 1/s]."""
    ks_sum, kd_sum = model.particle_spring_sums()
    free = model.host.inv_mass > 0
    if not free.any():
        return 0.0, 0.0
    mass = model.host.mass.astype(np.float64)[free]
    return float(np.max(ks_sum[free] / mass)), float(np.max(kd_sum[free] / mass))


def _hinge_only_pairs(model, offsets, other) -> np.ndarray:
    """The (i, j) vertex pairs, both directions, that a dihedral hinge couples and no spring does, (P, 2) int64."""
    if not model.hinge_count:
        return np.zeros((0, 2), dtype=np.int64)
    n = model.particle_count
    pairs = hinge_pairs(model.host.hinges.indices).astype(np.int64)
    rows = np.repeat(np.arange(n), np.diff(offsets))
    springs = np.unique(rows * n + other.astype(np.int64))
    key = pairs[:, 0] * n + pairs[:, 1]
    missing = pairs[~np.isin(key, springs)]
    return np.concatenate([missing, missing[:, ::-1]])


def _hinge_matrix_terms(model, row_offsets, columns) -> tuple[np.ndarray, np.ndarray]:
    """Per CSR entry of S, sum_e k_e c_a c_b and sum_e kd_e c_a c_b over the hinges coupling its row a and
    column b (c the rest coefficients, :func:`~warpcloth.sim.hinges.hinge_rest_coefficients`); 0 on pinned
    rows and columns. float32 arrays."""
    n = model.particle_count
    hinges = model.host.hinges
    c = hinge_rest_coefficients(model.host.q, hinges.indices)
    q = hinges.indices.astype(np.int64)
    a, b = np.meshgrid(np.arange(4), np.arange(4), indexing="ij")
    rows, cols = q[:, a.ravel()].ravel(), q[:, b.ravel()].ravel()
    cc = (c[:, a.ravel()] * c[:, b.ravel()]).ravel()
    k = np.repeat(hinges.stiffness, 16) * cc
    kd = np.repeat(hinges.damping, 16) * cc
    free = model.host.inv_mass > 0
    keep = free[rows] & free[cols]
    rows_csr = np.repeat(np.arange(n), np.diff(row_offsets))
    keys = rows_csr * n + columns.astype(np.int64)
    order = np.argsort(keys, kind="stable")
    pos = order[np.searchsorted(keys[order], rows[keep] * n + cols[keep])]
    K, D = np.zeros(columns.size), np.zeros(columns.size)
    np.add.at(K, pos, k[keep])
    np.add.at(D, pos, kd[keep])
    return K.astype(np.float32), D.astype(np.float32)
