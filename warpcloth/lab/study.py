"""``warpcloth study``: the seed's question answered with measured, accuracy-aware figures.

For each device x integrator x mesh size (n x n particles) it measures, one CSV row per
measurement (:data:`COLUMNS`):

* ``max_stable_dt`` (sheet and flag): :func:`warpcloth.lab.maxdt.find_max_dt` up to one 60 FPS frame,
  with the max strain at that dt;
* at the *accuracy sizes* (where a float64 reference is computed): ``floor`` (rk4 at a quarter of
  its default dt: the float32 noise floor of the transient), ``error`` (e at dt = frame/k, every
  trial), ``max_accurate_dt`` (sheet swing and flag transient, :mod:`warpcloth.lab.accuracy`),
  ``static`` (the sheet run from rest to equilibrium: static error, sag error, time to
  equilibrium) and ``max_static_accurate_dt``; with ``match_accuracy``, ``match`` rows for
  pbd/xpbd (iterations x substeps at one step per frame) and ``match_result``;
* ``timing`` on the sheet at the max stable dt and the max accurate dt (the smaller of the two
  transients'): ms/step over ``windows`` timed windows after a warm-up (compile) and an untimed
  replay (graph capture), median and spread; wall s per simulated s, real time at 30 and 60 FPS;
* ``static`` at the max stable dt at every size (time to equilibrium; static error where the
  float64 equilibrium is computed).

Rows are written as they finish (header atomically, each row flushed and fsync'd, a writer lock);
``resume`` skips measurements whose key is already in the file and reuses their values.
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
import socket
import statistics
import sys
import time
from dataclasses import asdict, dataclass, field, replace

from warpcloth.errors import WarpclothError, require
from warpcloth.run.harness import RunHarness
from warpcloth.io.files import OutputError, csv_cell, csv_line, WriterLock, check_output_path, describe_write_error, sweep_stale_temporaries, write_atomic
from warpcloth.lab.results import COLUMN_DOCS, COLUMNS, MESH_NOTE  # noqa: F401  (importable from here)
from warpcloth.lab.accuracy import DEFAULT_TOLERANCE, FRAME_DT, AccuracyProblem, StaticProblem, Transient, check_tolerance, search_steps_per_frame, steps_per_frame_at_most

SCENARIOS = ("sheet", "flag")
#: pbd/xpbd iterations x substeps tried by ``--match-accuracy``, cheapest (iterations x substeps) first.
MATCH_ITERATIONS = (5, 10, 20, 40, 80)
MATCH_SUBSTEPS = (1, 2, 4, 8, 16)


@dataclass
class StudyPlan:
    """What a study measures. ``sizes``: the timing/stability ladder (n x n); ``accuracy_sizes``:
    where the float64 references are computed (their timing is measured too)."""

    profile: str
    integrators: list
    sizes: list
    accuracy_sizes: list
    devices: list
    tolerance: float = DEFAULT_TOLERANCE
    sheet_transient: float = 1.0  # s
    flag_transient: float = 0.5  # s
    maxdt_duration: float = 1.0  # s each stability trial must survive
    maxdt_durations: tuple = ()  # ((n_min, seconds), ...): shorter trials from size n_min up (large sizes)
    maxdt_precision: float = 0.05
    maxdt_wall_cap: float | None = 30.0
    accurate_precision: float = 0.05
    accuracy_k_max: int = 4096  # the accuracy search's bound: dt >= (1/60 s) / max(this, 64 k_stable)
    windows: int = 5
    window_seconds: float = 0.1
    equilibrium_duration: float = 10.0  # s simulated at most
    equilibrium_wall_cap: float | None = 30.0
    static_max_size: int = 64  # the float64 equilibrium (Newton) up to this n
    error_ladder: tuple = (1, 2, 4, 8, 16, 32, 64)  # steps per frame, at the smallest accuracy size
    timing_scenarios: tuple = ("sheet",)
    extra_dt_fractions: tuple = ()  # timing also at max stable dt x each (the seed's "two smaller")
    match_accuracy: bool = False
    grid: bool = True  # the sheet and flag at the sizes above
    scenario_files: list = field(default_factory=list)  # fixed-mesh scenarios (files or registered names): stability, equilibrium, timing

    def maxdt_duration_at(self, n: int) -> float:
        """The stability trial's simulated duration [s] at size ``n`` (``maxdt_durations``)."""
        out = self.maxdt_duration
        for n_min, seconds in sorted(self.maxdt_durations):
            if n >= n_min:
                out = seconds
        return out

    @property
    def all_sizes(self) -> list:
        return sorted(set(self.sizes) | set(self.accuracy_sizes))

    def transient(self, scenario: str) -> Transient:
        return Transient(scenario, self.sheet_transient if scenario == "sheet" else self.flag_transient, swing=scenario == "sheet")


PROFILES = {
    "quick": dict(sizes=[4, 6, 8], accuracy_sizes=[4, 6], sheet_transient=0.5, flag_transient=0.25, maxdt_duration=0.5,
                  maxdt_precision=0.1, accurate_precision=0.1, window_seconds=0.03, equilibrium_duration=4.0,
                  equilibrium_wall_cap=5.0, maxdt_wall_cap=5.0, error_ladder=(1, 2, 4, 8, 16, 32)),
    # every integrator, 16-128 on a 2-core CPU within about 40 minutes (docs/study.md, "Profiles"):
    # stability trials shortened with size (a 1 s trial of rk4 at 128x128 is ~9k steps of ~4.5 ms);
    # accuracy at 8 and 12 (implicit-type integrators search to k of hundreds there; at 16 the
    # last standard run spent 25 min on them), bisection to 15 %.
    "standard": dict(sizes=[16, 32, 64, 128], accuracy_sizes=[8, 12], maxdt_durations=((64, 0.5), (128, 0.25)),
                     maxdt_wall_cap=30.0, equilibrium_wall_cap=10.0, accurate_precision=0.15),
    "seed": dict(sizes=[32, 64, 128], accuracy_sizes=[8, 16], timing_scenarios=("sheet", "flag"),
                 extra_dt_fractions=(0.5, 0.25), maxdt_duration=2.0, maxdt_precision=0.02, equilibrium_wall_cap=60.0,
                 maxdt_wall_cap=60.0),
}


