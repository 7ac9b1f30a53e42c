"""Hinges for dihedral bending (discrete shells; Grinspun et al. 2003, Bridson et al. 2003): topology,
rest geometry and per-hinge stiffness, built on the host in vectorised NumPy (float64).

A hinge is an interior edge x0-x1 with its two opposite vertices: x2 in triangle A = (x0, x1, x2)
and x3 in triangle B = (x1, x0, x3), both in the mesh's orientation (so a flat, consistently
oriented sheet has angle 0). Its energy (material-design.md section 2.1) is

    E_e = 1/2 k_e (theta - theta0)^2,   k_e = w_e B(m_e) |e|^2 / (A_A + A_B)   [N m = J / rad^2],

with rest values for |e|, A_A, A_B, theta0; w_e = 1 (mesh hinges) or 1/2 (each of the grid's two
diagonal choices). This is discrete shells' 3 k_b |e|^2 / (A_A + A_B) with **k_b = B / 3**: a flat
grid or equilateral mesh wrapped isometrically on a cylinder of curvature kappa stores B kappa^2 / 2
per unit area. B(m) = B_warp m_w^2 + B_weft m_f^2 [N m] is the rigidity for curvature along m, the
unit in-plane vector across the edge (perpendicular to it), (m_w, m_f) its components along the
warp and weft: a strip cut along warp bends over hinges whose edges run along weft.

The angle and its gradient (material-design.md section 2.2; :mod:`warpcloth.kernels.bending` has
the same formulas in float32):

    e = x1 - x0,  nA = e x (x2 - x0),  nB = (x0 - x1) x (x3 - x1),
    theta = atan2((nA x nB) . e / |e|, nA . nB)                        in (-pi, pi],
    g2 = -nA / (|nA| hA),  g3 = -nB / (|nB| hB),  hA = |nA| / |e|,  hB = |nB| / |e|,
    g0 = -(1 - tA) g2 - (1 - tB) g3,  g1 = -tA g2 - tB g3,  tA = (x2 - x0).e / |e|^2, tB likewise.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import warp as wp

from warpcloth.errors import WarpclothError
from warpcloth.sim.coloring import Coloring

#: Degenerate-hinge guards, as in the kernels: an edge shorter than this [m] or a triangle whose
#: |n| = 2 area is below AREA_EPS [m^2] gives no force and no stiffness.
EDGE_EPS = 1.0e-9
AREA_EPS = 1.0e-12
#: The heights in the gradient are clamped from below at this fraction of |e| (ARCSim's ``distance``).
HEIGHT_FLOOR = 1.0e-3
#: The builders' default bending rigidity B [N m]: the cotton preset's (warpcloth.sim.material, docs/materials.md).
DEFAULT_BEND_RIGIDITY = 31.4e-6
#: The builders' default hinge damping ratio (as the springs' default, warpcloth.sim.model.DEFAULT_DAMPING_RATIO):
#: each hinge's own mode gets this ratio, so refining the mesh does not make explicit steps unstable.
DEFAULT_BEND_DAMPING_RATIO = 0.05


@dataclass(frozen=True)
class Hinges:
    """The hinges of a cloth, host arrays (float64 geometry).

    Attributes:
        indices: (x0, x1, x2, x3) per hinge, shape (hinge_count, 4), int32 (module docstring order).
        rest_angle: theta0 [rad], shape (hinge_count,), in (-pi, pi].
        rest_length: |e| at rest [m], shape (hinge_count,).
        rest_area: (A_A, A_B) at rest [m^2], shape (hinge_count, 2).
        weight: w_e (1, or 1/2 for each of a grid's two diagonal choices), shape (hinge_count,).
        rigidity: B(m_e) [N m], shape (hinge_count,).
        stiffness: k_e = w_e B(m_e) |e|^2 / (A_A + A_B) [N m / rad^2], shape (hinge_count,);
            0 for a hinge degenerate at rest.
        damping: kd_e = beta k_e [N m s / rad^2] (Rayleigh, beta = :func:`bend_damping_time`), shape (hinge_count,).
    """

    indices: np.ndarray
    rest_angle: np.ndarray
    rest_length: np.ndarray
    rest_area: np.ndarray
    weight: np.ndarray
    rigidity: np.ndarray
    stiffness: np.ndarray
    damping: np.ndarray

    @property
    def hinge_count(self) -> int:
        return int(self.indices.shape[0])

    def to_device(self, device=None) -> HingeArrays:
        """The arrays the kernels read, float32 on ``device``."""
        return HingeArrays(
            hinge_indices=wp.array(self.indices.astype(np.int32), dtype=wp.vec4i, device=device),
            hinge_rest_angle=wp.array(self.rest_angle.astype(np.float32), dtype=float, device=device),
            hinge_stiffness=wp.array(self.stiffness.astype(np.float32), dtype=float, device=device),
            hinge_damping=wp.array(self.damping.astype(np.float32), dtype=float, device=device),
        )


@dataclass(frozen=True)
class HingeArrays:
    """Device arrays of the hinges (what :mod:`warpcloth.kernels.bending` reads).

    Attributes:
        hinge_indices: (x0, x1, x2, x3), shape (hinge_count,), wp.vec4i.
        hinge_rest_angle: theta0 [rad], shape (hinge_count,).
        hinge_stiffness: k_e [N m / rad^2], shape (hinge_count,).
        hinge_damping: kd_e [N m s / rad^2], shape (hinge_count,).
    """

    hinge_indices: wp.array
    hinge_rest_angle: wp.array
    hinge_stiffness: wp.array
    hinge_damping: wp.array

    @property
    def hinge_count(self) -> int:
        return int(self.hinge_indices.shape[0])


# -- topology -------------------------------------------------------------------------------------
def triangle_hinges(triangles) -> np.ndarray:
    """The hinges of a triangle mesh: one per edge shared by two triangles, shape (H, 4), int32.

    x0 -> x1 is the edge as directed in the first triangle (lowest triangle index) that holds it,
    x2 that triangle's third vertex, x3 the other triangle's. Boundary edges have no hinge.

    Raises:
        WarpclothError: an edge is shared by more than two triangles (non-manifold).
    """
    tris = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    if tris.shape[0] == 0:
        return np.zeros((0, 4), dtype=np.int32)
    # directed edges (a, b) with opposite vertex o, per triangle (a, b, c): (a, b; c), (b, c; a), (c, a; b)
    a = tris.reshape(-1)
    b = tris[:, [1, 2, 0]].reshape(-1)
    o = tris[:, [2, 0, 1]].reshape(-1)
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    key = lo * (int(tris.max()) + 1) + hi
    order = np.argsort(key, kind="stable")  # stable: the first of a pair is the lower triangle index
    key_s = key[order]
    counts = np.bincount(np.unique(key_s, return_inverse=True)[1])
    if counts.size and counts.max() > 2:
        raise WarpclothError(
            f"{int(np.sum(counts > 2))} edge(s) are shared by more than two triangles; hinges need a manifold mesh"
        )
    pair = np.flatnonzero(key_s[1:] == key_s[:-1])  # positions p with order[p], order[p + 1] one edge
    first, second = order[pair], order[pair + 1]
    return np.stack([a[first], b[first], o[first], o[second]], axis=1).astype(np.int32)


def grid_hinge_indices(rows: int, cols: int) -> tuple[np.ndarray, np.ndarray]:
    """Symmetrised grid hinges (material-design.md section 2.1): every interior structural edge of a
    rows x cols grid (particle [r, c] = r * cols + c), once per diagonal choice of its two cells.

    x-edge (r, c)-(r, c+1), r in 1..rows-2: x2, x3 = (r-1, c+1), (r+1, c) and (r-1, c), (r+1, c+1);
    y-edge (r, c)-(r+1, c), c in 1..cols-2: x2, x3 = (r, c+1), (r+1, c-1) and (r+1, c+1), (r, c-1).
    The first choice of each is the hinge :func:`triangle_hinges` finds on ``grid_triangles``.
    Count: 2 [(rows-2)(cols-1) + (rows-1)(cols-2)].

    Returns:
        (indices (H, 4) int32, axis (H,) int8: 0 for an x-edge (along the columns), 1 for a y-edge).
    """
    idx = np.arange(rows * cols, dtype=np.int64).reshape(rows, cols)
    parts, axes = [], []
    if rows >= 3 and cols >= 2:
        r = slice(1, rows - 1)
        x0, x1 = idx[r, :-1], idx[r, 1:]
        for x2, x3 in ((idx[:-2, 1:], idx[2:, :-1]), (idx[:-2, :-1], idx[2:, 1:])):
            parts.append(np.stack([x0.ravel(), x1.ravel(), x2.ravel(), x3.ravel()], axis=1))
            axes.append(np.zeros(x0.size, dtype=np.int8))
    if cols >= 3 and rows >= 2:
        c = slice(1, cols - 1)
        x0, x1 = idx[:-1, c], idx[1:, c]
        for x2, x3 in ((idx[:-1, 2:], idx[1:, :-2]), (idx[1:, 2:], idx[:-1, :-2])):
            parts.append(np.stack([x0.ravel(), x1.ravel(), x2.ravel(), x3.ravel()], axis=1))
            axes.append(np.ones(x0.size, dtype=np.int8))
    if not parts:
        return np.zeros((0, 4), dtype=np.int32), np.zeros(0, dtype=np.int8)
    return np.concatenate(parts).astype(np.int32), np.concatenate(axes)


# -- geometry (float64 mirror of the kernels) -----------------------------------------------------
def _corners(x, indices):
    x = np.asarray(x, dtype=np.float64)
    q = np.asarray(indices, dtype=np.int64).reshape(-1, 4)
    return x[q[:, 0]], x[q[:, 1]], x[q[:, 2]], x[q[:, 3]]


def _dot(a, b):
    return a[:, 0] * b[:, 0] + a[:, 1] * b[:, 1] + a[:, 2] * b[:, 2]


def _cross(a, b):
    # row-wise a x b (np.cross is several times slower on (H, 3) arrays)
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[:, 0] = a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1]
    out[:, 1] = a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2]
    out[:, 2] = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    return out


def _norm(a):
    return np.sqrt(_dot(a, a))


def hinge_geometry(x, indices) -> tuple[np.ndarray, np.ndarray]:
    """(|e| [m], (A_A, A_B) [m^2]) of every hinge at positions ``x`` (N, 3)."""
    x0, x1, x2, x3 = _corners(x, indices)
    e = x1 - x0
    area_a = 0.5 * _norm(_cross(e, x2 - x0))
    area_b = 0.5 * _norm(_cross(x0 - x1, x3 - x1))
    return _norm(e), np.stack([area_a, area_b], axis=1)


def hinge_angles(x, indices) -> np.ndarray:
    """theta = atan2((nA x nB) . e / |e|, nA . nB) [rad] per hinge (0 where degenerate)."""
    return hinge_angle_gradients(x, indices)[0]


def hinge_angle_gradients(x, indices) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """theta [rad] (H,), its gradient g = d theta / d(x0, x1, x2, x3) [1/m] (H, 4, 3) and a validity
    mask (H,); degenerate hinges (module guards) get theta = 0, g = 0, valid = False. Float64."""
    xt = np.ascontiguousarray(np.asarray(x, dtype=np.float64).T)  # (3, N): component rows, contiguous
    q = np.asarray(indices, dtype=np.int64).reshape(-1, 4)
    x0, x1, x2, x3 = (xt[:, q[:, k]] for k in range(4))

    def cross(u, w):
        return np.stack([u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2], u[0] * w[1] - u[1] * w[0]])

    def dot(u, w):
        return u[0] * w[0] + u[1] * w[1] + u[2] * w[2]

    e = x1 - x0
    le = np.sqrt(dot(e, e))
    na = cross(e, x2 - x0)
    nb = cross(x0 - x1, x3 - x1)
    la, lb = np.sqrt(dot(na, na)), np.sqrt(dot(nb, nb))
    valid = (le >= EDGE_EPS) & (la >= AREA_EPS) & (lb >= AREA_EPS)
    le_s = np.where(valid, le, 1.0)
    la_s, lb_s = np.where(valid, la, 1.0), np.where(valid, lb, 1.0)
    theta = np.arctan2(dot(cross(na, nb), e) / le_s, dot(na, nb))
    ha = np.maximum(la_s / le_s, HEIGHT_FLOOR * le_s)
    hb = np.maximum(lb_s / le_s, HEIGHT_FLOOR * le_s)
    g = np.empty((4, 3, q.shape[0]))
    g[2] = -na / (la_s * ha)
    g[3] = -nb / (lb_s * hb)
    ta = dot(x2 - x0, e) / le_s**2
    tb = dot(x3 - x0, e) / le_s**2
    g[0] = -(1.0 - ta) * g[2] - (1.0 - tb) * g[3]
    g[1] = -ta * g[2] - tb * g[3]
    g[:, :, ~valid] = 0.0
    return np.where(valid, theta, 0.0), np.ascontiguousarray(g.transpose(2, 0, 1)), valid


def wrap_angle(a):
    """a wrapped into (-pi, pi] (as the kernels wrap theta - theta0)."""
    a = np.asarray(a, dtype=np.float64)
    return a - 2.0 * np.pi * np.ceil((a - np.pi) / (2.0 * np.pi))


def hinge_energies(x, hinges: Hinges) -> np.ndarray:
    """E_e = 1/2 k_e wrap(theta - theta0)^2 [J] per hinge at positions ``x`` (float64; 0 where degenerate)."""
    theta, _, valid = hinge_angle_gradients(x, hinges.indices)
    return np.where(valid, 0.5 * hinges.stiffness * wrap_angle(theta - hinges.rest_angle) ** 2, 0.0)


def hinge_rest_coefficients(x, indices) -> np.ndarray:
    """The scalars c_a with g_a = c_a n_hat at a flat rest state (projective dynamics' constant
    matrix h^2 sum_e k_e c c^T, material-design.md section 2.3), shape (H, 4): c2 = -1/hA,
    c3 = -1/hB, c0 = (1-tA)/hA + (1-tB)/hB, c1 = tA/hA + tB/hB (sum 0). For a curved rest state
    the gradient is projected on the mean normal of the two triangles."""
    x0, x1, x2, x3 = _corners(x, indices)
    e = x1 - x0
    n = _cross(e, x2 - x0)
    n = n / np.maximum(_norm(n), 1e-300)[:, None]
    nb = _cross(x0 - x1, x3 - x1)
    n = n + nb / np.maximum(_norm(nb), 1e-300)[:, None]
    n = n / np.maximum(_norm(n), 1e-300)[:, None]
    _, g, _ = hinge_angle_gradients(x, indices)
    return np.einsum("hai,hi->ha", g, n)


# -- stiffness ------------------------------------------------------------------------------------
def bend_rigidity(warp_share, bend_warp: float, bend_weft: float) -> np.ndarray:
    """B(m) = B_warp m_w^2 + B_weft (1 - m_w^2) [N m], ``warp_share`` = m_w^2 (per hinge)."""
    s = np.clip(np.asarray(warp_share, dtype=np.float64), 0.0, 1.0)
    return bend_warp * s + bend_weft * (1.0 - s)


def bend_damping_time(ratio: float, frequency: float) -> float:
    """beta_b = 2 zeta / omega_ref = zeta / (pi f_ref) [s]: a bending mode of angular frequency
    omega then has damping ratio beta_b omega / 2 at every resolution (material-design.md 1.4)."""
    if frequency <= 0.0:
        raise WarpclothError(f"bend damping frequency must be > 0 Hz, got {frequency}")
    return float(ratio) / (np.pi * float(frequency))


def _require_rigidity(bend_warp, bend_weft):
    bend_weft = bend_warp if bend_weft is None else bend_weft
    for name, value in (("bend_warp", bend_warp), ("bend_weft", bend_weft)):
        if not np.isfinite(value) or value < 0.0:
            raise WarpclothError(f"{name} must be a finite bending rigidity >= 0 N m, got {value}")
    return float(bend_warp), float(bend_weft)


def build_hinges(x, indices, rigidity, weight=1.0, damping_time: float = 0.0) -> Hinges:
    """Hinges with rest values from positions ``x`` (N, 3) [m] and rigidities B_e [N m] per hinge
    (scalar or (H,)); k_e = w_e B_e |e|^2 / (A_A + A_B), kd_e = damping_time k_e."""
    q = np.asarray(indices, dtype=np.int32).reshape(-1, 4)
    length, area = hinge_geometry(x, q)
    theta, _, valid = hinge_angle_gradients(x, q)
    h = q.shape[0]
    weight = np.broadcast_to(np.asarray(weight, dtype=np.float64), (h,)).copy()
    rigidity = np.broadcast_to(np.asarray(rigidity, dtype=np.float64), (h,)).copy()
    area_sum = area.sum(axis=1)
    stiffness = np.where(valid, weight * rigidity * length**2 / np.where(valid, area_sum, 1.0), 0.0)
    return Hinges(
        indices=q,
        rest_angle=theta,
        rest_length=length,
        rest_area=area,
        weight=weight,
        rigidity=rigidity,
        stiffness=stiffness,
        damping=float(damping_time) * stiffness,
    )


def hinge_damping_for_ratio(x, hinges: Hinges, mass, ratio: float) -> np.ndarray:
    """kd_e = 2 zeta sqrt(k_e / sum_b |g_b|^2 / m_b) [N m s / rad^2] per hinge, at the rest shape ``x``:
    the hinge's own mode (E = 1/2 k_e C^2, its inertia 1 / sum_b |g_b|^2 / m_b) then has damping ratio
    ``ratio`` = zeta at every resolution (the hinge analogue of the springs' kd = 2 zeta sqrt(ks m))."""
    _, g, valid = hinge_angle_gradients(x, hinges.indices)
    inv_mass = 1.0 / np.asarray(mass, dtype=np.float64)
    wg = np.einsum("hb,hb->h", inv_mass[hinges.indices], np.einsum("hbi,hbi->hb", g, g))
    return np.where(
        valid & (wg > 0.0), 2.0 * float(ratio) * np.sqrt(hinges.stiffness / np.where(wg > 0.0, wg, 1.0)), 0.0
    )


def hinge_row_sums(x, hinges: Hinges, particle_count: int) -> tuple[np.ndarray, np.ndarray]:
    """Per particle i, the block-Gershgorin row sums of sum_e k_e g g^T and sum_e kd_e g g^T at ``x``:
    sum_(e at i) k_e |g_i| sum_b |g_b| [N/m] and the same with kd_e [N s/m] (float64): a bound on what
    the hinges add to the stiffness (damping) eigenvalues of particle i's rows (block norms |g_a| |g_b|)."""
    _, g, _ = hinge_angle_gradients(x, hinges.indices)
    norms = np.sqrt(np.einsum("hbi,hbi->hb", g, g))  # (H, 4)
    row = norms * norms.sum(axis=1, keepdims=True)  # |g_a| sum_b |g_b|
    stiff, damp = np.zeros(particle_count), np.zeros(particle_count)
    idx = hinges.indices.ravel()
    np.add.at(stiff, idx, (hinges.stiffness[:, None] * row).ravel())
    np.add.at(damp, idx, (hinges.damping[:, None] * row).ravel())
    return stiff, damp


def grid_hinges(
    positions,
    rows: int,
    cols: int,
    bend_warp: float,
    bend_weft: float | None = None,
    warp_angle: float = 0.0,
    damping_time: float = 0.0,
) -> Hinges:
    """Symmetrised hinges of a rows x cols grid (:func:`grid_hinge_indices`, weight 1/2 each) with
    rest values from ``positions`` (N, 3) [m]. Warp runs along the columns (+c, grid +x) turned by
    ``warp_angle`` [rad]: a y-edge (across +c) gets m_w^2 = cos^2(warp_angle), an x-edge sin^2; so
    at warp_angle 0 y-edges carry B_warp and x-edges B_weft, exactly, and a flat grid wrapped on a
    cylinder of curvature kappa along direction phi stores (B_warp cos^2 phi + B_weft sin^2 phi)
    kappa^2 / 2 per unit area, at every phi (on its interior hinges: boundary rows/columns of cells
    have no hinge across them, an O(1/N) deficit in the total)."""
    bend_warp, bend_weft = _require_rigidity(bend_warp, bend_weft)
    q, axis = grid_hinge_indices(rows, cols)
    share = np.where(axis == 1, np.cos(warp_angle) ** 2, np.sin(warp_angle) ** 2)
    return build_hinges(positions, q, bend_rigidity(share, bend_warp, bend_weft), 0.5, damping_time)


def mesh_hinges(
    positions,
    triangles,
    bend_warp: float,
    bend_weft: float | None = None,
    uv=None,
    warp_angle: float = 0.0,
    damping_time: float = 0.0,
) -> Hinges:
    """Hinges on the interior edges of a triangle mesh (:func:`triangle_hinges`, weight 1).

    The warp axis in triangle A of each hinge is the UV u axis (d x / d u, from per-vertex ``uv``
    (N, 2)) or, without UVs, global +x projected into the triangle's plane; then turned by
    ``warp_angle`` [rad] about the triangle's normal. m = n_A x e_hat (in-plane, across the edge),
    m_w^2 = (m . warp)^2. Irregular meshes are mesh dependent (+3..16 % on jittered Delaunay,
    material-design.md 2.1); the per-direction calibration there is not applied here.

    Raises:
        WarpclothError: a non-manifold edge, degenerate UVs, or a triangle perpendicular to x (no UVs).
    """
    bend_warp, bend_weft = _require_rigidity(bend_warp, bend_weft)
    x = np.asarray(positions, dtype=np.float64)
    q = triangle_hinges(triangles)
    x0, x1, x2, _ = _corners(x, q)
    e = x1 - x0
    n = _cross(e, x2 - x0)
    n_len = _norm(n)
    ok = n_len > 0.0
    n = n / np.where(ok, n_len, 1.0)[:, None]
    if uv is not None:
        uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
        d1, d2 = uv[q[:, 1]] - uv[q[:, 0]], uv[q[:, 2]] - uv[q[:, 0]]
        det = d1[:, 0] * d2[:, 1] - d2[:, 0] * d1[:, 1]
        if np.any(ok & (np.abs(det) < 1e-14)):
            raise WarpclothError("degenerate UVs on a hinge triangle: the warp direction is undefined there")
        ref = (e * d2[:, 1:2] - (x2 - x0) * d1[:, 1:2]) / np.where(det == 0.0, 1.0, det)[:, None]  # d x / d u
    else:
        ref = np.broadcast_to(np.array([1.0, 0.0, 0.0]), e.shape)
    ref = ref - _dot(ref, n)[:, None] * n
    ref_len = _norm(ref)
    if np.any(ok & (ref_len < 1e-12)):
        raise WarpclothError("a hinge triangle is perpendicular to the warp reference axis; pass uv")
    warp = ref / np.where(ref_len > 0.0, ref_len, 1.0)[:, None]
    warp = np.cos(warp_angle) * warp + np.sin(warp_angle) * _cross(n, warp)
    m = _cross(n, e / np.maximum(_norm(e), 1e-300)[:, None])
    share = np.where(ok, _dot(m, warp) ** 2, 1.0)
    return build_hinges(x, q, bend_rigidity(share, bend_warp, bend_weft), 1.0, damping_time)


# -- adjacency, sparsity, colouring ---------------------------------------------------------------
def hinge_pairs(indices) -> np.ndarray:
    """The distinct unordered vertex pairs (i < j) that hinges couple, shape (P, 2), int32: the
    off-diagonal blocks a hinge adds to an implicit system or a vertex-colouring graph (on grids
    the x2-x3 pairs are knight moves that no spring has)."""
    q = np.asarray(indices, dtype=np.int64).reshape(-1, 4)
    a, b = np.triu_indices(4, 1)
    i, j = q[:, a].ravel(), q[:, b].ravel()
    lo, hi = np.minimum(i, j), np.maximum(i, j)
    n = int(q.max()) + 1 if q.size else 1
    key = np.unique((lo * n + hi)[lo != hi])  # 1-D keys: np.unique(axis=0) is ~30x slower
    return np.stack([key // n, key % n], axis=1).astype(np.int32)


def hinge_adjacency(indices, particle_count: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each particle's hinges, grouped by particle (CSR): ``(offsets, hinge, slot)``, particle i's
    entries ``offsets[i]:offsets[i + 1]``, ``slot`` its position 0..3 in the hinge; int32."""
    q = np.asarray(indices, dtype=np.int64).reshape(-1, 4)
    ends = q.ravel()
    hinge = np.repeat(np.arange(q.shape[0]), 4)
    slot = np.tile(np.arange(4), q.shape[0])
    order = np.argsort(ends, kind="stable")
    offsets = np.zeros(particle_count + 1, dtype=np.int32)
    offsets[1:] = np.cumsum(np.bincount(ends, minlength=particle_count))
    return offsets, hinge[order].astype(np.int32), slot[order].astype(np.int32)


def hinge_block_index(indices, adjacency_offsets, adjacency_hinge, row_offsets, columns) -> np.ndarray:
    """For every entry of :func:`hinge_adjacency` (particle a, hinge e) and every slot b of e, the
    position of block (a, x_b[e]) in a CSR/BSR pattern (``row_offsets``, ``columns``, columns sorted
    within each row), shape (entries, 4), int32: where an implicit system's row gather adds
    s g_a g_b^T (the diagonal block included, b = a's own slot).

    Raises:
        WarpclothError: the pattern lacks a block a hinge needs (build it from springs and :func:`hinge_pairs`).
    """
    q = np.asarray(indices, dtype=np.int64).reshape(-1, 4)
    adjacency_offsets = np.asarray(adjacency_offsets, dtype=np.int64)
    particle = np.repeat(np.arange(adjacency_offsets.size - 1), np.diff(adjacency_offsets))
    rows = np.repeat(particle, 4)
    cols = q[np.asarray(adjacency_hinge, dtype=np.int64)].ravel()
    row_offsets = np.asarray(row_offsets, dtype=np.int64)
    columns = np.asarray(columns, dtype=np.int64)
    n = row_offsets.size - 1
    pattern = np.repeat(np.arange(n), np.diff(row_offsets)) * n + columns
    key = rows * n + cols
    if key.size == 0:
        return np.zeros((0, 4), dtype=np.int32)
    pos = np.minimum(np.searchsorted(pattern, key), max(pattern.size - 1, 0))
    if pattern.size == 0 or np.any(pattern[pos] != key):
        raise WarpclothError("the matrix pattern lacks blocks that the hinges couple")
    return pos.reshape(-1, 4).astype(np.int32)


def greedy_hinge_colors(indices, particle_count: int, seed: int = 0) -> np.ndarray:
    """Greedy colouring in which no two hinges of one colour share a vertex, vectorised (Jones &
    Plassmann 1993): hinges take a seeded random priority; each round, every uncoloured hinge whose
    priority beats all uncoloured hinges at its four vertices takes the smallest colour unused at
    them. The result equals sequential greedy in priority order; rounds are few (O(log H)).

    Raises:
        WarpclothError: more than 63 colours would be needed (a vertex of very high valence).
    """
    q = np.asarray(indices, dtype=np.int64).reshape(-1, 4)
    count = q.shape[0]
    colors = np.full(count, -1, dtype=np.int32)
    if count == 0:
        return colors
    priority = np.random.default_rng(seed).permutation(count).astype(np.int64)
    used = np.zeros(particle_count, dtype=np.uint64)  # bit k: colour k touches the vertex
    pending = np.arange(count)
    while pending.size:
        qp = q[pending]
        pr = priority[pending]
        best = np.full(particle_count, count, dtype=np.int64)
        np.minimum.at(best, qp.ravel(), np.repeat(pr, 4))
        win = np.all(best[qp] == pr[:, None], axis=1)
        qw = qp[win]  # winners share no vertex (each is the unique minimum at its vertices)
        taken = used[qw[:, 0]] | used[qw[:, 1]] | used[qw[:, 2]] | used[qw[:, 3]]
        if np.any(taken == np.uint64(2**63 - 1)) or np.any(taken >= np.uint64(2**63)):
            raise WarpclothError("hinge colouring needs more than 63 colours")
        free = ~taken & (taken + np.uint64(1))  # lowest clear bit
        k = np.round(np.log2(free.astype(np.float64))).astype(np.int32)
        colors[pending[win]] = k
        for s in range(4):
            used[qw[:, s]] |= free
        pending = pending[~win]
    return colors


def is_valid_hinge_coloring(indices, colors, particle_count: int) -> bool:
    """True when no two hinges of one colour share a vertex."""
    q = np.asarray(indices, dtype=np.int64).reshape(-1, 4)
    if q.shape[0] == 0:
        return True
    qs = np.sort(q, axis=1)
    distinct = int(q.shape[0] + np.sum(qs[:, 1:] != qs[:, :-1]))  # a degenerate hinge may repeat a vertex
    keys = np.asarray(colors, dtype=np.int64)[:, None] * particle_count + q
    return np.unique(keys).size == distinct


def color_hinges(indices, particle_count: int, seed: int = 0) -> Coloring:
    """Hinges sorted by colour (:func:`greedy_hinge_colors`), verified."""
    colors = greedy_hinge_colors(indices, particle_count, seed)
    if not is_valid_hinge_coloring(indices, colors, particle_count):  # pragma: no cover - greedy is always valid
        raise RuntimeError("hinge colouring is invalid")
    return Coloring.from_colors(colors)
