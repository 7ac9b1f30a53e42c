"""What implicit_euler's strain cap (option ``strain_cap``, default 0.1) costs a step where it does
not bind: the cap against none on scenes whose springs stay under it.

    python bench/strain_cap.py [--device cpu] [--sizes 64 128] [--steps 10] [--repeats 5]

Per case, ms/step (kernel time after warm-up, :func:`implicit.ms_per_step`) with ``strain_cap``
0 and 0.1, alternating (0, 0.1, 0, 0.1, ...) so that a shared machine's load falls on both; prints
the median [min-max] of each and of the per-repeat ratio cap / none. Cases: the sheet hanging from
its top row from rest, and the default drape's first steps of its fall (before it lands, 0.15 s).
Where the cap binds (the drape's landing) the bare scheme goes unstable, so there is no like run.
"""

from __future__ import annotations

import argparse
import platform

import warp as wp
from implicit import ms_per_step, spread  # bench/implicit.py: the same timing and summary

from warpcloth.scenarios import get_scenario


def case(name: str, n: int | None, cap: float, device: str):
    size = {} if n is None else {"rows": n, "cols": n}
    return get_scenario(name).build(
        **size, integrator="implicit_euler", integrator_options={"strain_cap": cap}, device=device
    )


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--device", default="cpu")
    p.add_argument("--sizes", type=int, nargs="+", default=[64, 128], help="sheet sizes")
    p.add_argument("--steps", type=int, default=9, help="steps timed per case (the drape falls 0.15 s in 9)")
    p.add_argument("--repeats", type=int, default=5)
    a = p.parse_args(argv)
    wp.config.quiet = True
    print(
        f"# {platform.node()} {platform.processor() or platform.machine()} warp {wp.config.version} device {a.device}"
    )
    cases = [("sheet", n) for n in a.sizes] + [("drape", None)]
    for name, n in cases:
        times = {0.0: [], 0.1: []}
        for _ in range(a.repeats):
            for cap in (0.0, 0.1):
                times[cap].append(ms_per_step(case(name, n, cap, a.device), a.steps))
        ratios = [c / b for b, c in zip(times[0.0], times[0.1])]
        label = f"{name} {n}x{n}" if n else f"{name} (default size)"
        print(f"{label}: none {spread(times[0.0])} ms, cap 0.1 {spread(times[0.1])} ms, cap/none {spread(ratios)}")


if __name__ == "__main__":
    main()
