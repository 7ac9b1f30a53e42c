"""Run an XML test list (seed 4.3) and write one CSV row per run.

* A sheet run ends at equilibrium, at its simulated duration or at its wall-clock cap, whichever
  comes first; a flag run ends at its duration or its cap.
* Durability: the header is written atomically when the file is created; each row is written,
  flushed and fsync'd as its run finishes. ``resume=True`` skips the runs whose key
  (:attr:`~warpcloth.lab.testlist.RunSpec.key`, built from the run's parameters) is already in the
  file. A run that raises records ``outcome=error`` and its message, and the sweep goes on.
* ``dt="max"`` / ``"max*F"`` uses :func:`~warpcloth.lab.maxdt.find_max_dt`, searched once per
  integrator, scenario, mesh, parameters and run duration within a sweep, up to one frame
  (1/frame_rate): a real-time run takes at least one step per frame, so a larger dt is never
  useful here. The found dt is verified over the run's own duration and schedule (stepped down
  until that run is stable), so a run at "max" (or max*F, F <= 1) is stable for its whole length.
* Progress goes to stderr, never to stdout.
* Parallel (``workers`` > 1, ``devices``, ``ray``): the runs go to
  :mod:`warpcloth.lab.parallel` (local ``spawn`` worker processes or Ray tasks); this process
  stays the only writer of the CSV and writes each row as it arrives. Runs that share a max-dt
  search (:attr:`RunSpec.search_key`) go to one worker, in order, so the search runs once.
"""

from __future__ import annotations

import dataclasses
import os
import socket
import time
from dataclasses import dataclass, field

import warp as wp

from warpcloth.errors import WarpclothError
from warpcloth.io.progress import Progress, format_clock
from warpcloth.io.results import ResultsFile, ResultsFormat
from warpcloth.lab.maxdt import find_max_dt
from warpcloth.lab.parallel import Job, check_count, event_printer, init_worker, open_pool, require_ray, run_jobs
from warpcloth.lab.testlist import RunSpec, TestList, parse_test_list, resolved_params
from warpcloth.run.params import TimeStep, csv_columns, per_type_triple
from warpcloth.scenarios import get_scenario
from warpcloth.sim.device import device_name
from warpcloth.sim.grid import expected_spring_counts
from warpcloth.version import __version__

#: Columns of the CSV, in order (docs/sweep.md describes each): the test id, the run parameters
#: (their columns come from the declarations, :func:`warpcloth.run.params.csv_columns`), then what
#: the run measured.
COLUMNS = [
    "test_id",
    *csv_columns(),
    "options",
    "particles",
    "springs",
    "dt_s",
    "max_dt_s",
    "unstable_dt_s",
    "outcome",
    "steps",
    "sim_time_s",
    "wall_time_s",
    "compile_s",
    "ms_per_step",
    "steps_per_s",
    "frames_per_wall_second",
    "realtime_factor",
    "realtime",
    "integration_ms_mean",
    "other_ms_mean",
    "stable",
    "unstable_reason",
    "equilibrium_reached",
    "time_to_equilibrium_sim_s",
    "time_to_equilibrium_wall_s",
    "max_strain_rel",
    "wall_cap_reached",
    "solver_iterations",
    "solver_converged",
    "solver_capped_steps",
    "solver",
    "measurements",
    "error",
    "host",
    "worker",
    "concurrent_runs",
    "warpcloth_version",
    "warp_version",
    "key",
]

OUTCOMES = ("equilibrium", "completed", "wall_cap", "unstable", "error")


# -- one run ---------------------------------------------------------------------------------
def parameter_row(spec: RunSpec) -> dict:
    """The columns known before a run starts (the parameter columns from the declarations)."""
    row = {
        "test_id": spec.test_id,
        "options": " ".join(f"{k}={v}" for k, v in spec.options),
        "warpcloth_version": __version__,
        "warp_version": wp.config.version,
        "key": spec.key,
    }
    for p in resolved_params():
        value = spec.get(p.name)
        columns = p.csv_columns
        if len(columns) > 1:
            row.update(zip(columns, per_type_triple(value) or (None,) * len(columns)))
        elif columns:
            row[columns[0]] = str(value) if isinstance(value, TimeStep) else value
    if get_scenario_kind(spec.scenario) == "grid" and spec.rows is not None:
        row["particles"] = spec.rows * spec.cols
        row["springs"] = sum(expected_spring_counts(spec.rows, spec.cols, spec.bend).values())
    return row


