"""The cloth model: immutable topology and parameters of a mass-spring cloth.

A :class:`ClothModel` holds particle masses, pins, springs (structural, shear, bend) with their
rest lengths and per-type stiffness/damping, and the triangles (for wind and rendering). It is
built once per run by :func:`build_model` from arrays, which the Provot grid
(:func:`~warpcloth.sim.grid.build_grid_cloth`) and the triangle-mesh cloth
(:func:`~warpcloth.sim.mesh.build_mesh_cloth`) builders fill; :meth:`ClothModel.state` makes a
fresh :class:`~warpcloth.sim.state.State`. The default spring parameters are here too.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field, replace

import numpy as np
import warp as wp

from warpcloth.errors import WarpclothError, require, require_indices, require_non_negative
from warpcloth.sim.device import resolve_device
from warpcloth.sim.hinges import Hinges, hinge_row_sums
from warpcloth.sim.state import State


class SpringType(enum.IntEnum):
    """Kinds of spring in the Provot grid (seed 2.1.2)."""

    STRUCTURAL = 0
    SHEAR = 1
    BEND = 2


class BendModel(str, enum.Enum):
    """Which bend (flexion) springs a grid gets."""

    PROVOT = "provot"  # [i,j]-[i+2,j], [i,j]-[i,j+2]
    CHOI_KO = "choi_ko"  # Provot's plus the diagonals [i,j]-[i+2,j+2], [i+2,j]-[i,j+2]
    NONE = "none"
    DIHEDRAL = "dihedral"  # no bend springs: dihedral-angle hinges (discrete shells), warpcloth.sim.hinges


@dataclass(frozen=True)
class SpringParams:
    """Stiffness ks [N/m] and damping kd [N s/m] of one spring type."""

    stiffness: float
    damping: float


@dataclass(frozen=True, eq=False)
class HostArrays:
    """The host (NumPy) arrays a :class:`ClothModel` was built from, as typed fields
    (``model.host.q``; read-only by convention: the device arrays were made from them).

    Attributes:
        q: rest positions [m], (N, 3) float32.
        pairs: spring particle pairs, (S, 2) int32.
        rest: spring rest lengths [m], (S,) float32.
        mass: particle masses [kg], (N,) float32.
        inv_mass: inverse masses [1/kg], 0 where pinned, (N,) float32.
        tris: triangles, (T, 3) int32.
        uv: texture coordinates per triangle corner, (3T, 2), or None.
        groups: named vertex groups of a mesh (name -> indices, int64); empty for a grid.
        hinges: the dihedral-bending hinges (:class:`~warpcloth.sim.hinges.Hinges`, float64), or None.
        collision_group: per particle, its piece's self-collision group (int32), or None (one group): the
            self-collision skips every pair of two groups (:class:`~warpcloth.sim.builder.ClothBuilder`).
    """

    q: np.ndarray
    pairs: np.ndarray
    rest: np.ndarray
    mass: np.ndarray
    inv_mass: np.ndarray
    tris: np.ndarray
    uv: np.ndarray | None = None
    groups: dict = field(default_factory=dict)
    hinges: Hinges | None = None
    collision_group: np.ndarray | None = None


@dataclass(frozen=True)
class ClothPiece:
    """One cloth of a model that holds several (:class:`~warpcloth.sim.builder.ClothBuilder`): its
    particles are ``particle_offset .. particle_offset + particle_count - 1`` of the model, its
    triangles ``tri_offset .. tri_offset + tri_count - 1`` (their indices are the model's).

    Attributes:
        name: the piece's name (unique in its model; the USD prim's name).
        particle_offset, particle_count: its particle range.
        tri_offset, tri_count: its triangle range.
        material: its :class:`~warpcloth.sim.material.Material`, or None (per-spring parameters).
        collision_group: its self-collision group: pieces of two groups do not collide with each other.
        bend: its :class:`BendModel`.
        rows, cols: its grid's size (a mesh: 1 x particle_count), for a grid's colouring.
    """

    name: str
    particle_offset: int
    particle_count: int
    tri_offset: int
    tri_count: int
    material: object = None
    collision_group: int = 0
    bend: BendModel = BendModel.PROVOT
    rows: int = 1
    cols: int = 0

    @property
    def particles(self) -> slice:
        """Its particles as a slice of the model's arrays."""
        return slice(self.particle_offset, self.particle_offset + self.particle_count)

    @property
    def triangles(self) -> slice:
        """Its triangles as a slice of the model's triangle arrays."""
        return slice(self.tri_offset, self.tri_offset + self.tri_count)


