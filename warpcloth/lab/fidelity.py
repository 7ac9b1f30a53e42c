"""Fidelity of a scene's integrator configuration (design.md, "Fidelity rule"): does it reproduce its material?

:func:`measure_fidelity` runs a scenario to rest on the CPU with a configuration, then solves the float64
static equilibrium of the same model with its contacts from that rest (so the same folds): Newton on
springs, hinges and gravity (``lab.reference.minimize``) with a frictionless penalty on every sphere,
plane and rounded box, kappa raised until nothing is 1e-6 of the size inside; the wind at rest a load
iterated to a fixed point. A particle resting on a collider or on another layer is held where it lies
(static friction: a frictionless cloth slides off the sphere); the rest is solved for.

Reported: the shape error max |x - x_eq| / size, the largest structural strain of a spring with a moving
particle against the equilibrium's, the peak strain in motion, capped steps, and CPU ms per 1/60 s frame
(:func:`~warpcloth.run.harness.time_steps` at rest, contacts on). :attr:`Fidelity.failures` applies the
rule: at rest; shape <= :data:`SHAPE_TOLERANCE`; strain <= :data:`STRAIN_RATIO` x the equilibrium's
(plus what float32 positions resolve, :func:`strain_resolution`); peak strain in motion at most
:data:`~warpcloth.lab.accuracy.OVERSTRETCH` above the equilibrium's or, where measured, the converged
dynamics' peak (:data:`MOTION_REFERENCE`); no capped step. A scene whose wind never lets it rest (the
cape flaps in its breeze) is measured with ``still_air``: at rest with its wind stilled, in motion in its wind
too. ``python bench/fidelity.py`` prints the table of docs/materials.md.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from warpcloth.errors import WarpclothError, require
from warpcloth.lab.accuracy import OVERSTRETCH
from warpcloth.lab.reference import Float64Model, Penalty, cloth_size, minimize, scatter_add
from warpcloth.run.harness import RunHarness, time_steps
from warpcloth.scenarios import get_scenario
from warpcloth.sim.colliders import Box, Plane, Sphere, auto_edge_radius, quat_matrix
from warpcloth.sim.control import WindSchedule
from warpcloth.sim.hinges import hinge_angle_gradients, hinge_energies, wrap_angle
from warpcloth.sim.model import SpringType

#: The rule: the rest shape within this fraction of the cloth's size of the float64 equilibrium's.
SHAPE_TOLERANCE = 0.02
#: The rule: the largest strain at rest at most this times the float64 equilibrium's.
STRAIN_RATIO = 1.5
#: The equilibrium's contacts: no particle deeper than this fraction of the size inside a collider.
PENETRATION = 1e-6
#: Hinge models are solved with a finite-difference Hessian of the hinge forces: up to this many particles.
MAX_HINGE_PARTICLES = 400
#: The converged dynamics whose peak strain in motion a run's is held to where it exceeds the equilibrium's
#: by more than OVERSTRETCH: xpbd with one iteration a substep and 128 substeps a 1/60 s frame (the issue's
#: 1 x 64 came within 0.1 % of explicit Euler at dt 6e-5 on the 64 x 64 drape: 3.0 % vs 3.1 %).
MOTION_REFERENCE = ("xpbd", {"iterations": 1, "substeps": 128})
#: A particle at rest within this of a collider's contact surface [m] rests on it (:func:`held_particles`).
CONTACT_GAP = 5e-4


class _Boxes:
    """Frictionless contact with rounded boxes (as the kernels' ``rounded_box_contact``): the box grown
    by its thickness and capsules of R = thickness + rounding along its 12 edges; the penalty energy
    1/2 kappa phi^2 of the deepest term, phi = max(thickness - d_box, R - d_edge) where > 0."""

    def __init__(self, boxes, kappa: float, auto_radius: float):
        self.kappa = float(kappa)
        self.boxes = [
            (
                np.asarray(b.center, dtype=np.float64),
                quat_matrix(b.rotation),
                np.asarray(b.half_extents, dtype=np.float64),
                float(b.thickness),
                float(b.thickness) + b.rounding(auto_radius),
            )
            for b in boxes
        ]

    def terms(self, x: np.ndarray):
        """Per box: (phi (N,) >= 0, outward normal (N, 3), the distance's projector P (N, 3, 3), 1 / d (N,))."""
        out = []
        for c, rot, half, thick, radius in self.boxes:
            p = (x - c) @ rot  # the box's frame: R^T (x - c)
            s = np.where(p < 0.0, -1.0, 1.0)
            u = np.abs(p)
            best_w = np.maximum(u - half, 0.0)  # the box term: the offset from the box (0 inside)
            best_phi = thick - np.linalg.norm(best_w, axis=1)
            best_mask = best_w > 0.0
            for i in range(3):  # the capsule along axis i (at +half in the two other axes)
                w = u - half
                w[:, i] = np.maximum(w[:, i], 0.0)
                mask = np.ones_like(w, dtype=bool)
                mask[:, i] = u[:, i] > half[i]
                phi = radius - np.linalg.norm(w, axis=1)
                better = phi > best_phi
                best_phi = np.where(better, phi, best_phi)
                best_w = np.where(better[:, None], w, best_w)
                best_mask = np.where(better[:, None], mask, best_mask)
            d = np.linalg.norm(best_w, axis=1)
            inv_d = np.where(d > 0.0, 1.0 / np.where(d > 0.0, d, 1.0), 0.0)
            nrm = (s * best_w * inv_d[:, None]) @ rot.T
            proj = np.einsum("ij,nj,kj->nik", rot, best_mask.astype(np.float64), rot)  # R diag(mask) R^T
            out.append((np.maximum(best_phi, 0.0), nrm, proj, inv_d, best_phi))
        return out

    def energy(self, x) -> float:
        return float(sum(0.5 * self.kappa * np.sum(t[0] ** 2) for t in self.terms(x)))

    def forces(self, x) -> np.ndarray:
        f = np.zeros_like(x)
        for phi, nrm, _, _, _ in self.terms(x):
            f += self.kappa * phi[:, None] * nrm
        return f

    def penetration(self, x) -> float:
        return float(max((t[0].max() for t in self.terms(x)), default=0.0))

    def hessian(self, x) -> sp.csr_matrix:
        """d^2 E / dx^2 = kappa (n n^T - phi (P - n n^T) / d) on the particles in contact."""
        blocks, index = [], []
        for phi, nrm, proj, inv_d, _ in self.terms(x):
            a = np.nonzero(phi > 0)[0]
            nn = nrm[a, :, None] * nrm[a, None, :]
            blocks.append(self.kappa * (nn - (phi[a] * inv_d[a])[:, None, None] * (proj[a] - nn)))
            index.append(a)
        return _block_diagonal(blocks, index, x.size)


def _block_diagonal(blocks, index, n_dof: int) -> sp.csr_matrix:
    rows, cols, vals = [], [], []
    r3 = np.arange(3)
    for blk, a in zip(blocks, index, strict=True):
        if a.size:
            rows.append(np.broadcast_to(3 * a[:, None, None] + r3[None, :, None], blk.shape).ravel())
            cols.append(np.broadcast_to(3 * a[:, None, None] + r3[None, None, :], blk.shape).ravel())
            vals.append(blk.ravel())
    if not rows:
        return sp.csr_matrix((n_dof, n_dof))
    return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n_dof, n_dof))


