"""The study's measurements, each made once and written as one row of results.csv
(:data:`~warpcloth.lab.results.COLUMNS`), keyed so that a resumed study reuses it:

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
  float64 equilibrium is computed);
* a fixed-mesh scenario (a file or a registered scenario): max stable dt, time to equilibrium
  and ms/step at it; no accuracy (:data:`~warpcloth.lab.results.MESH_NOTE`).

:meth:`Measurements.group` makes those of one device x integrator x size group.
"""

from __future__ import annotations

import math
import socket
import time

from warpcloth.run.harness import RunHarness
from warpcloth.lab.accuracy import (FRAME_DT, AccuracyProblem, StaticProblem, search_steps_per_frame,
                                    steps_per_frame_at_most)
from warpcloth.lab.plan import SCENARIOS, StudyPlan
from warpcloth.lab.results import MESH_NOTE

#: pbd/xpbd iterations x substeps tried by ``--match-accuracy``, cheapest (iterations x substeps) first.
MATCH_ITERATIONS = (5, 10, 20, 40, 80)
MATCH_SUBSTEPS = (1, 2, 4, 8, 16)


class _Deferred(Exception):
    """A measurement that needs a timing, in the search phase of a parallel study."""


def _options_text(options: dict) -> str:
    return " ".join(f"{k}={v}" for k, v in sorted(options.items()))


class Measurements:
    """The measurements of a :class:`~warpcloth.lab.plan.StudyPlan` made in one process, each
    written once to ``out``: the driver's results.csv (a :class:`~warpcloth.io.results.ResultsFile`
    with ``keep_rows``) or a worker's stand-in with the same ``done`` and ``write``. A key already
    in ``out.done`` is reused, not measured again; the sims and float64 problems that the
    measurements share are built once per process. ``on_row`` is called with each new row.
    """

    def __init__(self, plan: StudyPlan, out, on_row=None):
        import warp as wp

        from warpcloth.version import __version__

        self.plan = plan
        self.out = out
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

    # a group ------------------------------------------------------------------------------------
    def group(self, device: str, integrator: str, n) -> None:
        """The measurements of one device x integrator x size group (``n`` a scenario name: a
        fixed-mesh group), in the order each needs the last."""
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
            self.max_static_accurate_dt(integrator, device, n, stable["sheet"])
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


def _size(n) -> str:
    return "mesh" if n is None else str(n)


__all__ = ["MATCH_ITERATIONS", "MATCH_SUBSTEPS", "Measurements"]
