"""A float64 reference of warpcloth's model: an independent implementation to measure accuracy.

The same model as the Warp kernels (``kernels/forces.py``), written again in NumPy, float64:

- spring s = (i, j): ``f_i = ks (L - L0) n + kd ((v_j - v_i) . n) n``, ``f_j = -f_i``,
  ``n = (x_j - x_i) / L``;
- gravity ``m g`` and linear air drag ``-m c v`` on every particle;
- wind on every triangle (a, b, c): ``f = c_w A (n . (W(t) - v_mean)) n``, shared equally (1/3)
  by its three vertices, ``n`` the unit normal of ``cross(x_b - x_a, x_c - x_a)``, ``A`` the
  area, ``v_mean`` the mean velocity of the three vertices, ``W(t)`` the control's piecewise
  constant :class:`~warpcloth.sim.control.WindSchedule`;
- pinned particles (inverse mass 0) keep their position and their velocity (zero by default),
  as in the integrator kernels.

:func:`reference_trajectory` integrates it with SciPy's ``solve_ivp`` (DOP853, tight rtol/atol),
restarted at every switch of the wind schedule (W(t) is discontinuous there), and samples the
frames t_k = k frame_dt. :func:`convergence_check` compares two tolerances.
:func:`static_equilibrium` solves the static problem under gravity (net force on every free
particle = 0) by Newton's method with the analytic spring Jacobian (SciPy sparse).

Forces are vectorised (``np.bincount`` scatter, no per-spring Python loop). Model data are read
from the model's host arrays (float32, converted exactly to float64): the reference integrates
exactly the model the kernels integrate, with float64 arithmetic.
"""

from __future__ import annotations

import itertools
import math
import warnings
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import scipy.sparse as sp
from scipy.integrate import solve_ivp
from scipy.sparse.linalg import MatrixRankWarning, spsolve

from warpcloth.errors import WarpclothError, require, require_positive
from warpcloth.sim.colliders import Plane, Sphere
from warpcloth.sim.control import Control, WindSchedule