class _Hinges:
    """The dihedral hinges' energy sum 1/2 k_e wrap(theta - theta0)^2 (float64, sim.hinges), its forces and a
    central-difference Hessian of them (a strip's few hundred degrees of freedom)."""

    def __init__(self, hinges, n: int, size: float):
        self.hinges, self.n, self.step = hinges, n, 1e-7 * size

    def energy(self, x) -> float:
        return float(np.sum(hinge_energies(x, self.hinges)))

    def forces(self, x) -> np.ndarray:
        theta, g, valid = hinge_angle_gradients(x, self.hinges.indices)
        torque = np.where(valid, self.hinges.stiffness * wrap_angle(theta - self.hinges.rest_angle), 0.0)
        f = np.zeros((self.n, 3))
        q = np.asarray(self.hinges.indices, dtype=np.int64).reshape(-1, 4)
        for k in range(4):
            scatter_add(f, q[:, k], -torque[:, None] * g[:, k])
        return f

    def penetration(self, x) -> float:
        return 0.0

    def hessian(self, x) -> sp.csr_matrix:
        cols = []
        for k in range(x.size):
            plus, minus = x.copy(), x.copy()
            plus.ravel()[k] += self.step
            minus.ravel()[k] -= self.step
            cols.append(-(self.forces(plus) - self.forces(minus)).ravel() / (2.0 * self.step))
        h = np.stack(cols, axis=1)
        return sp.csr_matrix(0.5 * (h + h.T))


