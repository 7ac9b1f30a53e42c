"""The interface every integrator shares.

An integrator is made with its options, bound to a model once (:meth:`Integrator.bind`
allocates every scratch array), then advances a :class:`~warpcloth.sim.state.State` in place:
``step(state, control, dt)``. A step launches kernels only: it allocates nothing and never
reads back to the host, so a frame of steps can be captured and replayed.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from fractions import Fraction
from typing import ClassVar

import numpy as np
import warp as wp

from warpcloth.errors import WarpclothError
from warpcloth.kernels.bending import HingeAdjacency
from warpcloth.kernels.springs import SpringAdjacency
from warpcloth.sim.coloring import particle_adjacency
from warpcloth.sim.hinges import hinge_adjacency


@dataclass(frozen=True)
class Option:
    """A user-settable integrator option (constructor keyword, CLI flag ``--name-with-dashes``,
    XML attribute ``name``).

    Attributes:
        name: keyword name, e.g. ``"cg_tol"``.
        type: ``float``, ``int`` or ``str``.
        default: value when not given.
        help: one line, with units.
        check: function(value) -> error message or None.
        choices: allowed values for ``str`` options.
    """

    name: str
    type: type
    default: object
    help: str
    check: Callable | None = None
    choices: tuple = ()

    @property
    def flag(self) -> str:
        return "--" + self.name.replace("_", "-")

    def parse(self, value):
        """``value`` converted and checked; raises :class:`WarpclothError` naming it."""
        if self.type is int and (isinstance(value, bool) or (isinstance(value, float) and not value.is_integer())):
            raise WarpclothError(f"{self.name} must be an integer, got {value!r}")
        if self.type is float and isinstance(value, bool):
            raise WarpclothError(f"{self.name} must be a number, got {value!r}")
        try:
            v = self.type(value)
        except (TypeError, ValueError, OverflowError):
            raise WarpclothError(f"{self.name} must be {self.type.__name__}, got {value!r}") from None
        if self.choices and v not in self.choices:
            raise WarpclothError(f"{self.name} must be one of {', '.join(map(str, self.choices))}, got {value!r}")
        if self.check is not None:
            msg = self.check(v)
            if msg:
                raise WarpclothError(f"{self.name} {msg}, got {value!r}")
        return v


class Integrator:
    """Base class of all integrators.

    Subclasses set :attr:`name`, :attr:`force_evals_per_step` and implement :meth:`_allocate`
    and :meth:`step`; they may override :meth:`begin` (called before the first step after a
    bind, a switch, a change of dt or an outside change of the state).
    """

    name: ClassVar[str] = ""
    force_evals_per_step: ClassVar[int] = 1
    #: True for integrators that evaluate spring forces (Provot deformation constraints apply).
    force_based: ClassVar[bool] = True
    #: True when the integrator projects collision constraints inside its own solver loop; else
    #: the Simulator projects contacts after each step (:mod:`warpcloth.sim.colliders`).
    collides_in_solver: ClassVar[bool] = False
    #: What the Simulator's velocity filter after a step does with self-contacts
    #: (:meth:`SelfCollision.filter_velocities <warpcloth.sim.self_collision.SelfCollision.filter_velocities>`):
    #: ``"full"``: the repulsion, inelastic impulses and the min-gap pass (a scheme that does nothing
    #: with them itself); ``"inelastic"``: no repulsion (the scheme has it in its solve: implicit_euler);
    #: ``"gap"``: the min-gap pass only (the scheme holds them as constraints: pbd, xpbd, projective, vbd).
    self_contact_filter: ClassVar[str] = "full"
    #: How a velocity change during a step moves x by the step's end, per unit dt (1 where
    #: x += dt v_new; 1/2 for Runge-Kutta schemes): friction corrects x with it.
    velocity_position_weight: ClassVar[float] = 1.0
    #: Fraction of :func:`stable_dt_estimate` used by :meth:`default_dt`.
    default_dt_factor: ClassVar[float] = 0.8
    #: Largest default dt [s] (one 60 Hz frame unless an integrator says otherwise).
    default_dt_cap: ClassVar[float] = 1.0 / 60.0

    #: User-settable options; each becomes an attribute of the instance.
    options: ClassVar[tuple[Option, ...]] = ()

    # -- what the study and the contract read: a scheme that declares nothing gets these ----------
    #: True for a conditionally stable scheme without a solve (explicit_euler, midpoint, rk4, verlet):
    #: the study steps it at fractions of its measured max stable dt and runs it to rest at that dt
    #: (:mod:`warpcloth.lab.configs`), and its max-dt search costs more trials
    #: (:mod:`warpcloth.lab.estimate`). False: the study's steps are taken as they are (a step above
    #: the max stable dt runs, and is recorded unstable).
    explicit: ClassVar[bool] = False
    #: The study's configurations per level, ``{"full" | "quick": ({option: values}, steps)}``: every
    #: combination of option values x steps is one (:func:`warpcloth.lab.configs.configurations`).
    #: ``steps`` are k per 1/60 s frame, dt = (1/60 s) / k (``Fraction(1, 2)``: 1/30 s), or for an
    #: :attr:`explicit` scheme the f of dt = max stable dt / f. Default: the default options at dt
    #: 1/30 s to 1/480 s.
    study_grid: ClassVar[dict] = {
        "full": ({}, (Fraction(1, 2), 1, 2, 4, 8)),
        "quick": ({}, (Fraction(1, 2), 1, 4)),
    }
    #: Options every study run of the scheme takes, outside its grid (a configuration's key does not
    #: name them): implicit_euler's ``strain_cap`` 0 (:func:`warpcloth.lab.configs.study_options`).
    study_fixed_options: ClassVar[dict] = {}
    #: The scheme's own discrete free fall from rest per unit acceleration, which the contract
    #: (tests/test_contract.py) holds a free cloth's centroid to: ``"euler"``: h^2 n (n + 1) / 2 after
    #: n steps of h (symplectic and backward Euler; per substep where the scheme has ``substeps``);
    #: ``"exact"``: (n h)^2 / 2 (midpoint, rk4, verlet).
    free_fall: ClassVar[str] = "euler"
    #: Relative tolerance of the contract on a free cloth's centroid motion (its free fall and its
    #: slide down a frictionless slope): 1e-3 where the internal forces cancel exactly in the centroid;
    #: 0.02 for a solver whose iterate leaves a residual in it (implicit_euler, vbd, projective).
    free_motion_rtol: ClassVar[float] = 1e-3

    @classmethod
    def option_defaults(cls) -> dict:
        """Every option's default, by name."""
        return {o.name: o.default for o in cls.options}

    @classmethod
    def relative_work(cls, options: dict) -> float:
        """Cost of one step with ``options`` (every option given) relative to one with the defaults:
        what the study prunes configurations by before it measures them
        (:func:`warpcloth.lab.configs.work`), not a measurement. 1.0: options do not change the cost."""
        return 1.0

    def rest_extension(self, mass: float, stiffness: float, gravity: float, dt: float) -> float:
        """The extension [m] at rest of one spring of ``stiffness`` [N/m] holding ``mass`` [kg] under
        ``gravity`` [m/s^2] at steps of ``dt`` [s]: m g / k for a scheme whose springs have a stiffness
        in N/m (the contract's hanging mass, tests/test_contract.py)."""
        return mass * gravity / stiffness

    def __init__(self, **options):
        known = {o.name: o for o in self.options}
        for key in options:
            if key not in known:
                allowed = ", ".join(known) or "none"
                raise WarpclothError(f"integrator {self.name!r} has no option {key!r} (its options: {allowed})")
        for name, opt in known.items():
            setattr(self, name, opt.parse(options[name]) if options.get(name) is not None else opt.default)
        self.model = None
        #: The :class:`~warpcloth.sim.self_collision.SelfCollision` of the model, or None (off): its
        #: contacts are detected by the Simulator before each step; :meth:`set_self_collision` sets it.
        self.self_collision = None

    def option_values(self) -> dict:
        """The value of every option of this integrator."""
        return {o.name: getattr(self, o.name) for o in self.options}

    # -- binding -----------------------------------------------------------------------
    def bind(self, model) -> Integrator:
        """Allocate scratch arrays for ``model``. Rebinding to another model reallocates."""
        if self.model is not model:
            self.model = model
            with wp.ScopedDevice(model.device):
                self._allocate(model)
        return self

    def set_self_collision(self, self_collision) -> None:
        """Use ``self_collision`` (bound to this integrator's model; None: off) from the next step."""
        self.self_collision = self_collision

    def default_strain_limit(self) -> float | None:
        """Provot's deformation constraint tau the :class:`~warpcloth.simulator.Simulator` applies
        after each step of this integrator where the user sets no ``strain_limit`` (None: none;
        implicit_euler's ``strain_cap`` option)."""
        return None

    def capturable_on(self, device) -> bool:
        """Whether a step on ``device`` can be captured with ``wp.ScopedCapture`` and replayed: True
        where a step is kernel launches only, with no host synchronisation (override where not)."""
        return True

    def _allocate(self, model) -> None:
        """Allocate scratch arrays (override)."""

    def position_history(self):
        """The array a step derives its next positions from besides x and v (Verlet's
        displacement d = x - x_prev), which a contact resets to v dt; None for most schemes."""
        return None

    def begin(self, state, control, dt: float) -> None:
        """Prepare to step ``state`` with ``dt`` (override where an integrator keeps history)."""

    def step(self, state, control, dt: float) -> None:  # pragma: no cover - interface
        """Advance ``state`` by ``dt`` in place."""
        raise NotImplementedError

    def stats(self) -> dict:
        """Per-run solver statistics (e.g. CG iterations); empty by default."""
        return {}

    def reset_stats(self) -> None:
        """Forget statistics gathered so far."""

    def convergence(self, stats: dict) -> tuple[bool | None, int, str | None]:
        """Whether the run whose :meth:`stats` are ``stats`` met the integrator's own solver
        tolerance: ``(solver_converged, solver_capped_steps, warning)``. ``solver_converged`` is
        None where not applicable (no iterative solver with a tolerance: the default);
        ``solver_capped_steps`` counts the steps whose solver stopped at its iteration cap above
        its tolerance; ``warning`` is one line for stderr when it did not converge, else None."""
        return None, 0, None

    def capped_steps(self, stats: dict) -> int:
        """The steps of the run whose :meth:`stats` are ``stats`` whose solve stopped at its iteration
        cap above its tolerance (0 by default: no solve with a tolerance and a cap)."""
        return 0

    def cap_advice(self) -> list:
        """The settings, besides a smaller dt, that let a solve stopped at its iteration cap converge
        (``--flag`` phrases for a run's :attr:`~warpcloth.run.harness.RunResult.capped_cause`)."""
        return []

    # -- time step -------------------------------------------------------------------------
    def default_dt(self, model, drag_rate: float = 0.0) -> float:
        """A time step [s] that is stable on ``model``: :attr:`default_dt_factor` times
        :func:`stable_dt_estimate`, capped at :attr:`default_dt_cap` (0.0: no dt is stable,
        see :meth:`no_stable_dt_reason`)."""
        return min(self.default_dt_cap, self.default_dt_factor * stable_dt_estimate(model, drag_rate))

    def no_stable_dt_reason(self, model, drag_rate: float = 0.0) -> str | None:
        """Why no time step is stable for this scheme on ``model``, or None when some is."""
        return None


