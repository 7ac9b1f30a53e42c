"""Accuracy of the float32 integrators against the float64 reference (design.md, "Accuracy and
the study").

* **References.** At <= 12 x 12 the SciPy DOP853 integration (:mod:`warpcloth.lab.reference`);
  above, the float64 Warp RK4 with its halving run (:mod:`warpcloth.lab.reference_warp`),
  accepted *per metric* where that metric's halving estimate is <= 1e-5 (:func:`halving_estimates`,
  :func:`reference_refusal`; DOP853 is its cross-check at <= 12 x 12). Static: the float64
  equilibrium with the contact (:func:`~warpcloth.lab.reference.contact_equilibrium`).
* **Metrics** (:func:`trajectory_metrics`, :data:`METRICS`), each a fraction of the cloth size or
  a ratio: pointwise e = max over frames and particles |x - x_ref| / size; coarse shape (the
  centre of mass, and the 4 x 4 patch means); damping (1 - the frames' kinetic energy summed over
  the window / the reference's: numerical damping, > 0 damped, < 0 energy gained); stretch (the
  run's largest strain of a structural spring against the reference's at the same instant: above
  :data:`OVERSTRETCH` "over-stretched"); static: the rest shape and the sag against the float64
  equilibrium (:data:`STATIC_METRICS`).
* **Conditioning floor** of a transient x size (:meth:`TransientProblem.floor`): the same metrics
  between the float64 reference and float64 runs from the start moved by a 1e-7 m random
  perturbation (2 seeds; the max). A verdict at tolerance t is refused where the floor exceeds
  :data:`FLOOR_FRACTION` t (:func:`refused`) or the reference is not accepted for the metric;
  then the size is judged on the first of :data:`DECIDING_METRICS` both allow.
* A trial's step is dt = (1/60 s) / k, k a whole number of steps per frame, or k = 1/2 (dt =
  1/30 s: compared every other frame).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
import warp as wp

from warpcloth.errors import WarpclothError, require
from warpcloth.lab.reference import (
    cloth_size,
    contact_equilibrium,
    reference_trajectory,
    simulate_frames,
    static_equilibrium,
    swing_from_horizontal,
    trajectory_error,
)
from warpcloth.lab.reference_warp import DEFAULT_TOLERANCE as REFERENCE_TOLERANCE
from warpcloth.lab.reference_warp import warp_reference, warp_trajectory
from warpcloth.run.harness import RunHarness
from warpcloth.sim.model import SpringType

#: The frame of every accuracy run [s]: trial dts are FRAME_DT / k.
FRAME_DT = 1.0 / 60.0
#: Default tolerance of e: 1 % of the cloth size.
DEFAULT_TOLERANCE = 0.01
#: The tolerances of the study's tables ("cheapest configuration reaching e <= ...").
TOLERANCES = (0.01, 0.05, 0.10)
#: A verdict at tolerance t is refused where the conditioning floor exceeds this fraction of t.
FLOOR_FRACTION = 0.1
#: The conditioning floor's perturbation of the start [m] (per free particle, a random direction).
PERTURBATION = 1e-7
#: Above this many particles a side the reference is the float64 Warp RK4 (below: SciPy DOP853).
SCIPY_MAX_SIZE = 12
#: The metrics of a dynamic transient (fractions of the size, but damping: a ratio, and stretch: a strain).
METRICS = ("point", "centroid", "patch", "damping", "stretch")
#: The metrics of a static one (the rest shape: a fraction of the size; the sag: relative).
STATIC_METRICS = ("rest", "sag")
#: A run whose largest structural strain exceeds the reference's at the same instant by more than
#: this (a strain) is "over-stretched", even when stable: the reference's own strain (the flag's
#: 16 % at 16x16) is the material's, not a defect.
OVERSTRETCH = 0.02
#: The metrics a verdict at a tolerance rests on, in order: the pointwise e, then where its floor
#: refuses the verdict the coarse shape (4 x 4 patch means, then the centre of mass), whose
#: floors grow more slowly with the conditioning (design.md, "One question at every size").
DECIDING_METRICS = ("point", "patch", "centroid")
#: The results.csv column of each metric's reference halving estimate (the Warp reference's
#: estimate of that metric between its last two runs; a ``floor`` row's).
REFERENCE_ESTIMATE_COLUMNS = {
    "point": "reference_estimate_rel",
    "centroid": "reference_estimate_centroid_rel",
    "patch": "reference_estimate_patch_rel",
    "damping": "reference_estimate_damping_rel",
    "stretch": "reference_estimate_stretch_rel",
}


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
        # DOP853 up to SCIPY_MAX_SIZE particles a side, the float64 Warp RK4 above (reference_for)
        require(
            transient.frames >= 1 and abs(transient.frames * FRAME_DT - transient.duration) < 1e-9,
            f"transient duration {transient.duration!r} s must be a whole number of 1/60 s frames",
        )
        self.transient = transient
        self.size = cloth_size(sim.model)
        x0 = swing_from_horizontal(sim.model) if transient.swing else sim.model.host.q.astype(np.float64)
        self.x0 = _float32_exact(x0)
        t0 = time.perf_counter()
        ref = reference_for(sim.model, sim.control, transient.frames, self.x0, rtol=rtol, atol=atol)
        self.reference, self.reference_estimate = ref.frames, ref.estimate
        self.reference_seconds = time.perf_counter() - t0

    def run(self, sim, k: int) -> np.ndarray:
        """The float32 trajectory of ``sim`` (its current integrator) at dt = frame/k, from the
        transient's start: (frames + 1, N, 3)."""
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
        self.rest = sim.model.host.q.astype(np.float64)
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
        return StaticAccuracy(
            dt=dt,
            error=err,
            sag_error=sag_err,
            equilibrium_reached=r.equilibrium_reached,
            time_to_equilibrium=r.time_to_equilibrium,
            time_to_equilibrium_wall=r.time_to_equilibrium_wall,
            sim_time=r.sim_time,
            wall_time=r.wall_time,
            stable=r.stable and finite,
        )