def make_plan(profile: str = "quick", integrators=None, sizes=None, devices=None, tolerance=DEFAULT_TOLERANCE,
              match_accuracy: bool = False, accuracy_sizes=None, scenarios=None) -> StudyPlan:
    """A :class:`StudyPlan` from a profile and explicit overrides (checked; one-line errors)."""
    from warpcloth.integrators import integrator_names

    if profile not in PROFILES:
        raise WarpclothError(f"unknown profile {profile!r}; choose one of {', '.join(PROFILES)}")
    names = integrator_names()
    if integrators is None:
        integrators = list(names)
    integrators = list(integrators)
    require(bool(integrators), "the integrator list is empty")
    for name in integrators:
        if name not in names:
            raise WarpclothError(f"unknown integrator {name!r}; choose from {', '.join(names)}")
    base = dict(PROFILES[profile])
    if sizes is not None:
        sizes = list(sizes)
        require(bool(sizes), "the size list is empty: give sizes like --sizes 8,16")
        for s in sizes:
            require(isinstance(s, int) and s >= 3, f"sizes must be integers >= 3 (n x n particles), got {s!r}")
        base["sizes"] = sizes
        if accuracy_sizes is None:
            base["accuracy_sizes"] = [s for s in sizes if s <= max(PROFILES[profile]["accuracy_sizes"])] or [min(sizes)]
    if accuracy_sizes is not None:
        base["accuracy_sizes"] = list(accuracy_sizes)
    if devices is None:
        devices = ["cpu", "cuda"] if profile == "seed" else ["cpu"]
    devices = list(devices)
    require(bool(devices), "the device list is empty")
    grid, files = check_scenarios(scenarios)
    return StudyPlan(profile=profile, integrators=integrators, devices=devices, tolerance=check_tolerance(tolerance),
                     match_accuracy=bool(match_accuracy), grid=grid, scenario_files=files, **base)


def check_scenarios(scenarios) -> tuple[bool, list]:
    """``--scenarios``: (whether the sheet/flag grid study runs, the other scenarios). None: the
    grid only. ``sheet`` and ``flag`` go together (the accuracy metric uses both); any other
    item is a scenario file (.toml) or a registered scenario, loaded here so that a bad one is
    refused before any work."""
    if scenarios is None:
        return True, []
    from warpcloth.scenarios import get_scenario

    items = list(dict.fromkeys(scenarios))
    require(bool(items), "the scenario list is empty: give e.g. --scenarios sheet,flag,examples/cape.toml")
    grid = [s for s in items if s in SCENARIOS]
    if len(grid) == 1:
        raise WarpclothError(f"--scenarios: {grid[0]} without {'flag' if grid[0] == 'sheet' else 'sheet'}: the study's sheet and "
                             "flag go together (the accuracy uses both); give both or neither")
    files = [s for s in items if s not in SCENARIOS]
    for name in files:
        get_scenario(name)  # WarpclothError: unknown name, missing or malformed file
    return bool(grid), files


# -- the results file ------------------------------------------------------------------------
def format_row(row: dict) -> str:
    """One CSV line (with its newline) for ``row``; missing columns are empty."""
    return csv_line(row, COLUMNS)


def parse_cell(text: str):
    """A CSV cell back to a value: '' -> None, true/false, int, float (inf, nan), else str."""
    if text == "":
        return None
    if text in ("true", "false"):
        return text == "true"
    try:
        return int(text)
    except ValueError:
        pass
    try:
        return float(text)
    except ValueError:
        return text


def read_rows(path: str) -> list[dict]:
    """The rows of a study's results.csv, values parsed."""
    with open(path, newline="", encoding="utf-8") as fh:
        return [{k: parse_cell(v) for k, v in r.items()} for r in csv.DictReader(fh)]


class StudyCsv:
    """results.csv: header written atomically, one fsync'd row per measurement, a writer lock;
    ``resume`` validates the whole file first (header, cell counts), drops a cut last line and
    returns the finished rows by key. The same rules as the sweep's results file."""

    def __init__(self, path: str, resume: bool = False, overwrite: bool = False, report=None):
        self.path = path
        self.done: dict[str, dict] = {}
        self.note = ""
        directory = os.path.dirname(os.path.abspath(path))
        try:
            check_output_path(path, "results")
        except WarpclothError as exc:
            raise WarpclothError(f"cannot write results to {path}: {exc}") from None
        self.lock = WriterLock(path).acquire()
        try:
            sweep_stale_temporaries(directory, report)
            exists = os.path.exists(path) and os.path.getsize(path) > 0
            if exists and resume:
                self._read_existing()
            elif exists and not overwrite:
                raise WarpclothError(f"{path} already exists: use --resume to continue it or --overwrite to replace it")
            else:
                write_atomic(path, format_row(dict(zip(COLUMNS, COLUMNS))), "results CSV")
            self.fh = open(path, "a", newline="", encoding="utf-8")
        except OutputError as exc:
            self.lock.release()
            raise WarpclothError(str(exc)) from None
        except BaseException:
            self.lock.release()
            raise

    def _read_existing(self) -> None:
        with open(self.path, "rb") as fh:
            data = fh.read()
        cut = data.rfind(b"\n") + 1
        require(cut > 0, f"cannot resume {self.path}: it has no complete header line (left unchanged)")
        try:
            text = data[:cut].decode("utf-8")
        except UnicodeDecodeError:
            raise WarpclothError(f"cannot resume {self.path}: not UTF-8 text (left unchanged)") from None
        reader = csv.reader(io.StringIO(text))
        header = next(reader, None)
        if header != COLUMNS:
            raise WarpclothError(f"cannot resume {self.path}: its header is not this warpcloth's study columns (left unchanged)")
        rows = {}
        for line_no, cells in enumerate(reader, start=2):
            if len(cells) != len(COLUMNS):
                raise WarpclothError(f"cannot resume {self.path}: line {line_no} has {len(cells)} cells, expected {len(COLUMNS)} (left unchanged)")
            row = {k: parse_cell(v) for k, v in zip(COLUMNS, cells)}
            rows[row["key"]] = row
        if cut < len(data):
            os.truncate(self.path, cut)
            self.note = f"{self.path}: dropped an incomplete last line ({len(data) - cut} bytes, a measurement cut short); it runs again"
        self.done = rows

    def write(self, row: dict) -> None:
        text = format_row(row)
        try:
            self.fh.write(text)
            self.fh.flush()
            os.fsync(self.fh.fileno())
        except OSError as exc:
            raise OutputError(describe_write_error(exc, self.path, "results CSV", needed=len(text.encode()))
                              .replace(f"; {self.path} is unchanged", "; the rows before it are kept")) from None
        self.done[row["key"]] = {k: parse_cell(csv_cell(row.get(k))) for k in COLUMNS}

    def close(self) -> None:
        try:
            self.fh.close()
        finally:
            self.lock.release()


