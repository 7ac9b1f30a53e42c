"""The run harness: frames, timing, metrics, verdicts and outputs above the stepping core.

A :class:`~warpcloth.simulator.Simulator` steps (``step``, ``simulate``); :class:`RunHarness`
runs it for a simulated duration (seed 3.2.2): forces are computed every time step ``dt``,
frames are sampled every ``1/fps`` seconds of simulated time, metrics are reduced on the device
and read once per frame, and the verdicts (stable, equilibrium) are made here, by the settings
the harness holds (what "stable" means belongs to the experiment, not to the stepping core). A
run returns a :class:`RunResult` that serialises to JSON. Frame outputs (USD, HTML, previews)
are sinks the caller hands in: this layer writes no file.

The timing helpers (:class:`Stopwatch`, :func:`time_steps`) are the one way warpcloth times
steps: the run loop, the benchmark, the max-dt search and the study use them, so "ms/step"
means the same everywhere (kernel time after warm-up; compile and graph capture apart).
"""

from __future__ import annotations

import json
import math
import statistics
import time
from dataclasses import asdict, dataclass, field

import numpy as np
import warp as wp

from warpcloth.errors import WarpclothError, require_count, require_positive, warn
from warpcloth.run.metrics import (
    DEFAULT_INSTABILITY_STRAIN,
    EnergyCriteria,
    EnergyMonitor,
    EquilibriumCriteria,
    EquilibriumDetector,
    FrameMetrics,
    MetricsProbe,
    wind_power_bound,
)
from warpcloth.sim.colliders import box_edge_distance, describe, signed_distance
from warpcloth.sim.contacts import starting_inside
from warpcloth.version import __version__

#: Most steps one run may take (a larger count is a typo in dt or duration, not an experiment).
MAX_RUN_STEPS = 10**12
#: A frame may be at most this many times shorter than a step (frames shorter than a step are
#: sampled once per step anyway).
MAX_FRAMES_PER_STEP = 1000.0
#: The wall cap is checked after chunks of steps of about this many wall seconds.
CHUNK_SECONDS = 0.2


# -- timing ----------------------------------------------------------------------------------
class Stopwatch:
    """Time of a block of launches on ``device``, synchronised at both ends::

        with Stopwatch(device) as watch:
            sim.simulate(n)
        watch.seconds

    On a CPU device it reads the calling thread's CPU time (``time.thread_time``): Warp's CPU
    backend runs each kernel on the calling thread, so on a quiet machine this equals the wall
    time, and on a shared one other jobs' share of the cores does not count (docs/study.md,
    "Timings"). On a CUDA device (or none) it reads the wall clock after synchronising.
    """

    def __init__(self, device=None):
        self.device = device
        self.seconds = 0.0
        self.clock = time.thread_time if device is not None and wp.get_device(device).is_cpu else time.perf_counter

    def __enter__(self):
        if self.device is not None:
            wp.synchronize_device(self.device)
        self._t0 = self.clock()
        return self

    def __exit__(self, *exc):
        if self.device is not None:
            wp.synchronize_device(self.device)
        self.seconds = self.clock() - self._t0
        return False


@dataclass
class StepTiming:
    """ms/step of a simulator over timed windows (warm-up and first replay excluded)."""

    dt: float
    steps_per_window: int
    ms_per_step: list  # one entry per timed window
    compile_s: float = 0.0
    steps_timed: int | None = None  # every timed step (None: steps_per_window x windows)

    @property
    def median_ms(self) -> float:
        return statistics.median(self.ms_per_step)

    @property
    def min_ms(self) -> float:
        return min(self.ms_per_step)

    @property
    def max_ms(self) -> float:
        return max(self.ms_per_step)

    @property
    def steps(self) -> int:
        return self.steps_timed if self.steps_timed is not None else self.steps_per_window * len(self.ms_per_step)

    @property
    def wall_s_per_sim_s(self) -> float:
        """Cost per simulated second: wall seconds per step / dt (from the median)."""
        return self.median_ms / 1000.0 / self.dt

    @property
    def realtime_factor(self) -> float:
        return 1.0 / self.wall_s_per_sim_s

    def realtime(self, fps: float) -> bool:
        """Whether the steps of one 1/fps s frame take at most 1/fps s of wall time."""
        steps = math.ceil((1.0 / fps) / self.dt - 1e-9)
        return steps * self.median_ms / 1000.0 <= 1.0 / fps


