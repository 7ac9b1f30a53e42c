"""Mutable simulation state: positions, velocities and the force accumulator.

A :class:`~warpcloth.simulator.Simulator` steps its own state in place (``step``, ``simulate``) or
reads one state and writes another (``step_states``); what else a run carries between steps
(an integrator's history, the self-contact lists, the clock) is in its snapshot (``Simulator.snapshot``).
"""

from __future__ import annotations

from dataclasses import dataclass

import warp as wp


@dataclass
class State:
    """Cloth state on one device.

    Attributes:
        particle_q: positions [m], shape (particle_count,), vec3.
        particle_qd: velocities [m/s], shape (particle_count,), vec3.
        particle_f: force accumulator [N], shape (particle_count,), vec3.
    """

    particle_q: wp.array
    particle_qd: wp.array
    particle_f: wp.array

    @classmethod
    def from_model(cls, model) -> State:
        with wp.ScopedDevice(model.device):
            return cls(
                particle_q=wp.clone(model.particle_q),
                particle_qd=wp.zeros_like(model.particle_q),
                particle_f=wp.zeros_like(model.particle_q),
            )

    def assign(self, other: State) -> None:
        """Copy ``other`` into this state (no allocation)."""
        wp.copy(self.particle_q, other.particle_q)
        wp.copy(self.particle_qd, other.particle_qd)
        wp.copy(self.particle_f, other.particle_f)

    @property
    def particle_count(self) -> int:
        return int(self.particle_q.shape[0])

    def clone(self) -> State:
        """A new state with copies of this one's arrays (on the same device): a branch point for
        :meth:`Simulator.step_states <warpcloth.simulator.Simulator.step_states>`."""
        return State(wp.clone(self.particle_q), wp.clone(self.particle_qd), wp.clone(self.particle_f))
