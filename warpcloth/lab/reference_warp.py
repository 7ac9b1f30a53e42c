"""The float64 Warp reference: the model of :mod:`warpcloth.lab.reference` integrated by classic
RK4 in float64 Warp kernels (``kernels/reference64.py``), on any device, with a run at half the
step as its error estimate (design.md, "Accuracy and the study": above 12 x 12 the reference is
float64 Warp RK4 at a safety factor of its stability limit, accepted when the halving estimate
is <= 1e-5 of the cloth size).

The model is the one :class:`~warpcloth.lab.reference.Float64Model` reads from a ClothModel and a
Control (the float32 parameters converted exactly): springs ks (L - L0) n + kd ((v_j - v_i) . n) n,
gravity m g, linear drag -m c v (c [1/s]), wind c_w A (n . (W(t) - v_mean)) n a third on each vertex
of a triangle, pinned particles at x0 and v0. Unlike the SciPy reference, pinned particles on a pin
track of ``control.pin_tracks`` take the track's position and velocity, evaluated in float64 on the
device at every RK stage time (t + h/2, t + h).

Time stepping: the window [0, duration] is cut at every frame time k frame_dt, every switch of the
wind schedule (:func:`~warpcloth.lab.reference.wind_switch_times`) and every key time of a keyframed
pin track, so no RK4 step crosses a discontinuity; a piece of length l takes n = ceil(l / h_max)
equal steps, the halving run 2n, h_max = safety x the linear stability limit of RK4
(:func:`stability_limit`).

Per RK4 stage, one kernel evaluates every spring (and triangle's wind) once and one per particle
gathers them in a fixed order (no atomics: bit-reproducible on every device) fused with the stage
update; no host synchronisation inside the loop (docs/reference.md).
"""

from __future__ import annotations

import itertools
import math
import threading
import time
from dataclasses import dataclass, field, replace

import numpy as np
import warp as wp

from warpcloth.errors import WarpclothError, require, require_int, require_positive
from warpcloth.kernels import reference64
from warpcloth.lab.reference import Float64Model, cloth_size, frame_count, initial_state, wind_switch_times
from warpcloth.sim.pins import KinematicPins, PinTrack

#: RK4's stability region contains the half-disc |z| <= 2.61, Re z <= 0 (its boundary comes
#: closest to 0 in the left half-plane at about 125 degrees, |z| = 2.6197; 2.8284 = 2 sqrt 2 on
#: the imaginary axis, 2.7853 on the negative real axis).
RK4_STABILITY_RADIUS = 2.61
#: Default tolerance of the halving estimate, relative to the cloth size (design.md).
DEFAULT_TOLERANCE = 1e-5
DEFAULT_SAFETY = 0.5
DEFAULT_MAX_HALVINGS = 3


def _kernels():
    return reference64


# -- the stability limit -----------------------------------------------------------------------
@dataclass(frozen=True)
class StabilityLimit:
    """RK4's linear stability limit of the model at a state (:func:`stability_limit`).

    Attributes:
        omega: sqrt of the largest |eigenvalue| of M^-1 K [rad/s], K = -df/dx (Lanczos).
        gamma: a bound of the largest eigenvalue of M^-1 C [1/s], C = -df/dv: the springs' kd
            part by Gershgorin (max_i 2 sum kd / m_i), or by Lanczos where that bound exceeds omega,
            plus the drag rate, plus a Gershgorin bound of the wind's velocity term.
        rho: max(omega, gamma), the bound of |lambda| over the eigenvalues of the linearised
            first-order system in the left half-plane.
        dt: RK4_STABILITY_RADIUS / rho [s] (inf without springs, drag and wind).
        omega_gershgorin: max_i 2 sum_s ks_s / m_i, square-rooted [rad/s]: the configuration-free
            bound (for L >= L0 / 2), for comparison.
    """

    omega: float
    gamma: float
    rho: float
    dt: float
    omega_gershgorin: float


