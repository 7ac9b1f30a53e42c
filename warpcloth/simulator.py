"""The fixed-step simulation loop, decoupled from the frame rate (seed 3.2.2).

Forces are computed every time step ``dt``; frames are sampled every ``1/fps`` seconds of
simulated time. A frame's steps are pure kernel launches; metrics are reduced on the device
and read once per frame. A run returns a :class:`RunResult` that serialises to JSON.
"""

from __future__ import annotations

import json
import math
import os
import time
from dataclasses import asdict, dataclass, field

import warp as wp

from . import __version__
from .errors import WarpclothError, require, require_count, require_positive, warn
from .forces import Control
from .integrators import Integrator, make_integrator
from .model import ClothModel
from .metrics import (
    DEFAULT_INSTABILITY_STRAIN,
    EnergyCriteria,
    EnergyMonitor,
    EquilibriumCriteria,
    EquilibriumDetector,
    FrameMetrics,
    MetricsProbe,
    wind_power_bound,
)
from .pins import apply_pins
from .strain_limit import StrainLimiter

#: Most steps one run may take (a larger count is a typo in dt or duration, not an experiment).
MAX_RUN_STEPS = 10**12
#: A frame may be at most this many times shorter than a step (frames shorter than a step are
#: sampled once per step anyway).
MAX_FRAMES_PER_STEP = 1000.0
#: The wall cap is checked after chunks of steps of about this many wall seconds.
CHUNK_SECONDS = 0.2


def graph_capture_supported(device) -> bool:
    """CUDA graphs on a GPU (with mempool); API capture on the CPU from Warp 1.19."""
    d = wp.get_device(device)
    if d.is_cuda:
        return bool(wp.is_mempool_enabled(d))
    major, minor = (int(p) for p in wp.config.version.split(".")[:2])
    return (major, minor) >= (1, 19)


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
    solver_capped_steps: int = 0
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

    def to_dict(self) -> dict:
        d = asdict(self)
        d["integration_ms_mean"] = self.integration_ms_mean
        d["other_ms_mean"] = self.other_ms_mean
        d["frames_per_sec"] = self.frames_per_sec
        return d

    def to_json(self, **kwargs) -> str:
        return json.dumps(self.to_dict(), **kwargs)