def explicit_euler_dt_bound(model) -> float:
    """The seed's explicit-Euler stability estimate 0.4 pi sqrt(m/K) [s] (Vassilev et al. 2001),
    m the particle mass and K the largest spring stiffness."""
    k = model.max_stiffness()
    if k <= 0.0:
        return math.inf
    return 0.4 * math.pi * math.sqrt(model.particle_mass_value / k)


def stable_dt_estimate(model, drag_rate: float = 0.0) -> float:
    """A guaranteed-stable dt [s] for symplectic (explicit) Euler on ``model``.

    By Gershgorin, the stiffness matrix's eigenvalues are below 2 sum_j ks_ij at each particle,
    so omega^2 <= max_i 2 sum_j ks_ij / m_i; likewise the damping rate c <= max_i 2 sum_j kd_ij /
    m_i + drag. Symplectic Euler on x'' = -omega^2 x - c x' is stable while
    h^2 omega^2 + 2 h c < 4, i.e. h < (sqrt(c^2 + 4 omega^2) - c) / omega^2. Unlike the seed's
    single-spring estimate 0.4 pi sqrt(m/K), this accounts for every spring at a particle.
    Dihedral hinges add their block-Gershgorin row sums (:meth:`ClothModel.particle_hinge_sums`,
    sum_e k_e |g_i| sum_b |g_b|), which grow as 1/h^2 (bending limits dt as h^2).
    """
    ks_sum, kd_sum = _stiffness_rows(model)
    mass = model.host.mass.astype(np.float64)
    omega2 = float(np.max(ks_sum / mass))
    c = float(np.max(kd_sum / mass)) + float(drag_rate)
    if omega2 <= 0.0:
        return math.inf if c <= 0.0 else 2.0 / c
    return (math.sqrt(c * c + 4.0 * omega2) - c) / omega2