def stability_limit(m64: Float64Model, x: np.ndarray) -> StabilityLimit:
    """The largest stable RK4 step of the model linearised at positions ``x`` (at rest).

    Linearised, M y'' = -K y - C y' (K = -df/dx, the spring Hessian with its geometric term; C =
    -df/dv: spring damping kd n n^T, drag c M, wind). For an eigenpair (lambda, u) with u^H M u =
    1: lambda^2 + c lambda + k = 0 with c = u^H C u in [0, gamma] and k = u^H K u <= omega^2. For
    k >= 0 (C >= 0): an underdamped pair (c^2 < 4k) has |lambda| = sqrt(k) <= omega and Re <= 0;
    an overdamped one is real in [-c, 0], |lambda| <= gamma. So |lambda| <= rho = max(omega, gamma)
    in the left half-plane; k < 0 (a compressed spring's geometric term) gives a small positive
    real lambda, a physical instability that RK4 follows, not a step limit. RK4 is stable where
    |h lambda| <= 2.61 in the left half-plane, hence ``dt = 2.61 / rho``. omega^2 and the spring
    part of gamma (where its Gershgorin bound would set the step) are the extreme eigenvalues of
    M^-1/2 K M^-1/2 and M^-1/2 C M^-1/2 on the free degrees of freedom (SciPy ``eigsh``, Lanczos,
    rtol 1e-3: omega within 1.3e-4 of the converged value at 128x128, 4 s). K changes along the trajectory
    (stretch adds ks (1 - L0/L) across each spring); on the top-row swing omega stays within 0.1 %
    of its start value for 1 s (32x32, 64x64), and an unstable run is rejected by the halving check
    anyway (a non-finite run's estimate is inf: h is halved).
    """
    from scipy.sparse.linalg import eigsh  # noqa: PLC0415 (SciPy loads only where this solve runs: stepping loads none)

    free = m64.free
    fdof = (3 * np.nonzero(free)[0][:, None] + np.arange(3)[None, :]).ravel()
    drag = float(m64.drag_rate)
    wind_gamma = 0.0
    if m64.wind_on and m64.tris.shape[0] and m64.wind_coefficient > 0:
        # C_wind blocks c_w A / 9 n n^T between every two vertices of a triangle: a row of blocks sums to c_w A / 3
        a, b, c = (m64.tris[:, k] for k in range(3))
        area = 0.5 * np.linalg.norm(np.cross(x[b] - x[a], x[c] - x[a]), axis=1)
        row = np.zeros(m64.particle_count)
        for k in range(3):
            row += np.bincount(m64.tris[:, k], weights=m64.wind_coefficient * area / 3.0, minlength=m64.particle_count)
        wind_gamma = float(np.max(row[free] / m64.mass[free])) if free.any() else 0.0
    omega = gamma_springs = omega_g = 0.0
    if m64.pairs.shape[0] and fdof.size:
        scale = 1.0 / np.sqrt(np.repeat(m64.mass, 3))[fdof]

        def top(matrix) -> float:
            a = matrix[fdof][:, fdof]
            a = a.multiply(scale[:, None]).multiply(scale[None, :]).tocsr()
            if a.shape[0] <= 3:
                return float(np.max(np.abs(np.linalg.eigvalsh(a.toarray()))))
            v0 = np.random.default_rng(0).standard_normal(a.shape[0])  # a fixed start: a reproducible dt
            return float(np.max(np.abs(eigsh(a, k=1, which="LM", tol=1e-3, v0=v0, return_eigenvectors=False))))

        omega = math.sqrt(top(m64.stiffness_matrix(x)))
        i, j = m64.pairs[:, 0], m64.pairs[:, 1]
        n = m64.particle_count

        def gershgorin(k: np.ndarray) -> float:  # max_i 2 sum_s k_s / m_i: every block k_s n n^T has norm k_s
            row = np.bincount(i, weights=k, minlength=n) + np.bincount(j, weights=k, minlength=n)
            return float(np.max(2.0 * row[free] / m64.mass[free]))

        omega_g = math.sqrt(gershgorin(m64.ks))
        gamma_springs = gershgorin(m64.kd)
        if gamma_springs + drag + wind_gamma > omega and np.any(m64.kd > 0):
            # the bound would set the step: Lanczos on kd n n^T (the stiffness matrix of springs ks = kd at rest)
            lengths = np.linalg.norm(x[j] - x[i], axis=1)
            gamma_springs = top(replace(m64, ks=m64.kd, rest=lengths).stiffness_matrix(x))
    gamma = gamma_springs + drag + wind_gamma
    rho = max(omega, gamma)
    dt = RK4_STABILITY_RADIUS / rho if rho > 0 else math.inf
    return StabilityLimit(omega=omega, gamma=gamma, rho=rho, dt=dt, omega_gershgorin=omega_g)


