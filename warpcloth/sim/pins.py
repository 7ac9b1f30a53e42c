"""Kinematic pins: pinned particles that follow a prescribed track.

A :class:`PinTrack` moves some pinned particles along keyframes (linear, Catmull-Rom or Hermite
interpolation) or a rigid motion (translation and rotation about an axis: a rod swinging, a
shoulder moving). Tracks go in :attr:`Control.pin_tracks <warpcloth.sim.control.Control>` or
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

import math
from dataclasses import dataclass

import numpy as np
import warp as wp

from warpcloth.errors import WarpclothError, require
from warpcloth.kernels import pins as pk

INTERPOLATIONS = ("linear", "catmull_rom", "hermite")


def _finite(name: str, a: np.ndarray) -> np.ndarray:
    if not np.all(np.isfinite(a)):
        raise WarpclothError(f"pin track {name} must be finite numbers, got {float(a[~np.isfinite(a)][0])!r}")
    return a


@dataclass(frozen=True, eq=False)
class PinTrack:
    """Where some pinned particles are at time t.

    Make one with :meth:`keyframes` or :meth:`rigid`. ``particles`` must be pinned in the model.
    """

    particles: tuple
    kind: str  # "keyframes" or "rigid"
    times: np.ndarray | None = None
    values: np.ndarray | None = None  # (K, P, 3) absolute, or (K, 3) offsets from the rest positions
    tangents: np.ndarray | None = None
    interpolation: str = "linear"
    center: tuple = (0.0, 0.0, 0.0)
    axis: tuple = (0.0, 0.0, 1.0)
    velocity: tuple = (0.0, 0.0, 0.0)
    angular_velocity: float = 0.0
    swing_amplitude: float = 0.0
    swing_frequency: float = 0.0
    swing_phase: float = 0.0
    name: str = "track"

    @classmethod
    def keyframes(cls, particles, times, positions, interpolation: str = "linear", tangents=None, name: str = "track") -> "PinTrack":
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
        idx = _particles(particles)
        require(interpolation in INTERPOLATIONS, f"pin track interpolation must be one of {', '.join(INTERPOLATIONS)}, got {interpolation!r}")
        t = _finite("times", np.asarray(times, dtype=np.float64).reshape(-1))
        require(t.size >= 1, "pin track needs at least one keyframe")
        bad = np.flatnonzero(np.diff(t) <= 0)
        if bad.size:
            k = int(bad[0])
            raise WarpclothError(f"pin track keyframes out of order: time {float(t[k + 1])!r} s (key {k + 1}) is not after {float(t[k])!r} s (key {k}); key times must increase")
        v = _finite("positions", np.asarray(positions, dtype=np.float64))
        shapes = [(t.size, 3), (t.size, idx.size, 3)]
        require(v.shape in shapes, f"pin track positions must have shape (K, 3) offsets or (K, P, 3) = {shapes[1]}, got {v.shape}")
        tan = None
        if interpolation == "hermite":
            require(tangents is not None, "pin track interpolation 'hermite' needs tangents (shaped like positions) [m/s]")
            tan = _finite("tangents", np.asarray(tangents, dtype=np.float64))
            require(tan.shape == v.shape, f"pin track tangents must have the shape of positions {v.shape}, got {tan.shape}")
        elif tangents is not None:
            raise WarpclothError(f"pin track tangents apply to interpolation 'hermite' only, not {interpolation!r}")
        return cls(particles=tuple(idx.tolist()), kind="keyframes", times=t, values=v, tangents=tan, interpolation=interpolation, name=name)

    @classmethod
    def rigid(cls, particles, center=(0.0, 0.0, 0.0), axis=(0.0, 0.0, 1.0), angular_velocity: float = 0.0,
              swing_amplitude: float = 0.0, swing_frequency: float = 0.0, swing_phase: float = 0.0,
              velocity=(0.0, 0.0, 0.0), name: str = "track") -> "PinTrack":
        """Pins moving rigidly: p(t) = c + u t + R(axis, theta(t)) (p0 - c), with
        theta(t) = omega t + A sin(2 pi f t + phi) [rad] and p0 each particle's rest position.

        Args:
            center: a point c on the rotation axis at t = 0 [m]; axis: its direction (normalised).
            angular_velocity: omega [rad/s]; swing_amplitude: A [rad]; swing_frequency: f [Hz];
            swing_phase: phi [rad]; velocity: the translation velocity u [m/s].
        """
        idx = _particles(particles)
        a = _finite("axis", np.asarray(axis, dtype=np.float64).reshape(-1))
        require(a.size == 3 and np.linalg.norm(a) > 0, f"pin track axis must be a non-zero 3-vector, got {list(axis)!r}")
        c = _finite("center", np.asarray(center, dtype=np.float64).reshape(-1))
        u = _finite("velocity", np.asarray(velocity, dtype=np.float64).reshape(-1))
        require(c.size == 3 and u.size == 3, "pin track center and velocity must be 3-vectors")
        nums = _finite("motion", np.array([angular_velocity, swing_amplitude, swing_frequency, swing_phase], dtype=np.float64))
        require(nums[2] >= 0, f"pin track swing frequency must be >= 0 Hz, got {swing_frequency!r}")
        return cls(particles=tuple(idx.tolist()), kind="rigid", center=tuple(c), axis=tuple(a / np.linalg.norm(a)), velocity=tuple(u),
                   angular_velocity=float(nums[0]), swing_amplitude=float(nums[1]), swing_frequency=float(nums[2]), swing_phase=float(nums[3]), name=name)

    # -- host evaluation (tests, reports) --------------------------------------------------------
    def key_positions(self, rest: np.ndarray) -> np.ndarray:
        """(K, P, 3) keyframe positions [m] for the model's rest positions ``rest`` (N, 3)."""
        p0 = np.asarray(rest, dtype=np.float64)[list(self.particles)]
        return self.values[:, None, :] + p0[None] if self.values.ndim == 2 else self.values

    def key_tangents(self, rest: np.ndarray) -> np.ndarray:
        """(K, P, 3) tangents [m/s] (Catmull-Rom: central differences, zero at the ends)."""
        pos = self.key_positions(rest)
        if self.interpolation == "hermite":
            return np.broadcast_to(self.tangents[:, None, :], pos.shape).copy() if self.tangents.ndim == 2 else self.tangents
        tan = np.zeros_like(pos)
        if self.interpolation == "catmull_rom" and pos.shape[0] > 2:
            t = self.times
            tan[1:-1] = (pos[2:] - pos[:-2]) / (t[2:] - t[:-2])[:, None, None]
        return tan

    def evaluate(self, t: float, rest: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(positions (P, 3) [m], velocities (P, 3) [m/s]) at time t, in float64 on the host."""
        if self.kind == "rigid":
            c, a, u = (np.asarray(x) for x in (self.center, self.axis, self.velocity))
            phase = 2 * math.pi * self.swing_frequency * t + self.swing_phase
            theta = self.angular_velocity * t + self.swing_amplitude * math.sin(phase)
            theta_dot = self.angular_velocity + self.swing_amplitude * 2 * math.pi * self.swing_frequency * math.cos(phase)
            r = np.asarray(rest, dtype=np.float64)[list(self.particles)] - c
            rr = r * math.cos(theta) + np.cross(a, r) * math.sin(theta) + np.outer(r @ a, a) * (1 - math.cos(theta))
            return c + u * t + rr, u + theta_dot * np.cross(a, rr)
        pos, times = self.key_positions(rest), self.times
        if t <= times[0]:
            return pos[0].copy(), np.zeros_like(pos[0])
        if t >= times[-1]:
            return pos[-1].copy(), np.zeros_like(pos[-1])
        k = int(np.searchsorted(times, t, side="right") - 1)
        h = times[k + 1] - times[k]
        s = (t - times[k]) / h
        a, b = pos[k], pos[k + 1]
        if self.interpolation == "linear":
            return a + s * (b - a), (b - a) / h
        tan = self.key_tangents(rest)
        ma, mb = tan[k] * h, tan[k + 1] * h
        p = (2 * s**3 - 3 * s**2 + 1) * a + (s**3 - 2 * s**2 + s) * ma + (3 * s**2 - 2 * s**3) * b + (s**3 - s**2) * mb
        dp = (6 * s**2 - 6 * s) * (a - b) + (3 * s**2 - 4 * s + 1) * ma + (3 * s**2 - 2 * s) * mb
        return p, dp / h


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
    """Pin tracks bound to a model: device arrays built once, launches per step only."""

    def __init__(self, model, tracks):
        self.device = model.device
        self.tracks = tuple(tracks)
        rest = model.host["q"].astype(np.float64)
        n = model.particle_count
        pinned = np.zeros(n, dtype=bool)
        pinned[model.pinned] = True
        owner = {}
        self._bound = []
        with wp.ScopedDevice(self.device):
            for track in self.tracks:
                require(isinstance(track, PinTrack), f"pin tracks must be PinTrack objects, got {track!r}")
                idx = np.asarray(track.particles, dtype=np.int64)
                bad = idx[(idx < 0) | (idx >= n)]
                if bad.size:
                    raise WarpclothError(f"pin track {track.name!r}: particle {int(bad[0])} is out of range: particles are 0..{n - 1}")
                free = idx[~pinned[idx]]
                if free.size:
                    raise WarpclothError(f"pin track {track.name!r}: particle {int(free[0])} is not pinned in the model; pin it (pins=...) to move it along a track")
                for i in idx.tolist():
                    if i in owner:
                        raise WarpclothError(f"particle {i} is in two pin tracks ({owner[i]!r} and {track.name!r})")
                    owner[i] = track.name
                particle = wp.array(idx.astype(np.int32), dtype=int)
                if track.kind == "rigid":
                    args = [particle, wp.array(rest[idx], dtype=wp.vec3d), wp.vec3d(*track.center), wp.vec3d(*track.axis), wp.vec3d(*track.velocity),
                            wp.vec4d(track.angular_velocity, track.swing_amplitude, track.swing_frequency, track.swing_phase)]
                    self._bound.append((pk.apply_pin_rigid, pk.eval_pin_rigid_delta, idx.size, args))
                else:
                    args = [particle, wp.array(track.times, dtype=wp.float64),
                            wp.array(track.key_positions(rest).reshape(-1, 3), dtype=wp.vec3d),
                            wp.array(track.key_tangents(rest).reshape(-1, 3), dtype=wp.vec3d), int(track.interpolation != "linear")]
                    self._bound.append((pk.apply_pin_keyframes, pk.eval_pin_keyframes_delta, idx.size, args))

    def apply(self, control, x, v, offset: float = 0.0) -> None:
        """x_i = track(t + offset), v_i = track'(t + offset) for every tracked pin (t = control.time)."""
        for kernel, _, count, args in self._bound:
            wp.launch(kernel, dim=count, inputs=[control.time, wp.float64(offset), *args], outputs=[x, v], device=self.device)

    def delta(self, control, x, v, offset: float, scale: float, velocity_weight: float, out) -> None:
        """out_i = scale (track(t + offset) - x_i) - velocity_weight v_i for every tracked pin."""
        for _, kernel, count, args in self._bound:
            wp.launch(kernel, dim=count, inputs=[control.time, wp.float64(offset), *args, x, v, float(scale), float(velocity_weight)], outputs=[out], device=self.device)


def apply_pins(control, x, v, offset: float = 0.0) -> None:
    """Put tracked pins on their track at t + offset (nothing when the control has no tracks)."""
    kin = getattr(control, "kinematic_pins", None)
    if kin is not None:
        kin.apply(control, x, v, offset)


def has_pin_tracks(control) -> bool:
    return getattr(control, "kinematic_pins", None) is not None


__all__ = ["INTERPOLATIONS", "KinematicPins", "PinTrack", "apply_pins", "has_pin_tracks"]