def time_steps(
    sim,
    windows: int = 5,
    window_seconds: float = 0.1,
    batch: int | None = None,
    steps: int | None = None,
    warm_up: bool = True,
) -> StepTiming:
    """Time ``sim``'s steps: a warm-up (compile; its seconds in ``compile_s``), one untimed
    replay of each step count timed (first launches, graph capture), then ``windows`` timed
    windows.

    Args:
        windows: timed windows (>= 1); the median and the spread come from them.
        window_seconds: each window replays whole batches until it lasts about this long.
        batch: steps per replay (default one 60 Hz frame of steps, at least 1, so a captured
            graph is replayed as it is in a run; where a frame's steps outlast a window, as many
            whole graph chunks as fit in it, at least one).
        steps: instead of ``window_seconds``: time exactly this many steps in all, split evenly
            over the windows (each window one replay of its share; at most ``steps`` windows).
        warm_up: compile first (skip when the caller already did).
    """
    windows = require_count("windows", windows)
    if windows < 1:
        raise WarpclothError(f"windows must be >= 1, got {windows}")
    device = sim.model.device
    compile_s = sim.warm_up() if warm_up else 0.0
    if steps is not None:
        steps = require_count("steps", steps)
        if steps < windows:
            raise WarpclothError(f"steps ({steps}) must be at least windows ({windows}): one step a window")
        shares = [steps // windows + (1 if k < steps % windows else 0) for k in range(windows)]
        for n in sorted(set(shares)):
            sim.simulate(n)  # first launches / graph capture of each count: excluded
        sim.integrator.reset_stats()
        ms = []
        for n in shares:
            with Stopwatch(device) as watch:
                sim.simulate(n)
            ms.append(1000.0 * watch.seconds / n)
        return StepTiming(
            dt=sim.dt, steps_per_window=steps // windows, ms_per_step=ms, compile_s=compile_s, steps_timed=steps
        )
    if batch is None:
        batch = max(1, math.ceil((1.0 / 60.0) / sim.dt - 1e-9))
        chunk = min(batch, sim.chunk_steps())
        if chunk < batch:  # a frame of many steps: does it fit in a window? (one chunk timed to see)
            sim.simulate(chunk)  # first launches / graph capture: excluded
            with Stopwatch(device) as watch:
                sim.simulate(chunk)
            fit = int(window_seconds / max(watch.seconds / chunk, 1e-9))
            batch = batch if fit >= batch else max(chunk, fit // chunk * chunk)
    sim.simulate(batch)  # first launches / graph capture: excluded
    with Stopwatch(device) as watch:
        sim.simulate(batch)
    per_step = max(watch.seconds / batch, 1e-9)
    replays = max(1, math.ceil(window_seconds / (per_step * batch)))
    sim.integrator.reset_stats()
    ms = []
    for _ in range(windows):
        with Stopwatch(device) as watch:
            for _ in range(replays):
                sim.simulate(batch)
        ms.append(1000.0 * watch.seconds / (replays * batch))
    return StepTiming(dt=sim.dt, steps_per_window=replays * batch, ms_per_step=ms, compile_s=compile_s)


# -- results ---------------------------------------------------------------------------------
@dataclass
class RunResult:
    """Outcome and measurements of one run (SI units; times in seconds unless named ``_ms``)."""

    scenario: str
    integrator: str
    device: str
    rows: int
    cols: int
    particles: int
    springs: int
    dt: float
    fps: float
    #: the cloth's triangles (a mesh's summary names them: a mesh has no rows and columns)
    triangles: int = 0
    steps: int = 0
    frames: int = 0
    sim_time: float = 0.0
    wall_time: float = 0.0
    compile_time: float = 0.0
    capture_time: float = 0.0
    integration_time: float = 0.0
    other_time: float = 0.0
    export_time: float = 0.0
    ms_per_step: float = 0.0
    steps_per_sec: float = 0.0
    realtime_factor: float = 0.0
    stable: bool = True
    unstable_reason: str = ""
    unstable_time: float | None = None
    equilibrium_reached: bool = False
    time_to_equilibrium: float | None = None
    time_to_equilibrium_wall: float | None = None
    equilibrium_criterion: str = "speed+force"
    force_floor: float = 0.0
    max_strain: float = 0.0
    instability_strain: float = DEFAULT_INSTABILITY_STRAIN
    final_max_speed: float = 0.0
    wall_cap_reached: bool = False
    graph: bool = False
    solver: dict = field(default_factory=dict)
    #: False when the integrator's iterative solver missed its own tolerance in at least one
    #: step; None where not applicable (no iterative solver with a tolerance).
    solver_converged: bool | None = None
    #: Steps whose solve ended above its tolerance for any reason (at its iteration cap, or a true
    #: residual under the float32 floor): the count behind ``solver_converged``.
    solver_capped_steps: int = 0
    #: Steps whose solve stopped at its iteration cap above its tolerance (implicit_euler's CG at
    #: ``cg_max_iter``, whatever its preconditioner; schemes with a fixed iteration count and no
    #: tolerance, projective, vbd, xpbd, have no cap: 0), counted on the device.
    capped_steps: int = 0
    #: Steps in which the strain limit applied after the step moved a particle (a spring was longer
    #: than (1 + tau) L0 after the integrator's step), counted on the device, and which limit it was:
    #: ``"strain_cap"`` (the integrator's own, implicit_euler's ``strain_cap``, 10 % by default),
    #: ``"strain_limit"`` (the user's ``--strain-limit``) or ``""`` (none applied).
    strain_capped_steps: int = 0
    strain_limit_source: str = ""
    strain_limit_tau: float | None = None
    #: Steps whose strain-limit passes stopped at their cap (the limit perhaps not met).
    strain_limit_pass_capped_steps: int = 0
    #: Why this run is not a measurement of its model, with the settings that fix it ("" where it is):
    #: its solve stopped at an iteration cap, or the integrator's own strain cap engaged (either makes
    #: the steps the solver's, not the model's). A strain limit the user set is part of the model asked
    #: for: its engaging is counted (``strain_capped_steps``), not a cause.
    capped_cause: str = ""
    #: Self-collision's counters over the run (:meth:`SelfCollision.stats
    #: <warpcloth.sim.self_collision.SelfCollision.stats>`: contacts, rebuilds, ``overflow_candidates`` and
    #: ``overflow_contacts`` (pairs that did not fit its lists), ``truncated_queries``, ``fast``,
    #: ``unresolved``, and the continuous response's ``ccd_collisions``, ``ccd_rollbacks``, ``ccd_unresolved``);
    #: empty with self-collision off. A run whose lists overflowed, or that left pairs crossing, also warns on
    #: stderr.
    self_collision: dict = field(default_factory=dict)
    #: What the scenario measured at the end (a textile test's reading, a fold count; Scenario.measure).
    measurements: dict = field(default_factory=dict)
    warpcloth_version: str = __version__
    warp_version: str = wp.config.version

    @property
    def integration_ms_mean(self) -> float:
        """Mean integration time per frame [ms]."""
        return 1000.0 * self.integration_time / self.frames if self.frames else 0.0

    @property
    def other_ms_mean(self) -> float:
        """Mean time per frame outside integration (metrics, export, bookkeeping) [ms]."""
        return 1000.0 * self.other_time / self.frames if self.frames else 0.0

    @property
    def frames_per_sec(self) -> float:
        """Frames of 1/fps simulated seconds produced per wall second."""
        return self.realtime_factor * self.fps

    def refusal(self, what: str) -> dict | None:
        """What a scenario's measurement of ``what`` (a bending length, a drape coefficient) reports
        instead of it where :attr:`capped_cause` names one: ``refused`` (no ``what`` from this run,
        the cause and the fix) and the counts; None where the run is a measurement."""
        if not self.capped_cause:
            return None
        return {
            "refused": f"no {what} from this run: {self.capped_cause}",
            "capped_steps": self.capped_steps,
            "strain_capped_steps": self.strain_capped_steps,
            "steps": self.steps,
        }

    def to_dict(self) -> dict:
        d = asdict(self)
        d["integration_ms_mean"] = self.integration_ms_mean
        d["other_ms_mean"] = self.other_ms_mean
        d["frames_per_sec"] = self.frames_per_sec
        return d

    def to_json(self, **kwargs) -> str:
        return json.dumps(self.to_dict(), **kwargs)


def _unstable_cause(sim, inside: list) -> str:
    """Why a run most likely went unstable, in words, for its summary."""
    if inside:
        k, what, count = inside[0]
        return f"{count} vertices started inside collider {k} ({what}): move the cloth out of it"
    return (
        f"the likeliest cause is the time step: dt = {sim.dt:.3g} s for {sim.integrator.name} on this cloth; "
        f"try a smaller --dt (warpcloth max-dt finds the largest stable one) or another integrator"
    )


def _capped_cause(sim, result: RunResult) -> str:
    """:attr:`RunResult.capped_cause`: the iteration-capped steps and the integrator's strain-cap steps
    of ``result``, and the settings that fix them (the integrator's :meth:`cap_advice
    <warpcloth.integrators.base.Integrator.cap_advice>`, a smaller dt, the cap off); "" where none."""
    name, steps = result.integrator, result.steps
    causes, fixes = [], [f"a smaller --dt (now {result.dt:.3g} s)"]
    if result.capped_steps:
        causes.append(f"{name}'s solve stopped at its iteration cap in {result.capped_steps} of {steps} steps")
        fixes += sim.integrator.cap_advice()
    if result.strain_capped_steps and result.strain_limit_source == "strain_cap":
        causes.append(
            f"{name}'s {100 * result.strain_limit_tau:g} % strain cap engaged in {result.strain_capped_steps} of "
            f"{steps} steps"
        )
        fixes.append("--strain-cap 0 (the model's own stretch, where the solve converges)")
    if not causes:
        return ""
    return " and ".join(causes) + "; fix: " + ", or ".join(fixes)


class RunHarness:
    """Runs a :class:`~warpcloth.simulator.Simulator` for a simulated duration: frames, metrics,
    verdicts (unstable, equilibrium), timing and frame sinks (USD, HTML, ...)::

        harness = RunHarness(sim, instability_strain=0.5)
        result = harness.run(duration=5.0, stop_at_equilibrium=True)

    Args:
        sim: the :class:`~warpcloth.simulator.Simulator` to run (it may be stepped between runs).
        scenario: a name carried into results.
        instability_strain: a spring stretched past (1 + this) x its rest length is unstable
            (default :data:`~warpcloth.run.metrics.DEFAULT_INSTABILITY_STRAIN`).
        equilibrium: tolerances of the equilibrium test (:class:`~warpcloth.run.metrics.EquilibriumCriteria`).
        energy: when growing energy counts as unstable (:class:`~warpcloth.run.metrics.EnergyCriteria`).
    """

    def __init__(
        self,
        sim,
        scenario: str = "custom",
        instability_strain: float = DEFAULT_INSTABILITY_STRAIN,
        equilibrium: EquilibriumCriteria | None = None,
        energy: EnergyCriteria | None = None,
    ):
        if not callable(getattr(sim, "simulate", None)) or not hasattr(sim, "model"):
            raise WarpclothError(f"RunHarness needs a warpcloth.Simulator, got {sim!r:.80}")
        if equilibrium is not None and not isinstance(equilibrium, EquilibriumCriteria):
            raise WarpclothError(f"equilibrium must be an EquilibriumCriteria or None, got {equilibrium!r:.80}")
        if energy is not None and not isinstance(energy, EnergyCriteria):
            raise WarpclothError(f"energy must be an EnergyCriteria or None, got {energy!r:.80}")
        self.sim = sim
        self.scenario = str(scenario)
        self.instability_strain = require_positive("instability strain", instability_strain)
        self.equilibrium = equilibrium or EquilibriumCriteria()
        self.energy_criteria = energy or EnergyCriteria()
        self._probe, self._probe_version = None, None
        self._metrics_warmed = False
        self._step_seconds: dict = {}  # wall seconds of one step, by the simulator's step_version

    @property
    def probe(self) -> MetricsProbe:
        """The metrics of the simulator's current model (rebuilt after ``sim.set_model``)."""
        if self._probe is None or self._probe_version != self.sim.model_version:
            self._probe, self._probe_version = MetricsProbe(self.sim.model, self.sim.control), self.sim.model_version
        return self._probe

    def measure(self) -> FrameMetrics:
        """Metrics of the current state (one small read from the device)."""
        sim = self.sim
        # with colliders the net force of a resting particle is balanced by a contact the metric
        # does not see: equilibrium is then judged by speed alone (as for position-based schemes)
        return self.probe.measure(sim.state, with_force=sim.integrator.force_based and sim.control.collision is None)

    def energy(self) -> float:
        """Total mechanical energy of the current state [J]."""
        return self.probe.energy(self.sim.state)

    def run(
        self,
        duration: float,
        fps: float = 60.0,
        stop_at_equilibrium: bool = False,
        wall_cap: float | None = None,
        frames=None,
        warm_up: bool = True,
        resumed_steps: int = 0,
        **unknown,
    ) -> RunResult:
        """Run for ``duration`` seconds of simulated time, sampling a frame every 1/fps s.

        Args:
            duration: simulated time [s].
            fps: frame rate of sampling (metrics, USD frames) [1/s].
            stop_at_equilibrium: end the run when equilibrium is confirmed.
            wall_cap: stop after this many wall-clock seconds (None: no cap). It is checked
                between chunks of about 0.2 s of steps, so it bounds the run's wall time
                whatever the number of steps per frame.
            frames: a frame sink that receives every frame, ``write_frame(points, sim_time)``
                (a :class:`~warpcloth.io.usd.UsdWriter`, :class:`~warpcloth.io.frames.FrameSinks`, ...;
                the caller closes it), or None.
            warm_up: compile kernels before timing (:meth:`Simulator.warm_up
                <warpcloth.simulator.Simulator.warm_up>` and the metrics' kernels).
            resumed_steps: steps of this run taken before this call, by a run whose state the
                simulator was restored to (:meth:`Simulator.restore
                <warpcloth.simulator.Simulator.restore>`, a checkpoint): the run still ends
                ``ceil(duration / dt)`` steps from its start and its frames fall where the
                uninterrupted run's did, so its steps are that run's, bit for bit. The verdicts'
                windows (equilibrium, energy) and the result's counts start at this call.

        A run that goes unstable stops there and is recorded as unstable; it never raises.
        Graph capture time is reported apart (``capture_time``) and excluded from ms/step.
        """
        if unknown:
            raise WarpclothError(
                f"RunHarness.run got an unknown keyword {sorted(unknown)[0]!r}; its keywords are duration, fps, "
                "stop_at_equilibrium, wall_cap, frames, warm_up, resumed_steps"
            )
        duration = require_positive("duration", duration, "s")
        fps = require_positive("fps", fps, "1/s")
        if wall_cap is not None:
            wall_cap = require_positive("wall cap", wall_cap, "s")
        resumed_steps = require_count("resumed steps", resumed_steps)
        sim = self.sim
        m, dt = sim.model, sim.dt
        check_run_length(duration, fps, dt)
        if frames is not None and not callable(getattr(frames, "write_frame", None)):
            raise WarpclothError(
                f"frames must be a frame sink with write_frame(points, sim_time) or None, got {frames!r:.80}"
            )
        result = RunResult(
            scenario=self.scenario,
            integrator=sim.integrator.name,
            device=str(m.device),
            rows=m.rows,
            cols=m.cols,
            particles=m.particle_count,
            springs=m.spring_count,
            triangles=m.tri_count,
            dt=dt,
            fps=fps,
            equilibrium_criterion="speed+force"
            if sim.integrator.force_based and sim.control.collision is None
            else "speed",
            graph=sim.graph_enabled,
            instability_strain=self.instability_strain,
        )
        if warm_up and not sim.warmed:  # once: a warm-up restarts the integrator's history
            result.compile_time = sim.warm_up()
        limiter = sim.active_limiter
        if limiter is not None:
            limiter.reset_stats()  # this run's steps only (not the warm-up's, nor earlier steps')
        if warm_up and not self._metrics_warmed:  # the metrics' kernels compile outside the timing too
            t0 = time.perf_counter()
            self.measure()
            self.probe.energies(sim.state)
            self._metrics_warmed = True
            result.compile_time += time.perf_counter() - t0
        detector = EquilibriumDetector(self.equilibrium, self.probe.force_floor)
        result.force_floor = self.probe.force_floor
        start_steps, start_time = sim.steps, sim.sim_time
        start_capture = sim.capture_time
        total_steps = max(1, math.ceil(duration / dt - 1e-9))
        frame_dt = 1.0 / fps
        steps_per_frame = frame_dt / dt
        e0, _ = self.probe.energies(sim.state)

        def energy_monitor(e_start: float) -> EnergyMonitor:
            return EnergyMonitor(
                e_start,
                wind_power_bound(m, sim.control, self.instability_strain),
                window_frames=max(
                    math.ceil(self.energy_criteria.window_time * fps - 1e-9),
                    math.ceil(self.energy_criteria.window_steps / max(1.0, steps_per_frame) - 1e-9),
                ),
                scale=m.total_mass * sim.control.gravity_magnitude * max(m.width, m.height, 1e-3),
                criteria=self.energy_criteria,
            )

        energy, energy_start = energy_monitor(e0), start_time
        # moving kinematic pins do work no a-priori bound knows: the energy criterion waits until
        # they stop and starts from the energy then (non-finite state and strain still apply)
        pins_move_until = sim.pins_moving_until()
        inside = self._check_start(sim)
        if frames is not None:
            t0 = time.perf_counter()
            frames.write_frame(sim.state.particle_q.numpy(), sim.sim_time)
            result.export_time += time.perf_counter() - t0

        loop_start = time.perf_counter()
        frame = 0
        done = resumed_steps  # the next frame follows from it (below)
        while done < total_steps:
            # the next frame that needs a step (frames shorter than a step are skipped at once)
            frame = max(frame + 1, math.floor((done + 1e-9) / steps_per_frame) + 1)
            target = min(total_steps, math.ceil(frame * steps_per_frame - 1e-9))
            n = target - done
            if n <= 0:
                continue
            t0 = time.perf_counter()
            capped = self._advance(n, loop_start, wall_cap, probe=1 if done == 0 else sim.chunk_steps())
            t1 = time.perf_counter()
            result.integration_time += t1 - t0
            done = sim.steps - start_steps + resumed_steps

            metrics = self.measure()
            e, kinetic = self.probe.energies(sim.state)
            result.frames += 1
            if metrics.finite:
                result.max_strain = max(result.max_strain, metrics.max_strain)
            result.final_max_speed = metrics.max_speed
            if not metrics.finite or not math.isfinite(e):
                result.stable, result.unstable_reason = False, "non-finite state"
            elif metrics.max_strain > self.instability_strain:
                result.stable = False
                result.unstable_reason = (
                    f"spring strain {metrics.max_strain:.3g} beyond the limit {self.instability_strain:g}"
                )
            elif sim.sim_time < pins_move_until:
                energy, energy_start = None, None
            elif energy is None:
                energy, energy_start = energy_monitor(e), sim.sim_time
            elif energy.update(sim.sim_time - energy_start, e, kinetic):
                result.stable = False
                result.unstable_reason = (
                    f"energy growing without bound: {energy.excess:.3g} J above what gravity and the external forces "
                    f"can supply, growing in {energy.streak} consecutive windows"
                )
            if frames is not None and result.stable:
                te = time.perf_counter()
                frames.write_frame(sim.state.particle_q.numpy(), sim.sim_time)
                result.export_time += time.perf_counter() - te
            t2 = time.perf_counter()
            result.other_time += t2 - t1
            if not result.stable:
                result.unstable_time = sim.sim_time
                break
            if detector.update(sim.sim_time - start_time, t2 - loop_start, metrics):
                if not result.equilibrium_reached:
                    result.equilibrium_reached = True
                    result.time_to_equilibrium = detector.rest_since
                    result.time_to_equilibrium_wall = detector.rest_since_wall
                if stop_at_equilibrium:
                    break
            if capped or (wall_cap is not None and t2 - loop_start >= wall_cap):
                result.wall_cap_reached = True
                break

        if not result.stable:
            result.unstable_reason += "; " + _unstable_cause(sim, inside)
        result.wall_time = time.perf_counter() - loop_start
        result.capture_time = sim.capture_time - start_capture
        result.integration_time = max(0.0, result.integration_time - result.capture_time)
        result.steps = sim.steps - start_steps
        result.sim_time = sim.sim_time - start_time
        if result.steps and result.integration_time > 0:
            result.ms_per_step = 1000.0 * result.integration_time / result.steps
            result.steps_per_sec = result.steps / result.integration_time
        if result.wall_time > 0:
            result.realtime_factor = result.sim_time / result.wall_time
        result.solver = sim.integrator.stats()
        sim.integrator.reset_stats()  # the next run's statistics (and capped-step count) start here
        result.solver_converged, result.solver_capped_steps, warning = sim.integrator.convergence(result.solver)
        if warning:
            warn(warning)  # once per run
        result.capped_steps = sim.integrator.capped_steps(result.solver)
        self._report_strain_limit(sim, limiter, result)
        result.capped_cause = _capped_cause(sim, result)
        self._report_self_collision(sim, result)
        return result

    @staticmethod
    def _report_strain_limit(sim, limiter, result: RunResult) -> None:
        """The strain limit's counters into the result (one read, then zeroed), and one warning line
        where the integrator's own strain cap engaged (the user's limit is a choice, not a warning)."""
        if limiter is None:
            return
        stats = limiter.stats()
        limiter.reset_stats()
        result.strain_limit_source = "strain_limit" if limiter is sim.strain_limiter else "strain_cap"
        result.strain_limit_tau = limiter.tau
        result.strain_capped_steps = stats["engaged_steps"]
        result.strain_limit_pass_capped_steps = stats["pass_capped_steps"]
        if result.strain_limit_source == "strain_cap" and result.strain_capped_steps:
            warn(
                f"{result.integrator}: its {100 * limiter.tau:g} % strain cap engaged in {result.strain_capped_steps} "
                f"of {result.steps} steps (springs stretched past it after the step were shortened): those steps are "
                "not the model's own (a smaller --dt; --strain-cap 0 turns it off)"
            )

    @staticmethod
    def _report_self_collision(sim, result: RunResult) -> None:
        """Self-collision's counters into the result (then zeroed for the next run), and one warning
        line where pairs may have been missed: lists that overflowed, queries cut short, vertices
        faster than the list's largest margin; another where pairs stayed crossed after the continuous
        response."""
        sc = getattr(sim, "self_collision", None)
        if sc is None:
            return
        stats = result.self_collision = sc.stats()
        sc.reset_stats()
        missed = {
            "candidate pairs that did not fit its list (raise candidates_per_vertex / candidates_per_edge)": stats[
                "overflow_candidates"
            ],
            "contacts that did not fit its list (raise contacts_per_element)": stats["overflow_contacts"],
            "queries cut to the cells searched": stats["truncated_queries"],
            # counted per vertex at each list build (a vertex fast over 100 builds counts 100)
            f"vertex-builds over {stats['rebuilds']:,} list builds where a vertex moved farther in a step than the "
            "list's largest margin covers (skin_max; lower --dt, or raise SelfCollision's skin_max in Python)": stats[
                "fast"
            ],
        }
        said = [f"{count:,} {what}" for what, count in missed.items() if count]
        if said:
            warn("self-collision may have missed pairs: " + "; ".join(said))
        if stats["ccd_unresolved"]:
            warn(
                f"self-collision: {stats['ccd_unresolved']} pairs crossed within a step and stayed crossed "
                "after the continuous response (lower dt, or raise ccd_passes)"
            )

    def _check_start(self, sim) -> list:
        """Before a run: one warning line per collider that free vertices start inside (they
        are thrown out at the first step); returns those colliders (the unstable cause)."""
        colliders = sim.control.colliders
        if not colliders:
            return []
        free = np.ones(sim.model.particle_count, dtype=bool)
        free[np.asarray(sim.model.pinned, dtype=np.int64)] = False
        found = starting_inside(colliders, sim.state.particle_q.numpy(), free, sim.sim_time)
        for k, what, count in found:
            warn(
                f"{count} of {int(free.sum())} free cloth vertices start inside collider {k} ({what}): the first step "
                f"throws them out; move the cloth or the collider"
            )
        self._check_rounded_edges(sim, free, {k for k, _, _ in found})
        return found

    def _check_rounded_edges(self, sim, free, inside: set) -> None:
        """One warning line per box whose rounded edges (Box.edge_radius, docs/colliders.md) free
        vertices start within: the first step pushes them out to the radius at once."""
        contacts = sim.control.collision
        contacts.bind_model(sim.model)  # the boxes' radius for this cloth (once per model)
        x = sim.state.particle_q.numpy().astype(np.float64)[free]
        for k, (c, rounding) in enumerate(zip(sim.control.colliders, contacts.roundings())):
            if c.kind != "box" or rounding <= 0.0 or k in inside:
                continue
            posed = c.at(sim.sim_time) if c.track is not None else c
            radius = float(c.thickness) + rounding
            near = (box_edge_distance(posed, x) < radius) & (signed_distance(posed, x) >= 0.0)
            if count := int(np.count_nonzero(near)):
                warn(
                    f"{count} of {int(free.sum())} free cloth vertices start within the rounded edges of collider {k} "
                    f"({describe(posed)}, edge radius {radius:.3g} m): the first step pushes them out to it at once; "
                    f"move the cloth, or give the box a smaller edge_radius (0: sharp)"
                )

    def _advance(self, n: int, loop_start: float, wall_cap: float | None, probe: int = 1) -> bool:
        """Advance ``n`` steps in chunks of about :data:`CHUNK_SECONDS` of wall time, checking
        the wall cap between chunks; True when the cap stopped it early. Where a step's time is not
        known yet, two calls of ``probe`` steps come first, the second timed: 1 at a run's start,
        :meth:`Simulator.chunk_steps <warpcloth.simulator.Simulator.chunk_steps>` where a resumed run
        starts (whole graphs, as the uninterrupted run's later frames take them)."""
        sim = self.sim
        device = sim.model.device
        done = 0
        step_seconds = self._step_seconds.get(sim.step_version)
        if step_seconds is None:  # size the chunks from a step timed after a first one
            done = min(probe, n)
            sim.simulate(done)  # may compile or capture
            wp.synchronize_device(device)
            if n <= done:
                return False
            timed = min(probe, n - done)
            with Stopwatch(device) as watch:
                sim.simulate(timed)
            step_seconds = self._step_seconds[sim.step_version] = max(watch.seconds / timed, 1e-7)
            done += timed
        # whole graphs of steps, so that self-collision intervals do not depend on the machine's speed
        granule = sim.chunk_steps()
        chunk = max(granule, int(CHUNK_SECONDS / step_seconds) // granule * granule)
        while done < n:
            if wall_cap is not None and done and time.perf_counter() - loop_start >= wall_cap:
                return True
            k = min(chunk, n - done)
            sim.simulate(k)
            wp.synchronize_device(device)
            done += k
        return False


def check_run_length(duration: float, fps: float, dt: float) -> None:
    """Refuse, in one line, runs that cannot be meaningful: a step longer than the run, a frame
    more than :data:`MAX_FRAMES_PER_STEP` times shorter than a step, or more than
    :data:`MAX_RUN_STEPS` steps."""
    if dt > duration:
        raise WarpclothError(f"dt ({dt:.4g} s) is longer than the duration ({duration:.4g} s): choose dt <= duration")
    if dt * fps > MAX_FRAMES_PER_STEP:
        raise WarpclothError(
            f"fps ({fps:.4g} 1/s) asks for a frame every {1.0 / fps:.3g} s, {dt * fps:.3g} frames per step of "
            f"{dt:.3g} s (at most {MAX_FRAMES_PER_STEP:g}): choose fps <= {MAX_FRAMES_PER_STEP / dt:.4g}"
        )
    steps = duration / dt
    if steps > MAX_RUN_STEPS:
        raise WarpclothError(
            f"duration {duration:.4g} s at dt {dt:.3g} s is {steps:.3g} steps (at most {MAX_RUN_STEPS:.0e}): "
            f"a larger dt or a shorter duration"
        )