# -- the time grid -----------------------------------------------------------------------------
@dataclass(frozen=True)
class _Piece:
    """[start, end] with W constant inside; ``frame``: the frame index at ``end`` (or -1)."""

    start: float
    end: float
    wind: tuple
    frame: int


def _pieces(m64: Float64Model, tracks, duration: float, frames: int, frame_dt: float) -> list[_Piece]:
    times = {k: (k * frame_dt if k < frames else duration) for k in range(frames + 1)}
    cuts = set()
    if m64.wind_on:
        cuts.update(wind_switch_times(m64.wind_schedule, 0.0, duration))
    for track in tracks:
        if track.kind == "keyframes":
            cuts.update(float(t) for t in track.times if 0.0 < t < duration)
    snap = 1e-12 * max(1.0, duration)
    frame_times = np.array([times[k] for k in range(frames + 1)])
    extra = sorted(t for t in cuts if np.min(np.abs(frame_times - t)) > snap)
    points = sorted([(t, k) for k, t in times.items()] + [(t, -1) for t in extra])
    pieces = []
    for (a, _), (b, k) in itertools.pairwise(points):
        wind = tuple(float(w) for w in m64.wind(0.5 * (a + b))) if m64.wind_on else (0.0, 0.0, 0.0)
        pieces.append(_Piece(a, b, wind, k))
    return pieces


