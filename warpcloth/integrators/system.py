"""The implicit system of a mass-spring step, shared by implicit Euler (its linear system) and vbd
(h^2 times its Hessian, for the multigrid correction):

    A = M (1 + h c) - h df/dv - h^2 df/dx,

df/dx the spring Jacobian (full, with the compression clamp that keeps A symmetric positive
definite, or the seed's constant approximation eq. 2.23), df/dv the spring damping, c the linear
air drag rate [1/s] (kernels: :mod:`warpcloth.kernels.system`). With B_s = h^2 K_s + h D_s per
spring, A is applied assembled (``matrix="bsr"``: a ``warp.sparse`` BSR matrix of 3 x 3 blocks, its
pattern built once, its values refilled by a kernel) or matrix-free (``matrix="free"``: a gather over
each particle's springs); both give the same A. Pinned particles have identity rows and zero columns.

Preconditioners: ``jacobi`` (1 / diag A), ``block_jacobi`` (A's inverse 3 x 3 diagonal blocks) and
``multigrid`` (:class:`~warpcloth.integrators.multigrid.GridMultigrid`; it needs A assembled, so it
assembles the BSR matrix whatever ``matrix`` says).

Dihedral hinges (``bend="dihedral"``, :mod:`warpcloth.kernels.bending`) add their Gauss-Newton
blocks A_ab += (h^2 k_e + h kd_e) g_a g_b^T over the 4 x 4 vertex pairs of each hinge (g = d theta / dx,
rank 1, PSD; the pattern grows by :func:`~warpcloth.sim.hinges.hinge_pairs`, a row gather, no atomics),
before the Jacobi / block-Jacobi diagonal is taken; ``jacobian="approx"`` uses the constant
(h^2 k_e + h kd_e) c_a c_b I, c the rest coefficients (:func:`~warpcloth.sim.hinges.hinge_rest_coefficients`).
"""

from __future__ import annotations

import numpy as np
import warp as wp
import warp.sparse as wps
from warp.optim.linear import LinearOperator, aslinearoperator

from warpcloth.integrators.base import spring_adjacency
from warpcloth.integrators.multigrid import GridMultigrid
from warpcloth.kernels import bending as bk
from warpcloth.kernels import linalg as lk
from warpcloth.kernels import system as sk
from warpcloth.sim.hinges import hinge_adjacency, hinge_block_index, hinge_pairs, hinge_rest_coefficients

JACOBIANS = ("full", "approx")
MATRICES = ("free", "bsr")
PRECONDITIONERS = ("jacobi", "block_jacobi", "multigrid")