class _Load:
    """A constant force per particle (N, 3) [N] as the energy -sum f . x: the wind at rest, held fixed."""

    def __init__(self, f: np.ndarray):
        self.f = f

    def energy(self, x) -> float:
        return -float(np.sum(self.f * x))

    def forces(self, x) -> np.ndarray:
        return self.f.copy()

    def penetration(self, x) -> float:
        return 0.0

    def hessian(self, x) -> sp.csr_matrix:
        return sp.csr_matrix((x.size, x.size))


class _Sum:
    """Several energy terms as one penalty of ``reference.minimize``."""

    def __init__(self, parts):
        self.parts = parts

    def energy(self, x) -> float:
        return float(sum(p.energy(x) for p in self.parts))

    def forces(self, x) -> np.ndarray:
        return sum((p.forces(x) for p in self.parts), np.zeros_like(x))

    def penetration(self, x) -> float:
        return max((p.penetration(x) for p in self.parts), default=0.0)

    def hessian(self, x) -> sp.csr_matrix:
        return sum((p.hessian(x) for p in self.parts), sp.csr_matrix((x.size, x.size)))


@dataclass
class RestEquilibrium:
    """The float64 equilibrium of :func:`rest_equilibrium`: positions x (N, 3) [m], ``moving`` (N,): the
    particles it solved for (not pinned, not held), the largest net force on one of them [N], the deepest
    penetration [m] and the last penalty stiffness [N/m]."""

    x: np.ndarray
    moving: np.ndarray
    residual: float
    penetration: float
    kappa: float


def held_particles(sim, x: np.ndarray) -> np.ndarray:
    """(N,) True where a particle at rest at ``x`` rests on something: within :data:`CONTACT_GAP` of a
    collider's contact surface, or within twice the self-collision thickness of a particle of another
    layer (one farther than that at rest). Friction holds these where they are."""
    x = np.asarray(x, dtype=np.float64)
    gap = np.full(x.shape[0], np.inf)
    for c in sim.control.colliders:
        if isinstance(c, Sphere):
            gap = np.minimum(gap, np.linalg.norm(x - np.asarray(c.center), axis=1) - c.radius - c.thickness)
        elif isinstance(c, Plane):
            nrm = np.asarray(c.normal, dtype=np.float64) / np.linalg.norm(c.normal)
            gap = np.minimum(gap, (x - np.asarray(c.point)) @ nrm - c.thickness)
    boxes = [c for c in sim.control.colliders if isinstance(c, Box)]
    if boxes:
        auto = auto_edge_radius(sim.model.host.q, sim.model.host.tris)
        for t in _Boxes(boxes, 1.0, auto).terms(x):
            gap = np.minimum(gap, -t[4])
    held = gap <= CONTACT_GAP
    sc = sim.self_collision
    if sc is not None:
        r = 2.0 * sc.thickness
        pairs = cKDTree(x).query_pairs(r, output_type="ndarray")
        if len(pairs):
            q = sim.model.host.q.astype(np.float64)
            far = np.linalg.norm(q[pairs[:, 0]] - q[pairs[:, 1]], axis=1) > 2.0 * r
            held[pairs[far].ravel()] = True
    return held


