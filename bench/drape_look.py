"""The drape and the tablecloth at their defaults: how long a frame takes, how many folds they make,
and what they look like in the HTML player (docs/drape.png, docs/tablecloth.png).

    python bench/drape_look.py [--scenarios drape,tablecloth] [--frames 300] [--screenshots DIR]
                               [--integrators xpbd,implicit_euler,...] [--bend dihedral]

Per scenario and integrator: the median wall time of one 1/60 s frame (``sim.simulate`` of a
frame's steps, after a warm-up frame; p10-p90 spread over the frames), the folds at the end
(``Scenario.measure``: peaks of a level cut of the hanging cloth) and the largest spring strain.
With ``--screenshots DIR`` the default integrator's run is written as an HTML player page and
headless Chromium photographs its last frame into DIR/<scenario>.png. Output:
bench/results/drape-look-cpu.txt.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import tempfile
import time

import numpy as np

CHROMIUM_FLAGS = [
    "--headless=new",
    "--no-sandbox",
    "--disable-gpu",
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
    "--hide-scrollbars",
    "--window-size=900,650",
    "--virtual-time-budget=8000",
]


def timed_run(name: str, integrator: str | None, frames: int, html: str | None, device: str, bend=None) -> dict:
    import warp as wp

    from warpcloth.io.player import HtmlWriter
    from warpcloth.scenarios import get_scenario

    wp.config.quiet = True
    scenario = get_scenario(name)
    cfg = scenario.config(device=device, bend=bend, **({"integrator": integrator} if integrator else {}))
    sim = scenario.build(cfg)
    per_frame = max(1, int(round((1.0 / 60.0) / sim.dt)))
    writer = None
    if html:
        writer = HtmlWriter(
            html,
            sim.model,
            60.0,
            title=f"warpcloth {name}: {sim.integrator.name}, {sim.model.rows}x{sim.model.cols}, cotton",
            expected_frames=frames + 1,
            colliders=sim.control.colliders,
        )
        writer.write_frame(sim.state.particle_q.numpy(), 0.0)
    sim.simulate(per_frame)  # warm-up: compile, capture
    times = []
    for k in range(frames - 1):
        t = time.perf_counter()
        sim.simulate(per_frame)
        wp.synchronize_device(sim.model.device)
        times.append(time.perf_counter() - t)
        if writer is not None:
            writer.write_frame(sim.state.particle_q.numpy(), (k + 2) / 60.0)
    if writer is not None:
        writer.close()
    x = sim.state.particle_q.numpy()
    pairs, rest = sim.model.host.pairs, sim.model.host.rest
    strain = np.linalg.norm(x[pairs[:, 1]] - x[pairs[:, 0]], axis=1) / rest - 1.0
    ms = 1000.0 * np.asarray(times)
    return {
        "scenario": name,
        "integrator": sim.integrator.name,
        "bend": cfg.bend,
        "size": f"{sim.model.rows}x{sim.model.cols}",
        "dt": sim.dt,
        "steps_per_frame": per_frame,
        "ms_median": float(np.median(ms)),
        "ms_p10": float(np.percentile(ms, 10)),
        "ms_p90": float(np.percentile(ms, 90)),
        "folds": scenario.measure(sim, cfg).get("folds") if scenario.measure else None,
        "max_strain": float(strain.max()),
        "finite": bool(np.isfinite(x).all()),
    }


def screenshot(html: str, png: str, t: float) -> None:
    browser = next(
        (shutil.which(b) for b in ("chromium", "chromium-browser", "google-chrome") if shutil.which(b)), None
    )
    if browser is None:
        raise SystemExit("no Chromium found for --screenshots")
    with tempfile.TemporaryDirectory() as profile:
        subprocess.run(
            [browser, *CHROMIUM_FLAGS, f"--user-data-dir={profile}", f"--screenshot={png}", f"file://{html}#t={t}"],
            capture_output=True,
            timeout=300,
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenarios", default="drape,tablecloth")
    parser.add_argument("--integrators", default="", help="comma-separated; default: the scenario's own")
    parser.add_argument("--frames", type=int, default=300)
    parser.add_argument("--screenshots", default=None, metavar="DIR")
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--bend", default=None, help="the bending model (default the scenario's: provot)")
    args = parser.parse_args()
    print("| scenario | integrator | bend | size | dt [s] | steps/frame | ms/frame median [p10, p90] | folds |", end="")
    print(" max strain |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name in args.scenarios.split(","):
        for integrator in args.integrators.split(",") if args.integrators else [None]:
            html = None
            if args.screenshots and integrator is None:
                html = os.path.abspath(os.path.join(tempfile.gettempdir(), f"warpcloth-{name}.html"))
            r = timed_run(name, integrator, args.frames, html, args.device, args.bend)
            print(
                f"| {r['scenario']} | {r['integrator']} | {r['bend']} | {r['size']} | {r['dt']:.3g} | "
                f"{r['steps_per_frame']} | "
                f"{r['ms_median']:.1f} [{r['ms_p10']:.1f}, {r['ms_p90']:.1f}] | {r['folds']} | "
                f"{100 * r['max_strain']:.1f} %{'' if r['finite'] else ' (not finite)'} |",
                flush=True,
            )
            if html:
                png = os.path.join(args.screenshots, f"{name}.png")
                screenshot(html, os.path.abspath(png), (args.frames - 1) / 60.0)
                print(f"# wrote {png}", flush=True)


if __name__ == "__main__":
    main()
