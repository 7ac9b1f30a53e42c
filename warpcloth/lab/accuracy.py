"""Accuracy of the float32 integrators against the float64 reference (design.md, "Accuracy and
the study").

* **Transient error** e(dt): max over frames and particles of |x - x_ref| / cloth size on a
  transient every integrator can follow: the sheet released from horizontal, swinging down on
  its two pins (:func:`~warpcloth.lab.reference.swing_from_horizontal`), and the flag's first
  seconds from rest in its wind. Frames are 1/60 s apart, so a trial dt is one frame divided by
  a whole number of steps k: dt = (1/60 s) / k.
* **Max accurate dt**: the largest dt = frame/k with e <= tolerance, found by
  :func:`search_steps_per_frame` (bracket by doubling k, then bisection on k). The search
  *assumes* e grows monotonically with dt (it does for a scheme in its asymptotic range; a
  non-monotone curve makes the answer one accurate dt, not necessarily the largest).
* **Float32 noise floor**: e of rk4 at a tiny dt (a quarter of its default dt), reported beside
  every max accurate dt so that the tolerance is known to be above it.
* **Static error**: after a run of the sheet from rest to equilibrium, max |x - x_eq| / size
  against the float64 equilibrium (:func:`~warpcloth.lab.reference.static_equilibrium`), and the
  relative error of the sag (the largest displacement from rest).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from warpcloth.errors import WarpclothError, require
from warpcloth.run.harness import RunHarness
from warpcloth.lab.reference import cloth_size, reference_trajectory, simulate_frames, static_equilibrium, swing_from_horizontal, trajectory_error

#: The frame of every accuracy run [s]: trial dts are FRAME_DT / k.
FRAME_DT = 1.0 / 60.0
#: Default tolerance of e: 1 % of the cloth size.
DEFAULT_TOLERANCE = 0.01


@dataclass(frozen=True)
class Transient:
    """A transient of a scenario: its duration [s] and its start (``swing``: the sheet rotated
    to horizontal; otherwise the rest shape), at rest."""

    scenario: str
    duration: float
    swing: bool

    @property
    def frames(self) -> int:
        return int(round(self.duration / FRAME_DT))

    def describe(self) -> str:
        start = "released from horizontal" if self.swing else "from rest in its wind"
        return f"{self.scenario} {start}, {self.duration:g} s"


def _float32_exact(x: np.ndarray) -> np.ndarray:
    """``x`` rounded to float32 and back: the state the float32 runs really start from."""
    return np.asarray(x, dtype=np.float32).astype(np.float64)


class AccuracyProblem:
    """One transient on one simulator's model: the float64 reference computed once, and
    :meth:`error` for any dt = frame/k of any integrator bound to the same simulator.

    Args:
        sim: a :class:`~warpcloth.simulator.Simulator` of ``transient.scenario``.
        transient: the :class:`Transient`.
        rtol, atol: the reference's tolerances (see :func:`reference_trajectory`).
    """

    def __init__(self, sim, transient: Transient, rtol: float = 1e-10, atol: float = 1e-12):
        require(transient.frames >= 1 and abs(transient.frames * FRAME_DT - transient.duration) < 1e-9,
                f"transient duration {transient.duration!r} s must be a whole number of 1/60 s frames")
        self.transient = transient
        self.size = cloth_size(sim.model)
        x0 = swing_from_horizontal(sim.model) if transient.swing else sim.model.host["q"].astype(np.float64)
        self.x0 = _float32_exact(x0)
        t0 = time.perf_counter()
        self.reference = reference_trajectory(sim.model, sim.control, transient.frames * FRAME_DT, FRAME_DT,
                                              x0=self.x0, rtol=rtol, atol=atol)
        self.reference_seconds = time.perf_counter() - t0

    def run(self, sim, k: int) -> np.ndarray:
        """The float32 trajectory of ``sim`` (its current integrator) at dt = frame/k, from the
        transient's start: (frames + 1, N, 3)."""
        import warp as wp

        require(int(k) >= 1, f"steps per frame must be >= 1, got {k!r}")
        sim.reset()
        sim.state.particle_q.assign(wp.array(self.x0.astype(np.float32), dtype=wp.vec3, device=sim.model.device))
        sim.set_dt(FRAME_DT / int(k))
        return simulate_frames(sim, self.transient.frames * FRAME_DT, FRAME_DT)

    def error(self, sim, k: int) -> float:
        """e(frame/k) of ``sim``'s integrator; ``inf`` when the run is not finite (unstable)."""
        traj = self.run(sim, k)
        if not np.all(np.isfinite(traj)):
            return math.inf
        return trajectory_error(traj, self.reference, self.size)


# -- the search ------------------------------------------------------------------------------
@dataclass
class AccurateSearch:
    """Outcome of :func:`search_steps_per_frame`.

    Attributes:
        k: the fewest steps per frame found accurate (dt = frame / k), None if none up to k_max.
        k_inaccurate: the most steps per frame found inaccurate (the bracket's other side), None
            if the first trial (k_start) was already accurate.
        trials: (k, e) in the order tried.
        bounded: True when k == k_start was accurate: the max accurate dt is at least the upper
            bound of the search (the max stable dt or one frame), not a found boundary.
        stalled: True when the bracket gave up because e stopped falling as dt shrank (an error
            floor above the tolerance: float32 noise, or a scheme whose error is not set by dt).
    """

    k: int | None
    k_inaccurate: int | None
    trials: list = field(default_factory=list)
    bounded: bool = False
    stalled: bool = False

    def dt(self, frame_dt: float = FRAME_DT) -> float | None:
        return None if self.k is None else frame_dt / self.k


