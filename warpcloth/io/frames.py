"""Frame sinks: everything that receives a run's frames (USD, the HTML player, a preview).

:meth:`warpcloth.simulator.Simulator.run` hands every frame to one object through
``write_frame(points, sim_time)``; :class:`FrameSinks` is that object for several writers at
once, each with ``write_frame``, ``close`` and ``abort`` (a writer's temporary file is dropped
on ``abort``, its target left as it was).

:func:`vertex_strain` is the per-vertex spring strain the USD colours and the player's legend
use: for each particle, the largest stretch ``(L - L0) / L0`` of the springs at it (0 when they
are all at rest or compressed).
"""

from __future__ import annotations

import numpy as np


class FrameSinks:
    """Several frame writers behind one ``write_frame``/``close``/``abort``.

    ``close`` closes them in order; if one fails, the others that are not closed yet are
    aborted (their targets left as they were) and the error is raised.
    """

    def __init__(self, writers=()):
        self.writers = [w for w in writers if w is not None]
        self.frames = 0

    def __bool__(self) -> bool:
        return bool(self.writers)

    def write_frame(self, points, sim_time: float | None = None) -> None:
        for w in self.writers:
            w.write_frame(points, sim_time)
        self.frames += 1

    def close(self) -> list:
        """Close every writer; returns their paths (None for a writer without one)."""
        paths = []
        for k, w in enumerate(self.writers):
            try:
                paths.append(w.close())
            except BaseException:
                for other in self.writers[k + 1 :]:
                    other.abort()
                raise
        return paths

    def abort(self) -> None:
        for w in self.writers:
            try:
                w.abort()
            except Exception:  # pragma: no cover - abort is best effort on the way out
                pass

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb):
        if exc_type is None:
            self.close()
        else:
            self.abort()


def spring_arrays(model) -> tuple[np.ndarray, np.ndarray]:
    """The model's springs as (pairs (S, 2) int64, rest lengths (S,) float64) on the host."""
    pairs = np.asarray(model.host.pairs, dtype=np.int64).reshape(-1, 2)
    rest = np.asarray(model.host.rest, dtype=np.float64).reshape(-1)
    return pairs, rest


def vertex_strain(points: np.ndarray, pairs: np.ndarray, rest: np.ndarray) -> np.ndarray:
    """Per particle, the largest stretch ``max(0, (L - L0) / L0)`` of its springs (float32, (N,))."""
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    length = np.linalg.norm(p[pairs[:, 0]] - p[pairs[:, 1]], axis=1)
    strain = np.maximum(0.0, (length - rest) / np.where(rest > 0, rest, 1.0))
    strain[~np.isfinite(strain)] = 0.0
    out = np.zeros(p.shape[0])
    np.maximum.at(out, pairs[:, 0], strain)
    np.maximum.at(out, pairs[:, 1], strain)
    return out.astype(np.float32)


#: Colour ramp of strain, from 0 to the scale: blue, cyan, green, yellow, red (the player's too).
STRAIN_RAMP = np.array(
    [[0.10, 0.25, 0.85], [0.10, 0.75, 0.85], [0.20, 0.75, 0.25], [0.95, 0.85, 0.15], [0.85, 0.12, 0.10]],
    dtype=np.float32,
)


def strain_colors(strain: np.ndarray, scale: float) -> np.ndarray:
    """RGB in [0, 1] (N, 3) of ``strain`` on :data:`STRAIN_RAMP` from 0 to ``scale`` (clamped)."""
    s = np.clip(np.asarray(strain, dtype=np.float64) / max(scale, 1e-12), 0.0, 1.0) * (len(STRAIN_RAMP) - 1)
    k = np.minimum(np.floor(s).astype(np.int64), len(STRAIN_RAMP) - 2)
    f = (s - k)[:, None]
    return ((1 - f) * STRAIN_RAMP[k] + f * STRAIN_RAMP[k + 1]).astype(np.float32)


def nice_scale(value: float) -> float:
    """The smallest of 1, 2, 2.5, 5 x 10^k at or above ``value`` (a legend's end; 0.01 for 0)."""
    if not np.isfinite(value) or value <= 0:
        return 0.01
    exp = np.floor(np.log10(value))
    for m in (1.0, 2.0, 2.5, 5.0, 10.0):
        if m * 10**exp >= value * (1 - 1e-9):
            return float(m * 10**exp)
    return float(10 ** (exp + 1))  # pragma: no cover