def rest_equilibrium(sim, x0: np.ndarray, t: float = 0.0) -> RestEquilibrium:
    """The float64 static equilibrium of ``sim``'s model (springs, hinges, gravity; the wind at time ``t``
    at rest) from its rest ``x0`` (N, 3): the particles that rest on something (:func:`held_particles`)
    held where they are (static friction; a frictionless reference slides off a sphere), the others
    solved for, kept out of the control's spheres, planes and boxes by a frictionless penalty."""
    model, control = sim.model, sim.control
    m64 = Float64Model.from_model(model.with_hinges(None) if model.hinge_count else model, control)
    x = np.asarray(x0, dtype=np.float64).copy()
    m64 = replace(m64, free=m64.free & ~held_particles(sim, x))
    size = cloth_size(model)
    hinges = None
    if model.hinge_count:
        require(
            m64.particle_count <= MAX_HINGE_PARTICLES,
            f"a hinge model's equilibrium is solved up to {MAX_HINGE_PARTICLES} particles, not {m64.particle_count}",
        )
        hinges = _Hinges(model.host.hinges, m64.particle_count, size)
    round_colliders, boxes = [], []
    for c in control.colliders:
        if isinstance(c, Box):
            boxes.append(c)
        elif isinstance(c, (Sphere, Plane)):
            round_colliders.append(c)
        else:
            raise WarpclothError(f"the fidelity equilibrium supports spheres, planes and boxes, not {type(c).__name__}")
    auto = auto_edge_radius(model.host.q, model.host.tris)
    kappa = 100.0 * max(1.0, float(m64.ks.max()) if m64.ks.size else 1.0)
    for _outer in range(40 if m64.wind_on else 1):
        parts = [hinges] if hinges is not None else []
        if m64.wind_on:
            fw = m64.wind_forces(x, np.zeros_like(x), m64.wind(t))
            f = np.zeros_like(x)
            for k in range(3):
                scatter_add(f, m64.tris[:, k], fw)
            parts.append(_Load(f))
        start = x.copy()
        for _ in range(20):
            terms = _Sum([*parts, Penalty(round_colliders, kappa), _Boxes(boxes, kappa, auto)])
            eq = minimize(m64, x, terms, max(1e-9, 1e-14 * kappa * size), 200)
            x = eq.x
            depth = float(max((terms.penetration(x[m64.free]) if m64.free.any() else 0.0), 0.0))
            if depth <= PENETRATION * size:
                break
            kappa *= 10.0
        if float(np.max(np.linalg.norm(x - start, axis=1))) <= 1e-7 * size:
            break
    return RestEquilibrium(x, m64.free, eq.residual, depth, kappa)


def structural_strain(model, x, moving=None) -> float:
    """The largest strain (L - L0) / L0 of a structural spring (the warp and weft) at positions ``x``; with
    ``moving`` (N,), of those with a moving particle only."""
    keep = np.asarray(model.spring_type) == int(SpringType.STRUCTURAL)
    pairs = model.host.pairs.astype(np.int64).reshape(-1, 2)
    if moving is not None:
        keep &= np.asarray(moving)[pairs].any(axis=1)
    pairs = pairs[keep]
    rest = model.host.rest.astype(np.float64)[keep]
    d = np.asarray(x, dtype=np.float64)[pairs[:, 1]] - np.asarray(x, dtype=np.float64)[pairs[:, 0]]
    return float(np.max(np.linalg.norm(d, axis=1) / rest - 1.0))


