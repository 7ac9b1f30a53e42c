"""Tracks: where something kinematic is at time t, as keyframes or a rigid motion.

:class:`Track` is what a pin track (:class:`~warpcloth.sim.pins.PinTrack`) and a collider's pose
track (:class:`~warpcloth.sim.colliders.ColliderTrack`) share:

- ``"keyframes"``: K increasing key times [s] and key values (positions or offsets [m]),
  interpolated linearly, by Catmull-Rom (tangents (p_{k+1} - p_{k-1}) / (t_{k+1} - t_{k-1}), zero
  at the first and last key) or by cubic Hermite with given tangents [m/s]; held still before the
  first key and after the last;
- ``"rigid"``: y -> c + u t + R(axis, theta(t)) (y - c), theta(t) = omega t + A sin(2 pi f t + phi);
- ``"driven"``: set from the host each frame (:class:`FrameDrive`): a game's or a tool's own loop
  says where the pins or the collider are at the end of the next frame, and the frame's steps
  interpolate to it. The values go into device arrays that a captured frame already reads, so
  driving costs a few small copies per frame and never a new capture.

The step evaluates tracks on the device (:mod:`warpcloth.kernels.pins`,
:mod:`warpcloth.kernels.collide`); this module holds their description, its validation, the host
evaluation (tests, reports, writers), :meth:`Track.moving_until` and the kernels' track arguments.
The subclasses add what differs: the pinned particles, or a collider's pose.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import KW_ONLY, dataclass

import numpy as np
import warp as wp

from warpcloth.errors import WarpclothError, require

INTERPOLATIONS = ("linear", "catmull_rom", "hermite")


#: The largest |coordinate| [m] (or |velocity| [m/s]) a driven target may have: as a mesh's vertices
#: (:data:`warpcloth.sim.mesh.MAX_COORDINATE`), the kernels square distances in float32.
MAX_TARGET = 1e18


def _finite(what: str, name: str, a: np.ndarray) -> np.ndarray:
    if not np.all(np.isfinite(a)):
        raise WarpclothError(f"{what} {name} must be finite numbers, got {float(a[~np.isfinite(a)][0])!r}")
    return a


def _in_range(what: str, name: str, a: np.ndarray, unit: str) -> np.ndarray:
    """``a`` if every entry is finite and within +-:data:`MAX_TARGET`, else one line naming the first."""
    _finite(what, name, a)
    far = np.abs(a) > MAX_TARGET
    if np.any(far):
        raise WarpclothError(
            f"{what} {name} must be within +-{MAX_TARGET:.0e} {unit} (float32 must hold squared distances), "
            f"got {float(a[far][0])!r}"
        )
    return a


def check_target(what: str, name: str, value, unit: str = "m") -> np.ndarray:
    """A driven target (positions [m], an offset [m] or velocities [m/s]) as a float64 array: numbers
    (a sequence, a NumPy array or a ``wp.array``), finite, within +-:data:`MAX_TARGET`; else one
    :class:`WarpclothError` naming ``what`` and ``name``."""
    return _in_range(what, name, _numbers(what, name, value), unit)


def _numbers(what: str, name: str, value) -> np.ndarray:
    """``value`` (a sequence, a NumPy array or a ``wp.array``) as a float64 array, or a
    :class:`WarpclothError` (text, booleans, complex numbers, tables, generators and ragged lists
    are not numbers)."""

    def bad():
        shown = " ".join(repr(value).split())  # an array's repr spans lines: the message is one
        return WarpclothError(f"{what} {name} must be numbers, got {shown:.80}")

    if isinstance(value, wp.array):
        value = value.numpy()
    if isinstance(value, np.ndarray) and value.dtype.kind in "iuf":  # the fast path of a frame's targets
        return np.asarray(value, dtype=np.float64)
    if isinstance(value, (str, bytes, bool, dict, set, frozenset)) or value is None or not hasattr(value, "__len__"):
        if not isinstance(value, numbers.Real) or isinstance(value, bool):
            raise bad()
    try:
        items = np.asarray(value, dtype=object).ravel()
    except (TypeError, ValueError):
        raise bad() from None
    if any(isinstance(x, (bool, np.bool_, str, bytes, complex, np.complexfloating)) for x in items):
        raise bad()
    try:
        a = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        raise bad() from None
    return a


def check_keyframes(what: str, times, positions, interpolation: str, tangents, points: int):
    """Checked keyframes (times (K,) float64, values (K, 3) or (K, P, 3) with P = ``points``,
    tangents shaped like the values or None); errors start with ``what`` ("pin track")."""
    require(
        interpolation in INTERPOLATIONS,
        f"{what} interpolation must be one of {', '.join(INTERPOLATIONS)}, got {interpolation!r}",
    )
    t = _finite(what, "times", _numbers(what, "times", times).reshape(-1))
    require(t.size >= 1, f"{what} needs at least one keyframe")
    bad = np.flatnonzero(np.diff(t) <= 0)
    if bad.size:
        k = int(bad[0])
        raise WarpclothError(
            f"{what} keyframes out of order: time {float(t[k + 1])!r} s (key {k + 1}) is not after "
            f"{float(t[k])!r} s (key {k}); key times must increase"
        )
    v = _finite(what, "positions", _numbers(what, "positions", positions))
    shapes = [(t.size, 3), (t.size, points, 3)]
    require(
        v.shape in shapes, f"{what} positions must have shape (K, 3) offsets or (K, P, 3) = {shapes[1]}, got {v.shape}"
    )
    tan = None
    if interpolation == "hermite":
        require(tangents is not None, f"{what} interpolation 'hermite' needs tangents (shaped like positions) [m/s]")
        tan = _finite(what, "tangents", _numbers(what, "tangents", tangents))
        require(tan.shape == v.shape, f"{what} tangents must have the shape of positions {v.shape}, got {tan.shape}")
    elif tangents is not None:
        raise WarpclothError(f"{what} tangents apply to interpolation 'hermite' only, not {interpolation!r}")
    return t, v, tan


def check_rigid(
    what: str, center, axis, angular_velocity, swing_amplitude, swing_frequency, swing_phase, velocity
) -> dict:
    """The checked fields of a rigid motion (``kind="rigid"``, centre, unit axis, ...) for a
    :class:`Track` subclass's constructor; errors start with ``what``."""
    a = _finite(what, "axis", _numbers(what, "axis", axis).reshape(-1))
    require(a.size == 3 and np.linalg.norm(a) > 0, f"{what} axis must be a non-zero 3-vector, got {axis!r:.80}")
    c = _finite(what, "center", _numbers(what, "center", center).reshape(-1))
    u = _finite(what, "velocity", _numbers(what, "velocity", velocity).reshape(-1))
    require(c.size == 3 and u.size == 3, f"{what} center and velocity must be 3-vectors")
    scalars = {
        "angular_velocity": angular_velocity,
        "swing_amplitude": swing_amplitude,
        "swing_frequency": swing_frequency,
        "swing_phase": swing_phase,
    }
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
    return dict(
        kind="rigid",
        center=tuple(c),
        axis=tuple(a / np.linalg.norm(a)),
        velocity=tuple(u),
        angular_velocity=float(nums[0]),
        swing_amplitude=float(nums[1]),
        swing_frequency=float(nums[2]),
        swing_phase=float(nums[3]),
    )


