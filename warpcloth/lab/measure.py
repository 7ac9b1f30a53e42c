"""The study's measurements, each made once and written as one row of results.csv
(:data:`~warpcloth.lab.results.COLUMNS`), keyed so that a resumed study reuses it:

* ``max_stable_dt`` (the swing's sheet): :func:`warpcloth.lab.maxdt.find_max_dt` up to one 60 FPS
  frame, trials as long as the swing's window at that size;
* ``floor`` (per transient x size, shared by the integrators): the float64 reference (its method,
  halving estimate of every metric, step) and the conditioning floor of every metric
  (:meth:`~warpcloth.lab.accuracy.TransientProblem.floor`, :meth:`~warpcloth.lab.accuracy.ContactProblem.floor`);
* ``trial``: one configuration (:mod:`warpcloth.lab.configs`) on one dynamic transient: every
  metric; "not run" only where its ms per frame predicted from the group's ``calibration`` row
  (measured once) exceeds the plan's ``max_frame_ms`` (:meth:`Measurements.trial`): the rows never
  depend on the load at each configuration;
* ``static``: a configuration run to rest on the contact transient: rest shape and sag against the
  float64 equilibrium with the contact, time to equilibrium;
* ``timing``: every configuration that ran finite on both dynamic transients, on the swing's sheet
  from the swing's start: ms/step over ``timing_windows`` windows after a warm-up (compile) and an
  untimed replay (graph capture), median and spread (re-timed above :data:`MAX_SPREAD`);
  ms per 1/60 s frame, wall s per simulated s;
* a fixed-mesh scenario (a file or a registered scenario): max stable dt, time to equilibrium
  and ms/step at it; no accuracy (:data:`~warpcloth.lab.results.MESH_NOTE`).

:meth:`Measurements.group` makes those of one device x integrator x size group. References and
floors are kept in the plan's ``reference_cache`` folder (one file each, made under a lock): the
worker processes of a parallel study and a resumed study compute each once.
"""

from __future__ import annotations

import math
import os
import socket
import time
from dataclasses import replace

import numpy as np
import warp as wp

from warpcloth.integrators import integrator_class, make_integrator
from warpcloth.integrators.pbd import material_bend_stiffness
from warpcloth.lab.accuracy import (
    FRAME_DT,
    METRICS,
    REFERENCE_ESTIMATE_COLUMNS,
    REFERENCE_TOLERANCE,
    ContactProblem,
    Reference,
    TransientProblem,
    steps_per_frame_at_most,
)
from warpcloth.lab.configs import Config, configurations, static_configurations, steps_for, study_options, work
from warpcloth.lab.maxdt import find_max_dt
from warpcloth.lab.plan import StudyPlan
from warpcloth.lab.results import MESH_NOTE
from warpcloth.lab.transients import DYNAMIC, TRANSIENTS
from warpcloth.run.harness import RunHarness, time_steps
from warpcloth.scenarios import get_scenario
from warpcloth.version import __version__

#: A configuration's timing is taken again when its spread across windows, (max - min) / median,
#: exceeds this (another job's burst, not the configuration's cost); at most :data:`RETIMES` times.
MAX_SPREAD = 0.20
RETIMES = 2


def spread_of(ms) -> float:
    """The spread of timed windows: (max - min) / median of ``ms`` (0 for one window)."""
    ms = sorted(float(m) for m in ms)
    med = float(np.median(ms))
    return (ms[-1] - ms[0]) / med if med > 0 else math.inf


class _Deferred(Exception):
    """A measurement that needs a timing, in the search phase of a parallel study."""


def _options_text(options: dict) -> str:
    return " ".join(f"{k}={v}" for k, v in sorted(options.items()))


def _k_text(k) -> str:
    k = float(k)
    return f"{k:g}" if k >= 1 else f"1/{round(1 / k)}"