def strain_resolution(model, x) -> float:
    """The strain float32 positions resolve [-]: two roundings of a coordinate (2^-24 |x|, |x| the largest)
    over the shortest structural rest length; a strain ratio below it is noise (the cantilever's 1e-5)."""
    keep = np.asarray(model.spring_type) == int(SpringType.STRUCTURAL)
    rest = float(np.min(model.host.rest[keep]))
    return 2.0 * 2.0**-24 * float(np.max(np.abs(x))) / rest


class _PiecePeaks:
    """A frame sink keeping each piece's largest structural strain over a run's frames (a model of several
    garments: the character's cape and skirt)."""

    def __init__(self, model):
        self.model, n = model, model.particle_count
        self.masks = {}
        for piece in model.pieces:
            mask = np.zeros(n, dtype=bool)
            mask[piece.particle_offset : piece.particle_offset + piece.particle_count] = True
            self.masks[piece.name] = mask
        self.peaks = dict.fromkeys(self.masks, -math.inf)

    def write_frame(self, points, sim_time=None) -> None:
        for name, mask in self.masks.items():
            self.peaks[name] = max(self.peaks[name], structural_strain(self.model, points, mask))


class _PeakStrain:
    """A frame sink keeping the largest structural strain over a run's frames."""

    def __init__(self, model):
        self.model, self.peak = model, -math.inf

    def write_frame(self, points, sim_time=None) -> None:
        self.peak = max(self.peak, structural_strain(self.model, points))


@dataclass
class Fidelity:
    """One scene x configuration of :func:`measure_fidelity` (strains are (L - L0) / L0; shape a fraction
    of the cloth's size; ``ms_frame`` CPU ms per 1/60 s frame at rest)."""

    scene: str
    integrator: str
    options: dict
    dt: float
    particles: int
    stable: bool
    at_rest: bool
    rest_time: float
    capped_steps: int
    strain_capped_steps: int
    capped_cause: str
    strain: float = math.nan
    strain_eq: float = math.nan
    shape: float = math.nan
    peak_strain: float = math.nan
    ms_frame: float = math.nan
    residual: float = math.nan
    peak_reference: float = math.nan
    strain_resolution: float = 0.0
    solve_s: float = 0.0
    extra: dict = field(default_factory=dict)

    @property
    def strain_ratio(self) -> float:
        return self.strain / self.strain_eq if self.strain_eq > 0.0 else math.inf

    @property
    def stretch_excess(self) -> float:
        """The peak strain in motion less the reference's: the equilibrium's, or where measured the larger
        peak of the converged dynamics (:data:`MOTION_REFERENCE`)."""
        ref = self.strain_eq if math.isnan(self.peak_reference) else max(self.strain_eq, self.peak_reference)
        return self.peak_strain - ref

    @property
    def failures(self) -> list[str]:
        """Why this configuration breaks the rule (empty: it meets it)."""
        out = []
        if not self.stable:
            return ["unstable"]
        if not self.at_rest:
            out.append("not at rest")
        if self.capped_cause:
            out.append("capped")
        if not self.shape <= SHAPE_TOLERANCE:
            out.append(f"shape {100 * self.shape:.2f} % > {100 * SHAPE_TOLERANCE:g} %")
        if not self.strain <= STRAIN_RATIO * self.strain_eq + self.strain_resolution:
            out.append(f"strain {self.strain_ratio:.2f}x > {STRAIN_RATIO:g}x")
        if not self.stretch_excess <= OVERSTRETCH:
            out.append(f"stretch in motion +{100 * self.stretch_excess:.2f} % > {100 * OVERSTRETCH:g} %")
        return out

    @property
    def meets(self) -> bool:
        return not self.failures


#: ``still_air``'s wind: still air W = 0 [m/s] (the air's drag on the cloth's normal motion stays).
STILL_AIR = WindSchedule.constant((0.0, 0.0, 0.0))