# -- references ----------------------------------------------------------------------------
@dataclass
class Reference:
    """A float64 reference trajectory: frames (frames + 1, N, 3); estimate: its error estimate
    as a fraction of the size (the Warp halving estimate; DOP853: None, its tolerances are 1e-10);
    accepted: the pointwise estimate is within the Warp reference's tolerance; method; dt: the
    step of the Warp run [s]; piece_steps: its steps per piece (for :meth:`TransientProblem.floor`'s
    runs); estimates: the pointwise estimate of every halving; metric_estimates: each metric's
    halving estimate of the last halving (:func:`halving_estimates`; empty for DOP853)."""

    frames: np.ndarray
    estimate: float | None
    accepted: bool
    method: str
    dt: float | None = None
    piece_steps: tuple = ()
    estimates: tuple = ()
    metric_estimates: dict = field(default_factory=dict)

    def estimate_of(self, metric: str) -> float | None:
        """The halving estimate of ``metric`` (None for DOP853; the pointwise one where the
        metric's was not computed: it bounds the centroid's and the patches')."""
        if self.method == "DOP853":
            return None
        return self.estimate if metric == "point" else self.metric_estimates.get(metric, self.estimate)

    def accepted_for(self, metric: str) -> bool:
        """Whether the reference is accepted for ``metric``: DOP853, or its halving estimate <=
        the Warp reference's tolerance (1e-5)."""
        e = self.estimate_of(metric)
        return self.method == "DOP853" or (e is not None and e <= REFERENCE_TOLERANCE)


def reference_for(model, control, frames: int, x0, rtol: float = 1e-10, atol: float = 1e-12) -> Reference:
    """The float64 reference of ``frames`` 1/60 s frames from ``x0`` (at rest): SciPy DOP853 up to
    :data:`SCIPY_MAX_SIZE` particles a side, the float64 Warp RK4 with its halving run above
    with at most one more halving (not accepted then: returned with ``accepted`` False, its
    estimates saying by how much; a window that needs more is ill-conditioned, and its floor says so).
    Each metric's halving estimate is kept (``metric_estimates``): a chaotic window's pointwise
    estimate is the chaos-amplified difference of two runs and never converges, while its centre
    of mass or patch means may (:meth:`Reference.accepted_for`)."""
    n = max(int(model.rows or 0), int(model.cols or 0)) or int(round(math.sqrt(model.particle_count)))
    if n <= SCIPY_MAX_SIZE:
        return Reference(
            reference_trajectory(model, control, frames * FRAME_DT, FRAME_DT, x0=x0, rtol=rtol, atol=atol),
            None,
            True,
            "DOP853",
        )

    r = warp_reference(
        model,
        control,
        frames * FRAME_DT,
        FRAME_DT,
        x0=x0,
        max_halvings=1,
        require_accepted=False,
        metrics=halving_estimates(_Shape(model), cloth_size(model)),
    )
    last = r.metric_estimates[-1] if r.metric_estimates else None
    per_metric = dict.fromkeys(METRICS, math.inf) if last is None else dict(last)
    return Reference(
        r.frames, r.relative_estimate, r.accepted, "Warp RK4", r.dt, r.piece_steps, tuple(r.estimates), per_metric
    )


