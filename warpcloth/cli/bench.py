"""``warpcloth bench`` (and ``python bench/devices.py``): the flags and the driver of the CPU vs
CUDA benchmark of :mod:`warpcloth.lab.bench`."""

from __future__ import annotations

import argparse
import json
import os
import sys

import warp as wp

from warpcloth.cli.parse import Parser, guarded
from warpcloth.errors import WarpclothError, require
from warpcloth.integrators import check_integrator_name, integrator_names, make_integrator
from warpcloth.io.files import check_output_path, sweep_stale_temporaries
from warpcloth.io.preview import require_matplotlib
from warpcloth.io.progress import Progress, format_seconds
from warpcloth.lab import bench as lab_bench
from warpcloth.lab.bench import (
    DEFAULT_WINDOWS,
    csv_text,
    default_devices,
    format_table,
    parse_sizes,
    plot,
    roofline_ms,
    write_csv,
)
from warpcloth.run.harness import MAX_RUN_STEPS
from warpcloth.run.params import positive
from warpcloth.scenarios import get_scenario
from warpcloth.sim.device import device_name as resolve_device
from warpcloth.simulator import graph_capture_supported


def build_parser(prog: str = "bench/devices.py") -> argparse.ArgumentParser:
    p = Parser(prog=prog, description=lab_bench.__doc__.split("\n\n")[0].replace(", as a library", ""))
    add_arguments(p)
    p.add_argument("--verbose", action="store_true", help="show Warp's start-up and module-load messages on stderr")
    p.add_argument(
        "--quiet", "-q", action="store_true", help="print nothing on success but what --json or --out - ask for"
    )
    return p


#: The longest --seconds of one combination [s] (a day): a benchmark ends, as a run's duration is
#: bounded by its step count.
MAX_BENCH_SECONDS = 86400.0