class _Cache:
    """Files of ``folder`` made once under an exclusive lock (other processes wait, then read)."""

    def __init__(self, folder: str):
        self.folder = folder
        self.memory: dict = {}

    def get(self, name: str, compute):
        """The arrays of ``name`` (a dict of NumPy arrays and scalars), computed by ``compute()`` if
        no process has made them yet."""
        if name in self.memory:
            return self.memory[name]
        if not self.folder:
            self.memory[name] = compute()
            return self.memory[name]
        import fcntl  # noqa: PLC0415 (POSIX only)

        os.makedirs(self.folder, exist_ok=True)
        ignore = os.path.join(self.folder, ".gitignore")
        if not os.path.exists(ignore):  # float64 trajectories (MBs): kept for workers and --resume, not for a commit
            with open(ignore, "w") as fh:
                fh.write("*\n")
        path = os.path.join(self.folder, name + ".npz")
        with open(path + ".lock", "a+") as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)
            try:
                if os.path.exists(path):
                    with np.load(path, allow_pickle=False) as f:
                        out = {k: f[k] for k in f.files}
                else:
                    out = compute()
                    tmp = path + ".tmp.npz"
                    np.savez(tmp, **out)
                    os.replace(tmp, path)
            finally:
                fcntl.flock(lock, fcntl.LOCK_UN)
        self.memory[name] = out
        return out