# -- progress --------------------------------------------------------------------------------
def _clock(seconds: float) -> str:
    seconds = max(0, int(round(seconds)))
    return f"{seconds // 3600}:{seconds // 60 % 60:02d}:{seconds % 60:02d}" if seconds >= 3600 else f"{seconds // 60}:{seconds % 60:02d}"


class Progress:
    """A bar with an ETA on ``stream`` (redrawn in place on a terminal, one line per update
    otherwise). Work is weighted by particle count; the ETA is elapsed x remaining / done."""

    def __init__(self, total_weight: float, stream=None, width: int = 24):
        self.total = max(total_weight, 1e-9)
        self.done = 0.0
        self.stream = stream
        self.width = width
        self.start = time.perf_counter()
        self.tty = bool(stream is not None and getattr(stream, "isatty", lambda: False)())

    def update(self, label: str, finished_weight: float = 0.0) -> None:
        self.done += finished_weight
        if self.stream is None:
            return
        frac = min(1.0, self.done / self.total)
        elapsed = time.perf_counter() - self.start
        eta = f"ETA {_clock(elapsed * (1 - frac) / frac)}" if frac > 0 else "ETA ?"
        bar = "#" * int(round(frac * self.width))
        line = f"study [{bar:<{self.width}}] {100 * frac:3.0f}% {_clock(elapsed)} {eta} {label}"
        if self.tty:
            self.stream.write("\r\x1b[K" + line)
        else:
            self.stream.write(line + "\n")
        self.stream.flush()

    def close(self) -> None:
        if self.stream is not None and self.tty:
            self.stream.write("\n")
            self.stream.flush()


# -- the runner ------------------------------------------------------------------------------
class _Deferred(Exception):
    """A measurement that needs a timing, in the search phase of a parallel study."""


def _options_text(options: dict) -> str:
    return " ".join(f"{k}={v}" for k, v in sorted(options.items()))


