"""The largest spring strain each integrator reaches on the built-in scenarios at its default dt,
and rk4 at a half and a quarter of its default (converged): the measurement behind the default
instability strain (warpcloth.run.metrics.DEFAULT_INSTABILITY_STRAIN).

    python bench/instability_strain.py [--duration-sheet 4] [--duration-flag 5]
"""

import argparse

from warpcloth.scenarios import flag, sheet


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--duration-sheet", type=float, default=4.0)
    p.add_argument("--duration-flag", type=float, default=5.0)
    args = p.parse_args(argv)
    runs = (("rk4", 0.25), ("rk4", 0.5), ("explicit_euler", 1.0), ("pbd", 1.0), ("xpbd", 1.0), ("implicit_euler", 1.0))
    print("scenario  integrator      dt [s]     max strain")
    for scenario, duration in ((sheet, args.duration_sheet), (flag, args.duration_flag)):
        for integrator, fraction in runs:
            harness = scenario.SCENARIO.harness(integrator=integrator, instability_strain=10.0)
            sim = harness.sim
            sim.set_dt(sim.dt * fraction)
            r = harness.run(duration, stop_at_equilibrium=False)
            print(
                f"{scenario.SCENARIO.name:9s} {integrator:15s} {sim.dt:9.3g}  {100 * r.max_strain:6.2f} %", flush=True
            )


if __name__ == "__main__":
    main()
