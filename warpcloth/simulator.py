"""The stepping core: a cloth, its state, an integrator, the external forces and a time step.

:class:`Simulator` advances the state (``step``, ``simulate``; ``step_states`` reads one state and
writes another), switches integrators and time steps between steps, and captures a frame's steps
as graphs (``wp.ScopedCapture``: on CUDA at most :data:`GRAPH_CHUNK` steps each, on the CPU at
most :data:`CPU_GRAPH_STEPS`) to replay them. A
:class:`Snapshot` holds everything a run carries between steps (``snapshot``, ``restore``: the
checkpoints of :mod:`warpcloth.io.checkpoint`). Running for a duration with frames, metrics,
verdicts, timing and outputs is the run harness's job, a layer above
(:class:`warpcloth.run.harness.RunHarness`): this module knows nothing of it.
"""

from __future__ import annotations

import functools
import time
from dataclasses import dataclass, field

import numpy as np
import warp as wp

from warpcloth.errors import WarpclothError, require, require_count, require_positive, warn
from warpcloth.integrators import Integrator, make_integrator
from warpcloth.integrators.strain_limit import StrainLimiter
from warpcloth.sim.control import Control
from warpcloth.sim.device import set_deterministic
from warpcloth.sim.model import ClothModel
from warpcloth.sim.pins import apply_pins
from warpcloth.sim.self_collision import SelfCollision
from warpcloth.sim.state import State
from warpcloth.sim.tracks import check_target

#: Most steps in one chunk: :meth:`Simulator.simulate` calls of more steps run as chunks of this
#: many and the rest (capturing a long call whole, 800 steps of projective's ~700 launches each,
#: took 57 s on the CPU, 1.2 s in chunks). On CUDA a chunk is one captured graph. Either way the
#: replays are the same launches in the same order, so results stay bit-identical.
GRAPH_CHUNK = 16

#: Most steps in one captured graph on the CPU (:meth:`Simulator._pieces`): there Warp records a
#: launch into a graph in about 1 ms of Python, twenty times a plain launch, so a chunk is cut into
#: graphs of this many steps, most of them alike, and a run captures each distinct one once. A replay
#: costs about 1.5 us a graph more than its launches (0.65 us each): explicit Euler's 16 x 16 frame
#: (45 steps) 2.16 ms in graphs of one step, 2.10 in graphs of four (its first frame 0.006 s
#: against 0.012), rk4's 7.58 and 7.55; two test files of small cloths 38 s of CPU against 48 s
#: (docs/architecture.md).
CPU_GRAPH_STEPS = 1

#: Most graphs a simulator keeps (a run alternates between two step counts, a chunk and a rest,
#: each of a few pieces).
MAX_GRAPHS = 16