def _run(scenario, cfg, still_air: bool = False, to_rest: bool = True):
    """(simulator, RunResult, peak structural strain over the frames) of a run of ``cfg`` to rest (where the
    scene stops there and ``to_rest``; else for its duration); with ``still_air``, its wind stilled."""
    sim = scenario.build(cfg)
    if still_air and sim.control.has_wind:
        sim.control.wind_schedule = STILL_AIR
    harness = RunHarness(sim, scenario=scenario.name, instability_strain=cfg.instability_strain)
    peak = _PeakStrain(harness.sim.model)
    stop = scenario.stop_at_equilibrium and to_rest
    result = harness.run(cfg.duration, fps=cfg.fps, stop_at_equilibrium=stop, frames=peak)
    return harness.sim, result, peak.peak


def _motion_config(scene: str, integrator, options, dt_scale: float, overrides: dict):
    """(scenario, config) of ``scene`` on the CPU with ``integrator`` and ``options`` (None: the scene's) at
    ``dt_scale`` x that configuration's step: the run :func:`motion_peak_strain` and
    :func:`motion_piece_peaks` measure."""
    scenario = get_scenario(scene)
    cfg = scenario.config(device="cpu", **overrides)
    if integrator is not None:
        cfg = replace(cfg, integrator=integrator)
    cfg = replace(cfg, integrator_options=scenario.integrator_options(cfg.integrator, options))
    if dt_scale != 1.0:
        cfg = replace(cfg, dt=scenario.build(cfg).dt * dt_scale)
    return scenario, cfg


def motion_peak_strain(
    scene: str, integrator: str | None = None, options: dict | None = None, dt_scale: float = 1.0, **overrides
) -> float:
    """The peak structural strain of ``scene`` run as it is (its wind on, no stop at rest) for its duration
    with ``integrator`` and ``options`` (None: the scene's), at ``dt_scale`` x that configuration's step (a
    converged reference: explicit Euler at a fraction of its stable step). Raises if the run is not stable."""
    scenario, cfg = _motion_config(scene, integrator, options, dt_scale, overrides)
    _, result, peak = _run(scenario, cfg, to_rest=False)
    require(result.stable, f"{scenario.name} under {cfg.integrator} went unstable: {result.unstable_reason}")
    return peak


def motion_piece_peaks(
    scene: str, integrator: str | None = None, options: dict | None = None, dt_scale: float = 1.0, **overrides
) -> tuple[dict[str, float], float, int, object]:
    """:func:`motion_peak_strain` per piece of a model of several (a structural spring counts for the piece
    of its particles): (piece name -> peak strain, CPU process seconds of the run, frames, RunResult). A
    scene that never rests (the character's walking body) is judged by these against a converged run's."""
    scenario, cfg = _motion_config(scene, integrator, options, dt_scale, overrides)
    sim = scenario.build(cfg)
    harness = RunHarness(sim, scenario=scenario.name, instability_strain=cfg.instability_strain)
    peaks = _PiecePeaks(harness.sim.model)
    start = time.process_time()
    result = harness.run(cfg.duration, fps=cfg.fps, stop_at_equilibrium=False, frames=peaks)
    cpu = time.process_time() - start
    return dict(peaks.peaks), cpu, round(cfg.duration * cfg.fps), result


