"""``warpcloth max-dt SCENARIO --integrator NAME``: the largest stable time step
(:func:`warpcloth.lab.maxdt.find_max_dt`), with a progress line per trial."""

from __future__ import annotations

import argparse
import json
import math

from warpcloth.cli.model import DefaultDtExplained, add_model_arguments, check_spacing, config_from_args
from warpcloth.io.progress import Progress
from warpcloth.lab.maxdt import DEFAULT_DT_MAX, DEFAULT_DT_MIN, find_max_dt, format_result
from warpcloth.run.params import BY_NAME
from warpcloth.scenarios import get_scenario


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Flags of ``warpcloth max-dt``: the model and integrator of a run, and the search."""
    p.add_argument("scenario", help="scenario name (see 'warpcloth list') or a scenario file (.toml)")
    add_model_arguments(p, "max-dt")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of the report")
    p.set_defaults(dt=None, num_frames=None, duration=None)


def run(args) -> int:
    scenario = get_scenario(args.scenario)
    cfg = config_from_args(scenario, args, "max-dt")
    check_spacing(scenario, cfg)
    precision = args.maxdt_precision if args.maxdt_precision is not None else BY_NAME["maxdt_precision"].default
    duration = args.maxdt_duration if args.maxdt_duration is not None else BY_NAME["maxdt_duration"].default

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

    with DefaultDtExplained(args):
        try:
            result = find_max_dt(
                scenario,
                cfg,
                precision=precision,
                duration=duration,
                dt_min=DEFAULT_DT_MIN if args.dt_min is None else args.dt_min,
                dt_max=DEFAULT_DT_MAX if args.dt_max is None else args.dt_max,
                start=args.dt_start,
                wall_cap=args.wall_cap,
                on_trial=on_trial,
            )
        finally:
            progress.close()
    if args.json:
        print(json.dumps(result.to_dict()))
    elif not args.quiet:
        print(format_result(result))
    return 0


__all__ = ["add_arguments", "run"]