def get_scenario_kind(name: str) -> str:
    """``grid`` or ``mesh``: what kind of cloth scenario ``name`` builds."""
    return "mesh" if get_scenario(name).is_mesh else "grid"


def result_columns(result, stop_at_equilibrium: bool = True) -> dict:
    """The measured columns of a :class:`~warpcloth.simulator.RunResult`; ``outcome`` says why
    the run ended (``equilibrium`` only where reaching it ends the run)."""
    if not result.stable:
        outcome = "unstable"
    elif result.equilibrium_reached and stop_at_equilibrium:
        outcome = "equilibrium"
    elif result.wall_cap_reached:
        outcome = "wall_cap"
    else:
        outcome = "completed"
    return {
        "dt_s": result.dt,
        "particles": result.particles,
        "springs": result.springs,
        "outcome": outcome,
        "steps": result.steps,
        "sim_time_s": result.sim_time,
        "wall_time_s": result.wall_time,
        "compile_s": result.compile_time,
        "ms_per_step": result.ms_per_step,
        "steps_per_s": result.steps_per_sec,
        "frames_per_wall_second": result.frames_per_sec,
        "realtime_factor": result.realtime_factor,
        "realtime": result.realtime_factor >= 1.0,
        "integration_ms_mean": result.integration_ms_mean,
        "other_ms_mean": result.other_ms_mean,
        "stable": result.stable,
        "unstable_reason": result.unstable_reason,
        "equilibrium_reached": result.equilibrium_reached,
        "time_to_equilibrium_sim_s": result.time_to_equilibrium,
        "time_to_equilibrium_wall_s": result.time_to_equilibrium_wall,
        "max_strain_rel": result.max_strain,
        "wall_cap_reached": result.wall_cap_reached,
        "solver_iterations": solver_iterations(result.solver),
        "solver_converged": result.solver_converged,
        "solver_capped_steps": result.solver_capped_steps,
        "solver": result.solver or None,
        "measurements": result.measurements or None,
    }


def solver_iterations(stats: dict):
    """The iteration count among an integrator's stats: the first numeric entry whose name
    contains ``iter`` (a name with ``mean`` first); None when the integrator has none."""
    names = [
        k for k, v in stats.items() if "iter" in k.lower() and isinstance(v, (int, float)) and not isinstance(v, bool)
    ]
    names.sort(key=lambda k: "mean" not in k.lower())
    return stats[names[0]] if names else None


class MaxDtCache:
    """Max-stable-dt searches of one sweep, by :attr:`RunSpec.search_key` (results or errors)."""

    def __init__(self, on_trial=None):
        self._results: dict = {}
        self.on_trial = on_trial

    def get(self, spec: RunSpec):
        key = spec.search_key
        if key not in self._results:
            try:
                scenario = get_scenario(spec.scenario)
                # "max" is for this run: the found dt is verified over the run's own duration and schedule
                self._results[key] = find_max_dt(
                    scenario,
                    spec.config(),
                    precision=spec.maxdt_precision,
                    duration=spec.maxdt_duration,
                    dt_max=1.0 / spec.frame_rate,
                    wall_cap=spec.wall_cap,
                    on_trial=self.on_trial,
                    verify_duration=spec.duration,
                    stop_at_equilibrium=scenario.stop_at_equilibrium,
                )
            except Exception as exc:  # recorded in every run that needs it
                self._results[key] = exc
        found = self._results[key]
        if isinstance(found, Exception):
            raise found
        return found


