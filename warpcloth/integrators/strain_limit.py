"""Provot's deformation constraints (super-elasticity correction; Provot 1995, seed 2.1.3.3).

After an integrator step, every structural and shear spring longer than (1 + tau) L0 is shortened
to (1 + tau) L0 by moving its ends along the spring, split by inverse mass (a pinned end does not
move):

    c = (L - (1 + tau) L0) / (w_i + w_j) n ;  x_i += w_i c ;  x_j -= w_j c

The springs are split once into colours in which no two springs share a particle; a pass solves
the colours one after the other (parallel within a colour, Gauss-Seidel across colours), the
springs with a pinned end last. Passes repeat until no spring is longer than (1 + tau) L0 by more
than ``tolerance`` L0, or ``max_passes`` is reached. A hanging cloth propagates corrections from
its pins only slowly through such passes, so each step first applies long-range attachments
(Kim, Chentanez & Mueller 2012): |x_i - x_pin| <= (1 + tau) g_i, g_i the rest length of the
shortest structural/shear path from particle i to its nearest pin. They are implied by the spring
limits, so they change no answer, only the number of passes. At the end,
v += (x_corrected - x_step) / dt keeps velocities consistent with the positions.

Each step also counts, on the device, whether the limit moved any particle (it engaged: the step's
result is not the model's own) and whether its passes stopped at ``max_passes``; :meth:`StrainLimiter.stats`
reads the counts once (a run's result reports them: no silent capped step).
"""

from __future__ import annotations

import numpy as np
import warp as wp

from warpcloth.errors import require_int, require_positive
from warpcloth.kernels import strain_limit as sk
from warpcloth.sim.coloring import Coloring, greedy_spring_colors
from warpcloth.sim.model import SpringType

#: Most passes over all colours per step.
DEFAULT_MAX_PASSES = 200
#: Passes stop once no spring's strain exceeds tau by more than this.
DEFAULT_TOLERANCE = 1.0e-4


def nearest_pin_paths(pairs: np.ndarray, rest: np.ndarray, particle_count: int, pins) -> tuple[np.ndarray, np.ndarray]:
    """Multi-source Dijkstra over the springs: for each particle, the nearest pin (-1 if none is
    connected) and the rest length g of the shortest spring path to it [m] (inf if none).

    ``scipy.sparse.csgraph.dijkstra``: at 256 x 256 the search took 0.015-0.018 s where a Python
    heap took 0.65-0.89 s (single runs; every implicit_euler simulator builds a limiter for its
    strain cap, whose spring colouring, ~0.3 s there, is the rest of its build). A spring listed
    twice counts with its shorter rest length."""
    from scipy.sparse import csr_matrix  # noqa: PLC0415 (SciPy loads only where this solve runs: stepping loads none)
    from scipy.sparse.csgraph import dijkstra  # noqa: PLC0415 (SciPy loads only where this solve runs: stepping loads none)

    n = int(particle_count)
    source = np.full(n, -1, dtype=np.int32)
    pins = np.asarray(pins, dtype=np.int64)
    if len(pins) == 0:
        return source, np.full(n, np.inf)
    pairs = np.sort(np.asarray(pairs, dtype=np.int64).reshape(-1, 2), axis=1)
    rest = np.asarray(rest, dtype=np.float64)
    order = np.lexsort((rest, pairs[:, 1], pairs[:, 0]))  # by pair, shortest first
    pairs, rest = pairs[order], rest[order]
    first = np.ones(len(pairs), dtype=bool)
    first[1:] = np.any(pairs[1:] != pairs[:-1], axis=1)
    graph = csr_matrix((rest[first], (pairs[first, 0], pairs[first, 1])), shape=(n, n))
    dist, _, nearest = dijkstra(graph, directed=False, indices=pins, min_only=True, return_predecessors=True)
    reached = np.isfinite(dist)
    source[reached] = nearest[reached]
    return source, dist


