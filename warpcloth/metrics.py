"""Run metrics: stability, equilibrium and strain, reduced on the device and read once per frame.

Definitions (shared by every integrator, see design.md):

* **unstable**: a non-finite position, velocity or force, or a spring stretched past
  ``instability_strain`` (default 1.0, i.e. twice its rest length).
* **equilibrium**: over a window of ``window`` seconds of simulated time, at every sampled frame,
  every free particle's speed is below ``speed_tol`` and its net force per unit weight
  |f| / (m |g|) below ``force_tol`` -- or below the float32 force floor, if that is larger:
  positions are stored in float32, so a particle cannot sit closer to equilibrium than one unit
  in the last place u of its coordinates, which leaves a net force up to sum_j ks_ij u on it. The
  floor is max_i sum_j ks_ij u / (m_i |g|) (reported as ``force_floor``); for stiff cloth it
  exceeds any useful tolerance and the speed criterion decides. Position-based integrators have no net force from springs:
  for them only the speed criterion applies (:attr:`FrameMetrics.force_checked` is False).
  The time reported is the start of that window (when the cloth came to rest).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import warp as wp

from warpcloth.kernels import metrics as mk

from .errors import require_positive
from .forces import eval_forces


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

    def at_rest(self, criteria: EquilibriumCriteria, force_floor: float = 0.0) -> bool:
        ok = self.finite and self.max_speed < criteria.speed_tol
        if self.force_checked:
            ok = ok and self.max_force_per_weight < max(criteria.force_tol, force_floor)
        return ok


class MetricsProbe:
    """Reduces the metrics of a state on the device; scratch is made once per model."""

    def __init__(self, model, control):
        self.model = model
        self.control = control
        with wp.ScopedDevice(model.device):
            self.buffer = wp.zeros(mk.METRIC_COUNT, dtype=float)
            self.force = wp.zeros(model.particle_count, dtype=wp.vec3)
            self.energy_buffer = wp.zeros(1, dtype=wp.float64)
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
            wp.launch(mk.reduce_spring_strain, dim=m.spring_count, inputs=[state.particle_q, m.spring_indices, m.spring_rest_length], outputs=[self.buffer], device=d)
        wp.launch(
            mk.reduce_particle_motion,
            dim=m.particle_count,
            inputs=[state.particle_q, state.particle_qd, self.force, m.particle_mass, m.particle_inv_mass, float(self.control.gravity_magnitude)],
            outputs=[self.buffer],
            device=d,
        )
        b = self.buffer.numpy()
        finite = bool(b[mk.NON_FINITE] == 0.0 and np.all(np.isfinite(b)))
        return FrameMetrics(
            max_strain=float(b[mk.MAX_STRAIN]),
            max_speed=float(b[mk.MAX_SPEED]),
            max_force_per_weight=float(b[mk.MAX_FORCE_PER_WEIGHT]) if with_force else float("nan"),
            finite=finite,
            force_checked=with_force,
        )

    def energy(self, state) -> float:
        """Total mechanical energy [J]: kinetic + gravitational + spring (ks (L - L0)^2 / 2)."""
        m = self.model
        self.energy_buffer.zero_()
        wp.launch(
            mk.reduce_energy,
            dim=m.particle_count + m.spring_count,
            inputs=[state.particle_q, state.particle_qd, m.particle_mass, m.spring_indices, m.spring_rest_length, m.spring_stiffness, wp.vec3(*self.control.gravity)],
            outputs=[self.energy_buffer],
            device=m.device,
        )
        return float(self.energy_buffer.numpy()[0])


def force_floor(model, control) -> float:
    """The float32 force floor per unit weight, max_i sum_j ks_ij u / (m_i |g|) (see module doc),
    u the spacing of float32 numbers at the largest coordinate the cloth can reach."""
    h = model.host
    reach = float(np.abs(h["q"]).max()) + model.width + model.height
    ulp = float(np.spacing(np.float32(reach)))
    ks_sum, _ = model.particle_spring_sums()
    g = max(control.gravity_magnitude, 1.0e-6)
    return float(np.max(ks_sum * ulp / (h["mass"] * g)))


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
