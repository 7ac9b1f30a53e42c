"""Same cloth at every size: the static shape of a hanging and of a draped sheet at 16^2 .. 128^2,
made of a material (cotton, dihedral bending) and with today's per-spring parameters.

    python bench/material_convergence.py [--sizes 16,32,64,128] [--out DIR] [--scenes hanging,draped]

Each (scene, model, size) runs to rest (implicit Euler, dt 1/60; rest: every particle slower than
0.5 mm/s over 1 s, at most 20 s simulated, 12 s for the draped sheet) and its positions are kept in DIR (default
/tmp/material-convergence; a run found there is not run again, so the script resumes). Then, for
successive sizes, the coarser sheet's particles are compared with the finer sheet at the same
material points (bilinear in the finer grid's (u, v)): the largest and the root-mean-square
distance, divided by the cloth's size (1 m). The observed order is log2 of the ratio of successive
differences. The tables are docs/materials.md's ("Same cloth at every size"); this script's output
is bench/results/material-convergence.txt.

Scenes: ``hanging`` is the study's sheet (1 m x 1 m in a vertical plane, its two top corners
pinned, gravity, drag 1/s: a membrane problem, gravity in the sheet's plane); ``draped`` is a 1 m x
1 m sheet dropped flat on a table (a box, friction 0.5) with a quarter of it beyond the table's
straight edge: that quarter folds down and hangs, and bending shapes it where it leaves the edge.
(The drape scenario's sheet on a sphere is not used: its folds are a bifurcation, so its static
shape is not unique; its measure is the drape coefficient, docs/materials.md.) Models:
``material`` = cotton (docs/materials.md) with dihedral bending; ``per-spring`` = today's
defaults (0.2 kg, ks 1000/1000/200 N/m, Provot bend springs).
"""

from __future__ import annotations

import argparse
import itertools
import json
import math
import os
import time

import numpy as np

SCENES = {"hanging": "sheet", "draped": "edge"}
TABLE_HEIGHT, TABLE_THICKNESS, OVERHANG = 0.75, 0.01, 0.25
MODELS = {
    "material": dict(material="cotton", bend="dihedral"),
    "per-spring": dict(material="none", bend="provot"),
}


def edge_scenario():
    """The draped sheet: a 1 m square dropped flat on a table, OVERHANG [m] of it beyond the edge."""
    from warpcloth.scenarios.common import Scenario, ScenarioConfig
    from warpcloth.sim.colliders import Box
    from warpcloth.sim.control import Control

    def control(config, device):
        edge = 0.5 - OVERHANG  # the table's edge at x = 0.25: the sheet spans -0.5..0.5
        table = Box(
            center=(edge - 0.5, 0.5 * TABLE_HEIGHT, 0.0),
            half_extents=(0.5, 0.5 * TABLE_HEIGHT, 0.7),
            thickness=TABLE_THICKNESS,
            friction=0.5,
            edge_radius=0.0,  # sharp at every mesh size (the default rounds it by the cloth's spacing)
        )
        return Control(drag_rate=1.0, colliders=(table,), device=device)

    return Scenario(
        name="edge",
        description="a sheet on a table, a quarter of it over the edge",
        defaults=ScenarioConfig(rows=32, cols=32, width=1.0, height=1.0, mass=0.2),
        pins=lambda rows, cols: [],
        control=control,
        origin=lambda config: (-0.5, TABLE_HEIGHT + TABLE_THICKNESS + 0.002, -0.5),
        stop_at_equilibrium=True,
        plane="horizontal",
    )


