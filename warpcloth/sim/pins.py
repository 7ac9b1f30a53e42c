"""Kinematic pins: pinned particles that follow a prescribed track.

A :class:`PinTrack` moves some pinned particles along keyframes (linear, Catmull-Rom or Hermite
interpolation), a rigid motion (translation and rotation about an axis: a rod swinging, a
shoulder moving), or targets that your own loop sets each frame (:meth:`PinTrack.driven`: a
hand dragging a corner; see docs/driving.md). Tracks go in :attr:`Control.pin_tracks <warpcloth.sim.control.Control>` or
:meth:`Simulator.set_pin_track <warpcloth.simulator.Simulator.set_pin_track>`.

Evaluation is on the device, from the simulated time in ``Control.time`` (float64, plus a
stage offset), inside the step, so a captured frame replays it: a step adds kernel launches
only, no host work. Pinned particles take the track's position and velocity (so damping, drag
and wind see the moving pin), and the pin positions equal the track at every step time:

- every integrator: after the step, at the new time t + dt, x = track(t + dt), v = track'(t + dt);
- midpoint and rk4 stages see the pins at the stage times (t + dt/2, t + dt);
- pbd and xpbd substeps: the pins' displacement dp = track(t + (k+1) h) - x takes part in the
  constraint solve, and each substep ends on the track;
- implicit Euler: the pinned rows keep dv = (track(t + h) - x)/h - v (so x + h (v + dv) is the
  track), and the known dv of each pinned neighbour moves to the right-hand side of the free
  rows (b_i += B_s dv_j), keeping the system symmetric.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import warp as wp

from warpcloth.errors import WarpclothError, require
from warpcloth.kernels import pins as pk
from warpcloth.sim.tracks import INTERPOLATIONS, FrameDrive, Track, check_keyframes, check_rigid


@dataclass(frozen=True, eq=False)
class PinTrack(Track):
    """Where some pinned particles are at time t: a :class:`~warpcloth.sim.tracks.Track` of
    ``particles`` (its ``kind``, ``times``, ``tangents``, ``interpolation`` and rigid-motion
    attributes are the track's).

    Make one with :meth:`keyframes` or :meth:`rigid`. ``particles`` must be pinned in the model.
    """

    particles: tuple
    values: np.ndarray | None = None  # (K, P, 3) absolute, or (K, 3) offsets from the rest positions
    name: str = "track"

    @property
    def keys(self) -> np.ndarray | None:
        return self.values

    @classmethod
    def keyframes(
        cls, particles, times, positions, interpolation: str = "linear", tangents=None, name: str = "track"
    ) -> PinTrack:
        """Keyframed pins.

        Args:
            particles: P pinned particle indices.
            times: K increasing key times [s].
            positions: (K, P, 3) positions [m], or (K, 3) offsets [m] added to each particle's
                rest position (the pins move together, as on a rod).
            interpolation: ``"linear"``; ``"catmull_rom"`` (cubic Hermite with tangents
                (p_{k+1} - p_{k-1}) / (t_{k+1} - t_{k-1}), zero at the first and last key, so the
                motion starts and ends at rest); ``"hermite"`` (cubic with your ``tangents`` [m/s],
                shaped like ``positions``). Before the first key and after the last the pins hold
                still.
        """
        idx, name = _particles(particles), _name(name)
        t, v, tan = check_keyframes("pin track", times, positions, interpolation, tangents, idx.size)
        return cls(
            particles=tuple(idx.tolist()),
            kind="keyframes",
            times=t,
            values=v,
            tangents=tan,
            interpolation=interpolation,
            name=name,
        )

    @classmethod
    def rigid(
        cls,
        particles,
        center=(0.0, 0.0, 0.0),
        axis=(0.0, 0.0, 1.0),
        angular_velocity: float = 0.0,
        swing_amplitude: float = 0.0,
        swing_frequency: float = 0.0,
        swing_phase: float = 0.0,
        velocity=(0.0, 0.0, 0.0),
        name: str = "track",
    ) -> PinTrack:
        """Pins moving rigidly: p(t) = c + u t + R(axis, theta(t)) (p0 - c), with
        theta(t) = omega t + A sin(2 pi f t + phi) [rad] and p0 each particle's rest position.

        Args:
            center: a point c on the rotation axis at t = 0 [m]; axis: its direction (normalised).
            angular_velocity: omega [rad/s]; swing_amplitude: A [rad]; swing_frequency: f [Hz];
            swing_phase: phi [rad]; velocity: the translation velocity u [m/s].
        """
        idx, name = _particles(particles), _name(name)
        motion = check_rigid(
            "pin track", center, axis, angular_velocity, swing_amplitude, swing_frequency, swing_phase, velocity
        )
        return cls(particles=tuple(idx.tolist()), name=name, **motion)

    @classmethod
    def driven(cls, particles, interpolation: str = "linear", name: str = "driven") -> PinTrack:
        """Pins that your loop moves each frame: ``track.set(positions)`` (or
        :meth:`Simulator.set_pin_targets <warpcloth.simulator.Simulator.set_pin_targets>`) says
        where they are at the end of the next ``simulate()`` call, and its steps interpolate to
        it (:class:`~warpcloth.sim.tracks.FrameDrive`). The targets go into device arrays the
        captured frame already reads: a new target costs a copy, not a capture.

        Args:
            particles: P pinned particle indices; they start at their rest positions.
            interpolation: ``"linear"`` (velocity (p1 - p0) / frame time; the same motion as a
                linear :meth:`keyframes` track through the targets, to the bit) or ``"hermite"``
                (give each target's velocity too: ``set(positions, velocities)``, e.g. a hand's
                velocity, which damping, drag and wind see).
        """
        idx, name = _particles(particles), _name(name)
        drive = FrameDrive(f"pin track {name!r}", idx.size, interpolation)
        return cls(particles=tuple(idx.tolist()), kind="driven", interpolation=interpolation, name=name, drive=drive)

    def set(self, positions, velocities=None) -> None:
        """A driven track's target: ``positions`` (P, 3) [m] at the end of the next frame (a
        ``simulate()`` call), and with ``"hermite"`` the ``velocities`` (P, 3) [m/s] there."""
        require(
            self.kind == "driven",
            f"pin track {self.name!r} is {self.kind}, not driven: only PinTrack.driven takes targets",
        )
        self.drive.set(positions, velocities)

    # -- host evaluation (tests, reports) --------------------------------------------------------
    def _rest(self, rest: np.ndarray) -> np.ndarray:
        return np.asarray(rest, dtype=np.float64)[list(self.particles)]

    def key_positions(self, rest: np.ndarray) -> np.ndarray:
        """(K, P, 3) keyframe positions [m] for the model's rest positions ``rest`` (N, 3)."""
        return self._key_points(self._rest(rest))

    def key_tangents(self, rest: np.ndarray) -> np.ndarray:
        """(K, P, 3) tangents [m/s] (Catmull-Rom: central differences, zero at the ends)."""
        return self._key_tangents(self._rest(rest))

    def evaluate(self, t: float, rest: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(positions (P, 3) [m], velocities (P, 3) [m/s]) at time t, in float64 on the host."""
        return self._evaluate(t, self._rest(rest))

    def launch_args(self, rest: np.ndarray) -> list:
        """The pin kernels' track arguments (after the time and offset) for the model's rest
        positions ``rest`` (N, 3) float64: device arrays made once, on the current device."""
        idx = np.asarray(self.particles, dtype=np.int64)
        particle = wp.array(idx.astype(np.int32), dtype=int)
        if self.kind == "rigid":
            return [particle, wp.array(rest[idx], dtype=wp.vec3d), *self._rigid_args()]
        if self.kind == "driven":
            raise WarpclothError("a driven pin track's arguments come from its drive (KinematicPins binds it)")
        keys, tangents = self.key_positions(rest).reshape(-1, 3), self.key_tangents(rest).reshape(-1, 3)
        return [particle, *self._keyframe_args(keys, tangents)]


def _name(name) -> str:
    """A track's name: non-empty printable text (it names the track in set_pin_targets(track=...) and
    in messages)."""
    require(
        isinstance(name, str) and name != "" and name.isprintable(),
        f"pin track name must be non-empty printable text, got {name!r:.80}",
    )
    return name


def _particles(particles) -> np.ndarray:
    try:
        idx = np.asarray(list(particles), dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise WarpclothError(f"pin track particles must be integer indices, got {particles!r}") from None
    require(idx.size > 0, "pin track needs at least one particle")
    require(bool(np.all(idx == np.round(idx))), f"pin track particles must be integer indices, got {list(particles)!r}")
    idx = idx.astype(np.int64)
    require(np.unique(idx).size == idx.size, "pin track particles must not repeat")
    return idx


class KinematicPins:
    """Pin tracks bound to a model: device arrays built once, launches per step only.

    ``frame_times``: the device array of a driven frame's key times (:attr:`Control.frame_times
    <warpcloth.sim.control.Control.frame_times>`), read by the driven tracks."""

    def __init__(self, model, tracks, frame_times=None):
        self.device = model.device
        self.tracks = tuple(tracks)
        rest = model.host.q.astype(np.float64)
        n = model.particle_count
        pinned = np.zeros(n, dtype=bool)
        pinned[model.pinned] = True
        owner = {}
        self._bound = []
        self.drives = []  # (FrameDrive, its entry in _bound) of the driven tracks
        self._driven_launches = None  # ((x, v, time) pointers, recorded apply launches of the driven tracks)
        with wp.ScopedDevice(self.device):
            for track in self.tracks:
                require(isinstance(track, PinTrack), f"pin tracks must be PinTrack objects, got {track!r}")
                idx = np.asarray(track.particles, dtype=np.int64)
                bad = idx[(idx < 0) | (idx >= n)]
                if bad.size:
                    raise WarpclothError(
                        f"pin track {track.name!r}: particle {int(bad[0])} is out of range: particles are 0..{n - 1}"
                    )
                free = idx[~pinned[idx]]
                if free.size:
                    raise WarpclothError(
                        f"pin track {track.name!r}: particle {int(free[0])} is not pinned in the model; pin it "
                        "(pins=...) to move it along a track"
                    )
                for i in idx.tolist():
                    if i in owner:
                        raise WarpclothError(f"particle {i} is in two pin tracks ({owner[i]!r} and {track.name!r})")
                    owner[i] = track.name
                kernels = (
                    (pk.apply_pin_rigid, pk.eval_pin_rigid_delta)
                    if track.kind == "rigid"
                    else (pk.apply_pin_keyframes, pk.eval_pin_keyframes_delta)
                )
                if track.kind == "driven":
                    require(frame_times is not None, "driven pin tracks need the control's frame_times")
                    track.drive.start(rest[idx])
                    particle = wp.array(idx.astype(np.int32), dtype=int)
                    self._bound.append((*kernels, idx.size, [particle, frame_times, *track.drive.bind(self.device)]))
                    self.drives.append((track.drive, self._bound[-1]))
                else:
                    self._bound.append((*kernels, idx.size, track.launch_args(rest)))

    def apply(self, control, x, v, offset: float = 0.0) -> None:
        """x_i = track(t + offset), v_i = track'(t + offset) for every tracked pin (t = control.time)."""
        for kernel, _, count, args in self._bound:
            wp.launch(
                kernel, dim=count, inputs=[control.time, wp.float64(offset), *args], outputs=[x, v], device=self.device
            )

    def apply_driven(self, control, x, v) -> None:
        """x_i = track(t), v_i = track'(t) for the driven tracks only (a new frame's keys start
        at t: the pins take its velocity, as a keyframes track's pins would at a key)."""
        if self._driven_launches is None or self._driven_launches[0] != (x.ptr, v.ptr, control.time.ptr):
            cmds = [
                wp.launch(
                    kernel,
                    dim=count,
                    inputs=[control.time, wp.float64(0.0), *args],
                    outputs=[x, v],
                    device=self.device,
                    record_cmd=True,
                )
                for _, (kernel, _, count, args) in self.drives
            ]
            self._driven_launches = ((x.ptr, v.ptr, control.time.ptr), cmds)
        for cmd in self._driven_launches[1]:
            cmd.launch()

    def delta(self, control, x, v, offset: float, scale: float, velocity_weight: float, out) -> None:
        """out_i = scale (track(t + offset) - x_i) - velocity_weight v_i for every tracked pin."""
        for _, kernel, count, args in self._bound:
            wp.launch(
                kernel,
                dim=count,
                inputs=[control.time, wp.float64(offset), *args, x, v, float(scale), float(velocity_weight)],
                outputs=[out],
                device=self.device,
            )


def apply_pins(control, x, v, offset: float = 0.0) -> None:
    """Put tracked pins on their track at t + offset (nothing when the control has no tracks)."""
    kin = getattr(control, "kinematic_pins", None)
    if kin is not None:
        kin.apply(control, x, v, offset)


def has_pin_tracks(control) -> bool:
    return getattr(control, "kinematic_pins", None) is not None


__all__ = ["INTERPOLATIONS", "KinematicPins", "PinTrack", "apply_pins", "has_pin_tracks"]
