"""Geometric multigrid V-cycle for the implicit-Euler system of a grid cloth (a CG preconditioner).

Levels coarsen the particle grid 2x per direction (coarse nodes on the even rows and columns);
the prolongation P_l is bilinear interpolation (3 x 3 blocks w I), zero on pinned particles, and
the coarse operators are Galerkin products A_(l+1) = P_l^T A_l P_l, recomputed each step by one
gather kernel per level over a list of (fine block, weight P_fI P_gJ) terms per coarse block
built once at bind (the patterns are fixed; ``warp.sparse.bsr_mm`` with a reused topology
was over ten times slower for the same products on the CPU in a one-off measurement at 128^2,
not a committed bench). The
smoother is damped block Jacobi, ``smoothing_steps`` sweeps before and the same after the coarse
correction; the coarsest level takes ``coarse_steps`` sweeps from zero. With equal pre- and
post-smoothing by the same symmetric smoother, the V-cycle is a fixed symmetric positive
definite linear operator, so it is a valid preconditioner for CG.
"""

from __future__ import annotations

import numpy as np
import warp as wp
import warp.sparse as wps

from warpcloth.kernels import implicit as ik

#: Coarsen while the coarse grid keeps at least this many rows and columns.
MIN_COARSE_SIDE = 4


def grid_structure_reason(model) -> str | None:
    """Why ``model`` is not a grid the multigrid can coarsen (None when it is): the particles must
    be a rows x cols grid (particle [r, c] = r * cols + c) whose springs join particles at most
    2 rows and 2 columns apart."""
    rows, cols, n = int(model.rows or 0), int(model.cols or 0), model.particle_count
    if rows * cols != n or min(rows, cols) < 2 * MIN_COARSE_SIDE - 1:
        return f"the model is not a grid of at least {2 * MIN_COARSE_SIDE - 1} x {2 * MIN_COARSE_SIDE - 1} particles"
    pairs = model.host["pairs"].astype(np.int64)
    if pairs.size:
        dr = np.abs(pairs[:, 0] // cols - pairs[:, 1] // cols)
        dc = np.abs(pairs[:, 0] % cols - pairs[:, 1] % cols)
        if dr.max() > 2 or dc.max() > 2:
            return "its springs do not follow a grid (some join particles more than 2 rows or columns apart)"
    return None


def interpolation_1d(fine: int) -> tuple[int, list[list[tuple[int, float]]]]:
    """Coarse size and, per fine index, its (coarse index, weight) pairs: even fine indices are
    coarse nodes, odd ones the mean of their two neighbours (the last one, without a right
    neighbour, copies its left)."""
    coarse = (fine + 1) // 2
    weights = []
    for k in range(fine):
        if k % 2 == 0:
            weights.append([(k // 2, 1.0)])
        elif (k + 1) // 2 < coarse:
            weights.append([((k - 1) // 2, 0.5), ((k + 1) // 2, 0.5)])
        else:
            weights.append([((k - 1) // 2, 1.0)])
    return coarse, weights


def _bsr_pattern(matrix) -> tuple[np.ndarray, np.ndarray]:
    """(block rows, block columns) of a BSR matrix's stored blocks, in storage order."""
    matrix.nnz_sync()
    offsets = matrix.offsets.numpy()[: matrix.nrow + 1].astype(np.int64)
    columns = matrix.columns.numpy()[: offsets[-1]].astype(np.int64)
    return np.repeat(np.arange(matrix.nrow), np.diff(offsets)), columns


def galerkin_terms(fine_rows, fine_cols, n_coarse: int, p_fine, p_coarse, p_weight):
    """The coarse pattern of P^T A P and, per coarse block, its terms (fine block, P_fI P_gJ):
    returns (coarse rows, coarse cols, term offsets, term sources, term weights), the terms of
    coarse block k being ``offsets[k]:offsets[k + 1]``."""
    n_fine = int(max(fine_rows.max(), p_fine.max()) + 1) if fine_rows.size else 0
    order = np.argsort(p_fine, kind="stable")
    pf, pc, pw = p_fine[order], p_coarse[order], p_weight[order].astype(np.float64)
    start = np.zeros(n_fine + 1, dtype=np.int64)
    start[1:] = np.cumsum(np.bincount(pf, minlength=n_fine))
    deg = np.diff(start)
    blocks = np.arange(fine_rows.size)
    # every (fine block e = (f, g), entry a of P row f, entry b of P row g)
    na, nb = deg[fine_rows], deg[fine_cols]
    e = np.repeat(blocks, na * nb)
    local = np.arange(e.size) - np.repeat(np.cumsum(na * nb) - na * nb, na * nb)
    a = start[fine_rows[e]] + local // nb[e]
    b = start[fine_cols[e]] + local % nb[e]
    key = pc[a].astype(np.int64) * n_coarse + pc[b]
    weight = pw[a] * pw[b]
    order = np.argsort(key, kind="stable")
    key, e, weight = key[order], e[order], weight[order]
    unique, first = np.unique(key, return_index=True)
    offsets = np.append(first, key.size).astype(np.int32)
    return (unique // n_coarse).astype(np.int32), (unique % n_coarse).astype(np.int32), offsets, e.astype(np.int32), weight.astype(np.float32)


def prolongation(rows: int, cols: int, pinned=()) -> tuple[int, int, np.ndarray, np.ndarray, np.ndarray]:
    """Bilinear prolongation from the (rows + 1) // 2 x (cols + 1) // 2 grid: (coarse rows, coarse
    cols, fine index, coarse index, weight) triplets, none for pinned fine particles."""
    rc, wr = interpolation_1d(rows)
    cc, wc = interpolation_1d(cols)
    pinned = set(int(p) for p in pinned)
    fi, ci, w = [], [], []
    for r in range(rows):
        for c in range(cols):
            f = r * cols + c
            if f in pinned:
                continue
            for R, a in wr[r]:
                for C, b in wc[c]:
                    fi.append(f)
                    ci.append(R * cc + C)
                    w.append(a * b)
    return rc, cc, np.array(fi, dtype=np.int32), np.array(ci, dtype=np.int32), np.array(w, dtype=np.float32)


class GridMultigrid:
    """V-cycle preconditioner of the BSR system matrix ``A`` of a ``rows`` x ``cols`` grid.

    Call :meth:`update` after A's values change (each step), then :meth:`apply` (the
    LinearOperator's matvec) as often as CG needs. All arrays are allocated here.
    """

    def __init__(self, A, rows: int, cols: int, pinned, device, smoothing_steps: int = 1, coarse_steps: int = 10, omega: float = 0.7, fine_residual=None):
        """``fine_residual(x, b, r)``: r = b - A x on the finest level, where a faster operator
        than A's BSR product exists (implicit_euler's matrix-free one); default ``bsr_mv``."""
        self.smoothing_steps, self.coarse_steps, self.omega = smoothing_steps, coarse_steps, omega
        self.fine_residual = fine_residual
        self.device = device
        self.A = [A]
        self.P, self.Pt, self.terms = [], [], []
        self.grids = [(rows, cols)]
        while min(rows, cols) >= 2 * MIN_COARSE_SIDE - 1:
            rc, cc, fi, ci, w = prolongation(rows, cols, pinned if len(self.P) == 0 else ())
            n_f, n_c = rows * cols, rc * cc
            blocks = w[:, None, None] * np.eye(3, dtype=np.float32)[None]
            P = wps.bsr_from_triplets(n_f, n_c, wp.array(fi, dtype=int), wp.array(ci, dtype=int), wp.array(blocks, dtype=wp.mat33))
            Pt = wps.bsr_transposed(P)
            fine_rows, fine_cols = _bsr_pattern(self.A[-1])
            rows_c, cols_c, offsets, sources, weights = galerkin_terms(fine_rows, fine_cols, n_c, fi, ci, w)
            # the coarse blocks in the order bsr_from_triplets stores them (row-major, sorted columns)
            Ac = wps.bsr_from_triplets(n_c, n_c, wp.array(rows_c, dtype=int), wp.array(cols_c, dtype=int), wp.zeros(rows_c.size, dtype=wp.mat33), prune_numerical_zeros=False)
            stored_rows, stored_cols = _bsr_pattern(Ac)
            assert np.array_equal(stored_rows, rows_c) and np.array_equal(stored_cols, cols_c)
            self.terms.append((wp.array(offsets, dtype=int), wp.array(sources, dtype=int), wp.array(weights, dtype=float)))
            self.P.append(P)
            self.Pt.append(Pt)
            self.A.append(Ac)
            rows, cols = rc, cc
            self.grids.append((rows, cols))
        sizes = [r * c for r, c in self.grids]
        self.inv_block = [wp.zeros(n, dtype=wp.mat33) for n in sizes]
        self.diag = [wp.zeros(n, dtype=wp.mat33) for n in sizes]
        self.b = [wp.zeros(n, dtype=wp.vec3) for n in sizes]
        self.x = [wp.zeros(n, dtype=wp.vec3) for n in sizes]
        self.r = [wp.zeros(n, dtype=wp.vec3) for n in sizes]

    @property
    def levels(self) -> int:
        return len(self.A)

    def update(self) -> None:
        """Galerkin coarse operators A_(l+1) = P^T A_l P and the smoothers' inverse diagonal blocks."""
        for level in range(self.levels):
            if level > 0:
                offsets, sources, weights = self.terms[level - 1]
                wp.launch(ik.galerkin_product, dim=offsets.shape[0] - 1, inputs=[offsets, sources, weights, self.A[level - 1].values], outputs=[self.A[level].values], device=self.device)
            wps.bsr_get_diag(self.A[level], out=self.diag[level])
            wp.launch(ik.invert_blocks, dim=self.diag[level].shape[0], inputs=[self.diag[level]], outputs=[self.inv_block[level]], device=self.device)

    def _residual(self, level: int, x, b, r) -> None:
        """r = b - A_l x."""
        if level == 0 and self.fine_residual is not None:
            self.fine_residual(x, b, r)
        else:
            wp.copy(r, b)
            wps.bsr_mv(self.A[level], x, r, alpha=-1.0, beta=1.0)

    def _smooth(self, level: int, sweeps: int, from_zero: bool) -> None:
        """``sweeps`` damped block-Jacobi sweeps on A_l x = b_l (from x = 0 when ``from_zero``)."""
        A, b, x, r = self.A[level], self.b[level], self.x[level], self.r[level]
        n = b.shape[0]
        for k in range(sweeps):
            first = from_zero and k == 0
            if first:
                wp.copy(r, b)
            else:
                self._residual(level, x, b, r)
            wp.launch(ik.smooth_jacobi, dim=n, inputs=[r, self.inv_block[level], self.omega, int(first)], outputs=[x], device=self.device)

    def _vcycle(self, level: int) -> None:
        """x_l = V(b_l): pre-smooth, restrict the residual, recurse, prolong, post-smooth."""
        if level == self.levels - 1:
            self._smooth(level, self.coarse_steps, from_zero=True)
            return
        self._smooth(level, self.smoothing_steps, from_zero=True)
        r = self.r[level]
        self._residual(level, self.x[level], self.b[level], r)
        wps.bsr_mv(self.Pt[level], r, self.b[level + 1], alpha=1.0, beta=0.0)
        self._vcycle(level + 1)
        wps.bsr_mv(self.P[level], self.x[level + 1], self.x[level], alpha=1.0, beta=1.0)
        self._smooth(level, self.smoothing_steps, from_zero=False)

    def apply(self, x, y, z, alpha, beta) -> None:
        """z = alpha V(x) + beta y (the LinearOperator's matvec; y and z may alias)."""
        wp.copy(self.b[0], x)
        self._vcycle(0)
        n = self.b[0].shape[0]
        wp.launch(ik.scale_add, dim=n, inputs=[self.x[0], y, float(alpha), float(beta)], outputs=[z], device=self.device)