class Simulator:
    """Advances one cloth with a chosen integrator at a fixed time step.

    Args:
        model: the :class:`~warpcloth.model.ClothModel`.
        integrator: an :class:`~warpcloth.integrators.Integrator` or its name.
        control: external forces (:class:`~warpcloth.forces.Control`); default gravity only.
        dt: time step [s]; default the integrator's :meth:`~Integrator.default_dt`.
        instability_strain: a spring stretched past (1 + this) x its rest length is unstable
            (default :data:`~warpcloth.metrics.DEFAULT_INSTABILITY_STRAIN`).
        equilibrium: tolerances of the equilibrium test.
        energy: when growing energy counts as unstable (:class:`~warpcloth.metrics.EnergyCriteria`).
        scenario: a name carried into results.
        use_graph: capture a frame's steps once with ``wp.ScopedCapture`` and replay it (CUDA
            graphs; Warp's API capture on the CPU). None: wherever the device and the
            integrator support it. Results are bit-identical either way.
        strain_limit: Provot's deformation constraint tau (> 0, e.g. 0.1 for 10 %) applied after
            every step of a force-based integrator (:mod:`warpcloth.strain_limit`); None: off.
    """

    def __init__(
        self,
        model,
        integrator: Integrator | str = "explicit_euler",
        control: Control | None = None,
        dt: float | None = None,
        instability_strain: float = DEFAULT_INSTABILITY_STRAIN,
        equilibrium: EquilibriumCriteria | None = None,
        energy: EnergyCriteria | None = None,
        scenario: str = "custom",
        use_graph: bool | None = None,
        strain_limit: float | None = None,
    ):
        if not isinstance(model, ClothModel):
            raise WarpclothError(f"model must be a ClothModel (from build_grid_cloth or build_model), got {model!r:.80}")
        if control is not None and not isinstance(control, Control):
            raise WarpclothError(f"control must be a warpcloth.Control or None, got {control!r:.80}")
        self.model = model
        self.control = control if control is not None else Control(device=model.device)
        require(
            str(self.control.device) == str(model.device),
            f"control is on device '{self.control.device}' but the model is on '{model.device}'",
        )
        self.state = model.state()
        self._pins_version = 0
        self._bind_pin_tracks(self.control.pin_tracks)
        self.instability_strain = require_positive("instability strain", instability_strain)
        self.equilibrium = equilibrium or EquilibriumCriteria()
        self.energy_criteria = energy or EnergyCriteria()
        self.scenario = scenario
        self.probe = MetricsProbe(model, self.control)
        self.strain_limiter = StrainLimiter(model, strain_limit) if strain_limit is not None else None
        self.integrator: Integrator | None = None
        self._dt: float | None = None
        self._use_graph = use_graph
        self._graphs: dict[tuple, object] = {}
        self._warmed = False
        self._step_seconds: float | None = None  # wall time of one step, once measured
        #: Wall seconds spent capturing frame graphs (excluded from step timings).
        self.capture_time = 0.0
        #: Simulated time [s]: t_base + n dt after n steps of the current dt (as Control.time).
        self.sim_time = 0.0
        self.steps = 0
        self._time_base, self._base_steps = 0.0, 0
        self.set_integrator(integrator, dt)

    # -- configuration -------------------------------------------------------------------
    @property
    def dt(self) -> float:
        return self._dt

    def set_integrator(self, integrator: Integrator | str, dt: float | None = None) -> None:
        """Switch integrators between steps (the model is not rebuilt); ``dt`` None keeps the
        current step when one is set, else takes the integrator's default."""
        if isinstance(integrator, str):
            integrator = make_integrator(integrator)
        if not isinstance(integrator, Integrator):
            raise WarpclothError(f"integrator must be an Integrator or a name, got {integrator!r}")
        if self.strain_limiter is not None and not integrator.force_based:
            raise WarpclothError(f"strain limit applies to force-based integrators only, not {integrator.name!r}")
        integrator.bind(self.model)
        if dt is None and self._dt is None:
            reason = integrator.no_stable_dt_reason(self.model, self.control.drag_rate)
            if reason:
                raise WarpclothError(reason + "; or give dt yourself")
            dt = integrator.default_dt(self.model, self.control.drag_rate)
            if not dt > 0.0:
                raise WarpclothError(
                    f"dt must be > 0 s, got {dt!r} (the default dt of {integrator.name!r} on this model underflowed: "
                    f"check the mass, stiffness, damping and drag)"
                )
        elif dt is None:
            dt = self._dt
        self._rebase_clock()
        self._dt = require_positive("dt", dt, "s")
        self.integrator = integrator
        self._needs_begin = True
        self._graphs.clear()
        self._warmed = False
        self._step_seconds = None

    def set_model(self, model) -> None:
        """Continue the current state on ``model`` (the same particles, e.g. from
        :meth:`~warpcloth.model.ClothModel.with_spring_params`): the integrator, metrics and
        strain limiter rebind to it (scratch is reallocated; this is not a step)."""
        if not isinstance(model, ClothModel):
            raise WarpclothError(f"model must be a ClothModel, got {model!r:.80}")
        if model.particle_count != self.model.particle_count or str(model.device) != str(self.model.device):
            raise WarpclothError(
                f"set_model needs the same particles on the same device ({self.model.particle_count} on {self.model.device}), "
                f"got {model.particle_count} on {model.device}"
            )
        self.model = model
        self._bind_pin_tracks(self.control.pin_tracks)  # kinematic pins: checked and bound to the new model
        self.probe = MetricsProbe(model, self.control)
        if self.strain_limiter is not None:
            self.strain_limiter = StrainLimiter(model, self.strain_limiter.tau)
        self.integrator.bind(model)
        self._needs_begin = True
        self._graphs.clear()
        self._warmed = False

    def set_pin_track(self, *tracks) -> None:
        """Move pinned particles along :class:`~warpcloth.pins.PinTrack` s from the next step
        (replacing the tracks set before; no argument: every pin stays where it is)."""
        self._bind_pin_tracks(tracks)
        self._needs_begin = True
        self._graphs.clear()

    def _bind_pin_tracks(self, tracks) -> None:
        from .pins import KinematicPins, PinTrack

        if isinstance(tracks, PinTrack):
            tracks = (tracks,)
        tracks = tuple(tracks or ())
        self.control.pin_tracks = tracks
        self.control.kinematic_pins = KinematicPins(self.model, tracks) if tracks else None
        self._pins_version += 1

    def _pins_moving_until(self) -> float:
        """Simulated time [s] after which no kinematic pin moves (0 without tracks; inf for a
        rigid motion that never stops)."""
        end = 0.0
        for track in self.control.pin_tracks:
            if track.kind == "keyframes":
                end = max(end, float(track.times[-1]))
            elif any(track.velocity) or track.angular_velocity or (track.swing_amplitude and track.swing_frequency):
                end = math.inf
        return end

    def set_dt(self, dt: float) -> None:
        dt = require_positive("dt", dt, "s")
        self._rebase_clock()
        self._dt = dt
        self._needs_begin = True
        self._graphs.clear()

    @property
    def use_graph(self) -> bool | None:
        """Graph capture: True (always; an error where unsupported), False (plain launches) or
        None (wherever the device and the integrator support it). Results are bit-identical."""
        return self._use_graph

    @use_graph.setter
    def use_graph(self, value: bool | None) -> None:
        if value not in (True, False, None):
            raise WarpclothError(f"use_graph must be True, False or None (auto), got {value!r}")
        self._use_graph = value
        self._graphs.clear()
        self._step_seconds = None

    @property
    def graph_enabled(self) -> bool:
        """Whether frames are captured and replayed (see ``use_graph``)."""
        supported = graph_capture_supported(self.model.device) and self.integrator.capturable_on(self.model.device)
        if self.strain_limiter is not None and wp.get_device(self.model.device).is_cuda:
            supported = supported and wp.is_conditional_graph_supported()  # its pass loop is capture_while
        if self._use_graph is None:
            return supported
        if self._use_graph and not supported:
            raise WarpclothError(
                f"graph capture is not available for integrator {self.integrator.name!r} on {self.model.device} "
                f"with Warp {wp.config.version}"
            )
        return bool(self._use_graph)

    def reset(self) -> None:
        """Back to the rest configuration at t = 0."""
        self.state.assign(self.model.state())
        self.control.set_time(0.0)
        self.sim_time, self.steps = 0.0, 0
        self._rebase_clock()
        self._needs_begin = True

    def _rebase_clock(self) -> None:
        """Count steps from now (before dt changes); the device clock follows in :meth:`_begin`."""
        self._time_base, self._base_steps = self.sim_time, self.steps

    def _count_steps(self, n: int) -> None:
        self.steps += n
        self.sim_time = self._time_base + (self.steps - self._base_steps) * self._dt

    # -- stepping ------------------------------------------------------------------------
    def step(self) -> None:
        """Advance one time step: W(t) update, integrator step, strain limit, t += dt (launches only)."""
        if self._needs_begin:
            self._begin()
        self._launch_step()
        self._count_steps(1)

    def _capture_key(self) -> tuple:
        """Every host value a captured frame bakes in besides dt and the integrator (those clear
        the cache): a change to any of them captures a new graph."""
        c = self.control
        return (tuple(c.gravity), c.drag_rate, c.wind_coefficient, c.wind_schedule, c.colliders, self._pins_version,
                tuple(sorted((k, repr(v)) for k, v in self.integrator.option_values().items())))

    def _begin(self) -> None:
        """Let the integrator start its history from the current state and wind W(t)."""
        self._rebase_clock()
        self.control.rebase()
        self.control.update()
        apply_pins(self.control, self.state.particle_q, self.state.particle_qd)  # pins on their track at t
        self.integrator.begin(self.state, self.control, self._dt)
        self._needs_begin = False

    def _launch_step(self) -> None:
        self.control.update()
        self.integrator.step(self.state, self.control, self._dt)
        if self.control.collision is not None and not self.integrator.collides_in_solver:
            self.control.collision.project_velocity(self.model, self.state, self._dt, self.integrator.position_history(),
                                                    self.integrator.velocity_position_weight)
        if self.strain_limiter is not None:
            self.strain_limiter.apply(self.state, self._dt)
        self.control.advance(self._dt)
        apply_pins(self.control, self.state.particle_q, self.state.particle_qd)  # x = track(t + dt), v = track'(t + dt)

    def simulate(self, steps: int) -> None:
        """Advance ``steps`` time steps (replaying a captured graph of them where enabled)."""
        steps = require_count("steps", steps)
        if steps == 0:
            return
        if not self.graph_enabled:
            for _ in range(steps):
                self.step()
            return
        if self._needs_begin:
            self._begin()
        key = (steps, self._capture_key())
        graph = self._graphs.get(key)
        if graph is None:
            if not self._warmed:  # load every kernel before capturing (older CUDA drivers require it)
                self.warm_up()
                self._begin()
            if len(self._graphs) >= 4:  # frames alternate between at most two step counts (+ chunks)
                self._graphs.clear()
            t0 = time.perf_counter()
            with wp.ScopedCapture(device=self.model.device) as capture:
                for _ in range(steps):
                    self._launch_step()
            graph = self._graphs[key] = capture.graph
            self.capture_time += time.perf_counter() - t0
        wp.capture_launch(graph)
        self._count_steps(steps)

    def measure(self) -> FrameMetrics:
        """Metrics of the current state (one small read from the device)."""
        # with colliders the net force of a resting particle is balanced by a contact the metric
        # does not see: equilibrium is then judged by speed alone (as for position-based schemes)
        return self.probe.measure(self.state, with_force=self.integrator.force_based and self.control.collision is None)

    def energy(self) -> float:
        """Total mechanical energy of the current state [J]."""
        return self.probe.energy(self.state)

    def warm_up(self) -> float:
        """Compile and load every kernel a step uses, on a scratch copy of the state; returns
        the seconds it took (reported as compile time, excluded from step timings)."""
        t0 = time.perf_counter()
        saved = wp.clone(self.state.particle_q), wp.clone(self.state.particle_qd)
        saved_time = wp.clone(self.control.time)
        self._begin()
        self._launch_step()
        self.measure()
        wp.copy(self.state.particle_q, saved[0])
        wp.copy(self.state.particle_qd, saved[1])
        wp.copy(self.control.time, saved_time)
        self.control.rebase()
        self.control.update()
        wp.synchronize_device(self.model.device)
        self.integrator.reset_stats()
        self._needs_begin = True
        self._warmed = True
        return time.perf_counter() - t0

    def run(
        self,
        duration: float,
        fps: float = 60.0,
        stop_at_equilibrium: bool = False,
        wall_cap: float | None = None,
        usd=None,
        warm_up: bool = True,
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
            usd: a :class:`~warpcloth.usd.UsdWriter` that receives every frame, a path
                (.usd/.usda/.usdc: a writer is made, checked before the run and closed after),
                or None.
            warm_up: compile kernels before timing (see :meth:`warm_up`).

        A run that goes unstable stops there and is recorded as unstable; it never raises.
        Graph capture time is reported apart (``capture_time``) and excluded from ms/step.
        """
        if unknown:
            raise WarpclothError(
                f"Simulator.run got an unknown keyword {sorted(unknown)[0]!r}; its keywords are duration, fps, "
                "stop_at_equilibrium, wall_cap, usd, warm_up"
            )
        duration = require_positive("duration", duration, "s")
        fps = require_positive("fps", fps, "1/s")
        if wall_cap is not None:
            wall_cap = require_positive("wall cap", wall_cap, "s")
        m, dt = self.model, self._dt
        check_run_length(duration, fps, dt)
        if isinstance(usd, (str, os.PathLike)):
            from .usd import UsdWriter

            writer = UsdWriter(os.fspath(usd), m, fps)
            try:
                result = self.run(duration, fps, stop_at_equilibrium, wall_cap, writer, warm_up)
            except BaseException:
                writer.abort()
                raise
            writer.close()
            return result
        if usd is not None and not callable(getattr(usd, "write_frame", None)):
            raise WarpclothError(f"usd must be a UsdWriter, a .usd/.usda/.usdc path or None, got {usd!r:.80}")
        result = RunResult(
            scenario=self.scenario, integrator=self.integrator.name, device=str(m.device), rows=m.rows, cols=m.cols,
            particles=m.particle_count, springs=m.spring_count, dt=dt, fps=fps,
            equilibrium_criterion="speed+force" if self.integrator.force_based and self.control.collision is None else "speed",
            graph=self.graph_enabled, instability_strain=self.instability_strain,
        )
        if warm_up and not self._warmed:  # once: a warm-up restarts the integrator's history
            result.compile_time = self.warm_up()
        detector = EquilibriumDetector(self.equilibrium, self.probe.force_floor)
        result.force_floor = self.probe.force_floor
        start_steps, start_time = self.steps, self.sim_time
        start_capture = self.capture_time
        total_steps = max(1, math.ceil(duration / dt - 1e-9))
        frame_dt = 1.0 / fps
        steps_per_frame = frame_dt / dt
        e0, _ = self.probe.energies(self.state)

        def energy_monitor(e_start: float) -> EnergyMonitor:
            return EnergyMonitor(
                e_start, wind_power_bound(m, self.control, self.instability_strain),
                window_frames=max(math.ceil(self.energy_criteria.window_time * fps - 1e-9),
                                  math.ceil(self.energy_criteria.window_steps / max(1.0, steps_per_frame) - 1e-9)),
                scale=m.total_mass * self.control.gravity_magnitude * max(m.width, m.height, 1e-3),
                criteria=self.energy_criteria,
            )

        energy, energy_start = energy_monitor(e0), start_time
        # moving kinematic pins do work no a-priori bound knows: the energy criterion waits until
        # they stop and starts from the energy then (non-finite state and strain still apply)
        pins_move_until = self._pins_moving_until()
        if usd is not None:
            t0 = time.perf_counter()
            usd.write_frame(self.state.particle_q.numpy(), self.sim_time)
            result.export_time += time.perf_counter() - t0

        loop_start = time.perf_counter()
        frame = 0
        done = 0
        while done < total_steps:
            # the next frame that needs a step (frames shorter than a step are skipped at once)
            frame = max(frame + 1, math.floor((done + 1e-9) / steps_per_frame) + 1)
            target = min(total_steps, math.ceil(frame * steps_per_frame - 1e-9))
            n = target - done
            if n <= 0:
                continue
            t0 = time.perf_counter()
            capped = self._advance(n, loop_start, wall_cap)
            t1 = time.perf_counter()
            result.integration_time += t1 - t0
            done = self.steps - start_steps

            metrics = self.measure()
            e, kinetic = self.probe.energies(self.state)
            result.frames += 1
            if metrics.finite:
                result.max_strain = max(result.max_strain, metrics.max_strain)
            result.final_max_speed = metrics.max_speed
            if not metrics.finite or not math.isfinite(e):
                result.stable, result.unstable_reason = False, "non-finite state"
            elif metrics.max_strain > self.instability_strain:
                result.stable = False
                result.unstable_reason = f"spring strain {metrics.max_strain:.3g} beyond the limit {self.instability_strain:g}"
            elif self.sim_time < pins_move_until:
                energy, energy_start = None, None
            elif energy is None:
                energy, energy_start = energy_monitor(e), self.sim_time
            elif energy.update(self.sim_time - energy_start, e, kinetic):
                result.stable = False
                result.unstable_reason = (
                    f"energy growing without bound: {energy.excess:.3g} J above what gravity and the external forces "
                    f"can supply, growing in {energy.streak} consecutive windows"
                )
            if usd is not None and result.stable:
                te = time.perf_counter()
                usd.write_frame(self.state.particle_q.numpy(), self.sim_time)
                result.export_time += time.perf_counter() - te
            t2 = time.perf_counter()
            result.other_time += t2 - t1
            if not result.stable:
                result.unstable_time = self.sim_time
                break
            if detector.update(self.sim_time - start_time, t2 - loop_start, metrics):
                if not result.equilibrium_reached:
                    result.equilibrium_reached = True
                    result.time_to_equilibrium = detector.rest_since
                    result.time_to_equilibrium_wall = detector.rest_since_wall
                if stop_at_equilibrium:
                    break
            if capped or (wall_cap is not None and t2 - loop_start >= wall_cap):
                result.wall_cap_reached = True
                break

        result.wall_time = time.perf_counter() - loop_start
        result.capture_time = self.capture_time - start_capture
        result.integration_time = max(0.0, result.integration_time - result.capture_time)
        result.steps = self.steps - start_steps
        result.sim_time = self.sim_time - start_time
        if result.steps and result.integration_time > 0:
            result.ms_per_step = 1000.0 * result.integration_time / result.steps
            result.steps_per_sec = result.steps / result.integration_time
        if result.wall_time > 0:
            result.realtime_factor = result.sim_time / result.wall_time
        result.solver = self.integrator.stats()
        self.integrator.reset_stats()  # the next run's statistics (and capped-step count) start here
        result.solver_converged, result.solver_capped_steps, warning = self.integrator.convergence(result.solver)
        if warning:
            warn(warning)  # once per run
        return result

    def _advance(self, n: int, loop_start: float, wall_cap: float | None) -> bool:
        """Advance ``n`` steps in chunks of about :data:`CHUNK_SECONDS` of wall time, checking
        the wall cap between chunks; True when the cap stopped it early."""
        device = self.model.device
        done = 0
        if self._step_seconds is None:  # size the chunks from a step timed after a first one
            self.simulate(1)  # may compile or capture
            wp.synchronize_device(device)
            done = 1
            if n < 2:
                return False
            t0 = time.perf_counter()
            self.simulate(1)
            wp.synchronize_device(device)
            self._step_seconds = max(time.perf_counter() - t0, 1e-7)
            done = 2
        chunk = max(1, int(CHUNK_SECONDS / self._step_seconds))
        while done < n:
            if wall_cap is not None and done and time.perf_counter() - loop_start >= wall_cap:
                return True
            k = min(chunk, n - done)
            self.simulate(k)
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
            f"fps ({fps:.4g} 1/s) asks for a frame every {1.0 / fps:.3g} s, {dt * fps:.3g} frames per step of {dt:.3g} s "
            f"(at most {MAX_FRAMES_PER_STEP:g}): choose fps <= {MAX_FRAMES_PER_STEP / dt:.4g}"
        )
    steps = duration / dt
    if steps > MAX_RUN_STEPS:
        raise WarpclothError(
            f"duration {duration:.4g} s at dt {dt:.3g} s is {steps:.3g} steps (at most {MAX_RUN_STEPS:.0e}): "
            f"a larger dt or a shorter duration"
        )