def _seconds(text: str) -> float:
    """``--seconds``: a finite number of wall seconds > 0, at most :data:`MAX_BENCH_SECONDS`."""
    try:
        value = positive(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    if value > MAX_BENCH_SECONDS:
        raise argparse.ArgumentTypeError(f"{value:g} s is more than {MAX_BENCH_SECONDS:g} s (a day) per combination")
    return value


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--integrators", default=None, help="comma-separated names (default: every registered integrator)")
    p.add_argument("--scenario", default="sheet", help="scenario name or scenario file (.toml) to time (default sheet)")
    p.add_argument(
        "--sizes",
        default=None,
        help="comma-separated grid sizes N for N x N (default 32,64,128; not for mesh scenarios)",
    )
    p.add_argument(
        "--devices", default=None, help="comma-separated Warp devices (default: cpu and every CUDA device present)"
    )
    group = p.add_mutually_exclusive_group()
    group.add_argument("--steps", type=int, default=None, help="steps to time per combination")
    group.add_argument(
        "--seconds",
        type=_seconds,
        default=1.0,
        help="wall seconds to time per combination, over all windows (default 1)",
    )
    p.add_argument(
        "--windows",
        type=int,
        default=DEFAULT_WINDOWS,
        help="timed windows per combination: the median and the [min-max] spread come from them (default "
        f"{DEFAULT_WINDOWS})",
    )
    p.add_argument(
        "--graph",
        choices=["both", "on", "off"],
        default="both",
        help="time with graph capture, without, or both (default both)",
    )
    p.add_argument(
        "--roofline", action="store_true", help="time the speed-of-light force pass and report multiples of it"
    )
    p.add_argument(
        "--out",
        "-o",
        default=None,
        help="write the results to this CSV ('-' for stdout; the table then goes to stderr)",
    )
    p.add_argument(
        "--json", action="store_true", help="print the results as one JSON object on stdout (the table goes to stderr)"
    )
    p.add_argument("--plot", default=None, help="write a log-log PNG of ms/step vs particles (needs matplotlib)")


def run(args) -> int:
    if args.integrators is None:
        names = integrator_names()
    else:
        names = [s.strip() for s in args.integrators.split(",") if s.strip()]
        require(
            bool(names),
            f"--integrators {args.integrators!r} names no integrator; give comma-separated names from "
            f"{', '.join(integrator_names())}",
        )
    for n in names:
        check_integrator_name(n, flag="--integrators")

    scenario = get_scenario(args.scenario)  # unknown name or bad file: one line
    if scenario.is_mesh:  # a mesh: its own particles, no grid sizes
        require(
            args.sizes is None, f"--sizes does not apply to the mesh scenario {args.scenario!r} (it has its own mesh)"
        )
        sizes = [None]
    else:
        sizes = parse_sizes("32,64,128" if args.sizes is None else args.sizes)

    require(args.steps is None or args.steps >= 1, f"--steps must be >= 1, got {args.steps}")
    require(
        args.steps is None or args.steps <= MAX_RUN_STEPS,
        f"--steps must be at most {MAX_RUN_STEPS:.0e}, got {args.steps}",
    )
    require(args.seconds is None or args.seconds > 0, f"--seconds must be > 0, got {args.seconds}")
    require(args.windows >= 1, f"--windows must be >= 1, got {args.windows}")
    wanted = default_devices() if args.devices is None else [s.strip() for s in args.devices.split(",") if s.strip()]
    require(
        bool(wanted), f"--devices {args.devices!r} names no device; give comma-separated Warp devices, e.g. cpu,cuda:0"
    )
    devices, skipped = [], []
    for d in wanted:
        try:
            devices.append(resolve_device(d))
        except WarpclothError as exc:
            if args.devices is None:
                skipped.append(str(exc))
            else:
                raise
    if not any(d.startswith("cuda") for d in devices) and not getattr(args, "quiet", False):
        reason = "no CUDA device is present" if not wp.get_cuda_devices() else "not asked for (--devices)"
        print(f"bench: CUDA skipped: {reason}; timing the CPU only", file=sys.stderr)
    # every output path is checked before the benchmark starts, not after it
    require(not (args.out == "-" and getattr(args, "json", False)), "--out - and --json both want stdout; choose one")
    if args.out and args.out != "-":
        check_output_path(args.out, "--out")
    if args.plot:
        check_output_path(args.plot, "--plot", extensions=(".png", ".pdf", ".svg"))
    require(
        not (args.out and args.plot and os.path.abspath(args.out) == os.path.abspath(args.plot)),
        f"--out and --plot are the same file {args.out!r}",
    )
    if args.plot:
        require_matplotlib("--plot")  # before the benchmark, not after it
    for path in {os.path.dirname(os.path.abspath(p)) for p in (args.out, args.plot) if p and p != "-"}:
        sweep_stale_temporaries(path, sys.stderr)

    quiet = getattr(args, "quiet", False)
    modes = {"both": [False, True], "on": [True], "off": [False]}[args.graph]
    combos = [
        (device, size, name, graph)
        for device in devices
        for size in sizes
        for name in names
        for graph in modes
        if not graph or (graph_capture_supported(device) and make_integrator(name).capturable_on(device))
    ]
    progress = Progress("bench", enabled=not quiet)
    rows, floors = [], {}
    for k, (device, size, name, graph) in enumerate(combos):
        if args.roofline and (device, size) not in floors:
            floors[(device, size)] = roofline_ms(lab_bench.build_sim(args.scenario, size, device).model)
        what = f"{name} {args.scenario if size is None else f'{size}x{size}'} on {device}{' (graph)' if graph else ''}"
        if progress.tty:
            progress.update(k, len(combos), note=what, force=True)
        elif not quiet:  # a plain line per combination, with the ETA once one is timed
            eta = progress.eta(k, len(combos))
            more = f" ({k + 1}/{len(combos)}" + (f", ETA {format_seconds(eta)})" if eta is not None else ")")
            print(f"bench: {what} ...{more}", file=sys.stderr, flush=True)
        row = lab_bench.bench_one(
            name, size, device, graph, args.steps, args.seconds, scenario=args.scenario, windows=args.windows
        )
        if args.roofline:
            floor = floors[(device, size)]
            row["roofline_ms"] = floor
            row["floor_multiple"] = row["ms_per_step_median"] / (row["force_evals_per_step"] * floor)
        rows.append(row)
    progress.close()
    cpu = {(r["integrator"], r["rows"], r["graph"]): r["ms_per_step_median"] for r in rows if r["device"] == "cpu"}
    for r in rows:
        if r["device"] != "cpu" and (r["integrator"], r["rows"], r["graph"]) in cpu:
            r["speedup_vs_cpu"] = cpu[(r["integrator"], r["rows"], r["graph"])] / r["ms_per_step_median"]
    to_stdout = args.out == "-"
    # the table goes to stdout unless stdout carries the CSV or the JSON; --quiet drops it
    report = None if quiet else (sys.stderr if (to_stdout or getattr(args, "json", False)) else sys.stdout)
    if report is not None:
        print(format_table(rows), file=report)
        if args.roofline:
            for (device, size), floor in sorted(floors.items()):
                print(f"roofline floor on {device}, {size}x{size}: {floor:.4f} ms per force pass", file=report)
    if to_stdout:
        sys.stdout.write(csv_text(rows))
    elif args.out:
        write_csv(args.out, rows)
        if report is not None:
            print(f"wrote {args.out}", file=report)
    if getattr(args, "json", False):
        print(
            json.dumps(
                {
                    "rows": rows,
                    "roofline_ms": {f"{d} {s}x{s}": v for (d, s), v in sorted(floors.items())},
                    "cuda_skipped": not any(d.startswith("cuda") for d in devices),
                }
            )
        )
    if args.plot and plot(args.plot, rows) and report is not None:
        print(f"wrote {args.plot}", file=report)
    return 0


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    return guarded(args, lambda: run(args))
