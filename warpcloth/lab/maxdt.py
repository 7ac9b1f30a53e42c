"""The largest stable time step of an integrator on a scenario (design.md, seed 4.2.2).

A time step is *stable* when the scenario runs a fixed simulated duration (default 2 s, from
rest, without stopping at equilibrium) and never goes unstable by the simulator's definition
(non-finite state, a spring strained past the instability strain, or energy growing without
bound). Where the scheme's stability region on the model holds no dt at all (midpoint without
damping), the search reports that before any trial instead of a number set by the trial length. The search brackets the
boundary by doubling or halving a first guess, then bisects (geometric mean) until the
bracket's relative width is at most the precision. It assumes stability is monotonic in dt,
as it is for the explicit schemes; it returns the largest dt seen stable.

Each trial reuses one :class:`~warpcloth.simulator.Simulator` (reset to rest, new dt), so the
model is built and kernels compiled once.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

from warpcloth.errors import require, require_positive
from warpcloth.integrators import explicit_euler_dt_bound
from warpcloth.run.harness import Stopwatch

DEFAULT_PRECISION = 0.02
DEFAULT_DURATION = 2.0  # s of simulated time a trial must survive
DEFAULT_DT_MIN = 1.0e-7  # s
DEFAULT_DT_MAX = 0.1  # s: beyond this the search stops (implicit integrators are stable at any dt)


@dataclass
class Trial:
    """One trial run of the search."""

    dt: float
    stable: bool
    reason: str = ""  # why it went unstable
    capped: bool = False  # stopped by the wall-clock cap before the duration (counted as stable)
    wall_time: float = 0.0
    max_strain: float = 0.0  # the largest spring strain reached
    duration: float = 0.0  # simulated time asked of the trial [s]


@dataclass
class MaxDtResult:
    """Outcome of :func:`find_max_dt`.

    Attributes:
        dt: the largest dt [s] found stable (None if none was, down to ``dt_min``).
        unstable_dt: the smallest dt [s] found unstable (None if none was, up to ``dt_max``).
        precision: relative precision asked.
        duration: simulated time of each trial [s].
        trials: every trial, in order.
        reference: the seed's explicit-Euler bound 0.4 pi sqrt(m/K) [s] on this model.
        particle_mass: m [kg]; max_stiffness: K [N/m].
        wall_time: seconds the search took.
    """

    scenario: str
    integrator: str
    device: str
    rows: int
    cols: int
    dt: float | None
    unstable_dt: float | None
    precision: float
    duration: float
    dt_min: float
    dt_max: float
    reference: float
    particle_mass: float
    max_stiffness: float
    trials: list[Trial] = field(default_factory=list)
    wall_time: float = 0.0
    #: Why no dt can be stable (the scheme's stability region on this model), found before any trial.
    no_stable_reason: str = ""
    #: The largest spring strain reached in the trial at :attr:`dt`.
    max_strain: float | None = None
    #: Simulated time the found dt was verified over (the run's own duration and schedule; 0: not asked).
    verified_duration: float = 0.0

    @property
    def limit_reached(self) -> bool:
        """True when no instability was found up to ``dt_max``."""
        return self.unstable_dt is None and not self.no_stable_reason

    @property
    def inconclusive_trials(self) -> int:
        return sum(t.capped for t in self.trials)

    def to_dict(self) -> dict:
        return {
            "scenario": self.scenario,
            "integrator": self.integrator,
            "device": self.device,
            "rows": self.rows,
            "cols": self.cols,
            "max_dt": self.dt,
            "unstable_dt": self.unstable_dt,
            "precision": self.precision,
            "duration": self.duration,
            "dt_min": self.dt_min,
            "dt_max": self.dt_max,
            "explicit_euler_reference": self.reference,
            "particle_mass": self.particle_mass,
            "max_stiffness": self.max_stiffness,
            "trials": [t.__dict__ for t in self.trials],
            "wall_time": self.wall_time,
            "max_strain": self.max_strain,
            "no_stable_reason": self.no_stable_reason,
            "verified_duration": self.verified_duration,
        }


def trial_stable(
    harness,
    dt: float,
    duration: float,
    fps: float = 60.0,
    wall_cap: float | None = None,
    stop_at_equilibrium: bool = False,
) -> Trial:
    """Run the simulator of ``harness`` (a :class:`~warpcloth.run.harness.RunHarness`) from rest
    for ``duration`` seconds at ``dt`` (ending at equilibrium where asked, as the scenario's own
    runs do); is it stable?"""
    sim = harness.sim
    sim.reset()
    sim.set_dt(dt)
    with Stopwatch(sim.model.device) as watch:
        r = harness.run(duration, fps=fps, stop_at_equilibrium=stop_at_equilibrium, wall_cap=wall_cap, warm_up=False)
    return Trial(
        dt=dt,
        stable=r.stable,
        reason=r.unstable_reason,
        capped=r.wall_cap_reached and r.stable,
        wall_time=watch.seconds,
        max_strain=r.max_strain,
        duration=duration,
    )


def find_max_dt(
    scenario,
    config,
    precision: float = DEFAULT_PRECISION,
    duration: float = DEFAULT_DURATION,
    dt_min: float = DEFAULT_DT_MIN,
    dt_max: float = DEFAULT_DT_MAX,
    start: float | None = None,
    wall_cap: float | None = None,
    on_trial=None,
    verify_duration: float | None = None,
    stop_at_equilibrium: bool = False,
) -> MaxDtResult:
    """The largest stable dt of ``config.integrator`` on ``scenario`` with ``config``.

    Args:
        scenario: a :class:`~warpcloth.scenarios.Scenario`.
        config: its :class:`~warpcloth.scenarios.ScenarioConfig` (``dt`` and ``duration`` ignored).
        precision: stop when (unstable - stable) / stable <= precision.
        duration: simulated time [s] each trial must survive.
        dt_min, dt_max: the search's bounds [s].
        start: first dt tried [s] (default: the integrator's own default dt).
        wall_cap: wall-clock cap of one trial [s]; a trial that reaches it without going
            unstable counts as stable (reported in :attr:`MaxDtResult.inconclusive_trials`).
        on_trial: called with each :class:`Trial` as it finishes.
        verify_duration: where longer than ``duration``, the found dt must also survive a trial
            of this length (the run it is for: its whole duration and wind schedule, ending at
            equilibrium if ``stop_at_equilibrium``); while it does not, dt steps down by
            2^(-1/4) and the boundary is bisected again with trials of that length. The search's
            short trials miss what comes later in a run: the quick sweep's flag at its 2 s max
            dt went past the instability strain (0.62 explicit Euler, 0.54 midpoint) in its 3 s
            run (issue 26). Stability is assumed monotonic in dt below the boundary.
        stop_at_equilibrium: the verification trials end at equilibrium, as the run does.
    """
    precision = require_positive("precision", precision)
    require(precision < 1.0, f"precision must be < 1 (relative, e.g. 0.02), got {precision!r}")
    duration = require_positive("duration", duration, "s")
    dt_min = require_positive("dt_min", dt_min, "s")
    dt_max = require_positive("dt_max", dt_max, "s")
    require(dt_min < dt_max, f"dt_min ({dt_min:g} s) must be below dt_max ({dt_max:g} s)")
    if start is not None:  # a first dt outside the search's bounds is refused, not clamped
        require(
            isinstance(start, (int, float)) and math.isfinite(start) and dt_min <= start <= dt_max,
            f"start must be a finite dt within [dt_min, dt_max] = [{dt_min:g}, {dt_max:g}] s, got {start!r}",
        )

    t_start = time.perf_counter()
    harness = scenario.harness(config, dt=dt_max)  # an explicit dt: the default may not exist
    sim = harness.sim
    model = sim.model
    result = MaxDtResult(
        scenario=scenario.name,
        integrator=sim.integrator.name,
        device=str(model.device),
        rows=model.rows,
        cols=model.cols,
        dt=None,
        unstable_dt=None,
        precision=precision,
        duration=duration,
        dt_min=dt_min,
        dt_max=dt_max,
        reference=explicit_euler_dt_bound(model),
        particle_mass=model.particle_mass_value,
        max_stiffness=model.max_stiffness(),
    )
    reason = sim.integrator.no_stable_dt_reason(model, sim.control.drag_rate)
    if reason:
        result.no_stable_reason = reason
        result.wall_time = time.perf_counter() - t_start
        return result
    sim.set_dt(sim.integrator.default_dt(model, sim.control.drag_rate))
    sim.warm_up()

    def test(dt: float, length: float = duration, stop: bool = False) -> bool:
        trial = trial_stable(harness, dt, length, fps=config.fps, wall_cap=wall_cap, stop_at_equilibrium=stop)
        result.trials.append(trial)
        if on_trial is not None:
            on_trial(trial)
        return trial.stable

    dt = min(max(start if start is not None else sim.dt, dt_min), dt_max)
    lo = hi = None
    # Bracket: double while stable, halve while unstable.
    if test(dt):
        lo = dt
        while hi is None and lo < dt_max:
            dt = min(2.0 * lo, dt_max)
            if test(dt):
                lo = dt
            else:
                hi = dt
    else:
        hi = dt
        while lo is None and hi > dt_min:
            dt = max(0.5 * hi, dt_min)
            if test(dt):
                lo = dt
            else:
                hi = dt
    # Bisect.
    if lo is not None and hi is not None:
        while (hi - lo) / lo > precision:
            mid = math.sqrt(lo * hi)
            if test(mid):
                lo = mid
            else:
                hi = mid
    # Verify over the run's own duration: step down while unstable, then bisect with such trials.
    if verify_duration is not None and verify_duration > duration and lo is not None:
        verify_duration = require_positive("verify_duration", verify_duration, "s")
        result.verified_duration = verify_duration
        stepped = False
        while lo is not None and not test(lo, verify_duration, stop_at_equilibrium):
            stepped = True
            hi = lo
            lo = lo * 2.0**-0.25 if lo * 2.0**-0.25 >= dt_min else None
        if stepped and lo is not None:
            while (hi - lo) / lo > precision:
                mid = math.sqrt(lo * hi)
                if test(mid, verify_duration, stop_at_equilibrium):
                    lo = mid
                else:
                    hi = mid
    result.dt, result.unstable_dt = lo, hi
    if lo is not None:
        result.max_strain = max(t.max_strain for t in result.trials if t.dt == lo and t.stable)
    result.wall_time = time.perf_counter() - t_start
    return result


def format_result(r: MaxDtResult) -> str:
    """The human-readable report of ``warpcloth max-dt``."""
    verified = f" (the found dt verified over {r.verified_duration:g} s)" if r.verified_duration else ""
    lines = [
        f"{r.scenario}: {r.integrator} on {r.device}, {r.rows}x{r.cols}; stable = {r.duration:g} s simulated without "
        f"going unstable{verified}"
    ]
    if r.no_stable_reason:
        lines.append(f"  no stable dt exists: {r.no_stable_reason}")
    elif r.dt is None:
        lines.append(f"  no stable dt found down to {r.dt_min:.4g} s")
    elif r.unstable_dt is None:
        lines.append(
            f"  max stable dt: >= {r.dt:.4g} s (stable up to the search limit {r.dt_max:.4g} s; no instability found)"
        )
    else:
        lines.append(f"  max stable dt: {r.dt:.4g} s (max strain {100 * r.max_strain:.3g} % at that dt)")
        lines.append(
            f"  bracket: stable at {r.dt:.4g} s, unstable at {r.unstable_dt:.4g} s "
            f"(relative width {(r.unstable_dt - r.dt) / r.dt:.2%}, precision {r.precision:.2%})"
        )
    top = next((t for t in r.trials if not t.stable and t.dt == r.unstable_dt), None)
    if top is not None:
        lines.append(f"  at {top.dt:.4g} s: {top.reason}")
    if r.limit_reached and r.dt is not None:
        lines.append(f"  max strain at {r.dt:.4g} s: {100 * r.max_strain:.3g} %")
    lines.append(
        f"  {len(r.trials)} trials in {r.wall_time:.1f} s wall"
        + (f" ({r.inconclusive_trials} stopped by the wall cap, counted as stable)" if r.inconclusive_trials else "")
    )
    if r.integrator == "explicit_euler":
        ratio = (
            f"; found / reference = {r.dt / r.reference:.2f}" if r.dt is not None and math.isfinite(r.reference) else ""
        )
        lines.append(
            f"  explicit-Euler reference 0.4 pi sqrt(m/K) (seed 4.2.2): {r.reference:.4g} s "
            f"(m = {r.particle_mass:.4g} kg, K = {r.max_stiffness:.4g} N/m){ratio}"
        )
    return "\n".join(lines)


__all__ = [
    "DEFAULT_DURATION",
    "DEFAULT_PRECISION",
    "MaxDtResult",
    "Trial",
    "find_max_dt",
    "format_result",
    "trial_stable",
]
