"""The ``warpcloth`` command line.

    warpcloth run SCENARIO [--integrator NAME] [--rows N] [--cols N] [--dt S] ... [--usd PATH] [--json]
    warpcloth list
    warpcloth sweep TESTS.xml --out RESULTS.csv [--resume | --overwrite] [--max-runs N]
                    [--workers N] [--devices cuda:0,cuda:1] [--ray auto|ADDRESS]
    warpcloth max-dt SCENARIO --integrator NAME [--rows N --cols N --stiffness KS ...] [--precision 0.02]

Bad input prints one line, ``warpcloth: error: ...``, and exits with status 2; an output that
cannot be written during the work exits 74, SIGTERM 143, Ctrl-C 130, a closed stdout 141
(:func:`warpcloth.cli.parse.guarded`). Every subcommand takes ``--verbose`` (Warp's messages).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys

from warpcloth.cli.parse import EXIT_USAGE, Parser, guarded  # noqa: F401  (EXIT_USAGE: kept importable from cli)
from warpcloth.errors import WarpclothError, require_positive
from warpcloth.run.params import BY_NAME, add_flags, check_applies, cli_value, config_values, params_for

def add_model_arguments(p: argparse.ArgumentParser, command: str = "max-dt", exclusive: dict | None = None) -> None:
    """The flags of ``command``'s run parameters (:mod:`warpcloth.run.params`) and the integrators'
    options (:class:`~warpcloth.integrators.Option`)."""
    add_flags(p, command, skip=("scenario",), exclusive=exclusive)
    _add_integrator_options(p)


def add_run_arguments(p: argparse.ArgumentParser) -> None:
    """Flags of a scenario run (shared by ``warpcloth run`` and ``python -m warpcloth.scenarios.X``)."""
    num_frames = (("--num-frames",), dict(type=int, default=None, help="run this many frames instead of --duration"))
    add_model_arguments(p, "run", exclusive={"duration": [num_frames]})
    out = p.add_argument_group("outputs")
    out.add_argument("--usd", "--stage-path", dest="usd", default=None, metavar="PATH",
                     help="write the animation to this USD file (.usd/.usda/.usdc, or .usdz: a package)")
    out.add_argument("--usd-color", choices=["none", "strain"], default="none",
                     help="strain: a per-frame primvars:displayColor of spring strain, blue 0 to red 10%% (default none)")
    out.add_argument("--html", default=None, metavar="PATH", help="write a self-contained HTML player of the animation (WebGL, no network)")
    out.add_argument("--preview", default=None, metavar="PATH",
                     help="write a picture: .png (the last frame) or .gif (the animation, frames skipped to fit); needs warpcloth[plot]")
    p.add_argument("--fail-unstable", action="store_true", help="exit with status 3 when the run goes unstable")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of the summary")


def _add_integrator_options(p: argparse.ArgumentParser) -> None:
    """One flag per integrator option, declared by the integrators themselves."""
    from warpcloth.integrators import all_options

    group = p.add_argument_group("integrator options")
    for name, (opt, owners) in all_options().items():
        kwargs = {"choices": list(opt.choices)} if opt.choices else {}
        group.add_argument(opt.flag, dest="opt_" + name, type=str, default=None, metavar=opt.type.__name__.upper(),
                           help=f"{opt.help} [{', '.join(owners)}; default {opt.default}]", **kwargs)


def integrator_options_from_args(integrator: str, args) -> dict:
    """Options given on the command line for ``integrator``; an option it does not take is an error."""
    from warpcloth.integrators import all_options, integrator_class

    taken = {o.name for o in integrator_class(integrator).options}
    out = {}
    for name, (opt, owners) in all_options().items():
        value = getattr(args, "opt_" + name, None)
        if value is None:
            continue
        if name not in taken:
            raise WarpclothError(f"{opt.flag} does not apply to integrator {integrator!r} (it applies to {', '.join(owners)})")
        out[name] = opt.parse(value)
    return out


def param_values(args, command: str) -> dict:
    """The run parameters given on the command line, by name (unset: None)."""
    return {p.name: cli_value(p, args) for p in params_for(command) if not p.positional}


def config_from_args(scenario, args, command: str = "run"):
    """A ScenarioConfig from parsed flags (unset flags keep the scenario defaults)."""
    from warpcloth.integrators import integrator_class, integrator_names

    values = param_values(args, command)
    if values.get("integrator") is not None and not values["integrator"].strip():
        raise WarpclothError(f"--integrator is empty; choose one of {', '.join(integrator_names())}")
    if values.get("integrator") == "all":
        raise WarpclothError(f"--integrator all is for test lists (warpcloth sweep); choose one of {', '.join(integrator_names())}")
    integrator = values.get("integrator") or scenario.defaults.integrator
    integrator_class(integrator)  # unknown name -> clear error
    if values.get("size") is not None and (values.get("rows") is not None or values.get("cols") is not None):
        raise WarpclothError("give either --size or --rows and --cols, not both")
    check_applies(values, scenario.model is not None, scenario.name)
    if values.get("device") is None:
        values["device"] = BY_NAME["device"].default  # the CLI's default device
    kwargs = config_values(values)
    kwargs.update(integrator=integrator, integrator_options=integrator_options_from_args(integrator, args),
                  dt=values.get("dt"))
    cfg = scenario.config(**kwargs)
    num_frames = getattr(args, "num_frames", None)
    if num_frames is not None:
        require_positive("fps", cfg.fps, "1/s")
        if num_frames < 1:
            raise WarpclothError(f"--num-frames must be >= 1, got {num_frames}")
        cfg.duration = num_frames / cfg.fps
    return cfg


def summary(result) -> str:
    """A short human-readable summary of a RunResult."""
    lines = [
        f"{result.scenario}: {result.integrator} on {result.device}, {result.rows}x{result.cols} "
        f"({result.particles} particles, {result.springs} springs), dt={result.dt:.3g} s",
        f"  simulated {result.sim_time:.3f} s in {result.steps} steps, {result.wall_time:.2f} s wall "
        f"(+{result.compile_time:.2f} s compile" + (f", +{result.capture_time:.2f} s graph capture" if result.capture_time else "") + ")",
        f"  {result.ms_per_step:.4f} ms/step, {result.steps_per_sec:,.0f} steps/s, real-time factor {result.realtime_factor:.2f}"
        + (" (graph replay)" if result.graph else ""),
        f"  stable: {'yes' if result.stable else 'NO (' + result.unstable_reason + ')'}, max strain {100 * result.max_strain:.2f} %",
    ]
    if result.scenario != "flag" or result.equilibrium_reached:
        eq = f"yes, at t={result.time_to_equilibrium:.2f} s" if result.equilibrium_reached else "not reached"
        lines.append(f"  equilibrium: {eq}")
    if result.solver_converged is not None:
        converged = "yes" if result.solver_converged else (
            f"NO (iteration cap hit above tolerance in {result.solver_capped_steps} of {result.steps} steps)")
        lines.append(f"  solver converged: {converged}")
    if result.solver:
        lines.append("  solver: " + ", ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}" for k, v in result.solver.items()))
    return "\n".join(lines)


def _check_spacing(scenario, cfg) -> None:
    """Refuse a cloth whose particles float32 cannot tell apart (e.g. ``--height 1e-30``),
    naming the flag, rather than failing later on springs of rest length 0."""
    import numpy as np

    try:
        rows, cols, width, height = int(cfg.rows), int(cfg.cols), float(cfg.width), float(cfg.height)
        origin = [float(v) for v in scenario.origin(cfg)]
    except (TypeError, ValueError):
        return  # the builder names the bad value
    extent = max(abs(v) for v in origin) + max(abs(width), abs(height))
    if not np.isfinite(extent):
        return
    ulp = float(np.spacing(np.float32(extent)))
    for flag, size, n in (("--width", width, cols), ("--height", height, rows)):
        if n >= 2 and size > 0 and size / (n - 1) <= ulp:
            raise WarpclothError(
                f"{flag} {size:g} m over {n} particles puts neighbours {size / (n - 1):.3g} m apart, below float32's "
                f"resolution ({ulp:.3g} m) at the cloth's position, so they would coincide; use at least {4 * ulp * (n - 1):.2g} m")


class _DefaultDtExplained:
    """Turns "dt must be > 0 s, got 0.0" from a *computed* default dt (the user gave none) into
    a message naming the flags the default came from (``--mass 1e30`` underflows it)."""

    FLAGS = tuple((p.name, p.flag) for p in params_for("run")
                  if p.name in ("mass", "drag") or p.name.startswith(("stiffness", "damping")))

    def __init__(self, args):
        self.args = args

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb):
        if exc_type is None or not issubclass(exc_type, WarpclothError) or getattr(self.args, "dt", None) is not None:
            return False
        text = str(exc)
        if not text.startswith("dt must be"):
            return False
        given = []
        for attr, flag in self.FLAGS:
            value = getattr(self.args, attr, None)
            if value is not None:
                shown = ",".join(f"{v:g}" for v in value) if isinstance(value, tuple) else f"{value:g}"
                given.append(f"{flag} {shown}")
        cause = " ".join(given) if given else "the scenario's parameters"
        got = text.split("got", 1)[-1].strip().split()[0] if "got" in text else "?"
        raise WarpclothError(
            f"the integrator's default time step computed from {cause} is {got} s, not a usable dt "
            "(the stability estimate under- or overflows at these values); use values nearer the defaults, or give --dt") from None


#: Exit status of ``run --fail-unstable`` when the run went unstable.
EXIT_UNSTABLE = 3


def _output_writers(scenario_name: str, args) -> list:
    """Check every output path of a run (before any work) and return the writer factories
    ``(sim, cfg) -> writer`` that :meth:`Scenario.run` calls once the model is built."""
    from warpcloth.io.files import sweep_stale_temporaries
    from warpcloth.io.provenance import provenance

    argv = getattr(args, "argv", None)
    paths, writers = [], []

    prefix = getattr(args, "command_prefix", ("warpcloth",))

    def frames(cfg):  # frames a run of cfg writes at most (the first one too)
        return math.ceil(cfg.duration * cfg.fps - 1e-9) + 1

    def info(sim, cfg):
        return provenance(sim, scenario_name, cfg.fps, argv, prefix=prefix)

    if getattr(args, "preview", None):
        from warpcloth.io.preview import check_preview_path

        check_preview_path(args.preview)  # also: matplotlib installed
        paths.append(args.preview)
    if args.usd:
        from warpcloth.io.usd import usd_frames

        writers.append(usd_frames(args.usd, getattr(args, "usd_color", "none"), info))  # the path is checked now
        paths.append(args.usd)
    if getattr(args, "html", None):
        from warpcloth.io.player import HtmlWriter, check_html_path

        check_html_path(args.html)
        paths.append(args.html)
        writers.append(lambda sim, cfg: HtmlWriter(args.html, sim.model, cfg.fps, title=f"warpcloth {scenario_name}: {sim.integrator.name}, "
                                                   f"{sim.model.rows}x{sim.model.cols}, dt={sim.dt:.3g} s", info=info(sim, cfg),
                                                   expected_frames=frames(cfg), colliders=sim.control.colliders))
    if getattr(args, "preview", None):
        from warpcloth.io.preview import PreviewWriter

        writers.append(lambda sim, cfg: PreviewWriter(args.preview, sim.model, cfg.fps, title=f"{scenario_name}, {sim.integrator.name}",
                                                      expected_frames=frames(cfg)))
    if len({os.path.abspath(p) for p in paths}) < len(paths):
        raise WarpclothError("two outputs name the same file: " + ", ".join(paths))
    for folder in sorted({os.path.dirname(os.path.abspath(p)) for p in paths}):
        sweep_stale_temporaries(folder, sys.stderr)
    return writers


def _run(scenario_name: str, args) -> int:
    from warpcloth.scenarios import get_scenario

    scenario = get_scenario(scenario_name)
    cfg = config_from_args(scenario, args)
    _check_spacing(scenario, cfg)
    writers = _output_writers(scenario_name, args)
    if not getattr(args, "quiet", False):
        from warpcloth.io.progress import RunProgress

        writers.insert(0, lambda sim, cfg: RunProgress(cfg.duration, label=f"run {scenario_name}"))
    with _DefaultDtExplained(args):
        result = scenario.run(cfg, wall_cap=args.wall_cap, writers=writers)
    quiet = getattr(args, "quiet", False)
    if args.json:
        print(result.to_json())
    elif not quiet:
        print(summary(result))
        written = result.frames + (1 if result.stable else 0)  # the first frame, not the unstable last one
        for path in (args.usd, getattr(args, "html", None), getattr(args, "preview", None)):
            if path:
                print(f"  wrote {path} ({os.path.getsize(path):,} bytes, {written} frames)")
    if getattr(args, "fail_unstable", False) and not result.stable:
        if not args.json:
            print(f"warpcloth: the run went unstable ({result.unstable_reason}); exit {EXIT_UNSTABLE}", file=sys.stderr)
        return EXIT_UNSTABLE
    return 0


def examples_dir() -> str:
    """The folder of the XML test lists shipped in the package (``warpcloth.examples``)."""
    from warpcloth import examples

    return os.path.dirname(os.path.abspath(examples.__file__))


def example_names() -> list[str]:
    return sorted(os.path.splitext(n)[0] for n in os.listdir(examples_dir()) if n.endswith(".xml"))


def example_path(name: str) -> str:
    names = example_names()
    if name not in names:
        raise WarpclothError(f"no example test list {name!r}; the examples are {', '.join(names)} ('warpcloth list --examples')")
    return os.path.join(examples_dir(), name + ".xml")


def _list(args) -> int:
    from warpcloth.integrators import integrator_class, integrator_names
    from warpcloth.scenarios import get_scenario, scenario_names

    if getattr(args, "examples", False):
        if not args.quiet:
            for name in example_names():
                print(f"{name:12s} {example_path(name)}")
        return 0
    if args.quiet:
        return 0
    print("scenarios:")
    for name in scenario_names():
        print(f"  {name:16s} {get_scenario(name).description}")
    print("integrators:")
    for name in integrator_names():
        doc = (integrator_class(name).__doc__ or sys.modules[integrator_class(name).__module__].__doc__ or "").strip().splitlines()
        print(f"  {name:16s} {doc[0] if doc else ''}")
    return 0


def _sweep(args) -> int:
    from warpcloth.lab.sweep import run_sweep

    if (args.tests is None) == (args.example is None):
        raise WarpclothError("give a test list (TESTS.xml) or --example NAME, not " + ("both" if args.tests else "neither"))
    tests = args.tests if args.tests is not None else example_path(args.example)
    devices = None
    if args.devices is not None:
        devices = [d for d in args.devices.split(",")]
        if any(not d.strip() for d in devices):
            raise WarpclothError(f"--devices: {args.devices!r} is not a comma-separated list of CUDA devices (cuda:0,cuda:1)")
    summary = run_sweep(tests, args.out, resume=args.resume, overwrite=args.overwrite,
                        progress=None if args.quiet else sys.stderr, max_runs=args.max_runs, report=sys.stderr,
                        workers=args.workers, devices=devices, ray=args.ray)
    line = f"{args.out if args.out != '-' else 'stdout'}: {summary.describe()}"
    print(line, file=sys.stderr if args.out == "-" else sys.stdout)  # the result's summary, also with --quiet
    return 1 if summary.outcomes.get("error") else 0


def _add_max_dt_arguments(p: argparse.ArgumentParser) -> None:
    """Flags of ``warpcloth max-dt``: the model and integrator of a run, and the search."""
    p.add_argument("scenario", help="scenario name (see 'warpcloth list') or a scenario file (.toml)")
    add_model_arguments(p, "max-dt")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of the report")
    p.set_defaults(dt=None, num_frames=None, duration=None)


def _max_dt(args) -> int:
    from warpcloth.lab.maxdt import DEFAULT_DT_MAX, DEFAULT_DT_MIN, find_max_dt, format_result
    from warpcloth.scenarios import get_scenario

    scenario = get_scenario(args.scenario)
    cfg = config_from_args(scenario, args, "max-dt")
    _check_spacing(scenario, cfg)
    precision = args.maxdt_precision if args.maxdt_precision is not None else BY_NAME["maxdt_precision"].default
    duration = args.maxdt_duration if args.maxdt_duration is not None else BY_NAME["maxdt_duration"].default
    from warpcloth.io.progress import Progress

    progress = Progress(f"max-dt {args.scenario} {cfg.integrator}", enabled=not args.quiet)
    trials = []

    def on_trial(trial):
        trials.append(trial)
        stable = [t.dt for t in trials if t.stable]
        unstable = [t.dt for t in trials if not t.stable]
        total = None
        if stable and unstable and min(unstable) > max(stable):  # bisection: the trials left are known
            ratio = math.log(min(unstable) / max(stable))
            left = max(0, math.ceil(math.log2(max(ratio / math.log1p(precision), 1.0))))
            total = len(trials) + left
        note = f"trial {len(trials)}: dt={trial.dt:.4g} s {'stable' if trial.stable else 'unstable'}"
        progress.update(len(trials), total, note=note, unit=" trials")

    with _DefaultDtExplained(args):
        try:
            result = find_max_dt(
                scenario, cfg, precision=precision, duration=duration,
                dt_min=DEFAULT_DT_MIN if args.dt_min is None else args.dt_min,
                dt_max=DEFAULT_DT_MAX if args.dt_max is None else args.dt_max,
                start=args.dt_start, wall_cap=args.wall_cap, on_trial=on_trial,
            )
        finally:
            progress.close()
    if args.json:
        print(json.dumps(result.to_dict()))
    elif not args.quiet:
        print(format_result(result))
    return 0


def _workers(text: str) -> int:
    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number >= 1") from None
    if n < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1, got {n}")
    return n


def _add_verbose(p: argparse.ArgumentParser, quiet: bool = True) -> None:
    p.add_argument("--verbose", action="store_true", help="show Warp's start-up and module-load messages on stderr")
    if quiet:
        p.add_argument("--quiet", "-q", action="store_true", help="print nothing on success (no summary, no progress); errors still print")


def build_parser() -> argparse.ArgumentParser:
    from warpcloth.version import __version__
    from warpcloth.lab.testlist import DEFAULT_MAX_RUNS

    parser = Parser(prog="warpcloth", description="Mass-spring cloth simulator and integrator laboratory on NVIDIA Warp.")
    parser.add_argument("--version", action="version", version=f"warpcloth {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=Parser)
    run = sub.add_parser("run", help="run a scenario and print a summary")
    run.add_argument("scenario", help="scenario name (see 'warpcloth list') or a scenario file, path/to/scenario.toml")
    add_run_arguments(run)
    _add_verbose(run)
    listing = sub.add_parser("list", help="list scenarios and integrators (--examples: the shipped XML test lists)")
    listing.add_argument("--examples", action="store_true", help="list the example test lists shipped with warpcloth and their paths")
    _add_verbose(listing)
    bench = sub.add_parser("bench", help="benchmark integrators x sizes x devices on the sheet (bench/devices.py)")
    from warpcloth.cli import bench as bench_module

    bench_module.add_arguments(bench)
    _add_verbose(bench)
    sweep = sub.add_parser("sweep", help="run an XML test list, one CSV row per run (docs/sweep.md)")
    sweep.add_argument("tests", metavar="TESTS.xml", nargs="?", default=None, help="the test list")
    sweep.add_argument("--example", default=None, metavar="NAME", help="run a test list shipped with warpcloth (quick, seed_plan; see 'list --examples')")
    sweep.add_argument("--out", "-o", required=True, metavar="RESULTS.csv", help="results file ('-' for stdout)")
    mode = sweep.add_mutually_exclusive_group()
    mode.add_argument("--resume", action="store_true", help="continue RESULTS.csv: skip runs already in it")
    mode.add_argument("--overwrite", action="store_true", help="replace RESULTS.csv if it exists")
    sweep.add_argument("--max-runs", type=int, default=DEFAULT_MAX_RUNS, metavar="N",
                       help=f"refuse a test list that expands to more than N runs (default {DEFAULT_MAX_RUNS})")
    sweep.add_argument("--workers", type=_workers, default=None, metavar="N",
                       help="run N runs at once in local worker processes (default 1: one after another; more than "
                            "the devices or cores prints a warning: timings are affected)")
    sweep.add_argument("--devices", default=None, metavar="cuda:0,cuda:1",
                       help="spread the CUDA runs over these GPUs, one worker each (--workers defaults to their number)")
    sweep.add_argument("--ray", default=None, metavar="auto|ADDRESS",
                       help="run the runs as Ray tasks on a cluster: auto (the local cluster of 'ray start'), HOST:PORT, "
                            "ray://HOST:PORT, or local (start one in this process); needs pip install 'warpcloth[cluster]'")
    sweep.add_argument("--quiet", "-q", action="store_true", help="no progress bar on stderr (the closing summary line still prints)")
    _add_verbose(sweep, quiet=False)
    max_dt = sub.add_parser("max-dt", help="find the largest stable time step of an integrator on a scenario")
    _add_max_dt_arguments(max_dt)
    _add_verbose(max_dt)
    from warpcloth.cli import study as studycli

    study = sub.add_parser("study", help="the accuracy-aware study: stable/accurate dt, cost, real-time frontier, report (docs/study.md)")
    studycli.add_arguments(study)
    _add_verbose(study)
    return parser


def _dispatch(args) -> int:
    if args.command == "run":
        return _run(args.scenario, args)
    if args.command == "list":
        return _list(args)
    if args.command == "bench":
        from warpcloth.cli import bench as bench_module

        return bench_module.run(args)
    if args.command == "sweep":
        return _sweep(args)
    if args.command == "max-dt":
        return _max_dt(args)
    if args.command == "study":
        from warpcloth.cli import study as studycli

        return studycli.run(args)
    raise WarpclothError(f"unknown command {args.command!r}")


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    args.argv = list(sys.argv[1:] if argv is None else argv)
    hint = ""
    if args.command == "sweep" and args.out != "-":
        hint = f"; finished runs are in {args.out}, continue with --resume"
    if args.command == "study":
        hint = f"; finished measurements are in {args.out}/results.csv, continue with --resume"
    return guarded(args, lambda: _dispatch(args), hint)


def scenario_main(name: str, argv=None) -> None:
    """Entry point of ``python -m warpcloth.scenarios.<name>`` (Warp-example style flags)."""
    parser = Parser(prog=f"python -m warpcloth.scenarios.{name}", description=f"Run the {name} scenario.")
    add_run_arguments(parser)
    _add_verbose(parser)
    args = parser.parse_args(argv)
    args.argv = list(sys.argv[1:] if argv is None else argv)
    args.command_prefix = ("python", "-m", f"warpcloth.scenarios.{name}")
    sys.exit(guarded(args, lambda: _run(name, args)))


if __name__ == "__main__":
    sys.exit(main())