# -- one RK4 run -------------------------------------------------------------------------------
class _Run:
    """Device arrays and recorded launches for RK4 runs of one model on one device."""

    def __init__(self, m64: Float64Model, tracks, x0: np.ndarray, v0: np.ndarray, frames: int, device):
        k = _kernels()
        self.k = k
        self.device = device
        n = m64.particle_count
        self.n = n
        pinned = ~m64.free
        with wp.ScopedDevice(device):
            cloth = k.Cloth64()
            cloth.mass = wp.array(m64.mass, dtype=wp.float64)
            cloth.pinned = wp.array(pinned.astype(np.int32), dtype=wp.int32)
            # springs oriented first < second and sorted by (first, second), so that a particle's
            # springs sit close together in f_spring (seen from its other end a spring's force is
            # exactly the negative: reorienting changes no bit); particle i's slots: s where i is
            # spring s's first particle, -1 - s where it is the second
            lo, hi = m64.pairs.min(axis=1), m64.pairs.max(axis=1)
            order = np.lexsort((hi, lo))
            pairs = np.stack([lo, hi], axis=1)[order]
            n_springs = pairs.shape[0]
            offsets, slot = _adjacency(
                np.concatenate([pairs[:, 0], pairs[:, 1]]),
                n,
                np.concatenate([np.arange(n_springs), -1 - np.arange(n_springs)]),
            )
            cloth.spring_offsets = wp.array(offsets, dtype=wp.int32)
            cloth.spring_slot = wp.array(slot, dtype=wp.int32)
            cloth.springs = wp.array(pairs.astype(np.int32), dtype=wp.vec2i)
            cloth.spring_rest = wp.array(m64.rest[order], dtype=wp.float64)
            cloth.spring_ks = wp.array(m64.ks[order], dtype=wp.float64)
            cloth.spring_kd = wp.array(m64.kd[order], dtype=wp.float64)
            self.has_wind = m64.wind_on and m64.tris.shape[0] > 0 and m64.wind_coefficient > 0
            tris = m64.tris if self.has_wind else np.zeros((0, 3), dtype=np.int64)
            t_offsets, t_slot = _adjacency(tris.reshape(-1), n, np.repeat(np.arange(tris.shape[0]), 3))
            cloth.tri_offsets = wp.array(t_offsets, dtype=wp.int32)
            cloth.tri_slot = wp.array(t_slot, dtype=wp.int32)
            cloth.tris = wp.array(tris.astype(np.int32).reshape(-1, 3), dtype=wp.vec3i)
            self.f_spring = wp.zeros(n_springs, dtype=wp.vec3d)
            self.f_tri = wp.zeros(tris.shape[0], dtype=wp.vec3d)
            cloth.gravity = wp.vec3d(*m64.gravity)
            cloth.drag_rate = wp.float64(m64.drag_rate)
            cloth.wind_coefficient = wp.float64(m64.wind_coefficient if self.has_wind else 0.0)
            self.cloth = cloth
            self.x0 = wp.array(x0, dtype=wp.vec3d)
            self.v0 = wp.array(v0, dtype=wp.vec3d)
            self.x, self.v = wp.zeros(n, dtype=wp.vec3d), wp.zeros(n, dtype=wp.vec3d)
            self.xa, self.va = wp.zeros(n, dtype=wp.vec3d), wp.zeros(n, dtype=wp.vec3d)
            self.xb, self.vb = wp.zeros(n, dtype=wp.vec3d), wp.zeros(n, dtype=wp.vec3d)
            self.acc_x, self.acc_v = wp.zeros(n, dtype=wp.vec3d), wp.zeros(n, dtype=wp.vec3d)
            # pins at the stage times: fixed pins hold (x0, v0) in both; tracks overwrite theirs each step
            self.pin_half = (wp.array(x0, dtype=wp.vec3d), wp.array(v0, dtype=wp.vec3d))
            self.pin_full = (wp.array(x0, dtype=wp.vec3d), wp.array(v0, dtype=wp.vec3d)) if tracks else self.pin_half
            self.frames = wp.zeros((frames + 1) * n, dtype=wp.vec3d)
            self.tracks = [self._bind_track(t, m64.q0) for t in tracks]
        self.cmds = self._record()

    def _bind_track(self, track: PinTrack, rest: np.ndarray):
        idx = np.asarray(track.particles, dtype=np.int64)
        particle = wp.array(idx.astype(np.int32), dtype=int)
        if track.kind == "rigid":
            motion = (track.angular_velocity, track.swing_amplitude, track.swing_frequency, track.swing_phase)
            args = [
                particle,
                wp.array(rest[idx], dtype=wp.vec3d),
                wp.vec3d(*track.center),
                wp.vec3d(*track.axis),
                wp.vec3d(*track.velocity),
                wp.vec4d(*motion),
            ]
            kernel = self.k.eval_pin_rigid64
        else:
            args = [
                particle,
                wp.array(track.times, dtype=wp.float64),
                wp.array(track.key_positions(rest).reshape(-1, 3), dtype=wp.vec3d),
                wp.array(track.key_tangents(rest).reshape(-1, 3), dtype=wp.vec3d),
                int(track.interpolation != "linear"),
            ]
            kernel = self.k.eval_pin_keyframes64
        cmds = [
            wp.launch(
                kernel,
                dim=idx.size,
                inputs=[wp.float64(0.0), *args],
                outputs=[*pins],
                device=self.device,
                record_cmd=True,
            )
            for pins in (self.pin_half, self.pin_full)
        ]
        return cmds

    def _record(self):
        """Per stage: the springs' forces, the triangles' wind (with wind), the particle update."""
        k, c, dev = self.k, self.cloth, self.device
        zero, w = wp.float64(0.0), wp.vec3d(0.0, 0.0, 0.0)

        def forces(xs, vs):
            cmds = [
                wp.launch(
                    k.eval_springs64,
                    dim=c.springs.shape[0],
                    inputs=[c, xs, vs],
                    outputs=[self.f_spring],
                    device=dev,
                    record_cmd=True,
                )
            ]
            if self.has_wind:
                cmds.append(
                    wp.launch(
                        k.eval_wind64,
                        dim=c.tris.shape[0],
                        inputs=[c, xs, vs, w],
                        outputs=[self.f_tri],
                        device=dev,
                        record_cmd=True,
                    )
                )
            return cmds

        def stage(xs, vs, weight, first, pins, x_out, v_out):
            inputs = [c, self.x, self.v, vs, self.f_spring, self.f_tri, zero, wp.float64(weight), first, *pins]
            outputs = [self.acc_x, self.acc_v, x_out, v_out]
            return forces(xs, vs) + [
                wp.launch(
                    k.integrate_rk4_stage64, dim=self.n, inputs=inputs, outputs=outputs, device=dev, record_cmd=True
                )
            ]

        final = [c, self.va, self.f_spring, self.f_tri, zero, *self.pin_full, self.acc_x, self.acc_v]
        return [
            stage(self.x, self.v, 1.0, 1, self.pin_half, self.xa, self.va),  # k1 -> s + h/2 k1
            stage(self.xa, self.va, 2.0, 0, self.pin_half, self.xb, self.vb),  # k2 -> s + h/2 k2
            stage(self.xb, self.vb, 2.0, 0, self.pin_full, self.xa, self.va),  # k3 -> s + h k3
            # k4 -> s + h/6 (k1 + 2 k2 + 2 k3 + k4)
            forces(self.xa, self.va)
            + [
                wp.launch(
                    k.integrate_rk4_final64,
                    dim=self.n,
                    inputs=final,
                    outputs=[self.x, self.v],
                    device=dev,
                    record_cmd=True,
                )
            ],
        ]

    def _pins_at(self, t_half: float, t_full: float) -> None:
        for half, full in self.tracks:
            half.set_param_at_index(0, wp.float64(t_half))
            half.launch()
            full.set_param_at_index(0, wp.float64(t_full))
            full.launch()

    def run(self, pieces: list[_Piece], counts: list[int]) -> np.ndarray:
        """Frames (frames + 1, N, 3) of RK4 from (x0, v0) with ``counts[p]`` equal steps on piece p."""
        wp.copy(self.x, self.x0)
        wp.copy(self.v, self.v0)
        if self.tracks:  # tracked pins start on their track
            self._pins_at(0.0, 0.0)
            wp.launch(
                self.k.apply_pins64,
                dim=self.n,
                inputs=[self.cloth.pinned, *self.pin_full],
                outputs=[self.x, self.v],
                device=self.device,
            )
        wp.copy(self.frames, self.x, dest_offset=0, count=self.n)
        stages = self.cmds
        for piece, n in zip(pieces, counts):
            h = (piece.end - piece.start) / n
            wind = wp.vec3d(*piece.wind)
            for cmds, hh in zip(stages, (0.5 * h, 0.5 * h, h, h)):
                cmds[-1].set_param_by_name("h", wp.float64(hh))
                if self.has_wind:
                    cmds[1].set_param_by_name("wind", wind)
            launches = [cmd.launch for cmds in stages for cmd in cmds]
            for step in range(n):
                if self.tracks:
                    t = piece.start + step * h
                    self._pins_at(t + 0.5 * h, piece.end if step == n - 1 else piece.start + (step + 1) * h)
                for launch in launches:
                    launch()
            if piece.frame >= 0:
                wp.copy(self.frames, self.x, dest_offset=piece.frame * self.n, count=self.n)
        return self.frames.numpy().reshape(-1, self.n, 3).copy()  # a copy: on the CPU numpy() is a view of the buffer