class Study:
    """Runs a :class:`StudyPlan` into a :class:`StudyCsv` (see the module docstring)."""

    def __init__(self, plan: StudyPlan, out: StudyCsv, progress=None, on_row=None):
        import warp as wp

        from warpcloth.version import __version__

        self.plan = plan
        self.out = out
        self.progress = progress
        self.on_row = on_row  # called with each new row (tests: interrupt after N)
        self.versions = {"warpcloth_version": __version__, "warp_version": wp.config.version}
        self.place = {"host": socket.gethostname(), "worker": "main", "concurrent_runs": 1}
        self.defer_timing = False  # the search phase of a parallel study: timings come later, alone
        self.device_map: dict = {}  # plan device -> the device this process runs it on (a Ray GPU task: cuda:0)
        self._sims: dict = {}
        self._counts: dict = {}  # (scenario, n, device) -> (particles, springs)
        self._problems: dict = {}
        self._static: dict = {}
        self.measured = 0
        self.reused = 0

    # one measurement, done once ---------------------------------------------------------------
    def once(self, key: str, base: dict, fn) -> dict:
        if key in self.out.done:
            self.reused += 1
            return self.out.done[key]
        t0 = time.perf_counter()
        row = dict(base)
        row.update(fn())
        row.setdefault("measure_wall_s", time.perf_counter() - t0)
        row.update(self.versions)
        row.update(self.place)
        row["key"] = key
        self.out.write(row)
        self.measured += 1
        if self.on_row is not None:
            self.on_row(row)
        return self.out.done[key]

    def sim(self, scenario: str, n: int, device: str, integrator: str, options: dict | None = None):
        from warpcloth.integrators import make_integrator
        from warpcloth.scenarios import get_scenario

        key = (scenario, n, device)
        sim = self._sims.get(key)
        if sim is None:
            size = {} if n is None else {"rows": n, "cols": n}  # n None: a fixed-mesh scenario
            sim = self._sims[key] = get_scenario(scenario).build(**size, device=self.device_map.get(device, device),
                                                                 integrator=integrator, dt=FRAME_DT)
            self._counts[key] = (sim.model.particle_count, sim.model.spring_count)
        sim.set_integrator(make_integrator(integrator, **(options or {})), dt=FRAME_DT)
        sim.reset()
        return sim

    def problem(self, scenario: str, n: int, device: str) -> AccuracyProblem:
        key = (scenario, n, device)
        if key not in self._problems:
            self._problems[key] = AccuracyProblem(self.sim(scenario, n, device, "explicit_euler"), self.plan.transient(scenario))
        return self._problems[key]

    def static_problem(self, n: int, device: str) -> StaticProblem | None:
        if n > self.plan.static_max_size:
            return None
        key = (n, device)
        if key not in self._static:
            self._static[key] = StaticProblem(self.sim("sheet", n, device, "explicit_euler"))
        return self._static[key]

    def base(self, measurement: str, scenario: str, integrator: str, device: str, n: int, options: dict | None = None) -> dict:
        from warpcloth.sim.grid import expected_spring_counts

        if n is None:  # a fixed-mesh scenario: its own counts
            if (scenario, None, device) not in self._counts:
                self.sim(scenario, None, device, integrator)
            particles, springs = self._counts[(scenario, None, device)]
            return {"measurement": measurement, "scenario": scenario, "integrator": integrator, "options": _options_text(options or {}),
                    "device": device, "rows": None, "cols": None, "particles": particles, "springs": springs}
        return {"measurement": measurement, "scenario": scenario, "integrator": integrator, "options": _options_text(options or {}),
                "device": device, "rows": n, "cols": n, "particles": n * n,
                "springs": sum(expected_spring_counts(n, n, "provot").values())}

    # the measurements ---------------------------------------------------------------------------
    def max_stable_dt(self, scenario: str, integrator: str, device: str, n: int) -> dict:
        p = self.plan
        base = self.base("max_stable_dt", scenario, integrator, device, n)
        duration = p.maxdt_duration_at(n if n is not None else round(math.sqrt(base["particles"])))
        key = f"max_stable_dt|{scenario}|{integrator}|{device}|{_size(n)}|dur={duration}|prec={p.maxdt_precision}|cap={p.maxdt_wall_cap}"

        def run():
            from warpcloth.lab.maxdt import find_max_dt
            from warpcloth.scenarios import get_scenario

            sc = get_scenario(scenario)
            size = {} if n is None else {"rows": n, "cols": n}
            r = find_max_dt(sc, sc.config(**size, integrator=integrator, device=self.device_map.get(device, device)),
                            precision=p.maxdt_precision,
                            duration=duration, dt_max=FRAME_DT, wall_cap=p.maxdt_wall_cap)
            note = r.no_stable_reason or ("stable up to the search limit (one 60 FPS frame)" if r.limit_reached and r.dt else "")
            if r.inconclusive_trials:
                note = (note + "; " if note else "") + f"{r.inconclusive_trials} trials stopped by the wall cap (counted stable)"
            return {"dt_s": r.dt, "bound_dt_s": r.unstable_dt, "search_bounded": r.limit_reached, "max_strain_rel": r.max_strain,
                    "stable": r.dt is not None, "trials": len(r.trials), "transient_s": duration, "note": note}

        return self.once(key, base, run)

    def floor(self, scenario: str, device: str, n: int) -> dict:
        from warpcloth.integrators import make_integrator

        p = self.plan
        tr = p.transient(scenario)
        key = f"floor|{scenario}|rk4|{device}|{n}|T={tr.duration}"

        def run():
            problem = self.problem(scenario, n, device)  # first: building it rebinds the cached sim's integrator
            sim = self.sim(scenario, n, device, "rk4")
            k = 4 * steps_per_frame_at_most(make_integrator("rk4").default_dt(sim.model, sim.control.drag_rate))
            e = problem.error(sim, k)
            return {"dt_s": FRAME_DT / k, "steps_per_frame": k, "error_rel": e, "floor_error_rel": e, "transient_s": tr.duration,
                    "note": "rk4 at a quarter of its default dt: the float32 noise floor of this transient"}

        return self.once(key, self.base("floor", scenario, "rk4", device, n), run)

    def error(self, scenario: str, integrator: str, device: str, n: int, k: int, options: dict | None = None) -> float:
        tr = self.plan.transient(scenario)
        opt = _options_text(options or {})
        key = f"error|{scenario}|{integrator}|{opt}|{device}|{n}|T={tr.duration}|k={k}"

        def run():
            problem = self.problem(scenario, n, device)  # first: building it rebinds the cached sim's integrator
            sim = self.sim(scenario, n, device, integrator, options)
            e = problem.error(sim, k)
            return {"dt_s": FRAME_DT / k, "steps_per_frame": k, "error_rel": e, "transient_s": tr.duration, "stable": math.isfinite(e),
                    **({"iterations": options.get("iterations"), "substeps": options.get("substeps")} if options else {})}

        return self.once(key, self.base("error", scenario, integrator, device, n, options), run)["error_rel"]

    def max_accurate_dt(self, scenario: str, integrator: str, device: str, n: int, stable_dt) -> dict:
        p = self.plan
        tr = p.transient(scenario)
        key = (f"max_accurate_dt|{scenario}|{integrator}|{device}|{n}|T={tr.duration}|tol={p.tolerance}|prec={p.accurate_precision}"
               + (f"|kmax={p.accuracy_k_max}" if p.accuracy_k_max != 4096 else ""))
        floor = self.floor(scenario, device, n)["error_rel"]

        def run():
            if stable_dt is None:
                return {"note": "no stable dt: no accurate dt", "tolerance_rel": p.tolerance, "floor_error_rel": floor}
            k0 = steps_per_frame_at_most(stable_dt)
            s = search_steps_per_frame(lambda k: self.error(scenario, integrator, device, n, k), p.tolerance, k_start=k0,
                                       k_max=max(p.accuracy_k_max, 64 * k0), precision=p.accurate_precision)
            e = dict(s.trials).get(s.k) if s.k else None
            note = "monotone e(dt) assumed"
            if s.bounded:
                note += "; accurate at the search's upper bound (the max stable dt or one frame)"
            if s.k is None:
                last = s.trials[-1][1] if s.trials else None
                note += (f"; e stopped falling as dt shrank (about {last:.3g}): no dt is accurate with these options" if s.stalled
                         else f"; no dt found accurate down to (1/60 s)/{max(p.accuracy_k_max, 64 * k0)} (the search's bound)")
            return {"dt_s": s.dt(), "steps_per_frame": s.k, "bound_dt_s": FRAME_DT / s.k_inaccurate if s.k_inaccurate else None,
                    "search_bounded": s.bounded, "tolerance_rel": p.tolerance, "error_rel": e, "floor_error_rel": floor,
                    "transient_s": tr.duration, "trials": len(s.trials), "note": note}

        return self.once(key, self.base("max_accurate_dt", scenario, integrator, device, n), run)

    def static(self, integrator: str, device: str, n: int, k: int, options: dict | None = None) -> dict:
        p = self.plan
        opt = _options_text(options or {})
        key = f"static|sheet|{integrator}|{opt}|{device}|{n}|k={k}|dur={p.equilibrium_duration}|cap={p.equilibrium_wall_cap}"

        def run():
            prob = self.static_problem(n, device)  # first: building it rebinds the cached sim's integrator
            sim = self.sim("sheet", n, device, integrator, options)
            dt = FRAME_DT / k
            if prob is None:
                sim.set_dt(dt)
                r = RunHarness(sim).run(p.equilibrium_duration, stop_at_equilibrium=True, wall_cap=p.equilibrium_wall_cap)
                return {"dt_s": dt, "steps_per_frame": k, "equilibrium_reached": r.equilibrium_reached, "stable": r.stable,
                        "time_to_equilibrium_sim_s": r.time_to_equilibrium, "time_to_equilibrium_wall_s": r.time_to_equilibrium_wall,
                        "max_strain_rel": r.max_strain, "note": f"no float64 equilibrium above {p.static_max_size}x{p.static_max_size}"}
            s = prob.measure(sim, dt, p.equilibrium_duration, p.equilibrium_wall_cap)
            return {"dt_s": dt, "steps_per_frame": k, "equilibrium_reached": s.equilibrium_reached, "stable": s.stable,
                    "time_to_equilibrium_sim_s": s.time_to_equilibrium, "time_to_equilibrium_wall_s": s.time_to_equilibrium_wall,
                    "static_error_rel": s.error, "sag_error_rel": s.sag_error, "tolerance_rel": p.tolerance,
                    "note": "" if s.equilibrium_reached else f"not at rest after {s.sim_time:.3g} s simulated (cap {p.equilibrium_duration:g} s or {p.equilibrium_wall_cap} s wall)"}

        return self.once(key, self.base("static", "sheet", integrator, device, n, options), run)

    def max_static_accurate_dt(self, integrator: str, device: str, n: int, stable_dt) -> dict:
        p = self.plan
        key = f"max_static_accurate_dt|sheet|{integrator}|{device}|{n}|tol={p.tolerance}|dur={p.equilibrium_duration}"

        def run():
            if stable_dt is None:
                return {"note": "no stable dt", "tolerance_rel": p.tolerance}
            k0 = steps_per_frame_at_most(stable_dt)

            def err(k):
                row = self.static(integrator, device, n, k)
                return row["static_error_rel"] if row.get("static_error_rel") is not None else math.inf

            s = search_steps_per_frame(err, p.tolerance, k_start=k0, k_max=max(1024, 16 * k0), precision=max(p.accurate_precision, 0.2))
            note = "monotone static error assumed"
            if s.bounded:
                note += "; accurate at the max stable dt (the search's upper bound)"
            return {"dt_s": s.dt(), "steps_per_frame": s.k, "bound_dt_s": FRAME_DT / s.k_inaccurate if s.k_inaccurate else None,
                    "search_bounded": s.bounded, "tolerance_rel": p.tolerance, "error_rel": dict(s.trials).get(s.k) if s.k else None,
                    "trials": len(s.trials), "note": note}

        return self.once(key, self.base("max_static_accurate_dt", "sheet", integrator, device, n), run)

    def timing(self, scenario: str, integrator: str, device: str, n: int, dt: float, label: str, options: dict | None = None) -> dict:
        p = self.plan
        opt = _options_text(options or {})
        key = f"timing|{scenario}|{integrator}|{opt}|{device}|{n}|{label}|dt={dt!r}|w={p.windows}"

        if self.defer_timing and key not in self.out.done:
            return {}

        def run():
            from warpcloth.run.harness import time_steps

            sim = self.sim(scenario, n, device, integrator, options)
            sim.set_dt(dt)
            steps_frame = max(1, math.ceil(FRAME_DT / dt - 1e-9))
            # compile and the first replay (graph capture) excluded; windows replay the frame's steps
            t = time_steps(sim, windows=p.windows, window_seconds=p.window_seconds, batch=steps_frame)
            ms, m = t.ms_per_step, t.steps_per_window
            med = t.median_ms
            cost = t.wall_s_per_sim_s

            return {"dt_s": dt, "ms_per_step_median": med, "ms_per_step_min": min(ms), "ms_per_step_max": max(ms),
                    "timed_windows": len(ms), "steps_per_window": m, "wall_s_per_sim_s": cost, "realtime_factor": 1.0 / cost,
                    "realtime_30fps": t.realtime(30.0), "realtime_60fps": t.realtime(60.0), "note": f"at the {label} dt",
                    **({"iterations": options.get("iterations"), "substeps": options.get("substeps")} if options else {})}

        return self.once(key, self.base("timing", scenario, integrator, device, n, options), run)

    def match(self, integrator: str, device: str, n: int) -> dict:
        """The cheapest iterations x substeps (by their product) at one step per frame reaching the
        tolerance on both transients."""
        p = self.plan
        key = f"match_result|{integrator}|{device}|{n}|tol={p.tolerance}|T={p.sheet_transient},{p.flag_transient}"

        def run():
            pairs = sorted(((i, s) for i in MATCH_ITERATIONS for s in MATCH_SUBSTEPS), key=lambda t: (t[0] * t[1], t[1]))
            tried = 0
            for it, sub in pairs:
                opts = {"iterations": it, "substeps": sub}
                tried += 1
                errs = []
                for sc in SCENARIOS:
                    errs.append(self.error(sc, integrator, device, n, 1, opts))
                    if not errs[-1] <= p.tolerance:
                        break
                if len(errs) == len(SCENARIOS) and all(e <= p.tolerance for e in errs):
                    if self.defer_timing:
                        raise _Deferred
                    t = self.timing("sheet", integrator, device, n, FRAME_DT, "matched", opts)
                    return {"dt_s": FRAME_DT, "steps_per_frame": 1, "iterations": it, "substeps": sub, "error_rel": max(errs),
                            "tolerance_rel": p.tolerance, "trials": tried, "ms_per_step_median": t["ms_per_step_median"],
                            "wall_s_per_sim_s": t["wall_s_per_sim_s"], "realtime_30fps": t["realtime_30fps"],
                            "realtime_60fps": t["realtime_60fps"], "note": "cheapest iterations x substeps reaching the tolerance on both transients at dt = 1/60 s"}
            return {"dt_s": FRAME_DT, "tolerance_rel": p.tolerance, "trials": tried,
                    "note": f"no pair up to {MATCH_ITERATIONS[-1]} iterations x {MATCH_SUBSTEPS[-1]} substeps reaches the tolerance"}

        try:
            return self.once(key, self.base("match_result", "sheet+flag", integrator, device, n), run)
        except _Deferred:  # found in the search phase; timed (and written) in the timing phase
            return {}

    def settle(self, scenario: str, integrator: str, device: str, k: int) -> dict:
        """A fixed-mesh scenario run from its start at dt = frame/k until at rest (or the caps):
        time to equilibrium and max strain. No float64 reference: no static error."""
        p = self.plan
        key = f"static|{scenario}|{integrator}||{device}|mesh|k={k}|dur={p.equilibrium_duration}|cap={p.equilibrium_wall_cap}"

        def run():
            sim = self.sim(scenario, None, device, integrator)
            dt = FRAME_DT / k
            sim.set_dt(dt)
            r = RunHarness(sim).run(p.equilibrium_duration, stop_at_equilibrium=True, wall_cap=p.equilibrium_wall_cap)
            return {"dt_s": dt, "steps_per_frame": k, "equilibrium_reached": r.equilibrium_reached, "stable": r.stable,
                    "time_to_equilibrium_sim_s": r.time_to_equilibrium, "time_to_equilibrium_wall_s": r.time_to_equilibrium_wall,
                    "max_strain_rel": r.max_strain, "note": MESH_NOTE}

        return self.once(key, self.base("static", scenario, integrator, device, None), run)

    def mesh_group(self, device: str, integrator: str, scenario: str) -> None:
        """A fixed-mesh scenario (a file or a registered scenario): max stable dt, time to
        equilibrium at it and ms/step at it. Accuracy is not measured (:data:`MESH_NOTE`)."""
        stable = self.max_stable_dt(scenario, integrator, device, None)["dt_s"]
        if stable is None:
            return
        k = steps_per_frame_at_most(stable)
        self.settle(scenario, integrator, device, k)
        self.timing(scenario, integrator, device, None, FRAME_DT / k, "stable")

    # the plan -----------------------------------------------------------------------------------
    def group(self, device: str, integrator: str, n) -> None:
        if isinstance(n, str):  # a fixed-mesh scenario's group
            return self.mesh_group(device, integrator, n)
        p = self.plan
        stable = {sc: self.max_stable_dt(sc, integrator, device, n)["dt_s"] for sc in SCENARIOS}
        accurate = None
        if n in p.accuracy_sizes:
            acc = {}
            for sc in SCENARIOS:
                if n == min(p.accuracy_sizes):  # the error-vs-dt ladder for the plot of orders
                    k_stable = steps_per_frame_at_most(stable[sc]) if stable[sc] is not None else None
                    for k in p.error_ladder:
                        if k_stable is not None and k >= k_stable:
                            self.error(sc, integrator, device, n, k)
                acc[sc] = self.max_accurate_dt(sc, integrator, device, n, stable[sc])["dt_s"]
            if all(v is not None for v in acc.values()):
                accurate = min(acc.values())
            ms = self.max_static_accurate_dt(integrator, device, n, stable["sheet"])
            if accurate is not None:
                self.static(integrator, device, n, steps_per_frame_at_most(accurate))
            if p.match_accuracy and integrator in ("pbd", "xpbd"):
                self.match(integrator, device, n)
        if stable["sheet"] is not None:
            self.static(integrator, device, n, steps_per_frame_at_most(stable["sheet"]))
        for sc in p.timing_scenarios:
            if stable[sc] is not None:
                dt_stable = FRAME_DT / steps_per_frame_at_most(stable[sc])
                self.timing(sc, integrator, device, n, dt_stable, "stable")
                for f in p.extra_dt_fractions:
                    self.timing(sc, integrator, device, n, FRAME_DT / steps_per_frame_at_most(stable[sc] * f), f"stable x {f:g}")
            if accurate is not None:
                self.timing(sc, integrator, device, n, accurate, "accurate")

    def run(self) -> None:
        p = self.plan
        groups = plan_groups(p)
        bar = Progress(sum(_group_weight(p, n) for _, _, n in groups), self.progress)
        for d, i, n in groups:
            bar.update(f"{i} {_label(n)} {d}")
            self.group(d, i, n)
            bar.update(f"{i} {_label(n)} {d} done", _group_weight(p, n))
        bar.close()