@dataclass(frozen=True, eq=False)  # identity equality and hash (its arrays have no value equality)
class ClothModel:
    """Immutable cloth topology and parameters, with device copies of every array (a frozen
    dataclass: a model with other spring parameters is a new model, :meth:`with_spring_params`).

    Attributes (device arrays are ``wp.array`` on :attr:`device`):
        rows, cols: grid size (particles per column and per row).
        particle_count: rows * cols.
        particle_q: initial particle positions [m], shape (particle_count,), vec3.
        particle_mass: particle masses [kg], shape (particle_count,).
        particle_inv_mass: inverse masses [1/kg]; 0 for pinned particles.
        pinned: indices of pinned particles (NumPy, int).
        spring_indices: particle pairs (i, j), shape (spring_count,), vec2i.
        spring_type: :class:`SpringType` of each spring (NumPy).
        spring_rest_length: rest lengths L0 [m], shape (spring_count,).
        spring_stiffness: ks [N/m] per spring, filled from the per-type parameters (or given
            per spring to :func:`build_model`).
        spring_damping: kd [N s/m] per spring, filled from the per-type parameters (or given
            per spring).
        tri_indices: triangles (a, b, c), two per grid cell, shape (tri_count,), vec3i.
        spring_params: per-type :class:`SpringParams`.
        bend: the :class:`BendModel` the cloth was built with.
        hinge_indices: dihedral-bending hinges (x0, x1, x2, x3), shape (hinge_count,), vec4i, or
            None without hinges (:meth:`with_hinges`; host copy ``host.hinges``).
        hinge_rest_angle: theta0 [rad] per hinge.
        hinge_stiffness: k_e [N m / rad^2] per hinge.
        hinge_damping: kd_e [N m s / rad^2] per hinge.
        spring_compression: phi per spring, shape (spring_count,): a spring shorter than its rest
            length acts with phi ks (a material's compression factor, emulating sub-grid buckling;
            Choi & Ko 2002); ones unless given to :func:`build_model` (a factor of 1 leaves every
            kernel's result bit-identical).
        material: the :class:`~warpcloth.sim.material.Material` the parameters came from, or None
            (per-spring parameters, or pieces of different materials).
        pieces: the :class:`ClothPiece` records of a model of several cloths
            (:class:`~warpcloth.sim.builder.ClothBuilder`); empty for one cloth (:attr:`cloth_pieces`).
    """

    rows: int
    cols: int
    width: float
    height: float
    total_mass: float
    device: wp.Device
    particle_q: wp.array
    particle_mass: wp.array
    particle_inv_mass: wp.array
    pinned: np.ndarray
    spring_indices: wp.array
    spring_type: np.ndarray
    spring_rest_length: wp.array
    spring_stiffness: wp.array
    spring_damping: wp.array
    tri_indices: wp.array
    spring_params: dict[SpringType, SpringParams]
    bend: BendModel = BendModel.PROVOT
    host: HostArrays | None = field(default=None, repr=False)
    hinge_indices: wp.array | None = None
    hinge_rest_angle: wp.array | None = None
    hinge_stiffness: wp.array | None = None
    hinge_damping: wp.array | None = None
    spring_compression: wp.array | None = None
    material: object = None
    pieces: tuple = ()

    def __post_init__(self):
        if self.spring_compression is None:  # every spring as stiff in compression as in tension
            count = int(self.spring_indices.shape[0])
            object.__setattr__(self, "spring_compression", wp.ones(count, dtype=float, device=self.device))

    @property
    def cloth_pieces(self) -> tuple[ClothPiece, ...]:
        """The model's cloths: its :attr:`pieces`, or for a model of one cloth one piece named
        ``"cloth"`` spanning every particle and triangle."""
        if self.pieces:
            return self.pieces
        n, bend = self.particle_count, self.bend
        whole = ClothPiece("cloth", 0, n, 0, self.tri_count, self.material, 0, bend, self.rows, self.cols)
        return (whole,)

    @property
    def has_compression(self) -> bool:
        """Whether some spring is softer in compression (phi < 1)."""
        return bool(self.spring_count) and bool(np.any(self.spring_compression.numpy() < 1.0))

    @property
    def particle_count(self) -> int:
        return int(self.host.q.shape[0])

    @property
    def spring_count(self) -> int:
        return int(self.spring_type.shape[0])

    @property
    def tri_count(self) -> int:
        return int(self.tri_indices.shape[0])

    @property
    def hinge_count(self) -> int:
        """Number of dihedral-bending hinges (0 without them)."""
        return 0 if self.hinge_indices is None else int(self.hinge_indices.shape[0])

    def hinge_arrays(self) -> tuple:
        """(hinge_indices, hinge_rest_angle, hinge_stiffness, hinge_damping): the device arrays in
        the order :mod:`warpcloth.kernels.bending`'s kernels take them."""
        return self.hinge_indices, self.hinge_rest_angle, self.hinge_stiffness, self.hinge_damping

    def with_hinges(self, hinges: Hinges | None) -> ClothModel:
        """A new model with these dihedral-bending hinges (None: none), device copies on :attr:`device`;
        this model is left unchanged."""
        host = replace(self.host, hinges=hinges)
        if hinges is None:
            return replace(
                self, host=host, hinge_indices=None, hinge_rest_angle=None, hinge_stiffness=None, hinge_damping=None
            )
        require(
            hinges.hinge_count == 0 or int(hinges.indices.max()) < self.particle_count,
            f"hinge particle indices must be in 0..{self.particle_count - 1}",
        )
        d = hinges.to_device(self.device)
        return replace(
            self,
            host=host,
            hinge_indices=d.hinge_indices,
            hinge_rest_angle=d.hinge_rest_angle,
            hinge_stiffness=d.hinge_stiffness,
            hinge_damping=d.hinge_damping,
        )

    def particle_hinge_sums(self) -> tuple[np.ndarray, np.ndarray]:
        """Per particle, Gershgorin row sums of the hinges' stiffness and damping matrices at the
        rest shape, sum_e k_e |g_i| sum_b |g_b| [N/m] and the same with kd_e [N s/m] (float64, host;
        zeros without hinges): what a particle's row of sum_e k_e g g^T adds to 2 sum_j ks_ij."""
        if not self.hinge_count:
            z = np.zeros(self.particle_count)
            return z, z.copy()
        return hinge_row_sums(self.host.q, self.host.hinges, self.particle_count)

    @property
    def particle_mass_value(self) -> float:
        """Mass of one particle [kg] (the total split evenly, seed 4.2.4; the smallest mass for
        a non-uniform model)."""
        return float(self.host.mass.min())

    def spring_counts(self) -> dict[str, int]:
        """Number of springs of each type."""
        return {t.name.lower(): int(np.count_nonzero(self.spring_type == t)) for t in SpringType}

    def max_stiffness(self) -> float:
        """Largest spring stiffness K [N/m] in the model."""
        return max(p.stiffness for t, p in self.spring_params.items() if np.any(self.spring_type == t))

    def particle_spring_sums(self) -> tuple[np.ndarray, np.ndarray]:
        """Per particle, the sums of ks [N/m] and kd [N s/m] of its springs (float64, host)."""
        pairs = self.host.pairs
        ks_sum = np.zeros(self.particle_count)
        kd_sum = np.zeros(self.particle_count)
        ks = self.spring_stiffness.numpy().astype(np.float64)
        kd = self.spring_damping.numpy().astype(np.float64)
        for end in (0, 1):
            np.add.at(ks_sum, pairs[:, end], ks)
            np.add.at(kd_sum, pairs[:, end], kd)
        return ks_sum, kd_sum

    def state(self):
        """A new :class:`~warpcloth.sim.state.State` at the rest configuration with zero velocity."""
        return State.from_model(self)

    def with_spring_params(self, params: dict[SpringType, SpringParams]) -> ClothModel:
        """A new model with per-spring stiffness and damping from per-type ``params`` (the same
        topology, masses and pins, shared); this model is left unchanged. A
        :class:`~warpcloth.simulator.Simulator` switches with :meth:`~warpcloth.simulator.Simulator.set_model`."""
        check_spring_params(params)
        ks = np.array([params[SpringType(t)].stiffness for t in self.spring_type], dtype=np.float32)
        kd = np.array([params[SpringType(t)].damping for t in self.spring_type], dtype=np.float32)
        with wp.ScopedDevice(self.device):
            return replace(
                self,
                spring_stiffness=wp.array(ks, dtype=float),
                spring_damping=wp.array(kd, dtype=float),
                spring_params=dict(params),
            )