# -- the model in float64 ---------------------------------------------------------------------
@dataclass(frozen=True)
class Float64Model:
    """Everything the force model needs, in float64 NumPy arrays (host copies of a ClothModel
    and a Control).

    Attributes:
        q0: (N, 3) rest / initial positions [m].
        mass: (N,) particle masses [kg].
        free: (N,) True where the particle moves (inverse mass > 0).
        pairs: (S, 2) spring particle indices; rest, ks, kd: (S,) L0 [m], ks [N/m], kd [N s/m].
        tris: (T, 3) triangles for the wind.
        gravity: (3,) [m/s^2]; drag_rate: c [1/s]; wind_coefficient: c_w [kg/(m^2 s)].
        wind_schedule: W(t); wind_on: whether wind forces apply (as ``Control.has_wind``).
    """

    q0: np.ndarray
    mass: np.ndarray
    free: np.ndarray
    pairs: np.ndarray
    rest: np.ndarray
    ks: np.ndarray
    kd: np.ndarray
    tris: np.ndarray
    gravity: np.ndarray
    drag_rate: float
    wind_coefficient: float
    wind_schedule: WindSchedule
    wind_on: bool

    @classmethod
    def from_model(cls, model, control: Control | None = None) -> Float64Model:
        """Read ``model``'s host arrays and per-spring ks/kd, and ``control``'s gravity, drag and
        wind (default: ``Control()``, gravity only)."""
        if getattr(model, "hinge_count", 0):
            raise WarpclothError(
                "the float64 reference has springs only, no dihedral bending: it cannot judge a "
                "bend='dihedral' model (use provot, choi_ko or none)"
            )
        if getattr(model, "has_compression", False):
            raise WarpclothError(
                "the float64 reference has springs as stiff in compression as in tension: it cannot judge a "
                "model with a compression factor below 1 (give the material compression 1)"
            )
        control = control if control is not None else Control(device="cpu")
        h = model.host
        n = int(h.q.shape[0])
        free = np.ones(n, dtype=bool)
        free[np.asarray(model.pinned, dtype=np.int64)] = False
        free &= h.inv_mass > 0
        return cls(
            q0=h.q.astype(np.float64),
            mass=h.mass.astype(np.float64),
            free=free,
            pairs=h.pairs.astype(np.int64).reshape(-1, 2),
            rest=h.rest.astype(np.float64),
            ks=model.spring_stiffness.numpy().astype(np.float64),
            kd=model.spring_damping.numpy().astype(np.float64),
            tris=h.tris.astype(np.int64).reshape(-1, 3),
            gravity=np.asarray(control.gravity, dtype=np.float64),
            drag_rate=float(control.drag_rate),
            wind_coefficient=float(control.wind_coefficient),
            wind_schedule=control.wind_schedule,
            wind_on=bool(control.has_wind),
        )

    @property
    def particle_count(self) -> int:
        return int(self.q0.shape[0])

    def wind(self, t: float) -> np.ndarray:
        """W(t) [m/s] (zero when wind is off)."""
        return self.wind_schedule(t) if self.wind_on else np.zeros(3)

    def spring_forces(self, x: np.ndarray, v: np.ndarray | None = None) -> np.ndarray:
        """(S, 3) force on the first particle of each spring (the second gets the opposite)."""
        i, j = self.pairs[:, 0], self.pairs[:, 1]
        d = x[j] - x[i]
        length = np.sqrt(np.einsum("sk,sk->s", d, d))
        safe = np.where(length > 0.0, length, 1.0)
        n = np.where((length > 0.0)[:, None], d / safe[:, None], 0.0)  # L = 0: no force (as the kernel)
        magnitude = self.ks * (length - self.rest)
        if v is not None:
            magnitude = magnitude + self.kd * np.einsum("sk,sk->s", v[j] - v[i], n)
        return magnitude[:, None] * n

    def wind_forces(self, x: np.ndarray, v: np.ndarray, wind: np.ndarray) -> np.ndarray:
        """(T, 3) wind force on each vertex of each triangle (one third of the triangle's)."""
        a, b, c = self.tris[:, 0], self.tris[:, 1], self.tris[:, 2]
        cr = np.cross(x[b] - x[a], x[c] - x[a])
        twice_area = np.sqrt(np.einsum("tk,tk->t", cr, cr))
        safe = np.where(twice_area > 0.0, twice_area, 1.0)
        n = np.where((twice_area > 0.0)[:, None], cr / safe[:, None], 0.0)
        v_mean = (v[a] + v[b] + v[c]) / 3.0
        u = np.asarray(wind, dtype=np.float64)[None, :] - v_mean
        magnitude = self.wind_coefficient * 0.5 * twice_area * np.einsum("tk,tk->t", n, u)
        return (magnitude / 3.0)[:, None] * n

    def forces(self, x: np.ndarray, v: np.ndarray, wind: np.ndarray | None = None) -> np.ndarray:
        """(N, 3) net force [N] at positions ``x``, velocities ``v`` and wind velocity ``wind``
        (None: no wind), on every particle, pinned ones included (as ``eval_forces``)."""
        x = np.asarray(x, dtype=np.float64).reshape(-1, 3)
        v = np.asarray(v, dtype=np.float64).reshape(-1, 3)
        f = self.mass[:, None] * (self.gravity[None, :] - self.drag_rate * v)
        if self.pairs.shape[0]:
            fs = self.spring_forces(x, v)
            scatter_add(f, self.pairs[:, 0], fs)
            scatter_add(f, self.pairs[:, 1], -fs)
        if wind is not None and self.wind_on and self.tris.shape[0]:
            fw = self.wind_forces(x, v, wind)
            for k in range(3):
                scatter_add(f, self.tris[:, k], fw)
        return f

    # -- statics ---------------------------------------------------------------------------
    def static_forces(self, x: np.ndarray) -> np.ndarray:
        """(N, 3) net force at rest (v = 0, no wind): springs and gravity."""
        return self.forces(x, np.zeros_like(x))

    def potential_energy(self, x: np.ndarray) -> float:
        """Spring energy sum 1/2 ks (L - L0)^2 minus the work of gravity sum m g . x [J]."""
        d = x[self.pairs[:, 1]] - x[self.pairs[:, 0]]
        length = np.sqrt(np.einsum("sk,sk->s", d, d))
        return float(0.5 * np.sum(self.ks * (length - self.rest) ** 2) - np.sum(self.mass * (x @ self.gravity)))

    def stiffness_matrix(self, x: np.ndarray) -> sp.csr_matrix:
        """The (3N, 3N) Hessian of the potential energy, -d(force)/dx, without damping.

        Per spring, K = ks [n n^T + (1 - L0/L)(I - n n^T)] (the full, un-clamped Jacobian); the
        force Jacobian has blocks df_i/dx_i = df_j/dx_j = -K and df_i/dx_j = df_j/dx_i = K, so
        the Hessian has +K on the diagonal blocks and -K off the diagonal.
        """
        n_dof = 3 * self.particle_count
        i, j = self.pairs[:, 0], self.pairs[:, 1]
        d = x[j] - x[i]
        length = np.sqrt(np.einsum("sk,sk->s", d, d))
        n = d / length[:, None]
        nn = n[:, :, None] * n[:, None, :]
        K = self.ks[:, None, None] * (nn + (1.0 - self.rest / length)[:, None, None] * (np.eye(3)[None] - nn))
        shape = K.shape  # (S, 3, 3): entry [s, r, c] goes to row 3a + r, column 3b + c
        r3 = np.arange(3)
        rows, cols, vals = [], [], []
        for a, b, sign in ((i, i, 1.0), (j, j, 1.0), (i, j, -1.0), (j, i, -1.0)):
            rows.append(np.broadcast_to(3 * a[:, None, None] + r3[None, :, None], shape).ravel())
            cols.append(np.broadcast_to(3 * b[:, None, None] + r3[None, None, :], shape).ravel())
            vals.append((sign * K).ravel())
        # duplicate (row, column) pairs add up: a particle's diagonal block sums its springs
        return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n_dof, n_dof))