def _adjacency(owner: np.ndarray, n: int, payload: np.ndarray):
    """CSR by owner: (offsets (n + 1,), payload sorted by owner, stably: in payload order)."""
    order = np.argsort(owner, kind="stable")
    offsets = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(np.bincount(owner, minlength=n), out=offsets[1:])
    return offsets.astype(np.int32), payload[order].astype(np.int32)


# -- the reference -----------------------------------------------------------------------------
@dataclass
class WarpReference:
    """Result of :func:`warp_reference`.

    Attributes:
        frames: positions [m] at t_k = k frame_dt, (frames + 1, N, 3) float64: the finest run.
        halving_estimate: max over frames and particles of |x_h - x_{h/2}| [m] of the last two
            runs; the finest run's error is about a fifteenth of it (RK4: (h/2)^4 / (h^4 - (h/2)^4)).
        relative_estimate: halving_estimate / cloth size.
        accepted: relative_estimate <= tolerance.
        dt: the finest run's largest step [s]; steps: its number of steps.
        stability: the :class:`StabilityLimit` at the start.
        estimates: the relative halving estimate of each halving, in order.
        seconds: wall time of all runs [s].
        metric_estimates: per halving, in order, ``metrics(x_h, x_{h/2})`` (a dict: the halving
            estimate of each metric a caller judges, :func:`warpcloth.lab.accuracy.halving_estimates`);
            empty without ``metrics``.
    """

    frames: np.ndarray
    halving_estimate: float
    relative_estimate: float
    accepted: bool
    dt: float
    steps: int
    stability: StabilityLimit
    estimates: list
    seconds: float
    piece_steps: tuple = ()  # the finest run's steps per piece of the time grid (for warp_trajectory)
    metric_estimates: list = field(default_factory=list)


