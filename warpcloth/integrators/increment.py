"""What the increment solvers share (vbd and projective dynamics): a step is solved for the
increment dx = x_new - x,

    dy = h v + h^2 f_ext / m ;  dx = h v          (predict; kinematic pins: dx = track(t + h) - x)
    ... the scheme's iterations on dx ...          (colliders held inside them)
    v = dx / h ;  x += dx                          (finish; kinematic pins: x = track(t + h))

f_ext = gravity + drag + wind, explicit. The initial guess x + h v makes a rest state of the
stepping the exact static equilibrium whatever the iteration counts. Positions are carried as the
increment dx, so float32 keeps h v whatever |x|. Kernels: :mod:`warpcloth.kernels.increment`.
"""

from __future__ import annotations

from typing import ClassVar

import warp as wp

from warpcloth.integrators.base import Integrator, hinge_adjacency_of, scratch_like, spring_adjacency
from warpcloth.integrators.forces import eval_external_forces
from warpcloth.integrators.linalg import TranslationSolve
from warpcloth.kernels import collide as ck
from warpcloth.kernels import increment as nk
from warpcloth.sim.pins import apply_pins, has_pin_tracks


def at_least_one(value) -> str | None:
    """The check of an iteration-count option (:class:`~warpcloth.integrators.base.Option`)."""
    return None if value >= 1 else "must be an integer >= 1"


class IncrementSolver(Integrator):
    """Base of :class:`~warpcloth.integrators.vbd.VBD` and
    :class:`~warpcloth.integrators.projective.Projective`.

    Binding allocates dx, dy and the contacts with the colliders (:attr:`contacts`, an
    :class:`IncrementContacts`, with the per-particle contact state of the last contact pass), and fills
    the kernels' struct arguments once (:attr:`springs`, :attr:`inertia`, :attr:`contact`); a
    subclass adds its own scratch in :meth:`_allocate_solver`. Its :meth:`step` is :meth:`predict`,
    its iterations on :attr:`dx`, :meth:`finish`.
    """

    force_evals_per_step: ClassVar[int] = 1
    #: contacts inside the iterations (each increment projected out of the colliders with Coulomb
    #: friction, :func:`warpcloth.kernels.increment.project_increment`), no projection after the step
    collides_in_solver: ClassVar[bool] = True

    def default_dt(self, model, drag_rate: float = 0.0) -> float:
        """One 60 Hz frame: the step is implicit (a solve of backward Euler's potential)."""
        return self.default_dt_cap

    def _allocate(self, model) -> None:
        #: Each particle's springs and their parameters (:class:`~warpcloth.kernels.springs.SpringAdjacency`).
        self.springs = spring_adjacency(model)
        #: Each particle's dihedral hinges (:class:`~warpcloth.kernels.bending.HingeAdjacency`; empty without).
        self.hinges = hinge_adjacency_of(model)
        #: The increment dx = x_new - x [m] and the inertial target dy = h v + h^2 f_ext / m [m], shape
        #: (particle_count,).
        self.dx, self.dy = scratch_like(model, 2)
        #: dy with the particle masses (:class:`~warpcloth.kernels.increment.Inertia`).
        self.inertia = nk.Inertia()
        self.inertia.dy = self.dy
        self.inertia.mass, self.inertia.inv_mass = model.particle_mass, model.particle_inv_mass
        #: The contacts with the colliders, phase by phase (:class:`IncrementContacts`).
        self.contacts = IncrementContacts(model)
        # its per-particle state of the last contact pass, also under the names tests and kernels' callers read
        self.contact = self.contacts.state
        self.contact_normal, self.contact_velocity = self.contacts.normal, self.contacts.velocity
        self.contact_force, self.contact_state = self.contacts.force, self.contacts.mode
        #: The rigid translation mode's 3 x 3 Galerkin problem (:class:`~warpcloth.integrators.linalg.TranslationSolve`;
        #: its regular term 1e-6 of the free mass keeps it invertible where every free particle slides on one plane).
        host = model.host
        free_mass = float(host.mass.astype("float64")[host.inv_mass > 0].sum())
        self.rigid = TranslationSolve(model.particle_count, 1.0e-6 * free_mass, model.device)
        self._allocate_solver(model)

    def _allocate_solver(self, model) -> None:
        """The scheme's own scratch (override)."""

    def predict(self, state, control, h: float, clear_contacts: bool = True):
        """dy = h v + h^2 f_ext / m, dx = h v (a kinematic pin's dx = track(t + h) - x, held through
        the iterations); then the contacts' step begins (:meth:`IncrementContacts.begin_step`:
        ``clear_contacts``, whether the contact states are cleared without colliders). Returns the
        colliders as a kernel argument, or None without colliders."""
        m = self.model
        x, v, f = state.particle_q, state.particle_qd, state.particle_f
        eval_external_forces(m, x, v, control, f)
        wp.launch(
            nk.predict_inertia,
            dim=m.particle_count,
            inputs=[v, f, m.particle_inv_mass, h],
            outputs=[self.dy, self.dx],
            device=m.device,
        )
        if has_pin_tracks(control):
            control.kinematic_pins.delta(control, x, v, h, 1.0, 0.0, self.dx)
        return self.contacts.begin_step(control, h, clear_contacts)

    def finish(self, state, control, h: float) -> None:
        """v = dx / h ;  x += dx (:meth:`IncrementContacts.finish`); kinematic pins x = track(t + h),
        v = track'(t + h)."""
        x, v = state.particle_q, state.particle_qd
        self.contacts.finish(x, v, self.dx, h)
        apply_pins(control, x, v, h)


