"""Linear-solver pieces the integrators share: sums in a fixed order, the exact solve of a
3-unknown (rigid translation) Galerkin problem and a preconditioned CG whose scalars live on the
device.

Dot products are summed without atomics, in an order fixed by the problem size alone (per-element
terms, sums over fixed chunks, then the chunks' sum by one thread), so results are bit-identical
run to run, on every device, and between launches and graph replay.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from warpcloth.kernels import linalg as lk


class OrderedSum:
    """Sums of ``count`` per-element terms in a fixed order (:mod:`warpcloth.kernels.linalg`:
    ``sum_chunks`` then ``sum_partials``). A kernel writes the terms to :attr:`terms`;
    :meth:`sum_into` adds them up. All arrays are allocated here.
    """

    def __init__(self, count: int, device):
        self.count, self.device = int(count), device
        #: The terms to sum, shape (count,); written by the caller's kernels.
        self.terms = wp.zeros(self.count, dtype=float, device=device)
        self.chunk = max(1, -(-self.count // 128))
        self.partial = wp.zeros(-(-self.count // self.chunk), dtype=float, device=device)

    def sum_into(self, out, k: int) -> None:
        """out[k] = sum of :attr:`terms` (device launches only)."""
        d = self.device
        wp.launch(
            lk.sum_chunks,
            dim=self.partial.shape[0],
            inputs=[self.terms, self.chunk, self.count],
            outputs=[self.partial],
            device=d,
        )
        wp.launch(lk.sum_partials, dim=1, inputs=[self.partial, k], outputs=[out], device=d)


class TranslationSolve:
    """A 3-unknown Galerkin problem solved exactly, t = (sum_i A_i + regular I)^-1 sum_i b_i, the
    sums in a fixed order (:mod:`warpcloth.kernels.linalg`: ``sum_block_chunks`` then
    ``solve_block_sum``): the rigid translation mode of vbd's and projective dynamics' solves
    (issue 26). A kernel writes the per-particle terms to :attr:`b` and :attr:`A`; :meth:`solve`
    leaves t in :attr:`translation` [m], shape (1,). All arrays are allocated here.
    """

    def __init__(self, count: int, regular: float, device):
        self.count, self.regular, self.device = int(count), float(regular), device
        #: The per-particle terms T^T r and T^T A T, shape (count,); written by the caller's kernels.
        self.b = wp.zeros(self.count, dtype=wp.vec3, device=device)
        self.A = wp.zeros(self.count, dtype=wp.mat33, device=device)
        self.chunk = max(1, -(-self.count // 128))
        chunks = -(-self.count // self.chunk)
        self.b_partial = wp.zeros(chunks, dtype=wp.vec3, device=device)
        self.A_partial = wp.zeros(chunks, dtype=wp.mat33, device=device)
        self.translation = wp.zeros(1, dtype=wp.vec3, device=device)

    def solve(self) -> None:
        """translation[0] = t (device launches only)."""
        d = self.device
        wp.launch(
            lk.sum_block_chunks,
            dim=self.b_partial.shape[0],
            inputs=[self.b, self.A, self.chunk, self.count],
            outputs=[self.b_partial, self.A_partial],
            device=d,
        )
        wp.launch(
            lk.solve_block_sum,
            dim=1,
            inputs=[self.b_partial, self.A_partial, self.regular],
            outputs=[self.translation],
            device=d,
        )


class DevicePCG:
    """Preconditioned CG whose scalars live in a device array, run in chunks of ``check_every``
    iterations between host convergence checks (implicit_euler's solver on the CPU).

    A solve is a start (r = b - A x, z = M r, p = z, the tolerance from |b|) and chunks of
    iterations; each iteration is A p, p.Ap, the fused update of x and r with r.r, the convergence
    count, z = M r, r.z and the new direction. Once converged (r.r <= tol^2 b.b, warp's ``cg``
    test) or at ``max_iter`` a device flag turns the updates of x, r and p into no-ops, so the
    rest of a chunk changes nothing. Dot products are summed in a fixed order (chunks, then their
    sum), so results do not depend on scheduling. Where the device can capture (the CPU from Warp
    1.19), the start and a chunk are each captured once and replayed: a chunk of iterations costs
    one call instead of ~40 Python launches per iteration with a multigrid V-cycle.

    ``apply_A`` and ``apply_M`` are LinearOperator matvecs ``(x, y, z, alpha, beta)``. All arrays
    are allocated here.
    """

    def __init__(self, apply_A, apply_M, b, x, tol: float, max_iter: int, check_every: int, device):
        self.apply_A, self.apply_M, self.b, self.x = apply_A, apply_M, b, x
        self.tol, self.max_iter, self.check_every = float(tol), int(max_iter), int(check_every)
        self.device = wp.get_device(device)
        n = b.shape[0]
        self.r, self.z, self.p, self.q = (wp.zeros(n, dtype=wp.vec3, device=device) for _ in range(4))
        self.sums = OrderedSum(n, device)
        self.scalars = wp.zeros(8, dtype=float, device=device)
        major, minor = (int(v) for v in wp.config.version.split(".")[:2])
        self._capture = self.device.is_cpu and (major, minor) >= (1, 19)
        self._graphs: dict = {}

    def reset(self) -> None:
        """Capture the start and the chunk anew at the next solve (after ``apply_A`` changed what it launches)."""
        self._graphs.clear()

    def _dot(self, a, b, slot: int) -> None:
        """scalars[slot] = a . b (``a`` None: of the terms already in ``sums.terms``), summed in a fixed order."""
        if a is not None:
            wp.launch(lk.dot_terms, dim=self.sums.count, inputs=[a, b], outputs=[self.sums.terms], device=self.device)
        self.sums.sum_into(self.scalars, slot)

    def _start(self) -> None:
        n, d = self.b.shape[0], self.device
        self.apply_A(self.x, self.b, self.r, -1.0, 1.0)
        self._dot(self.b, self.b, 4)
        self._dot(self.r, self.r, 3)
        self.apply_M(self.r, self.z, self.z, 1.0, 0.0)
        self._dot(self.r, self.z, 0)
        wp.launch(lk.cg_start, dim=n, inputs=[self.tol, self.scalars, self.p, self.z], outputs=[self.x], device=d)

    def _iterations(self, count: int) -> None:
        n, d, s = self.b.shape[0], self.device, self.scalars
        for _ in range(count):
            self.apply_A(self.p, self.q, self.q, 1.0, 0.0)
            self._dot(self.p, self.q, 2)
            wp.launch(
                lk.cg_update_solution,
                dim=n,
                inputs=[s, self.p, self.q],
                outputs=[self.x, self.r, self.sums.terms],
                device=d,
            )
            self._dot(None, None, 3)
            wp.launch(lk.cg_count, dim=1, inputs=[self.max_iter, s], device=d)
            self.apply_M(self.r, self.z, self.z, 1.0, 0.0)
            self._dot(self.r, self.z, 1)
            wp.launch(lk.cg_update_direction, dim=n, inputs=[s, self.z], outputs=[self.p], device=d)
            wp.launch(lk.cg_shift, dim=1, inputs=[s], device=d)

    def _run(self, key, record) -> None:
        if not self._capture or self.device.is_capturing:
            record()
            return
        graph = self._graphs.get(key)
        if graph is None:
            with wp.ScopedCapture(device=self.device) as capture:
                record()
            graph = self._graphs[key] = capture.graph
        wp.capture_launch(graph)

    def solve(self) -> tuple[int, float]:
        """x = A^-1 b from the current x; returns (iterations, final relative residual |r| / |b|),
        reading the scalars on the host once per chunk."""
        self._run("start", self._start)
        while True:
            s = self.scalars.numpy()
            if s[7] != 0.0:
                break
            self._run("chunk", lambda: self._iterations(self.check_every))
        rr, bb = float(s[3]), float(s[4])
        return int(s[6]), (float(np.sqrt(rr / bb)) if bb > 0.0 else 0.0), bool(s[3] <= s[5])


__all__ = ["DevicePCG", "OrderedSum", "TranslationSolve"]