@dataclass(frozen=True, eq=False)
class Track:
    """A keyframed or rigid motion (see the module docstring); subclasses give the key values
    (:attr:`keys`) and make one through their ``keyframes`` and ``rigid`` constructors.

    Attributes (keyword-only):
        kind: ``"keyframes"``, ``"rigid"`` or ``"driven"``.
        times: key times [s], (K,) float64 (keyframes).
        tangents: Hermite tangents [m/s], shaped like the key values, or None.
        interpolation: one of :data:`INTERPOLATIONS`.
        center, axis, velocity: c [m], the unit rotation axis, u [m/s] (rigid).
        angular_velocity, swing_amplitude, swing_frequency, swing_phase: omega [rad/s], A [rad],
            f [Hz], phi [rad] (rigid).
        drive: the :class:`FrameDrive` of a driven track.
    """

    _: KW_ONLY
    kind: str  # "keyframes", "rigid" or "driven"
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
    drive: FrameDrive | None = None  # kind "driven": the host side (targets, device arrays)

    @property
    def keys(self) -> np.ndarray | None:
        """The key values [m]: (K, 3) offsets from each point's rest position, or (K, P, 3)."""
        raise NotImplementedError

    def moving_until(self) -> float:
        """Time [s] after which the track holds still (the last key; inf for a rigid motion
        that moves, 0 for one that does not)."""
        if self.kind == "keyframes":
            return float(self.times[-1])
        if self.kind == "driven":  # the host may move it at any frame
            return math.inf
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
        if self.kind == "driven":
            return self.drive.evaluate(t)
        pos = self._key_points(p0)
        return interpolate(self.times, pos, self._key_tangents(p0) if self.interpolation != "linear" else None, t)

    # -- the kernels' track arguments (device arrays on the current device) -------------------
    def _rigid_args(self) -> list:
        """c, axis, u and (omega, A, f, phi) as the kernels take them."""
        return [
            wp.vec3d(*self.center),
            wp.vec3d(*self.axis),
            wp.vec3d(*self.velocity),
            wp.vec4d(self.angular_velocity, self.swing_amplitude, self.swing_frequency, self.swing_phase),
        ]

    def _keyframe_args(self, positions: np.ndarray, tangents: np.ndarray) -> list:
        """Key times, key ``positions`` and ``tangents`` (each (K P, 3), float64) and whether
        the interpolation is cubic, as the kernels take them."""
        return [
            wp.array(self.times, dtype=wp.float64),
            wp.array(positions, dtype=wp.vec3d),
            wp.array(tangents, dtype=wp.vec3d),
            int(self.interpolation != "linear"),
        ]