def model_spectrum(model, drag_rate: float = 0.0) -> tuple[float, float, float]:
    """(omega_max [rad/s], alpha [1/s], beta [s]) of the linearised model: omega_max^2 bounds
    the stiffness eigenvalues by Gershgorin (max_i 2 sum_j ks_ij / m_i), and a mode of angular
    frequency omega is damped at the rate at least c(omega) = alpha + beta omega^2, alpha the air
    drag and beta the smallest kd / ks of the springs (damping proportional to stiffness, as the
    default kd = 2 zeta sqrt(ks m) gives per spring type). Dihedral hinges count in both: their
    Gershgorin rows in omega_max, their kd_e / k_e in beta."""
    ks_sum, _ = _stiffness_rows(model)
    mass = model.host.mass.astype(np.float64)
    omega_max = math.sqrt(float(np.max(ks_sum / mass))) if ks_sum.size else 0.0
    ks = model.spring_stiffness.numpy().astype(np.float64)
    kd = model.spring_damping.numpy().astype(np.float64)
    if model.hinge_count:
        ks = np.concatenate([ks, model.host.hinges.stiffness])
        kd = np.concatenate([kd, model.host.hinges.damping])
    stiff = ks > 0
    beta = float(np.min(kd[stiff] / ks[stiff])) if np.any(stiff) else 0.0
    return omega_max, float(drag_rate), beta


