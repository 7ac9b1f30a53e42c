"""The time-varying external input of a simulation: gravity, drag, wind, pin tracks, colliders.

:class:`Control` holds the time-varying input (Newton's "Control"): gravity, linear air drag and
a wind schedule W(t). Its simulated time and current wind live in device arrays, so a captured
frame replays with the right wind.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import warp as wp

from warpcloth.errors import (
    WarpclothError,
    require,
    require_non_negative,
    require_number,
    require_positive,
    require_vector,
)
from warpcloth.kernels import collide as ck
from warpcloth.kernels import forces as fk
from warpcloth.kernels import pins as pk
from warpcloth.sim.contacts import ColliderSet
from warpcloth.sim.device import resolve_device
from warpcloth.sim.pins import KinematicPins, PinTrack

GRAVITY = (0.0, -9.81, 0.0)


@dataclass(frozen=True)
class WindSchedule:
    """Piecewise-constant wind velocity W(t) [m/s].

    ``W(t) = winds[k]`` for the last ``k`` with ``starts[k] <= t`` (zero before the first start);
    with ``period > 0`` the schedule repeats: t is taken modulo the period.
    """

    starts: tuple[float, ...] = ()
    winds: tuple[tuple[float, float, float], ...] = ()
    period: float = 0.0

    def __post_init__(self):
        for name in ("starts", "winds"):
            if isinstance(getattr(self, name), (str, bytes)) or not hasattr(getattr(self, name), "__len__"):
                raise WarpclothError(f"wind schedule {name} must be a sequence, got {getattr(self, name)!r:.80}")
        require(len(self.starts) == len(self.winds), "wind schedule needs one wind vector per start time")
        starts = tuple(require_number(f"wind schedule start {k}", s, "s") for k, s in enumerate(self.starts))
        winds = tuple(require_vector(f"wind schedule wind {k}", w, 3, "m/s") for k, w in enumerate(self.winds))
        object.__setattr__(self, "starts", starts)
        object.__setattr__(self, "winds", winds)
        require(
            all(b >= a for a, b in zip(self.starts, self.starts[1:])),
            f"wind schedule start times must be increasing, got {list(self.starts)}",
        )
        object.__setattr__(self, "period", require_non_negative("wind schedule period", self.period, "s"))

    @classmethod
    def constant(cls, wind) -> WindSchedule:
        """The constant wind ``wind`` [m/s] from t = 0."""
        return cls(starts=(0.0,), winds=(require_vector("wind", wind, 3, "m/s"),))

    @classmethod
    def gusts(cls, wind, on: float, off: float, base=(0.0, 0.0, 0.0)) -> WindSchedule:
        """Gusts of ``wind`` for ``on`` seconds, then ``base`` for ``off`` seconds, repeating."""
        wind = require_vector("gust wind", wind, 3, "m/s")
        base = require_vector("gust base wind", base, 3, "m/s")
        on = require_positive("gust on duration", on, "s")
        off = require_positive("gust off duration", off, "s")
        return cls(starts=(0.0, on), winds=(wind, base), period=on + off)

    def __call__(self, t: float) -> np.ndarray:
        """W(t) evaluated on the host (for tests and reports)."""
        if self.period > 0:
            t = t % self.period
        w = np.zeros(3)
        for s, wk in zip(self.starts, self.winds):
            if s <= t:
                w = np.asarray(wk, dtype=float)
        return w


#: No wind: the default schedule (a WindSchedule is frozen, so one instance serves every Control).
NO_WIND = WindSchedule()


class Control:
    """Time-varying external input of a simulation.

    Args:
        gravity: gravitational acceleration [m/s^2].
        drag_rate: linear air drag rate c [1/s]; the force on a particle is -m c v.
        wind_coefficient: c_w [kg/(m^2 s)] in f = c_w A (n . u) n on each triangle; 0 disables wind.
        wind_schedule: the wind velocity W(t) (:attr:`wind_schedule`).
        device: Warp device of the device arrays (default: Warp's current device).
        pin_tracks: kinematic pins (:attr:`pin_tracks`).
        colliders: the colliders (:attr:`colliders`).

    Setting :attr:`colliders` rebuilds :attr:`collision` and setting :attr:`wind_schedule`
    refills its device copy (both properties); every other attribute is a plain one.
    """

    def __init__(
        self,
        gravity=GRAVITY,
        drag_rate: float = 0.0,
        wind_coefficient: float = 0.0,
        wind_schedule: WindSchedule = NO_WIND,
        device: str | None = None,
        pin_tracks: tuple = (),
        colliders: tuple = (),
    ):
        require_non_negative("drag", drag_rate, "1/s")
        require_non_negative("wind coefficient", wind_coefficient, "kg/(m^2 s)")
        self.gravity: tuple[float, float, float] = require_vector("gravity", gravity, 3, "m/s^2")
        """Gravitational acceleration [m/s^2], a 3-tuple."""
        self.drag_rate = drag_rate
        """Linear air drag rate c [1/s]: the force on a particle is -m c v."""
        self.wind_coefficient = wind_coefficient
        """c_w [kg/(m^2 s)] in f = c_w A (n . u) n on each triangle; 0 disables wind."""
        self.device = resolve_device(device)
        """The Warp device of :attr:`time`, :attr:`wind` and the collider records."""
        self.pin_tracks = pin_tracks
        """Kinematic pins (:class:`~warpcloth.sim.pins.PinTrack`), bound to a model by
        :meth:`bind_pin_tracks` (the :class:`~warpcloth.simulator.Simulator` calls it; see
        :mod:`warpcloth.sim.pins`)."""
        self.kinematic_pins: KinematicPins | None = None
        """The :attr:`pin_tracks` bound to the model (:meth:`bind_pin_tracks`), which the
        integrators launch; None without tracks."""
        with wp.ScopedDevice(self.device):
            self.time = wp.zeros(1, dtype=wp.float64)
            """Simulated time [s], device array of shape (1,), float64: t_base + n dt after n
            steps of dt since the last change of dt, so switch times land exactly on steps."""
            self._time_base = wp.zeros(1, dtype=wp.float64)
            self._clock = wp.zeros(1, dtype=wp.int64)
            self.wind = wp.zeros(1, dtype=wp.vec3)
            """Current wind velocity W(time) [m/s], device array of shape (1,), vec3 (:meth:`update`)."""
            self._step_dt = wp.zeros(
                1, dtype=wp.float64
            )  # the last step's dt: position-based steps pose moving colliders with it
            self.frame_times = wp.zeros(4, dtype=wp.float64)
            """The key times (t0 - 1, t0, t1, t1 + 1) [s] of the frame being driven from the host
            (:meth:`upload_drives`), device array of shape (4,), float64: read by driven pin
            tracks and colliders (:class:`~warpcloth.sim.tracks.FrameDrive`)."""
        self._frame_launch = None  # ((dt, steps), the recorded eval_frame_times launch)
        self._schedule_start = self._schedule_wind = None  # the device copy of the wind schedule (_fill_schedule)
        self.colliders = colliders
        self.wind_schedule = wind_schedule

    def __repr__(self) -> str:
        return (
            f"Control(gravity={self.gravity!r}, drag_rate={self.drag_rate!r}, "
            f"wind_coefficient={self.wind_coefficient!r}, wind_schedule={self.wind_schedule!r}, "
            f"device={self.device!r}, pin_tracks={self.pin_tracks!r}, colliders={self.colliders!r})"
        )

    @property
    def colliders(self) -> tuple:
        """:class:`~warpcloth.sim.colliders.Plane`, ``Sphere``, ``Capsule``, ``Box`` or
        :class:`~warpcloth.sim.colliders.MeshCollider` objects, static or moving on a
        :class:`~warpcloth.sim.colliders.ColliderTrack` (see :mod:`warpcloth.sim.colliders`).
        Setting them rebuilds :attr:`collision` (on the device; a Simulator's next frame captures
        anew, its capture key has the colliders)."""
        return self._colliders

    @colliders.setter
    def colliders(self, value) -> None:
        value = tuple(value)
        collision = (
            ColliderSet(value, self.device, time=self.time, step_dt=self._step_dt, frame_times=self.frame_times)
            if value
            else None
        )
        self._colliders, self._collision = value, collision

    @property
    def collision(self) -> ColliderSet | None:
        """The :attr:`colliders` on the device (:class:`~warpcloth.sim.contacts.ColliderSet`),
        None without colliders; rebuilt when :attr:`colliders` is set."""
        return self._collision

    @property
    def wind_schedule(self) -> WindSchedule:
        """The wind velocity W(t). Setting it copies it to the device (in place where the number
        of entries is the same, so a captured frame keeps its arrays) and re-evaluates
        :attr:`wind` at the current time."""
        return self._wind_schedule

    @wind_schedule.setter
    def wind_schedule(self, value: WindSchedule) -> None:
        if not isinstance(value, WindSchedule):
            raise WarpclothError(f"wind_schedule must be a WindSchedule, got {value!r}")
        self._wind_schedule = value
        self._fill_schedule()

    def bind_pin_tracks(self, model, tracks) -> None:
        """Set :attr:`pin_tracks` to ``tracks`` (a :class:`~warpcloth.sim.pins.PinTrack` or
        several) and bind them to ``model`` as :attr:`kinematic_pins` (checked: their particles
        are pinned in the model, in no two tracks)."""
        if isinstance(tracks, PinTrack):
            tracks = (tracks,)
        tracks = tuple(tracks or ())
        self.pin_tracks = tracks
        self.kinematic_pins = KinematicPins(model, tracks, self.frame_times) if tracks else None

    @property
    def drives(self) -> list:
        """The :class:`~warpcloth.sim.tracks.FrameDrive` s of the driven pin tracks and colliders."""
        pins = [d for d, _ in self.kinematic_pins.drives] if self.kinematic_pins is not None else []
        return pins + (self.collision.drives if self.collision is not None else [])

    def upload_drives(self, dt: float, steps: int, t0: float) -> bool:
        """Before a frame of ``steps`` steps of ``dt`` from the host time ``t0``: the frame's key
        times on the device (from its clock, as the steps will advance it) and every driven
        track's keys for it (its new target, or a hold after a moving frame). Returns whether
        a driven pin track was written (its pins then take the frame's start, see
        :meth:`KinematicPins.apply_driven <warpcloth.sim.pins.KinematicPins.apply_driven>`)."""
        pins = [d for d, _ in self.kinematic_pins.drives] if self.kinematic_pins is not None else []
        others = self.collision.drives if self.collision is not None else []
        if not pins and not others:
            return False
        if any(d.pending for d in pins) or any(d.pending for d in others):
            key = (float(dt), int(steps))
            if self._frame_launch is None or self._frame_launch[0] != key:  # recorded once per frame length
                cmd = wp.launch(
                    pk.eval_frame_times,
                    dim=1,
                    inputs=[self.time, self._time_base, self._clock, wp.float64(dt), int(steps)],
                    outputs=[self.frame_times],
                    device=self.device,
                    record_cmd=True,
                )
                self._frame_launch = (key, cmd)
            self._frame_launch[1].launch()
        t1 = t0 + steps * dt
        moved = [d.upload(t0, t1) for d in pins]
        for d in others:
            d.upload(t0, t1)
        return any(moved)

    def _fill_schedule(self) -> None:
        """Copy :attr:`wind_schedule` to the device (float64 start times) and re-evaluate W(t)."""
        n = max(1, len(self.wind_schedule.starts))
        starts = np.full(n, np.inf, dtype=np.float64)
        winds = np.zeros((n, 3), dtype=np.float32)
        if self.wind_schedule.starts:
            starts[:] = self.wind_schedule.starts
            winds[:] = self.wind_schedule.winds
        current = self._schedule_start
        if current is not None and current.shape[0] == n:  # in place: captured graphs keep their arrays
            current.assign(starts)
            self._schedule_wind.assign(winds)
        else:
            with wp.ScopedDevice(self.device):
                self._schedule_start = wp.array(starts, dtype=wp.float64)
                self._schedule_wind = wp.array(winds, dtype=wp.vec3)
        self.update()

    @property
    def has_wind(self) -> bool:
        return self.wind_coefficient > 0.0 and len(self.wind_schedule.starts) > 0

    @property
    def gravity_magnitude(self) -> float:
        return float(np.linalg.norm(self.gravity))

    def set_time(self, t: float) -> None:
        """Set the simulated time [s] (host write; not for use inside a captured frame)."""
        self.time.fill_(float(t))
        self.rebase()
        self.update()

    def rebase(self, dt: float | None = None) -> None:
        """Count steps from the current time: after n steps of dt, t = t_now + n dt (on the device); with
        ``dt``, moving colliders take it as the last step's before the first :meth:`advance` (a first
        position-based step posed them at t, a sphere at 5 m/s 30 mm into the cloth it had met by t + dt)."""
        wp.launch(fk.rebase_time, dim=1, inputs=[self.time, self._time_base, self._clock], device=self.device)
        if dt is not None and self.collision is not None and self.collision.moving:
            wp.launch(ck.store_step, dim=1, inputs=[wp.float64(dt)], outputs=[self._step_dt], device=self.device)

    def update(self) -> None:
        """Evaluate W(time) into :attr:`wind` on the device, and start a step of the moving
        colliders (:meth:`ColliderSet.begin_step <warpcloth.sim.contacts.ColliderSet.begin_step>`:
        posed at the end of the first position-based substep, with the dt of the last
        :meth:`advance`; force-based steps re-pose them at exactly t + dt after the step)."""
        if self.collision is not None:
            self.collision.begin_step()
        if self.has_wind:
            wp.launch(
                fk.eval_wind_schedule,
                dim=1,
                inputs=[self.time, self._schedule_start, self._schedule_wind, wp.float64(self.wind_schedule.period)],
                outputs=[self.wind],
                device=self.device,
            )

    def advance(self, dt: float) -> None:
        """t = t_base + n dt after the n-th step since :meth:`rebase`, on the device."""
        wp.launch(
            fk.advance_time, dim=1, inputs=[self.time, self._time_base, self._clock, wp.float64(dt)], device=self.device
        )
        if self.collision is not None and self.collision.moving:
            wp.launch(ck.store_step, dim=1, inputs=[wp.float64(dt)], outputs=[self._step_dt], device=self.device)