def check_spring_params(params: dict[SpringType, SpringParams]) -> None:
    """Raise a :class:`WarpclothError` unless ``params`` maps every :class:`SpringType` to
    :class:`SpringParams` with ks, kd >= 0."""
    if not isinstance(params, dict) or not all(isinstance(p, SpringParams) for p in params.values()):
        raise WarpclothError(
            "spring_params must map each SpringType to SpringParams(stiffness, damping) (see default_spring_params), "
            f"got {params!r:.80}"
        )
    for t in SpringType:
        require(t in params, f"spring parameters for {t.name.lower()} springs are missing")
        require_non_negative(f"{t.name.lower()} stiffness", params[t].stiffness, "N/m")
        require_non_negative(f"{t.name.lower()} damping", params[t].damping, "N s/m")


def build_model(
    positions,
    spring_pairs,
    spring_types,
    masses,
    spring_params=None,
    pins=(),
    triangles=None,
    device=None,
    *,
    spring_stiffness=None,
    spring_damping=None,
    spring_compression=None,
) -> ClothModel:
    """Build a mass-spring model from arrays (any topology; the grid and mesh builders use this).

    Args:
        positions: (N, 3) rest positions [m].
        spring_pairs: (S, 2) particle indices.
        spring_types: (S,) :class:`SpringType` values.
        masses: (N,) particle masses [kg] (> 0).
        spring_params: per-type :class:`SpringParams` (may be None when both per-spring arrays
            are given).
        pins: indices of pinned particles.
        triangles: (T, 3) particle indices for wind and rendering (default none).
        device: Warp device.
        spring_stiffness: optional (S,) ks [N/m] per spring (e.g. from a material,
            :mod:`warpcloth.sim.material`), used instead of the per-type stiffness.
        spring_damping: optional (S,) kd [N s/m] per spring, used instead of the per-type damping.
        spring_compression: optional (S,) factors phi in [0, 1]: a spring shorter than its rest
            length acts with phi ks (default 1: as stiff in compression as in tension).

    With per-spring arrays the model's ``spring_params`` records, per type, the largest ks and
    kd of that type's springs (0 for a type without springs), so that
    :meth:`ClothModel.max_stiffness` stays the largest ks in the model.
    """
    q = np.asarray(positions, dtype=np.float32).reshape(-1, 3)
    n = q.shape[0]
    require(n >= 1, "a model needs at least one particle")
    mass = np.asarray(masses, dtype=np.float32).reshape(-1)
    require(mass.shape[0] == n, f"masses must have one value per particle ({n}), got {mass.shape[0]}")
    if not np.all(mass > 0):
        raise WarpclothError(f"particle masses must be > 0 kg, got {float(mass[mass <= 0][0])!r}")
    per_spring = spring_stiffness is not None or spring_damping is not None
    if spring_params is None:
        require(
            spring_stiffness is not None and spring_damping is not None,
            "build_model needs spring_params, or both spring_stiffness and spring_damping per spring",
        )
    elif spring_stiffness is not None and spring_damping is not None:
        raise WarpclothError("give per-type spring_params or per-spring spring_stiffness and spring_damping, not both")
    else:
        check_spring_params(spring_params)
    pairs = np.asarray(spring_pairs, dtype=np.int32).reshape(-1, 2)
    types = np.asarray(spring_types, dtype=np.int32).reshape(-1)
    require(types.shape[0] == pairs.shape[0], "spring_types must have one value per spring")
    if pairs.size and (pairs.min() < 0 or pairs.max() >= n):
        raise WarpclothError(f"spring particle indices must be in 0..{n - 1}")
    pins = require_indices("pins", pins, n)
    inv_mass = (1.0 / mass).astype(np.float32)
    inv_mass[pins] = 0.0
    rest = np.linalg.norm(q[pairs[:, 1]].astype(np.float64) - q[pairs[:, 0]], axis=1).astype(np.float32)
    if rest.size and not np.all(rest > 0):
        raise WarpclothError("every spring must have a rest length > 0 m (two particles at the same place)")
    if types.size and (types.min() < 0 or types.max() > max(SpringType)):
        raise WarpclothError(f"spring types must be in 0..{int(max(SpringType))} (SpringType)")
    # per-type lookup by indexing (a Python loop over 300k springs took 0.5 s)
    if spring_stiffness is None:
        ks = np.array([spring_params[t].stiffness for t in SpringType], dtype=np.float32)[types]
    else:
        ks = _per_spring("spring_stiffness", spring_stiffness, types.shape[0], "N/m")
    if spring_damping is None:
        kd = np.array([spring_params[t].damping for t in SpringType], dtype=np.float32)[types]
    else:
        kd = _per_spring("spring_damping", spring_damping, types.shape[0], "N s/m")
    if spring_compression is not None:
        phi = _per_spring("spring_compression", spring_compression, types.shape[0], "")
        bad = np.flatnonzero(phi > 1.0)
        if bad.size:
            k = int(bad[0])
            raise WarpclothError(f"spring_compression of spring {k} must be in [0, 1], got {float(phi[k])!r}")
    if per_spring:  # per type, the largest value of that type's springs
        spring_params = {
            t: SpringParams(float(ks[types == t].max(initial=0.0)), float(kd[types == t].max(initial=0.0)))
            for t in SpringType
        }
    tris = (
        np.zeros((0, 3), dtype=np.int32) if triangles is None else np.asarray(triangles, dtype=np.int32).reshape(-1, 3)
    )
    device = resolve_device(device)
    with wp.ScopedDevice(device):
        return ClothModel(
            rows=1,
            cols=n,
            width=float(np.ptp(q[:, 0])) if n > 1 else 0.0,
            height=float(np.ptp(q[:, 1])) if n > 1 else 0.0,
            total_mass=float(mass.astype(np.float64).sum()),
            device=device,
            particle_q=wp.array(q, dtype=wp.vec3),
            particle_mass=wp.array(mass, dtype=float),
            particle_inv_mass=wp.array(inv_mass, dtype=float),
            pinned=pins,
            spring_indices=wp.array(pairs, dtype=wp.vec2i),
            spring_type=types,
            spring_rest_length=wp.array(rest, dtype=float),
            spring_stiffness=wp.array(ks, dtype=float),
            spring_damping=wp.array(kd, dtype=float),
            tri_indices=wp.array(tris, dtype=wp.vec3i),
            spring_params=dict(spring_params),
            bend=BendModel.NONE,
            spring_compression=None if spring_compression is None else wp.array(phi, dtype=float),
            host=HostArrays(q=q, pairs=pairs, rest=rest, mass=mass, inv_mass=inv_mass, tris=tris),
        )