def execute_run(spec: RunSpec, cache: MaxDtCache) -> dict:
    """Run ``spec`` and return its CSV row; never raises on a failing run (outcome ``error``)."""
    row = parameter_row(spec)
    try:
        dt = None  # a value or the integrator's default: as the spec says (RunSpec.config)
        if spec.dt.uses_max:
            found = cache.get(spec)
            row["max_dt_s"], row["unstable_dt_s"] = found.dt, found.unstable_dt
            if found.dt is None:
                raise WarpclothError(f"no stable dt found down to {found.dt_min:g} s")
            dt = found.dt * spec.dt.value
        scenario = get_scenario(spec.scenario)
        harness = scenario.harness(spec.config(dt=dt))
        row["dt_s"] = harness.sim.dt
        result = harness.run(
            spec.duration, fps=spec.frame_rate, stop_at_equilibrium=scenario.stop_at_equilibrium, wall_cap=spec.wall_cap
        )
        row.update(result_columns(result, scenario.stop_at_equilibrium))
    except Exception as exc:
        row["outcome"] = "error"
        row["error"] = " ".join(f"{type(exc).__name__}: {exc}".split())
    return row


# -- output ----------------------------------------------------------------------------------
#: The sweep's results file (:class:`~warpcloth.io.results.ResultsFile`): these columns, cells
#: kept as text, ``-`` for stdout.
RESULTS = ResultsFormat(tuple(COLUMNS), what="sweep", unit="run", stdout=True)
#: One CSV line (with its newline) for a row; missing columns are empty.
format_row = RESULTS.format_row
#: The results file of a sweep (kept importable by this name).
CsvOutput = ResultsFile


def _line(bar: Progress, done: int, total: int, status: str, unit: str = "") -> str:
    """The sweep's progress line: ``[####----] 3/8 | status | elapsed 0:12 | remaining ~0:20``."""
    eta = bar.eta(done, total)
    return (
        f"{bar.bar(done / total if total else 1.0, 24, '-')} {done}/{total} | {status} | elapsed "
        f"{format_clock(bar.elapsed())} | remaining {'?' if eta is None else '~' + format_clock(eta)}"
    )


# -- the sweep -------------------------------------------------------------------------------
@dataclass
class SweepSummary:
    """What a sweep did."""

    total: int  # runs in the test list (after expansion)
    skipped: int  # already in the CSV (resume)
    written: int = 0
    outcomes: dict = field(default_factory=dict)
    wall_time: float = 0.0

    def describe(self) -> str:
        parts = ", ".join(f"{n} {k}" for k, n in self.outcomes.items() if n)
        skipped = f"; {self.skipped} already in the file" if self.skipped else ""
        return f"{self.written} runs written ({parts or 'none'}){skipped} in {format_clock(self.wall_time)}"


