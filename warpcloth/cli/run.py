"""``warpcloth run SCENARIO`` (also ``python -m warpcloth run SCENARIO``): a scenario run with its
outputs (one table, :data:`OUTPUTS`), its progress and its summary."""

from __future__ import annotations

import argparse
import math
import os
import sys
from collections.abc import Callable
from dataclasses import dataclass

from warpcloth.cli.model import DefaultDtExplained, add_model_arguments, check_spacing, config_from_args
from warpcloth.errors import WarpclothError
from warpcloth.io.checkpoint import CheckpointWriter, check_checkpoint_path
from warpcloth.io.files import check_input_file, sweep_stale_temporaries
from warpcloth.io.meshio import ObjSequenceWriter, check_obj_sequence_path
from warpcloth.io.player import HtmlWriter, check_html_path
from warpcloth.io.preview import PreviewWriter, check_preview_path
from warpcloth.io.progress import RunProgress
from warpcloth.io.provenance import provenance
from warpcloth.io.usd import UsdWriter, check_usd_path, clip_folder_of
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
    for o in OUTPUTS:
        out.add_argument(*o.flags, dest=o.dest, default=None, metavar=o.metavar, help=o.help)
        for flags, kwargs in o.options:
            out.add_argument(*flags, **kwargs)
    p.add_argument("--fail-unstable", action="store_true", help="exit with status 3 when the run goes unstable")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of the summary")


def cloth_shape(rows: int, cols: int, particles: int, triangles: int) -> str:
    """A grid as ``ROWSxCOLS``; a mesh (one row: grids have at least two) as ``N vertices, T triangles``."""
    return f"{rows}x{cols}" if rows > 1 else f"{particles:,} vertices, {triangles:,} triangles"


def summary(result) -> str:
    """A short human-readable summary of a RunResult."""
    lines = [
        f"{result.scenario}: {result.integrator} on {result.device}, "
        + (
            f"{result.rows}x{result.cols} ({result.particles} particles, {result.springs} springs)"
            if result.rows > 1
            else f"{cloth_shape(result.rows, result.cols, result.particles, result.triangles)} "
            f"({result.springs} springs)"
        )
        + f", dt={result.dt:.3g} s",
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
        lines.append(f"  solver capped in {result.capped_steps} of {result.steps} steps")
    if result.strain_limit_source:
        which = "strain cap" if result.strain_limit_source == "strain_cap" else "strain limit"
        lines.append(
            f"  {which} ({100 * result.strain_limit_tau:g} %) engaged in {result.strain_capped_steps} of "
            f"{result.steps} steps"
        )
    if result.solver:
        lines.append(
            "  solver: "
            + ", ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}" for k, v in result.solver.items())
        )
    if "refused" in result.measurements:
        lines.append(f"  not measured: {result.measurements['refused']}")
    elif result.measurements:
        lines.append(
            "  measured: "
            + ", ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}" for k, v in result.measurements.items())
        )
    return "\n".join(lines)


#: Exit status of ``run --fail-unstable`` when the run went unstable.
EXIT_UNSTABLE = 3


# -- the outputs of a run: one table ---------------------------------------------------------
class OutputRun:
    """What an output's sink factory may read of the run: the scenario's name, the flags
    (``option``), the provenance record and the most frames a run of a config writes."""

    def __init__(self, scenario: str, args):
        self.scenario = scenario
        self.args = args

    def option(self, name: str, default=None):
        return getattr(self.args, name, default)

    def info(self, sim, cfg) -> dict:
        return provenance(sim, self.scenario, cfg.fps, self.option("argv"), prefix=("warpcloth",))

    @staticmethod
    def frames(cfg) -> int:
        """Frames a run of ``cfg`` writes at most (the first one too)."""
        return math.ceil(cfg.duration * cfg.fps - 1e-9) + 1