def _size(n) -> str:
    return "mesh" if n is None else str(n)


def _label(n) -> str:
    return n if isinstance(n, str) else f"{n}x{n}"


def plan_groups(plan: StudyPlan) -> list:
    """(device, integrator, n or scenario) of every group: the grid sizes, then the scenarios."""
    grid = [(d, i, n) for d in plan.devices for n in plan.all_sizes for i in plan.integrators] if plan.grid else []
    return grid + [(d, i, sc) for d in plan.devices for sc in plan.scenario_files for i in plan.integrators]


# -- in parallel: worker processes or Ray tasks (warpcloth.lab.parallel) -----------------------
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
    def check(cls, devices: list, workers=None, ray=None, timing_workers=None) -> "ParallelSettings":
        """Validated settings for a study on ``devices``; WarpclothError names the bad value."""
        for flag, value in (("--workers", workers), ("--timing-workers", timing_workers)):
            if value is not None and (isinstance(value, bool) or not isinstance(value, int) or value < 1):
                raise WarpclothError(f"{flag} must be a whole number >= 1, got {value!r}")
        if ray is not None:
            if workers is not None:
                raise WarpclothError("--ray runs the searches on the cluster's CPUs and GPUs: it takes no --workers")
            ray = str(ray).strip()
            if not ray:
                raise WarpclothError("--ray: give auto, local, HOST:PORT or ray://HOST:PORT")
            try:
                from warpcloth.lab.parallel import import_ray

                import_ray()
            except ImportError as exc:
                raise WarpclothError(f"--ray needs Ray: {str(exc).split(': ', 1)[1]}") from None
        out = cls(workers=workers or 1, ray=ray, timing_workers=timing_workers or 1)
        cores = os.cpu_count() or 1
        if out.workers > 1 and any(not d.startswith("cuda") for d in devices) and out.workers > cores:
            out.warnings.append(f"--workers {out.workers} is more than the {cores} CPU cores: the searches share cores (their "
                                "results do not depend on it, but a trial that reaches a wall cap stops sooner: see the note "
                                "column); the timings still run alone")
        if out.timing_workers > len(devices):
            out.warnings.append(f"--timing-workers {out.timing_workers} is more than the {len(devices)} device(s) "
                                f"({', '.join(devices)}): timed runs share a device and their ms/step are affected "
                                "(see the concurrent_runs column)")
        return out


