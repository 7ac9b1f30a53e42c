"""``warpcloth study``: the seed's question answered with measured, accuracy-aware figures: the
driver (:func:`run_study`).

For each device x integrator x mesh size (n x n particles) of a :class:`~warpcloth.lab.plan.StudyPlan`
it makes the measurements of :mod:`warpcloth.lab.measure`, one row of results.csv each
(:mod:`warpcloth.lab.results`), then writes report.md and the plots (:mod:`warpcloth.lab.report`).
Serially by default; in parallel (:class:`ParallelSettings`) the groups go to worker processes or
Ray tasks through :func:`warpcloth.lab.parallel.run_jobs`, and this process stays the only writer.

Rows are written as they finish (a :class:`~warpcloth.io.results.ResultsFile`: header atomically,
each row flushed and fsync'd, a writer lock); ``resume`` skips measurements whose key is already
in the file and reuses their values.
"""

from __future__ import annotations

import json
import os
import socket
import sys
import time
from dataclasses import asdict, dataclass, field, replace

from warpcloth.errors import WarpclothError, require
from warpcloth.io.files import check_output_path
from warpcloth.io.progress import Progress, format_clock
from warpcloth.io.results import ResultsFile
from warpcloth.lab.measure import Measurements
from warpcloth.lab.parallel import (
    Job,
    check_count,
    event_printer,
    init_worker,
    is_cuda,
    open_pool,
    require_ray,
    run_jobs,
)
from warpcloth.lab.plan import StudyPlan, group_label, plan_groups
from warpcloth.lab.report import write_report
from warpcloth.lab.results import RESULTS, read_rows
from warpcloth.sim.device import device_name as resolve_device


def _line(bar: Progress, done: float, total: float, label: str, unit: str = "") -> str:
    """The study's progress line: ``study [######      ]  50% 0:12 ETA 0:12 LABEL`` (work weighted by particles)."""
    frac = min(1.0, done / total) if total > 0 else 1.0
    eta = bar.eta(done, total)
    return (
        f"study {bar.bar(frac, 24, ' ')} {100 * frac:3.0f}% {format_clock(bar.elapsed())} "
        f"ETA {'?' if eta is None else format_clock(eta)} {label}"
    )


def _group_weight(plan: StudyPlan, n) -> float:
    if isinstance(n, str):
        return 32 * 32
    return n * n


def run_serial(study: Measurements, progress=None) -> None:
    """Every group of ``study``'s plan, one after another, in this process."""
    p = study.plan
    groups = plan_groups(p)
    total = max(sum(_group_weight(p, n) for _, _, n in groups), 1e-9)
    bar = Progress(stream=progress, enabled=progress is not None, layout=_line, keep=True)
    done = 0.0
    for d, i, n in groups:
        bar.update(done, total, f"{i} {group_label(n)} {d}", force=True)
        study.group(d, i, n)
        done += _group_weight(p, n)
        bar.update(done, total, f"{i} {group_label(n)} {d} done", force=True)
    bar.close()


@dataclass
class ParallelSettings:
    """How a study runs its measurements: serially (the default), in ``workers`` local worker
    processes, or as Ray tasks (``ray``). In parallel, each device x integrator x size group
    runs in two phases: the *searches* (max stable dt, accuracy, equilibrium) with ``workers``
    (or the cluster's) concurrency, then the *timings*, ``timing_workers`` at a time (default
    one: a timed run has its machine to itself, as in a serial study)."""

    workers: int = 1
    ray: str | None = None
    timing_workers: int = 1
    warnings: list = field(default_factory=list)

    @property
    def parallel(self) -> bool:
        return self.ray is not None or self.workers > 1 or self.timing_workers > 1

    def describe(self) -> str:
        if self.ray is not None:
            return f"as Ray tasks ({self.ray}), timings {self.timing_workers} at a time"
        return f"in {self.workers} worker processes, timings {self.timing_workers} at a time"

    @classmethod
    def check(cls, devices: list, workers=None, ray=None, timing_workers=None) -> ParallelSettings:
        """Validated settings for a study on ``devices``; WarpclothError names the bad value."""
        check_count("--workers", workers)
        check_count("--timing-workers", timing_workers)
        if ray is not None:
            if workers is not None:
                raise WarpclothError("--ray runs the searches on the cluster's CPUs and GPUs: it takes no --workers")
            ray = str(ray).strip()
            if not ray:
                raise WarpclothError("--ray: give auto, local, HOST:PORT or ray://HOST:PORT")
            require_ray()
        out = cls(workers=workers or 1, ray=ray, timing_workers=timing_workers or 1)
        cores = os.cpu_count() or 1
        if out.workers > 1 and any(not d.startswith("cuda") for d in devices) and out.workers > cores:
            out.warnings.append(
                f"--workers {out.workers} is more than the {cores} CPU cores: the searches share cores (their "
                "results do not depend on it, but a trial that reaches a wall cap stops sooner: see the note "
                "column); the timings still run alone"
            )
        if out.timing_workers > len(devices):
            out.warnings.append(
                f"--timing-workers {out.timing_workers} is more than the {len(devices)} device(s) "
                f"({', '.join(devices)}): timed runs share a device and their ms/step are affected "
                "(see the concurrent_runs column)"
            )
        return out