@functools.lru_cache(maxsize=256)
def interval_schedule(steps: int, interval: int) -> tuple[tuple[int, int], ...]:
    """Per step of a chunk of ``steps`` steps, its self-collision work ``(detect, filter)``: the
    steps of the collision interval it starts (contacts found for them) and of the one it ends
    (the velocity filter over them), else 0; the chunk's intervals are as even as whole steps
    allow, none longer than ``interval`` steps (every step (1, 1) where that is 1). Cached: a run
    asks for the same one or two chunks every frame."""
    count = -(-steps // interval)
    plan = []
    for i in range(count):
        m = (i + 1) * steps // count - i * steps // count
        plan += [(m if j == 0 else 0, m if j == m - 1 else 0) for j in range(m)]
    return tuple(plan)


@functools.lru_cache(maxsize=256)
def graph_pieces(chunk: int, interval: int, per_graph: int) -> tuple[tuple[tuple[int, int], ...], ...]:
    """The schedules of the graphs that replay a chunk (:meth:`Simulator._pieces`): its
    :func:`interval_schedule` in runs of ``per_graph`` steps. Cached, as :func:`interval_schedule`."""
    schedule = interval_schedule(chunk, interval)
    return tuple(schedule[i : i + per_graph] for i in range(0, len(schedule), per_graph))


@dataclass
class Snapshot:
    """Everything a :class:`Simulator` carries from one step to the next, on the host
    (:meth:`Simulator.snapshot`, :meth:`Simulator.restore`; a checkpoint file holds one).

    Attributes:
        arrays: every device array the run owns besides the model's, by where it lives
            (``state.particle_q``, ``integrator.displacement``, ``self_collision.cand_vt``,
            ``control.time``, ...), each as its raw bytes (uint8): positions, velocities, the
            integrator's history and scratch, the self-contact lists, the device clock and the
            colliders' and pins' track state. A step reads only these and the model, so restoring
            them all makes the next step the uninterrupted one's, bit for bit.
        layout: per array, its Warp dtype's name and shape (checked where it is restored).
        clock: the host clock: ``sim_time`` [s], ``steps``, and the step count and time
            [s] it counts from since the last change of dt (``time_base``, ``base_steps``).
        setup: what must be the same where it is restored: the integrator's name and options,
            dt [s], the self-collision settings and the strain limit.
        run: what the layer above records with it (the run harness's frame and step counts).
    """

    arrays: dict[str, np.ndarray]
    layout: dict[str, tuple[str, tuple[int, ...]]]
    clock: dict
    setup: dict
    run: dict = field(default_factory=dict)


def graph_capture_supported(device) -> bool:
    """CUDA graphs on a GPU (with mempool); API capture on the CPU from Warp 1.19."""
    d = wp.get_device(device)
    if d.is_cuda:
        return bool(wp.is_mempool_enabled(d))
    major, minor = (int(p) for p in wp.config.version.split(".")[:2])
    return (major, minor) >= (1, 19)


class Simulator:
    """Advances one cloth with a chosen integrator at a fixed time step.

    Args:
        model: the :class:`~warpcloth.sim.model.ClothModel`.
        integrator: an :class:`~warpcloth.integrators.Integrator` or its name.
        control: external forces (:class:`~warpcloth.sim.control.Control`); default gravity only.
        dt: time step [s]; default the integrator's :meth:`~Integrator.default_dt`.
        use_graph: capture a frame's steps once with ``wp.ScopedCapture`` and replay it (CUDA
            graphs; Warp's API capture on the CPU). None: wherever the device and the
            integrator support it (not on the CPU with a deforming mesh collider, whose refit
            is a host call the capture does not record). Results are bit-identical either way on
            the CPU; on CUDA with ``deterministic`` (otherwise the order of the GPU's atomic sums
            differs from launch to launch, and so do the last bits).
        strain_limit: Provot's deformation constraint tau (> 0, e.g. 0.1 for 10 %) applied after
            every step of a force-based integrator (:mod:`warpcloth.integrators.strain_limit`); None: the
            integrator's own, if it has one (implicit_euler's ``strain_cap`` option, 0.1 by default;
            :attr:`integrator_limiter`), else off.
        self_collision: the cloth against itself (:class:`~warpcloth.sim.self_collision.SelfCollision`
            bound to ``model``, or a dict of its keyword arguments, e.g. ``{"thickness": 0.005,
            "friction": 0.3}``); None: off (:meth:`set_self_collision`; docs/self-collision.md).
        deterministic: on a CUDA model, True makes every kernel's atomic sums run in a fixed order
            so that runs are bit-reproducible, False restores Warp's default; process-wide
            (:func:`~warpcloth.sim.device.set_deterministic`). None leaves it as it is; ignored on
            the CPU, which is bit-reproducible anyway.
    """

    def __init__(
        self,
        model,
        integrator: Integrator | str = "explicit_euler",
        control: Control | None = None,
        dt: float | None = None,
        use_graph: bool | None = None,
        strain_limit: float | None = None,
        self_collision: SelfCollision | dict | None = None,
        deterministic: bool | None = None,
    ):
        if not isinstance(model, ClothModel):
            raise WarpclothError(
                f"model must be a ClothModel (from build_grid_cloth or build_model), got {model!r:.80}"
            )
        if control is not None and not isinstance(control, Control):
            raise WarpclothError(f"control must be a warpcloth.Control or None, got {control!r:.80}")
        if deterministic is not None:
            require(
                isinstance(deterministic, bool), f"deterministic must be True, False or None, got {deterministic!r:.80}"
            )
            if wp.get_device(model.device).is_cuda:
                set_deterministic(deterministic)
                if deterministic and self_collision is not None:
                    warn(
                        "deterministic: self-collision's kernels are not covered "
                        "(its lists are built in the GPU's thread order): this run is reproducible to rounding only"
                    )
        self.model = model
        self.control = control if control is not None else Control(device=model.device)
        require(
            str(self.control.device) == str(model.device),
            f"control is on device '{self.control.device}' but the model is on '{model.device}'",
        )
        self.state = model.state()
        self._pins_version = 0
        self._bind_pin_tracks(self.control.pin_tracks)
        self.strain_limiter = StrainLimiter(model, strain_limit) if strain_limit is not None else None
        #: The integrator's own strain limit where the user gives none (implicit_euler's ``strain_cap``;
        #: :meth:`~warpcloth.integrators.base.Integrator.default_strain_limit`), else None.
        self.integrator_limiter: StrainLimiter | None = None
        self.self_collision: SelfCollision | None = self._bind_self_collision(self_collision)
        self.integrator: Integrator | None = None
        self._dt: float | None = None
        self._use_graph = use_graph
        self._graphs: dict[tuple, object] = {}
        self._warmed = False
        self._last_out: State | None = None  # step_states' last output: a state_in that continues the history
        #: Counts changes to what a step does (integrator, dt, graph mode, model, pins): timings
        #: of one step are valid for one version.
        self.step_version = 0
        #: Counts :meth:`set_model` calls: whatever holds arrays of the model rebinds when it changes.
        self.model_version = 0
        #: Wall seconds spent capturing frame graphs (excluded from step timings).
        self.capture_time = 0.0
        #: Simulated time [s]: t_base + n dt after n steps of the current dt (as Control.time).
        self.sim_time = 0.0
        self.steps = 0
        self._time_base, self._base_steps = 0.0, 0
        self.set_integrator(integrator, dt)

    # -- configuration -------------------------------------------------------------------
    @property
    def dt(self) -> float:
        return self._dt

    @property
    def warmed(self) -> bool:
        """Whether every kernel of the current step is compiled and loaded (:meth:`warm_up`)."""
        return self._warmed

    def set_integrator(self, integrator: Integrator | str, dt: float | None = None) -> None:
        """Switch integrators between steps (the model is not rebuilt); ``dt`` None keeps the
        current step when one is set, else takes the integrator's default."""
        if isinstance(integrator, str):
            integrator = make_integrator(integrator)
        if not isinstance(integrator, Integrator):
            raise WarpclothError(f"integrator must be an Integrator or a name, got {integrator!r}")
        if self.strain_limiter is not None and not integrator.force_based:
            raise WarpclothError(f"strain limit applies to force-based integrators only, not {integrator.name!r}")
        integrator.bind(self.model)
        if dt is None and self._dt is None:
            reason = integrator.no_stable_dt_reason(self.model, self.control.drag_rate)
            if reason:
                raise WarpclothError(reason + "; or give dt yourself")
            dt = integrator.default_dt(self.model, self.control.drag_rate)
            if not dt > 0.0:
                raise WarpclothError(
                    f"dt must be > 0 s, got {dt!r} (the default dt of {integrator.name!r} on this model underflowed: "
                    f"check the mass, stiffness, damping and drag)"
                )
        elif dt is None:
            dt = self._dt
        self._rebase_clock()
        self._dt = require_positive("dt", dt, "s")
        integrator.set_self_collision(self.self_collision)
        self.integrator = integrator
        self._bind_integrator_limiter()
        self._needs_begin = True
        self._graphs.clear()
        self._warmed = False
        self.step_version += 1

    def set_model(self, model) -> None:
        """Continue the current state on ``model`` (the same particles, e.g. from
        :meth:`~warpcloth.sim.model.ClothModel.with_spring_params`): the integrator, metrics and
        strain limiter rebind to it (scratch is reallocated; this is not a step)."""
        if not isinstance(model, ClothModel):
            raise WarpclothError(f"model must be a ClothModel, got {model!r:.80}")
        if model.particle_count != self.model.particle_count or str(model.device) != str(self.model.device):
            raise WarpclothError(
                f"set_model needs the same particles on the same device ({self.model.particle_count} on "
                f"{self.model.device}), got {model.particle_count} on {model.device}"
            )
        self.model = model
        self._bind_pin_tracks(self.control.pin_tracks)  # kinematic pins: checked and bound to the new model
        self.model_version += 1  # what measures the old model (a run harness's probe) rebinds
        if self.strain_limiter is not None:
            self.strain_limiter = StrainLimiter(model, self.strain_limiter.tau)
        self._bind_integrator_limiter()
        if self.self_collision is not None:
            self.self_collision = self.self_collision.rebind(model)
        self.integrator.bind(model)
        self.integrator.set_self_collision(self.self_collision)
        self._needs_begin = True
        self._graphs.clear()
        self._warmed = False

    def _bind_integrator_limiter(self) -> None:
        """The integrator's own strain limit on the current model, where the user gave none (kept
        where its tau and model are unchanged)."""
        tau = self.integrator.default_strain_limit() if self.strain_limiter is None else None
        limiter = self.integrator_limiter
        if tau is None:
            self.integrator_limiter = None
        elif limiter is None or limiter.tau != tau or limiter.model is not self.model:
            self.integrator_limiter = StrainLimiter(self.model, tau)
        if self.integrator_limiter is not limiter:  # a captured frame holds the old one's arrays
            self._graphs.clear()
            self.step_version += 1

    @property
    def active_limiter(self) -> StrainLimiter | None:
        """The strain limit applied after each step: the user's, else the integrator's, else None."""
        return self.strain_limiter if self.strain_limiter is not None else self.integrator_limiter

    def set_self_collision(self, self_collision: SelfCollision | dict | None) -> None:
        """Self-collision from the next step: a :class:`~warpcloth.sim.self_collision.SelfCollision`
        bound to the model, a dict of its keyword arguments, or None (off)."""
        self.self_collision = self._bind_self_collision(self_collision)
        self.integrator.set_self_collision(self.self_collision)
        self._needs_begin = True
        self._graphs.clear()
        self._warmed = False
        self.step_version += 1

    def _bind_self_collision(self, value) -> SelfCollision | None:
        if value is None or value is False:
            return None
        if isinstance(value, dict):
            return SelfCollision(self.model, **value)
        if not isinstance(value, SelfCollision):
            raise WarpclothError(
                f"self_collision must be a SelfCollision, a dict of its settings or None, got {value!r:.80}"
            )
        if value.model is not self.model:
            raise WarpclothError("self_collision is bound to another model: make it with this simulator's model")
        return value

    def set_pin_track(self, *tracks) -> None:
        """Move pinned particles along :class:`~warpcloth.sim.pins.PinTrack` s from the next step
        (replacing the tracks set before; no argument: every pin stays where it is)."""
        self._bind_pin_tracks(tracks)
        self._needs_begin = True
        self._graphs.clear()
        self.step_version += 1

    def _bind_pin_tracks(self, tracks) -> None:
        self.control.bind_pin_tracks(self.model, tracks)
        self._pins_version += 1

    def pins_moving_until(self) -> float:
        """Simulated time [s] after which no kinematic pin and no collider on a pose track moves
        (0 without tracks; inf for a rigid motion that never stops): the latest
        :meth:`~warpcloth.sim.tracks.Track.moving_until` of the tracks."""
        tracks = list(self.control.pin_tracks)
        tracks += [c.track for c in self.control.colliders or () if getattr(c, "track", None) is not None]
        return max([0.0, *(float(track.moving_until()) for track in tracks)])

    def set_pin_targets(self, positions, velocities=None, track: str | None = None) -> None:
        """Where the pins of a driven track (:meth:`PinTrack.driven
        <warpcloth.sim.pins.PinTrack.driven>`) are at the end of the next :meth:`simulate` call:
        ``positions`` (P, 3) [m], and for a ``"hermite"`` track ``velocities`` (P, 3) [m/s].
        ``track``: its name (None: the only driven track). Costs a copy into the arrays the
        captured frame reads, never a capture (see docs/driving.md)."""
        driven = [t for t in self.control.pin_tracks if t.kind == "driven" and (track is None or t.name == track)]
        if len(driven) != 1:
            names = [t.name for t in self.control.pin_tracks if t.kind == "driven"]
            raise WarpclothError(
                f"no driven pin track {track!r}; driven tracks: {', '.join(map(repr, names)) or 'none'} "
                "(add PinTrack.driven(particles) to the control's pin tracks)"
                if track is not None or not names
                else f"{len(names)} driven pin tracks ({', '.join(map(repr, names))}): name one with track="
            )
        driven[0].set(positions, velocities)

    def set_collider_pose(self, index: int, offset=(0.0, 0.0, 0.0), rotation=None, velocity=None) -> None:
        """Where collider ``index`` (of ``control.colliders``, on a :meth:`ColliderTrack.driven
        <warpcloth.sim.colliders.ColliderTrack.driven>`) is at the end of the next
        :meth:`simulate` call: the collider as given, turned by the quaternion ``rotation``
        (x, y, z, w) about its centre and moved by ``offset`` [m] (see
        :meth:`ColliderTrack.set <warpcloth.sim.colliders.ColliderTrack.set>`)."""
        colliders = self.control.colliders
        if not isinstance(index, int) or not 0 <= index < len(colliders):
            raise WarpclothError(f"collider index must be 0..{len(colliders) - 1}, got {index!r}")
        track = colliders[index].track
        if track is None or track.kind != "driven":
            raise WarpclothError(
                f"collider {index} ({colliders[index].kind}) is not driven: give it track=ColliderTrack.driven()"
            )
        what = f"collider {index}'s"
        offset = tuple(check_target(what, "offset", offset, "m").reshape(-1))
        if velocity is not None:
            velocity = tuple(check_target(what, "velocity", velocity, "m/s").reshape(-1))
        if isinstance(rotation, wp.array):  # as offset and velocity: a device array is read back
            rotation = tuple(rotation.numpy().reshape(-1).tolist())
        track.set(offset, rotation, velocity)

    def set_dt(self, dt: float) -> None:
        dt = require_positive("dt", dt, "s")
        self._rebase_clock()
        self._dt = dt
        self._needs_begin = True
        self._graphs.clear()
        self.step_version += 1

    @property
    def use_graph(self) -> bool | None:
        """Graph capture: True (always; an error where unsupported), False (plain launches) or
        None (wherever the device and the integrator support it). Results are bit-identical (on
        CUDA with ``deterministic``)."""
        return self._use_graph

    @use_graph.setter
    def use_graph(self, value: bool | None) -> None:
        if value not in (True, False, None):
            raise WarpclothError(f"use_graph must be True, False or None (auto), got {value!r}")
        self._use_graph = value
        self._graphs.clear()
        self.step_version += 1

    @property
    def graph_enabled(self) -> bool:
        """Whether frames are captured and replayed (see ``use_graph``)."""
        supported = graph_capture_supported(self.model.device) and self.integrator.capturable_on(self.model.device)
        if self.active_limiter is not None and wp.get_device(self.model.device).is_cuda:
            supported = supported and wp.is_conditional_graph_supported()  # its pass loop is capture_while
        collision = self.control.collision
        # a deforming mesh refits its wp.Mesh each pose: a host call on the CPU that Warp's API capture
        # does not record (Warp 1.19 records wp.Bvh.refit, not wp.Mesh.refit), so a replay would query
        # a BVH left at the captured pose and miss the surface under a particle
        refit_on_host = collision is not None and collision.deforming and wp.get_device(self.model.device).is_cpu
        if self._use_graph is None:
            return supported and not refit_on_host
        if self._use_graph and (not supported or refit_on_host):
            why = " (a deforming mesh collider's refit is a host call there)" if refit_on_host else ""
            raise WarpclothError(
                f"graph capture is not available for integrator {self.integrator.name!r} on {self.model.device} "
                f"with Warp {wp.config.version}{why}"
            )
        return bool(self._use_graph)

    def reset(self) -> None:
        """Back to the rest configuration at t = 0."""
        self.state.assign(self.model.state())
        self.control.set_time(0.0)
        self.sim_time, self.steps = 0.0, 0
        self._rebase_clock()
        self._needs_begin = True

    def _rebase_clock(self) -> None:
        """Count steps from now (before dt changes); the device clock follows in :meth:`_begin`."""
        self._time_base, self._base_steps = self.sim_time, self.steps

    def _count_steps(self, n: int) -> None:
        self.steps += n
        self.sim_time = self._time_base + (self.steps - self._base_steps) * self._dt

    # -- state in, state out; snapshots ------------------------------------------------------
    def step_states(self, state_in: State, state_out: State, control: Control | None = None, dt=None) -> None:
        """One step from ``state_in`` into ``state_out`` (the two may be the same object), as
        Newton's ``solver.step(state_in, state_out, control, contacts, dt)``: copies in, one
        :meth:`step`, copies out (launches only).

        Where ``state_in`` is the last ``state_out`` (or :attr:`state`), the step continues this
        simulator's history (Verlet's displacement, the self-contact lists, the clock) and equals
        the in-place :meth:`step` bit for bit; any other state starts the history anew from it, as
        after :meth:`reset` (to branch with the history, :meth:`restore` a :meth:`snapshot`).
        ``control``: None or this simulator's own :attr:`control` (tracks and colliders are bound
        to it); ``dt`` [s]: None keeps the current step, another value is :meth:`set_dt`.
        :attr:`state` holds the result too; a rigid-body solver that moves vertices between steps
        writes them into ``state_out`` before passing it back in."""
        if control is not None and control is not self.control:
            raise WarpclothError(
                "control must be None or this simulator's own control (sim.control): its tracks and colliders are "
                "bound to it; build a Simulator per Control"
            )
        for name, s in (("state_in", state_in), ("state_out", state_out)):
            if not isinstance(s, State):
                raise WarpclothError(f"{name} must be a warpcloth State (model.state()), got {s!r:.80}")
            if s.particle_count != self.model.particle_count or str(s.particle_q.device) != str(self.model.device):
                raise WarpclothError(
                    f"{name} has {s.particle_count} particles on {s.particle_q.device}; this simulator's model has "
                    f"{self.model.particle_count} on {self.model.device}"
                )
        if dt is not None and float(dt) != self._dt:
            self.set_dt(dt)
        if state_in is not self.state:
            if state_in is not self._last_out:
                self._needs_begin = True  # a state from elsewhere: the history starts from it
            self.state.assign(state_in)
        self.step()
        if state_out is not self.state:
            state_out.assign(self.state)
        self._last_out = state_out

    def _prepare_arrays(self) -> None:
        """Make what a step makes on first use (the strain limiter, the colliders' edge
        contacts), so that a snapshot and a restore see the same arrays."""
        self._bind_integrator_limiter()
        if self.control.collision is not None:
            self.control.collision.bind_model(self.model)
            self.control.collision.edges(self.model)

    def run_arrays(self) -> dict[str, wp.array]:
        """Every device array this simulator's run owns besides the model's, by path (the
        :attr:`Snapshot.arrays`): found by walking the state, the integrator, self-collision, the
        control (tracks, colliders) and the strain limiters, so a scheme's own scratch is
        included without a list kept by hand."""
        self._prepare_arrays()
        model_arrays = {id(a) for a in vars(self.model).values() if isinstance(a, wp.array)}
        found: dict[str, wp.array] = {}
        seen: set[int] = set()

        def walk(path: str, obj) -> None:
            if isinstance(obj, wp.array):
                # not: the model's (read-only), empty ones, records of structs (colliders: they hold device
                # addresses of meshes and BVHs, and are posed anew from the clock at every step) or uint64 (ids)
                plain = isinstance(obj.dtype, type) and obj.dtype is not wp.uint64
                if plain and id(obj) not in seen and id(obj) not in model_arrays and obj.size > 0:
                    found[path] = obj
                seen.add(id(obj))
                return
            if isinstance(obj, (list, tuple, dict)):
                if id(obj) in seen:
                    return
                seen.add(id(obj))
                items = sorted(obj.items(), key=lambda kv: str(kv[0])) if isinstance(obj, dict) else enumerate(obj)
                for key, value in items:
                    walk(f"{path}.{key}", value)
                return
            if isinstance(obj, ClothModel) or not type(obj).__module__.startswith("warpcloth."):
                return
            if id(obj) in seen or not hasattr(obj, "__dict__"):
                return
            seen.add(id(obj))
            attrs = sorted(vars(obj).items(), key=lambda kv: (not isinstance(kv[1], wp.array), kv[0]))
            for key, value in attrs:  # its own arrays first, then what it holds
                walk(f"{path}.{key}", value)

        for root, obj in (
            ("state", self.state),
            ("control", self.control),
            ("self_collision", self.self_collision),
            ("integrator", self.integrator),
            ("strain_limiter", self.strain_limiter),
            ("integrator_limiter", self.integrator_limiter),
        ):
            if obj is not None:
                walk(root, obj)
        return found

    def setup(self) -> dict:
        """What a :class:`Snapshot` must be restored into: the integrator, its options, dt, the
        self-collision settings and the strain limit (values as text, compared as such)."""
        sc = self.self_collision
        limiter = self.active_limiter
        return {
            "integrator": self.integrator.name,
            "options": ", ".join(f"{k}={v!r}" for k, v in sorted(self.integrator.option_values().items())),
            "dt": repr(float(self._dt)),
            "self_collision": "off"
            if sc is None
            else ", ".join(f"{k}={v!r}" for k, v in sorted(sc.settings().items())),
            "strain_limit": "off" if limiter is None else repr(float(limiter.tau)),
        }

    def snapshot(self, run: dict | None = None) -> Snapshot:
        """The run's state now, on the host (reads the device): restored with :meth:`restore`, the
        next step is this run's next step, bit for bit. ``run``: what the caller records with it."""
        if self._needs_begin:  # the history starts at the next step: start it now, so that it is saved
            self._begin()
        arrays, layout = {}, {}
        for path, a in self.run_arrays().items():
            host = np.ascontiguousarray(a.numpy())
            arrays[path] = host.view(np.uint8).reshape(-1).copy()
            layout[path] = (wp.types.type_repr(a.dtype), tuple(int(n) for n in a.shape))
        clock = {
            "sim_time": float(self.sim_time),
            "steps": int(self.steps),
            "time_base": float(self._time_base),
            "base_steps": int(self._base_steps),
        }
        return Snapshot(arrays, layout, clock, self.setup(), dict(run or {}))

    def restore(self, snapshot: Snapshot) -> None:
        """Continue from ``snapshot`` (of a simulator of the same model and :meth:`setup`): every
        run array and the clock as they were; compiles the step first where not done yet
        (:meth:`warm_up`), so no later warm-up or capture restarts the history. Raises a
        :class:`~warpcloth.errors.WarpclothError` naming the first thing that differs."""
        if not isinstance(snapshot, Snapshot):
            raise WarpclothError(f"restore needs a Snapshot (Simulator.snapshot), got {snapshot!r:.80}")
        mine = self.setup()
        for key, value in mine.items():
            if snapshot.setup.get(key) != value:
                raise WarpclothError(
                    f"the snapshot was taken with {key} {snapshot.setup.get(key)}; this run has {key} {value}"
                )
        if not self._warmed:
            self.warm_up()
        self._begin()
        arrays = self.run_arrays()
        if set(arrays) != set(snapshot.arrays):
            extra = sorted(set(snapshot.arrays) ^ set(arrays))
            raise WarpclothError(
                f"the snapshot's arrays do not match this run's ({len(extra)} differ, e.g. {extra[0]}): another setup"
            )
        for path, a in arrays.items():
            want = (wp.types.type_repr(a.dtype), tuple(int(n) for n in a.shape))
            got = (snapshot.layout[path][0], tuple(snapshot.layout[path][1]))
            if got != want:
                raise WarpclothError(
                    f"the snapshot's {path} is {got[0]} {got[1]}; this run's is {want[0]} {want[1]}: another setup"
                )
        for path, a in arrays.items():
            host = wp.empty(a.shape, dtype=a.dtype, device="cpu")
            view = host.numpy().view(np.uint8).reshape(-1)
            data = snapshot.arrays[path]
            if data.size != view.size:
                raise WarpclothError(f"the snapshot's {path} holds {data.size} bytes, not {view.size}: it is damaged")
            view[:] = data
            wp.copy(a, host)
        clock = snapshot.clock
        self.sim_time, self.steps = float(clock["sim_time"]), int(clock["steps"])
        self._time_base, self._base_steps = float(clock["time_base"]), int(clock["base_steps"])
        self._last_out = None
        self._needs_begin = False
        wp.synchronize_device(self.model.device)

    # -- stepping ------------------------------------------------------------------------
    def step(self) -> None:
        """Advance one time step: W(t) update, integrator step, strain limit, t += dt (launches only;
        a driven track's target set before it is reached at its end)."""
        self._drive(1)
        self._launch_step()
        self._count_steps(1)

    def _capture_key(self) -> tuple:
        """Every host value a captured frame bakes in besides dt and the integrator (those clear
        the cache): a change to any of them captures a new graph."""
        c = self.control
        edges = c.collision.edges(self.model) if c.collision is not None else None
        return (
            (edges.passes, edges.passes_after_limit) if edges is not None else None,
            tuple(c.gravity),
            c.drag_rate,
            c.wind_coefficient,
            c.wind_schedule,
            c.colliders,
            self._pins_version,
            tuple(sorted((k, repr(v)) for k, v in self.integrator.option_values().items())),
        )

    def _drive(self, steps: int) -> None:
        """Before a frame of ``steps`` steps: the integrator's start if due (:meth:`_begin`) and
        the driven tracks' keys for the frame (their targets set since the last frame)."""
        self._bind_integrator_limiter()  # its strain cap may have been set since (a new limiter only then)
        if self.control.collision is not None:  # the boxes' edge radius from this model (once per model)
            self.control.collision.bind_model(self.model)
        if self._needs_begin:
            self._begin(steps)
        elif self.control.upload_drives(self._dt, steps, self.sim_time):
            self.control.kinematic_pins.apply_driven(self.control, self.state.particle_q, self.state.particle_qd)

    def _begin(self, drive_steps: int | None = None) -> None:
        """Let the integrator start its history from the current state and wind W(t) (and with
        ``drive_steps``, the driven tracks' keys for a frame of that many steps first)."""
        self._rebase_clock()
        self.control.rebase(self._dt)
        self.control.update()
        if drive_steps is not None:
            self.control.upload_drives(self._dt, drive_steps, self.sim_time)
        apply_pins(self.control, self.state.particle_q, self.state.particle_qd)  # pins on their track at t
        if self.self_collision is not None:
            self.self_collision.invalidate()  # the state may have changed from outside: rebuild the candidates
        self.integrator.begin(self.state, self.control, self._dt)
        self._needs_begin = False

    def _interval_steps(self) -> int:
        """Steps per self-collision interval (1 without self-collision or for a scheme that holds the
        contacts in its solve; :meth:`SelfCollision.interval_steps
        <warpcloth.sim.self_collision.SelfCollision.interval_steps>`)."""
        sc = self.self_collision
        return 1 if sc is None else sc.interval_steps(self._dt, self.integrator.self_contact_filter)

    def chunk_steps(self) -> int:
        """Steps of one chunk (on CUDA one captured graph): :data:`GRAPH_CHUNK`, or a multiple of the self-collision
        interval where that is longer than a step. :meth:`simulate` calls of multiples of it give the
        same collision intervals however a run is split into calls (the run layer's chunks are)."""
        k = self._interval_steps()
        return GRAPH_CHUNK if k == 1 else k * max(1, GRAPH_CHUNK // k)

    def _chunks(self, steps: int) -> list[int]:
        """A call of ``steps`` steps as the step counts of its chunks: whole chunks of
        :meth:`chunk_steps` steps and the rest. Plain launches follow the same chunks, so both stay
        bit-identical."""
        chunk = min(steps, self.chunk_steps())
        full, rest = divmod(steps, chunk)
        return [chunk] * full + ([rest] if rest else [])

    def _schedule(self, steps: int) -> tuple[tuple[int, int], ...]:
        """Per step of a chunk of ``steps`` steps, its self-collision work (:func:`interval_schedule`
        with this simulator's :meth:`_interval_steps`)."""
        return interval_schedule(steps, self._interval_steps())

    def _launch_step(self, detect_steps: int = 1, filter_steps: int = 1) -> None:
        self.control.update()
        sc, integrator, state = self.self_collision, self.integrator, self.state
        if sc is not None and detect_steps:  # the self-contacts of the collision interval starting here
            sc.detect(state.particle_q, state.particle_qd, detect_steps * self._dt)
        integrator.step(state, self.control, self._dt)
        if sc is not None and filter_steps:
            # Bridson's velocity filter over the interval's `filter_steps` steps (only its last guarantee where
            # the solve held the contacts); then colliders, pins
            sc.filter_velocities(
                state.particle_q,
                state.particle_qd,
                self._dt,
                integrator.velocity_position_weight,
                integrator.position_history(),
                repulsion=integrator.self_contact_filter == "full",
                inelastic=integrator.self_contact_filter != "gap",
                colliders=self.control.collision,
                steps=filter_steps,
            )
        if self.control.collision is not None and not self.integrator.collides_in_solver:
            self._project_colliders()
        edges = self.control.collision.edges(self.model) if self.control.collision is not None else None
        if edges is not None:  # box and mesh edges against the cloth (after the solvers that hold them too)
            if detect_steps:  # a collision interval starts: the continuous response after it sees its pushes
                edges.begin_step()
            edges.project(
                self.state, self._dt, self.integrator.position_history(), self.integrator.velocity_position_weight
            )
        limiter = self.active_limiter
        if limiter is not None:  # after them: the passes above may stretch (a landing vertex pushed out of a
            # collider); it knows no contacts, so it may move a vertex back into a collider or a layer (the next step
            # meets it), but not a cloth triangle back over a collider's edge: the edge passes once more
            limiter.apply(self.state, self._dt)
            if self.control.collision is not None and not self.integrator.collides_in_solver:
                self._project_colliders()  # a vertex the limit pulled into a collider (26 mm at 5 m/s) out again
            if edges is not None:
                edges.project(
                    self.state,
                    self._dt,
                    self.integrator.position_history(),
                    self.integrator.velocity_position_weight,
                    passes=edges.passes_after_limit,
                )
        self.control.advance(self._dt)
        apply_pins(self.control, self.state.particle_q, self.state.particle_qd)  # x = track(t + dt), v = track'(t + dt)
        if sc is not None and filter_steps:  # last (pins at their end, moving none): no pair crossed on the way
            sc.prevent_crossings(
                state.particle_q,
                state.particle_qd,
                self._dt,
                integrator.velocity_position_weight,
                integrator.position_history(),
                colliders=self.control.collision,
                steps=filter_steps,
                held=edges.held if edges is not None else None,
            )

    def _project_colliders(self) -> None:
        """Every particle out of the colliders posed at the step's end, its normal velocity relative to them
        removed, with friction (:meth:`ColliderSet.project_velocity <warpcloth.sim.contacts.ColliderSet.project_velocity>`)."""
        self.control.collision.project_velocity(
            self.model,
            self.state,
            self._dt,
            self.integrator.position_history(),
            self.integrator.velocity_position_weight,
        )

    def simulate(self, steps: int) -> None:
        """Advance ``steps`` time steps (replaying captured graphs of them where enabled: in chunks of
        at most :data:`GRAPH_CHUNK` steps and the rest, each chunk one graph on CUDA, graphs of at most
        :data:`CPU_GRAPH_STEPS` steps on the CPU; :meth:`_pieces`)."""
        steps = require_count("steps", steps)
        if steps == 0:
            return
        self._drive(steps)
        if not self.graph_enabled:
            self._warm_deforming()
            for chunk in self._chunks(steps):
                for detect_steps, filter_steps in self._schedule(chunk):
                    self._launch_step(detect_steps, filter_steps)
                    self._count_steps(1)
            return
        chunks = self._chunks(steps)
        pieces = {n: self._pieces(n) for n in dict.fromkeys(chunks)}  # at most two counts
        key = self._capture_key()
        distinct = dict.fromkeys(p for n in pieces for p in pieces[n])
        graphs = {p: self._graph(p, key) for p in distinct}  # all captured before any replay
        for chunk in chunks:
            for piece in pieces[chunk]:
                wp.capture_launch(graphs[piece])
        self._count_steps(steps)

    def _warm_deforming(self) -> None:
        """Before the first plain-launch step with a deforming mesh collider (on the CPU its frames
        are not captured): the warm-up a capture does first, so that a position-based step's first
        substeps pose the mesh at t + dt (k + 1)/S with the integrator's S, not with S = 1 (the
        whole step's motion pushed into the first substep, 0.9 m/s up off a sphere breathing at
        0.19 m/s, pbd at dt = 1/600 s)."""
        collision = self.control.collision
        if not self._warmed and collision is not None and collision.deforming:
            self.warm_up()
            self._begin()

    def _pieces(self, chunk: int) -> tuple[tuple, ...]:
        """A chunk of ``chunk`` steps as the schedules of the graphs that replay it (each a tuple of
        :meth:`_schedule`'s ``(detect, filter)`` per step): on CUDA the whole chunk, one graph launch;
        on the CPU runs of :data:`CPU_GRAPH_STEPS` steps, so that a frame's capture records a step or
        a few, not up to two chunks (explicit Euler on the 16 x 16 flag, 45 steps a frame: its first frame
        0.042 s of CPU in graphs of 16 and 13 steps, 0.012 s in graphs of 4 and 1, 0.006 s in graphs of
        one step; docs/architecture.md)."""
        per_graph = CPU_GRAPH_STEPS if wp.get_device(self.model.device).is_cpu else chunk
        return graph_pieces(chunk, self._interval_steps(), per_graph)

    def _graph(self, piece: tuple, capture_key: tuple):
        """The captured graph of the steps ``piece`` (a tuple of ``(detect, filter)``, :meth:`_pieces`),
        captured on first use and kept per piece and :meth:`_capture_key`."""
        key = (piece, capture_key)
        graph = self._graphs.get(key)
        if graph is None:
            if not self._warmed:  # load every kernel before capturing (older CUDA drivers require it)
                self.warm_up()
                self._begin()
            if len(self._graphs) >= MAX_GRAPHS:
                self._graphs.clear()
            t0 = time.perf_counter()
            with wp.ScopedCapture(device=self.model.device) as capture:
                for detect_steps, filter_steps in piece:
                    self._launch_step(detect_steps, filter_steps)
            graph = self._graphs[key] = capture.graph
            self.capture_time += time.perf_counter() - t0
        return graph

    def warm_up(self) -> float:
        """Compile and load every kernel a step uses, on a scratch copy of the state; returns
        the seconds it took (reported as compile time, excluded from step timings)."""
        t0 = time.perf_counter()
        saved = wp.clone(self.state.particle_q), wp.clone(self.state.particle_qd)
        saved_time = wp.clone(self.control.time)
        self._begin()
        self._launch_step()
        wp.copy(self.state.particle_q, saved[0])
        wp.copy(self.state.particle_qd, saved[1])
        wp.copy(self.control.time, saved_time)
        self.control.rebase()
        self.control.update()
        wp.synchronize_device(self.model.device)
        self.integrator.reset_stats()
        if self.self_collision is not None:  # the warm-up's step counts nothing
            self.self_collision.invalidate()
            self.self_collision.reset_stats()
        self._needs_begin = True
        self._warmed = True
        return time.perf_counter() - t0