def _stiffness_rows(model) -> tuple[np.ndarray, np.ndarray]:
    """Per particle, Gershgorin row sums of the stiffness and damping matrices [N/m], [N s/m]:
    2 sum_j ks_ij (2 sum_j kd_ij) plus the hinges' rows."""
    ks_sum, kd_sum = model.particle_spring_sums()
    ks_rows, kd_rows = 2.0 * ks_sum, 2.0 * kd_sum
    if model.hinge_count:
        hs, hd = model.particle_hinge_sums()
        ks_rows, kd_rows = ks_rows + hs, kd_rows + hd
    return ks_rows, kd_rows


def runge_kutta_stable_dt(amplification: Callable, model, drag_rate: float = 0.0) -> float:
    """The largest dt [s] for which an explicit Runge-Kutta scheme with stability function
    ``amplification(z)`` (e.g. 1 + z + z^2/2 for the midpoint rule) keeps every mode of the
    linearised model bounded, |R(h lambda)| <= 1, for the eigenvalues
    lambda = -c/2 +- sqrt(c^2/4 - omega^2) of the modes 0 < omega <= omega_max with damping
    c(omega) = alpha + beta omega^2 (:func:`model_spectrum`). 0.0 when no dt is stable: RK2
    without any damping amplifies every mode by sqrt(1 + (h omega)^4 / 4) per step.
    """
    omega_max, alpha, beta = model_spectrum(model, drag_rate)
    if omega_max <= 0.0:
        return math.inf
    omega = omega_max * np.logspace(-3.0, 0.0, 400)
    c = alpha + beta * omega * omega
    root = np.sqrt((0.25 * c * c - omega * omega).astype(complex))
    lambdas = np.concatenate([-0.5 * c + root, -0.5 * c - root])

    def stable(h: float) -> bool:
        return bool(np.all(np.abs(amplification(h * lambdas)) <= 1.0 + 1e-12))

    if alpha == 0.0 and beta == 0.0 and abs(amplification(0.1j)) > 1.0:
        return 0.0  # undamped modes grow at every dt (float64 cannot see |R| - 1 ~ (h omega)^4 below 1e-4)
    lo, hi = 1e-6 / omega_max, 4.0 / omega_max
    if not stable(lo):
        return 0.0
    if stable(hi):
        return hi
    for _ in range(60):  # bisection to ~1e-15 relative
        mid = math.sqrt(lo * hi)
        if stable(mid):
            lo = mid
        else:
            hi = mid
    return lo