def _pin_tracks(model, control) -> tuple:
    tracks = tuple(getattr(control, "pin_tracks", ()) or ()) if control is not None else ()
    if tracks:
        KinematicPins(model, tracks)  # its checks: PinTrack objects, on pinned particles in range, no particle twice
    return tracks


def warp_reference(
    model,
    control=None,
    duration: float = 1.0,
    frame_dt: float = 1.0 / 60.0,
    x0=None,
    v0=None,
    *,
    tolerance: float = DEFAULT_TOLERANCE,
    safety: float = DEFAULT_SAFETY,
    max_halvings: int = DEFAULT_MAX_HALVINGS,
    dt: float | None = None,
    device=None,
    parallel: bool = False,
    require_accepted: bool = True,
    metrics=None,
) -> WarpReference:
    """The float64 RK4 reference trajectory of ``model`` under ``control`` (None: gravity only)
    from (``x0``, ``v0``) at t = 0 (default: the rest shape, at rest), sampled at t_k = k frame_dt.

    RK4 at ``h = safety x`` :func:`stability_limit` (or at ``dt`` when given, which replaces the
    estimate: a step beyond the limit goes unstable and is halved), and at h/2; the
    halving estimate is max |x_h - x_{h/2}| over the frames and particles. Accepted when it is <=
    ``tolerance`` x cloth size; otherwise h is halved again (one more run each time), at most
    ``max_halvings`` times. ``parallel``: the first two runs in two threads (Warp's CPU kernels run
    on one thread each). ``metrics``: a function (coarse frames, fine frames) -> dict, called on
    every halving's pair (``metric_estimates``): the halving estimate of each metric a caller
    judges, so a chaotic window whose pointwise estimate never converges can still be accepted
    for the metrics that do (:func:`warpcloth.lab.accuracy.reference_for`); it does not change
    when halving stops (the pointwise rule). Raises :class:`WarpclothError` on bad input, and when no halving is
    accepted if ``require_accepted`` (else returns the last with ``accepted`` False).
    """
    frames = frame_count(duration, frame_dt)
    duration, frame_dt = float(duration), float(frame_dt)
    tolerance = require_positive("reference tolerance", tolerance)
    safety = require_positive("reference safety factor", safety)
    require(
        safety <= 1.0, f"reference safety factor must be <= 1 (a fraction of RK4's stability limit), got {safety!r}"
    )
    max_halvings = require_int("max halvings", max_halvings, 0)
    if dt is not None:
        dt = require_positive("reference dt", dt, "s")
    m64 = Float64Model.from_model(model, control)
    x, v = initial_state(m64, x0, v0)
    tracks = _pin_tracks(model, control)
    device = model.device if device is None else wp.get_device(device)
    size = cloth_size(model)
    t_start = time.perf_counter()
    limit = stability_limit(m64, x)
    h_max = safety * limit.dt if dt is None else dt
    pieces = _pieces(m64, tracks, duration, frames, frame_dt)
    base = [max(1, math.ceil((p.end - p.start) / h_max * (1.0 - 1e-12))) for p in pieces]

    def counts(level: int) -> list[int]:
        return [n << level for n in base]

    def finite(a: np.ndarray) -> np.ndarray | None:
        return a if np.all(np.isfinite(a)) else None

    runners = [_Run(m64, tracks, x, v, frames, device)]
    if parallel:
        runners.append(_Run(m64, tracks, x, v, frames, device))
        out = [None, None]

        def work(slot):
            out[slot] = runners[slot].run(pieces, counts(slot))

        threads = [threading.Thread(target=work, args=(s,)) for s in (0, 1)]
        for th in threads:
            th.start()
        for th in threads:
            th.join()
        coarse, fine = out
    else:
        coarse = runners[0].run(pieces, counts(0))
        fine = runners[0].run(pieces, counts(1))
    level = 1
    estimates, metric_estimates = [], []
    while True:
        c, f = finite(coarse), finite(fine)
        e = float(np.max(np.linalg.norm(c - f, axis=-1))) if c is not None and f is not None else math.inf
        estimates.append(e / size)
        if metrics is not None:
            metric_estimates.append(metrics(coarse, fine) if c is not None and f is not None else None)
        if e <= tolerance * size or level > max_halvings:
            break
        level += 1
        coarse, fine = fine, runners[0].run(pieces, counts(level))
    accepted = e <= tolerance * size
    if not accepted and require_accepted:
        raise WarpclothError(
            f"the Warp reference did not converge: halving estimate {e / size:.3g} x size "
            f"after {level} halvings "
            f"(tolerance {tolerance:g}; estimates {', '.join(f'{s:.3g}' for s in estimates)}); "
            f"lower the safety factor or raise max_halvings"
        )
    fine_counts = counts(level)
    dt_fine = max((p.end - p.start) / n for p, n in zip(pieces, fine_counts))
    return WarpReference(
        frames=fine,
        halving_estimate=e,
        relative_estimate=e / size,
        accepted=accepted,
        dt=dt_fine,
        steps=int(sum(fine_counts)),
        stability=limit,
        estimates=estimates,
        seconds=time.perf_counter() - t_start,
        piece_steps=tuple(int(c) for c in fine_counts),
        metric_estimates=metric_estimates,
    )