def settle(scene: str, model: str, n: int, out: str, device: str) -> dict:
    """Run one (scene, model, size) to rest; its record (positions in ``out``)."""
    import warp as wp

    from warpcloth.run.harness import RunHarness
    from warpcloth.run.metrics import EquilibriumCriteria
    from warpcloth.scenarios import get_scenario

    path = os.path.join(out, f"{scene}-{model}-{n}.npz")
    if os.path.exists(path):
        data = np.load(path, allow_pickle=False)
        return {"x": data["x"], **json.loads(str(data["info"]))}
    wp.config.quiet = True
    scenario = edge_scenario() if SCENES[scene] == "edge" else get_scenario(SCENES[scene])
    cfg = scenario.config(rows=n, cols=n, integrator="implicit_euler", device=device, **MODELS[model])
    harness = RunHarness(
        scenario.build(cfg),
        scenario=scenario.name,
        equilibrium=EquilibriumCriteria(speed_tol=5e-4, force_tol=2e-3, window=1.0),
    )
    t = time.perf_counter()
    result = harness.run(20.0 if scene == "hanging" else 12.0, fps=30.0, stop_at_equilibrium=True)
    info = {
        "scene": scene,
        "model": model,
        "size": n,
        "stable": result.stable,
        "equilibrium": result.equilibrium_reached,
        "sim_time_s": result.sim_time,
        "wall_s": time.perf_counter() - t,
        "final_max_speed": result.final_max_speed,
        "max_strain": result.max_strain,
    }
    x = harness.sim.state.particle_q.numpy().astype(np.float64)
    np.savez(path, x=x, info=json.dumps(info))
    print(f"# ran {json.dumps(info)}", flush=True)
    return {"x": x, **info}


def sample(x_fine: np.ndarray, n_fine: int, n_coarse: int) -> np.ndarray:
    """The fine n x n sheet's positions at the coarse grid's material points (bilinear in (u, v))."""
    grid = x_fine.reshape(n_fine, n_fine, 3)
    s = np.linspace(0.0, 1.0, n_coarse) * (n_fine - 1)
    i0 = np.minimum(np.floor(s).astype(int), n_fine - 2)
    f = s - i0
    rows = grid[i0] * (1 - f)[:, None, None] + grid[i0 + 1] * f[:, None, None]  # (n_coarse, n_fine, 3)
    return rows[:, i0] * (1 - f)[None, :, None] + rows[:, i0 + 1] * f[None, :, None]


def table(records: dict, sizes: list, scene: str, model: str, size_m: float = 1.0) -> list[str]:
    lines = [
        f"{scene} sheet, {model}: static shape difference between successive sizes (/ {size_m:g} m)",
        "| sizes | max | rms | observed order (max) | observed order (rms) | at rest (coarse, fine) |",
        "|---|---|---|---|---|---|",
    ]
    previous = None
    for a, b in itertools.pairwise(sizes):
        ra, rb = records.get((scene, model, a)), records.get((scene, model, b))
        if ra is None or rb is None:
            continue
        d = np.linalg.norm(ra["x"].reshape(a, a, 3) - sample(rb["x"], b, a), axis=2) / size_m
        diff = (float(d.max()), float(np.sqrt(np.mean(d * d))))
        order = ("", "")
        if previous is not None:
            order = tuple(f"{math.log2(p / c):.2f}" if c > 0 and p > 0 else "" for p, c in zip(previous, diff))
        rest = f"{'yes' if ra['equilibrium'] else 'no'}, {'yes' if rb['equilibrium'] else 'no'}"
        lines.append(
            f"| {a}^2 -> {b}^2 | {100 * diff[0]:.3g} % | {100 * diff[1]:.3g} % | {order[0]} | {order[1]} | {rest} |"
        )
        previous = diff
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="16,32,64,128")
    parser.add_argument("--scenes", default="hanging,draped")
    parser.add_argument("--models", default="material,per-spring")
    parser.add_argument("--out", default="/tmp/material-convergence")
    parser.add_argument("--device", default="cpu")
    args = parser.parse_args()
    sizes = [int(s) for s in args.sizes.split(",")]
    os.makedirs(args.out, exist_ok=True)
    records = {}
    for n in sizes:  # every scene and model at a size before the next size: the tables fill from the top
        for scene in args.scenes.split(","):
            for model in args.models.split(","):
                records[(scene, model, n)] = settle(scene, model, n, args.out, args.device)
    for scene in args.scenes.split(","):
        for model in args.models.split(","):
            print()
            print("\n".join(table(records, sizes, scene, model)))
    print()
    print("| scene | model | size | at rest | simulated [s] | wall [s] | largest speed at the end [m/s] | max strain |")
    print("|---|---|---|---|---|---|---|---|")
    for (scene, model, n), r in records.items():
        print(
            f"| {scene} | {model} | {n}^2 | {'yes' if r['equilibrium'] else 'no'} | {r['sim_time_s']:.2f} | "
            f"{r['wall_s']:.0f} | {r['final_max_speed']:.2g} | {100 * r['max_strain']:.2f} % |"
        )


if __name__ == "__main__":
    main()