def _perturbed(model, x0: np.ndarray, seed: int) -> np.ndarray:
    """x0 with every free particle moved by :data:`PERTURBATION` in a random direction."""
    rng = np.random.default_rng(seed)
    d = rng.normal(size=x0.shape)
    d *= PERTURBATION / np.linalg.norm(d, axis=1, keepdims=True)
    d[model.host.inv_mass <= 0] = 0.0
    d[np.asarray(model.pinned, dtype=np.int64)] = 0.0
    return x0 + d


# -- metrics -------------------------------------------------------------------------------
def sample_stride(k: float) -> tuple[int, int]:
    """(reference frames per sample, steps per sample) of a run at dt = (1/60 s) / k."""
    if k >= 1:
        require(abs(k - round(k)) < 1e-9, f"steps per frame must be whole or 1/2, got {k!r}")
        return 1, int(round(k))
    m = round(1.0 / k)
    require(m >= 1 and abs(m * k - 1.0) < 1e-9, f"steps per frame below 1 must be 1/m, got {k!r}")
    return m, 1


class _Shape:
    """What the metrics need of a grid model: masses, the 4 x 4 patches, the membrane springs."""

    def __init__(self, model):
        h = model.host
        self.mass = h.mass.astype(np.float64)
        rows, cols = int(model.rows or 0), int(model.cols or 0)
        if rows * cols == model.particle_count and rows >= 1:
            grid = np.arange(rows * cols).reshape(rows, cols)
            self.patches = [
                grid[np.ix_(r, c)].ravel()
                for r in np.array_split(np.arange(rows), min(4, rows))
                for c in np.array_split(np.arange(cols), min(4, cols))
            ]
        else:
            self.patches = [np.arange(model.particle_count)]

        pairs = h.pairs.astype(np.int64).reshape(-1, 2)
        # stretch along the warp and the weft: structural springs (a shear spring's strain is the
        # cloth's shear, which a soft-shear fabric takes freely: the flag's diagonals strain 16 %)
        keep = np.asarray(model.spring_type) == int(SpringType.STRUCTURAL)
        self.pairs = pairs[keep]
        self.rest = h.rest.astype(np.float64)[keep]

    def centroid(self, x):  # (F, N, 3) -> (F, 3)
        return np.einsum("n,fnk->fk", self.mass, x) / self.mass.sum()

    def patch_means(self, x):  # (F, N, 3) -> (F, P, 3)
        return np.stack(
            [np.einsum("n,fnk->fk", self.mass[p], x[:, p]) / self.mass[p].sum() for p in self.patches], axis=1
        )

    def kinetic(self, x, interval: float):  # frame-difference kinetic energy per interval (F - 1,)
        v = np.diff(x, axis=0) / interval
        return 0.5 * np.einsum("n,fnk,fnk->f", self.mass, v, v)

    def strain_history(self, x):  # (F, N, 3) -> (F,): the largest structural strain of each frame
        if not len(self.pairs):
            return np.zeros(len(x))
        d = x[:, self.pairs[:, 1]] - x[:, self.pairs[:, 0]]
        return np.max(np.linalg.norm(d, axis=-1) / self.rest[None] - 1.0, axis=1)

    def max_strain(self, x) -> float:
        return float(np.max(self.strain_history(x)))


def trajectory_metrics(traj, ref, size: float, shape: _Shape, interval: float) -> dict:
    """The metrics (:data:`METRICS`) of ``traj`` against ``ref``, both (F, N, 3) at the same
    times ``interval`` [s] apart: point, centroid, patch (fractions of ``size``), damping (1 - sum
    of the kinetic energy / the reference's; numerical damping) and stretch (``traj``'s largest
    strain of a structural spring: stretch along the warp or the weft); plus ``stretch_ref`` (the
    reference's) and ``stretch_excess`` (max over frames of the run's largest strain minus the
    reference's at the same frame: 0 for the reference itself, > 0 where the run over-stretches)."""
    a = np.asarray(traj, dtype=np.float64)
    b = np.asarray(ref, dtype=np.float64)
    require(a.shape == b.shape, f"trajectories differ in shape: {a.shape} vs {b.shape}")
    ke, ke_ref = shape.kinetic(a, interval), shape.kinetic(b, interval)
    strain, strain_ref = shape.strain_history(a), shape.strain_history(b)
    return {
        "point": float(np.max(np.linalg.norm(a - b, axis=-1)) / size),
        "centroid": float(np.max(np.linalg.norm(shape.centroid(a) - shape.centroid(b), axis=-1)) / size),
        "patch": float(np.max(np.linalg.norm(shape.patch_means(a) - shape.patch_means(b), axis=-1)) / size),
        "damping": float(1.0 - ke.sum() / ke_ref.sum()) if ke_ref.sum() > 0 else 0.0,
        "stretch": float(np.max(strain)),
        "stretch_ref": float(np.max(strain_ref)),
        "stretch_excess": float(np.max(strain - strain_ref)),
    }


