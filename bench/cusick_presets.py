"""The Cusick drape test of every material preset at several disc resolutions.

    python bench/cusick_presets.py [--sizes 24,32] [--presets cotton,...] [--out FILE.jsonl]

Each run is ``warpcloth run cusick --material PRESET --size N`` at its defaults (implicit Euler,
dt 1/240 s, drag 3/s, 3 s simulated, dihedral bending): the drape coefficient, the node count and whether
DC falls in the published range for the fabric (docs/materials.md). Runs already in FILE (default
/tmp/cusick-presets.jsonl) are not run again. The table is docs/materials.md's ("The Cusick
scenario"); this script's output is bench/results/cusick-presets.txt.
"""

from __future__ import annotations

import argparse
import json
import os
import time


def run_one(preset: str, n: int, device: str) -> dict:
    import warp as wp

    from warpcloth.scenarios import get_scenario

    wp.config.quiet = True
    scenario = get_scenario("cusick")
    t = time.perf_counter()
    result = scenario.run(scenario.config(rows=n, cols=n, material=preset, device=device))
    m = result.measurements
    return {
        "preset": preset,
        "size": n,
        "stable": result.stable,
        "dc": m.get("drape_coefficient"),
        "nodes": m.get("nodes"),
        "low": m.get("published_dc_low"),
        "high": m.get("published_dc_high"),
        "within": m.get("within_published"),
        "at_rest": result.equilibrium_reached,
        "max_strain": result.max_strain,
        "wall_s": time.perf_counter() - t,
        "particles": result.particles,
    }


def main() -> None:
    from warpcloth.sim.material import PRESETS

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="24,32")
    parser.add_argument("--presets", default=",".join(PRESETS))
    parser.add_argument("--out", default="/tmp/cusick-presets.jsonl")
    parser.add_argument("--device", default="cpu")
    args = parser.parse_args()
    done = {}
    if os.path.exists(args.out):
        for line in open(args.out):
            r = json.loads(line)
            done[(r["preset"], r["size"])] = r
    sizes = [int(s) for s in args.sizes.split(",")]
    presets = args.presets.split(",")
    for n in sizes:
        for preset in presets:
            if (preset, n) not in done:
                r = run_one(preset, n, args.device)
                done[(preset, n)] = r
                with open(args.out, "a") as f:
                    f.write(json.dumps(r) + "\n")
                print(f"# {json.dumps(r)}", flush=True)
    head = " | ".join(f"{n}^2 DC, nodes" for n in sizes)
    print(f"| preset | published DC | {head} |")
    print("|---|---|" + "---|" * len(sizes))
    for preset in presets:
        cells = []
        for n in sizes:
            r = done.get((preset, n))
            if r is None or not r["stable"]:
                cells.append("unstable" if r else "")
                continue
            mark = "" if r["within"] is None else (" ✓" if r["within"] else " ✗")
            cells.append(f"{100 * r['dc']:.1f} %{mark}, {r['nodes']}")
        r0 = done.get((preset, sizes[0])) or {}
        published = f"{100 * r0['low']:.0f}-{100 * r0['high']:.0f} %" if r0.get("low") is not None else ""
        print(f"| {preset} | {published} | " + " | ".join(cells) + " |")
    print()
    print("| preset | size | wall [s] | at rest | max strain |")
    print("|---|---|---|---|---|")
    for (preset, n), r in sorted(done.items(), key=lambda kv: (kv[0][1], kv[0][0])):
        if preset in presets and n in sizes:
            print(f"| {preset} | {n}^2 | {r['wall_s']:.0f} | {r['at_rest']} | {100 * r['max_strain']:.1f} % |")


if __name__ == "__main__":
    main()