def scatter_add(f: np.ndarray, index: np.ndarray, values: np.ndarray) -> None:
    """f[index[k]] += values[k] for every k (repeated indices add up), one bincount per axis."""
    n = f.shape[0]
    for k in range(3):
        f[:, k] += np.bincount(index, weights=values[:, k], minlength=n)


def reference_forces(model, control: Control | None, x, v, t: float = 0.0) -> np.ndarray:
    """The float64 net force [N], (N, 3), on every particle of ``model`` at positions ``x``,
    velocities ``v`` and time ``t`` (for W(t)): what ``warpcloth.integrators.forces.eval_forces`` computes
    in float32. ``control`` None: gravity only."""
    m64 = Float64Model.from_model(model, control)
    return m64.forces(x, v, m64.wind(t))


# -- the wind schedule's switch times --------------------------------------------------------
def wind_switch_times(schedule: WindSchedule, t0: float, t1: float) -> list[float]:
    """Times in the open interval (t0, t1) where the piecewise constant W(t) may jump: every
    start time, repeated every period for a periodic schedule (and the period's wrap-around)."""
    starts = [float(s) for s in schedule.starts]
    if not starts or t1 <= t0:
        return []
    if schedule.period > 0:
        period = float(schedule.period)
        points = set()
        base = [s % period for s in starts] + [0.0]
        k0 = math.floor(t0 / period) - 1
        k1 = math.ceil(t1 / period) + 1
        for k in range(k0, k1 + 1):
            for s in base:
                t = k * period + s
                if t0 < t < t1:
                    points.add(t)
        return sorted(points)
    return sorted({s for s in starts if t0 < s < t1})


# -- trajectories ----------------------------------------------------------------------------
def frame_count(duration: float, frame_dt: float) -> int:
    duration = require_positive("duration", duration, "s")
    frame_dt = require_positive("frame dt", frame_dt, "s")
    frames = int(round(duration / frame_dt))
    require(
        frames >= 1 and abs(frames * frame_dt - duration) <= 1e-9 * duration,
        f"duration {duration!r} s must be a whole number of frames of {frame_dt!r} s",
    )
    return frames