class StrainLimiter:
    """Provot's strain limit on the structural and shear springs of a model.

    Args:
        model: the :class:`~warpcloth.sim.model.ClothModel`.
        tau: largest allowed strain (L - L0) / L0, > 0 (Provot's tau_c; 0.1 is 10 %).
        max_passes: most passes over all spring colours per step (>= 1).
        tolerance: passes stop once every strain is <= tau + tolerance.
    """

    def __init__(self, model, tau: float, max_passes: int = DEFAULT_MAX_PASSES, tolerance: float = DEFAULT_TOLERANCE):
        self.model = model
        self.tau = require_positive("strain limit", tau)
        self.max_passes = require_int("strain limit passes", max_passes, 1)
        self.tolerance = require_positive("strain limit tolerance", tolerance)
        h = model.host
        limited = np.flatnonzero(np.isin(model.spring_type, [SpringType.STRUCTURAL, SpringType.SHEAR]))
        pairs = h.pairs[limited]
        colors = greedy_spring_colors(pairs, model.particle_count)
        # springs with a pinned end get colours of their own, solved last in each pass: they are
        # one-sided (only the free end moves), so they end every pass exactly satisfied
        pinned_end = np.isin(pairs, model.pinned).any(axis=1)
        if pinned_end.any():
            colors[pinned_end] = colors.max() + 1 + greedy_spring_colors(pairs[pinned_end], model.particle_count)
        coloring = Coloring.from_colors(colors)
        order = coloring.order
        #: (offset, count) of each colour in the sorted spring arrays.
        self.colors = list(zip(coloring.starts, coloring.counts))
        max_length = (1.0 + self.tau) * h.rest[limited].astype(np.float64)
        pin, path = nearest_pin_paths(pairs, h.rest[limited].astype(np.float64), model.particle_count, model.pinned)
        path[pin < 0] = 0.0
        with wp.ScopedDevice(model.device):
            self.spring_indices = wp.array(pairs[order].astype(np.int32), dtype=wp.vec2i)
            self.spring_max_length = wp.array(max_length[order].astype(np.float32), dtype=float)
            self.x_before = wp.zeros(model.particle_count, dtype=wp.vec3)
            self.attachment_pin = wp.array(pin, dtype=int)
            self.condition = wp.zeros(1, dtype=wp.int32)
            self.passes = wp.zeros(1, dtype=wp.int32)
            self.attachment_max_length = wp.array(((1.0 + self.tau) * path).astype(np.float32), dtype=float)
            self.engaged = wp.zeros(1, dtype=wp.int32)
            #: [steps, steps the limit moved a particle in, steps whose passes stopped at max_passes]
            self.counts = wp.zeros(3, dtype=wp.int64)

    def apply(self, state, dt: float) -> None:
        """Shorten over-stretched springs of ``state`` in place and update its velocities.

        Launches only: the pass loop is ``wp.capture_while`` on a device flag (a conditional
        node in a captured CUDA graph; on the CPU, a read of that flag in host memory).
        """
        m = self.model
        x = state.particle_q
        wp.copy(self.x_before, x)
        wp.launch(
            sk.solve_long_range_attachment,
            dim=m.particle_count,
            inputs=[x, self.attachment_pin, self.attachment_max_length, m.particle_inv_mass],
            device=m.device,
        )
        wp.launch(sk.reset_strain_limit_loop, dim=1, inputs=[self.condition, self.passes], device=m.device)
        wp.capture_while(self.condition, self._pass, x=x)
        wp.launch(
            sk.apply_position_correction_velocity,
            dim=m.particle_count,
            inputs=[x, self.x_before, m.particle_inv_mass, 1.0 / float(dt)],
            outputs=[state.particle_qd],
            device=m.device,
        )
        wp.launch(
            sk.mark_strain_limit_engaged, dim=m.particle_count, inputs=[x, self.x_before, self.engaged], device=m.device
        )
        wp.launch(
            sk.count_strain_limit_step,
            dim=1,
            inputs=[self.engaged, self.passes, self.max_passes, self.counts],
            device=m.device,
        )

    def stats(self) -> dict:
        """The steps counted since :meth:`reset_stats` (one read of the device counters): ``steps``,
        ``engaged_steps`` (the limit moved a particle: a spring was longer than (1 + tau) L0 after the
        integrator's step) and ``pass_capped_steps`` (its passes stopped at ``max_passes``, the limit
        perhaps not met)."""
        steps, engaged, capped = (int(c) for c in self.counts.numpy())
        return {"tau": self.tau, "steps": steps, "engaged_steps": engaged, "pass_capped_steps": capped}

    def reset_stats(self) -> None:
        """Zero the step counters."""
        self.counts.zero_()

    def _pass(self, x) -> None:
        """One pass over all colours, then set the loop flag if a spring is still too long."""
        m = self.model
        for offset, count in self.colors:
            wp.launch(
                sk.solve_strain_limit,
                dim=count,
                inputs=[x, self.spring_indices, self.spring_max_length, m.particle_inv_mass, offset],
                device=m.device,
            )
        wp.launch(sk.begin_strain_limit_check, dim=1, inputs=[self.condition, self.passes], device=m.device)
        wp.launch(
            sk.check_strain_limit,
            dim=self.spring_indices.shape[0],
            inputs=[
                x,
                self.spring_indices,
                self.spring_max_length,
                self.tau,
                self.tolerance,
                self.max_passes,
                self.passes,
                self.condition,
            ],
            device=m.device,
        )