def _per_spring(name: str, values, count: int, unit: str) -> np.ndarray:
    """A (count,) float32 array of finite values >= 0, else raise naming the first bad one."""
    try:
        a = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError):
        raise WarpclothError(f"{name} must be numbers, one per spring ({count})") from None
    require(
        a.ndim == 1 and a.shape[0] == count, f"{name} must have one value per spring ({count}), got shape {a.shape}"
    )
    bad = np.flatnonzero(~(np.isfinite(a) & (a >= 0.0)))
    if bad.size:
        k = int(bad[0])
        raise WarpclothError(f"{name} of spring {k} must be a finite number >= 0 {unit}, got {float(a[k])!r}")
    require(bool(np.all(a <= np.finfo(np.float32).max)), f"{name} must fit in float32")
    return a.astype(np.float32)


# Defaults: per-spring constants, as in the seed (one k per spring type).
DEFAULT_STIFFNESS = {SpringType.STRUCTURAL: 1000.0, SpringType.SHEAR: 1000.0, SpringType.BEND: 200.0}
DEFAULT_DAMPING_RATIO = 0.05


def default_damping(stiffness: float, particle_mass: float, ratio: float = DEFAULT_DAMPING_RATIO) -> float:
    """Spring damping kd = 2 ratio sqrt(ks m) [N s/m]: scales with particle mass, so refining
    the mesh keeps the same damping ratio and does not make explicit steps unstable."""
    return 2.0 * ratio * float(np.sqrt(stiffness * particle_mass))