class IncrementContacts:
    """The increment solvers' contacts with the colliders, bound once to a model, by phase of a step:

    - :meth:`begin_step` (after the prediction): the control's colliders as one kernel argument, posed
      at t + h, and their edges; without colliders none (the contact states cleared where asked);
    - :meth:`after_iteration`: box and mesh edges against the cloth's edges and triangles;
    - :meth:`project`: the increment out of the colliders (after a step that may reach into one);
    - :meth:`finish`: v = dx / h ;  x += dx, with no normal velocity relative to a collider that held
      the particle.

    The iterations' kernels read and write :attr:`state`; between the phases a scheme reads
    :attr:`colliders` (None without) for its own contact kernels. Nothing is allocated after binding.
    """

    def __init__(self, model):
        self.model = model
        # per particle, from the last contact pass: the contact's normal (0: none), collider velocity
        # and force, state (0 free, 1 slide, 2 stick)
        self.normal, self.velocity, self.force = scratch_like(model, 3)
        self.mode = wp.zeros(model.particle_count, dtype=int)
        # and mu of a sliding contact (0: none, or sticking; vbd's rigid translation takes its friction)
        self.friction = wp.zeros(model.particle_count, dtype=float)
        # and 1 where the last step ended with the particle on a collider
        self.resting = wp.zeros(model.particle_count, dtype=int)
        #: Those seven arrays as one kernel argument (:class:`~warpcloth.kernels.increment.ContactState`).
        self.state = nk.ContactState()
        self.state.normal, self.state.velocity = self.normal, self.velocity
        self.state.force, self.state.state, self.state.friction = self.force, self.mode, self.friction
        # and how many contacts with friction the last sweep held (vbd's rigid translation)
        self.held = wp.zeros(1, dtype=int)
        self.state.resting, self.state.held = self.resting, self.held
        # the colliders as one kernel argument: none (empty records), and the control's (filled when it changes)
        self.none = ck.Colliders()
        self.none.records, self.none.box = wp.zeros(0, dtype=ck.Collider), wp.zeros(2, dtype=wp.vec3)
        self._colliders = ck.Colliders()
        #: This step's colliders as one kernel argument (:class:`~warpcloth.kernels.collide.Colliders`), or None.
        self.colliders = None
        #: This step's box and mesh edges (:class:`~warpcloth.sim.contacts.ColliderEdges`), or None.
        self.edges = None

    def begin_step(self, control, h: float, clear: bool = True):
        """The control's colliders as one kernel argument (records, broad-phase box, plane count), moving
        ones posed at the step's end t + h (device launches only), and their edges; or None without
        colliders (then the contact states are zeroed where ``clear``: none is held, and colliders may
        have been removed). The struct is refilled only when the control's collider arrays change (no
        device memory either way)."""
        contacts = control.collision
        if contacts is None or len(contacts.colliders) == 0:
            self.colliders = self.edges = None
            if clear:
                self.mode.zero_()
            return None
        if contacts.moving:
            contacts.pose(h)  # positions relative to the pose at t + h, friction relative to v_c there
        c = self._colliders
        if c.records is not contacts.params or c.box is not contacts.box or c.plane_count != contacts.plane_count:
            c.records, c.box, c.plane_count = contacts.params, contacts.box, contacts.plane_count
        self.colliders, self.edges = c, contacts.edges(self.model)
        return c

    def after_iteration(self, x, dx) -> None:
        """Box and mesh edges against the cloth's edges and triangles, on dx (nothing without)."""
        if self.edges is not None:
            self.edges.project_increment(x, dx)

    def project(self, x, dx, h: float) -> None:
        """Every particle's dx out of the colliders, the contact states refilled (nothing without
        colliders; :func:`~warpcloth.kernels.increment.project_increments`)."""
        if self.colliders is None:
            return
        m = self.model
        wp.launch(
            nk.project_increments,
            dim=m.particle_count,
            inputs=[x, m.particle_inv_mass, self.colliders, h],
            outputs=[dx, self.state],
            device=m.device,
        )

    def finish(self, x, v, dx, h: float) -> None:
        """v = dx / h ;  x += dx (with colliders: no normal velocity relative to a collider that held the
        particle, :func:`~warpcloth.kernels.increment.update_from_increment_contact`)."""
        m = self.model
        if self.colliders is not None:
            wp.launch(
                nk.update_from_increment_contact,
                dim=m.particle_count,
                inputs=[x, v, dx, m.particle_inv_mass, h, self.state],
                device=m.device,
            )
        else:
            wp.launch(
                nk.update_from_increment,
                dim=m.particle_count,
                inputs=[x, v, dx, m.particle_inv_mass, h],
                device=m.device,
            )


__all__ = ["IncrementContacts", "IncrementSolver", "at_least_one"]