def initial_state(m64: Float64Model, x0, v0) -> tuple[np.ndarray, np.ndarray]:
    n = m64.particle_count
    x = m64.q0.copy() if x0 is None else np.array(x0, dtype=np.float64).reshape(-1, 3)
    v = np.zeros((n, 3)) if v0 is None else np.array(v0, dtype=np.float64).reshape(-1, 3)
    require(x.shape == (n, 3) and v.shape == (n, 3), f"x0 and v0 must have shape ({n}, 3)")
    require(bool(np.all(np.isfinite(x)) and np.all(np.isfinite(v))), "x0 and v0 must be finite")
    return x, v


def reference_trajectory(
    model,
    control: Control | None,
    duration: float,
    frame_dt: float,
    x0=None,
    v0=None,
    rtol: float = 1e-10,
    atol: float = 1e-12,
    method: str = "DOP853",
) -> np.ndarray:
    """Positions [m] at the frame times t_k = k frame_dt, k = 0..frames, shape (frames + 1, N, 3),
    integrated in float64 from (``x0``, ``v0``) at t = 0 (default: the model's rest shape, at rest).

    ``solve_ivp`` (``method``, default DOP853, tolerances ``rtol``/``atol`` on positions [m] and
    velocities [m/s]) runs piecewise between the switch times of the wind schedule, restarted at
    each. Pinned particles keep x0 and v0. Raises :class:`WarpclothError` if the integration fails.
    """
    frames = frame_count(duration, frame_dt)
    m64 = Float64Model.from_model(model, control)
    x, v = initial_state(m64, x0, v0)
    free = m64.free
    nf = int(free.sum())
    m_free = m64.mass[free][:, None]
    out = np.empty((frames + 1, m64.particle_count, 3))
    out[:] = x[None]
    if nf == 0:
        return out
    times = np.arange(frames + 1) * float(frame_dt)
    times[-1] = float(duration)
    x_work, v_work = x.copy(), v.copy()

    def rhs(t, y, wind):
        x_work[free] = y[: 3 * nf].reshape(nf, 3)
        v_work[free] = y[3 * nf :].reshape(nf, 3)
        f = m64.forces(x_work, v_work, wind)
        return np.concatenate([y[3 * nf :], (f[free] / m_free).ravel()])

    y = np.concatenate([x[free].ravel(), v[free].ravel()])
    bounds = [0.0] + wind_switch_times(m64.wind_schedule, 0.0, float(duration)) if m64.wind_on else [0.0]
    bounds = bounds + [float(duration)]
    for a, b in itertools.pairwise(bounds):
        wind = m64.wind(0.5 * (a + b)) if m64.wind_on else None
        inside = np.nonzero((times > a) & (times < b))[0]
        t_eval = np.concatenate([times[inside], [b]])
        sol = solve_ivp(rhs, (a, b), y, method=method, t_eval=t_eval, rtol=rtol, atol=atol, args=(wind,))
        if not sol.success:
            raise WarpclothError(f"the reference integration failed between t = {a:g} s and {b:g} s: {sol.message}")
        for col, k in enumerate(inside):
            out[k, free] = sol.y[: 3 * nf, col].reshape(nf, 3)
        y = sol.y[:, -1]
        last = np.nonzero(np.isclose(times, b, rtol=0.0, atol=1e-12 * max(1.0, b)))[0]
        for k in last:
            out[k, free] = y[: 3 * nf].reshape(nf, 3)
    return out


class Convergence(NamedTuple):
    """Result of :func:`convergence_check`.

    difference: max over frames and particles of |x_tol - x_tight| [m];
    reference: the trajectory at the tighter tolerances, (frames + 1, N, 3)."""

    difference: float
    reference: np.ndarray


def convergence_check(
    model,
    control: Control | None,
    duration: float,
    frame_dt: float,
    x0=None,
    v0=None,
    rtol: float = 1e-10,
    atol: float = 1e-12,
    factor: float = 100.0,
) -> Convergence:
    """Integrate at (rtol, atol) and at (rtol/factor, atol/factor); the max difference between
    the two estimates the error of the first (the second is ``factor``x more accurate)."""
    require(factor > 1.0, f"factor must be > 1, got {factor!r}")
    a = reference_trajectory(model, control, duration, frame_dt, x0, v0, rtol=rtol, atol=atol)
    b = reference_trajectory(model, control, duration, frame_dt, x0, v0, rtol=rtol / factor, atol=atol / factor)
    return Convergence(float(np.max(np.linalg.norm(a - b, axis=-1))), b)