def floor_of(metrics: dict) -> dict:
    """The conditioning floor of each metric from a perturbed run's :func:`trajectory_metrics`:
    the metric itself, |damping|, and the largest change of the largest strain at one instant."""
    out = {k: abs(metrics[k]) for k in ("point", "centroid", "patch", "damping")}
    out["stretch"] = max(abs(metrics["stretch"] - metrics["stretch_ref"]), abs(metrics.get("stretch_excess", 0.0)))
    return out


def halving_estimates(shape: _Shape, size: float):
    """The function (coarse frames, fine frames) -> each metric's halving estimate: the metrics
    of two float64 runs against each other, as a floor is (:func:`floor_of`: the metric itself,
    |damping|, the change of the largest strain); inf for every metric where a run is not finite."""

    def estimate(coarse: np.ndarray, fine: np.ndarray) -> dict:
        if not (np.all(np.isfinite(coarse)) and np.all(np.isfinite(fine))):
            return dict.fromkeys(METRICS, math.inf)
        return floor_of(trajectory_metrics(coarse, fine, size, shape, FRAME_DT))

    return estimate


def reference_estimate(row: dict, metric: str) -> float | None:
    """The halving estimate of ``metric`` from a results.csv ``floor`` row
    (:data:`REFERENCE_ESTIMATE_COLUMNS`). A row written before the per-metric estimates (no such
    column, or empty) gives the pointwise estimate: for the centroid and the patches a bound (a
    mass-weighted mean moves no more than its farthest particle), for damping and stretch the
    rule those rows were judged by."""
    value = row.get(REFERENCE_ESTIMATE_COLUMNS[metric])
    return row.get("reference_estimate_rel") if value is None else value


def reference_refusal(row: dict, transient: str, metric: str, name: str | None = None) -> str:
    """Why the reference of a results.csv ``floor`` row is not accepted for ``metric`` (``name``:
    what people call it) ("" where it is: DOP853, or the metric's halving estimate <=
    :data:`REFERENCE_TOLERANCE`)."""
    if row.get("reference") == "DOP853":
        return ""
    e = reference_estimate(row, metric)
    if e is not None and math.isfinite(e) and e <= REFERENCE_TOLERANCE:
        return ""
    shown = "unknown" if e is None else f"{e:.2g}"
    return (
        f"the {transient} reference is not accepted for the {name or metric} (its halving estimate {shown} > "
        f"{REFERENCE_TOLERANCE:g})"
    )


def refused(floor, tolerance: float) -> bool:
    """Whether a verdict at ``tolerance`` is refused: a floor above :data:`FLOOR_FRACTION` of it
    (or unknown)."""
    return floor is None or not math.isfinite(floor) or floor > FLOOR_FRACTION * tolerance


def deciding_metric(floors: dict, tolerance: float, estimates: dict | None = None) -> str | None:
    """The metric a verdict at ``tolerance`` rests on: the first of :data:`DECIDING_METRICS` whose
    floor (``floors``: metric -> floor) does not refuse it (:func:`refused`) and, with
    ``estimates`` (metric -> the Warp reference's halving estimate), for which the reference is
    accepted (<= :data:`REFERENCE_TOLERANCE`); None when none is. The window is never shortened
    instead: that would change the question, not the precision."""
    for metric in DECIDING_METRICS:
        e = None if estimates is None else estimates.get(metric)
        if estimates is not None and not (e is not None and e <= REFERENCE_TOLERANCE):
            continue
        if not refused(floors.get(metric), tolerance):
            return metric
    return None


def over_stretched(excess) -> bool:
    """Whether a run's strain excess over the reference (``stretch_excess``) exceeds :data:`OVERSTRETCH`."""
    return excess is not None and math.isfinite(excess) and excess > OVERSTRETCH


