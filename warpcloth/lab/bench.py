"""CPU vs CUDA benchmark of every integrator on the sheet, as a library (the command line,
``warpcloth bench`` and ``python bench/devices.py``, is :mod:`warpcloth.cli.bench`).

For each integrator x mesh size x device, and with and without graph capture, it runs the
sheet scenario at the integrator's default dt for enough steps to time it well, after a warm-up
step that compiles the kernels (reported apart as ``compile_s``). Output: a CSV row per
combination, a table on stdout, and with ``--plot`` a log-log PNG of ms/step against particle
count (matplotlib, the optional ``warpcloth[plot]`` extra). ``--roofline`` also times the
speed-of-light force pass (``warpcloth.kernels.roofline``) on each device and reports each
integrator's ms/step as a multiple of ``force_evals_per_step x floor``.
"""

from __future__ import annotations

import csv
import io
import os
import sys
import time

import numpy as np
import warp as wp

from warpcloth.errors import WarpclothError, require
from warpcloth.io.files import AtomicFile, OutputError, csv_cell, describe_write_error, write_atomic
from warpcloth.io.provenance import machine
from warpcloth.kernels import roofline as rk
from warpcloth.run.harness import time_steps
from warpcloth.scenarios import get_scenario
from warpcloth.simulator import graph_capture_supported
from warpcloth.version import __version__

#: Columns of the benchmark CSV: the study's naming (units in the names, booleans true/false).
COLUMNS = [
    "scenario",
    "integrator",
    "device",
    "graph",
    "rows",
    "cols",
    "particles",
    "springs",
    "dt_s",
    "timed_windows",
    "steps_timed",
    "steps_per_window",
    "ms_per_step_median",
    "ms_per_step_min",
    "ms_per_step_max",
    "steps_per_s",
    "springs_per_s",
    "wall_s_per_sim_s",
    "realtime_factor",
    "realtime_30fps",
    "realtime_60fps",
    "compile_s",
    "speedup_vs_cpu",
    "force_evals_per_step",
    "roofline_ms",
    "floor_multiple",
    "stable",
    "solver_iterations_mean",
    "solver_converged",
    "solver_capped_steps",
    "host",
    "cpu",
    "gpu",
    "warp_version",
    "warpcloth_version",
]

#: Timed windows per combination (median and spread).
DEFAULT_WINDOWS = 5


def parse_sizes(text: str) -> list[int]:
    try:
        sizes = [int(s) for s in text.split(",") if s.strip()]
    except ValueError:
        raise WarpclothError(f"--sizes must be comma-separated integers >= 3, got {text!r}") from None
    require(bool(sizes) and all(s >= 3 for s in sizes), f"--sizes must be comma-separated integers >= 3, got {text!r}")
    return sizes


def default_devices() -> list[str]:
    return ["cpu"] + [str(d) for d in wp.get_cuda_devices()]