class ImplicitSystem:
    """A = M (1 + h c) - h df/dv - h^2 df/dx of ``model``'s springs, its operator and preconditioner.

    Args:
        model: the :class:`~warpcloth.sim.model.ClothModel`.
        jacobian: ``"full"`` (refilled every step) or ``"approx"`` (seed eq. 2.23, constant: refilled
            only when h or the drag change).
        matrix: the operator :attr:`A_op` applies, ``"bsr"`` (assembled) or ``"free"``.
        preconditioner: ``"jacobi"``, ``"block_jacobi"`` or ``"multigrid"`` (a grid model: see
            :func:`~warpcloth.integrators.multigrid.grid_structure_reason`).

    Every array is allocated here; :meth:`assemble` and :meth:`update_preconditioner` launch
    kernels only.
    """

    def __init__(self, model, jacobian: str = "full", matrix: str = "bsr", preconditioner: str = "jacobi"):
        self.model, self.jacobian, self.matrix, self.preconditioner = model, jacobian, matrix, preconditioner
        with wp.ScopedDevice(model.device):
            self._allocate(model)

    def _allocate(self, model) -> None:
        n, device = model.particle_count, model.device
        pairs = model.host.pairs.astype(np.int64).reshape(-1, 2)
        #: K_s and B_s = h^2 K_s + h D_s per spring, shape (spring_count,).
        self.spring_K = wp.zeros(model.spring_count, dtype=wp.mat33)
        self.spring_B = wp.zeros(model.spring_count, dtype=wp.mat33)
        #: 1 / diag(A) (the Jacobi preconditioner), shape (particle_count,).
        self.inv_diag = wp.zeros(n, dtype=wp.vec3)
        self.mass_term = wp.zeros(n, dtype=float)
        # the multigrid's Galerkin products need A assembled (BSR); A_op still applies A as ``matrix`` says
        self.bsr = self.matrix == "bsr" or self.preconditioner == "multigrid"

        if self.bsr:
            # pattern: diagonal blocks + (i, j) and (j, i) per spring (and per pair of vertices a hinge couples), built
            # once
            if model.hinge_count:
                pairs = np.concatenate([pairs, hinge_pairs(model.host.hinges.indices).astype(np.int64)])
            rows = np.concatenate([np.arange(n), pairs[:, 0], pairs[:, 1]]).astype(np.int32)
            cols = np.concatenate([np.arange(n), pairs[:, 1], pairs[:, 0]]).astype(np.int32)
            ones = np.tile(np.eye(3, dtype=np.float32), (rows.size, 1, 1))
            self.A = wps.bsr_from_triplets(
                n,
                n,
                wp.array(rows, dtype=int),
                wp.array(cols, dtype=int),
                wp.array(ones, dtype=wp.mat33),
                prune_numerical_zeros=False,
            )
            self.A.nnz_sync()
            offsets = self.A.offsets.numpy()[: n + 1].astype(np.int64)
            columns = self.A.columns.numpy()[: offsets[-1]].astype(np.int64)
            keys = np.repeat(np.arange(n), np.diff(offsets)) * n + columns  # sorted: row-major, columns ascending

            def block_of(r, c):
                return np.searchsorted(keys, np.asarray(r) * n + np.asarray(c)).astype(np.int32)
        else:
            self.A = None

        #: Each particle's springs (the row kernels' gather; :class:`~warpcloth.kernels.springs.SpringAdjacency`).
        self.springs = spring_adjacency(model)
        if self.bsr:  # where each adjacency entry (particle, neighbour) and each diagonal block sits in A.values
            ends = np.repeat(np.arange(n), np.diff(self.springs.offsets.numpy()))
            self.adjacency_block = wp.array(block_of(ends, self.springs.other.numpy()), dtype=int)
            self.row_offsets = wp.array(offsets.astype(np.int32), dtype=int)
            self.block_columns = wp.array(columns.astype(np.int32), dtype=int)
            self.diag_block = wp.array(block_of(np.arange(n), np.arange(n)), dtype=int)
            #: Per row E_i = A_ii + sum_j A_ij (the mass and the pinned springs' part, formed from the
            #: masses) for the split product, unfiltered and as the solve sees it (after the contact filter).
            self.row_part, self.row_part_solve = wp.zeros(n, dtype=wp.mat33), wp.zeros(n, dtype=wp.mat33)
        self._allocate_hinges(model, offsets if self.bsr else None, columns if self.bsr else None)

        # Jacobi preconditioner: the same operator as preconditioner(A, "diag"), but its inverse
        # diagonal is refilled by the assembly kernel instead of being reallocated each step
        self.multigrid = None
        if self.preconditioner == "multigrid":
            self.multigrid = GridMultigrid(self.A, model.rows, model.cols, model.pinned, device)
            self.M = LinearOperator((3 * n, 3 * n), wp.mat33, wp.get_device(device), self.multigrid.apply)
        elif self.preconditioner == "block_jacobi":
            self.inv_block = wp.zeros(n, dtype=wp.mat33)
            self.M = LinearOperator((3 * n, 3 * n), wp.mat33, wp.get_device(device), self.apply_block_jacobi)
        else:
            self.M = aslinearoperator(self.inv_diag)
        matvec = self.bsr_matvec if self.matrix == "bsr" else self.matvec
        #: A as a LinearOperator (assembled or matrix-free, as ``matrix`` says).
        self.A_op = LinearOperator((3 * n, 3 * n), wp.mat33, wp.get_device(device), matvec)
        self._assembled_for = None
        #: A further symmetric term of A (implicit Euler's self-contacts), called as
        #: ``extra_product(x, z, alpha, filtered)`` (z += alpha C x) after every product; None: none.
        self.extra_product = None

    def _allocate_hinges(self, model, offsets, columns) -> None:
        """The hinges' adjacency (vertex -> (hinge, slot)), their blocks' places in A (BSR), and the
        gradients the blocks are made of: g refilled each step (full), or the three constant c_a e_k
        (approx: sum_k c_a c_b e_k e_k^T = c_a c_b I)."""
        #: Whether the model has dihedral hinges.
        self.has_hinges = model.hinge_count > 0
        self.h = 0.0
        if not self.has_hinges:
            return
        n, count, idx = model.particle_count, model.hinge_count, model.host.hinges.indices
        adj_offsets, adj_hinge, adj_slot = hinge_adjacency(idx, n)
        #: Each particle's hinges (offsets, hinge, slot), the row gathers' adjacency.
        self.hinge_adjacency = (
            wp.array(adj_offsets, dtype=int),
            wp.array(adj_hinge, dtype=int),
            wp.array(adj_slot, dtype=int),
        )
        if self.bsr:
            self.hinge_block = wp.array(hinge_block_index(idx, adj_offsets, adj_hinge, offsets, columns), dtype=int)
        self.hinge_angle = wp.zeros(count, dtype=float)
        if self.jacobian == "full":
            #: g_a = d theta / d x_a per hinge, (hinge_count, 4), refilled by :meth:`assemble`.
            self.hinge_gradient = wp.zeros((count, 4), dtype=wp.vec3)
            self.hinge_gradients = [self.hinge_gradient]
        else:
            c = hinge_rest_coefficients(model.host.q, idx)
            self.hinge_gradients = [
                wp.array((c[:, :, None] * np.eye(3)[k]).astype(np.float32), dtype=wp.vec3) for k in range(3)
            ]
        if self.matrix == "free":
            self.hinge_diagonal = wp.zeros(n, dtype=wp.mat33)  # sum_e s g_a g_a^T per particle (matrix-free)

    def _assemble_hinges(self, x, h: float) -> None:
        """A += (h^2 k_e + h kd_e) g g^T per hinge (values, or the matrix-free diagonal), then the
        Jacobi diagonal from the new rows."""
        m = self.model
        adj = self.hinge_adjacency
        if self.jacobian == "full":
            wp.launch(
                bk.eval_hinge_gradients,
                dim=m.hinge_count,
                inputs=[x, m.hinge_indices],
                outputs=[self.hinge_angle, self.hinge_gradient],
                device=m.device,
            )
        if self.bsr:
            for g in self.hinge_gradients:
                wp.launch(
                    bk.add_hinge_system_rows,
                    dim=m.particle_count,
                    inputs=[
                        *adj,
                        self.hinge_block,
                        m.hinge_indices,
                        g,
                        m.hinge_stiffness,
                        m.hinge_damping,
                        m.particle_inv_mass,
                        h * h,
                        h,
                    ],
                    outputs=[self.A.values, self.row_part, self.row_part_solve],
                    device=m.device,
                )
        if self.matrix == "free":
            self.hinge_diagonal.zero_()
            for g in self.hinge_gradients:
                wp.launch(
                    sk.add_hinge_diagonal_blocks,
                    dim=m.particle_count,
                    inputs=[*adj, g, m.hinge_stiffness, m.hinge_damping, m.particle_inv_mass, h * h, h],
                    outputs=[self.hinge_diagonal],
                    device=m.device,
                )
            wp.launch(
                sk.add_to_inverse_diagonal,
                dim=m.particle_count,
                inputs=[self.hinge_diagonal, m.particle_inv_mass],
                outputs=[self.inv_diag],
                device=m.device,
            )
        else:
            wp.launch(
                sk.refresh_inverse_diagonal,
                dim=m.particle_count,
                inputs=[self.A.values, self.diag_block, m.particle_inv_mass],
                outputs=[self.inv_diag],
                device=m.device,
            )

    def add_hinge_product(self, y, z, alpha: float, beta: float, zero_pinned_columns: int) -> None:
        """z += sum_e (alpha k_e + beta kd_e) g (g . y) on the free rows (nothing without hinges): the
        hinges' part of A y (alpha = h^2, beta = h), or of the right-hand side (alpha = -h^2, beta = 0:
        h^2 df/dx v; alpha = -h^2, beta = -h with y the pins' prescribed dv: their coupling)."""
        if not self.has_hinges:
            return
        m = self.model
        for g in self.hinge_gradients:
            wp.launch(
                bk.add_hinge_matrix_product,
                dim=m.particle_count,
                inputs=[
                    *self.hinge_adjacency,
                    m.hinge_indices,
                    g,
                    m.hinge_stiffness,
                    m.hinge_damping,
                    m.particle_inv_mass,
                    float(alpha),
                    float(beta),
                    int(zero_pinned_columns),
                    y,
                ],
                outputs=[z],
                device=m.device,
            )

    def add_hinge_rhs(self, v, b, h: float) -> None:
        """b += h^2 df/dx v of the hinges, -h^2 sum_e k_e g (g . v) (the pins' velocities kept)."""
        self.add_hinge_product(v, b, -h * h, 0.0, 0)

    def invalidate(self) -> None:
        """Refill A at the next :meth:`assemble` even where its values would be unchanged (after a
        change of the state, or after A's values were changed in place: the contact filter)."""
        self._assembled_for = None

    def assemble(self, x, h: float, drag: float) -> None:
        """Refill K_s, B_s = h^2 K_s + h D_s and the values of A (and the Jacobi diagonal):
        every step with the full Jacobian, only when h or the drag change with the approximation."""
        m = self.model
        self.h = float(h)
        if self.jacobian == "full":
            wp.launch(
                sk.eval_spring_jacobians,
                dim=m.spring_count,
                inputs=[
                    x,
                    m.spring_indices,
                    m.spring_rest_length,
                    m.spring_stiffness,
                    m.spring_damping,
                    m.spring_compression,
                    h,
                ],
                outputs=[self.spring_K, self.spring_B],
                device=m.device,
            )
        elif self._assembled_for == (h, drag):
            return
        else:
            wp.launch(
                sk.eval_spring_jacobians_approx,
                dim=m.spring_count,
                inputs=[m.spring_stiffness, m.spring_damping, h],
                outputs=[self.spring_K, self.spring_B],
                device=m.device,
            )
            self._assembled_for = (h, drag)
        if self.bsr:
            wp.launch(
                sk.assemble_system_rows,
                dim=m.particle_count,
                inputs=[
                    self.springs,
                    self.adjacency_block,
                    self.row_offsets,
                    self.diag_block,
                    self.spring_B,
                    m.particle_mass,
                    m.particle_inv_mass,
                    drag,
                    h,
                ],
                outputs=[self.A.values, self.inv_diag, self.row_part, self.row_part_solve],
                device=m.device,
            )
        if self.matrix == "free":
            wp.launch(
                sk.eval_system_diagonal,
                dim=m.particle_count,
                inputs=[self.springs, self.spring_B, m.particle_mass, m.particle_inv_mass, drag, h],
                outputs=[self.mass_term, self.inv_diag],
                device=m.device,
            )
        if self.has_hinges:
            self._assemble_hinges(x, h)

    def update_preconditioner(self, h: float, drag: float, filtered: bool = False) -> None:
        """The preconditioner of this step's A (after the contact filter where ``filtered``;
        Jacobi's diagonal is refilled by the assembly and the filter)."""
        m = self.model
        if self.preconditioner == "multigrid":
            self.multigrid.update()
        elif self.preconditioner == "block_jacobi" and (filtered or (self.has_hinges and self.bsr)):
            wp.launch(
                lk.invert_diagonal_blocks,
                dim=m.particle_count,
                inputs=[self.A.values, self.diag_block],
                outputs=[self.inv_block],
                device=m.device,
            )
        elif self.preconditioner == "block_jacobi":
            wp.launch(
                sk.eval_inverse_diagonal_blocks,
                dim=m.particle_count,
                inputs=[self.springs, self.spring_B, m.particle_mass, m.particle_inv_mass, drag, h],
                outputs=[self.inv_block],
                device=m.device,
            )
            if self.has_hinges:  # matrix-free: the hinges' diagonal blocks added
                wp.launch(
                    sk.add_to_inverse_blocks,
                    dim=m.particle_count,
                    inputs=[self.hinge_diagonal, m.particle_inv_mass],
                    outputs=[self.inv_block],
                    device=m.device,
                )

    def bsr_matvec(self, x, y, z, alpha, beta, values=None, row_part=None) -> None:
        """z = alpha A x + beta y with the assembled A (its BSR blocks, row by row; ``values`` and
        ``row_part``: other values on A's pattern and their E_i, e.g. A before the contact filter):
        one 3 x 3 product per stored block, read in storage order, in the split form
        (A x)_i = E_i x_i + sum_j A_ij (x_j - x_i) (:func:`~warpcloth.kernels.linalg.block_gemv_split`;
        issue 26: with the stored A_ii the float32 diagonal m I + sum B_s lost the mass on fine
        sheets, and dv differed from matrix="free" by 2e-3 of |dv| at 256^2)."""
        m = self.model
        filtered = values is None and row_part is None  # the solve's A (after the colliders' filter)
        values = self.A.values if values is None else values
        row_part = self.row_part_solve if row_part is None else row_part
        wp.launch(
            lk.block_gemv_split,
            dim=m.particle_count,
            inputs=[self.row_offsets, self.block_columns, values, row_part, x, y, float(alpha), float(beta)],
            outputs=[z],
            device=m.device,
        )
        if self.extra_product is not None:
            self.extra_product(x, z, alpha, filtered)

    def matvec(self, x, y, z, alpha, beta) -> None:
        """z = alpha A x + beta y without assembling A (the LinearOperator's matvec)."""
        m = self.model
        wp.launch(
            sk.apply_system_matrix,
            dim=m.particle_count,
            inputs=[x, y, self.springs, self.spring_B, self.mass_term, m.particle_inv_mass, float(alpha), float(beta)],
            outputs=[z],
            device=m.device,
        )
        self.add_hinge_product(x, z, alpha * self.h * self.h, alpha * self.h, 1)  # + the hinges' (h^2 k + h kd) g g^T x
        if self.extra_product is not None:
            self.extra_product(x, z, alpha, True)

    def apply_block_jacobi(self, x, y, z, alpha, beta) -> None:
        """z = alpha P x + beta y with P = blockdiag(A_ii^-1) (the block-Jacobi LinearOperator)."""
        m = self.model
        wp.launch(
            lk.apply_block_diagonal,
            dim=m.particle_count,
            inputs=[x, y, self.inv_block, float(alpha), float(beta)],
            outputs=[z],
            device=m.device,
        )


__all__ = ["JACOBIANS", "MATRICES", "PRECONDITIONERS", "ImplicitSystem"]
