"""Geometric multigrid V-cycle for the implicit-Euler system of a grid cloth (a CG preconditioner,
and vbd's coarse correction).

Levels coarsen the particle grid 2x per direction (coarse nodes on the even rows and columns);
the prolongation P_l is bilinear interpolation (3 x 3 blocks w I, applied with scalar weights),
zero on pinned particles, and the coarse operators are Galerkin products A_(l+1) = P_l^T A_l P_l,
recomputed each step by one gather kernel per level over a list of (fine block, weight P_fI P_gJ)
terms per coarse block built once at bind (the patterns are fixed, and this was far faster on the
CPU than ``warp.sparse.bsr_mm``). The smoother is block Jacobi, ``smoothing_steps`` sweeps before
and the same after the coarse correction, each sweep one kernel that forms its residual; the
coarsest level takes ``coarse_steps`` sweeps from zero. Damped (omega 0.7) for CG; l1
(``l1_smoother``, convergent for any SPD matrix) for vbd's correction. With equal pre- and
post-smoothing by the same symmetric smoother, the V-cycle is a fixed symmetric positive definite
linear operator, so it is a valid preconditioner for CG.

A V-cycle at 128^2 is ~35 small launches; it multiplies with
:func:`~warpcloth.kernels.linalg.block_gemv` and is captured once and replayed
(``wp.capture_launch``, Warp >= 1.19 on the CPU), so Python launch overhead does not dominate
(measured cost: docs/solvers.md, "implicit_euler --preconditioner jacobi|block_jacobi|multigrid").
"""

from __future__ import annotations

import numpy as np
import warp as wp
import warp.sparse as wps

from warpcloth.kernels import linalg as lk
from warpcloth.kernels import multigrid as mk

#: Coarsen while the coarse grid keeps at least this many rows and columns.
MIN_COARSE_SIDE = 4


