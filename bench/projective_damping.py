"""Projective dynamics' isotropic spring damping on a swing (docs/solvers.md, "Known limit").

    python bench/projective_damping.py

The sheet (6 x 6) released from horizontal for 0.25 s, 16 steps a 1/60 s frame, against the
float64 reference: the error (fraction of the cloth size) of implicit_euler and projective with
the default drag and spring damping, and with either set to 0.
"""

from warpcloth.integrators import make_integrator
from warpcloth.lab.accuracy import AccuracyProblem, Transient
from warpcloth.scenarios import get_scenario


def main() -> None:
    for drag, damping in ((1.0, None), (0.0, None), (0.0, 0.0), (1.0, 0.0)):
        sim = get_scenario("sheet").build(
            rows=6, cols=6, device="cpu", integrator="implicit_euler", use_graph=False, drag=drag, damping=damping
        )
        problem = AccuracyProblem(sim, Transient("sheet", 0.25, True))
        errors = []
        for name in ("implicit_euler", "projective"):
            sim.set_integrator(make_integrator(name))
            errors.append(problem.error(sim, 16))
        kd = "default" if damping is None else f"{damping:g}"
        print(
            f"drag {drag:g} 1/s, kd {kd:8s}: implicit_euler e = {errors[0]:.4f}, projective e = {errors[1]:.4f}",
            flush=True,
        )


if __name__ == "__main__":
    main()
