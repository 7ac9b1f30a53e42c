"""implicit_euler's reported CG residual against the true one (issue 26 item 5). Per step of the
scenario sheet (32^2 default: 0.2 kg, ks 1000, drag 1, dt 1/60) at --tol: the residual CG reports
(its recursively updated r), the device-recomputed true residual and floor estimate in the stats,
the true |b - A dv| / |b| recomputed here in float64 from the step's own b, dv and the model's A
(float64 from the step's spring blocks B_s and the masses), and the floor: the same for the exact
float64 solution rounded to float32. Also the cruder floor bound eps32 || |A| |dv| || / |b|.

    python bench/solver_checks/true_residual.py [--size 32] [--tol 1e-5] [--steps 3] [--restarts R] [--matrix bsr]
"""

import argparse

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
import warp as wp

from warpcloth.scenarios import sheet

EPS32 = float(np.finfo(np.float32).eps)


def model_matrix(integ, model, h, drag):
    """The model's A = M (1 + h c) + sum_s B_s terms in float64 (pinned rows and columns: identity)."""
    pairs = model.host.pairs.astype(np.int64).reshape(-1, 2)
    n = model.particle_count
    free = model.host.inv_mass > 0
    B = integ.system.spring_B.numpy().astype(np.float64)
    m = model.host.mass.astype(np.float64) * (1.0 + h * drag)
    rows, cols, vals = [], [], []

    def add(r, c, blocks):
        for a in range(3):
            for b in range(3):
                rows.append(3 * r + a)
                cols.append(3 * c + b)
                vals.append(blocks[:, a, b])

    i, j = pairs[:, 0], pairs[:, 1]
    add(np.arange(n), np.arange(n), m[:, None, None] * np.eye(3)[None])
    add(i, i, B)
    add(j, j, B)
    off = free[i] & free[j]
    add(i[off], j[off], -B[off])
    add(j[off], i[off], -B[off])
    A = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(3 * n, 3 * n))
    pinned = np.flatnonzero(~free)
    keep = np.ones(3 * n, bool)
    keep[(3 * pinned[:, None] + np.arange(3)).ravel()] = False
    D = sp.diags(keep.astype(float))
    return (D @ A @ D + sp.diags((~keep).astype(float))).tocsr()


def main():
    wp.config.quiet = True
    ap = argparse.ArgumentParser()
    ap.add_argument("--size", type=int, default=32)
    ap.add_argument("--tol", type=float, default=1e-5)
    ap.add_argument("--steps", type=int, default=3)
    ap.add_argument("--matrix", default="bsr")
    ap.add_argument("--restarts", type=int, default=None)
    a = ap.parse_args()
    opts = dict(cg_tol=a.tol, matrix=a.matrix, **({} if a.restarts is None else {"cg_restarts": a.restarts}))
    sim = sheet.build(rows=a.size, cols=a.size, integrator="implicit_euler", integrator_options=opts)
    integ, m, h = sim.integrator, sim.model, sim.dt
    drag = float(sim.control.drag_rate)
    print(f"# implicit_euler {opts}, sheet {a.size}^2, dt {h:.4g}: per step")
    for k in range(a.steps):
        integ.reset_stats()
        sim.simulate(1)
        st = integ.stats()
        b = integ.b.numpy().astype(np.float64).ravel()
        dv = integ.dv.numpy().astype(np.float64).ravel()
        A = model_matrix(integ, m, h, drag)
        nb = np.linalg.norm(b)
        true = np.linalg.norm(b - A @ dv) / nb
        exact = spla.spsolve(A.tocsc(), b)
        floor = np.linalg.norm(b - A @ exact.astype(np.float32).astype(np.float64)) / nb
        bound = EPS32 * np.linalg.norm(abs(A) @ np.abs(dv)) / nb
        print(
            f"step {k + 1}: reported {st['cg_residual_max']:.2e} ({st['cg_iterations_max']} its); device true "
            f"{st['cg_true_residual_max']:.2e}, floor est. {st['cg_float32_floor_max']:.2e}; float64 true {true:.2e}; "
            f"floor (exact rounded to float32) {floor:.2e}; eps32 |||A||dv||| / |b| {bound:.2e}",
            flush=True,
        )


if __name__ == "__main__":
    main()