def grid_structure_reason(model) -> str | None:
    """Why ``model`` is not a grid the multigrid can coarsen (None when it is): the particles must
    be a rows x cols grid (particle [r, c] = r * cols + c) whose springs join particles at most
    2 rows and 2 columns apart, and one cloth (a model of several pieces is not one grid)."""
    pieces = len(getattr(model, "pieces", ()))
    if pieces > 1:  # one hierarchy of one grid's rows and columns (vbd: the aggregation one instead)
        return f"the model holds {pieces} cloths (ClothBuilder) and the grid multigrid coarsens one grid"
    rows, cols, n = int(model.rows or 0), int(model.cols or 0), model.particle_count
    if rows * cols != n or min(rows, cols) < 2 * MIN_COARSE_SIDE - 1:
        return f"the model is not a grid of at least {2 * MIN_COARSE_SIDE - 1} x {2 * MIN_COARSE_SIDE - 1} particles"
    pairs = model.host.pairs.astype(np.int64)
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
    return (
        (unique // n_coarse).astype(np.int32),
        (unique % n_coarse).astype(np.int32),
        offsets,
        e.astype(np.int32),
        weight.astype(np.float32),
    )


def prolongation(rows: int, cols: int, pinned=()) -> tuple[int, int, np.ndarray, np.ndarray, np.ndarray]:
    """Bilinear prolongation from the (rows + 1) // 2 x (cols + 1) // 2 grid: (coarse rows, coarse
    cols, fine index, coarse index, weight) triplets, none for pinned fine particles."""
    rc, wr = interpolation_1d(rows)
    cc, wc = interpolation_1d(cols)
    pinned = {int(p) for p in pinned}
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


def aggregation_prolongation(
    n: int, fine_rows: np.ndarray, fine_cols: np.ndarray, pinned=()
) -> tuple[int, np.ndarray, np.ndarray, np.ndarray]:
    """Plain aggregation of a level's matrix graph (any mesh): an unaggregated node whose
    neighbours are all unaggregated starts an aggregate with them; the nodes left join a
    neighbouring aggregate (the one with most links to it), isolated ones are their own. P is
    piecewise constant (weight 1), with no rows on ``pinned`` nodes. Returns (coarse size, fine
    index, coarse index, weight)."""
    pinned = np.zeros(n, dtype=bool) if len(pinned) == 0 else np.isin(np.arange(n), np.asarray(pinned))
    off = fine_rows != fine_cols
    r, c = fine_rows[off].astype(np.int64), fine_cols[off].astype(np.int64)
    keep = ~pinned[r] & ~pinned[c]
    r, c = r[keep], c[keep]
    order = np.argsort(r, kind="stable")
    r, c = r[order], c[order]
    start = np.zeros(n + 1, dtype=np.int64)
    start[1:] = np.cumsum(np.bincount(r, minlength=n))
    label = np.full(n, -1, dtype=np.int64)
    count = 0
    for i in range(n):
        if pinned[i] or label[i] >= 0:
            continue
        nb = c[start[i] : start[i + 1]]
        if np.all(label[nb] < 0):
            label[i] = count
            label[nb] = count
            count += 1
    for i in range(n):
        if pinned[i] or label[i] >= 0:
            continue
        nb = c[start[i] : start[i + 1]]
        nb = nb[label[nb] >= 0]
        if nb.size:
            values, counts = np.unique(label[nb], return_counts=True)
            label[i] = values[np.argmax(counts)]
        else:
            label[i] = count
            count += 1
    fi = np.flatnonzero(label >= 0)
    return count, fi.astype(np.int32), label[fi].astype(np.int32), np.ones(fi.size, dtype=np.float32)


def _scalar_csr(rows: np.ndarray, cols: np.ndarray, weights: np.ndarray, nrow: int):
    """(offsets, columns, weights) of a scalar CSR matrix from triplets, rows in order."""
    order = np.lexsort((cols, rows))
    offsets = np.zeros(nrow + 1, dtype=np.int32)
    offsets[1:] = np.cumsum(np.bincount(rows, minlength=nrow))
    return (
        wp.array(offsets, dtype=int),
        wp.array(cols[order].astype(np.int32), dtype=int),
        wp.array(weights[order].astype(np.float32), dtype=float),
    )


def _cpu_capture_supported(device) -> bool:
    """Warp's API capture on the CPU (from 1.19), used to replay a V-cycle's launches at once."""
    d = wp.get_device(device)
    major, minor = (int(p) for p in wp.config.version.split(".")[:2])
    return d.is_cpu and (major, minor) >= (1, 19)


class GridMultigrid:
    """V-cycle preconditioner of the BSR system matrix ``A`` of a ``rows`` x ``cols`` grid.

    Call :meth:`update` after A's values change (each step), then :meth:`apply` (the
    LinearOperator's matvec) as often as CG needs. All arrays are allocated here.

    Every level applies its operator with :func:`~warpcloth.kernels.linalg.block_gemv` (a CSR
    of 3 x 3 blocks read from the BSR values in their storage order) and the grid transfers with
    scalar weights (P's blocks are w I); a smoothing sweep computes its residual in the same
    kernel. On the CPU (Warp >= 1.19) the launches of a V-cycle and of :meth:`update` are captured
    once per set of arrays and replayed (``wp.capture_launch``): a V-cycle at 128^2 is ~35
    launches, whose Python cost otherwise exceeds the coarse levels' work.
    """

    #: Graphs kept per operation before the cache is cleared (new argument arrays make new graphs).
    MAX_GRAPHS = 8

    def __init__(
        self,
        A,
        rows: int,
        cols: int,
        pinned,
        device,
        smoothing_steps: int = 1,
        coarse_steps: int = 10,
        omega: float = 0.7,
        post_smoothing: bool = True,
        aggregation: bool = False,
        min_coarse: int = 16,
    ):
        """``post_smoothing=False`` drops the sweeps after the coarse correction: the V-cycle is
        then not symmetric (only to show that the symmetry test can fail). ``aggregation``:
        coarsen any mesh by :func:`aggregation_prolongation` (``rows``, ``cols`` ignored; levels
        until at most ``min_coarse`` nodes or no coarsening) instead of the grid's bilinear one."""
        self.smoothing_steps, self.coarse_steps, self.omega = smoothing_steps, coarse_steps, omega
        self.post_smoothing = post_smoothing
        #: Smoother: False, damped block Jacobi (``omega``; the CG preconditioner's, fewest CG
        #: iterations: 14.6 against 21 with l1 at 128^2, dt = 1/60 s, tol 1e-3); True, l1 block
        #: Jacobi x += (A_ii + sum_(j != i) |A_ij|_F I)^-1 r, which converges for any SPD A (damped
        #: Jacobi needs omega < 2 / lambda_max(D^-1 A)), for a V-cycle used as a stationary
        #: correction (vbd), where it must contract every mode.
        self.l1_smoother = False
        self.device = wp.get_device(device)
        self.A = [A]
        self.P, self.Pt, self.terms = [], [], []
        self.grids = [(rows, cols)]
        self.csr = []  # per level: (offsets, columns, diagonal block index) of A_l's blocks
        fine_rows, fine_cols = _bsr_pattern(A)
        if aggregation:
            rows, cols = A.nrow, 1
            self.grids = [(rows, cols)]
        while True:
            n_f = rows * cols
            offsets = np.zeros(n_f + 1, dtype=np.int32)
            offsets[1:] = np.cumsum(np.bincount(fine_rows, minlength=n_f))
            diag = np.flatnonzero(fine_rows == fine_cols)
            assert diag.size == n_f and np.array_equal(fine_rows[diag], np.arange(n_f)), (
                "every level needs its diagonal blocks"
            )
            self.csr.append(
                (
                    wp.array(offsets, dtype=int),
                    wp.array(fine_cols.astype(np.int32), dtype=int),
                    wp.array(diag.astype(np.int32), dtype=int),
                )
            )
            if aggregation:
                if n_f <= min_coarse:
                    break
                n_c, fi, ci, w = aggregation_prolongation(n_f, fine_rows, fine_cols, pinned if len(self.P) == 0 else ())
                if n_c >= n_f or n_c == 0:
                    break
                rc, cc = n_c, 1
            else:
                if min(rows, cols) < 2 * MIN_COARSE_SIDE - 1:
                    break
                rc, cc, fi, ci, w = prolongation(rows, cols, pinned if len(self.P) == 0 else ())
                n_c = rc * cc
            rows_c, cols_c, term_offsets, sources, weights = galerkin_terms(fine_rows, fine_cols, n_c, fi, ci, w)
            # the coarse blocks in the order bsr_from_triplets stores them (row-major, sorted columns)
            Ac = wps.bsr_from_triplets(
                n_c,
                n_c,
                wp.array(rows_c, dtype=int),
                wp.array(cols_c, dtype=int),
                wp.zeros(rows_c.size, dtype=wp.mat33),
                prune_numerical_zeros=False,
            )
            stored_rows, stored_cols = _bsr_pattern(Ac)
            assert np.array_equal(stored_rows, rows_c) and np.array_equal(stored_cols, cols_c)
            self.terms.append(
                (wp.array(term_offsets, dtype=int), wp.array(sources, dtype=int), wp.array(weights, dtype=float))
            )
            self.P.append(_scalar_csr(fi, ci, w, n_f))
            self.Pt.append(_scalar_csr(ci, fi, w, n_c))
            self.A.append(Ac)
            fine_rows, fine_cols = stored_rows, stored_cols
            rows, cols = rc, cc
            self.grids.append((rows, cols))
        sizes = [r * c for r, c in self.grids]
        self.inv_block = [wp.zeros(n, dtype=wp.mat33) for n in sizes]
        self.b = [wp.zeros(n, dtype=wp.vec3) for n in sizes]
        self.x = [
            (wp.zeros(n, dtype=wp.vec3), wp.zeros(n, dtype=wp.vec3)) for n in sizes
        ]  # two buffers: Jacobi sweeps ping-pong
        self.r = [wp.zeros(n, dtype=wp.vec3) for n in sizes]
        self._capture = _cpu_capture_supported(self.device)
        self._graphs: dict = {}

    @property
    def levels(self) -> int:
        return len(self.A)

    def _replay(self, key, record) -> None:
        """Run ``record()`` (kernel launches only); on the CPU capture it once per ``key`` and replay."""
        if not self._capture or self.device.is_capturing:
            record()
            return
        graph = self._graphs.get(key)
        if graph is None:
            if len(self._graphs) >= self.MAX_GRAPHS:
                self._graphs.clear()
            with wp.ScopedCapture(device=self.device) as capture:
                record()
            graph = self._graphs[key] = capture.graph
        wp.capture_launch(graph)

    def update(self) -> None:
        """Galerkin coarse operators A_(l+1) = P^T A_l P and the smoothers' inverse diagonal blocks."""
        self._replay("update", self._update)

    def _update(self) -> None:
        for level in range(self.levels):
            if level > 0:
                offsets, sources, weights = self.terms[level - 1]
                wp.launch(
                    mk.galerkin_product,
                    dim=offsets.shape[0] - 1,
                    inputs=[offsets, sources, weights, self.A[level - 1].values],
                    outputs=[self.A[level].values],
                    device=self.device,
                )
            n = self.inv_block[level].shape[0]
            if not self.l1_smoother:
                wp.launch(
                    lk.invert_diagonal_blocks,
                    dim=n,
                    inputs=[self.A[level].values, self.csr[level][2]],
                    outputs=[self.inv_block[level]],
                    device=self.device,
                )
            else:
                wp.launch(
                    mk.invert_l1_diagonal_blocks,
                    dim=n,
                    inputs=[self.csr[level][0], self.A[level].values, self.csr[level][2]],
                    outputs=[self.inv_block[level]],
                    device=self.device,
                )

    def _omega(self, level: int) -> float:
        """The sweeps' damping: ``omega``, or 1 for the l1 smoother."""
        return 1.0 if self.l1_smoother else self.omega

    def _sweep(self, level: int, b, x, out, alpha: float = 1.0, beta: float = 0.0, y=None) -> None:
        """out = alpha (x + omega D^-1 (b - A_l x)) + beta y: one damped block-Jacobi sweep."""
        offsets, columns, _ = self.csr[level]
        wp.launch(
            mk.smooth_jacobi_block,
            dim=b.shape[0],
            inputs=[
                offsets,
                columns,
                self.A[level].values,
                self.inv_block[level],
                b,
                x,
                self._omega(level),
                float(alpha),
                float(beta),
                out if y is None else y,
            ],
            outputs=[out],
            device=self.device,
        )

    def _smooth_from_zero(self, level: int, b, sweeps: int) -> int:
        """``sweeps`` sweeps on A_l x = b from x = 0; returns the buffer index holding x."""
        first = self.x[level][0]
        wp.launch(
            mk.smooth_jacobi,
            dim=b.shape[0],
            inputs=[b, self.inv_block[level], self._omega(level), 1],
            outputs=[first],
            device=self.device,
        )
        cur = 0
        for _ in range(sweeps - 1):
            self._sweep(level, b, self.x[level][cur], self.x[level][1 - cur])
            cur = 1 - cur
        return cur

    def _vcycle(self, level: int, b, z=None, alpha: float = 1.0, beta: float = 0.0, y=None):
        """x_l = V(b): pre-smooth from 0, restrict the residual, recurse, prolong, post-smooth.
        Returns the array holding x_l; with ``z`` given, the last sweep writes alpha x_l + beta y
        to it instead (and returns z)."""
        if level == self.levels - 1:
            cur = self._smooth_from_zero(level, b, self.coarse_steps)
            x = self.x[level][cur]
            if z is not None:
                wp.launch(
                    lk.scale_add,
                    dim=b.shape[0],
                    inputs=[x, y, float(alpha), float(beta)],
                    outputs=[z],
                    device=self.device,
                )
                return z
            return x
        cur = self._smooth_from_zero(level, b, self.smoothing_steps)
        x, r = self.x[level][cur], self.r[level]
        offsets, columns, _ = self.csr[level]
        wp.launch(
            lk.block_gemv,
            dim=b.shape[0],
            inputs=[offsets, columns, self.A[level].values, x, b, -1.0, 1.0],
            outputs=[r],
            device=self.device,
        )
        offsets_t, columns_t, weights_t = self.Pt[level]
        wp.launch(
            mk.weight_gemv,
            dim=self.b[level + 1].shape[0],
            inputs=[offsets_t, columns_t, weights_t, r, 0.0],
            outputs=[self.b[level + 1]],
            device=self.device,
        )
        coarse = self._vcycle(level + 1, self.b[level + 1])
        offsets_p, columns_p, weights_p = self.P[level]
        wp.launch(
            mk.weight_gemv,
            dim=b.shape[0],
            inputs=[offsets_p, columns_p, weights_p, coarse, 1.0],
            outputs=[x],
            device=self.device,
        )
        sweeps = self.smoothing_steps if self.post_smoothing else 0
        for k in range(sweeps):
            last = k == sweeps - 1 and z is not None
            out = z if last else self.x[level][1 - cur]
            self._sweep(level, b, self.x[level][cur], out, alpha if last else 1.0, beta if last else 0.0, y)
            if last:
                return z
            cur = 1 - cur
        x = self.x[level][cur]
        if z is not None:
            wp.launch(
                lk.scale_add, dim=b.shape[0], inputs=[x, y, float(alpha), float(beta)], outputs=[z], device=self.device
            )
            return z
        return x

    def apply(self, x, y, z, alpha, beta) -> None:
        """z = alpha V(x) + beta y (the LinearOperator's matvec; y and z may alias)."""
        alpha, beta = float(alpha), float(beta)
        self._replay(("apply", x.ptr, y.ptr, z.ptr, alpha, beta), lambda: self._vcycle(0, x, z, alpha, beta, y))
