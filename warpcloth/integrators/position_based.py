"""What PBD and XPBD share: options, the spring colouring and the predict / update launches.

Position-based integrators treat every spring as a distance constraint and integrate only the
external forces f_ext (gravity, drag, wind). They have no net spring force, so equilibrium is
judged by particle speeds alone (``force_based = False``; see :mod:`warpcloth.run.metrics`).
"""

from __future__ import annotations

from fractions import Fraction
from typing import ClassVar

import numpy as np
import warp as wp

from warpcloth.integrators.base import Integrator, Option, scratch_like
from warpcloth.integrators.forces import eval_external_forces
from warpcloth.kernels import constraints as ck
from warpcloth.sim.coloring import SpringColoring, color_model
from warpcloth.sim.hinges import color_hinges
from warpcloth.sim.pins import has_pin_tracks

#: Most iterations or substeps per step: beyond, one step takes minutes (and a captured frame
#: holds millions of launches); no run needs it.
MAX_COUNT = 10_000


def _at_least_one(value) -> str | None:
    if value < 1:
        return "must be an integer >= 1"
    return None if value <= MAX_COUNT else f"must be at most {MAX_COUNT} (one step would take minutes)"


def in_unit_interval(value) -> str | None:
    return None if 0.0 <= value <= 1.0 else "must be in [0, 1]"


ITERATIONS = Option("iterations", int, 10, "constraint solver iterations per substep (>= 1)", check=_at_least_one)
#: Default 4: with one substep, 10 Gauss-Seidel iterations leave the corners of the 32 x 32
#: sheet stretched past the 100 % strain limit at dt = 1/60 s (the error of an unconverged solve
#: falls about as 1/substeps, Macklin et al. 2019); 4 keep it near 20 %.
SUBSTEPS = Option(
    "substeps",
    int,
    4,
    "substeps per time step, each with its own predict / solve / update (Macklin et al. 2019; >= 1)",
    check=_at_least_one,
)
VELOCITY_DAMPING = Option(
    "velocity_damping",
    float,
    0.0,
    "velocity damping per time step dt, v <- (1 - k_damp) v (Müller 2007's simple global form; "
    "(1 - k_damp)^(1/substeps) per substep), in [0, 1]",
    check=in_unit_interval,
)