def run_sweep(
    tests: str | TestList,
    out: str,
    resume: bool = False,
    overwrite: bool = False,
    progress=None,
    max_runs: int | None = None,
    report=None,
    workers: int | None = None,
    devices: list[str] | None = None,
    ray: str | None = None,
    max_retries: int = 2,
) -> SweepSummary:
    """Run every run of a test list and write one CSV row each.

    Args:
        tests: path of the XML test list, or a parsed :class:`~warpcloth.lab.testlist.TestList`.
        out: CSV path, or ``-`` for stdout.
        resume: skip runs already in ``out`` (matched on :attr:`RunSpec.key`).
        overwrite: replace an existing ``out``.
        progress: stream for the progress bar (e.g. ``sys.stderr``), or None.
        max_runs: refuse a test list that expands to more runs (default
            :data:`~warpcloth.lab.testlist.DEFAULT_MAX_RUNS`).
        report: stream for notes about the file that ``--quiet`` must not hide (stale
            temporaries removed, an incomplete last line dropped, a worker replaced, the
            timings warning); default ``progress``.
        workers: run in this many local worker processes (None or 1 without ``devices``: in
            this process, one run after another).
        devices: CUDA devices that the CUDA runs are spread over, one per worker in turn
            (``workers`` defaults to their number).
        ray: a Ray address (``auto``, ``HOST:PORT``, ``ray://HOST:PORT``, ``local``): the runs
            as Ray tasks; excludes ``workers`` and ``devices``.
        max_retries: times a run whose worker died is started again.

    Raises:
        WarpclothError: a bad test list, output path or parallel setting, before any run.
    """
    if isinstance(tests, TestList):
        test_list = tests
    else:
        test_list = parse_test_list(tests) if max_runs is None else parse_test_list(tests, max_runs=max_runs)
    report = progress if report is None else report
    plan = ParallelPlan.check(test_list.runs, workers, devices, ray)
    pool = plan.pool(max_retries, report)  # Ray: connected here, before the file is touched
    try:
        output = CsvOutput(out, RESULTS, resume=resume, overwrite=overwrite, report=report)
    except BaseException:
        if pool is not None:
            pool.close()
        raise
    todo = [r for r in test_list.runs if r.key not in output.done_keys]
    summary = SweepSummary(total=len(test_list.runs), skipped=len(test_list.runs) - len(todo))
    summary.outcomes = dict.fromkeys(OUTCOMES, 0)
    bar = Progress(stream=progress, enabled=progress is not None, layout=_line, keep=True)
    current = ""
    if output.truncated and report is not None:
        report.write(output.dropped_note() + "\n")
    if plan.warning and report is not None:
        report.write(f"warpcloth: warning: {plan.warning}\n")
    if progress is not None:
        if summary.skipped:
            progress.write(f"resuming {out}: {summary.skipped} of {summary.total} runs already done\n")
        if test_list.duplicates:
            progress.write(f"{test_list.path}: {test_list.duplicates} duplicate runs (same parameters) dropped\n")
        if plan.parallel and todo:
            progress.write(f"running {len(todo)} runs {plan.describe()}\n")
    t0 = time.perf_counter()
    written: set[str] = set()

    def record(row: dict) -> None:
        if row["key"] in written:  # a key is written once
            return
        output.write(row)
        written.add(row["key"])
        summary.written += 1
        summary.outcomes[row["outcome"]] = summary.outcomes.get(row["outcome"], 0) + 1
        outcome = row.get("outcome", "")
        if outcome == "error":
            outcome += f" ({row.get('error', '')[:80]})"
        bar.update(summary.written, len(todo), f"{current}: {outcome}", force=True)

    def on_trial(t) -> None:  # a terminal only: one line per trial would flood a log
        if bar.tty:
            bar.update(
                summary.written,
                len(todo),
                f"{current}: max-dt trial dt={t.dt:.4g} s {'stable' if t.stable else 'unstable'}",
                force=True,
            )

    try:
        if not plan.parallel:
            host = socket.gethostname()
            cache = MaxDtCache(on_trial=on_trial)
            for spec in todo:
                current = spec.describe()
                bar.update(summary.written, len(todo), f"running {current}", force=True)
                row = execute_run(spec, cache)
                row.update(host=host, worker="main", concurrent_runs=1)
                record(row)
        elif todo:
            jobs = [Job(spec.key, spec, spec.device, spec.search_key if spec.dt.uses_max else None) for spec in todo]
            for done in run_jobs(parallel_run, jobs, pool=pool):
                spec = done.job.payload
                row = done.row
                if row is None:
                    row = parameter_row(spec)
                    row.update(outcome="error", error=" ".join(done.error.split()))
                if done.place is not None:
                    row.update(host=done.place.host, worker=done.place.worker)
                row["concurrent_runs"] = done.concurrent
                row["key"] = spec.key
                current = spec.describe()
                record(row)
    finally:
        bar.close()
        if pool is not None:
            pool.close()
        output.close()
        summary.wall_time = time.perf_counter() - t0
    return summary