class _Collector:
    """A worker's stand-in for :class:`StudyCsv`: the rows it measured, kept to be handed back
    to the driver (the only writer of results.csv)."""

    def __init__(self):
        self.done: dict[str, dict] = {}
        self.new: list[dict] = []

    def write(self, row: dict) -> None:
        row = {k: parse_cell(csv_cell(row.get(k))) for k in COLUMNS}
        self.done[row["key"]] = row
        self.new.append(row)


_WORKER_STUDIES: dict = {}  # plan (JSON) -> Study, one per worker process: sims and references reused


def study_init(place) -> None:
    """Run once in each worker process: Warp initialised quietly."""
    from warpcloth.sim.device import init_warp

    init_warp(False)


def study_job(payload, place) -> dict:
    """One device x integrator x size group in a worker (``phase`` ``search``: everything but
    the timings; ``timing``: the timings, the searches' rows given). ``known`` holds the rows
    already in the driver's file (resume, the search phase's). Returns ``{"rows": [...]}``."""
    from warpcloth.lab.parallel import is_cuda

    plan_dict, device, integrator, n, phase, known, run_id = payload
    tag = json.dumps(plan_dict, sort_keys=True, default=list)
    study = _WORKER_STUDIES.get(tag)
    if study is None:
        plan = StudyPlan(**plan_dict)
        study = _WORKER_STUDIES[tag] = Study(plan, _Collector())
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


def _group_weight(plan: StudyPlan, n) -> float:
    if isinstance(n, str):
        return 32 * 32
    return n * n * (4 if n in plan.accuracy_sizes else 1)


def connect_ray(settings: ParallelSettings, report=None):
    """The connected :class:`~warpcloth.lab.parallel.RayPool` of ``settings`` (None without
    ``--ray``); a WarpclothError in one line when the cluster does not answer."""
    if settings.ray is None:
        return None
    from warpcloth.lab.parallel import RayPool

    def note(text: str) -> None:
        if report is not None:
            print(f"warpcloth: study: {text}", file=report, flush=True)

    pool = RayPool(study_job, settings.ray, init=study_init, max_retries=2, on_event=note)
    try:
        pool.connect()
    except ConnectionError as exc:
        raise WarpclothError(f"--ray {settings.ray}: {exc}") from None
    return pool