def interpolate(
    times: np.ndarray, pos: np.ndarray, tangents: np.ndarray | None, t: float
) -> tuple[np.ndarray, np.ndarray]:
    """(positions (P, 3), velocities (P, 3)) at time t of keys ``pos`` (K, P, 3) at ``times`` (K,):
    linear (``tangents`` None) or cubic Hermite with ``tangents`` (K, P, 3) [m/s]; held before the
    first key and after the last (float64, on the host: the kernels' formulas)."""
    if t <= times[0]:
        return pos[0].copy(), np.zeros_like(pos[0])
    if t >= times[-1]:
        return pos[-1].copy(), np.zeros_like(pos[-1])
    k = int(np.searchsorted(times, t, side="right") - 1)
    h = times[k + 1] - times[k]
    s = (t - times[k]) / h
    a, b = pos[k], pos[k + 1]
    if tangents is None:
        return a + s * (b - a), (b - a) / h
    ma, mb = tangents[k] * h, tangents[k + 1] * h
    p = (2 * s**3 - 3 * s**2 + 1) * a + (s**3 - 2 * s**2 + s) * ma + (3 * s**2 - 2 * s**3) * b + (s**3 - s**2) * mb
    dp = (6 * s**2 - 6 * s) * (a - b) + (3 * s**2 - 4 * s + 1) * ma + (3 * s**2 - 2 * s) * mb
    return p, dp / h


class HostWrite:
    """A device array that the host rewrites each frame, in place: on the CPU through a NumPy view
    of the array itself, on a GPU through a pinned host copy and one asynchronous ``wp.copy``
    (no allocation per frame, so the captured frame keeps reading the same array)."""

    def __init__(self, values: np.ndarray, dtype, device):
        device = wp.get_device(device)
        self.array = wp.array(values, dtype=dtype, device=device)
        self._staging = None if device.is_cpu else wp.array(values, dtype=dtype, device="cpu", pinned=True)
        self._view = (self.array if device.is_cpu else self._staging).numpy()

    def write(self, values: np.ndarray) -> None:
        self._view[...] = values.reshape(self._view.shape)
        if self._staging is not None:
            wp.copy(self.array, self._staging)


