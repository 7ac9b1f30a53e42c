"""``warpcloth run SCENARIO`` (also ``python -m warpcloth run SCENARIO``): a scenario run with its outputs (USD, HTML player, preview), its progress and its summary."""

from __future__ import annotations

import argparse
import math
import os
import sys

from warpcloth.cli.model import DefaultDtExplained, add_model_arguments, check_spacing, config_from_args
from warpcloth.errors import WarpclothError
from warpcloth.io.files import sweep_stale_temporaries
from warpcloth.io.player import HtmlWriter, check_html_path
from warpcloth.io.preview import PreviewWriter, check_preview_path
from warpcloth.io.progress import RunProgress
from warpcloth.io.provenance import provenance
from warpcloth.io.usd import clip_folder_of, usd_frames
from warpcloth.scenarios import get_scenario


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The flags of ``warpcloth run``."""
    p.add_argument("scenario", help="scenario name (see 'warpcloth list') or a scenario file, path/to/scenario.toml")
    add_run_arguments(p)


def add_run_arguments(p: argparse.ArgumentParser) -> None:
    """Flags of a scenario run (``warpcloth run``)."""
    num_frames = (("--num-frames",), dict(type=int, default=None, help="run this many frames instead of --duration"))
    add_model_arguments(p, "run", exclusive={"duration": [num_frames]})
    out = p.add_argument_group("outputs")
    out.add_argument(
        "--usd",
        "--stage-path",
        dest="usd",
        default=None,
        metavar="PATH",
        help="write the animation to this USD file (.usd/.usda/.usdc, or .usdz: a package)",
    )
    out.add_argument(
        "--usd-color",
        choices=["none", "strain"],
        default="none",
        help="strain: a per-frame primvars:displayColor of spring strain, blue 0 to red 10%% (default none)",
    )
    out.add_argument(
        "--usd-colliders",
        choices=["guide", "render"],
        default="guide",
        help="UsdGeom purpose of the collider prims: guide (shown in viewports, not rendered) or render "
        "(default guide)",
    )
    out.add_argument(
        "--html",
        default=None,
        metavar="PATH",
        help="write a self-contained HTML player of the animation (WebGL, no network)",
    )
    out.add_argument(
        "--preview",
        default=None,
        metavar="PATH",
        help="write a picture: .png (the last frame) or .gif (the animation, frames skipped to fit); needs "
        "warpcloth[plot]",
    )
    p.add_argument("--fail-unstable", action="store_true", help="exit with status 3 when the run goes unstable")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of the summary")


def summary(result) -> str:
    """A short human-readable summary of a RunResult."""
    lines = [
        f"{result.scenario}: {result.integrator} on {result.device}, {result.rows}x{result.cols} "
        f"({result.particles} particles, {result.springs} springs), dt={result.dt:.3g} s",
        f"  simulated {result.sim_time:.3f} s in {result.steps} steps, {result.wall_time:.2f} s wall "
        f"(+{result.compile_time:.2f} s compile"
        + (f", +{result.capture_time:.2f} s graph capture" if result.capture_time else "")
        + ")",
        f"  {result.ms_per_step:.4f} ms/step, {result.steps_per_sec:,.0f} steps/s, real-time factor "
        f"{result.realtime_factor:.2f}" + (" (graph replay)" if result.graph else ""),
        f"  stable: {'yes' if result.stable else 'NO (' + result.unstable_reason + ')'}, max strain "
        f"{100 * result.max_strain:.2f} %",
    ]
    if result.scenario != "flag" or result.equilibrium_reached:
        eq = f"yes, at t={result.time_to_equilibrium:.2f} s" if result.equilibrium_reached else "not reached"
        lines.append(f"  equilibrium: {eq}")
    if result.solver_converged is not None:
        # implicit_euler judges the true residual |b - A dv| / |b|, not only CG's own (issue 26)
        reason = (
            "iteration cap hit above tolerance"
            if (result.solver or {}).get("cg_capped_steps", 1)
            else "true residual above tolerance"
        )
        converged = (
            "yes"
            if result.solver_converged
            else f"NO ({reason} in {result.solver_capped_steps} of {result.steps} steps)"
        )
        lines.append(f"  solver converged: {converged}")
    if result.solver:
        lines.append(
            "  solver: "
            + ", ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}" for k, v in result.solver.items())
        )
    if result.measurements:
        lines.append(
            "  measured: "
            + ", ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}" for k, v in result.measurements.items())
        )
    return "\n".join(lines)


#: Exit status of ``run --fail-unstable`` when the run went unstable.
EXIT_UNSTABLE = 3


def output_writers(scenario_name: str, args) -> list:
    """Check every output path of a run (before any work) and return the writer factories
    ``(sim, cfg) -> writer`` that :meth:`Scenario.run` calls once the model is built."""
    argv = getattr(args, "argv", None)
    paths, writers = [], []

    prefix = ("warpcloth",)

    def frames(cfg):  # frames a run of cfg writes at most (the first one too)
        return math.ceil(cfg.duration * cfg.fps - 1e-9) + 1

    def info(sim, cfg):
        return provenance(sim, scenario_name, cfg.fps, argv, prefix=prefix)

    if getattr(args, "preview", None) is not None:  # "" is an error (the path check), not "no preview"
        check_preview_path(args.preview)  # also: matplotlib installed
        paths.append(args.preview)
    if args.usd is not None:
        writers.append(
            usd_frames(
                args.usd, getattr(args, "usd_color", "none"), info, colliders=getattr(args, "usd_colliders", "guide")
            )
        )  # the path is checked now
        paths.append(args.usd)
    if getattr(args, "html", None) is not None:
        check_html_path(args.html)
        paths.append(args.html)
        writers.append(
            lambda sim, cfg: HtmlWriter(
                args.html,
                sim.model,
                cfg.fps,
                title=f"warpcloth {scenario_name}: {sim.integrator.name}, "
                f"{sim.model.rows}x{sim.model.cols}, dt={sim.dt:.3g} s",
                info=info(sim, cfg),
                expected_frames=frames(cfg),
                colliders=sim.control.colliders,
            )
        )
    if getattr(args, "preview", None) is not None:
        writers.append(
            lambda sim, cfg: PreviewWriter(
                args.preview,
                sim.model,
                cfg.fps,
                title=f"{scenario_name}, {sim.integrator.name}",
                expected_frames=frames(cfg),
                colliders=sim.control.colliders,
            )
        )
    if len({os.path.abspath(p) for p in paths}) < len(paths):
        raise WarpclothError("two outputs name the same file: " + ", ".join(paths))
    for folder in sorted({os.path.dirname(os.path.abspath(p)) for p in paths}):
        sweep_stale_temporaries(folder, sys.stderr)
    return writers


def _clips_note(path: str, usd: str | None) -> str:
    """For a USD file whose samples went to value clips: where they are (the file alone opens empty)."""
    if path != usd:
        return ""

    folder, count = clip_folder_of(path)
    if folder is None:
        return ""
    return f"; its samples are in {folder}{os.sep} ({count} clip{'s' * (count != 1)}): copy the folder with the file"


def run_scenario(scenario_name: str, args) -> int:
    """Run the scenario ``scenario_name`` with the flags ``args``; the exit status."""
    scenario = get_scenario(scenario_name)
    cfg = config_from_args(scenario, args)
    check_spacing(scenario, cfg)
    writers = output_writers(scenario_name, args)
    if not getattr(args, "quiet", False):
        writers.insert(0, lambda sim, cfg: RunProgress(cfg.duration, label=f"run {scenario_name}"))
    with DefaultDtExplained(args):
        result = scenario.run(cfg, wall_cap=args.wall_cap, writers=writers)
    quiet = getattr(args, "quiet", False)
    if args.json:
        print(result.to_json())
    elif not quiet:
        print(summary(result))
        written = result.frames + (1 if result.stable else 0)  # the first frame, not the unstable last one
        for path in (args.usd, getattr(args, "html", None), getattr(args, "preview", None)):
            if path:
                print(
                    f"  wrote {path} ({os.path.getsize(path):,} bytes, {written} frames)" + _clips_note(path, args.usd)
                )
    if getattr(args, "fail_unstable", False) and not result.stable:
        if not args.json:
            print(f"warpcloth: the run went unstable ({result.unstable_reason}); exit {EXIT_UNSTABLE}", file=sys.stderr)
        return EXIT_UNSTABLE
    return 0


def run(args) -> int:
    return run_scenario(args.scenario, args)


__all__ = ["EXIT_UNSTABLE", "add_arguments", "add_run_arguments", "run", "run_scenario", "summary"]
