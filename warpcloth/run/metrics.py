"""Run metrics: stability, equilibrium and strain, reduced on the device and read once per frame.

Definitions (shared by every integrator, see design.md and docs/stability.md):

* **unstable**: a non-finite position, velocity or force; a spring stretched past
  ``instability_strain`` (:data:`DEFAULT_INSTABILITY_STRAIN`); or mechanical energy growing
  beyond what the external forces can supply (:class:`EnergyMonitor`).
* **equilibrium**: over a window of ``window`` seconds of simulated time, at every sampled frame,
  every free particle's speed is below ``speed_tol`` [m/s] and its net force per unit weight
  |f| / (m |g|) below ``force_tol`` -- or below the float32 force floor, if that is larger:
  a particle cannot sit closer to equilibrium than one ulp u of its coordinates, which leaves a
  net force up to sum_j ks_ij u on it, so the floor is max_i sum_j ks_ij u / (m_i |g|) (reported
  as ``force_floor``). Position-based integrators have no net spring force: for them only the
  speed criterion applies (:attr:`FrameMetrics.force_checked` is False). The time reported is the
  start of that window (when the cloth came to rest).

The same force test is made on patches of particles (about 16, 256 and 4096 free particles grown
over the springs, and each connected piece, :func:`particle_aggregates`): |sum_(i in a) f_i| /
(sum m_i |g|) below ``force_tol`` or the patch's own floor (the ks u of the springs crossing its
boundary per unit weight). Springs inside a patch cancel there, so a patch's floor falls with its
size and a stiff cloth's verdict does not rest on speed alone (why, measured: docs/solvers.md,
"The equilibrium verdict"). Not applied where the force is not checked (position-based schemes,
colliders).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import warp as wp

from warpcloth.errors import require_positive
from warpcloth.integrators.forces import eval_forces
from warpcloth.kernels import metrics as mk

#: Default instability strain: a spring stretched past (1 + this) x its rest length is unstable.
#: Measured (``python bench/instability_strain.py``, 4 s of sheet, 5 s of flag): rk4 at a half and
#: a quarter of its default dt reaches 2.8 % on the sheet and 10-14 % on the (fluttering) flag;
#: explicit Euler and implicit Euler at their defaults the same; pbd/xpbd at their defaults, which
#: stretch more, 17-28 %. 0.5 leaves a margin of 1.8x over all of those and flags the 83-99.9 %
#: strains of the flag at the time steps the old criterion (1.0) called stable.
DEFAULT_INSTABILITY_STRAIN = 0.5


@dataclass(frozen=True)
class EquilibriumCriteria:
    """Tolerances of the equilibrium test."""

    speed_tol: float = 5.0e-3  # m/s
    force_tol: float = 1.0e-2  # net force / weight
    window: float = 0.5  # s of simulated time

    def __post_init__(self):
        require_positive("equilibrium speed tolerance", self.speed_tol, "m/s")
        require_positive("equilibrium force tolerance", self.force_tol)
        require_positive("equilibrium window", self.window, "s")


@dataclass(frozen=True)
class FrameMetrics:
    """Metrics of one sampled frame."""

    max_strain: float
    max_speed: float
    max_force_per_weight: float
    finite: bool
    force_checked: bool
    #: per patch of particles (:func:`particle_aggregates`): |net force| / weight, and its float32 floor
    patch_force_per_weight: np.ndarray | None = field(default=None, compare=False, repr=False)
    patch_force_floor: np.ndarray | None = field(default=None, compare=False, repr=False)

    @property
    def max_patch_force_per_weight(self) -> float:
        """The largest patch net force per unit weight (nan when not measured)."""
        p = self.patch_force_per_weight
        return float(p.max()) if p is not None and p.size else float("nan")

    def at_rest(self, criteria: EquilibriumCriteria, force_floor: float = 0.0) -> bool:
        ok = self.finite and self.max_speed < criteria.speed_tol
        if self.force_checked:
            ok = ok and self.max_force_per_weight < max(criteria.force_tol, force_floor)
            patches = self.patch_force_per_weight
            if patches is not None and patches.size:
                ok = ok and bool(np.all(patches < np.maximum(criteria.force_tol, self.patch_force_floor)))
        return ok


class MetricsProbe:
    """Reduces the metrics of a state on the device; scratch is made once per model."""

    def __init__(self, model, control):
        self.model = model
        self.control = control
        with wp.ScopedDevice(model.device):
            self.buffer = wp.zeros(mk.METRIC_COUNT, dtype=float)
            self.force = wp.zeros(model.particle_count, dtype=wp.vec3)
            self.energy_buffer = wp.zeros(mk.ENERGY_COUNT, dtype=wp.float64)
            # the patches of the net-force test as one CSR list (each particle once per level)
            self.patch_index, self.patch_weight, self.patch_floor = particle_aggregates(model, control)
            self.patch_count = self.patch_weight.size
            slots = np.concatenate(self.patch_index) if self.patch_index else np.zeros(0, dtype=np.int32)
            particles = np.tile(np.arange(model.particle_count), len(self.patch_index))
            keep = slots >= 0
            order = np.argsort(slots[keep], kind="stable")
            offsets = np.zeros(self.patch_count + 1, dtype=np.int32)
            offsets[1:] = np.cumsum(np.bincount(slots[keep], minlength=self.patch_count))
            self.patch_offsets = wp.array(offsets, dtype=int)
            self.patch_members = wp.array(particles[keep][order].astype(np.int32), dtype=int)
            self.patch_force = wp.zeros(max(1, self.patch_count), dtype=wp.vec3)
        self.force_floor = force_floor(model, control)

    def measure(self, state, with_force: bool = True) -> FrameMetrics:
        """Metrics of ``state`` (one small device-to-host read)."""
        m, d = self.model, self.model.device
        wp.launch(mk.clear_metrics, dim=mk.METRIC_COUNT, outputs=[self.buffer], device=d)
        if with_force:
            eval_forces(m, state.particle_q, state.particle_qd, self.control, self.force)
        else:
            self.force.zero_()
        if m.spring_count:
            wp.launch(
                mk.reduce_spring_strain,
                dim=m.spring_count,
                inputs=[state.particle_q, m.spring_indices, m.spring_rest_length],
                outputs=[self.buffer],
                device=d,
            )
        wp.launch(
            mk.reduce_particle_motion,
            dim=m.particle_count,
            inputs=[
                state.particle_q,
                state.particle_qd,
                self.force,
                m.particle_mass,
                m.particle_inv_mass,
                float(self.control.gravity_magnitude),
            ],
            outputs=[self.buffer],
            device=d,
        )
        patch_ratio = None
        if with_force and self.patch_count:
            wp.launch(
                mk.reduce_patch_force,
                dim=self.patch_count,
                inputs=[self.force, self.patch_offsets, self.patch_members],
                outputs=[self.patch_force],
                device=d,
            )
            patch_ratio = (
                np.linalg.norm(self.patch_force.numpy()[: self.patch_count].astype(np.float64), axis=1)
                / self.patch_weight
            )
        b = self.buffer.numpy()
        finite = bool(b[mk.NON_FINITE] == 0.0 and np.all(np.isfinite(b)))
        return FrameMetrics(
            max_strain=float(b[mk.MAX_STRAIN]),
            max_speed=float(b[mk.MAX_SPEED]),
            max_force_per_weight=float(b[mk.MAX_FORCE_PER_WEIGHT]) if with_force else float("nan"),
            finite=finite,
            force_checked=with_force,
            patch_force_per_weight=patch_ratio,
            patch_force_floor=self.patch_floor if patch_ratio is not None else None,
        )

    def energy(self, state) -> float:
        """Total mechanical energy [J]: kinetic + gravitational + spring (ks (L - L0)^2 / 2) + hinge
        (k_e (theta - theta0)^2 / 2)."""
        return self.energies(state)[0]

    def energies(self, state) -> tuple[float, float]:
        """(total mechanical energy, kinetic energy) [J] of ``state`` (one small read)."""
        m = self.model
        self.energy_buffer.zero_()
        wp.launch(
            mk.reduce_energy,
            dim=m.particle_count + m.spring_count,
            inputs=[
                state.particle_q,
                state.particle_qd,
                m.particle_mass,
                m.spring_indices,
                m.spring_rest_length,
                m.spring_stiffness,
                m.spring_compression,
                wp.vec3(*self.control.gravity),
            ],
            outputs=[self.energy_buffer],
            device=m.device,
        )
        if m.hinge_count:  # + dihedral bending, 1/2 k_e (theta - theta0)^2
            wp.launch(
                mk.reduce_hinge_energy,
                dim=m.hinge_count,
                inputs=[state.particle_q, *m.hinge_arrays()[:3]],
                outputs=[self.energy_buffer],
                device=m.device,
            )
        e = self.energy_buffer.numpy()
        return float(e[mk.ENERGY_TOTAL]), float(e[mk.ENERGY_KINETIC])


def force_floor(model, control) -> float:
    """The float32 force floor per unit weight, max_i sum_j ks_ij u / (m_i |g|) (see module doc),
    u the spacing of float32 numbers at the largest coordinate the cloth can reach."""
    h = model.host
    reach = float(np.abs(h.q).max()) + model.width + model.height
    ulp = float(np.spacing(np.float32(reach)))
    ks_sum, _ = model.particle_spring_sums()
    g = max(control.gravity_magnitude, 1.0e-6)
    return float(np.max(ks_sum * ulp / (h.mass * g)))


#: Patch sizes (free particles) of the coarse-grained net-force test, besides each connected piece whole.
PATCH_SIZES = (16, 256, 4096)


def _grow_patches(adjacency, free: np.ndarray, target: int) -> np.ndarray:
    """Patch index per particle (-1: pinned): breadth-first over the springs from the lowest
    unassigned free particle until ``target`` particles; a patch left under half the target
    joins a neighbouring one."""
    n = free.size
    label = np.full(n, -1, dtype=np.int64)
    sizes = []
    for seed in range(n):
        if not free[seed] or label[seed] >= 0:
            continue
        k = len(sizes)
        label[seed] = k
        queue, members, head = [seed], 1, 0
        while head < len(queue) and members < target:
            i = queue[head]
            head += 1
            for j in adjacency[i]:
                if free[j] and label[j] < 0 and members < target:
                    label[j] = k
                    queue.append(j)
                    members += 1
        sizes.append(members)
    sizes = np.array(sizes)
    for k in np.flatnonzero(sizes < max(1, target // 2)):
        members = np.flatnonzero(label == k)
        neighbours = {int(label[j]) for i in members for j in adjacency[i] if free[j] and label[j] != k}
        if neighbours:
            into = min(neighbours, key=lambda q: sizes[q])
            label[members] = into
            sizes[into] += sizes[k]
            sizes[k] = 0
    used = np.unique(label[label >= 0])
    remap = np.full(max(1, len(sizes)), -1, dtype=np.int64)
    remap[used] = np.arange(used.size)
    return np.where(label >= 0, remap[np.maximum(label, 0)], -1)


def particle_aggregates(model, control) -> tuple[list[np.ndarray], np.ndarray, np.ndarray]:
    """Patches of free particles for the coarse-grained net-force test: per level (:data:`PATCH_SIZES`,
    then each connected piece), the patch slot of every particle (-1: pinned), slots numbered
    across levels; and per slot its weight sum m |g| [N] and float32 force floor (the ks of the
    springs crossing its boundary times u, per unit weight; u as in :func:`force_floor`)."""
    h = model.host
    n = model.particle_count
    free = h.inv_mass > 0
    pairs = h.pairs.astype(np.int64).reshape(-1, 2)
    ends = np.concatenate([pairs[:, 0], pairs[:, 1]])
    others = np.concatenate([pairs[:, 1], pairs[:, 0]])
    order = np.argsort(ends, kind="stable")
    starts = np.zeros(n + 1, dtype=np.int64)
    starts[1:] = np.cumsum(np.bincount(ends, minlength=n))
    flat = others[order].tolist()
    adjacency = [flat[starts[i] : starts[i + 1]] for i in range(n)]
    levels = [_grow_patches(adjacency, free, t) for t in PATCH_SIZES if t < free.sum()]
    levels.append(_grow_patches(adjacency, free, n))  # connected pieces
    g = max(control.gravity_magnitude, 1.0e-6)
    reach = float(np.abs(h.q).max()) + model.width + model.height
    ulp = float(np.spacing(np.float32(reach)))
    ks = model.spring_stiffness.numpy().astype(np.float64) if model.spring_count else np.zeros(0)
    mass = h.mass.astype(np.float64)
    indices, weights, floors, offset = [], [], [], 0
    for label in levels:
        count = int(label.max()) + 1 if label.size and label.max() >= 0 else 0
        weight = np.bincount(label[free], weights=mass[free], minlength=count) * g
        crossing = np.zeros(count)
        if pairs.size:
            la, lb = label[pairs[:, 0]], label[pairs[:, 1]]
            cut = la != lb
            for end in (la, lb):
                sel = cut & (end >= 0)
                np.add.at(crossing, end[sel], ks[sel])
        indices.append(np.where(label >= 0, label + offset, -1).astype(np.int32))
        weights.append(weight)
        floors.append(crossing * ulp / np.maximum(weight, 1e-300))
        offset += count
    return indices, np.concatenate(weights), np.concatenate(floors)


class EquilibriumDetector:
    """Tracks when the cloth has stayed at rest for a whole window of simulated time."""

    def __init__(self, criteria: EquilibriumCriteria, force_floor: float = 0.0):
        self.criteria = criteria
        self.force_floor = force_floor
        self.rest_since: float | None = None
        self.rest_since_wall: float | None = None

    def update(self, sim_time: float, wall_time: float, frame: FrameMetrics) -> bool:
        """Feed one frame; True once the cloth has been at rest for ``window`` seconds."""
        if frame.at_rest(self.criteria, self.force_floor):
            if self.rest_since is None:
                self.rest_since, self.rest_since_wall = sim_time, wall_time
            return sim_time - self.rest_since >= self.criteria.window - 1e-12
        self.rest_since = self.rest_since_wall = None
        return False


def wind_power_bound(model, control, instability_strain: float) -> float:
    """An upper bound [W] on the power the wind can deliver to the cloth.

    On a triangle of area A and unit normal n moving at v (the mean of its vertices), the wind
    force c_w A (n.u) n, u = W - v, delivers c_w A (n.W - n.v)(n.v) <= c_w A (n.W)^2 / 4
    <= c_w A |W|^2 / 4. A stable cloth's area is at most its rest area times
    (1 + instability_strain)^2, and |W| at most the schedule's largest wind.
    """
    if not control.has_wind or model.tri_count == 0:
        return 0.0
    q = model.host.q.astype(np.float64)
    t = model.host.tris
    area = 0.5 * float(np.linalg.norm(np.cross(q[t[:, 1]] - q[t[:, 0]], q[t[:, 2]] - q[t[:, 0]]), axis=1).sum())
    w2 = max(float(np.dot(w, w)) for w in control.wind_schedule.winds)
    return control.wind_coefficient * area * (1.0 + instability_strain) ** 2 * w2 / 4.0


@dataclass(frozen=True)
class EnergyCriteria:
    """When growing energy counts as unstable (see :class:`EnergyMonitor`)."""

    growth: float = 1.03  # a window's peak excess over the previous window's
    windows: int = 4  # consecutive growing windows
    significance: float = 0.25  # the excess as a fraction of the energy exchanged before it grew
    window_time: float = 0.1  # s of simulated time, at least
    window_steps: int = 10  # steps, at least


class EnergyMonitor:
    """Flags mechanical energy that grows without bound.

    Gravity is conservative; spring damping and drag only remove energy; the wind supplies at
    most :func:`wind_power_bound` P. So a faithful run keeps the excess
    X(t) = E(t) - E(0) - P t at or below zero, up to an integrator's bounded energy error
    (symplectic Euler's energy oscillates, boundedly, by up to ~ (h omega / 2) / (1 - h omega / 2)
    of the energy in a mode). The energy is sampled every frame; frames are grouped into windows
    of at least ``window_time`` seconds and ``window_steps`` steps (several periods of the modes
    whose energy error oscillates). The run is unstable when the windows' peak excess grew by
    ``growth`` in each of ``windows`` consecutive windows and exceeds ``significance`` times the
    energy exchanged before the growth began (the largest kinetic energy, or energy released,
    seen until then): growth without bound, not an oscillation. Undamped RK2, which amplifies
    every mode by sqrt(1 + (h omega)^4 / 4) per step, is caught this way.
    """

    def __init__(
        self, e0: float, power_bound: float, window_frames: int, scale: float, criteria: EnergyCriteria | None = None
    ):
        self.criteria = criteria or EnergyCriteria()
        self.e0 = float(e0)
        self.power_bound = float(power_bound)
        self.window_frames = max(1, int(window_frames))
        self.floor = 1.0e-6 * (abs(self.e0) + float(scale)) + 1.0e-12
        self.exchanged = self.floor  # energy moved around before the current growth streak
        self._frames = 0
        self._peak = -np.inf
        self._kinetic_peak = 0.0
        self._e_min = self.e0
        self._previous_peak = None
        self.streak = 0
        self.excess = 0.0

    def update(self, t: float, energy: float, kinetic: float) -> bool:
        """Feed one frame at simulated time ``t`` since the start [s]; True when unstable."""
        x = energy - self.e0 - self.power_bound * t
        self.excess = x
        self._peak = max(self._peak, x)
        self._kinetic_peak = max(self._kinetic_peak, kinetic)
        self._e_min = min(self._e_min, energy)
        self._frames += 1
        if self._frames < self.window_frames:
            return False
        c, peak, prev = self.criteria, self._peak, self._previous_peak
        growing = prev is not None and peak > self.floor and peak > c.growth * max(prev, 0.0)
        if growing:
            self.streak += 1
        else:
            self.streak = 0
            self.exchanged = max(self.exchanged, self._kinetic_peak, self.e0 - self._e_min)
        self._previous_peak = peak
        self._frames, self._peak = 0, -np.inf
        return self.streak >= c.windows and peak > c.significance * self.exchanged