def cloth_size(model) -> float:
    """The cloth's size [m]: max(width, height) of the model."""
    return float(max(model.width, model.height))


def trajectory_error(x_traj, x_ref, size: float) -> float:
    """max over frames and particles of |x - x_ref| / size (the design's error e)."""
    a = np.asarray(x_traj, dtype=np.float64)
    b = np.asarray(x_ref, dtype=np.float64)
    require(a.shape == b.shape, f"trajectories differ in shape: {a.shape} vs {b.shape}")
    size = require_positive("cloth size", size, "m")
    return float(np.max(np.linalg.norm(a - b, axis=-1)) / size)


def simulate_frames(sim, duration: float, frame_dt: float) -> np.ndarray:
    """Run a :class:`~warpcloth.simulator.Simulator` from its current state and sample its
    positions at every frame, (frames + 1, N, 3) float64, comparable with
    :func:`reference_trajectory`. ``frame_dt`` must be a whole number of steps ``sim.dt``."""
    frames = frame_count(duration, frame_dt)
    steps = int(round(frame_dt / sim.dt))
    require(
        steps >= 1 and abs(steps * sim.dt - frame_dt) <= 1e-9 * frame_dt,
        f"frame dt {frame_dt!r} s must be a whole number of steps of {sim.dt!r} s",
    )
    out = [sim.state.particle_q.numpy().astype(np.float64)]
    for _ in range(frames):
        sim.simulate(steps)
        out.append(sim.state.particle_q.numpy().astype(np.float64))
    return np.stack(out)


def swing_from_horizontal(model) -> np.ndarray:
    """Initial positions (N, 3) of the swinging transient: the rest shape rotated by 90 degrees
    about the x axis through particle 0, so a vertical sheet pinned along its top row starts
    horizontal (extending along +z), unstrained, and swings down under gravity."""
    q = model.host.q.astype(np.float64)
    rel = q - q[0]
    out = q.copy()
    out[:, 1] = q[0, 1] + rel[:, 2]
    out[:, 2] = q[0, 2] - rel[:, 1]
    return out


# -- statics ---------------------------------------------------------------------------------
class Equilibrium(NamedTuple):
    """Result of :func:`static_equilibrium`: positions x (N, 3) [m] and the residual, the largest
    net force on a free particle [N]."""

    x: np.ndarray
    residual: float


def static_equilibrium(
    model, control: Control | None = None, x0=None, tol: float = 1e-10, max_iter: int = 200
) -> Equilibrium:
    """The float64 static equilibrium under gravity (wind, drag and damping do not enter):
    positions where the net force on every free particle is zero.

    Newton's method on the potential energy E (springs + gravity) with the analytic Hessian
    (:meth:`Float64Model.stiffness_matrix`, the full un-clamped spring Jacobian, sparse,
    ``spsolve``), started from ``x0`` (default: the rest shape). Where the Hessian is singular
    or indefinite enough that the Newton step is not a descent direction, a multiple of the
    identity is added (Levenberg-Marquardt); an Armijo backtracking line search on E keeps every
    step downhill, so the solve ends at a stable equilibrium. Stops when the residual (largest
    |net force| on a free particle) is below ``tol`` [N] or after ``max_iter`` iterations;
    returns the positions and the residual (check it).
    """
    m64 = Float64Model.from_model(model, control)
    x, _ = initial_state(m64, x0, None)
    return minimize(m64, x, None, tol, max_iter)