class FrameDrive:
    """The host side of a ``"driven"`` track: P points (pinned particles, or a collider's offset)
    that the host moves each frame with :meth:`set`, and the device arrays that the step reads.

    A frame is one :meth:`Simulator.simulate <warpcloth.simulator.Simulator.simulate>` call
    (or one :meth:`~warpcloth.simulator.Simulator.step`). A target set before it is reached at
    its end: the steps in between follow the keys ``(t0 - 1, t0, t1, t1 + 1)`` with positions
    ``(p0 - v, p0, p1, p1 + v)`` (``p0`` where the points are, ``p1`` the target, t0 and t1 the
    frame's start and end on the device clock), interpolated by the pin and collider kernels as
    keyframes: ``"linear"`` (v = (p1 - p0) / (t1 - t0), the same arithmetic as a
    ``keyframes`` track through the same points, so a driven run equals that track's run) or
    ``"hermite"`` (cubic, with the velocities given to :meth:`set` as tangents at t0 and t1).
    Without a new target a frame holds the points at their last one, at rest.
    """

    def __init__(self, what: str, points: int, interpolation: str = "linear"):
        require(
            interpolation in ("linear", "hermite"),
            f"{what} interpolation must be 'linear' or 'hermite', got {interpolation!r}",
        )
        self.what = what
        self.points = int(points)
        self.interpolation = interpolation
        self.position: np.ndarray | None = None  # (P, 3) where the points are at the end of the last frame [m]
        self.velocity = np.zeros((self.points, 3))  # (P, 3) their velocity there [m/s] (hermite; 0 when held)
        self._pending: tuple[np.ndarray, np.ndarray] | None = None
        self._moving = False
        self._keys = None  # host copy of the last frame's keys: (times (4,), positions (4, P, 3), tangents or None)
        self.values = self.tangents = None  # the device arrays (bind)

    def start(self, position) -> None:
        """Where the points are before the first target (a model's rest positions, a collider's 0)."""
        if self.position is None:
            self.position = np.array(position, dtype=np.float64).reshape(self.points, 3)

    @property
    def pending(self) -> bool:
        """Whether a target waits for the next frame."""
        return self._pending is not None

    def set(self, positions, velocities=None) -> None:
        """Where the points are at the end of the next frame: ``positions`` (P, 3) [m] (a 3-vector
        for one point) and, for ``"hermite"``, their ``velocities`` (P, 3) [m/s] there."""
        p = check_target(self.what, "target positions", positions, "m")
        require(
            p.size == 3 * self.points and p.shape in ((self.points, 3), (3,)),
            f"{self.what} target must have shape ({self.points}, 3), got {p.shape}",
        )
        if self.interpolation == "hermite":
            require(velocities is not None, f"{self.what} is 'hermite': give the targets' velocities too [m/s]")
        v = np.zeros((self.points, 3))
        if velocities is not None:
            require(
                self.interpolation == "hermite",
                f"{self.what} velocities need interpolation 'hermite' (linear moves at (p1 - p0) / frame time)",
            )
            v = check_target(self.what, "velocities", velocities, "m/s")
            require(
                v.size == 3 * self.points, f"{self.what} velocities must have shape ({self.points}, 3), got {v.shape}"
            )
        self._pending = (p.reshape(self.points, 3), v.reshape(self.points, 3))

    def bind(self, device) -> list:
        """Allocate the device arrays (holding the points where they are); returns the keyframe
        kernels' arguments after the key times: values, tangents, whether cubic."""
        hold = np.broadcast_to(self.position[None], (4, self.points, 3)).reshape(-1, 3)
        self._values = HostWrite(hold, wp.vec3d, device)
        self._tangents = HostWrite(np.zeros_like(hold), wp.vec3d, device)
        self.values, self.tangents = self._values.array, self._tangents.array
        self._moving = False
        return [self.values, self.tangents, int(self.interpolation != "linear")]

    def upload(self, t0: float, t1: float) -> bool:
        """Write the next frame's keys into the device arrays (a target set, or a hold after a
        moving frame; ``t0``, ``t1`` the frame's host times, for :meth:`evaluate`). Returns
        whether anything was written."""
        if self._pending is None:
            if not self._moving:
                return False
            p = self.position
            keys = np.broadcast_to(p[None], (4, self.points, 3))
            self.velocity = np.zeros_like(p)
            self._write(keys, np.zeros_like(keys), t0, t1, moving=False)
            return True
        (p1, v1), self._pending = self._pending, None
        p0, v0 = self.position, self.velocity
        if self.interpolation == "linear":
            v = (p1 - p0) / max(t1 - t0, 1e-300)
            v0 = v1 = v
        keys = np.stack([p0 - v0, p0, p1, p1 + v1])
        tangents = np.stack([v0, v0, v1, v1]) if self.interpolation == "hermite" else np.zeros_like(keys)
        self.position, self.velocity = p1, v1 if self.interpolation == "hermite" else np.zeros_like(p1)
        self._write(keys, tangents, t0, t1, moving=True)
        return True

    def _write(self, keys, tangents, t0, t1, moving: bool) -> None:
        self._values.write(keys)
        if self.interpolation == "hermite":
            self._tangents.write(tangents)
        self._keys = (np.array([t0 - 1.0, t0, t1, t1 + 1.0]), np.array(keys), np.array(tangents))
        self._moving = moving

    def evaluate(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """(positions (P, 3), velocities (P, 3)) at time t [s] on the host, within the last frame
        written (writers and reports; before any frame: where the points started, at rest)."""
        if self._keys is None:
            p = self.position if self.position is not None else np.zeros((self.points, 3))
            return p.copy(), np.zeros_like(p)
        times, keys, tangents = self._keys
        return interpolate(times, keys, tangents if self.interpolation == "hermite" else None, float(t))


__all__ = [
    "INTERPOLATIONS",
    "MAX_TARGET",
    "FrameDrive",
    "HostWrite",
    "Track",
    "check_keyframes",
    "check_rigid",
    "check_target",
    "interpolate",
]
