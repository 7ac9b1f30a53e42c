"""Graph colouring of the springs, for parallel Gauss-Seidel constraint projection.

A colouring splits the springs into sets in which no two springs share a particle, so the
distance constraints of one set can be projected in parallel with the same result as projecting
them one after another (see :mod:`warpcloth.kernels.constraints`).

On the Provot grid the colouring is read off the topology: a spring is a step (dr, dc) from
particle (r, c), and two springs of the same direction share a particle only when one starts
where the other ends, a step further along the line; so direction plus the parity of
``t // s`` (t = r, or c for horizontal springs; s = max(|dr|, |dc|) the step length) gives
independent sets: two colours per spring direction, 12 for a Provot grid, 16 with Choi-Ko bend
springs. A model whose springs do not fit that pattern falls back to greedy colouring. Every
colouring is verified before use.

Particles (Vertex Block Descent) of a grid take (r mod 3, c mod 3); of any other mesh, Warp's
``wp.utils.graph_coloring_assign`` (MCS), with the greedy colouring as the fallback (an older
Warp, or more colours than greedy's bound, max degree + 1): as few colours as greedy, and much
faster. Springs keep the greedy edge colouring, which beat MCS on the springs' line graph in time
and colours (both measured: docs/solvers.md, "Graph colouring").
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import warp as wp

from warpcloth.errors import WarpclothError


@dataclass(frozen=True)
class Coloring:
    """Items (springs or particles) sorted by colour.

    Attributes:
        colors: colour of each item, shape (item_count,).
        order: item ids sorted by colour, shape (item_count,), int32; colour k is
            ``order[starts[k] : starts[k] + counts[k]]``.
        starts: first position of each (non-empty) colour in :attr:`order`.
        counts: number of items of each (non-empty) colour.
    """

    colors: np.ndarray
    order: np.ndarray
    starts: tuple[int, ...]
    counts: tuple[int, ...]

    @classmethod
    def from_colors(cls, colors) -> Coloring:
        """Sort items by their colours (stable: within a colour, items keep their order)."""
        colors = np.asarray(colors, dtype=np.int32)
        order = np.argsort(colors, kind="stable").astype(np.int32)
        counts = np.bincount(colors) if colors.size else np.zeros(0, dtype=np.int64)
        starts = np.concatenate([[0], np.cumsum(counts)[:-1]]) if counts.size else counts
        keep = counts > 0
        return cls(
            colors=colors,
            order=order,
            starts=tuple(int(v) for v in starts[keep]),
            counts=tuple(int(v) for v in counts[keep]),
        )

    @property
    def color_count(self) -> int:
        return len(self.counts)


#: Springs sorted by colour (no two springs of one colour share a particle).
SpringColoring = Coloring
#: Particles sorted by colour: no two particles of one colour share a spring, so their local
#: solves are independent (Chen et al. 2024, section 4).
VertexColoring = Coloring


def grid_spring_colors(pairs: np.ndarray, cols: int) -> np.ndarray:
    """Colours by (direction, parity along the direction) for springs of a grid with ``cols``
    particles per row (particle [r, c] = r * cols + c). Valid only for grid springs: check it."""
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    r, c = pairs // cols, pairs % cols
    dr, dc = r[:, 1] - r[:, 0], c[:, 1] - c[:, 0]
    # orient every spring so that (dr, dc) > (0, 0) lexicographically; start at its first end
    flip = (dr < 0) | ((dr == 0) & (dc < 0))
    r0 = np.where(flip, r[:, 1], r[:, 0])
    c0 = np.where(flip, c[:, 1], c[:, 0])
    dr, dc = np.where(flip, -dr, dr), np.where(flip, -dc, dc)
    step = np.maximum(np.maximum(np.abs(dr), np.abs(dc)), 1)
    t = np.where(dr != 0, r0, c0)
    parity = (t // step) % 2
    keys = np.stack([dr, dc, parity], axis=1)
    _, colors = np.unique(keys, axis=0, return_inverse=True)
    return colors.reshape(-1).astype(np.int32)


def greedy_spring_colors(pairs: np.ndarray, particle_count: int) -> np.ndarray:
    """Greedy edge colouring: each spring takes the smallest colour unused at both its ends."""
    used = [0] * particle_count  # bit k set: colour k already touches the particle
    colors = np.empty(len(pairs), dtype=np.int32)
    for s, (i, j) in enumerate(np.asarray(pairs, dtype=np.int64)):
        taken = used[i] | used[j]
        k = (~taken & (taken + 1)).bit_length() - 1
        colors[s] = k
        used[i] |= 1 << k
        used[j] |= 1 << k
    return colors


def is_valid_coloring(pairs: np.ndarray, colors: np.ndarray, particle_count: int) -> bool:
    """True when no two springs of one colour share a particle (and no spring joins a particle
    to itself)."""
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    if pairs.shape[0] == 0:
        return True
    keys = np.asarray(colors, dtype=np.int64)[:, None] * particle_count + pairs
    return np.unique(keys).size == keys.size


def color_springs(pairs: np.ndarray, particle_count: int, cols: int | None = None) -> SpringColoring:
    """Colour the springs (grid pattern when it is valid, else greedy) and sort them by colour.

    Raises:
        WarpclothError: a spring joins a particle to itself (it cannot be coloured).
    """
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    if np.any(pairs[:, 0] == pairs[:, 1]):
        s = int(np.flatnonzero(pairs[:, 0] == pairs[:, 1])[0])
        raise WarpclothError(
            f"spring {s} joins particle {int(pairs[s, 0])} to itself; a distance constraint needs two particles"
        )
    colors = grid_spring_colors(pairs, cols) if cols else None
    if colors is None or not is_valid_coloring(pairs, colors, particle_count):
        colors = greedy_spring_colors(pairs, particle_count)
    if not is_valid_coloring(pairs, colors, particle_count):  # pragma: no cover - greedy is always valid
        raise RuntimeError("spring colouring is invalid")
    return Coloring.from_colors(colors)


# -- vertex colouring (Vertex Block Descent) ------------------------------------------------------
def grid_vertex_colors(particle_count: int, cols: int) -> np.ndarray:
    """Colour (r mod 3, c mod 3) of particle [r, c] of a grid with ``cols`` particles per row: a
    Provot or Choi-Ko spring steps by at most 2 along each axis and never by (0, 0) mod 3, so its
    ends differ in colour (9 colours). Valid only for grid springs: check it."""
    index = np.arange(particle_count, dtype=np.int64)
    return (3 * ((index // cols) % 3) + (index % cols) % 3).astype(np.int32)


def greedy_vertex_colors(pairs: np.ndarray, particle_count: int) -> np.ndarray:
    """Greedy vertex colouring: each particle takes the smallest colour unused by its spring
    neighbours that already have one."""
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    neighbours = [[] for _ in range(particle_count)]
    for i, j in pairs:
        neighbours[i].append(j)
        neighbours[j].append(i)
    colors = np.full(particle_count, -1, dtype=np.int32)
    for i in range(particle_count):
        taken = {int(colors[j]) for j in neighbours[i] if colors[j] >= 0}
        k = 0
        while k in taken:
            k += 1
        colors[i] = k
    return colors


def warp_vertex_colors(pairs: np.ndarray, particle_count: int) -> np.ndarray | None:
    """Warp's MCS vertex colouring (``wp.utils.graph_coloring_assign``, on the CPU), or None where
    this Warp has none."""
    assign = getattr(getattr(wp, "utils", None), "graph_coloring_assign", None)
    if assign is None or particle_count == 0:
        return None
    colors = wp.zeros(particle_count, dtype=wp.int32, device="cpu")
    edges = np.ascontiguousarray(np.asarray(pairs, dtype=np.int32).reshape(-1, 2))
    if edges.size:
        assign(wp.array(edges, dtype=wp.int32, device="cpu"), colors)
    return colors.numpy().astype(np.int32)


def is_valid_vertex_coloring(pairs: np.ndarray, colors: np.ndarray) -> bool:
    """True when the two ends of every spring have different colours."""
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    colors = np.asarray(colors)
    return bool(np.all(colors[pairs[:, 0]] != colors[pairs[:, 1]])) if pairs.size else True


def color_vertices(pairs: np.ndarray, particle_count: int, cols: int | None = None) -> VertexColoring:
    """Colour the particles (grid pattern when it is valid, else Warp's MCS, else greedy) and sort
    them by colour.

    Raises:
        WarpclothError: a spring joins a particle to itself (it cannot be coloured).
    """
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    if np.any(pairs[:, 0] == pairs[:, 1]):
        s = int(np.flatnonzero(pairs[:, 0] == pairs[:, 1])[0])
        raise WarpclothError(f"spring {s} joins particle {int(pairs[s, 0])} to itself; it cannot be coloured")
    colors = grid_vertex_colors(particle_count, cols) if cols else None
    if colors is None or not is_valid_vertex_coloring(pairs, colors):
        colors = warp_vertex_colors(pairs, particle_count)
        degree = np.bincount(pairs.reshape(-1), minlength=particle_count).max(initial=0)
        if colors is None or not is_valid_vertex_coloring(pairs, colors) or colors.max(initial=0) > degree:
            colors = greedy_vertex_colors(pairs, particle_count)  # greedy uses at most max degree + 1 colours
    if not is_valid_vertex_coloring(pairs, colors):  # pragma: no cover - greedy is always valid
        raise RuntimeError("vertex colouring is invalid")
    return Coloring.from_colors(colors)


def color_model(pairs: np.ndarray, model, vertices: bool) -> Coloring:
    """The colouring of a model's ``pairs`` (its springs, and for vbd its hinges' pairs): of the
    particles (``vertices``, :func:`color_vertices`) or of the pairs (:func:`color_springs`), with the
    model's ``cols`` for its grid pattern. A model of several cloths (``model.pieces``) is coloured
    piece by piece, each with its own grid's columns, and colour k of every piece joined into colour k:
    no pair joins two pieces, so each piece is swept in the same order as alone (the same results) and a
    grid piece keeps its grid colouring."""
    color = color_vertices if vertices else color_springs
    pieces = getattr(model, "pieces", ())
    if len(pieces) < 2:
        return color(pairs, model.particle_count, model.cols)
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    offsets = np.array([p.particle_offset for p in pieces], dtype=np.int64)
    owner = np.searchsorted(offsets, pairs[:, 0], side="right") - 1
    colors = np.zeros(model.particle_count if vertices else len(pairs), dtype=np.int32)
    for k, piece in enumerate(pieces):
        mine = owner == k
        local = color(pairs[mine] - piece.particle_offset, piece.particle_count, piece.cols).colors
        if vertices:
            colors[piece.particles] = local
        else:
            colors[mine] = local
    return Coloring.from_colors(colors)


def particle_adjacency(pairs: np.ndarray, particle_count: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each particle's springs and neighbours, grouped by particle (CSR): ``(offsets, spring,
    other)``, particle i's entries being ``offsets[i]:offsets[i + 1]``; int32 arrays."""
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    ends = np.concatenate([pairs[:, 0], pairs[:, 1]])
    others = np.concatenate([pairs[:, 1], pairs[:, 0]])
    springs = np.concatenate([np.arange(len(pairs)), np.arange(len(pairs))])
    order = np.argsort(ends, kind="stable")
    offsets = np.zeros(particle_count + 1, dtype=np.int32)
    offsets[1:] = np.cumsum(np.bincount(ends, minlength=particle_count))
    return offsets, springs[order].astype(np.int32), others[order].astype(np.int32)