def run_parallel(study: "Study", settings: ParallelSettings, report=None, ray_pool=None) -> int:
    """Run ``study``'s plan through worker processes or Ray (see :class:`ParallelSettings`;
    ``ray_pool`` from :func:`connect_ray`); the driver (this process) writes every row.
    Returns the number of groups that failed."""
    from warpcloth.lab.parallel import Job, LocalPool

    p = study.plan
    groups = plan_groups(p)
    bar = Progress(2 * sum(_group_weight(p, n) for _, _, n in groups), study.progress)
    plan_dict = asdict(p)
    run_id = f"{socket.gethostname()}:{os.getpid()}:{time.time_ns()}"  # this study run (worker caches are per run)
    failed = 0

    def note(text: str) -> None:
        if report is not None:
            print(f"warpcloth: study: {text}", file=report, flush=True)

    def results(phase: str, workers: int):
        known = dict(study.out.done)
        jobs = [Job(f"{phase}|{d}|{i}|{n}", (plan_dict, d, i, n, phase, known, run_id), device=d) for d, i, n in groups]
        if ray_pool is not None:
            if phase == "search":
                yield from ray_pool.run(jobs)
            else:  # at most timing_workers timed groups in flight
                for at in range(0, len(jobs), workers):
                    yield from ray_pool.run(jobs[at:at + workers])
            return
        pool = LocalPool(study_job, workers, init=study_init, max_retries=2, on_event=note)
        try:
            yield from pool.run(jobs)
        finally:
            pool.close()

    for phase, workers in (("search", settings.workers), ("timing", settings.timing_workers)):
        for done in results(phase, workers):
            _, d, i, n, _, _, _ = done.job.payload
            if done.row is None:
                failed += 1
                note(f"{phase} of {i} {_label(n)} on {d} failed after {done.attempts} attempt(s): {done.error}")
            else:
                for row in done.row["rows"]:
                    if row["key"] in study.out.done:  # a shared measurement (the floor) another worker wrote first
                        continue
                    row = dict(row)
                    if done.place is not None:
                        row.update(host=done.place.host, worker=done.place.worker)
                    row["concurrent_runs"] = done.concurrent
                    study.out.write(row)
                    study.measured += 1
                    if study.on_row is not None:
                        study.on_row(row)
            bar.update(f"{phase} {i} {_label(n)} {d} done", _group_weight(p, n))
    bar.close()
    return failed


# -- an estimate of a plan's wall time (--estimate) ---------------------------------------------
#: seconds of the float64 reference per particle per simulated second (DOP853, rtol 1e-10; measured
#: on the project's 2-core CPU: 5.1 s for the 8x8 sheet's 1 s swing, 15 s at 12x12, 19 s at 16x16)
REFERENCE_S_PER_PARTICLE_S = 0.1
#: the accuracy search of an integrator stable at one frame (implicit_euler, pbd, xpbd, vbd,
#: projective) is modelled as reaching k = this x (n/8)^2 steps per frame: the last standard run
#: found k = 13-76 at 8x8 and 37-416 at 12x12 for them
ACCURATE_K_AT_8 = 64


@dataclass
class PhaseEstimate:
    phase: str
    measurements: int
    seconds: float


def calibrate(plan: StudyPlan, device: str, stream=None) -> dict:
    """Measured ms per step of the sheet for every integrator x size of ``plan`` on ``device`` at
    the integrator's default dt (one frame at most), and at (1/60 s)/64 at the accuracy sizes:
    ``{(integrator, n): (k0, ms at default dt, ms at frame/64 or None)}``. A few steps each
    after a warm-up; seconds in all (the implicit integrators' steps at 128x128 take ~1 s)."""
    from warpcloth.integrators import make_integrator
    from warpcloth.scenarios import get_scenario

    out = {}
    sheet = get_scenario("sheet")

    def ms_per_step(sim, dt):
        """The fastest of 3 windows of about 30 ms (other jobs on the machine only add), with the
        shared timing helper (compile and the first replay excluded)."""
        from warpcloth.run.harness import time_steps

        sim.reset()
        sim.set_dt(dt)
        frame = max(1, math.ceil(FRAME_DT / dt - 1e-9))
        return min(time_steps(sim, windows=3, window_seconds=0.03, batch=min(frame, 20)).ms_per_step)

    for n in plan.all_sizes if plan.grid else []:
        sim = sheet.build(rows=n, cols=n, device=device, integrator="explicit_euler", dt=FRAME_DT)
        for i in plan.integrators:
            sim.set_integrator(make_integrator(i), dt=FRAME_DT)
            k0 = steps_per_frame_at_most(min(make_integrator(i).default_dt(sim.model, sim.control.drag_rate), FRAME_DT))
            small = ms_per_step(sim, FRAME_DT / 64) if n in plan.accuracy_sizes else None
            out[(i, n)] = (k0, ms_per_step(sim, FRAME_DT / k0), small)
            if stream is not None:
                print(f"calibrate {i} {n}x{n} {device}: {out[(i, n)][1]:.3g} ms/step at (1/60 s)/{k0}", file=stream, flush=True)
    return out