@dataclass
class RunMetrics:
    """One float32 run against the reference: its metrics (None where it was not finite or stopped
    by the wall cap), whether it stayed finite, its wall time [s], and a note."""

    metrics: dict | None
    stable: bool
    wall: float
    note: str = ""


class TransientProblem:
    """A dynamic transient (:class:`~warpcloth.lab.transients.StudyTransient`) of ``frames`` 1/60 s
    frames on one simulator's model: the float64 reference (:func:`reference_for`), computed once
    (or given: ``reference``, e.g. from a cache), :meth:`measure` for any configuration, and
    :meth:`floor`."""

    def __init__(self, sim, transient, frames: int, reference: Reference | None = None):
        require(
            int(frames) >= 2 and int(frames) % 2 == 0,
            f"a transient's window must be an even number of frames >= 2 "
            f"(dt = 1/30 s runs compare every other frame), got {frames!r}",
        )
        self.transient = transient
        self.frames = int(frames)
        self.size = cloth_size(sim.model)
        self.x0 = transient.start(sim.model)
        self.shape = _Shape(sim.model)
        t0 = time.perf_counter()
        self.ref = reference if reference is not None else reference_for(sim.model, sim.control, self.frames, self.x0)
        self.reference_seconds = time.perf_counter() - t0

    @property
    def reference(self) -> np.ndarray:
        return self.ref.frames

    def run(self, sim, k: float, wall_cap: float | None = None) -> tuple:
        """The float32 trajectory of ``sim`` (its current integrator) at dt = (1/60 s)/k from the
        start, sampled every stride frames: ((samples, N, 3) or None if stopped by ``wall_cap``
        [s], wall seconds)."""
        stride, steps = sample_stride(k)
        sim.reset()
        sim.state.particle_q.assign(wp.array(self.x0.astype(np.float32), dtype=wp.vec3, device=sim.model.device))
        sim.set_dt(FRAME_DT / k)
        out = [sim.state.particle_q.numpy().astype(np.float64)]
        t0 = time.perf_counter()
        for _ in range(self.frames // stride):
            sim.simulate(steps)
            x = sim.state.particle_q.numpy().astype(np.float64)
            out.append(x)
            if not np.all(np.isfinite(x)):
                return np.stack(out + [x] * (self.frames // stride + 1 - len(out))), time.perf_counter() - t0
            if wall_cap is not None and time.perf_counter() - t0 > wall_cap:
                return None, time.perf_counter() - t0
        return np.stack(out), time.perf_counter() - t0

    def measure(self, sim, k: float, wall_cap: float | None = None) -> RunMetrics:
        """The metrics of ``sim``'s integrator at dt = (1/60 s)/k (:func:`trajectory_metrics`)."""
        traj, wall = self.run(sim, k, wall_cap)
        if traj is None:
            return RunMetrics(None, True, wall, f"stopped by the wall cap ({wall_cap:g} s) before the window's end")
        if not np.all(np.isfinite(traj)):
            return RunMetrics(None, False, wall, "unstable: the state went non-finite")
        stride, _ = sample_stride(k)
        return RunMetrics(
            trajectory_metrics(traj, self.reference[::stride], self.size, self.shape, FRAME_DT * stride), True, wall
        )

    def floor(self, sim, seeds=(0, 1)) -> dict:
        """The conditioning floor: per metric, the max over ``seeds`` of its value between the
        reference and a float64 run from the start perturbed by :data:`PERTURBATION` (the same
        integrator as the reference, at its steps)."""
        out = {}
        for seed in seeds:
            x0 = _perturbed(sim.model, self.x0, seed)
            if self.ref.method == "DOP853":
                traj = reference_trajectory(sim.model, sim.control, self.frames * FRAME_DT, FRAME_DT, x0=x0)
            else:
                traj = warp_trajectory(
                    sim.model, sim.control, self.frames * FRAME_DT, FRAME_DT, x0=x0, piece_steps=self.ref.piece_steps
                )
            f = floor_of(trajectory_metrics(traj, self.reference, self.size, self.shape, FRAME_DT))
            out = {k: max(out.get(k, 0.0), v) for k, v in f.items()}
        return out


class ContactProblem:
    """The contact transient: the float64 equilibrium with the contact
    (:func:`~warpcloth.lab.reference.contact_equilibrium`), computed once (or given), and
    :meth:`measure`: a float32 run from the transient's start until at rest, its rest shape and
    sag against it."""

    def __init__(self, sim, transient, x_eq: np.ndarray | None = None):
        self.transient = transient
        self.size = cloth_size(sim.model)
        self.x0 = transient.start(sim.model)
        self.rest = sim.model.host.q.astype(np.float64)
        t0 = time.perf_counter()
        self.kappa = None
        if x_eq is None:
            eq = contact_equilibrium(sim.model, sim.control)
            x_eq, self.kappa = eq.x, eq.kappa
        self.x_eq = np.asarray(x_eq, dtype=np.float64)
        self.reference_seconds = time.perf_counter() - t0
        self.sag = float(np.max(np.linalg.norm(self.x_eq - self.rest, axis=1)))

    def metrics(self, x: np.ndarray) -> dict:
        """rest: max |x - x_eq| / size; sag: |sag - sag_eq| / sag_eq (sag: the largest displacement
        from the hanging rest shape)."""
        sag = float(np.max(np.linalg.norm(x - self.rest, axis=1)))
        return {
            "rest": float(np.max(np.linalg.norm(x - self.x_eq, axis=1)) / self.size),
            "sag": abs(sag - self.sag) / self.sag if self.sag > 0 else 0.0,
        }

    def floor(self, sim, seeds=(0, 1)) -> dict:
        """The floor of the static metrics: the equilibrium solved again from itself moved by
        :data:`PERTURBATION` (2 seeds): a unique equilibrium comes back to within the solver's tolerance."""
        out = {}
        for seed in seeds:
            eq = contact_equilibrium(
                sim.model, sim.control, x0=_perturbed(sim.model, self.x_eq, seed), kappa=self.kappa
            )
            out = {k: max(out.get(k, 0.0), v) for k, v in self.metrics(eq.x).items()}
        return out

    def measure(self, sim, k: float, duration: float, wall_cap: float | None) -> StaticAccuracy:
        """Run ``sim`` from the start at dt = (1/60 s)/k until at rest (or ``duration`` simulated,
        ``wall_cap`` wall seconds); the error of where it stops."""
        sim.reset()
        sim.state.particle_q.assign(wp.array(self.x0.astype(np.float32), dtype=wp.vec3, device=sim.model.device))
        sim.set_dt(FRAME_DT / k)
        r = RunHarness(sim).run(duration, fps=60.0, stop_at_equilibrium=True, wall_cap=wall_cap)
        x = sim.state.particle_q.numpy().astype(np.float64)
        finite = bool(np.all(np.isfinite(x)))
        m = self.metrics(x) if finite else {"rest": math.inf, "sag": math.inf}
        return StaticAccuracy(
            dt=FRAME_DT / k,
            error=m["rest"],
            sag_error=m["sag"],
            equilibrium_reached=r.equilibrium_reached,
            time_to_equilibrium=r.time_to_equilibrium,
            time_to_equilibrium_wall=r.time_to_equilibrium_wall,
            sim_time=r.sim_time,
            wall_time=r.wall_time,
            stable=r.stable and finite,
        )


def check_tolerance(tolerance) -> float:
    """The tolerance as a float in (0, 1), or a one-line error."""
    try:
        t = float(tolerance)
    except (TypeError, ValueError):
        raise WarpclothError(f"--tolerance must be a number in (0, 1), e.g. 0.01 for 1 %, got {tolerance!r}") from None
    if not (math.isfinite(t) and 0.0 < t < 1.0):
        raise WarpclothError(
            f"--tolerance must be in (0, 1) (a fraction of the cloth size, e.g. 0.01), got {tolerance!r}"
        )
    return t


__all__ = [
    "DECIDING_METRICS",
    "DEFAULT_TOLERANCE",
    "FLOOR_FRACTION",
    "FRAME_DT",
    "METRICS",
    "OVERSTRETCH",
    "PERTURBATION",
    "REFERENCE_ESTIMATE_COLUMNS",
    "REFERENCE_TOLERANCE",
    "SCIPY_MAX_SIZE",
    "STATIC_METRICS",
    "TOLERANCES",
    "AccuracyProblem",
    "ContactProblem",
    "Reference",
    "RunMetrics",
    "StaticAccuracy",
    "StaticProblem",
    "Transient",
    "TransientProblem",
    "check_tolerance",
    "deciding_metric",
    "halving_estimates",
    "over_stretched",
    "reference_estimate",
    "reference_for",
    "reference_refusal",
    "refused",
    "sample_stride",
    "steps_per_frame_at_most",
    "trajectory_metrics",
]