class _Collector:
    """A worker's stand-in for the results file: the rows it measured (as the file would give
    them back), kept to be handed back to the driver (the only writer of results.csv)."""

    def __init__(self):
        self.done: dict[str, dict] = {}
        self.new: list[dict] = []

    def write(self, row: dict) -> None:
        row = RESULTS.as_written(row)
        self.done[row["key"]] = row
        self.new.append(row)


_WORKER_STUDIES: dict = {}  # plan (JSON) -> Measurements, one per worker process: sims and references reused


def study_job(payload, place) -> dict:
    """One device x integrator x size group in a worker (``phase`` ``search``: everything but
    the timings; ``timing``: the timings, the searches' rows given). ``known`` holds the rows
    already in the driver's file (resume, the search phase's). Returns ``{"rows": [...]}``."""
    plan_dict, device, integrator, n, phase, known, run_id = payload
    tag = json.dumps(plan_dict, sort_keys=True, default=list)
    study = _WORKER_STUDIES.get(tag)
    if study is None:
        plan = StudyPlan(**plan_dict)
        study = _WORKER_STUDIES[tag] = Measurements(plan, _Collector())
        study.run_id = run_id
    if study.run_id != run_id:  # a Ray worker outlives a study: the rows of an earlier one are not this one's
        study.out, study.run_id = _Collector(), run_id
    study.out.done.update(known)
    study.out.new = []
    study.defer_timing = phase == "search"
    if place.device and is_cuda(device) and place.device != device:
        study.device_map[device] = place.device  # a Ray GPU task sees its GPU as cuda:0; keys keep the plan's device
    study.place = {"host": place.host, "worker": place.worker, "concurrent_runs": 1}
    study.group(device, integrator, n)
    return {"rows": study.out.new}


def run_parallel(study: Measurements, settings: ParallelSettings, progress=None, report=None, ray_pool=None) -> int:
    """Run ``study``'s plan through worker processes or Ray (see :class:`ParallelSettings`;
    ``ray_pool``: a connected pool, see :func:`run_study`); the driver (this process) writes
    every row. Returns the number of groups that failed."""
    p = study.plan
    groups = plan_groups(p)
    total = max(2 * sum(_group_weight(p, n) for _, _, n in groups), 1e-9)
    bar = Progress(stream=progress, enabled=progress is not None, layout=_line, keep=True)
    progressed = 0.0
    plan_dict = asdict(p)
    run_id = f"{socket.gethostname()}:{os.getpid()}:{time.time_ns()}"  # this study run (worker caches are per run)
    failed = 0
    note = event_printer(report, "warpcloth: study: ")

    for phase, workers in (("search", settings.workers), ("timing", settings.timing_workers)):
        known = dict(study.out.done)
        jobs = [Job(f"{phase}|{d}|{i}|{n}", (plan_dict, d, i, n, phase, known, run_id), device=d) for d, i, n in groups]
        # on Ray, at most timing_workers timed groups in flight; locally, that many processes
        at_a_time = workers if ray_pool is not None and phase == "timing" else None
        for done in run_jobs(
            study_job, jobs, workers, init=init_worker, on_event=note, pool=ray_pool, at_a_time=at_a_time
        ):
            _, d, i, n, _, _, _ = done.job.payload
            if done.row is None:
                failed += 1
                note(f"{phase} of {i} {group_label(n)} on {d} failed after {done.attempts} attempt(s): {done.error}")
            else:
                for measured in done.row["rows"]:
                    if measured["key"] in study.out.done:  # a shared measurement (the floor) another worker wrote first
                        continue
                    row = dict(measured)
                    if done.place is not None:
                        row.update(host=done.place.host, worker=done.place.worker)
                    row["concurrent_runs"] = done.concurrent
                    study.write(row)
            progressed += _group_weight(p, n)
            bar.update(progressed, total, f"{phase} {i} {group_label(n)} {d} done", force=True)
    bar.close()
    return failed


