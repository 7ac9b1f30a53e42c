"""implicit_euler's two system-matrix paths (issue 26 item 6) on the numpy peer's workload (1 m, 1 kg
sheet, ks 1000, kd 1, no drag, dt 1/60). --product: A x by matrix="bsr" (assembled blocks) and by
matrix="free" (gather over springs) against A x in float64 from the same spring blocks B_s and
masses. --dv (default): one step (or --steps) from rest with each path at the same CG tolerance:
|dv_bsr - dv_free| / |dv_free| and the lowest point.

    python bench/solver_checks/bsr_vs_free.py --sizes 8 16 32 64 --tol 1e-6
    python bench/solver_checks/bsr_vs_free.py --sizes 128 256 --tol 1e-3 --steps 10
    python bench/solver_checks/bsr_vs_free.py --product --sizes 64 256
"""

import argparse

import numpy as np
import warp as wp

from warpcloth.integrators.forces import eval_forces
from warpcloth.kernels import implicit as ik
from warpcloth.scenarios import sheet

DT = 1.0 / 60.0


def peer(size, matrix, **opts):
    return sheet.build(
        rows=size,
        cols=size,
        integrator="implicit_euler",
        integrator_options=dict(matrix=matrix, **opts),
        dt=DT,
        mass=1.0,
        stiffness=1000.0,
        damping=1.0,
        drag=0.0,
        device="cpu",
    )


def reference_Ax(model, B, x):
    """float64 A x: A_ii = m_i I + sum_s B_s, A_ij = -B_s (free rows and columns only), pinned rows identity."""
    pairs = model.host.pairs.astype(np.int64).reshape(-1, 2)
    m = model.host.mass.astype(np.float64)
    free = model.host.inv_mass > 0
    B = B.astype(np.float64)
    y = m[:, None] * x
    i, j = pairs[:, 0], pairs[:, 1]
    xj_eff = np.where(free[j][:, None], x[j], 0.0)
    xi_eff = np.where(free[i][:, None], x[i], 0.0)
    np.add.at(y, i, np.einsum("sab,sb->sa", B, x[i]) - np.einsum("sab,sb->sa", B, xj_eff))
    np.add.at(y, j, np.einsum("sab,sb->sa", B, x[j]) - np.einsum("sab,sb->sa", B, xi_eff))
    y[~free] = x[~free]
    return y


def products(size):
    sims = {k: peer(size, k) for k in ("bsr", "free")}
    for sim in sims.values():
        s, m = sim.integrator.system, sim.model
        x, v, f = sim.state.particle_q, sim.state.particle_qd, sim.state.particle_f
        eval_forces(m, x, v, sim.control, f)
        s.assemble(x, DT, 0.0)
        wp.launch(
            ik.eval_rhs,
            dim=m.particle_count,
            inputs=[f, v, s.springs, s.spring_K, m.particle_inv_mass, DT],
            outputs=[sim.integrator.b],
        )
    n = sims["bsr"].model.particle_count
    B = sims["bsr"].integrator.system.spring_B.numpy()
    same_B = np.array_equal(B, sims["free"].integrator.system.spring_B.numpy())
    same_b = np.array_equal(sims["bsr"].integrator.b.numpy(), sims["free"].integrator.b.numpy())
    print(f"# {size}^2: B_s identical in both paths: {same_B}; b identical: {same_b}")
    xs = {
        "random": np.random.default_rng(1).normal(size=(n, 3)),
        "b (smooth)": sims["bsr"].integrator.b.numpy().astype(np.float64),
    }
    for name, xv in xs.items():
        ref = reference_Ax(sims["bsr"].model, B, xv.astype(np.float32).astype(np.float64))
        xw = wp.array(xv.astype(np.float32), dtype=wp.vec3)
        for k, sim in sims.items():
            out = wp.zeros(n, dtype=wp.vec3)
            s = sim.integrator.system
            (s.bsr_matvec if k == "bsr" else s.matvec)(xw, out, out, 1.0, 0.0)
            z = out.numpy().astype(np.float64)
            print(
                f"{size}^2 x = {name:10s} {k:4s}: |A x - (A x)_64| / |(A x)_64| = "
                f"{np.linalg.norm(z - ref) / np.linalg.norm(ref):.3e}",
                flush=True,
            )


def dv_difference(size, tol, steps):
    out = {}
    for k in ("bsr", "free"):
        sim = peer(size, k, cg_tol=tol)
        sim.simulate(steps)
        out[k] = (
            sim.integrator.dv.numpy().astype(np.float64),
            float(sim.state.particle_q.numpy()[:, 1].min()),
            sim.integrator.stats(),
        )
    d = np.linalg.norm(out["bsr"][0] - out["free"][0]) / np.linalg.norm(out["free"][0])
    low = out["bsr"][1] - out["free"][1]
    print(
        f"{size}^2 tol {tol:g} after {steps} steps: |dv_bsr - dv_free| / |dv_free| = {d:.3e}; lowest point bsr - free "
        f"{low:+.2e} m; CG its bsr {out['bsr'][2]['cg_iterations_mean']:.0f} free "
        f"{out['free'][2]['cg_iterations_mean']:.0f}",
        flush=True,
    )


def main():
    wp.config.quiet = True
    ap = argparse.ArgumentParser()
    ap.add_argument("--sizes", type=int, nargs="*", default=[16, 32, 64])
    ap.add_argument("--tol", type=float, default=1e-6)
    ap.add_argument("--steps", type=int, default=1)
    ap.add_argument("--product", action="store_true")
    a = ap.parse_args()
    for n in a.sizes:
        products(n) if a.product else dv_difference(n, a.tol, a.steps)


if __name__ == "__main__":
    main()