class Measurements:
    """The measurements of a :class:`~warpcloth.lab.plan.StudyPlan` made in one process, each
    written once to ``out``: the driver's results.csv (a :class:`~warpcloth.io.results.ResultsFile`
    with ``keep_rows``) or a worker's stand-in with the same ``done`` and ``write``. A key already
    in ``out.done`` is reused, not measured again; the sims and float64 problems that the
    measurements share are built once per process. ``on_row`` is called with each new row.
    """

    def __init__(self, plan: StudyPlan, out, on_row=None):
        self.plan = plan
        self.out = out
        self.on_row = on_row  # called with each new row (tests: interrupt after N)
        self.versions = {"warpcloth_version": __version__, "warp_version": wp.config.version}
        self.place = {"host": socket.gethostname(), "worker": "main", "concurrent_runs": 1}
        self.defer_timing = False  # the search phase of a parallel study: timings come later, alone
        self.device_map: dict = {}  # plan device -> the device this process runs it on (a Ray GPU task: cuda:0)
        self.cache = _Cache(plan.reference_cache)
        self._sims: dict = {}
        self._counts: dict = {}  # (scenario, n, device) -> (particles, springs)
        self._problems: dict = {}
        self.measured = 0
        self.reused = 0

    # one measurement, done once ---------------------------------------------------------------
    def once(self, key: str, base: dict, fn) -> dict:
        """The row of ``key``: reused from ``out``, or measured now (``base`` updated with ``fn()``)
        and written."""
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
        self.write(row)
        return self.out.done[key]

    def write(self, row: dict) -> None:
        """Write a new row to ``out`` (counted, and shown to ``on_row``)."""
        self.out.write(row)
        self.measured += 1
        if self.on_row is not None:
            self.on_row(row)

    def _scenario(self, scenario: str):
        for tr in TRANSIENTS.values():
            if tr.scenario.name == scenario:
                return tr.scenario
        return get_scenario(scenario)

    def sim(self, scenario: str, n: int, device: str, integrator: str, options: dict | None = None):
        key = (scenario, n, device)
        sim = self._sims.get(key)
        if sim is None:
            size = {} if n is None else {"rows": n, "cols": n}  # n None: a fixed-mesh scenario
            sim = self._sims[key] = self._scenario(scenario).build(
                **size,
                device=self.device_map.get(device, device),
                integrator=integrator,
                integrator_options=study_options(integrator),
                dt=FRAME_DT,
            )
            self._counts[key] = (sim.model.particle_count, sim.model.spring_count)
        # under the scene's own settings for it, as Scenario.build gives the max-dt search
        opts = self._scenario(scenario).integrator_options(integrator, study_options(integrator, options))
        sim.set_integrator(make_integrator(integrator, **opts), dt=FRAME_DT)
        sim.reset()
        return sim

    def base(
        self,
        measurement: str,
        scenario: str,
        integrator: str,
        device: str,
        n,
        options: dict | None = None,
        transient: str | None = None,
    ) -> dict:
        if (scenario, n, device) not in self._counts:
            self.sim(scenario, n, device, "explicit_euler")
        particles, springs = self._counts[(scenario, n, device)]
        return {
            "measurement": measurement,
            "scenario": scenario,
            "transient": transient,
            "integrator": integrator,
            "options": _options_text(options or {}),
            "device": device,
            "rows": n,
            "cols": n,
            "particles": particles,
            "springs": springs,
        }

    # references and floors (shared by the groups of a size) -------------------------------------
    def problem(self, name: str, n: int, device: str):
        """The :class:`TransientProblem` or :class:`ContactProblem` of transient ``name`` at ``n``,
        its reference from the cache (made once across processes)."""
        key = (name, n, device)
        if key in self._problems:
            return self._problems[key]
        tr = TRANSIENTS[name]
        sim = self.sim(tr.scenario.name, n, device, "explicit_euler")
        if tr.static:
            data = self.cache.get(f"contact_{n}", lambda: self._contact_data(sim, tr))
            prob = ContactProblem(sim, tr, x_eq=data["x_eq"])
        else:
            frames = self.plan.window_frames(name, n)
            data = self.cache.get(f"{name}_{n}_{frames}", lambda: self._dynamic_data(sim, tr, frames))
            ref = Reference(
                data["frames"],
                float(data["estimate"]) if data["estimate"] >= 0 else None,
                bool(data["accepted"]),
                str(data["method"]),
                float(data["dt"]) if data["dt"] > 0 else None,
                tuple(int(c) for c in data["piece_steps"]),
                tuple(float(e) for e in data["estimates"]),
                # a cache file made before the per-metric estimates has none: the pointwise one stands in
                {m: float(data[f"estimate_{m}"]) for m in METRICS if f"estimate_{m}" in data},
            )
            prob = TransientProblem(sim, tr, frames, reference=ref)
        prob.cached = data
        self._problems[key] = prob
        return prob

    @staticmethod
    def _dynamic_data(sim, tr, frames: int) -> dict:
        t0 = time.perf_counter()
        prob = TransientProblem(sim, tr, frames)
        floor = prob.floor(sim)
        r = prob.ref
        return {
            "frames": r.frames,
            "estimate": -1.0 if r.estimate is None else r.estimate,
            "accepted": r.accepted,
            "method": r.method,
            "dt": r.dt or -1.0,
            "piece_steps": np.asarray(r.piece_steps, dtype=np.int64),
            "estimates": np.asarray(r.estimates, dtype=np.float64),
            **{f"estimate_{m}": v for m, v in r.metric_estimates.items()},
            "seconds": time.perf_counter() - t0,
            **{f"floor_{k}": v for k, v in floor.items()},
        }

    @staticmethod
    def _contact_data(sim, tr) -> dict:
        t0 = time.perf_counter()
        prob = ContactProblem(sim, tr)
        floor = prob.floor(sim)
        return {"x_eq": prob.x_eq, "seconds": time.perf_counter() - t0, **{f"floor_{k}": v for k, v in floor.items()}}

    def floor(self, name: str, device: str, n: int) -> dict:
        """The ``floor`` row of transient ``name`` at ``n``: its reference and conditioning floors."""
        tr = TRANSIENTS[name]
        frames = None if tr.static else self.plan.window_frames(name, n)
        key = f"floor|{name}|{device}|{n}" + ("" if frames is None else f"|frames={frames}")

        def run():
            prob = self.problem(name, n, device)
            d = prob.cached
            row = {"reference_s": float(d["seconds"]), "measure_wall_s": float(d["seconds"])}
            if tr.static:
                row.update(
                    reference="Newton+contact",
                    floor_rest_rel=float(d["floor_rest"]),
                    floor_sag_rel=float(d["floor_sag"]),
                    note="float64 equilibrium with the frictionless contact (penalty continuation); the floor: "
                    "solved again from it moved by 1e-7 m (2 seeds)",
                )
            else:
                r = prob.ref
                row.update(
                    reference=r.method,
                    reference_estimate_rel=r.estimate,
                    **{REFERENCE_ESTIMATE_COLUMNS[m]: r.metric_estimates.get(m) for m in METRICS if m != "point"},
                    reference_dt_s=r.dt,
                    transient_s=frames * FRAME_DT,
                    ref_max_strain_rel=prob.shape.max_strain(r.frames),
                    **{
                        f"floor_{k}_rel": float(d[f"floor_{k}"])
                        for k in ("point", "centroid", "patch", "damping", "stretch")
                    },
                )
                if r.method != "DOP853":
                    row["note"] = _acceptance_note(r)
            return row

        return self.once(key, self.base("floor", tr.scenario.name, "reference", device, n, transient=name), run)

    # the measurements ---------------------------------------------------------------------------
    def max_stable_dt(self, scenario: str, integrator: str, device: str, n) -> dict:
        p = self.plan
        base = self.base("max_stable_dt", scenario, integrator, device, n)
        duration = p.maxdt_duration_at(n if n is not None else round(math.sqrt(base["particles"])))
        key = (
            f"max_stable_dt|{scenario}|{integrator}|{device}|{_size(n)}|dur={duration:.6g}"
            f"|prec={p.maxdt_precision}|cap={p.maxdt_wall_cap}"
        )

        def run():
            sc = self._scenario(scenario)
            size = {} if n is None else {"rows": n, "cols": n}
            r = find_max_dt(
                sc,
                sc.config(
                    **size,
                    integrator=integrator,
                    integrator_options=study_options(integrator),
                    device=self.device_map.get(device, device),
                ),
                precision=p.maxdt_precision,
                duration=duration,
                dt_max=FRAME_DT,
                wall_cap=p.maxdt_wall_cap,
            )
            note = r.no_stable_reason or (
                "stable up to the search limit (one 60 FPS frame)" if r.limit_reached and r.dt else ""
            )
            if r.inconclusive_trials:
                note = (
                    note + "; " if note else ""
                ) + f"{r.inconclusive_trials} trials stopped by the wall cap (counted stable)"
            return {
                "dt_s": r.dt,
                "bound_dt_s": r.unstable_dt,
                "search_bounded": r.limit_reached,
                "max_strain_rel": r.max_strain,
                "stable": r.dt is not None,
                "trials": len(r.trials),
                "transient_s": duration,
                "note": note,
            }

        return self.once(key, base, run)

    def calibration(self, device: str, integrator: str, n: int) -> dict:
        """The group's speed, measured once (as ``warpcloth study --estimate`` does): ms/step of the
        swing's sheet at ``integrator``'s default options and dt (one frame at most), the fastest
        of 3 windows of about 30 ms. The plan's "not run" rule reads it (:meth:`trial`)."""
        scenario = TRANSIENTS["swing"].scenario.name
        key = f"calibration|{scenario}|{integrator}|{device}|{n}"

        def run():
            sim = self.sim(scenario, n, device, integrator)
            k0 = steps_for(min(sim.integrator.default_dt(sim.model, sim.control.drag_rate), FRAME_DT))
            sim.set_dt(FRAME_DT / k0)
            t = time_steps(sim, windows=3, window_seconds=0.03, batch=min(k0, 20))
            ms = min(t.ms_per_step)
            return {
                "dt_s": FRAME_DT / k0,
                "steps_per_frame": k0,
                "ms_per_step_min": ms,
                "ms_per_frame": ms * k0,
                "timed_windows": len(t.ms_per_step),
                "note": "calibration: the fastest of 3 windows at the default options and dt; a configuration "
                "predicted from it above the plan's ms per frame is not run",
            }

        return self.once(key, self.base("calibration", scenario, integrator, device, n), run)

    def predicted_ms_per_frame(self, c: Config, device: str, n: int) -> float:
        """``c``'s cost per 1/60 s frame [ms] predicted from the group's :meth:`calibration`."""
        return (
            self.calibration(device, c.integrator, n)["ms_per_step_min"]
            * work(c.integrator, c.option_dict)
            * float(c.k)
        )

    def trial(self, name: str, c: Config, device: str, n: int) -> dict:
        """The metrics of configuration ``c`` on dynamic transient ``name`` at ``n``
        (:func:`~warpcloth.lab.accuracy.trajectory_metrics`). Not run where its cost per 1/60 s
        frame predicted from the group's :meth:`calibration` (ms/step at the integrator's defaults
        x :func:`~warpcloth.lab.configs.work` x steps per frame) exceeds the plan's
        ``max_frame_ms``: a function of the profile and that stated calibration; a run still going
        at twice the plan's ``run_wall_cap`` is stopped (its row says so)."""
        p = self.plan
        tr = TRANSIENTS[name]
        frames = p.window_frames(name, n)
        key = f"trial|{name}|{c.integrator}|{c.options_text()}|{device}|{n}|frames={frames}|k={_k_text(c.k)}"
        opts = c.option_dict

        def run():
            out = {
                "dt_s": c.dt,
                "steps_per_frame": float(c.k),
                "transient_s": frames * FRAME_DT,
                "iterations": opts.get("iterations"),
                "substeps": opts.get("substeps"),
            }
            if p.max_frame_ms is not None:
                per_frame = self.predicted_ms_per_frame(c, device, n)
                if per_frame > p.max_frame_ms:
                    return {
                        **out,
                        "note": f"not run: predicted {per_frame:.3g} ms per 1/60 s frame from the calibration "
                        f"> {p.max_frame_ms:g} ms",
                    }
            prob = self.problem(name, n, device)  # first: building it rebinds the cached sim's integrator
            sim = self.sim(tr.scenario.name, n, device, c.integrator, opts)
            sim.integrator.reset_stats()  # this trial's capped solves only
            r = prob.measure(sim, float(c.k), wall_cap=2.0 * p.run_wall_cap)
            capped = sim.integrator.capped_steps(sim.integrator.stats())  # a capped trial is no measurement
            m = {} if capped else r.metrics or {}
            return {
                **out,
                "stable": r.stable,
                "error_rel": m.get("point", math.inf if not r.stable else None),
                "centroid_error_rel": m.get("centroid"),
                "patch_error_rel": m.get("patch"),
                "damping_rel": m.get("damping"),
                "max_strain_rel": m.get("stretch"),
                "ref_max_strain_rel": m.get("stretch_ref"),
                "strain_excess_rel": m.get("stretch_excess"),
                "note": f"capped: the solve stopped at its iteration cap in {capped} steps (no measurement)"
                if capped
                else r.note,
                "measure_wall_s": r.wall,
            }

        return self.once(key, self.base("trial", tr.scenario.name, c.integrator, device, n, opts, transient=name), run)

    def static(self, c: Config, device: str, n: int) -> dict:
        """Configuration ``c`` run to rest on the contact transient."""
        p = self.plan
        tr = TRANSIENTS["contact"]
        key = (
            f"static|contact|{c.integrator}|{c.options_text()}|{device}|{n}|k={_k_text(c.k)}"
            f"|dur={p.equilibrium_duration}|cap={p.equilibrium_wall_cap}"
        )
        opts = c.option_dict

        def run():
            prob = self.problem("contact", n, device)
            sim = self.sim(tr.scenario.name, n, device, c.integrator, opts)
            s = prob.measure(sim, float(c.k), p.equilibrium_duration, p.equilibrium_wall_cap)
            return {
                "dt_s": c.dt,
                "steps_per_frame": float(c.k),
                "equilibrium_reached": s.equilibrium_reached,
                "stable": s.stable,
                "time_to_equilibrium_sim_s": s.time_to_equilibrium,
                "time_to_equilibrium_wall_s": s.time_to_equilibrium_wall,
                "static_error_rel": s.error,
                "sag_error_rel": s.sag_error,
                "error_rel": s.error,
                "note": ""
                if s.equilibrium_reached
                else f"not at rest after {s.sim_time:.3g} s simulated "
                f"(cap {p.equilibrium_duration:g} s or {p.equilibrium_wall_cap} s wall)",
            }

        return self.once(
            key, self.base("static", tr.scenario.name, c.integrator, device, n, opts, transient="contact"), run
        )

    def timing(
        self,
        scenario: str,
        integrator: str,
        device: str,
        n,
        dt: float,
        label: str,
        options: dict | None = None,
        start=None,
    ) -> dict:
        """ms/step of ``integrator`` with ``options`` at ``dt`` on ``scenario`` (from ``start``, a
        transient whose start state the timed steps begin at; None: the rest shape)."""
        p = self.plan
        opt = _options_text(options or {})
        key = (
            f"timing|{scenario}|{integrator}|{opt}|{device}|{_size(n)}|{label}|dt={dt!r}"
            f"|w={p.timing_windows}x{p.window_seconds}"
        )

        if self.defer_timing and key not in self.out.done:
            return {}

        def run():
            sim = self.sim(scenario, n, device, integrator, options)
            sim.set_dt(dt)
            if start is not None:
                x0 = start.start(sim.model).astype(np.float32)
                sim.state.particle_q.assign(wp.array(x0, dtype=wp.vec3, device=sim.model.device))
            steps_frame = max(1, math.ceil(FRAME_DT / dt - 1e-9))
            # compile and the first replay (graph capture) excluded; windows replay the frame's steps
            t = time_steps(sim, windows=p.timing_windows, window_seconds=p.window_seconds, batch=steps_frame)
            retimed = 0
            while spread_of(t.ms_per_step) > MAX_SPREAD and retimed < RETIMES:
                again = time_steps(sim, windows=p.timing_windows, window_seconds=p.window_seconds, batch=steps_frame)
                retimed += 1
                if spread_of(again.ms_per_step) < spread_of(t.ms_per_step):
                    t = again
            ms = t.ms_per_step
            med = t.median_ms
            cost = t.wall_s_per_sim_s
            return {
                "dt_s": dt,
                "steps_per_frame": FRAME_DT / dt,
                "ms_per_step_median": med,
                "ms_per_step_min": min(ms),
                "ms_per_step_max": max(ms),
                "timed_windows": len(ms),
                "steps_per_window": t.steps_per_window,
                "ms_per_frame": med * FRAME_DT / dt,
                "wall_s_per_sim_s": cost,
                "realtime_factor": 1.0 / cost,
                "realtime_30fps": t.realtime(30.0),
                "realtime_60fps": t.realtime(60.0),
                "timing_spread_rel": spread_of(ms),
                "retimed": retimed,
                "note": f"at the {label} dt",
                "iterations": (options or {}).get("iterations"),
                "substeps": (options or {}).get("substeps"),
            }

        return self.once(key, self.base("timing", scenario, integrator, device, n, options), run)

    def settle(self, scenario: str, integrator: str, device: str, k: int) -> dict:
        """A fixed-mesh scenario run from its start at dt = frame/k until at rest (or the caps):
        time to equilibrium and max strain. No float64 reference: no static error."""
        p = self.plan
        key = (
            f"static|{scenario}|{integrator}||{device}|mesh|k={k}|dur={p.equilibrium_duration}"
            f"|cap={p.equilibrium_wall_cap}"
        )

        def run():
            sim = self.sim(scenario, None, device, integrator)
            dt = FRAME_DT / k
            sim.set_dt(dt)
            r = RunHarness(sim).run(p.equilibrium_duration, stop_at_equilibrium=True, wall_cap=p.equilibrium_wall_cap)
            return {
                "dt_s": dt,
                "steps_per_frame": k,
                "equilibrium_reached": r.equilibrium_reached,
                "stable": r.stable,
                "time_to_equilibrium_sim_s": r.time_to_equilibrium,
                "time_to_equilibrium_wall_s": r.time_to_equilibrium_wall,
                "max_strain_rel": r.max_strain,
                "note": MESH_NOTE,
            }

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

    # a group ------------------------------------------------------------------------------------
    def configs(self, device: str, integrator: str, n: int) -> tuple[list, float | None]:
        """The configurations of ``integrator`` at ``n`` and the max stable dt they start from:
        the swing's sheet's (the flag's has been larger at every size measured; a configuration
        beyond it on the flag is recorded unstable there)."""
        dt = self.max_stable_dt(TRANSIENTS["swing"].scenario.name, integrator, device, n)["dt_s"]
        return self.material(configurations(integrator, dt, self.plan.level, n), device, n), dt

    def material(self, configs: list, device: str, n: int) -> list:
        """``configs`` with the study's material where a scheme's options would replace it: pbd's
        bend stiffness (``study_bend_from_material``) mapped from the swing sheet's bend springs at
        each configuration's substep (:func:`~warpcloth.integrators.pbd.material_bend_stiffness`),
        written into the options (rows, labels and ``warpcloth run`` flags carry it)."""
        out = []
        for c in configs:
            cls = integrator_class(c.integrator)
            if not getattr(cls, "study_bend_from_material", False) or "pbd_bend_stiffness" in c.option_dict:
                out.append(c)
                continue
            model = self.sim(TRANSIENTS["swing"].scenario.name, n, device, "explicit_euler").model
            opts = {**cls.option_defaults(), **c.option_dict}
            k = material_bend_stiffness(model, c.dt / opts["substeps"])
            out.append(replace(c, options=tuple(sorted({**c.option_dict, "pbd_bend_stiffness": k}.items()))))
        return out

    def group(self, device: str, integrator: str, n) -> None:
        """The measurements of one device x integrator x size group (``n`` a scenario name: a
        fixed-mesh group), in the order each needs the last."""
        if isinstance(n, str):  # a fixed-mesh scenario's group
            return self.mesh_group(device, integrator, n)
        configs, stable_dt = self.configs(device, integrator, n)
        contact = n <= self.plan.contact_max_size
        for name in TRANSIENTS:
            if contact or not TRANSIENTS[name].static:
                self.floor(name, device, n)
        ran = []
        for c in configs:
            rows = [self.trial(name, c, device, n) for name in DYNAMIC]
            # timed when any transient ran it stably: where a transient's floor refuses its verdict
            # (the flag from 64x64) the size is judged on the others alone, so a configuration the
            # flag's caps skipped can still be the answer there
            if any(r.get("stable") and r.get("error_rel") is not None for r in rows):
                ran.append(c)
        statics = self.material(static_configurations(integrator, stable_dt), device, n) if contact else []
        for c in statics:
            self.static(c, device, n)
        for c in dict.fromkeys(ran + statics):
            self.timing(
                TRANSIENTS["swing"].scenario.name,
                integrator,
                device,
                n,
                c.dt,
                "configuration",
                c.option_dict,
                start=TRANSIENTS["swing"],
            )


def _acceptance_note(r: Reference) -> str:
    """A Warp reference's acceptance per metric, for a ``floor`` row's note."""
    pointwise = ", ".join(f"{e:.2g}" for e in r.estimates)
    refused = [m for m in METRICS if not r.accepted_for(m)]
    if not refused:
        return f"halving estimates {pointwise}; accepted for every metric"
    accepted = [m for m in METRICS if r.accepted_for(m)]
    estimates = ", ".join(f"{m} {r.estimate_of(m):.2g}" for m in refused)
    return (
        f"halving estimates {pointwise} x size; not accepted for {estimates} (> {REFERENCE_TOLERANCE:g}): "
        "those verdicts refused"
        + (f"; accepted for {', '.join(accepted)}" if accepted else "; accepted for no metric: every verdict refused")
    )


def _size(n) -> str:
    return "mesh" if n is None else str(n)


__all__ = ["MAX_SPREAD", "RETIMES", "Measurements", "spread_of"]