def warp_trajectory(
    model,
    control,
    duration: float,
    frame_dt: float,
    x0=None,
    v0=None,
    *,
    dt: float | None = None,
    piece_steps=None,
    device=None,
) -> np.ndarray:
    """One float64 RK4 run of :func:`warp_reference`'s model on its time grid (cut at frames, wind
    switches and track keys), without a halving run: frames (frames + 1, N, 3). Each piece in
    equal steps of at most ``dt`` [s], or in ``piece_steps`` steps (a :class:`WarpReference`'s
    ``piece_steps``: the same steps as its finest run). For runs beside an accepted reference (the
    conditioning floor's perturbed starts, :func:`warpcloth.lab.accuracy.conditioning_floor`)."""
    frames = frame_count(duration, frame_dt)
    m64 = Float64Model.from_model(model, control)
    x, v = initial_state(m64, x0, v0)
    tracks = _pin_tracks(model, control)
    device = model.device if device is None else wp.get_device(device)
    pieces = _pieces(m64, tracks, float(duration), frames, float(frame_dt))
    if piece_steps is not None:
        counts = [int(c) for c in piece_steps]
        require(
            len(counts) == len(pieces) and min(counts) >= 1,
            f"piece_steps must give {len(pieces)} step counts >= 1 (one per piece of the time grid)",
        )
    else:
        require(dt is not None, "warp_trajectory needs dt or piece_steps")
        dt = require_positive("reference dt", dt, "s")
        counts = [max(1, math.ceil((p.end - p.start) / dt * (1.0 - 1e-12))) for p in pieces]
    return _Run(m64, tracks, x, v, frames, device).run(pieces, counts)


def reference_trajectory(model, control, duration: float, frame_dt: float, x0=None, v0=None, **options) -> np.ndarray:
    """:func:`warp_reference`'s frames, (frames + 1, N, 3): a drop-in for
    :func:`warpcloth.lab.reference.reference_trajectory` (``options`` go to :func:`warp_reference`)."""
    return warp_reference(model, control, duration, frame_dt, x0, v0, **options).frames


__all__ = [
    "DEFAULT_TOLERANCE",
    "RK4_STABILITY_RADIUS",
    "StabilityLimit",
    "WarpReference",
    "reference_trajectory",
    "stability_limit",
    "warp_reference",
    "warp_trajectory",
]
