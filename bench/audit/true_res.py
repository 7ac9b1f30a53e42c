# ruff: noqa
# One-off audit script of issues 26, 30 and 31 (2026-12-03, branch audit); outputs in bench/results/audit-26-30-31.txt.
"""implicit_euler on the 32^2 sheet: each step's true residual |b - A dv| / |b| recomputed in float64 from my own
assembly of Baraff-Witkin's A and b (design.md) at the step's start state, against the solver's report."""

import sys

import numpy as np
import scipy.sparse as sp
import warp as wp

wp.config.quiet = True
from warpcloth.scenarios import sheet

from warpcloth.run.harness import RunHarness

tol = float(sys.argv[1])
H = 1 / 60
sim = sheet.build(rows=32, cols=32, integrator="implicit_euler", integrator_options={"cg_tol": tol})
model, integ = sim.model, sim.integrator
h = model.host
P = h.pairs.astype(np.int64)
N = model.particle_count
m = h.mass.astype(np.float64)
free = h.inv_mass > 0
ks = model.spring_stiffness.numpy().astype(np.float64)
kd = model.spring_damping.numpy().astype(np.float64)
L0 = h.rest.astype(np.float64)
g = np.array(sim.control.gravity)
c = float(sim.control.drag_rate)


def system(x, v):
    d = x[P[:, 1]] - x[P[:, 0]]
    L = np.linalg.norm(d, axis=1)
    n = d / L[:, None]
    f = m[:, None] * g - c * m[:, None] * v
    fs = (ks * (L - L0) + kd * np.einsum("ij,ij->i", v[P[:, 1]] - v[P[:, 0]], n))[:, None] * n
    np.add.at(f, P[:, 0], fs)
    np.add.at(f, P[:, 1], -fs)
    nn = np.einsum("si,sj->sij", n, n)
    K = ks[:, None, None] * (nn + np.maximum(0, 1 - L0 / L)[:, None, None] * (np.eye(3) - nn))
    D = kd[:, None, None] * nn
    B = H * D + H * H * K  # per-spring block of A
    I, J = P[:, 0], P[:, 1]

    def blocks(ri, ci, blk):
        r = (3 * ri[:, None, None] + np.arange(3)[None, :, None]).repeat(3, 2)
        cc = (3 * ci[:, None, None] + np.arange(3)[None, None, :]).repeat(3, 1)
        return r.ravel(), cc.ravel(), blk.ravel()

    parts = [blocks(I, I, B), blocks(J, J, B), blocks(I, J, -B), blocks(J, I, -B)]
    r = np.concatenate([p[0] for p in parts])
    cc = np.concatenate([p[1] for p in parts])
    vv = np.concatenate([p[2] for p in parts])
    A = sp.coo_matrix((vv, (r, cc)), shape=(3 * N, 3 * N)).tocsr()
    A = A + sp.diags(np.repeat(m * (1 + H * c), 3))
    Kv = np.zeros((N, 3))  # K v (the spring stiffness product, f + h df/dx v with df/dx = -K)
    Kd = np.einsum("sij,sj->si", K, v[I] - v[J])
    np.add.at(Kv, I, Kd)
    np.add.at(Kv, J, -Kd)
    b = H * (f - H * Kv)
    # pinned: identity rows and columns, zero rhs
    fr = np.repeat(free, 3).astype(float)
    Dm = sp.diags(fr)
    A = Dm @ A @ Dm + sp.diags(1 - fr)
    b = b * free[:, None]
    return A, b.ravel()


for step in range(4):
    x = sim.state.particle_q.numpy().astype(np.float64)
    v = sim.state.particle_qd.numpy().astype(np.float64)
    integ.reset_stats()
    sim.simulate(1)
    A, b = system(x, v)
    dv = integ.dv.numpy().astype(np.float64).ravel()
    mine = np.linalg.norm(b - A @ dv) / np.linalg.norm(b)
    exact = sp.linalg.spsolve(A.tocsc(), b)
    floor = np.linalg.norm(b - A @ exact.astype(np.float32).astype(np.float64)) / np.linalg.norm(b)
    bdev = integ.b.numpy().astype(np.float64).ravel()
    st = integ.stats()
    own = np.linalg.norm(bdev - A @ dv) / np.linalg.norm(bdev)
    floor_own = np.linalg.norm(
        bdev - A @ sp.linalg.spsolve(A.tocsc(), bdev).astype(np.float32).astype(np.float64)
    ) / np.linalg.norm(bdev)
    print(
        f"tol {tol:g} step {step + 1}: with its own b and my float64 A: {own:.3e} (floor {floor_own:.2e}), above tol {own > tol}"
    )
    print(
        f"tol {tol:g} step {step + 1}: my float64 |b-A dv|/|b| {mine:.3e} (solver's true {st['cg_true_residual_max']:.3e}, CG reported {st['cg_residual_max']:.3e}, its b vs mine {np.linalg.norm(bdev - b) / np.linalg.norm(b):.1e}); float32 floor of the exact dv {floor:.2e}; above tol: {mine > tol} counted {st['cg_true_above_tol_steps']}"
    )
res = RunHarness(sheet.build(rows=32, cols=32, integrator="implicit_euler", integrator_options={"cg_tol": tol})).run(
    0.5
)
print(
    f"tol {tol:g}: run 0.5 s: solver_converged {res.solver_converged}, capped steps {res.solver_capped_steps}, true max {res.solver['cg_true_residual_max']:.3e}"
)