def search_steps_per_frame(error: Callable[[int], float], tolerance: float, k_start: int = 1, k_max: int = 4096,
                           precision: float = 0.05, stall_doublings: int = 3) -> AccurateSearch:
    """The fewest steps per frame k (the largest dt = frame/k) with ``error(k) <= tolerance``.

    Brackets by doubling k from ``k_start`` (the smallest k allowed, e.g. the one of the max
    stable dt) until accurate, then bisects on integers until (k_hi - k_lo) / k_lo <=
    ``precision`` or the two are adjacent. Assumes error(k) decreases monotonically as k grows
    (dt shrinks); NaN counts as inaccurate. The bracket gives up (``stalled``) when
    ``stall_doublings`` doublings in a row have not lowered the smallest finite e seen by 20 %:
    e has reached a floor above the tolerance and smaller dts would not help.
    """
    require(tolerance > 0, f"tolerance must be > 0, got {tolerance!r}")
    k_start = max(1, int(k_start))
    out = AccurateSearch(k=None, k_inaccurate=None)

    def ok(k: int) -> bool:
        e = float(error(k))
        out.trials.append((k, e))
        return e <= tolerance  # NaN and inf are False

    if ok(k_start):
        out.k, out.bounded = k_start, True
        return out
    lo = k_start  # inaccurate
    hi = None
    k = k_start
    best, since = out.trials[-1][1], 0
    while k < k_max:
        k = min(2 * k, k_max)
        if ok(k):
            hi = k
            break
        lo = k
        e = out.trials[-1][1]
        if math.isfinite(e) and (not math.isfinite(best) or e < best / 1.2):
            best, since = e, 0
        elif math.isfinite(best):
            since += 1
            if since >= stall_doublings:
                out.stalled = True
                break
    out.k_inaccurate = lo
    if hi is None:
        return out
    while hi - lo > 1 and (hi - lo) / lo > precision:
        mid = (lo + hi) // 2
        if ok(mid):
            hi = mid
        else:
            lo = mid
    out.k, out.k_inaccurate = hi, lo
    return out


def steps_per_frame_at_most(dt: float | None) -> int:
    """The smallest k with frame/k <= dt (1 when dt is None or at least a frame)."""
    if dt is None or dt >= FRAME_DT:
        return 1
    return max(1, math.ceil(FRAME_DT / dt - 1e-9))


# -- statics ---------------------------------------------------------------------------------
@dataclass
class StaticAccuracy:
    """The sheet run from rest to equilibrium, against the float64 equilibrium."""

    dt: float
    error: float  # max |x - x_eq| / size
    sag_error: float  # |sag - sag_ref| / sag_ref, sag = max displacement from rest
    equilibrium_reached: bool
    time_to_equilibrium: float | None  # simulated [s]
    time_to_equilibrium_wall: float | None  # wall [s]
    sim_time: float
    wall_time: float
    stable: bool


class StaticProblem:
    """The float64 static equilibrium of a sheet simulator's model, computed once."""

    def __init__(self, sim):
        eq = static_equilibrium(sim.model, sim.control)
        require(eq.residual < 1e-6, f"the float64 static equilibrium did not converge (residual {eq.residual:.3g} N)")
        self.x_eq = eq.x
        self.rest = sim.model.host["q"].astype(np.float64)
        self.size = cloth_size(sim.model)
        self.sag = float(np.max(np.linalg.norm(self.x_eq - self.rest, axis=1)))

    def measure(self, sim, dt: float, duration: float, wall_cap: float | None) -> StaticAccuracy:
        """Run ``sim`` from rest at ``dt`` to equilibrium (or ``duration`` / ``wall_cap``)."""
        sim.reset()
        sim.set_dt(dt)
        r = RunHarness(sim).run(duration, fps=60.0, stop_at_equilibrium=True, wall_cap=wall_cap)
        x = sim.state.particle_q.numpy().astype(np.float64)
        finite = bool(np.all(np.isfinite(x)))
        err = float(np.max(np.linalg.norm(x - self.x_eq, axis=1)) / self.size) if finite else math.inf
        sag = float(np.max(np.linalg.norm(x - self.rest, axis=1))) if finite else math.inf
        sag_err = abs(sag - self.sag) / self.sag if self.sag > 0 else 0.0
        return StaticAccuracy(dt=dt, error=err, sag_error=sag_err, equilibrium_reached=r.equilibrium_reached,
                              time_to_equilibrium=r.time_to_equilibrium, time_to_equilibrium_wall=r.time_to_equilibrium_wall,
                              sim_time=r.sim_time, wall_time=r.wall_time, stable=r.stable and finite)


def check_tolerance(tolerance) -> float:
    """The tolerance as a float in (0, 1), or a one-line error."""
    try:
        t = float(tolerance)
    except (TypeError, ValueError):
        raise WarpclothError(f"--tolerance must be a number in (0, 1), e.g. 0.01 for 1 %, got {tolerance!r}") from None
    if not (math.isfinite(t) and 0.0 < t < 1.0):
        raise WarpclothError(f"--tolerance must be in (0, 1) (a fraction of the cloth size, e.g. 0.01), got {tolerance!r}")
    return t


__all__ = ["AccuracyProblem", "AccurateSearch", "DEFAULT_TOLERANCE", "FRAME_DT", "StaticAccuracy", "StaticProblem",
           "Transient", "check_tolerance", "search_steps_per_frame", "steps_per_frame_at_most"]