def default_spring_params(particle_mass: float, stiffness=None, damping=None) -> dict[SpringType, SpringParams]:
    """Per-type spring parameters: given ks/kd (a number for all types or a per-type mapping),
    or the defaults, with kd scaled to the particle mass where not given."""

    def spring_type(key, what):
        try:
            return SpringType[key.upper()] if isinstance(key, str) else SpringType(key)
        except (KeyError, ValueError):
            names = ", ".join(t.name.lower() for t in SpringType)
            raise WarpclothError(f"{what}: unknown spring type {key!r}; the types are {names}") from None

    def per_type(value, fallback, what, unit):
        if value is None:
            return dict(fallback)
        if isinstance(value, dict):
            return {spring_type(k, what): require_non_negative(f"{what} of {k}", v, unit) for k, v in value.items()}
        if isinstance(value, (list, tuple)):
            require(len(value) == 3, f"{what} per type must be 3 values (structural, shear, bend), got {list(value)!r}")
            return {t: require_non_negative(f"{what} of {t.name.lower()} springs", value[t], unit) for t in SpringType}
        v = require_non_negative(what, value, unit)
        return dict.fromkeys(SpringType, v)

    ks = per_type(stiffness, DEFAULT_STIFFNESS, "stiffness", "N/m")
    for t in SpringType:
        ks.setdefault(t, DEFAULT_STIFFNESS[t])
        require_non_negative(f"{t.name.lower()} stiffness", ks[t], "N/m")
    kd_default = {t: default_damping(ks[t], particle_mass) for t in SpringType}
    kd = per_type(damping, kd_default, "damping", "N s/m")
    for t in SpringType:
        kd.setdefault(t, kd_default[t])
    return {t: SpringParams(ks[t], kd[t]) for t in SpringType}
