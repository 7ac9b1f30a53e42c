"""Final positions and velocities of fold, tablecloth, sheet and drape under every integrator, saved to
compare two trees bit for bit (a refactor must not change one bit).

    PYTHONPATH=OLD_TREE python bench/bit_identity.py save old.npz [--steps 60] [--scenarios fold,drape]
    PYTHONPATH=NEW_TREE python bench/bit_identity.py save new.npz
    python bench/bit_identity.py compare old.npz new.npz      # "compared 72 arrays; IDENTICAL"
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

SCENES = {
    "fold": {"rows": 12, "cols": 6},
    "tablecloth": {"rows": 10, "cols": 10},
    "sheet": {"rows": 10, "cols": 10},
    "drape": {"rows": 10, "cols": 10},
}


def save(out: str, steps: int, scenes: list[str]) -> None:
    from warpcloth.integrators import integrator_names
    from warpcloth.scenarios import get_scenario

    arrays = {}
    for scene in scenes:
        for name in integrator_names():
            sim = get_scenario(scene).build(integrator=name, device="cpu", **SCENES[scene])
            for _ in range(steps):
                sim.step()
            arrays[f"{scene}/{name}/x"] = sim.state.particle_q.numpy()
            arrays[f"{scene}/{name}/v"] = sim.state.particle_qd.numpy()
            print(scene, name, flush=True)
    np.savez(out, **arrays)


def compare(a_path: str, b_path: str) -> int:
    a, b = np.load(a_path), np.load(b_path)
    bad = [k for k in a.files if k not in b.files or not np.array_equal(a[k], b[k])]
    print("compared", len(a.files), "arrays;", "IDENTICAL" if not bad else f"DIFFER: {bad}")
    return 1 if bad else 0


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="what", required=True)
    s = sub.add_parser("save")
    s.add_argument("out")
    s.add_argument("--steps", type=int, default=60)
    s.add_argument("--scenarios", default=",".join(SCENES))
    c = sub.add_parser("compare")
    c.add_argument("a")
    c.add_argument("b")
    args = p.parse_args()
    if args.what == "save":
        save(args.out, args.steps, [s for s in args.scenarios.split(",") if s])
        return 0
    return compare(args.a, args.b)


if __name__ == "__main__":
    sys.exit(main())
