"""Geometric multigrid V-cycle for the implicit-Euler system of a grid cloth (a CG preconditioner).

Levels coarsen the particle grid 2x per direction (coarse nodes on the even rows and columns);
the prolongation P_l is bilinear interpolation (3 x 3 blocks w I), zero on pinned particles, and
the coarse operators are Galerkin products A_(l+1) = P_l^T A_l P_l, recomputed each step with
``warp.sparse.bsr_mm`` into matrices whose pattern is fixed at bind (``reuse_topology``). The
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

    def __init__(self, A, rows: int, cols: int, pinned, device, smoothing_steps: int = 2, coarse_steps: int = 20, omega: float = 0.6):
        self.smoothing_steps, self.coarse_steps, self.omega = smoothing_steps, coarse_steps, omega
        self.device = device
        self.A = [A]
        self.P, self.Pt, self.AP = [], [], []
        self.work_ap, self.work_rap = [], []
        self.grids = [(rows, cols)]
        while min(rows, cols) >= 2 * MIN_COARSE_SIDE - 1:
            rc, cc, fi, ci, w = prolongation(rows, cols, pinned if len(self.P) == 0 else ())
            n_f, n_c = rows * cols, rc * cc
            blocks = w[:, None, None] * np.eye(3, dtype=np.float32)[None]
            P = wps.bsr_from_triplets(n_f, n_c, wp.array(fi, dtype=int), wp.array(ci, dtype=int), wp.array(blocks, dtype=wp.mat33))
            Pt = wps.bsr_transposed(P)
            work_ap, work_rap = wps.bsr_mm_work_arrays(), wps.bsr_mm_work_arrays()
            AP = wps.bsr_mm(self.A[-1], P, work_arrays=work_ap)
            Ac = wps.bsr_mm(Pt, AP, work_arrays=work_rap)
            self.P.append(P)
            self.Pt.append(Pt)
            self.AP.append(AP)
            self.work_ap.append(work_ap)
            self.work_rap.append(work_rap)
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
                wps.bsr_mm(self.A[level - 1], self.P[level - 1], self.AP[level - 1], work_arrays=self.work_ap[level - 1], reuse_topology=True)
                wps.bsr_mm(self.Pt[level - 1], self.AP[level - 1], self.A[level], work_arrays=self.work_rap[level - 1], reuse_topology=True)
            wps.bsr_get_diag(self.A[level], out=self.diag[level])
            wp.launch(ik.invert_blocks, dim=self.diag[level].shape[0], inputs=[self.diag[level]], outputs=[self.inv_block[level]], device=self.device)

    def _smooth(self, level: int, sweeps: int, from_zero: bool) -> None:
        """``sweeps`` damped block-Jacobi sweeps on A_l x = b_l (from x = 0 when ``from_zero``)."""
        A, b, x, r = self.A[level], self.b[level], self.x[level], self.r[level]
        n = b.shape[0]
        for k in range(sweeps):
            first = from_zero and k == 0
            if first:
                wp.copy(r, b)
            else:
                wp.copy(r, b)
                wps.bsr_mv(A, x, r, alpha=-1.0, beta=1.0)
            wp.launch(ik.smooth_jacobi, dim=n, inputs=[r, self.inv_block[level], self.omega, int(first)], outputs=[x], device=self.device)

    def _vcycle(self, level: int) -> None:
        """x_l = V(b_l): pre-smooth, restrict the residual, recurse, prolong, post-smooth."""
        if level == self.levels - 1:
            self._smooth(level, self.coarse_steps, from_zero=True)
            return
        self._smooth(level, self.smoothing_steps, from_zero=True)
        r = self.r[level]
        wp.copy(r, self.b[level])
        wps.bsr_mv(self.A[level], self.x[level], r, alpha=-1.0, beta=1.0)
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