# -- parallel runs ---------------------------------------------------------------------------
@dataclass
class ParallelPlan:
    """How a sweep runs: serially, in local worker processes, or on Ray (validated settings)."""

    workers: int = 1
    devices: list | None = None
    ray: str | None = None
    warning: str = ""

    @property
    def parallel(self) -> bool:
        return self.ray is not None or self.workers > 1 or bool(self.devices)

    def describe(self) -> str:
        if self.ray is not None:
            return f"as Ray tasks ({self.ray})"
        on = f" on {','.join(self.devices)}" if self.devices else ""
        return f"in {self.workers} worker processes{on}"

    def pool(self, max_retries: int = 2, report=None):
        """The worker pool of a parallel plan (None when serial); a Ray pool is connected, or a
        WarpclothError says why it could not be."""
        if not self.parallel:
            return None

        return open_pool(
            parallel_run,
            self.workers,
            devices=self.devices,
            ray=self.ray,
            init=init_worker,
            max_retries=max_retries,
            on_event=event_printer(report),
        )

    @classmethod
    def check(cls, runs, workers=None, devices=None, ray=None) -> ParallelPlan:
        """Validate the parallel settings against the runs; WarpclothError names the problem."""
        if ray is not None:
            if workers is not None or devices:
                raise WarpclothError(
                    "--ray runs the sweep on the cluster's CPUs and GPUs: it takes neither --workers nor --devices"
                )
            if not str(ray).strip():
                raise WarpclothError("--ray: give 'auto', 'local' or a cluster address HOST:PORT")

            require_ray()
            return cls(ray=str(ray).strip())

        check_count("--workers", workers)
        names = None
        if devices is not None:
            names = []
            for given in devices:
                d = str(given).strip()
                if not d.startswith("cuda"):
                    raise WarpclothError(
                        f"--devices: {d!r} is not a CUDA device; --devices lists the GPUs (cuda:0,cuda:1) "
                        "that the CUDA runs are spread over"
                    )
                try:
                    name = device_name(d)
                except WarpclothError as exc:  # not present: the message names those that are
                    raise WarpclothError(f"--devices: {exc}") from None
                if name in names:
                    raise WarpclothError(f"--devices: {d!r} is given twice")
                names.append(name)
            if not names:
                raise WarpclothError("--devices: give at least one CUDA device, e.g. cuda:0,cuda:1")
        n = workers if workers is not None else (len(names) if names else 1)
        plan = cls(workers=n, devices=names)
        if n > 1:
            cuda = all(r.device.startswith("cuda") for r in runs) and runs
            if names:
                slots, what = len(names), f"the {len(names)} devices of --devices"
            elif cuda:
                used = sorted({r.device for r in runs})
                slots, what = len(used), f"the {len(used)} device(s) of the test list ({', '.join(used)})"
            else:
                slots, what = os.cpu_count() or 1, f"the {os.cpu_count() or 1} CPU cores"
            if n > slots:
                plan.warning = (
                    f"--workers {n} is more than {what}: runs share a device at once and their timings are "
                    "affected (see the concurrent_runs column)"
                )
        return plan


_WORKER_CACHE: MaxDtCache | None = None


def parallel_run(spec: RunSpec, place) -> dict:
    """A run in a worker process (``warpcloth.lab.parallel``): a CUDA run moves to the worker's
    device when it has one (its key stays the test list's, so --resume does not depend on where
    it ran); max-dt searches are cached per process."""
    global _WORKER_CACHE
    if _WORKER_CACHE is None:
        _WORKER_CACHE = MaxDtCache()
    key = spec.key
    if place.device and spec.device.startswith("cuda") and place.device != spec.device:
        spec = dataclasses.replace(spec, device=place.device)
    row = execute_run(spec, _WORKER_CACHE)
    row["key"] = key
    return row


def read_results(path: str) -> list[dict]:
    """The rows of a sweep CSV as dicts of strings (a convenience for analysis and tests)."""
    return RESULTS.read(path)


__all__ = [
    "COLUMNS",
    "RESULTS",
    "CsvOutput",
    "MaxDtCache",
    "ParallelPlan",
    "SweepSummary",
    "execute_run",
    "format_row",
    "parallel_run",
    "read_results",
    "run_sweep",
]