@dataclass(frozen=True)
class Output:
    """One output of ``warpcloth run``; :data:`OUTPUTS` lists them, and the flags, the path
    checks, the writers and the summary's lines all come from that table.

    Attributes:
        flags: the option strings; the first names it (``--obj-sequence`` -> ``args.obj_sequence``).
        help: the flag's help.
        check: ``check(path)``, run before any work: raises a WarpclothError naming the path.
        sink: ``sink(path, run, sim, cfg)`` -> a frame sink with ``write_frame(points, sim_time)``,
            ``close()`` (returns the path written) and ``abort()`` (the target left as it was);
            ``run`` is the :class:`OutputRun`, called once the simulator is built.
        report: whether the summary says ``wrote PATH (N bytes, K frames)``.
        metavar: the flag's argument in ``--help``.
        options: more flags of this output, ``((flags...), argparse keyword arguments)``.
        note: ``note(path)`` -> text after the summary's line (USD: where its value clips went).
        sample: a target name the sink contract test writes (tests/test_sinks.py).
    """

    flags: tuple
    help: str
    check: Callable
    sink: Callable
    report: bool = True
    metavar: str = "PATH"
    options: tuple = ()
    note: Callable | None = None
    sample: str = "out"

    @property
    def dest(self) -> str:
        return self.flags[0].lstrip("-").replace("-", "_")


def _clips_note(path: str) -> str:
    """For a USD file whose samples went to value clips: where they are (the file alone opens empty)."""
    folder, count = clip_folder_of(path)
    if folder is None:
        return ""
    return f"; its samples are in {folder}{os.sep} ({count} clip{'s' * (count != 1)}): copy the folder with the file"


def _bytes(path: str) -> int:
    """The size of a file, or of a folder's files."""
    if os.path.isdir(path):
        return sum(e.stat().st_size for e in os.scandir(path) if e.is_file(follow_symlinks=False))
    return os.path.getsize(path)


#: The outputs of ``warpcloth run``, in the order their writers receive frames and the summary lists them.
OUTPUTS = (
    Output(
        flags=("--usd", "--stage-path"),
        help="write the animation to this USD file (.usd/.usda/.usdc, or .usdz: a package)",
        check=check_usd_path,
        sink=lambda path, run, sim, cfg: UsdWriter(
            path,
            sim.model,
            cfg.fps,
            provenance=run.info(sim, cfg),
            color=run.option("usd_color", "none"),
            colliders=sim.control.colliders,
            colliders_purpose=run.option("usd_colliders", "guide"),
        ),
        options=(
            (
                ("--usd-color",),
                dict(
                    choices=["none", "strain"],
                    default="none",
                    help="strain: a per-frame primvars:displayColor of spring strain, blue 0 to red 10%% "
                    "(default none)",
                ),
            ),
            (
                ("--usd-colliders",),
                dict(
                    choices=["guide", "render"],
                    default="guide",
                    help="UsdGeom purpose of the collider prims: guide (shown in viewports, not rendered) or "
                    "render (default guide)",
                ),
            ),
        ),
        note=_clips_note,
        sample="out.usda",
    ),
    Output(
        flags=("--html",),
        help="write a self-contained HTML player of the animation (WebGL, no network)",
        check=check_html_path,
        sink=lambda path, run, sim, cfg: HtmlWriter(
            path,
            sim.model,
            cfg.fps,
            title=f"warpcloth {run.scenario}: {sim.integrator.name}, "
            f"{cloth_shape(sim.model.rows, sim.model.cols, sim.model.particle_count, sim.model.tri_count)}, "
            f"dt={sim.dt:.3g} s",
            info=run.info(sim, cfg),
            expected_frames=run.frames(cfg),
            colliders=sim.control.colliders,
        ),
        sample="out.html",
    ),
    Output(
        flags=("--preview",),
        help="write a picture: .png (the last frame) or .gif (the animation, frames skipped to fit); needs "
        "warpcloth[plot]",
        check=check_preview_path,  # also: matplotlib installed
        sink=lambda path, run, sim, cfg: PreviewWriter(
            path,
            sim.model,
            cfg.fps,
            title=f"{run.scenario}, {sim.integrator.name}",
            expected_frames=run.frames(cfg),
            colliders=sim.control.colliders,
        ),
        sample="out.png",
    ),
    Output(
        flags=("--obj-sequence",),
        help="write one OBJ file per frame into this folder, frame_0000.obj, frame_0001.obj, ... (built beside "
        "it and renamed into place; an existing folder is replaced only if it holds nothing but frame_NNNN.obj)",
        check=check_obj_sequence_path,
        sink=lambda path, run, sim, cfg: ObjSequenceWriter(path, sim.model),
        metavar="DIR",
        sample="frames",
    ),
    Output(
        flags=("--checkpoint",),
        help="write the run's state to this .npz file at its end (and with --checkpoint-every, after every K-th "
        "frame): --resume-from continues from it, bit-identically to an uninterrupted run on the same device",
        check=check_checkpoint_path,
        sink=lambda path, run, sim, cfg: CheckpointWriter(path, sim, every=run.option("checkpoint_every")),
        report=False,
        metavar="FILE",
        options=(
            (
                ("--checkpoint-every",),
                dict(
                    type=int,
                    default=None,
                    metavar="K",
                    help="with --checkpoint: also write it after every K-th frame (the file holds the latest)",
                ),
            ),
        ),
        sample="state.npz",
    ),
)


