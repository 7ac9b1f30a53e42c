"""Tracks: where something kinematic is at time t, as keyframes or a rigid motion.

:class:`Track` is what a pin track (:class:`~warpcloth.sim.pins.PinTrack`) and a collider's pose
track (:class:`~warpcloth.sim.colliders.ColliderTrack`) share:

- ``"keyframes"``: K increasing key times [s] and key values (positions or offsets [m]),
  interpolated linearly, by Catmull-Rom (tangents (p_{k+1} - p_{k-1}) / (t_{k+1} - t_{k-1}), zero
  at the first and last key) or by cubic Hermite with given tangents [m/s]; held still before the
  first key and after the last;
- ``"rigid"``: y -> c + u t + R(axis, theta(t)) (y - c), theta(t) = omega t + A sin(2 pi f t + phi).

The step evaluates tracks on the device (:mod:`warpcloth.kernels.pins`,
:mod:`warpcloth.kernels.collide`); this module holds their description, its validation, the host
evaluation (tests, reports, writers), :meth:`Track.moving_until` and the kernels' track arguments.
The subclasses add what differs: the pinned particles, or a collider's pose.
"""

from __future__ import annotations

import math
from dataclasses import KW_ONLY, dataclass

import numpy as np
import warp as wp

from warpcloth.errors import WarpclothError, require

INTERPOLATIONS = ("linear", "catmull_rom", "hermite")


def _finite(what: str, name: str, a: np.ndarray) -> np.ndarray:
    if not np.all(np.isfinite(a)):
        raise WarpclothError(f"{what} {name} must be finite numbers, got {float(a[~np.isfinite(a)][0])!r}")
    return a


def _numbers(what: str, name: str, value) -> np.ndarray:
    """``value`` as a float64 array, or a :class:`WarpclothError` (text, booleans, tables and
    ragged lists are not numbers)."""
    def bad():
        return WarpclothError(f"{what} {name} must be numbers, got {value!r:.80}")

    if isinstance(value, (str, bytes, bool, dict)) or value is None:
        raise bad()
    try:
        a = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        raise bad() from None
    if isinstance(value, (list, tuple)) and any(isinstance(x, (bool, str)) for x in np.asarray(value, dtype=object).ravel()):
        raise bad()
    return a


def check_keyframes(what: str, times, positions, interpolation: str, tangents, points: int):
    """Checked keyframes (times (K,) float64, values (K, 3) or (K, P, 3) with P = ``points``,
    tangents shaped like the values or None); errors start with ``what`` ("pin track")."""
    require(interpolation in INTERPOLATIONS,
            f"{what} interpolation must be one of {', '.join(INTERPOLATIONS)}, got {interpolation!r}")
    t = _finite(what, "times", _numbers(what, "times", times).reshape(-1))
    require(t.size >= 1, f"{what} needs at least one keyframe")
    bad = np.flatnonzero(np.diff(t) <= 0)
    if bad.size:
        k = int(bad[0])
        raise WarpclothError(f"{what} keyframes out of order: time {float(t[k + 1])!r} s (key {k + 1}) is not after "
                             f"{float(t[k])!r} s (key {k}); key times must increase")
    v = _finite(what, "positions", _numbers(what, "positions", positions))
    shapes = [(t.size, 3), (t.size, points, 3)]
    require(v.shape in shapes,
            f"{what} positions must have shape (K, 3) offsets or (K, P, 3) = {shapes[1]}, got {v.shape}")
    tan = None
    if interpolation == "hermite":
        require(tangents is not None, f"{what} interpolation 'hermite' needs tangents (shaped like positions) [m/s]")
        tan = _finite(what, "tangents", _numbers(what, "tangents", tangents))
        require(tan.shape == v.shape, f"{what} tangents must have the shape of positions {v.shape}, got {tan.shape}")
    elif tangents is not None:
        raise WarpclothError(f"{what} tangents apply to interpolation 'hermite' only, not {interpolation!r}")
    return t, v, tan


def check_rigid(what: str, center, axis, angular_velocity, swing_amplitude, swing_frequency, swing_phase,
                velocity) -> dict:
    """The checked fields of a rigid motion (``kind="rigid"``, centre, unit axis, ...) for a
    :class:`Track` subclass's constructor; errors start with ``what``."""
    a = _finite(what, "axis", _numbers(what, "axis", axis).reshape(-1))
    require(a.size == 3 and np.linalg.norm(a) > 0, f"{what} axis must be a non-zero 3-vector, got {axis!r:.80}")
    c = _finite(what, "center", _numbers(what, "center", center).reshape(-1))
    u = _finite(what, "velocity", _numbers(what, "velocity", velocity).reshape(-1))
    require(c.size == 3 and u.size == 3, f"{what} center and velocity must be 3-vectors")
    scalars = {"angular_velocity": angular_velocity, "swing_amplitude": swing_amplitude,
               "swing_frequency": swing_frequency, "swing_phase": swing_phase}
    for name, value in scalars.items():
        try:
            one = np.ndim(_numbers(what, name, value)) == 0
        except WarpclothError:
            one = False
        if not one:
            raise WarpclothError(f"{what} {name} must be a number, got {value!r:.80}")
    nums = np.array(list(scalars.values()), dtype=np.float64)
    nums = _finite(what, "motion", nums)
    require(nums[2] >= 0, f"{what} swing frequency must be >= 0 Hz, got {swing_frequency!r}")
    return dict(kind="rigid", center=tuple(c), axis=tuple(a / np.linalg.norm(a)), velocity=tuple(u),
                angular_velocity=float(nums[0]), swing_amplitude=float(nums[1]), swing_frequency=float(nums[2]),
                swing_phase=float(nums[3]))