# -- the driver ------------------------------------------------------------------------------
def available_devices(devices: list, stream=None) -> list:
    """The devices of ``devices`` that are present; each missing one is skipped with one line."""
    out = []
    for d in devices:
        try:
            out.append(resolve_device(d))
        except WarpclothError as exc:
            if stream is not None:
                print(f"warpcloth: study: skipping device {d}: {exc}", file=stream)
    return list(dict.fromkeys(out))


def prepare_out(out_dir: str) -> str:
    """The output folder, created if missing (its parent must exist); checked writable before
    any work. Returns the results.csv path."""
    out_dir = os.fspath(out_dir)
    require(bool(out_dir.strip()), "--out is empty")
    if os.path.lexists(out_dir) and not os.path.isdir(out_dir):
        raise WarpclothError(f"--out {out_dir!r} exists and is not a folder")
    if not os.path.isdir(out_dir):
        parent = os.path.dirname(os.path.abspath(out_dir))
        if not os.path.isdir(parent):
            raise WarpclothError(f"--out {out_dir!r}: folder {parent!r} does not exist")
        try:
            os.mkdir(out_dir)
        except OSError as exc:
            raise WarpclothError(f"--out {out_dir!r} cannot be created: {exc.strerror or exc}") from None
    for name in ("results.csv", "report.md", "work_precision.png"):
        check_output_path(os.path.join(out_dir, name), "study output")
    return os.path.join(out_dir, "results.csv")


def run_study(
    plan: StudyPlan,
    out_dir: str,
    resume: bool = False,
    overwrite: bool = False,
    progress=None,
    command: str = "",
    on_row=None,
    workers=None,
    ray=None,
    timing_workers=None,
) -> dict:
    """Run ``plan`` into ``out_dir`` (results.csv, report.md, PNG plots). Returns a summary.
    ``workers`` / ``ray`` / ``timing_workers``: see :class:`ParallelSettings` (default serial)."""
    report = progress if progress is not None else sys.stderr
    devices = available_devices(plan.devices, report)
    require(bool(devices), f"none of the devices {', '.join(plan.devices)} is available")
    settings = ParallelSettings.check(devices, workers=workers, ray=ray, timing_workers=timing_workers)
    prepare_out(out_dir)  # checked before connecting to a cluster; nothing written yet
    ray_pool = None
    if settings.ray is not None:
        ray_pool = open_pool(
            study_job, ray=settings.ray, init=init_worker, on_event=event_printer(report, "warpcloth: study: ")
        )
    try:
        return _run_study(
            plan, devices, settings, ray_pool, out_dir, resume, overwrite, progress, report, command, on_row
        )
    finally:
        if ray_pool is not None:
            ray_pool.close()


def _run_study(
    plan, devices, settings, ray_pool, out_dir, resume, overwrite, progress, report, command, on_row
) -> dict:
    csv_path = prepare_out(out_dir)
    plan = replace(
        plan,
        devices=devices,
        reference_cache=plan.reference_cache or os.path.abspath(os.path.join(out_dir, ".references")),
    )
    out = ResultsFile(csv_path, RESULTS, resume=resume, overwrite=overwrite, report=progress, keep_rows=True)
    t0 = time.perf_counter()
    failed = 0
    try:
        if out.truncated and progress is not None:
            print(out.dropped_note(), file=progress)
        study = Measurements(plan, out, on_row)
        if settings.parallel:
            for w in settings.warnings:
                print(f"warpcloth: warning: {w}", file=report, flush=True)
            if progress is not None:
                print(f"warpcloth: study: running {settings.describe()}", file=progress, flush=True)
            failed = run_parallel(study, settings, progress, report, ray_pool)
        else:
            run_serial(study, progress)
    finally:
        out.close()
    files = write_report(out_dir, read_rows(csv_path), plan, command=command, stream=progress)
    return {
        "measured": study.measured,
        "reused": study.reused,
        "wall_s": time.perf_counter() - t0,
        "files": files,
        "plan": asdict(plan),
        "failed": failed,
    }


__all__ = [
    "ParallelSettings",
    "available_devices",
    "prepare_out",
    "run_parallel",
    "run_serial",
    "run_study",
    "study_job",
]