def measure_fidelity(
    scene: str,
    integrator: str | None = None,
    options: dict | None = None,
    motion_reference: bool = True,
    still_air: bool = False,
    wind_duration: float | None = None,
    **overrides,
) -> Fidelity:
    """Run ``scene`` (a scenario's name or file) on the CPU with ``integrator`` and ``options`` (None: the
    scene's default, and its options for it) and ``overrides`` (ScenarioConfig fields: rows, cols, dt,
    duration, material, ...) to rest, and measure it against its float64 equilibrium (module docstring).
    ``motion_reference``: where the peak strain in motion exceeds the equilibrium's by more than
    OVERSTRETCH and the rest meets the rule, run :data:`MOTION_REFERENCE` too and judge against its peak.
    ``still_air``: the rest is the scene's with its wind stilled (:data:`STILL_AIR`), the motion both that
    run's and a run of the scene as it is, in its wind, for ``wind_duration`` [s] (None: the scene's own
    duration; its peak in ``extra["wind_peak"]``, its capped steps counted too); the motion reference runs both."""
    scenario = get_scenario(scene)
    cfg = scenario.config(device="cpu", **overrides)
    if integrator is not None:
        cfg = replace(cfg, integrator=integrator)
    base = cfg
    cfg = replace(cfg, integrator_options=scenario.integrator_options(cfg.integrator, options))
    sim, result, peak = _run(scenario, cfg, still_air)
    windy, wind_peak = still_air and sim.control.has_wind, math.nan
    if wind_duration is None:
        wind_duration = scenario.config().duration
    if windy and result.stable:
        _, wind_result, wind_peak = _run(scenario, replace(cfg, duration=wind_duration), to_rest=False)
        peak = max(peak, wind_peak)
        result.stable = wind_result.stable
        result.capped_steps += wind_result.capped_steps
        result.strain_capped_steps += wind_result.strain_capped_steps
        result.capped_cause = result.capped_cause or wind_result.capped_cause
    out = Fidelity(
        scene=scenario.name,
        integrator=cfg.integrator,
        options=dict(cfg.integrator_options),
        dt=sim.dt,
        particles=sim.model.particle_count,
        stable=result.stable,
        at_rest=result.equilibrium_reached,
        rest_time=result.sim_time,
        capped_steps=result.capped_steps,
        strain_capped_steps=result.strain_capped_steps,
        capped_cause=result.capped_cause,
        peak_strain=peak,
    )
    if windy:
        out.extra["wind_peak"] = wind_peak
    if not result.stable:
        return out
    x = sim.state.particle_q.numpy().astype(np.float64)
    t = sim.sim_time
    timing = time_steps(sim, windows=3, window_seconds=0.2, warm_up=False)
    out.ms_frame = timing.median_ms * (1.0 / 60.0) / sim.dt
    start = time.perf_counter()
    eq = rest_equilibrium(sim, x, t)
    out.solve_s = time.perf_counter() - start
    out.residual = eq.residual
    out.strain = structural_strain(sim.model, x, eq.moving)
    out.strain_eq = structural_strain(sim.model, eq.x, eq.moving)
    out.extra["held"] = int(np.count_nonzero(~eq.moving))
    out.strain_resolution = strain_resolution(sim.model, x)
    out.shape = float(np.max(np.linalg.norm(x - eq.x, axis=1))) / cloth_size(sim.model)
    rest_failures = [f for f in out.failures if not f.startswith("stretch in motion")]
    if motion_reference and out.stretch_excess > OVERSTRETCH and not rest_failures:
        name, opts = MOTION_REFERENCE
        ref_cfg = replace(base, integrator=name, integrator_options=dict(opts), dt=None)
        _, ref_result, ref_peak = _run(scenario, ref_cfg, still_air)
        require(ref_result.stable, f"the motion reference {name} {opts} went unstable on {scenario.name}")
        if windy:
            _, ref_result, ref_wind = _run(scenario, replace(ref_cfg, duration=wind_duration), to_rest=False)
            require(ref_result.stable, f"the motion reference {name} {opts} went unstable on {scenario.name}'s wind")
            ref_peak = max(ref_peak, ref_wind)
        out.peak_reference = ref_peak
    return out


__all__ = [
    "SHAPE_TOLERANCE",
    "STILL_AIR",
    "STRAIN_RATIO",
    "Fidelity",
    "RestEquilibrium",
    "measure_fidelity",
    "motion_peak_strain",
    "motion_piece_peaks",
    "rest_equilibrium",
    "structural_strain",
]