def roofline_ms(model, repeats: int = 50) -> float:
    """Median time [ms] of the speed-of-light force pass on ``model``'s device."""
    h = model.host
    order = np.argsort(h.pairs[:, 0], kind="stable")
    pairs = h.pairs[order]
    counts = np.bincount(pairs[:, 0], minlength=model.particle_count)
    offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int32)
    d = model.device
    with wp.ScopedDevice(d):
        args = [
            model.particle_q,
            wp.zeros_like(model.particle_q),
            wp.array(offsets, dtype=int),
            wp.array(pairs, dtype=wp.vec2i),
            wp.array(model.spring_rest_length.numpy()[order]),
            wp.array(model.spring_stiffness.numpy()[order]),
            wp.array(model.spring_damping.numpy()[order]),
            wp.zeros_like(model.particle_q),
        ]
        wp.launch(rk.roofline_stream, dim=model.particle_count, inputs=args)
        wp.synchronize_device(d)
        # capture a batch of launches so launch overhead does not count (where capture works)

        batch = 20
        if graph_capture_supported(d):
            with wp.ScopedCapture(device=d) as cap:
                for _ in range(batch):
                    wp.launch(rk.roofline_stream, dim=model.particle_count, inputs=args)

            def run():
                wp.capture_launch(cap.graph)
        else:

            def run():
                for _ in range(batch):
                    wp.launch(rk.roofline_stream, dim=model.particle_count, inputs=args)

        run()
        wp.synchronize_device(d)
        times = []
        for _ in range(max(3, repeats // batch)):
            t0 = time.perf_counter()
            run()
            wp.synchronize_device(d)
            times.append((time.perf_counter() - t0) / batch)
    return 1000.0 * float(np.median(times))


def build_sim(scenario: str, size: int | None, device: str, **kwargs):
    """A Simulator of ``scenario``: a size x size grid, or the scenario's own mesh (``size`` None)."""
    grid = {} if size is None else {"rows": size, "cols": size}
    return get_scenario(scenario).build(device=device, **grid, **kwargs)


def bench_one(
    integrator: str,
    size: int | None,
    device: str,
    graph: bool,
    steps: int | None,
    seconds: float,
    scenario: str = "sheet",
    windows: int = DEFAULT_WINDOWS,
) -> dict:
    """Time one integrator on a size x size grid of ``scenario`` (the sheet by default), or on a
    mesh scenario's own mesh (``size`` None), with :func:`warpcloth.run.harness.time_steps`:
    ``windows`` timed windows of about ``seconds / windows`` each (or ``steps`` steps in all),
    warm-up and first replay excluded. Returns a CSV row (without cross-row columns)."""
    sim = build_sim(scenario, size, device, integrator=integrator)
    sim.use_graph = graph
    if graph and not sim.graph_enabled:
        raise WarpclothError(f"graph capture unavailable for {integrator} on {device}")
    if steps is not None:
        windows = min(windows, steps)  # at least one step a window
    timing = time_steps(sim, windows=windows, window_seconds=seconds / windows, steps=steps)
    m = sim.model
    finite = bool(np.all(np.isfinite(sim.state.particle_q.numpy())))
    ms = timing.median_ms
    stats = sim.integrator.stats()
    iters = next((v for k, v in stats.items() if "iterations" in k and "mean" in k), stats.get("iterations", ""))
    converged, capped, _ = sim.integrator.convergence(stats)
    where = machine(device)
    return {
        "scenario": scenario,
        "integrator": integrator,
        "device": device,
        "graph": graph,
        "rows": m.rows,
        "cols": m.cols,
        "particles": m.particle_count,
        "springs": m.spring_count,
        "dt_s": sim.dt,
        "timed_windows": len(timing.ms_per_step),
        "steps_timed": timing.steps,
        "steps_per_window": timing.steps_per_window,
        "ms_per_step_median": ms,
        "ms_per_step_min": timing.min_ms,
        "ms_per_step_max": timing.max_ms,
        "steps_per_s": 1000.0 / ms,
        "springs_per_s": m.spring_count * 1000.0 / ms,
        "wall_s_per_sim_s": timing.wall_s_per_sim_s,
        "realtime_factor": timing.realtime_factor,
        "realtime_30fps": timing.realtime(30.0),
        "realtime_60fps": timing.realtime(60.0),
        "compile_s": timing.compile_s,
        "speedup_vs_cpu": "",
        "force_evals_per_step": sim.integrator.force_evals_per_step,
        "roofline_ms": "",
        "floor_multiple": "",
        "stable": finite,
        "solver_iterations_mean": iters,
        "solver_converged": "" if converged is None else converged,
        "solver_capped_steps": capped,
        "host": where["host"],
        "cpu": f"{where['cpu']} ({where['cores']} logical cores)",
        "gpu": where["gpu"],
        "warp_version": wp.config.version,
        "warpcloth_version": __version__,
    }


def csv_text(rows: list[dict]) -> str:
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=COLUMNS, lineterminator="\n")
    w.writeheader()
    w.writerows({k: csv_cell(v) for k, v in r.items()} for r in rows)
    return buf.getvalue()


def write_csv(path: str, rows: list[dict]) -> None:
    """Write rows atomically (temporary file, then rename); on failure (disk full) raises
    :class:`~warpcloth.io.files.OutputError` and leaves ``path`` as it was, no temporary left."""
    write_atomic(path, csv_text(rows), "benchmark CSV")


def bench_figure(rows: list[dict]):
    """The figure of :func:`plot`: wall seconds per simulated second against particles, one colour
    per integrator, a circle per CPU and a square per CUDA series, filled where the frames were
    replayed as graphs and hollow where launched one by one; the legend right of the axes."""
    import matplotlib.pyplot as plt  # noqa: PLC0415 (the optional [plot] extra)

    fig, ax = plt.subplots(figsize=(8, 5.5))
    keys = sorted({(r["integrator"], r["device"], r["graph"]) for r in rows})
    integrators = sorted({k[0] for k in keys})
    colors = {name: plt.get_cmap("tab10")(i % 10) for i, name in enumerate(integrators)}  # one colour per integrator
    for integ, dev, graph in keys:
        sel = sorted(
            (r for r in rows if (r["integrator"], r["device"], r["graph"]) == (integ, dev, graph)),
            key=lambda r: r["particles"],
        )
        ax.plot(
            [r["particles"] for r in sel],
            [r["wall_s_per_sim_s"] for r in sel],
            color=colors[integ],
            marker="o" if dev == "cpu" else "s",
            markerfacecolor=colors[integ] if graph else "none",
            linestyle="-" if graph else "--",
            label=f"{integ} {dev}{' graph' if graph else ''}",
        )
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("particles")
    ax.axhline(1.0, color="k", linewidth=0.8)
    ax.text(ax.get_xlim()[0], 1.0, " real time", va="bottom", fontsize=8)
    ax.set_ylabel("wall seconds per simulated second (at each integrator's default dt)")
    ax.set_title("warpcloth: cost per simulated second vs particle count")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(
        fontsize=7,
        loc="center left",
        bbox_to_anchor=(1.02, 0.5),
        frameon=False,
        title="filled: graph replay\nhollow: launches",
        title_fontsize=7,
    )
    fig.tight_layout()
    return fig


def plot(path: str, rows: list[dict]) -> bool:
    try:
        import matplotlib  # noqa: PLC0415 (the optional [plot] extra)

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt  # noqa: PLC0415 (the optional [plot] extra)
    except ImportError:
        print(
            "bench: --plot needs matplotlib (pip install 'warpcloth[plot]', from a clone pip install -e '.[plot]'); "
            "no plot written",
            file=sys.stderr,
        )
        return False
    fig = bench_figure(rows)
    out = AtomicFile(path, "plot", mode="wb")
    try:
        fig.savefig(out.fh, dpi=120, format=os.path.splitext(path)[1].lstrip(".").lower() or "png", bbox_inches="tight")
    except OSError as exc:
        out.abort()
        raise OutputError(describe_write_error(exc, path, "plot")) from None
    except BaseException:
        out.abort()
        raise
    finally:
        plt.close(fig)
    out.commit()
    return True


def grid_size(rows: int, cols: int) -> str:
    """A grid's ``ROWSxCOLS``; ``mesh`` for a mesh or several pieces (one row: a grid has at least two;
    its particle count is the next column)."""
    return f"{rows}x{cols}" if rows > 1 else "mesh"


def format_table(rows: list[dict]) -> str:
    head = (
        f"{'integrator':15s} {'device':7s} {'graph':5s} {'size':>9s} {'particles':>9s} {'ms/step':>10s} "
        f"{'[min-max]':>19s} {'wall s/sim s':>12s} {'RT factor':>9s} {'x floor':>8s} {'CUDA x':>7s}"
    )
    lines = [head, "-" * len(head)]
    for r in rows:

        def fmt(v, spec):
            return (
                format(v, spec) if isinstance(v, (int, float)) else format(str(v), ">" + spec.split(".")[0].lstrip(">"))
            )

        lines.append(
            f"{r['integrator']:15s} {r['device']:7s} {('yes' if r['graph'] else 'no'):5s} "
            f"{grid_size(r['rows'], r['cols']):>9s} {r['particles']:>9d} {r['ms_per_step_median']:>10.4f} "
            f"{'[' + format(r['ms_per_step_min'], '.4g') + '-' + format(r['ms_per_step_max'], '.4g') + ']':>19s} "
            f"{r['wall_s_per_sim_s']:>12.4g} {r['realtime_factor']:>9.3f} {fmt(r['floor_multiple'], '>8.2f')} "
            f"{fmt(r['speedup_vs_cpu'], '>7.1f')}"
        )
    return "\n".join(lines)