def output_writers(scenario_name: str, args) -> list:
    """Check every output path of a run (before any work) and return the writer factories
    ``(sim, cfg) -> writer`` that :meth:`Scenario.run` calls once the model is built: one per
    entry of :data:`OUTPUTS` whose flag is given, in the table's order."""
    run = OutputRun(scenario_name, args)
    chosen = [(o, getattr(args, o.dest, None)) for o in OUTPUTS]
    chosen = [(o, path) for o, path in chosen if path is not None]  # "" is an error (the path check), not "none"
    for o, path in chosen:
        o.check(path)
    paths = [path for _, path in chosen]
    if len({os.path.abspath(p) for p in paths}) < len(paths):
        raise WarpclothError("two outputs name the same file: " + ", ".join(paths))
    for folder in sorted({os.path.dirname(os.path.abspath(p)) for p in paths}):
        sweep_stale_temporaries(folder, sys.stderr)
    return [_factory(o, path, run) for o, path in chosen]


def _factory(o: Output, path: str, run: OutputRun):
    return lambda sim, cfg: o.sink(path, run, sim, cfg)


def written_outputs(args, frames: int) -> list[str]:
    """The summary's lines for the outputs the table reports: ``wrote PATH (N bytes, K frames)``."""
    lines = []
    for o in OUTPUTS:
        path = getattr(args, o.dest, None)
        if o.report and path:
            note = o.note(path) if o.note is not None else ""
            lines.append(f"  wrote {path} ({_bytes(path):,} bytes, {frames} frames){note}")
    return lines


def run_scenario(scenario_name: str, args) -> int:
    """Run the scenario ``scenario_name`` with the flags ``args``; the exit status."""
    scenario = get_scenario(scenario_name)
    cfg = config_from_args(scenario, args)
    check_spacing(scenario, cfg)
    writers = output_writers(scenario_name, args)
    resume = getattr(args, "resume_from", None)
    if resume is not None:
        check_input_file(resume, "checkpoint")
    every = getattr(args, "checkpoint_every", None)
    if every is not None and (getattr(args, "checkpoint", None) is None or every < 1):
        raise WarpclothError(f"--checkpoint-every {every} needs --checkpoint FILE and a whole number of frames >= 1")
    if not getattr(args, "quiet", False):
        writers.insert(0, lambda sim, cfg: RunProgress(cfg.duration, label=f"run {scenario_name}"))
    with DefaultDtExplained(args):
        result = scenario.run(cfg, wall_cap=args.wall_cap, writers=writers, resume_from=resume)
    quiet = getattr(args, "quiet", False)
    if args.json:
        print(result.to_json())
    elif not quiet:
        print(summary(result))
        written = result.frames + (1 if result.stable else 0)  # the first frame, not the unstable last one
        for line in written_outputs(args, written):
            print(line)
    if getattr(args, "fail_unstable", False) and not result.stable:
        if not args.json:
            print(f"warpcloth: the run went unstable ({result.unstable_reason}); exit {EXIT_UNSTABLE}", file=sys.stderr)
        return EXIT_UNSTABLE
    return 0


def run(args) -> int:
    return run_scenario(args.scenario, args)


__all__ = [
    "EXIT_UNSTABLE",
    "OUTPUTS",
    "Output",
    "OutputRun",
    "add_arguments",
    "add_run_arguments",
    "run",
    "run_scenario",
    "summary",
]