def scratch_like(model, count: int = 1):
    """``count`` zeroed vec3 arrays of the model's particle count on its device."""
    arrays = [wp.zeros(model.particle_count, dtype=wp.vec3, device=model.device) for _ in range(count)]
    return arrays if count > 1 else arrays[0]


def spring_adjacency(model) -> SpringAdjacency:
    """Each particle's springs (:func:`warpcloth.sim.coloring.particle_adjacency`) with the model's
    spring parameters, as one kernel argument (:class:`~warpcloth.kernels.springs.SpringAdjacency`);
    made once at bind."""
    offsets, spring, other = particle_adjacency(model.host.pairs, model.particle_count)
    springs = SpringAdjacency()
    springs.offsets = wp.array(offsets, dtype=int, device=model.device)
    springs.spring = wp.array(spring, dtype=int, device=model.device)
    springs.other = wp.array(other, dtype=int, device=model.device)
    springs.rest_length = model.spring_rest_length
    springs.stiffness = model.spring_stiffness
    springs.damping = model.spring_damping
    springs.compression = model.spring_compression
    return springs


def hinge_adjacency_of(model) -> HingeAdjacency:
    """Each particle's dihedral hinges (:func:`warpcloth.sim.hinges.hinge_adjacency`) with the model's
    hinge arrays, as one kernel argument (:class:`~warpcloth.kernels.bending.HingeAdjacency`; empty
    arrays, zero offsets, without hinges); made once at bind."""
    n, device = model.particle_count, model.device
    adj = HingeAdjacency()
    if model.hinge_count:
        offsets, hinge, slot = hinge_adjacency(model.host.hinges.indices, n)
        adj.offsets = wp.array(offsets, dtype=int, device=device)
        adj.hinge = wp.array(hinge, dtype=int, device=device)
        adj.slot = wp.array(slot, dtype=int, device=device)
        adj.indices, adj.rest_angle, adj.stiffness, adj.damping = model.hinge_arrays()
    else:
        adj.offsets = wp.zeros(n + 1, dtype=int, device=device)
        adj.hinge, adj.slot = wp.zeros(0, dtype=int, device=device), wp.zeros(0, dtype=int, device=device)
        adj.indices = wp.zeros(0, dtype=wp.vec4i, device=device)
        adj.rest_angle, adj.stiffness, adj.damping = (wp.zeros(0, dtype=float, device=device) for _ in range(3))
    return adj


#: The study's grid of an :attr:`Integrator.explicit` scheme: no knobs but dt, at fractions 1, 1/2,
#: 1/4, 1/8 of its max stable dt (``quick``: 1, 1/2, 1/4).
EXPLICIT_STUDY_GRID = {"full": ({}, (1, 2, 4, 8)), "quick": ({}, (1, 2, 4))}


__all__ = [
    "EXPLICIT_STUDY_GRID",
    "Integrator",
    "Option",
    "explicit_euler_dt_bound",
    "hinge_adjacency_of",
    "model_spectrum",
    "runge_kutta_stable_dt",
    "scratch_like",
    "spring_adjacency",
    "stable_dt_estimate",
]