class Penalty:
    """Frictionless contact with spheres and planes as the penalty energy 1/2 kappa phi^2 per
    particle, phi = max(0, penetration) of the collider's surface offset by its thickness."""

    def __init__(self, colliders, kappa: float):
        self.kappa = float(kappa)
        self.spheres, self.planes = [], []
        for c in colliders:
            if isinstance(c, Sphere):
                self.spheres.append((np.asarray(c.center, dtype=np.float64), float(c.radius) + float(c.thickness)))
            elif isinstance(c, Plane):
                nrm = np.asarray(c.normal, dtype=np.float64)
                nrm = nrm / np.linalg.norm(nrm)
                self.planes.append((np.asarray(c.point, dtype=np.float64) + float(c.thickness) * nrm, nrm))
            else:
                raise WarpclothError(f"contact_equilibrium supports spheres and planes, not {type(c).__name__}")

    def terms(self, x: np.ndarray):
        """Per contact: (penetration (N,) >= 0, outward normal (N, 3), curvature 1/r (N,) or 0)."""
        out = []
        for c, radius in self.spheres:
            d = x - c
            r = np.sqrt(np.einsum("nk,nk->n", d, d))
            nrm = d / np.where(r > 0, r, 1.0)[:, None]
            out.append((np.maximum(0.0, radius - r), nrm, 1.0 / np.where(r > 0, r, np.inf)))
        for p, nrm in self.planes:
            out.append((np.maximum(0.0, -(x - p) @ nrm), np.broadcast_to(nrm, x.shape), np.zeros(x.shape[0])))
        return out

    def energy(self, x) -> float:
        return float(sum(0.5 * self.kappa * np.sum(phi**2) for phi, _, _ in self.terms(x)))

    def forces(self, x) -> np.ndarray:
        f = np.zeros_like(x)
        for phi, nrm, _ in self.terms(x):
            f += self.kappa * phi[:, None] * nrm
        return f

    def penetration(self, x) -> float:
        return float(max((phi.max() for phi, _, _ in self.terms(x)), default=0.0))

    def hessian(self, x) -> sp.csr_matrix:
        """d^2 E / dx^2: kappa (n n^T - phi / r (I - n n^T)) on the particles in contact."""
        n_dof = x.size
        rows, cols, vals = [], [], []
        r3 = np.arange(3)
        for phi, nrm, curv in self.terms(x):
            active = np.nonzero(phi > 0)[0]
            if active.size == 0:
                continue
            nn = nrm[active, :, None] * nrm[active, None, :]
            blk = self.kappa * (nn - (phi[active] * curv[active])[:, None, None] * (np.eye(3)[None] - nn))
            rows.append(np.broadcast_to(3 * active[:, None, None] + r3[None, :, None], blk.shape).ravel())
            cols.append(np.broadcast_to(3 * active[:, None, None] + r3[None, None, :], blk.shape).ravel())
            vals.append(blk.ravel())
        if not rows:
            return sp.csr_matrix((n_dof, n_dof))
        return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n_dof, n_dof))


def minimize(m64: Float64Model, x: np.ndarray, penalty: Penalty | None, tol: float, max_iter: int) -> Equilibrium:
    """Newton (Levenberg-Marquardt where needed, Armijo line search) on the potential energy plus
    ``penalty``'s, from ``x``, until the largest net force on a free particle is <= ``tol`` [N]."""
    free = m64.free
    fdof = (3 * np.nonzero(free)[0][:, None] + np.arange(3)[None, :]).ravel()
    if fdof.size == 0:
        return Equilibrium(x, 0.0)
    mu_floor = 1e-10 * max(1.0, float(m64.ks.max()) if m64.ks.size else 1.0)

    def forces(y):
        f = m64.static_forces(y)
        return f + penalty.forces(y) if penalty is not None else f

    def energy(y):
        e = m64.potential_energy(y)
        return e + penalty.energy(y) if penalty is not None else e

    def residual(f):
        return float(np.max(np.linalg.norm(f[free], axis=1)))

    f = forces(x)
    res = residual(f)
    for _ in range(max_iter):
        if res <= tol:
            break
        g = -f.ravel()[fdof]  # gradient of E on the free degrees of freedom
        K = m64.stiffness_matrix(x)
        if penalty is not None:
            K = K + penalty.hessian(x)
        H = K[fdof][:, fdof].tocsc()
        eye = sp.identity(fdof.size, format="csc")
        mu, d = 0.0, None
        for _attempt in range(60):
            with warnings.catch_warnings():
                warnings.simplefilter("error", MatrixRankWarning)
                try:
                    step = spsolve(H + mu * eye if mu > 0 else H, -g)
                except (MatrixRankWarning, RuntimeError):
                    step = None
            if step is not None and np.all(np.isfinite(step)) and float(g @ step) < 0.0:
                d = step
                break
            mu = max(10.0 * mu, mu_floor)
        if d is None:
            raise WarpclothError("static equilibrium: no descent direction (is every free particle held by springs?)")
        e0 = energy(x)
        slack = 1e-13 * (abs(e0) + float(np.sum(m64.mass * np.abs(x @ m64.gravity))) + 1.0)
        slope = float(g @ d)
        alpha = 1.0
        while True:
            trial = x.copy()
            trial.ravel()[fdof] += alpha * d
            if energy(trial) <= e0 + 1e-4 * alpha * slope + slack or alpha < 1e-12:
                break
            alpha *= 0.5
        x = trial
        f = forces(x)
        res = residual(f)
    return Equilibrium(x, res)