class PositionBasedIntegrator(Integrator):
    """Base of :class:`~warpcloth.integrators.pbd.PBD` and :class:`~warpcloth.integrators.xpbd.XPBD`.

    Binding colours the springs (:func:`warpcloth.sim.coloring.color_springs`) and allocates the
    predicted displacements dp = p - x; a step allocates nothing.
    """

    force_based: ClassVar[bool] = False
    collides_in_solver: ClassVar[bool] = True
    self_contact_filter: ClassVar[str] = "gap"  # contacts are constraints of its iterations
    force_evals_per_step: ClassVar[int] = 1
    #: Position-based steps are stable at any dt; one 60 Hz frame is the default.
    default_dt_cap: ClassVar[float] = 1.0 / 60.0
    #: pbd's and xpbd's study grid: substeps x iterations at dt 1/30 s, 1/60 s and 1/240 s.
    study_grid: ClassVar[dict] = {
        "full": ({"substeps": (1, 4, 16, 64, 256), "iterations": (1, 5, 20)}, (Fraction(1, 2), 1, 4)),
        "quick": ({"substeps": (1, 16), "iterations": (1, 10)}, (Fraction(1, 2), 1)),
    }

    @classmethod
    def relative_work(cls, options: dict) -> float:
        """Substeps x iterations (one constraint sweep each) against the defaults'."""
        defaults = cls.option_defaults()
        return options["substeps"] * options["iterations"] / (defaults["substeps"] * defaults["iterations"])

    coloring: SpringColoring

    def default_dt(self, model, drag_rate: float = 0.0) -> float:
        """One 60 Hz frame, 1/60 s: constraint projection does not limit the step."""
        return self.default_dt_cap

    def _allocate(self, model) -> None:
        self.coloring = color_model(model.host.pairs, model, vertices=False)
        self.spring_order = wp.array(self.coloring.order, dtype=wp.int32)
        self.spring_type = wp.array(np.asarray(model.spring_type, dtype=np.int32), dtype=wp.int32)
        self.particle_dp = scratch_like(model)
        self.contact_normal = wp.zeros(model.particle_count, dtype=float, device=model.device)  # per substep
        self._sweep_key, self._sweep = None, []
        # dihedral hinges: their own colouring (no two hinges of a colour share a vertex), swept after the springs
        self.hinge_coloring = (
            color_hinges(model.host.hinges.indices, model.particle_count) if model.hinge_count else None
        )
        self.hinge_order = wp.array(self.hinge_coloring.order, dtype=wp.int32) if model.hinge_count else None
        self._hinge_sweep_key, self._hinge_sweep = None, []

    def stats(self) -> dict:
        colors = self.coloring.color_count if self.model is not None else 0
        if self.model is not None and self.hinge_coloring is not None:
            colors += self.hinge_coloring.color_count
        return {"colors": colors}

    def along_start(self, control) -> int:
        """1 on a free cloth (no pins, no colliders, no self-collision), else 0: its springs project along
        the substep's start edge x_j - x_i (SHAKE), which keeps its angular momentum exactly where PBD's
        predicted-edge direction turned it (pbd 5.3e-4 kg m^2/s, docs/solvers.md); elsewhere pins and
        contacts exert real torques, and the springs keep the predicted direction (results unchanged)."""
        m = self.model
        return int(len(m.pinned) == 0 and control.collision is None and self.self_collision is None)

    # -- the three phases of Müller et al. 2007, Algorithm 1 ------------------------------------
    def velocity_keep(self) -> float:
        """(1 - k_damp)^(1/substeps): the velocity kept per substep, so that a whole step dt
        keeps 1 - k_damp whatever the number of substeps."""
        return (1.0 - self.velocity_damping) ** (1.0 / self.substeps)

    def predict(self, state, control, h: float, velocity_keep: float, end: float | None = None) -> None:
        """v <- velocity_keep (v + h w f_ext);  dp = p - x = h v; a kinematic pin's
        dp = track(t + end) - x (``end`` the substep's end, from the step's start)."""
        m = self.model
        eval_external_forces(m, state.particle_q, state.particle_qd, control, state.particle_f)
        wp.launch(
            ck.integrate_predict,
            dim=m.particle_count,
            inputs=[state.particle_qd, state.particle_f, m.particle_inv_mass, float(h), float(velocity_keep)],
            outputs=[self.particle_dp],
            device=m.device,
        )
        if end is not None and has_pin_tracks(control):
            control.kinematic_pins.delta(control, state.particle_q, state.particle_qd, end, 1.0, 0.0, self.particle_dp)

    def color_sweep(self, kernel, params: list, outputs: list) -> list:
        """One Gauss-Seidel sweep over the springs: a launch of ``kernel`` per colour, with
        inputs (spring_order, colour start, *params) and ``outputs``.

        The launches are recorded once (``record_cmd``) and reused while the arguments stay the
        same, which cuts the Python cost of the (colours x iterations) launches of a step.
        """
        key = (kernel.key, tuple(_argument_key(a) for a in (*params, *outputs)))
        if key != self._sweep_key:
            d = self.model.device
            self._sweep = [
                wp.launch(
                    kernel,
                    dim=count,
                    inputs=[self.spring_order, start, *params],
                    outputs=outputs,
                    device=d,
                    record_cmd=True,
                )
                for start, count in zip(self.coloring.starts, self.coloring.counts)
            ]
            self._sweep_key = key
        return self._sweep

    def hinge_sweep(self, kernel, params: list, outputs: list) -> list:
        """One Gauss-Seidel sweep over the dihedral hinges (none without them): a launch of ``kernel``
        per hinge colour, with inputs (hinge_order, colour start, *params) and ``outputs``, recorded
        once like :meth:`color_sweep`'s. Sweeping them after the springs keeps Gauss-Seidel valid:
        each launch is independent within itself."""
        if self.hinge_coloring is None:
            return []
        key = (kernel.key, tuple(_argument_key(a) for a in (*params, *outputs)))
        if key != self._hinge_sweep_key:
            d = self.model.device
            self._hinge_sweep = [
                wp.launch(
                    kernel,
                    dim=count,
                    inputs=[self.hinge_order, start, *params],
                    outputs=outputs,
                    device=d,
                    record_cmd=True,
                )
                for start, count in zip(self.hinge_coloring.starts, self.hinge_coloring.counts)
            ]
            self._hinge_sweep_key = key
        return self._hinge_sweep

    def solve(self, state, control, sweep) -> None:
        """``iterations`` Gauss-Seidel sweeps over the springs, each followed by the self-contact
        constraints (with self-collision) and the collision constraints (Müller 2007, Alg. 1 line 13),
        then friction from the accumulated normal corrections (:mod:`warpcloth.sim.colliders`); where
        a collider has friction, one more sweep and the constraints again (normal only) after it."""
        contacts = control.collision
        if contacts is not None:
            self.contact_normal.zero_()
        edges = contacts.edges(self.model) if contacts is not None else None
        for _ in range(self.iterations):
            self._iterate(state, sweep, contacts, edges)
        if contacts is None:
            return
        relax = contacts.has_friction
        contacts.project_displacement(
            self.model, state.particle_q, self.particle_dp, self.contact_normal, friction=True, end_substep=not relax
        )
        if relax:
            # friction held the vertices it stuck and let their neighbours go: one more sweep over the
            # springs, then the contacts again, so that a substep does not end on springs that friction
            # alone stretched (pbd's drape landing: peak strain 0.56 -> 0.35); then friction once more, on the
            # normal correction the first pass left unspent and the sweep's own, so that a vertex static
            # friction holds ends the substep at rest (the sweep alone slid it a few micrometres a substep,
            # millimetres a second: the tablecloth's rest, docs/solvers.md)
            self._iterate(state, sweep, contacts, edges)
            contacts.project_displacement(
                self.model, state.particle_q, self.particle_dp, self.contact_normal, friction=True, end_substep=True
            )

    def _iterate(self, state, sweep, contacts, edges) -> None:
        """One iteration: the sweep over the springs, then the self-contacts, then the colliders (they
        win, friction aside) and their box and mesh edges against the cloth's edges and triangles."""
        for color in sweep:
            color.launch()
        if self.self_collision is not None:
            self.self_collision.project_increment(state.particle_q, self.particle_dp)
        if contacts is not None:
            contacts.project_displacement(
                self.model, state.particle_q, self.particle_dp, self.contact_normal, friction=False
            )
        if edges is not None:
            edges.project_increment(state.particle_q, self.particle_dp)

    def update(self, state, h: float, control=None, end: float | None = None) -> None:
        """v = dp / h;  x += dp; kinematic pins x = track(t + end), v = track'(t + end)."""
        m = self.model
        wp.launch(
            ck.update_velocities,
            dim=m.particle_count,
            inputs=[state.particle_q, state.particle_qd, self.particle_dp, m.particle_inv_mass, float(h)],
            device=m.device,
        )
        if end is not None and has_pin_tracks(control):
            control.kinematic_pins.apply(control, state.particle_q, state.particle_qd, end)


def _argument_key(value):
    """A hashable identity of a launch argument: an array by its memory, a value by itself."""
    if isinstance(value, wp.array):
        return ("array", value.ptr, value.shape)
    if isinstance(value, (int, float, str)):
        return value
    return tuple(float(c) for c in value)


__all__ = ["ITERATIONS", "SUBSTEPS", "VELOCITY_DAMPING", "PositionBasedIntegrator"]