def estimate_plan(plan: StudyPlan, costs: dict) -> list[PhaseEstimate]:
    """Seconds per phase of ``plan`` on one device from ``costs`` (:func:`calibrate`), serially.
    A model, not a measurement (docs/study.md, "Estimate"): stability trials at 1.5x the default
    dt (6 trials per search, 1 for an integrator stable at one frame), each capped by the wall cap;
    equilibrium runs to their simulated or wall cap; the float64 references at
    :data:`REFERENCE_S_PER_PARTICLE_S`; accuracy searches of 3 trials at k0 for the explicit
    schemes and doubling to k = :data:`ACCURATE_K_AT_8` (n/8)^2 (bounded by ``accuracy_k_max``)
    then bisection ((3 + log2(0.5 / precision)) k frames) for those stable at one frame; timings their warm-up, capture and windows of whole frames."""
    stab = eq = acc = tim = 0.0
    counts = {"stability": 0, "equilibrium": 0, "accuracy": 0, "timing": 0}
    for n in plan.all_sizes if plan.grid else []:
        for i in plan.integrators:
            k0, ms, ms_small = costs[(i, n)]
            dt0 = FRAME_DT / k0
            # the search's trials straddle the max stable dt, ~1.5-2x the default dt of the explicit
            # schemes (those above it stop early when they blow up): 6 trials at 1.5 dt0
            dt_trial = dt0 if k0 == 1 else 1.5 * dt0
            trial = plan.maxdt_duration_at(n) / dt_trial * ms / 1000.0
            trial = min(trial, plan.maxdt_wall_cap) if plan.maxdt_wall_cap else trial
            stab += len(SCENARIOS) * (1 if k0 == 1 else 6) * trial
            counts["stability"] += len(SCENARIOS)
            run_eq = plan.equilibrium_duration / dt0 * ms / 1000.0
            run_eq = min(run_eq, plan.equilibrium_wall_cap) if plan.equilibrium_wall_cap else run_eq
            eq += run_eq
            counts["equilibrium"] += 1
            frame = k0 * ms / 1000.0
            one_timing = (3 + plan.windows * max(1.0, math.ceil(plan.window_seconds / max(frame, 1e-9)))) * frame
            timings = len(plan.timing_scenarios) * (1 + len(plan.extra_dt_fractions))
            if n in plan.accuracy_sizes:
                timings += len(plan.timing_scenarios)
                eq += 3 * run_eq  # the static-accurate search and the static run at the accurate dt
                counts["equilibrium"] += 2
                for sc in SCENARIOS:
                    T = plan.transient(sc).duration
                    if k0 > 1:
                        acc += 3 * 60 * T * k0 * ms / 1000.0
                    else:
                        k = min(max(plan.accuracy_k_max, 64), ACCURATE_K_AT_8 * (n / 8) ** 2)
                        # doubling to the first k past the answer (~3 k in all), then bisection
                        # trials of ~k each down to the precision
                        trials_k = 3 + math.log2(0.5 / max(plan.accurate_precision, 0.01))
                        acc += 60 * T * trials_k * k * (ms_small if ms_small is not None else ms) / 1000.0
                    counts["accuracy"] += 1
            tim += timings * one_timing
            counts["timing"] += timings
    for n in plan.accuracy_sizes if plan.grid else []:  # references and floors, once per size (per worker process in parallel)
        for sc in SCENARIOS:
            T = plan.transient(sc).duration
            acc += REFERENCE_S_PER_PARTICLE_S * n * n * T
            k0, ms, _ = costs.get(("rk4", n), (1, 0.0, None))
            acc += 60 * T * 4 * k0 * ms / 1000.0
            counts["accuracy"] += 1
    return [PhaseEstimate("stability (max stable dt)", counts["stability"], stab),
            PhaseEstimate("equilibrium and static accuracy", counts["equilibrium"], eq),
            PhaseEstimate("accuracy (references, floors, searches)", counts["accuracy"], acc),
            PhaseEstimate("timing", counts["timing"], tim)]


def format_estimate(plan: StudyPlan, by_device: dict, workers: int = 1) -> str:
    """The estimate as text: per device, per phase, and in all."""
    lines = [f"estimate of profile {plan.profile}: integrators {', '.join(plan.integrators)}; sizes "
             f"{', '.join(map(str, plan.all_sizes))}; accuracy at {', '.join(map(str, plan.accuracy_sizes)) or 'none'}"]
    total = 0.0
    for d, phases in by_device.items():
        for ph in phases:
            lines.append(f"  {d:6s} {ph.phase:42s} {ph.measurements:4d} measurements  {ph.seconds / 60:7.1f} min")
            total += ph.seconds
    lines.append(f"  total about {total / 60:.0f} min serially" + (f"; the searches split over {workers} workers, the timings not" if workers > 1 else ""))
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else None
    if load is not None:
        lines.append(f"  load average {load:.1f} on {os.cpu_count()} cores while calibrating: other jobs' share is in the per-step costs")
    lines.append("  (a model from per-step costs measured now: see docs/study.md, 'Estimate'; --match-accuracy is not included"
                 + (f"; nor the scenarios {', '.join(plan.scenario_files)}" if plan.scenario_files else "") + ")")
    return "\n".join(lines)


def available_devices(devices: list, stream=None) -> list:
    """The devices of ``devices`` that are present; each missing one is skipped with one line."""
    from warpcloth.sim.device import device_name as resolve_device

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
    for name in ("results.csv", "report.md", "wall_per_sim_second.png"):
        check_output_path(os.path.join(out_dir, name), "study output")
    return os.path.join(out_dir, "results.csv")


def run_study(plan: StudyPlan, out_dir: str, resume: bool = False, overwrite: bool = False, progress=None,
              command: str = "", on_row=None, workers=None, ray=None, timing_workers=None) -> dict:
    """Run ``plan`` into ``out_dir`` (results.csv, report.md, PNG plots). Returns a summary.
    ``workers`` / ``ray`` / ``timing_workers``: see :class:`ParallelSettings` (default serial)."""
    report = progress if progress is not None else sys.stderr
    devices = available_devices(plan.devices, report)
    require(bool(devices), f"none of the devices {', '.join(plan.devices)} is available")
    settings = ParallelSettings.check(devices, workers=workers, ray=ray, timing_workers=timing_workers)
    prepare_out(out_dir)  # checked before connecting to a cluster; nothing written yet
    ray_pool = connect_ray(settings, report)
    try:
        return _run_study(plan, devices, settings, ray_pool, out_dir, resume, overwrite, progress, report, command, on_row)
    finally:
        if ray_pool is not None:
            ray_pool.close()


def _run_study(plan, devices, settings, ray_pool, out_dir, resume, overwrite, progress, report, command, on_row) -> dict:
    from warpcloth.lab.report import write_report

    csv_path = prepare_out(out_dir)
    plan = replace(plan, devices=devices)
    out = StudyCsv(csv_path, resume=resume, overwrite=overwrite, report=progress)
    t0 = time.perf_counter()
    failed = 0
    try:
        if out.note and progress is not None:
            print(out.note, file=progress)
        study = Study(plan, out, progress, on_row)
        if settings.parallel:
            for w in settings.warnings:
                print(f"warpcloth: warning: {w}", file=report, flush=True)
            if progress is not None:
                print(f"warpcloth: study: running {settings.describe()}", file=progress, flush=True)
            failed = run_parallel(study, settings, report, ray_pool)
        else:
            study.run()
    finally:
        out.close()
    files = write_report(out_dir, read_rows(csv_path), plan, command=command, stream=progress)
    return {"measured": study.measured, "reused": study.reused, "wall_s": time.perf_counter() - t0, "files": files,
            "plan": asdict(plan), "failed": failed}


__all__ = ["COLUMNS", "COLUMN_DOCS", "PROFILES", "ParallelSettings", "PhaseEstimate", "calibrate", "estimate_plan", "format_estimate", "Study", "StudyCsv", "StudyPlan", "available_devices",
           "make_plan", "prepare_out", "read_rows", "run_parallel", "run_study", "study_init", "study_job"]