class ContactEquilibrium(NamedTuple):
    """Result of :func:`contact_equilibrium`: positions x (N, 3) [m]; residual: the largest net
    force on a free particle, the contact force included [N]; penetration: the largest depth of
    a particle inside a collider's offset surface [m]; contacts: particles in contact; kappa:
    the last penalty stiffness [N/m]."""

    x: np.ndarray
    residual: float
    penetration: float
    contacts: int
    kappa: float


def contact_equilibrium(
    model,
    control: Control | None = None,
    x0=None,
    colliders=None,
    tol: float = 1e-9,
    penetration_tol: float = 1e-9,
    max_iter: int = 200,
    kappa: float | None = None,
) -> ContactEquilibrium:
    """The float64 static equilibrium under gravity with frictionless contact against spheres and
    planes (``colliders``; default ``control.colliders``): springs and gravity in balance with
    normal contact forces, no particle inside a collider's surface offset by its thickness.

    A penalty continuation: Newton (:func:`static_equilibrium`'s, on E + 1/2 kappa sum phi^2,
    phi the penetration depth) for kappa = 100 max ks, then x 10 from the last solution, until
    the deepest penetration is <= ``penetration_tol`` x the cloth size; the contact force on a
    particle is kappa phi along the collider's normal. With frictionless colliders and the cloth
    held by pins the equilibrium is unique where it is a strict minimum; starting from ``x0``
    (default: the rest shape with the particles inside a collider moved onto its surface); ``kappa``: the first penalty
    stiffness instead (e.g. a previous solve's, to start from its solution). Raises
    WarpclothError when the continuation does not reach the penetration tolerance.
    """
    m64 = Float64Model.from_model(model, control)
    x, _ = initial_state(m64, x0, None)
    colliders = tuple(control.colliders if colliders is None and control is not None else colliders or ())
    size = cloth_size(model)
    if x0 is None:  # the rest shape with every free particle inside a collider moved out onto its surface
        for phi, nrm, _ in Penalty(colliders, 1.0).terms(x):
            x[m64.free] += (phi[:, None] * nrm)[m64.free]
    if kappa is None:
        kappa = 100.0 * max(1.0, float(m64.ks.max()) if m64.ks.size else 1.0)
    for _ in range(20):
        pen = Penalty(colliders, kappa)
        # the force's rounding grows with kappa: kappa x 1e-14 of the size is the attainable residual
        eq = minimize(m64, x, pen, max(tol, 1e-14 * kappa * size), max_iter)
        x = eq.x
        depth = pen.penetration(x)
        if depth <= penetration_tol * size:
            contacts = int(sum(int(np.count_nonzero(phi > 0)) for phi, _, _ in pen.terms(x)))
            return ContactEquilibrium(x, eq.residual, depth, contacts, kappa)
        kappa *= 10.0 if depth > 1e3 * penetration_tol * size else max(2.0, 1.5 * depth / (penetration_tol * size))
    raise WarpclothError(f"contact equilibrium: penetration {depth:.3g} m after kappa = {kappa:.3g} N/m")