@dataclass(frozen=True, eq=False)
class Track:
    """A keyframed or rigid motion (see the module docstring); subclasses give the key values
    (:attr:`keys`) and make one through their ``keyframes`` and ``rigid`` constructors.

    Attributes (keyword-only):
        kind: ``"keyframes"`` or ``"rigid"``.
        times: key times [s], (K,) float64 (keyframes).
        tangents: Hermite tangents [m/s], shaped like the key values, or None.
        interpolation: one of :data:`INTERPOLATIONS`.
        center, axis, velocity: c [m], the unit rotation axis, u [m/s] (rigid).
        angular_velocity, swing_amplitude, swing_frequency, swing_phase: omega [rad/s], A [rad],
            f [Hz], phi [rad] (rigid).
    """

    _: KW_ONLY
    kind: str  # "keyframes" or "rigid"
    times: np.ndarray | None = None
    tangents: np.ndarray | None = None
    interpolation: str = "linear"
    center: tuple = (0.0, 0.0, 0.0)
    axis: tuple = (0.0, 0.0, 1.0)
    velocity: tuple = (0.0, 0.0, 0.0)
    angular_velocity: float = 0.0
    swing_amplitude: float = 0.0
    swing_frequency: float = 0.0
    swing_phase: float = 0.0

    @property
    def keys(self) -> np.ndarray | None:
        """The key values [m]: (K, 3) offsets from each point's rest position, or (K, P, 3)."""
        raise NotImplementedError

    def moving_until(self) -> float:
        """Time [s] after which the track holds still (the last key; inf for a rigid motion
        that moves, 0 for one that does not)."""
        if self.kind == "keyframes":
            return float(self.times[-1])
        moving = any(self.velocity) or self.angular_velocity or (self.swing_amplitude and self.swing_frequency)
        return math.inf if moving else 0.0

    # -- host evaluation (tests, reports, writers) --------------------------------------------
    def _angle(self, t: float) -> tuple[float, float]:
        """(theta(t) [rad], theta'(t) [rad/s]) of the rigid motion."""
        phase = 2 * math.pi * self.swing_frequency * t + self.swing_phase
        theta = self.angular_velocity * t + self.swing_amplitude * math.sin(phase)
        theta_dot = self.angular_velocity + self.swing_amplitude * 2 * math.pi * self.swing_frequency * math.cos(phase)
        return theta, theta_dot

    def _key_points(self, p0: np.ndarray) -> np.ndarray:
        """(K, P, 3) key positions [m] of points at rest at ``p0`` (P, 3)."""
        keys = self.keys
        return keys[:, None, :] + p0[None] if keys.ndim == 2 else keys

    def _key_tangents(self, p0: np.ndarray) -> np.ndarray:
        """(K, P, 3) key tangents [m/s] (Catmull-Rom: central differences, zero at the ends)."""
        pos = self._key_points(p0)
        if self.interpolation == "hermite":
            if self.tangents.ndim == 2:
                return np.broadcast_to(self.tangents[:, None, :], pos.shape).copy()
            return self.tangents
        tan = np.zeros_like(pos)
        if self.interpolation == "catmull_rom" and pos.shape[0] > 2:
            t = self.times
            tan[1:-1] = (pos[2:] - pos[:-2]) / (t[2:] - t[:-2])[:, None, None]
        return tan

    def _evaluate(self, t: float, p0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(positions (P, 3) [m], velocities (P, 3) [m/s]) at time t of points at rest at
        ``p0`` (P, 3), in float64."""
        if self.kind == "rigid":
            c, a, u = (np.asarray(x) for x in (self.center, self.axis, self.velocity))
            theta, theta_dot = self._angle(t)
            r = p0 - c
            rr = r * math.cos(theta) + np.cross(a, r) * math.sin(theta) + np.outer(r @ a, a) * (1 - math.cos(theta))
            return c + u * t + rr, u + theta_dot * np.cross(a, rr)
        pos, times = self._key_points(p0), self.times
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
        tan = self._key_tangents(p0)
        ma, mb = tan[k] * h, tan[k + 1] * h
        p = (2 * s**3 - 3 * s**2 + 1) * a + (s**3 - 2 * s**2 + s) * ma + (3 * s**2 - 2 * s**3) * b + (s**3 - s**2) * mb
        dp = (6 * s**2 - 6 * s) * (a - b) + (3 * s**2 - 4 * s + 1) * ma + (3 * s**2 - 2 * s) * mb
        return p, dp / h

    # -- the kernels' track arguments (device arrays on the current device) -------------------
    def _rigid_args(self) -> list:
        """c, axis, u and (omega, A, f, phi) as the kernels take them."""
        return [wp.vec3d(*self.center), wp.vec3d(*self.axis), wp.vec3d(*self.velocity),
                wp.vec4d(self.angular_velocity, self.swing_amplitude, self.swing_frequency, self.swing_phase)]

    def _keyframe_args(self, positions: np.ndarray, tangents: np.ndarray) -> list:
        """Key times, key ``positions`` and ``tangents`` (each (K P, 3), float64) and whether
        the interpolation is cubic, as the kernels take them."""
        return [wp.array(self.times, dtype=wp.float64), wp.array(positions, dtype=wp.vec3d),
                wp.array(tangents, dtype=wp.vec3d), int(self.interpolation != "linear")]


__all__ = ["INTERPOLATIONS", "Track", "check_keyframes", "check_rigid"]
