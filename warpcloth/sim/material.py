"""A cloth material in physical units, and its mapping onto springs (docs/materials.md).

A :class:`Material` holds what a fabric test measures: areal density rho [kg/m^2], the membrane
stiffnesses C11 = ``stretch_warp``, C22 = ``stretch_weft`` and C66 = ``shear`` [N/m], the bending
rigidities ``bend_warp`` / ``bend_weft`` [N m], a compression factor and damping ratios. Its
membrane energy per area for a small strain eps (x = warp, y = weft) is

    W = 1/2 (C11 e11^2 + 2 C12 e11 e22 + C22 e22^2 + 4 C66 e12^2),   C12 = C66 (Cauchy relation),

because a lattice of central springs cannot carry any other Poisson coupling.

:func:`grid_spring_params` and :func:`mesh_spring_params` turn a material into per-spring ks [N/m],
kd [N s/m], compression factors and per-particle masses [kg] such that the spring lattice stores the
material's membrane energy under any uniform strain (exactly on a grid; by a per-face least-squares
fit on a triangle mesh). A spring of rest length L, direction n stores 1/2 ks L^2 (n.eps.n)^2, so

    C_lattice = sum_springs ks L^2 n(x)n(x)n(x)n(x) / area   =  C (fully symmetric part),

and on a square grid ks does not change with the spacing: the same material gives the same membrane
response at every mesh size. Provot skip-one bend springs cannot give a bending rigidity; under a
material they get ks = 9 B / (kappa_ref^2 h^4), kappa_ref = 1 / c_b, c_b = (B / (rho g))^(1/3), exact
only at that curvature and growing as h^-4 (**not size-independent**), their membrane side effect
subtracted from the membrane springs ("Provot bend springs are not size-independent").
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from warpcloth.errors import (
    WarpclothError,
    require,
    require_int,
    require_non_negative,
    require_positive,
    require_vector,
    warn,
)
from warpcloth.sim.device import require_memory, resolve_device
from warpcloth.sim.grid import grid_memory_estimate, grid_positions, grid_springs, grid_triangles, grid_uvs
from warpcloth.sim.hinges import grid_hinges, mesh_hinges
from warpcloth.sim.mesh import (
    TriangleMesh,
    check_mesh,
    corner_uvs,
    lumped_masses,
    mesh_bend,
    mesh_memory_estimate,
    mesh_springs,
    mesh_topology,
    triangle_areas,
)
from warpcloth.sim.model import BendModel, ClothModel, SpringType, build_model
from warpcloth.sim.selection import resolve_pins

#: Standard gravity [m/s^2] used for the bending length c = (B / (rho g))^(1/3).
GRAVITY = 9.81

#: How membrane springs are damped: a damping ratio per spring (default) or Rayleigh kd = beta ks.
STRETCH_DAMPING_MODES = ("ratio", "rayleigh")

#: A mesh face fitted within this relative energy error keeps its material even where one of its
#: springs is at 0 N/m (the others carry it; NNLS's small Tikhonov term alone leaves ~1e-6).
FIT_TOLERANCE = 1e-3
#: A mesh whose springs store an energy off the material's by more than this (relative, for some
#: uniform strain) is warned about even where no spring is at 0 (triangles and fabrics' low shear).
MEMBRANE_WARNING = 0.1

#: Field names that describe the fabric (the ones a preset's ``estimated`` flags may name).
PHYSICAL_FIELDS = ("density", "stretch_warp", "stretch_weft", "shear", "bend_warp", "bend_weft")


@dataclass(frozen=True)
class Material:
    """A cloth material in SI units (x = warp, y = weft in the material frame).

    Attributes:
        name: a short name (a preset's key, or the user's).
        density: areal density rho [kg/m^2] (> 0).
        stretch_warp: membrane stiffness C11 [N/m] along the warp (> 0).
        stretch_weft: membrane stiffness C22 [N/m] along the weft (> 0).
        shear: in-plane shear stiffness C66 = G [N/m] (> 0; with C12 = G, G^2 < C11 C22).
        bend_warp: bending rigidity B_warp [N m] for curvature along the warp (a strip cut
            along the warp), >= 0.
        bend_weft: bending rigidity B_weft [N m] for curvature along the weft, >= 0.
        compression: phi in [0, 1]: a membrane spring shorter than its rest length has stiffness
            phi ks (emulates sub-grid buckling; 1 = as stiff in compression as in tension).
        stretch_damping_ratio: zeta_m >= 0, damping ratio of each membrane spring (numerical
            hygiene, see docs/materials.md).
        bend_damping_ratio: zeta_b >= 0 of a bending mode at ``bend_damping_frequency``.
        bend_damping_frequency: f_ref [Hz] (> 0) at which bending modes get ``bend_damping_ratio``.
        warp_angle: angle [rad] of the warp from the grid's +x (column) axis or the mesh's UV
            u axis, in [-pi, pi].
        source: citation key into docs/materials.md ("" for a user's material).
        estimated: names of the fields that are estimates, not measurements.
        note: a remark on the figures (e.g. a rig's ceiling).
    """

    name: str
    density: float
    stretch_warp: float
    stretch_weft: float
    shear: float
    bend_warp: float
    bend_weft: float
    compression: float = 1.0
    stretch_damping_ratio: float = 0.05
    bend_damping_ratio: float = 0.02
    bend_damping_frequency: float = 5.0
    warp_angle: float = 0.0
    source: str = ""
    estimated: tuple = ()
    note: str = ""

    def __post_init__(self):
        require(
            isinstance(self.name, str) and self.name.strip() != "",
            f"material name must be a non-empty string, got {self.name!r}",
        )
        what = f"material {self.name!r}:"
        checks = {
            "density": (require_positive, "kg/m^2"),
            "stretch_warp": (require_positive, "N/m"),
            "stretch_weft": (require_positive, "N/m"),
            "shear": (require_positive, "N/m"),
            "bend_warp": (require_non_negative, "N m"),
            "bend_weft": (require_non_negative, "N m"),
            "stretch_damping_ratio": (require_non_negative, ""),
            "bend_damping_ratio": (require_non_negative, ""),
            "bend_damping_frequency": (require_positive, "Hz"),
        }
        for key, (check, unit) in checks.items():
            object.__setattr__(self, key, check(f"{what} {key}", getattr(self, key), unit))
        phi = require_non_negative(f"{what} compression", self.compression)
        require(phi <= 1.0, f"{what} compression must be in [0, 1], got {self.compression!r}")
        object.__setattr__(self, "compression", phi)
        angle = _finite(f"{what} warp_angle", self.warp_angle)
        require(abs(angle) <= math.pi, f"{what} warp_angle must be in [-pi, pi] rad, got {self.warp_angle!r}")
        object.__setattr__(self, "warp_angle", angle)
        g, c11, c22 = self.shear, self.stretch_warp, self.stretch_weft
        require(
            g * g < c11 * c22,
            f"{what} shear must be < sqrt(stretch_warp * stretch_weft) = {math.sqrt(c11 * c22):.6g} N/m "
            f"(with C12 = shear the membrane must be positive definite), got {g!r}",
        )
        require(isinstance(self.source, str), f"{what} source must be a string, got {self.source!r}")
        require(isinstance(self.note, str), f"{what} note must be a string, got {self.note!r}")
        est = (self.estimated,) if isinstance(self.estimated, str) else tuple(self.estimated)
        allowed = PHYSICAL_FIELDS + (
            "compression",
            "stretch_damping_ratio",
            "bend_damping_ratio",
            "bend_damping_frequency",
        )
        for e in est:
            require(e in allowed, f"{what} estimated names unknown field {e!r}; fields: {', '.join(allowed)}")
        object.__setattr__(self, "estimated", est)

    # -- derived quantities ----------------------------------------------------------------

    def weight(self, gravity: float = GRAVITY) -> float:
        """Weight per area w = rho g [N/m^2]."""
        return self.density * gravity

    def membrane_voigt(self) -> np.ndarray:
        """The membrane stiffness in the material frame as a 3 x 3 matrix D [N/m] with
        W = 1/2 e^T D e, e = (e11, e22, 2 e12); D12 = C12 = shear (Cauchy relation)."""
        g = self.shear
        return np.array([[self.stretch_warp, g, 0.0], [g, self.stretch_weft, 0.0], [0.0, 0.0, g]])

    def membrane_energy_density(self, strain) -> np.ndarray:
        """Membrane energy per area [J/m^2] of small strains ``strain`` (..., 2, 2) given in the
        cloth frame (grid x/y or UV u/v; rotated by ``warp_angle`` into the material frame)."""
        eps = np.asarray(strain, dtype=np.float64)
        r = _frame(self.warp_angle)
        e = np.einsum("ai,...ab,bj->...ij", r, eps, r)  # material components R^T eps R
        v = np.stack([e[..., 0, 0], e[..., 1, 1], 2.0 * e[..., 0, 1]], axis=-1)
        return 0.5 * np.einsum("...i,ij,...j->...", v, self.membrane_voigt(), v)

    def bending_rigidity(self, angle: float = 0.0) -> float:
        """B [N m] for curvature along a direction at ``angle`` [rad] from the warp:
        B_warp cos^2 + B_weft sin^2."""
        c, s = math.cos(angle), math.sin(angle)
        return self.bend_warp * c * c + self.bend_weft * s * s

    def bending_length(self, direction: str = "warp", gravity: float = GRAVITY) -> float:
        """Bending length c = (B / (rho g))^(1/3) [m] of a strip cut along ``"warp"`` or ``"weft"``."""
        require(direction in ("warp", "weft"), f"direction must be 'warp' or 'weft', got {direction!r}")
        b = self.bend_warp if direction == "warp" else self.bend_weft
        return (b / self.weight(gravity)) ** (1.0 / 3.0)

    def bend_damping_time(self) -> float:
        """Rayleigh coefficient beta_b = zeta_b / (pi f_ref) [s] of the bending damping: a mode
        of angular frequency omega gets the damping ratio beta_b omega / 2 at any resolution."""
        return self.bend_damping_ratio / (math.pi * self.bend_damping_frequency)

    def stretch_damping_time(self) -> float:
        """Rayleigh coefficient beta_m = zeta_m / (pi f_ref) [s] for ``stretch_damping="rayleigh"``."""
        return self.stretch_damping_ratio / (math.pi * self.bend_damping_frequency)

    def replace(self, **changes) -> Material:
        """A copy with some fields changed (validated again); an unknown field is refused by name."""
        fields = [f.name for f in dataclasses.fields(self)]
        unknown = [k for k in changes if k not in fields]
        require(not unknown, f"material: unknown field {unknown[0]!r} (fields: {', '.join(fields)})" if unknown else "")
        return dataclasses.replace(self, **changes)

    def to_dict(self) -> dict:
        """The fields as plain JSON-ready values."""
        d = dataclasses.asdict(self)
        d["estimated"] = list(self.estimated)
        return d

    @classmethod
    def from_dict(cls, data: dict) -> Material:
        """A material from a mapping of field names (unknown names are an error)."""
        require(isinstance(data, dict), f"a material must be a mapping of field names, got {type(data).__name__}")
        fields = [f.name for f in dataclasses.fields(cls)]
        unknown = [k for k in data if k not in fields]
        require(not unknown, f"material: unknown field {unknown[0]!r} (fields: {', '.join(fields)})" if unknown else "")
        missing = [f.name for f in dataclasses.fields(cls) if f.default is dataclasses.MISSING and f.name not in data]
        require(not missing, f"material: field {missing[0]!r} is missing" if missing else "")
        return cls(**data)


def _finite(name: str, value) -> float:
    if isinstance(value, (str, bytes, bool)):
        raise WarpclothError(f"{name} must be a number, got {value!r}")
    try:
        v = float(value)
    except (TypeError, ValueError, OverflowError):
        raise WarpclothError(f"{name} must be a number, got {value!r:.80}") from None
    require(math.isfinite(v), f"{name} must be a finite number, got {value!r}")
    return v


# -- presets (docs/materials.md cites every figure) --------------------------------------------

_EST_ALL = PHYSICAL_FIELDS
_CEILING = "stretch values are ~ the stretch rig's ceiling in both directions: read them as lower bounds"

#: The built-in materials (figures and sources: docs/materials.md). Damping ratios and the
#: compression factor are the defaults for every preset (estimated, not measured).
PRESETS: dict[str, Material] = {
    m.name: m
    for m in (
        Material("cotton", 0.220, 4070.0, 4033.0, 52.4, 31.4e-6, 31.4e-6, source="W11:royal-target", note=_CEILING),
        Material(
            "denim",
            0.334,
            8890.0,
            8890.0,
            122.5,
            58.9e-6,
            58.9e-6,
            source="MK14",
            estimated=("stretch_warp", "stretch_weft", "shear", "bend_weft"),
            note="100 % cotton 3/1 twill jeans denim, enzyme washed: W and the bending length 2.62 cm measured "
            "(B = W c^3; weft B := warp's, one length given); stretch and shear from KES of other denims [H16]",
        ),
        Material(
            "polyester", 0.128, 4055.0, 4004.0, 9.6, 12.9e-6, 7.8e-6, source="W11:white-dots-on-blk", note=_CEILING
        ),
        Material(
            "polyester_light",
            0.113,
            343.0,
            86.0,
            7.2,
            3.6e-6,
            5.1e-6,
            source="W11:tango-red-jet-set",
            note="measured C12 = 109 N/m cannot be represented (Cauchy: C12 = shear)",
        ),
        Material(
            "wool",
            0.168,
            2132.0,
            1671.0,
            26.2,
            5.56e-6,
            5.02e-6,
            source="F14",
            note="secant stretch from FAST E100; a student lab report",
        ),
        Material(
            "silk",
            0.060,
            1000.0,
            1000.0,
            10.0,
            1.5e-6,
            1.5e-6,
            source="K80",
            estimated=_EST_ALL,
            note="estimated: B from the KES range of thin dress fabrics, S and G guesses; calibrate before use",
        ),
    )
}


def material(name) -> Material:
    """The preset called ``name`` (a :class:`Material` is returned as it is)."""
    if isinstance(name, Material):
        return name
    key = name.strip().lower() if isinstance(name, str) else None
    if key not in PRESETS:
        raise WarpclothError(f"unknown material {name!r}; the presets are {', '.join(PRESETS)}")
    return PRESETS[key]


#: The values a material may be given by (a run's parameters): name -> the Material fields it sets.
MATERIAL_VALUES = {
    "density": ("density",),
    "stretch": ("stretch_warp", "stretch_weft"),
    "shear": ("shear",),
    "bend_rigidity": ("bend_warp", "bend_weft"),
    "compression": ("compression",),
    "warp_angle": ("warp_angle",),
    "stretch_damping_ratio": ("stretch_damping_ratio",),
    "bend_damping_ratio": ("bend_damping_ratio",),
}


def material_with(base, **values) -> Material | None:
    """The material of a run: ``base`` (a preset's name, a :class:`Material`, ``"custom"``, or
    None / ``"none"`` for per-spring parameters) with ``values`` (:data:`MATERIAL_VALUES`; None:
    not given) replacing its fields. ``stretch`` and ``bend_rigidity`` are one number (warp and
    weft) or a (warp, weft) pair. ``custom`` needs density, stretch, shear and bend_rigidity. A
    changed preset is named ``"<preset>*"``. Bad values raise a one-line :class:`WarpclothError`."""
    unknown = sorted(set(values) - set(MATERIAL_VALUES))
    if unknown:
        raise WarpclothError(f"unknown material value {unknown[0]!r}; the values are {', '.join(MATERIAL_VALUES)}")
    given = {k: v for k, v in values.items() if v is not None}
    if base is None or (isinstance(base, str) and base.strip().lower() == "none"):
        names = [k for k in given if k != "bend_rigidity"]
        if names:
            raise WarpclothError(
                f"{names[0]} is a material's value: give a material (a preset, or custom with density, stretch, "
                "shear and bend_rigidity)"
            )
        return None
    fields = {}
    for key, value in given.items():
        targets = MATERIAL_VALUES[key]
        pair = tuple(value) if isinstance(value, (tuple, list)) else (value,) * len(targets)
        require(
            len(pair) == len(targets),
            f"material {key} must be one number or two (warp, weft), got {value!r}",
        )
        fields.update(zip(targets, pair))
    if isinstance(base, str) and base.strip().lower() == "custom":
        missing = [k for k in ("density", "stretch", "shear", "bend_rigidity") if k not in given]
        require(
            not missing,
            f"a custom material needs density, stretch, shear and bend_rigidity; {', '.join(missing)} missing",
        )
        return Material("custom", **fields)
    mat = material(base)
    return mat.replace(name=f"{mat.name}*", source="", estimated=(), note="", **fields) if fields else mat


# -- tensor helpers (5 components of a fully symmetric 2-D 4th-order tensor) -------------------

#: Frobenius weights of (C1111, C2222, C1122, C1112, C1222): multiplicities 1, 1, 6, 4, 4.
_FROB = np.sqrt(np.array([1.0, 1.0, 6.0, 4.0, 4.0]))


def _frame(angle: float) -> np.ndarray:
    """R with columns (warp, weft) in the cloth frame: v_cloth = R v_material."""
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s], [s, c]])


def _quartic(n: np.ndarray) -> np.ndarray:
    """(..., 2) unit vectors -> (..., 5) components of n (x) n (x) n (x) n."""
    x, y = n[..., 0], n[..., 1]
    return np.stack([x**4, y**4, x * x * y * y, x**3 * y, x * y**3], axis=-1)


def _target(mat: Material) -> np.ndarray:
    """The material's fully symmetric membrane tensor in its own frame (C12 = C66 = G)."""
    return np.array([mat.stretch_warp, mat.stretch_weft, mat.shear, 0.0, 0.0])


def _rotated_target(mat: Material) -> np.ndarray:
    """The material tensor's 5 components in the cloth frame (rotated by warp_angle)."""
    c = np.zeros((2, 2, 2, 2))
    t = _target(mat)
    idx = {(0, 0, 0, 0): t[0], (1, 1, 1, 1): t[1]}
    for p in {(0, 0, 1, 1), (0, 1, 0, 1), (0, 1, 1, 0), (1, 1, 0, 0), (1, 0, 1, 0), (1, 0, 0, 1)}:
        idx[p] = t[2]
    for key, value in idx.items():
        c[key] = value
    r = _frame(mat.warp_angle)
    cr = np.einsum("ia,jb,kc,ld,abcd->ijkl", r, r, r, r, c)
    return np.array([cr[0, 0, 0, 0], cr[1, 1, 1, 1], cr[0, 0, 1, 1], cr[0, 0, 0, 1], cr[0, 1, 1, 1]])


def _voigt(c5: np.ndarray) -> np.ndarray:
    """(..., 5) fully symmetric components -> (..., 3, 3) Voigt matrices for e = (e11, e22, 2 e12)."""
    a, b, m, p, q = (c5[..., k] for k in range(5))
    return np.stack([np.stack([a, m, p], -1), np.stack([m, b, q], -1), np.stack([p, q, m], -1)], -2)


def _relative_energy_error(delta5: np.ndarray, target5: np.ndarray) -> np.ndarray:
    """max over strains |e^T dD e| / (e^T D e): the largest generalized eigenvalue magnitude."""
    low, high = _relative_energy_range(delta5, target5)
    return np.maximum(-low, high)


def _relative_energy_range(delta5: np.ndarray, target5: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """min and max over strains of e^T dD e / (e^T D e) (the extreme generalized eigenvalues):
    min < 0 where the lattice is softer than the material for some strain, max > 0 stiffer."""
    chol = np.linalg.cholesky(_voigt(target5))
    inv = np.linalg.inv(chol)
    eig = np.linalg.eigvalsh(inv @ _voigt(delta5) @ inv.T)
    return eig[..., 0], eig[..., -1]


def bend_spring_stiffness(rigidity, segment, weight) -> np.ndarray:
    """Approximate Provot bend-spring ks [N/m] = 9 B / (kappa_ref^2 h^4), kappa_ref = (w / B)^(1/3)
    (equal energy with the rigidity ``B`` [N m] at the bending length's curvature; ``segment`` h
    [m] is half the spring's rest length, ``weight`` w = rho g [N/m^2]). Not size-independent:
    it grows as h^-4 and is exact only at kappa_ref (docs/materials.md)."""
    b = np.asarray(rigidity, dtype=np.float64)
    h = np.asarray(segment, dtype=np.float64)
    return 9.0 * b ** (5.0 / 3.0) * weight ** (-2.0 / 3.0) / h**4


# -- result -------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class MaterialSprings:
    """Per-spring and per-particle parameters of a material on one lattice (float64, host).

    Attributes:
        pairs: spring particle pairs (S, 2), the order the arrays follow.
        types: :class:`~warpcloth.sim.model.SpringType` of each spring (S,).
        stiffness: ks [N/m] per spring (S,).
        damping: kd [N s/m] per spring (S,).
        compression: per-spring factor (S,): a spring shorter than its rest length acts with
            ``compression * stiffness`` (the material's phi on structural and shear springs, 1 on
            bend springs, which only act through compression). Not read by the kernels yet.
        mass: particle masses [kg] (N,): rho times the vertex area.
        membrane_error: an upper bound of |E_lattice / E_material - 1| over all uniform small
            strains (0 up to rounding where the lattice is exact).
        clamped: number of springs whose ks was raised to 0 (bend springs stiffer than the membrane).
    """

    pairs: np.ndarray
    types: np.ndarray
    stiffness: np.ndarray
    damping: np.ndarray
    compression: np.ndarray
    mass: np.ndarray
    membrane_error: float
    clamped: int = 0

    def build_kwargs(self) -> dict:
        """The per-spring arguments of :func:`~warpcloth.sim.model.build_model`."""
        return {"spring_stiffness": self.stiffness, "spring_damping": self.damping}


def _damping(mat: Material, ks, types, pairs, mass, stretch_damping: str) -> np.ndarray:
    require(
        stretch_damping in STRETCH_DAMPING_MODES,
        f"stretch_damping must be one of {', '.join(STRETCH_DAMPING_MODES)}, got {stretch_damping!r}",
    )
    membrane = types != int(SpringType.BEND)
    if stretch_damping == "ratio":  # kd = 2 zeta_m sqrt(ks m_bar), m_bar the mean of the two masses
        m_bar = 0.5 * (mass[pairs[:, 0]] + mass[pairs[:, 1]])
        kd_m = 2.0 * mat.stretch_damping_ratio * np.sqrt(ks * m_bar)
    else:
        kd_m = mat.stretch_damping_time() * ks
    return np.where(membrane, kd_m, mat.bend_damping_time() * ks)


def _compression(mat: Material, types) -> np.ndarray:
    return np.where(types == int(SpringType.BEND), 1.0, mat.compression)


def _spring_lookup(pairs: np.ndarray, n: int):
    """A function (a, b) -> spring index (-1 where none) by packed-key binary search."""
    lo = np.minimum(pairs[:, 0], pairs[:, 1]).astype(np.int64)
    hi = np.maximum(pairs[:, 0], pairs[:, 1]).astype(np.int64)
    keys = lo * n + hi
    order = np.argsort(keys, kind="stable")
    sorted_keys = keys[order]

    def find(a, b):
        a, b = np.asarray(a, dtype=np.int64), np.asarray(b, dtype=np.int64)
        k = np.minimum(a, b) * n + np.maximum(a, b)
        if sorted_keys.size == 0:
            return np.full(k.shape, -1, dtype=np.int64)
        at = np.minimum(np.searchsorted(sorted_keys, k), sorted_keys.size - 1)
        return np.where(sorted_keys[at] == k, order[at], -1)

    return find


# -- grid ---------------------------------------------------------------------------------------


def grid_spring_params(
    mat,
    rows: int,
    cols: int,
    width: float,
    height: float,
    bend: str | BendModel = BendModel.PROVOT,
    stretch_damping: str = "ratio",
    gravity: float = GRAVITY,
) -> MaterialSprings:
    """Spring parameters of ``mat`` on a rows x cols Provot grid of width x height [m].

    Arrays follow :func:`~warpcloth.sim.grid.grid_springs` (rows, cols, bend). Cells are
    hx = width / (cols - 1) by hy = height / (rows - 1), d^2 = hx^2 + hy^2; C11, C22, G below are
    the material's tensor rotated into the grid frame (x = columns = UV u, y = UV v):

    - shear diagonals (two per cell): ks = G d^2 / (2 hx hy)  (= G on a square grid);
    - structural along x: per adjacent cell 1/2 (hy/hx) (C11 - G hx^2/hy^2) (interior springs
      have two cells, boundary ones one), along y: 1/2 (hx/hy) (C22 - G hy^2/hx^2) per cell;
    - each bend spring (length 2h) has the membrane energy of two springs of 2 k_b along the
      springs it spans, so 2 k_b is taken from each of those (structural for Provot, shear
      diagonals for Choi-Ko); a spring driven below 0 is clamped at 0 with a warning;
    - bend springs: :func:`bend_spring_stiffness` with B for curvature along the spring.

    The lattice then stores exactly the material's membrane energy (with C12 = G) under every
    uniform strain, boundaries included (``membrane_error`` ~ 1e-16), unless springs were
    clamped or the warp is off the grid axes (a tensor with C1112 != 0 cannot be represented;
    warned). Masses: rho times the vertex area (interior rho hx hy, edges 1/2, corners 1/4).
    Damping: membrane springs kd = 2 zeta_m sqrt(ks m_bar) (or Rayleigh, ``stretch_damping``),
    bend springs kd = beta_b ks (:meth:`Material.bend_damping_time`).
    """
    mat = material(mat)
    try:
        bend = BendModel(bend)
    except ValueError:
        raise WarpclothError(f"bend must be one of {[b.value for b in BendModel]}, got {bend!r}") from None
    minimum = 2 if bend in (BendModel.NONE, BendModel.DIHEDRAL) else 3
    rows, cols = require_int("rows", rows, minimum), require_int("cols", cols, minimum)
    width, height = require_positive("width", width, "m"), require_positive("height", height, "m")
    gravity = require_positive("gravity", gravity, "m/s^2")
    hx, hy = width / (cols - 1), height / (rows - 1)
    pairs, types = grid_springs(rows, cols, bend)
    r, c = pairs // cols, pairs % cols
    dr, dc = r[:, 1] - r[:, 0], c[:, 1] - c[:, 0]
    vec = np.stack([dc * hx, -dr * hy], axis=1).astype(np.float64)  # cloth frame: +x = +col, +y = -row (= +v)
    length = np.linalg.norm(vec, axis=1)
    unit = vec / length[:, None]

    c11, c22, g, c1112, c1222 = _rotated_target(mat)
    if max(abs(c1112), abs(c1222)) > 1e-9 * max(c11, c22):
        warn(
            f"material {mat.name!r}: warp_angle {mat.warp_angle:.6g} rad is off the grid axes; the grid cannot "
            f"represent its shear-stretch coupling (C1112 = {c1112:.4g} N/m), which is left out"
        )
    ks = np.zeros(len(types))
    structural = types == int(SpringType.STRUCTURAL)
    along_x = structural & (dr == 0)
    along_y = structural & (dc == 0)
    # cells adjacent to each structural spring: an x-spring in row r has cells above and below
    cells_x = (r[:, 0] > 0).astype(float) + (r[:, 0] < rows - 1)
    cells_y = (c[:, 0] > 0).astype(float) + (c[:, 0] < cols - 1)
    ks[along_x] = (cells_x * 0.5 * (hy / hx) * (c11 - g * hx * hx / (hy * hy)))[along_x]
    ks[along_y] = (cells_y * 0.5 * (hx / hy) * (c22 - g * hy * hy / (hx * hx)))[along_y]
    ks[types == int(SpringType.SHEAR)] = g * (hx * hx + hy * hy) / (2.0 * hx * hy)

    is_bend = types == int(SpringType.BEND)
    if is_bend.any():
        n_mat = unit[is_bend] @ _frame(mat.warp_angle)  # material components (R^T n)
        rigidity = mat.bend_warp * n_mat[:, 0] ** 2 + mat.bend_weft * n_mat[:, 1] ** 2
        kb = bend_spring_stiffness(rigidity, 0.5 * length[is_bend], mat.weight(gravity))
        ks[is_bend] = kb
        # membrane side effect: 2 k_b off each of the two springs the bend spring spans
        b = pairs[is_bend]
        mid = ((r[is_bend, 0] + r[is_bend, 1]) // 2) * cols + (c[is_bend, 0] + c[is_bend, 1]) // 2
        find = _spring_lookup(pairs, rows * cols)
        for end in (0, 1):
            covered = find(b[:, end], mid)
            assert np.all(covered >= 0), "a bend spring spans a missing spring"
            np.subtract.at(ks, covered, 2.0 * kb)
    clamped = _clamp(ks, mat)
    mass = _grid_masses(mat.density, rows, cols, hx, hy)
    area = width * height
    lattice = np.einsum("s,sk->k", ks * length**2, _quartic(unit)) / area
    target = np.array([c11, c22, g, c1112, c1222])
    error = float(_relative_energy_error(lattice - target, target))
    kd = _damping(mat, ks, types, pairs, mass, stretch_damping)
    return MaterialSprings(pairs, types, ks, kd, _compression(mat, types), mass, error, clamped)


def _clamp(ks: np.ndarray, mat: Material) -> int:
    low = ks < 0.0
    count = int(np.count_nonzero(low))
    if count:
        warn(
            f"material {mat.name!r}: {count} membrane springs clamped at 0 N/m (bend springs stiffer than the "
            f"membrane at this spacing: use --bend dihedral; or cells so long and thin that the shear diagonals "
            f"alone are stiffer along them than the material)"
        )
        ks[low] = 0.0
    return count


def _grid_masses(density: float, rows: int, cols: int, hx: float, hy: float) -> np.ndarray:
    wx = np.full(cols, hx)
    wx[[0, -1]] *= 0.5
    wy = np.full(rows, hy)
    wy[[0, -1]] *= 0.5
    return (density * np.outer(wy, wx)).ravel()


# -- triangle (and quad) meshes ------------------------------------------------------------------


def mesh_spring_params(
    mat,
    vertices,
    triangles,
    pairs,
    types,
    uv=None,
    stretch_damping: str = "ratio",
    gravity: float = GRAVITY,
    name: str | None = None,
    warn_fit: bool = True,
) -> MaterialSprings:
    """Spring parameters of ``mat`` on a mesh cloth's springs (``pairs``, ``types`` as from
    :func:`~warpcloth.sim.mesh.mesh_springs`, in that order).

    Faces: each triangle, or, where a shear spring lies on an interior edge (``quads=True``
    meshes), the quad of the two triangles with both diagonals. Per face, in its rest material
    frame (warp = the UV u axis if ``uv`` is given; without uv, on a quad the one of its two side
    directions that the whole connected quad region's side family nearer global +x gives
    (:func:`_lattice_axes`), on a triangle global +x projected into it; turned by ``warp_angle``),
    with edge springs k of direction n_k, length L_k and face area A:
    unknowns c_k = ks_k L_k^2 / A >= 0 fit the 5 components of the fully symmetric tensor
    (C11, C22, C12 = G, 0, 0) in the Frobenius norm (weights sqrt(1, 1, 6, 4, 4)): the minimum-norm
    least-squares solution where it is >= 0, else non-negative least squares. The face adds
    c_k A / L_k^2 to spring k. Bend springs (:func:`bend_spring_stiffness`, h = L / 2) have their
    membrane energy taken from the faces they cross (across an interior edge: its two triangles;
    along a straight line u-v-w: the faces of u-v and v-w) before the fit.

    Exact where each face's fit is exact: quads on rectangles (then the springs equal
    :func:`grid_spring_params`'), equilateral triangles for an isotropic Cauchy material
    (G = S / 3). A triangle with three spring directions cannot carry G much below S / 3, and a
    right triangle (one diagonal) leaves a shear-stretch coupling: ``membrane_error`` (the
    largest relative energy error of any face) says how far the lattice is from the material.
    Masses: rho times the vertex area (a third of each adjacent triangle). Damping as in
    :func:`grid_spring_params`. Structural or shear springs the fit leaves at 0 N/m are counted
    (``clamped``) and warned about by family, naming the mesh (``name``) and the material;
    ``warn_fit=False`` (a caller that mends them itself, and says so) only counts them.
    """
    mat = material(mat)
    gravity = require_positive("gravity", gravity, "m/s^2")
    v, t = check_mesh(vertices, triangles)
    n = v.shape[0]
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    types = np.asarray(types, dtype=np.int32).reshape(-1)
    require(
        types.shape[0] == pairs.shape[0],
        f"types must have one value per spring ({pairs.shape[0]}), got {types.shape[0]}",
    )
    if pairs.size:
        require(pairs.min() >= 0 and pairs.max() < n, f"spring particle indices must be in 0..{n - 1}")
    topo = mesh_topology(t, n)
    find = _spring_lookup(pairs, n)
    edge_spring = find(topo.edges[:, 0], topo.edges[:, 1])
    missing = np.flatnonzero((edge_spring < 0) | (types[np.maximum(edge_spring, 0)] == int(SpringType.BEND)))
    if missing.size:
        e = topo.edges[missing[0]]
        raise WarpclothError(
            f"mesh edge ({int(e[0])}, {int(e[1])}) has no structural or shear spring: the pairs "
            "must come from mesh_springs(vertices, triangles)"
        )

    faces, face_tris = _faces(topo, types, edge_spring, find, t)
    where = f"mesh {name!r}" if name else f"a mesh of {n:,} vertices"
    axes = None if uv is not None else _lattice_axes(v, pairs, faces, mat, where)
    _normal, frame_u, frame_v = _face_frames(v, t, face_tris, uv, mat.warp_angle, axes)
    tri_area = triangle_areas(v, t)
    face_area = np.array([tri_area[list(ft)].sum() for ft in face_tris])
    target = np.outer(face_area, _target(mat))  # A_f * C, reduced by the bend springs below

    ks = np.zeros(pairs.shape[0])
    rest = v[pairs[:, 1]] - v[pairs[:, 0]]
    length = np.linalg.norm(rest, axis=1)
    is_bend = np.flatnonzero(types == int(SpringType.BEND))
    if is_bend.size:
        tri_face = np.full(t.shape[0], -1, dtype=np.int64)
        for f, ft in enumerate(face_tris):
            tri_face[list(ft)] = f
        sb, sf, sw = _bend_faces(v, topo, pairs[is_bend], tri_face)
        first_face = np.full(is_bend.size, -1, dtype=np.int64)
        first_face[sb[::-1]] = sf[::-1]  # the first face listed for each bend spring
        n_mat = _in_frame(rest[is_bend], frame_u[first_face], frame_v[first_face])
        rigidity = mat.bend_warp * n_mat[:, 0] ** 2 + mat.bend_weft * n_mat[:, 1] ** 2
        kb = bend_spring_stiffness(rigidity, 0.5 * length[is_bend], mat.weight(gravity))
        ks[is_bend] = kb
        nb = _in_frame(rest[is_bend[sb]], frame_u[sf], frame_v[sf])
        np.subtract.at(target, sf, (sw * kb[sb] * length[is_bend[sb]] ** 2)[:, None] * _quartic(nb))

    low, high = np.zeros(len(faces)), np.zeros(len(faces))  # per face: the energy's relative range
    target_unit = _target(mat)
    for size in sorted({len(e) for e in faces}):
        group = [f for f, e in enumerate(faces) if len(e) == size]
        springs = np.array([faces[f] for f in group], dtype=np.int64)  # (F, size)
        fu, fv = frame_u[group][:, None, :], frame_v[group][:, None, :]
        d = rest[springs]
        nk = _in_frame(d.reshape(-1, 3), np.repeat(fu[:, 0], size, 0), np.repeat(fv[:, 0], size, 0))
        nk = nk.reshape(len(group), size, 2)
        m = np.swapaxes(_quartic(nk), 1, 2) * _FROB[None, :, None]  # (F, 5, size)
        rhs = target[group] / face_area[group][:, None] * _FROB[None, :]  # (F, 5)
        coef = _fit(m, rhs)
        np.add.at(ks, springs.ravel(), (coef * face_area[group][:, None] / length[springs] ** 2).ravel())
        fitted = np.einsum("fks,fs->fk", m, coef) / _FROB
        delta = fitted - target[group] / face_area[group][:, None]
        low[group], high[group] = _relative_energy_range(delta, target_unit)
    error = float(max(np.max(-low), np.max(high)))
    clamped = _warn_zero_springs(ks, types, mat, where, faces, low, high, warn_fit)
    mass = lumped_masses(v, t, density=mat.density)
    kd = _damping(mat, ks, types, pairs, mass, stretch_damping)
    return MaterialSprings(pairs.astype(np.int32), types, ks, kd, _compression(mat, types), mass, error, clamped)


def _faces(topo, types, edge_spring, find, t):
    """Faces as lists of spring indices, and the triangles of each face."""
    shear_edge = topo.interior & (types[edge_spring] == int(SpringType.SHEAR))
    faces, face_tris = [], []
    in_quad = np.zeros(t.shape[0], dtype=bool)
    for e in np.flatnonzero(shear_edge):
        t0, t1 = (int(x) for x in topo.edge_tris[e])
        if in_quad[t0] or in_quad[t1]:
            raise WarpclothError(
                f"mesh triangle {t0 if in_quad[t0] else t1} has two shear edges: a triangle can be in one quad only"
            )
        other = int(find(topo.opposite[e, 0], topo.opposite[e, 1]))
        if other < 0 or types[other] != int(SpringType.SHEAR):
            a, b = (int(x) for x in topo.opposite[e])
            raise WarpclothError(
                f"quad of triangles {t0} and {t1}: its second diagonal ({a}, {b}) is not a shear spring"
            )
        sides = {int(edge_spring[h]) for h in np.concatenate([topo.half_edge[t0], topo.half_edge[t1]]) if h != e}
        faces.append(sorted(sides) + [int(edge_spring[e]), other])
        face_tris.append((t0, t1))
        in_quad[[t0, t1]] = True
    for k in np.flatnonzero(~in_quad):
        sides = [int(edge_spring[h]) for h in topo.half_edge[k]]
        faces.append(sides)
        face_tris.append((int(k),))
    return faces, face_tris


def _face_frames(v, t, face_tris, uv, warp_angle, axes=None):
    """Per face: unit normal, warp and weft directions (3-D, in the face's plane). Without uv,
    ``axes`` (F, 3; NaN where none) gives a face's first axis (before ``warp_angle``)."""
    a, b, c = (v[t[:, k]] for k in range(3))
    e1, e2 = b - a, c - a
    tri_n = np.cross(e1, e2)  # |n| = 2 area
    if uv is not None:
        uvc = np.asarray(uv, dtype=np.float64)
        if uvc.shape == (v.shape[0], 2):
            uvc = uvc[t]
        require(
            uvc.shape == (t.shape[0], 3, 2),
            f"uv must have shape (T, 3, 2) per corner or (N, 2) per vertex, got {uvc.shape}",
        )
        require(bool(np.all(np.isfinite(uvc))), "uv must be finite numbers")
        du1, dv1 = (uvc[:, 1] - uvc[:, 0]).T
        du2, dv2 = (uvc[:, 2] - uvc[:, 0]).T
        det = du1 * dv2 - du2 * dv1
        bad = np.flatnonzero(np.abs(det) < 1e-14)
        if bad.size:
            raise WarpclothError(
                f"uv of triangle {int(bad[0])} is degenerate (zero area): the warp direction is undefined there"
            )
        tri_u = (e1 * dv2[:, None] - e2 * dv1[:, None]) / det[:, None]  # dX/du
        tri_v = (e2 * du1[:, None] - e1 * du2[:, None]) / det[:, None]  # dX/dv
    else:
        tri_u = np.broadcast_to(np.array([1.0, 0.0, 0.0]), tri_n.shape)
        tri_v = np.broadcast_to(np.array([0.0, 1.0, 0.0]), tri_n.shape)
    normal = np.array([tri_n[list(ft)].sum(axis=0) for ft in face_tris])
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    ref_u = np.array([tri_u[list(ft)].sum(axis=0) for ft in face_tris])
    ref_v = np.array([tri_v[list(ft)].sum(axis=0) for ft in face_tris])
    ax = _in_plane(ref_u, normal)
    if uv is None:  # a face perpendicular to x takes global z as its first axis
        weak = np.linalg.norm(ax, axis=1) < 1e-6
        ax[weak] = _in_plane(np.broadcast_to([0.0, 0.0, 1.0], ref_u.shape), normal)[weak]
        if axes is not None:  # a quad's own side direction (_lattice_axes)
            given = np.all(np.isfinite(axes), axis=1)
            ax[given] = _in_plane(axes[given], normal[given])
    ax /= np.linalg.norm(ax, axis=1, keepdims=True)
    ay = np.cross(normal, ax)
    if uv is None:  # the second axis along +y, or +z where y is (nearly) along the normal or the first axis
        py = _in_plane(ref_v, normal)
        py -= np.einsum("fi,fi->f", py, ax)[:, None] * ax
        pz = _in_plane(np.broadcast_to([0.0, 0.0, 1.0], ref_v.shape), normal)
        pz -= np.einsum("fi,fi->f", pz, ax)[:, None] * ax
        ref_v = np.where((np.linalg.norm(py, axis=1) >= np.linalg.norm(pz, axis=1))[:, None], py, pz)
    flip = np.einsum("fi,fi->f", ay, ref_v) < 0.0  # the second axis points along +v
    ay[flip] *= -1.0
    ca, sa = math.cos(warp_angle), math.sin(warp_angle)
    warp = ca * ax + sa * ay
    weft = -sa * ax + ca * ay
    return normal, warp, weft


def _in_plane(d, normal):
    return d - np.einsum("fi,fi->f", d, normal)[:, None] * normal


def _in_frame(d, fu, fv):
    """Unit 2-D material-frame directions of 3-D vectors d (projected into each face)."""
    p = np.stack([np.einsum("si,si->s", d, fu), np.einsum("si,si->s", d, fv)], axis=1)
    return p / np.linalg.norm(p, axis=1, keepdims=True)


def _lattice_axes(v, pairs, faces, mat: Material, where: str) -> np.ndarray:
    """Without uv, each quad face's first material axis (F, 3; NaN on triangle faces): the mean
    direction of one of its two pairs of opposite sides. The side families are followed from quad
    to quad across shared sides (a tube's rings stay one family, its meridians the other), and in
    each connected quad region the family more nearly along global +x (by the summed |cos| of its
    sides; z where no side has an x component) is the warp: the quad's frame is then its own, so a
    rectangle is fitted exactly (a frame at an angle to the sides needs C1112 != 0, which four
    spring directions cannot carry, and the fit drives springs to 0). Where the families cannot be
    followed consistently (an odd number of quads around a vertex), each quad takes its own nearer
    side and an anisotropic material is warned about."""
    axes = np.full((len(faces), 3), np.nan)
    quads = np.array([f for f, s in enumerate(faces) if len(s) == 6], dtype=np.int64)
    if quads.size == 0:
        return axes
    sides = np.array([faces[f][:4] for f in quads], dtype=np.int64)  # (Q, 4) structural springs
    ends = pairs[sides]  # (Q, 4, 2)
    disjoint = ~np.any(ends[:, :, None, :, None] == ends[:, None, :, None, :], axis=(3, 4))  # (Q, 4, 4)
    opposite0 = np.argmax(disjoint[:, 0, :], axis=1)  # side 0's opposite side
    slot = np.ones((quads.size, 4), dtype=np.int64)  # which pair (0 or 1) each side is in
    slot[:, 0] = 0
    slot[np.arange(quads.size), opposite0] = 0
    vec = v[pairs[sides, 1]] - v[pairs[sides, 0]]  # (Q, 4, 3)
    direction = np.zeros((quads.size, 2, 3))
    for p in (0, 1):
        ab = np.argsort(slot != p, axis=1, kind="stable")[:, :2]  # (Q, 2) the pair's two sides
        d0 = vec[np.arange(quads.size), ab[:, 0]]
        d1 = vec[np.arange(quads.size), ab[:, 1]]
        d1 = np.where((np.einsum("qi,qi->q", d0, d1) < 0.0)[:, None], -d1, d1)
        d = d0 / np.linalg.norm(d0, axis=1, keepdims=True) + d1 / np.linalg.norm(d1, axis=1, keepdims=True)
        direction[:, p] = d / np.linalg.norm(d, axis=1, keepdims=True)
    score = np.abs(direction[:, :, 0]) + 1e-9 * np.abs(direction[:, :, 2])  # along x; z breaks ties
    label, conflicted = _side_families(sides, slot)
    _, comp = np.unique(label[:, 0], return_inverse=True)  # the connected region of each quad
    fam = label[:, 1]  # the family of each quad's pair 0
    family_score = [np.bincount(comp, np.where(fam == f, score[:, 0], score[:, 1])) for f in (0, 1)]
    warp_family = np.where(family_score[0] >= family_score[1], 0, 1)[comp]
    pick = np.where(fam == warp_family, 0, 1)  # the warp pair of each quad
    if conflicted.any():
        mine = np.flatnonzero(conflicted)
        pick[mine] = np.where(score[mine, 0] >= score[mine, 1], 0, 1)
        if mat.stretch_warp != mat.stretch_weft or mat.bend_warp != mat.bend_weft:
            warn(
                f"material {mat.name!r} on {where}: without texture coordinates the warp of "
                f"{int(conflicted.sum()):,} quads cannot follow the mesh's side families (an odd number of quads "
                "around a vertex); there each quad takes as warp its side nearer global +x, so warp and weft "
                "may swap between neighbours: give the mesh uv (u along the warp) to set the warp"
            )
    chosen = direction[np.arange(quads.size), pick]
    chosen = np.where((chosen[:, :1] < 0.0) | ((chosen[:, :1] == 0.0) & (chosen[:, 2:] < 0.0)), -chosen, chosen)
    axes[quads] = chosen
    return axes


def _side_families(sides: np.ndarray, slot: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Follow the side families across shared sides: per quad (component, family of its pair 0),
    and whether its component met a contradiction (quads around a vertex of odd valence)."""
    q_count = sides.shape[0]
    flat = sides.ravel()
    order = np.argsort(flat, kind="stable")
    same = np.flatnonzero(flat[order][1:] == flat[order][:-1])  # a side shared by two quads
    a, b = order[same] // 4, order[same + 1] // 4
    parity = slot.ravel()[order[same]] ^ slot.ravel()[order[same + 1]]
    adjacency = [[] for _ in range(q_count)]
    for x, y, p in zip(a.tolist(), b.tolist(), parity.tolist()):
        adjacency[x].append((y, p))
        adjacency[y].append((x, p))
    label = np.full((q_count, 2), -1, dtype=np.int64)
    bad_component = set()
    for start in range(q_count):
        if label[start, 0] >= 0:
            continue
        label[start] = (start, 0)
        stack = [start]
        while stack:
            x = stack.pop()
            for y, p in adjacency[x]:
                fam = label[x, 1] ^ p
                if label[y, 0] < 0:
                    label[y] = (start, fam)
                    stack.append(y)
                elif label[y, 1] != fam:
                    bad_component.add(start)
    conflicted = np.isin(label[:, 0], list(bad_component))
    return label, conflicted


def _warn_zero_springs(ks, types, mat: Material, where: str, faces, low, high, say: bool = True) -> int:
    """Count the structural and shear springs at 0 N/m in faces whose fit is off (relative energy
    error above :data:`FIT_TOLERANCE`; a zero in a face fitted within it loses nothing: its other
    springs carry the material) and warn, by family, with what the lattice then does and what to
    do; without such springs, warn where the fit is off by more than :data:`MEMBRANE_WARNING`."""
    inexact = np.flatnonzero(np.maximum(-low, high) > FIT_TOLERANCE)
    in_bad = np.zeros(ks.shape[0], dtype=bool)
    for f in inexact:
        in_bad[faces[f]] = True
    if any(len(faces[f]) == 6 for f in inexact):
        fix = (
            "its quads are too far from rectangles, or too long and thin, for this material (their skewed sides "
            "or diagonals alone are stiffer than it): refine the mesh, make its quads closer to squares, or use "
            "a material with more shear"
        )
    else:
        fix = "a triangle's three springs carry no shear far from stretch / 3: use quads=True on a grid-like mesh"
    effect = (
        f"the lattice's energy is up to {100 * np.max(high):.3g} % above and {100 * np.max(-low):.3g} % below "
        f"the material's under some uniform strain"
    )
    total = 0
    for family in (SpringType.STRUCTURAL, SpringType.SHEAR):
        mine = types == int(family)
        zero = int(np.count_nonzero(mine & in_bad & (ks <= 0.0)))
        total += zero
        if zero and say:
            warn(
                f"material {mat.name!r} on {where}: {zero:,} of {int(mine.sum()):,} {family.name.lower()} springs "
                f"got stiffness 0 N/m: its faces cannot carry stretch {mat.stretch_warp:g}/{mat.stretch_weft:g} "
                f"N/m with shear {mat.shear:g} N/m, and {effect}; {fix}"
            )
    if say and not total and max(np.max(high), np.max(-low)) > MEMBRANE_WARNING:
        warn(f"material {mat.name!r} on {where}: {effect} (membrane_error); {fix}")
    return total


def _bend_faces(v, topo, bend_pairs, tri_face):
    """Arrays (bend index, face, share): the faces whose area a bend spring's membrane energy is
    taken from, shares summing to 1 per bend spring (one face may appear twice: shares add)."""
    n = np.int64(v.shape[0])
    interior = np.flatnonzero(topo.interior)
    opp = topo.opposite[interior]
    opp_keys = np.minimum(opp[:, 0], opp[:, 1]) * n + np.maximum(opp[:, 0], opp[:, 1])
    order = np.argsort(opp_keys)
    opp_sorted = opp_keys[order]
    edge_keys = topo.edges[:, 0] * n + topo.edges[:, 1]  # sorted (mesh_topology)
    edge_tri = np.empty(len(topo.edges), dtype=np.int64)  # one triangle of each edge
    edge_tri[topo.half_edge.ravel()] = np.repeat(np.arange(topo.half_edge.shape[0]), 3)
    src = np.concatenate([topo.edges[:, 0], topo.edges[:, 1]])  # neighbours along mesh edges (CSR)
    dst = np.concatenate([topo.edges[:, 1], topo.edges[:, 0]])
    eid = np.concatenate([np.arange(len(topo.edges))] * 2)
    o = np.argsort(src, kind="stable")
    src, dst, eid = src[o], dst[o], eid[o]
    ptr = np.searchsorted(src, np.arange(n + 1))
    sb, sf, sw = [], [], []

    def add(b, tris, share):
        for tri in tris:
            sb.append(b)
            sf.append(int(tri_face[tri]))
            sw.append(share / len(tris))

    for b, (u, w) in enumerate(np.asarray(bend_pairs, dtype=np.int64)):
        key = min(u, w) * n + max(u, w)
        at = np.searchsorted(opp_sorted, key)
        if at < opp_sorted.size and opp_sorted[at] == key:  # across an interior edge: its two triangles
            add(b, topo.edge_tris[interior[order[at]]], 1.0)
            continue
        nbr, nbr_e = dst[ptr[u] : ptr[u + 1]], eid[ptr[u] : ptr[u + 1]]  # along a line u - mid - w
        lo, hi = np.minimum(nbr, w), np.maximum(nbr, w)
        pos = np.minimum(np.searchsorted(edge_keys, lo * n + hi), edge_keys.size - 1)
        ok = edge_keys[pos] == lo * n + hi
        if not ok.any():
            raise WarpclothError(
                f"bend spring ({int(u)}, {int(w)}) is neither across an interior edge nor along two "
                "mesh edges: the pairs must come from mesh_springs(vertices, triangles)"
            )
        k = int(np.argmin(np.linalg.norm(v[nbr[ok]] - 0.5 * (v[u] + v[w]), axis=1)))
        for edge in (int(nbr_e[ok][k]), int(pos[ok][k])):
            add(b, topo.edge_tris[edge] if topo.interior[edge] else [edge_tri[edge]], 0.5)
    return np.asarray(sb, dtype=np.int64), np.asarray(sf, dtype=np.int64), np.asarray(sw)


def _fit(m: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """c >= 0 with m c ~ rhs per face: minimum-norm least squares, NNLS where that has c < 0."""
    coef = np.einsum("fsk,fk->fs", np.linalg.pinv(m, rcond=1e-10), rhs)
    scale = np.max(np.abs(rhs), axis=1, keepdims=True)
    bad = np.flatnonzero(np.any(coef < -1e-12 * scale, axis=1))
    if bad.size:
        from scipy.optimize import nnls  # noqa: PLC0415 (SciPy loads only where this solve runs: stepping loads none)

        size = m.shape[2]
        for f in bad:
            mu = 1e-8 * np.linalg.norm(m[f]) ** 2  # small Tikhonov term: splits parallel sides evenly
            a = np.vstack([m[f], math.sqrt(mu) * np.eye(size)])
            coef[f] = nnls(a, np.concatenate([rhs[f], np.zeros(size)]))[0]
    return np.maximum(coef, 0.0)


# -- cloth models of a material -------------------------------------------------------------------


def material_grid_cloth(
    mat,
    rows: int,
    cols: int,
    width: float = 1.0,
    height: float = 1.0,
    pins=(),
    origin=(0.0, 0.0, 0.0),
    plane: str = "vertical",
    bend: str | BendModel = BendModel.PROVOT,
    device: str | None = None,
) -> ClothModel:
    """A rows x cols grid cloth (as :func:`~warpcloth.sim.grid.build_grid_cloth`) made of ``mat`` (a
    :class:`Material` or a preset's name): per-spring ks, kd and compression factors and masses by
    vertex area from :func:`grid_spring_params`; with ``bend="dihedral"`` hinges of the material's
    B_warp / B_weft along its warp (:func:`~warpcloth.sim.hinges.grid_hinges`) with the Rayleigh
    damping kd_e = beta_b k_e (:meth:`Material.bend_damping_time`): the same at every mesh size."""
    mat = material(mat)
    try:
        bend = BendModel(bend)
    except ValueError:
        raise WarpclothError(f"bend must be one of {[b.value for b in BendModel]}, got {bend!r}") from None
    width = require_positive("width", width, "m")
    height = require_positive("height", height, "m")
    origin = require_vector("origin", origin, 3, "m")
    device = resolve_device(device)
    minimum = 2 if bend in (BendModel.NONE, BendModel.DIHEDRAL) else 3  # as grid_spring_params
    rows, cols = require_int("rows", rows, minimum), require_int("cols", cols, minimum)
    require_memory(f"a {rows} x {cols} cloth", grid_memory_estimate(rows, cols, bend), device)  # before any array
    springs = grid_spring_params(mat, rows, cols, width, height, bend=bend)
    q = grid_positions(rows, cols, width, height, origin, plane)
    model = build_model(
        q,
        springs.pairs,
        springs.types,
        springs.mass,
        None,
        pins,
        grid_triangles(rows, cols),
        device,
        spring_stiffness=springs.stiffness,
        spring_damping=springs.damping,
        spring_compression=springs.compression,
    )
    uv = grid_uvs(rows, cols)[model.host.tris].reshape(-1, 2)
    model = dataclasses.replace(
        model,
        rows=rows,
        cols=cols,
        width=width,
        height=height,
        bend=bend,
        total_mass=float(springs.mass.sum()),
        host=dataclasses.replace(model.host, uv=uv),
        material=mat,
    )
    if bend == BendModel.DIHEDRAL:
        hinges = grid_hinges(
            model.host.q, rows, cols, mat.bend_warp, mat.bend_weft, mat.warp_angle, mat.bend_damping_time()
        )
        model = model.with_hinges(hinges)
    return model


def material_mesh_cloth(
    mat,
    vertices,
    triangles=None,
    pins=(),
    pin_groups=(),
    pin_where=None,
    groups: dict | None = None,
    uv=None,
    quads: bool = False,
    bend: bool | str = True,
    device: str | None = None,
    warn_fit: bool = True,
) -> ClothModel:
    """A cloth from a triangle mesh (as :func:`~warpcloth.sim.mesh.build_mesh_cloth`, same
    arguments) made of ``mat``: per-spring ks, kd and compression factors from
    :func:`mesh_spring_params` (warp = the UV u axis where the mesh has UVs; else on quads the side
    family nearer global +x, on triangles global +x), masses
    rho times the vertex area, and with ``bend="dihedral"`` hinges of the material's B_warp /
    B_weft (:func:`~warpcloth.sim.hinges.mesh_hinges`) with Rayleigh damping beta_b k_e. Springs
    the fit leaves at 0 N/m are warned about unless ``warn_fit=False`` (:func:`mesh_spring_params`)."""
    mat = material(mat)
    name = None
    if isinstance(vertices, TriangleMesh):
        mesh = vertices
        name = mesh.source
        vertices, triangles = mesh.vertices, mesh.triangles
        uv = mesh.uv if uv is None else uv
        groups = {**mesh.groups, **(groups or {})}
    v, t = check_mesh(vertices, triangles)
    device = resolve_device(device)
    require_memory(
        f"a mesh cloth of {v.shape[0]:,} vertices and {t.shape[0]:,} triangles",
        mesh_memory_estimate(v.shape[0], t.shape[0]),
        device,
    )
    pinned = resolve_pins(v, pins, pin_groups, pin_where, groups)
    bend_model = mesh_bend(bend)
    pairs, types = mesh_springs(v, t, quads=quads, bend=bend_model in (BendModel.PROVOT, BendModel.CHOI_KO))
    springs = mesh_spring_params(mat, v, t, pairs, types, uv=uv, name=name, warn_fit=warn_fit)
    model = build_model(
        v,
        pairs,
        types,
        springs.mass,
        None,
        pinned,
        t,
        device,
        spring_stiffness=springs.stiffness,
        spring_damping=springs.damping,
        spring_compression=springs.compression,
    )
    host = dataclasses.replace(
        model.host,
        uv=corner_uvs(uv, t, v.shape[0]) if uv is not None else None,
        groups={k: np.asarray(g, dtype=np.int64) for k, g in (groups or {}).items()},
    )
    model = dataclasses.replace(model, host=host, material=mat)
    if bend_model == BendModel.DIHEDRAL:
        vertex_uv = None
        if uv is not None:  # per vertex (at a UV seam, from one of its triangles)
            vertex_uv = np.zeros((v.shape[0], 2))
            vertex_uv[t.ravel()] = corner_uvs(uv, t, v.shape[0]).astype(np.float64)
        hinges = mesh_hinges(
            model.host.q,
            t,
            mat.bend_warp,
            mat.bend_weft,
            uv=vertex_uv,
            warp_angle=mat.warp_angle,
            damping_time=mat.bend_damping_time(),
        )
        model = dataclasses.replace(model.with_hinges(hinges), bend=BendModel.DIHEDRAL)
    return model


__all__ = [
    "GRAVITY",
    "MATERIAL_VALUES",
    "PRESETS",
    "STRETCH_DAMPING_MODES",
    "Material",
    "MaterialSprings",
    "bend_spring_stiffness",
    "grid_spring_params",
    "material",
    "material_grid_cloth",
    "material_mesh_cloth",
    "material_with",
    "mesh_spring_params",
]
