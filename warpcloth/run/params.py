"""Run parameters, each declared once.

A :class:`Param` holds everything about one parameter of a run: its one spelling (the XML
attribute, the CSV column, the run-key field, the :class:`~warpcloth.scenarios.ScenarioConfig`
field; the CLI flag is the same name with dashes), its type (a parser from text), unit, default,
check and help. From :data:`PARAMS` come:

* the CLI flags of ``warpcloth run`` and ``warpcloth max-dt`` (:func:`add_flags`) and the
  :class:`~warpcloth.scenarios.ScenarioConfig` they make (:func:`config_values`);
* the attributes of an XML test list and their checks (:mod:`warpcloth.lab.testlist`);
* the keys of a scenario file (TOML values, typed: :meth:`Param.from_typed`,
  :mod:`warpcloth.scenarios.file`);
* the parameter columns of the sweep's CSV and the run key that ``--resume`` matches
  (:mod:`warpcloth.lab.sweep`, :class:`~warpcloth.lab.testlist.RunSpec`);
* the attribute table of ``docs/sweep.md`` (:func:`markdown_table`; a test keeps it in step).

Adding a parameter is one :class:`Param` here plus its use (a ScenarioConfig field, a Simulator
argument). Integrator options are declared by the integrators themselves
(:class:`~warpcloth.integrators.Option`) and reach the CLI, XML and CSV the same way. Old spellings
(XML ``timestep``, ``cap``, ``scenarios``; the CSV's ``timestep``, ``cap``, ``ks``/``kd`` columns; CLI
``--fps`` and max-dt's ``--precision``, ``--duration``, ``--start``) stay accepted one release, with a
note on stderr: docs/sweep.md, "Old spellings".
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from warpcloth.errors import FLOAT32_MAX, WarpclothError
from warpcloth.integrators import check_integrator_name
from warpcloth.run.metrics import DEFAULT_INSTABILITY_STRAIN
from warpcloth.run.parse import collider_specs
from warpcloth.sim.device import device_name
from warpcloth.sim.material import PRESETS

SPRING_TYPES = ("structural", "shear", "bend")


def _shown(value) -> str:
    """A value as a message shows it: its repr, cut to 60 characters."""
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


#: The defaults of a sweep where they differ from a single run's (the seed's test plan, 4.3):
#: a wall-clock cap of one minute per run, sampling at the seed's real-time threshold of 30 FPS.
SWEEP_WALL_CAP = 60.0
SWEEP_FRAME_RATE = 30.0
#: A sweep's simulated duration [s]: an upper bound for the sheet (it ends at equilibrium), the
#: length of a flag run; other scenarios use their own default.
SWEEP_DURATION = {"sheet": 60.0, "flag": 10.0}
DEFAULT_MAXDT_PRECISION = 0.02
DEFAULT_MAXDT_DURATION = 2.0


# -- values: parsers from text (each raises ValueError naming what is allowed) ----------------
@dataclass(frozen=True)
class TimeStep:
    """A requested time step: a value [s], the integrator's default, or a fraction of the
    largest stable dt (``max`` / ``max*F``)."""

    kind: str  # "value", "default" or "max"
    value: float | None = None  # dt [s] for "value", the factor F for "max"

    def __str__(self) -> str:
        if self.kind == "value":
            return repr(self.value)
        if self.kind == "max":
            return "max" if self.value == 1.0 else f"max*{self.value!r}"
        return "default"

    @property
    def uses_max(self) -> bool:
        return self.kind == "max"


def number(text: str) -> float:
    try:
        v = float(text)
    except (TypeError, ValueError):
        raise ValueError(f"{_shown(text)} is not a number") from None
    if not math.isfinite(v):
        raise ValueError(f"{_shown(text)} is not a finite number")
    if abs(v) > FLOAT32_MAX:
        raise ValueError(f"{_shown(text)} does not fit in float32 (|value| <= {FLOAT32_MAX:.4g})")
    return v


def positive(text: str) -> float:
    v = number(text)
    if not v > 0.0:
        raise ValueError(f"{_shown(text)} must be > 0")
    return v


def non_negative(text: str) -> float:
    v = number(text)
    if not v >= 0.0:
        raise ValueError(f"{_shown(text)} must be >= 0")
    return v


def grid_dim(text: str) -> int:
    try:
        v = int(text)
    except (TypeError, ValueError):
        raise ValueError(f"{_shown(text)} is not an integer") from None
    if v < 3:
        raise ValueError(f"{_shown(text)} must be an integer >= 3")
    return v


def size(text: str) -> tuple[int, int]:
    parts = text.lower().split("x")
    if len(parts) == 1:
        n = grid_dim(parts[0])
        return n, n
    if len(parts) == 2:
        return grid_dim(parts[0]), grid_dim(parts[1])
    raise ValueError(f"{_shown(text)} is not N or ROWSxCOLS")


def number_list(text: str):
    """The CLI's ``--stiffness``: ``'1000'`` -> 1000.0, ``'1000,500,100'`` -> a triple (checked
    where the model is built)."""
    parts = text.split(",")
    if len(parts) > 1 and any(not p.strip() for p in parts):
        raise argparse.ArgumentTypeError(
            f"{_shown(text)} has an empty item: give one number, or three separated by single commas "
            "(structural,shear,bend)"
        )
    try:
        values = [float(p) for p in parts]
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected a number or three comma-separated numbers, got {_shown(text)}"
        ) from None
    if len(values) == 1:
        return values[0]
    if len(values) == 3:
        return tuple(values)
    raise argparse.ArgumentTypeError(
        f"expected a number or three comma-separated numbers (structural,shear,bend), got {_shown(text)}"
    )


def per_type(text: str):
    """``'1000'`` -> 1000.0; ``'1000,500,100'`` -> (1000.0, 500.0, 100.0) (structural, shear, bend)."""
    parts = text.split(",")
    if len(parts) not in (1, 3) or any(not p.strip() for p in parts):
        raise ValueError(
            f"{_shown(text)}: give one number, or three separated by single commas (structural,shear,bend)"
        )
    values = tuple(non_negative(p) for p in parts)
    return values[0] if len(values) == 1 else values


def timestep(text: str) -> TimeStep:
    t = text.lower()
    if t == "default":
        return TimeStep("default")
    if t == "max":
        return TimeStep("max", 1.0)
    if t.startswith("max*"):
        try:
            return TimeStep("max", positive(t[4:]))
        except ValueError:
            raise ValueError(f"{_shown(text)}: the factor in max*F must be a number > 0") from None
    try:
        return TimeStep("value", positive(text))
    except ValueError:
        raise ValueError(f"{_shown(text)} is not a time step > 0 [s], 'max', 'max*F' or 'default'") from None


def wall_cap(text: str) -> float | None:
    if text.lower() == "none":
        return None
    try:
        return positive(text)
    except ValueError:
        raise ValueError(f"{_shown(text)} is not a number of seconds > 0 or 'none'") from None


def cli_wall_cap(text: str) -> float | None:
    """The CLI's ``--wall-cap``: seconds (checked where the run starts) or ``none``."""
    if text.lower() == "none":
        return None
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"invalid float value: {_shown(text)} (seconds, or 'none')") from None


def fraction(text: str) -> float:
    v = number(text)
    if not 0.0 < v < 1.0:
        raise ValueError(f"{_shown(text)} must be between 0 and 1 (relative, e.g. 0.02)")
    return v


def switch(text: str) -> str:
    """``on`` or ``off`` (a scenario file may also say true or false)."""
    if text not in ("on", "off"):
        raise ValueError(f"{_shown(text)} must be on or off")
    return text


def choice(*choices: str, what: str):
    def parse(text: str) -> str:
        if text not in choices:
            raise ValueError(f"unknown {what} {_shown(text)}; choose from {', '.join(choices)}")
        return text

    return parse


def integrator(text: str) -> str:
    """A registered integrator's name, or ``all`` (a test list's every one)."""
    return check_integrator_name(text, allow_all=True)


def scenario(text: str) -> str:
    """A scenario name or a scenario file (.toml); whether it exists is checked where scenarios
    are known (a layer above this table: :func:`warpcloth.scenarios.check_scenario`)."""
    return text_value(text).strip()


def device(text: str) -> str:
    try:
        return device_name(text)
    except WarpclothError as exc:
        raise ValueError(str(exc)) from None


def colliders(text: str) -> str:
    """One or more colliders joined by ``+`` (``sphere:center=0/1/0,radius=0.3+plane``; a ``+``
    joins where a collider kind follows it, so ``radius=1e+3`` and ``path=a+b.obj`` stay whole); checked
    here (:func:`warpcloth.run.parse.collider_specs`: no file is read), kept as text (the run
    key and the CSV show it as written)."""
    try:
        specs = collider_specs(text)
    except WarpclothError as exc:
        raise ValueError(str(exc)) from None
    return "+".join(spec.text for spec in specs)


def names(text: str) -> str:
    """Comma-separated names (vertex groups)."""
    items = [s.strip() for s in text.split(",")]
    if any(not s for s in items):
        raise ValueError(f"{_shown(text)} has an empty name; separate names with single commas")
    return ",".join(items)


def text_value(text: str) -> str:
    if not text.strip():
        raise ValueError("is empty")
    return text


def _one_or_two(text: str, parse) -> float | tuple:
    parts = text.split(",")
    if len(parts) not in (1, 2) or any(not p.strip() for p in parts):
        raise ValueError(f"{_shown(text)}: give one number, or two separated by a comma (warp,weft)")
    values = tuple(parse(p) for p in parts)
    return values[0] if len(values) == 1 else values


def positive_pair(text: str) -> float | tuple:
    """``'4000'`` -> 4000.0; ``'2028,411'`` -> (2028.0, 411.0) (warp, weft); each > 0."""
    return _one_or_two(text, positive)


def non_negative_pair(text: str) -> float | tuple:
    """``'3e-5'`` -> 3e-05; ``'16e-6,24e-6'`` -> (1.6e-05, 2.4e-05) (warp, weft); each >= 0."""
    return _one_or_two(text, non_negative)


def unit_interval(text: str) -> float:
    v = number(text)
    if not 0.0 <= v <= 1.0:
        raise ValueError(f"{_shown(text)} must be in [0, 1]")
    return v


def angle(text: str) -> float:
    v = number(text)
    if not abs(v) <= math.pi:
        raise ValueError(f"{_shown(text)} must be in [-pi, pi] rad")
    return v


def material_name(text: str) -> str:
    """A material preset (:data:`warpcloth.sim.material.PRESETS`), ``custom`` or ``none``."""
    name = text.strip().lower()
    if name not in (*PRESETS, "custom", "none"):
        raise ValueError(
            f"unknown material {_shown(text)}; choose a preset ({', '.join(PRESETS)}), custom (density, stretch, "
            "shear and bend_rigidity given) or none (per-spring stiffness and damping)"
        )
    return name


# -- the declaration ----------------------------------------------------------------------
_SAME = object()


@dataclass(frozen=True)
class Param:
    """One run parameter.

    Attributes:
        name: the one spelling: XML attribute, CSV column, run-key field and (unless
            ``config`` says otherwise) :class:`~warpcloth.scenarios.ScenarioConfig` field; the
            CLI flag is ``--name-with-dashes``.
        parse: text -> value; raises ``ValueError`` naming the value and what is allowed.
        unit: SI unit ("" when dimensionless).
        help: one line.
        values: what a value may be (docs table).
        group: ``cloth``, ``material``, ``forces``, ``self_collision``, ``integrator``, ``run``, ``mesh`` or ``search``.
        default: the value when not given (None: the scenario's or integrator's own).
        default_doc: the default as the docs say it, where ``default`` is computed.
        sweep_default: a test list's default where it differs from a single run's.
        commands: where it is accepted: ``run``, ``max-dt`` (CLI commands), ``sweep`` (XML).
        positional: on the CLI a positional argument, not a flag.
        flag_aliases / xml_aliases: other accepted spellings (old ones print a note).
        columns: CSV columns (default ``(name,)``; ``()``: none).
        key: in the run key ``always``, when ``set`` (not the default), ``with_max`` (when dt
            is searched), or ``never``.
        search: part of what a max-stable-dt search depends on.
        config: the ScenarioConfig field it feeds (None: none; the default: ``name``).
        to_config: value -> the ScenarioConfig value.
        multi: an XML attribute may hold several values separated by spaces (a product).
        repeat: the CLI flag may be given several times (values joined by ``join``).
        applies: ``grid`` or ``mesh``: refused on a scenario whose cloth is the other kind.
        folds_into: a per-type or size parameter resolved into another one (no column/key).
        cli_type: the CLI's converter where it is more lenient than ``parse`` (the value is then
            checked where it is used, by the Python API, with the API's message); None: ``parse``.
        choices: the allowed values of a choice (argparse shows them).
        cli_help: the CLI's help where it differs from ``help`` (a test list accepts more).
        from_scenario: a test list fills it from the scenario's default when not given (so the
            CSV and the run key show the value used).
    """

    name: str
    parse: Callable[[str], Any]
    unit: str
    help: str
    values: str
    group: str
    default: Any = None
    default_doc: str | None = None
    sweep_default: Any = _SAME
    commands: tuple = ("run", "max-dt", "sweep")
    positional: bool = False
    flag_aliases: tuple = ()
    xml_aliases: tuple = ()
    columns: tuple | None = None
    key: str = "always"
    search: bool = True
    config: Any = _SAME
    to_config: Callable | None = None
    multi: bool = True
    repeat: bool = False
    join: str = "+"
    applies: str | None = None
    folds_into: str | None = None
    from_scenario: bool = False
    metavar: str | None = None
    cli_type: Callable | None = None
    choices: tuple = ()
    cli_help: str | None = None

    @property
    def flag(self) -> str:
        return "--" + self.name.replace("_", "-")

    @property
    def csv_columns(self) -> tuple:
        if self.columns is not None:
            return self.columns
        return () if self.folds_into else (self.name,)

    @property
    def config_field(self) -> str | None:
        if self.folds_into:
            return None
        return self.name if self.config is _SAME else self.config

    def default_for(self, sweep: bool, scenario_name: str | None = None):
        if sweep and self.sweep_default is not _SAME:
            d = self.sweep_default
            return d(scenario_name) if callable(d) else d
        return self.default

    def check(self, text: str):
        """``text`` parsed; raises :class:`WarpclothError` naming the parameter."""
        try:
            return self.parse(text)
        except ValueError as exc:
            raise WarpclothError(f"{self.name}: {exc}") from None

    def from_typed(self, value):
        """A value from a typed file (a scenario file's TOML: numbers, strings, arrays) parsed as
        its text would be, so a file's key has the CLI flag's type, range and unit; a value of
        another type raises ``ValueError`` (``must be a number, got 'abc'``), as ``parse`` does."""
        takes = _TYPED.get(self.parse, "text")
        if takes == "switch" and isinstance(value, bool):
            return "on" if value else "off"
        if isinstance(value, bool) or not isinstance(value, (str, int, float, list)):
            raise ValueError(f"must be {_TYPED_WORDS[takes]}, got {_shown(value)}")
        if isinstance(value, list):
            if (
                takes not in ("per_type", "pair")
                or len(value) != {"per_type": 3, "pair": 2}[takes]
                or any(isinstance(v, bool) or not isinstance(v, (int, float)) for v in value)
            ):
                raise ValueError(f"must be {_TYPED_WORDS[takes]}, got {_shown(value)}")
            return self.parse(",".join(repr(float(v)) for v in value))
        if isinstance(value, str):
            if takes in ("number", "per_type", "pair"):
                raise ValueError(f"must be {_TYPED_WORDS[takes]}, got {_shown(value)}")
            return self.parse(value)
        if takes == "text":
            raise ValueError(f"must be {_TYPED_WORDS[takes]}, got {_shown(value)}")
        return self.parse(repr(value) if isinstance(value, float) else str(value))


#: What a typed file's value of a parameter may be, by its parser (the rest take text).
_TYPED = {
    number: "number",
    positive: "number",
    non_negative: "number",
    fraction: "number",
    grid_dim: "number",
    per_type: "per_type",
    positive_pair: "pair",
    non_negative_pair: "pair",
    unit_interval: "number",
    angle: "number",
    timestep: "number_or_text",
    wall_cap: "number_or_text",
    switch: "switch",
}
_TYPED_WORDS = {
    "number": "a number",
    "per_type": "a number or 3 numbers [structural, shear, bend]",
    "pair": "a number or 2 numbers [warp, weft]",
    "number_or_text": "a number or a string",
    "text": "a string",
    "switch": "true, false, 'on' or 'off'",
}


def _switch_config(value):
    return value == "on"


def _graph_config(value):
    return {"on": True, "off": False, "auto": None}[value]


def _colliders_config(value):
    return None if value is None else collider_specs(value)  # "" is an error (collider_specs), not "no collider"


def _group_config(value):
    return tuple(value.split(",")) if value else None


def _dt_config(value):
    """ScenarioConfig's ``dt`` [s]: a value as given (the CLI's float, or a :class:`TimeStep`),
    None for ``default`` (the integrator's own, computed where the model is built); ``max`` is
    None too: a test list's search finds that dt and gives it (:meth:`RunSpec.config
    <warpcloth.lab.testlist.RunSpec.config>`)."""
    if not isinstance(value, TimeStep):
        return value
    return value.value if value.kind == "value" else None


def _spring_params(kind: str, unit: str, default_doc: str) -> list[Param]:
    base = Param(
        kind,
        per_type,
        unit,
        f"{'ks' if kind == 'stiffness' else 'kd'} of every spring type, or structural,shear,bend",
        "one number >= 0, or three separated by commas",
        "cloth",
        default_doc=default_doc,
        columns=tuple(f"{kind}_{t}" for t in SPRING_TYPES),
        metavar="K",
        cli_type=number_list,
    )
    return [base] + [
        Param(
            f"{kind}_{t}",
            non_negative,
            unit,
            f"{'ks' if kind == 'stiffness' else 'kd'} of {t} springs (overrides {kind})",
            ">= 0",
            "cloth",
            default_doc=f"`{kind}`",
            folds_into=kind,
            metavar="K",
        )
        for t in SPRING_TYPES
    ]


#: Every run parameter, in the order of the CSV columns and the run key.
PARAMS: tuple[Param, ...] = (
    Param(
        "scenario",
        scenario,
        "",
        "scenario: a name ('warpcloth list') or a scenario file (.toml)",
        "`sheet`, `flag`, `curtain`, `mesh`, `drape`, `tablecloth`, `fold`, or a file `NAME.toml` (docs/meshes.md)",
        "run",
        default_doc="`sheet flag` in a test list",
        sweep_default=("sheet", "flag"),
        positional=True,
        xml_aliases=("scenarios",),
        config=None,
    ),
    Param(
        "integrator",
        integrator,
        "",
        "integrator name ('warpcloth list'); in a test list also 'all'",
        "integrator names, or `all`",
        "integrator",
        default_doc="the scenario's (explicit_euler); required in a test list",
        flag_aliases=("-i",),
        metavar="NAME",
        cli_type=str,
    ),
    Param(
        "device",
        device,
        "",
        "Warp device: cpu, cuda, cuda:N (a device that is not present is an error before any run)",
        "`cpu`, `cuda`, `cuda:N`",
        "run",
        default="cpu",
        cli_type=str,
    ),
    Param(
        "size",
        size,
        "",
        "grid size: N (N x N) or ROWSxCOLS; excludes rows/cols",
        "`N` or `ROWSxCOLS`, at least 3 x 3",
        "cloth",
        default_doc="the scenario's (sheet 32x32, flag 20x30)",
        folds_into="rows",
        applies="grid",
        metavar="N",
    ),
    Param(
        "rows",
        grid_dim,
        "",
        "particles per column (with cols)",
        "integer >= 3",
        "cloth",
        default_doc="the scenario's",
        applies="grid",
        metavar="N",
        from_scenario=True,
        cli_type=int,
    ),
    Param(
        "cols",
        grid_dim,
        "",
        "particles per row (with rows)",
        "integer >= 3",
        "cloth",
        default_doc="the scenario's",
        applies="grid",
        metavar="N",
        from_scenario=True,
        cli_type=int,
    ),
    Param(
        "width",
        positive,
        "m",
        "cloth width",
        "> 0",
        "cloth",
        default_doc="the scenario's",
        applies="grid",
        from_scenario=True,
        cli_type=float,
    ),
    Param(
        "height",
        positive,
        "m",
        "cloth height",
        "> 0",
        "cloth",
        default_doc="the scenario's",
        applies="grid",
        from_scenario=True,
        cli_type=float,
    ),
    Param(
        "mass",
        positive,
        "kg",
        "total cloth mass, split evenly over the particles (seed 4.2.4)",
        "> 0",
        "cloth",
        default_doc="the scenario's (sheet 0.2, flag 0.3)",
        from_scenario=True,
        cli_type=float,
    ),
    *_spring_params("stiffness", "N/m", "1000 structural and shear, 200 bend"),
    *_spring_params("damping", "N s/m", "2 * 0.05 * sqrt(ks m), m the particle mass"),
    Param(
        "bend",
        choice("provot", "choi_ko", "none", "dihedral", what="bend model"),
        "",
        "bend springs, or dihedral: no bend springs, dihedral-angle hinges of rigidity bend_rigidity",
        "`provot`, `choi_ko`, `none`, `dihedral`",
        "cloth",
        default="provot",
        choices=("provot", "choi_ko", "none", "dihedral"),
    ),
    Param(
        "bend_rigidity",
        non_negative_pair,
        "N m",
        "bending rigidity B of the dihedral hinges (bend dihedral only); with a material its B, "
        "one number or warp,weft",
        ">= 0, or two (warp,weft) with a material",
        "cloth",
        default_doc="31.4e-6 (cotton); the material's",
        key="set",
        metavar="B",
    ),
    # -- the material in physical units (docs/materials.md): the preset, then its values
    Param(
        "material",
        material_name,
        "",
        "the cloth's material: a preset, custom (give density, stretch, shear, bend_rigidity) or none "
        "(per-spring stiffness and damping); 'warpcloth list' shows the presets",
        "`cotton`, `denim`, `polyester`, `polyester_light`, `wool`, `silk`, `custom`, `none`",
        "material",
        default_doc="the scenario's (drape, tablecloth, cantilever, cusick: cotton; the others none)",
        key="set",
        from_scenario=True,
        metavar="NAME",
    ),
    Param(
        "density",
        positive,
        "kg/m^2",
        "areal density rho of the material",
        "> 0",
        "material",
        default_doc="the material's",
        key="set",
        metavar="RHO",
    ),
    Param(
        "stretch",
        positive_pair,
        "N/m",
        "membrane stiffness of the material (Young's modulus x thickness): one number or warp,weft",
        "> 0, or two (warp,weft)",
        "material",
        default_doc="the material's",
        key="set",
        metavar="C",
    ),
    Param(
        "shear",
        positive,
        "N/m",
        "in-plane shear stiffness G of the material (G^2 < stretch_warp * stretch_weft)",
        "> 0",
        "material",
        default_doc="the material's",
        key="set",
        metavar="G",
    ),
    Param(
        "compression",
        unit_interval,
        "",
        "compression factor phi: a membrane spring shorter than its rest length acts with phi ks "
        "(buckling finer than the mesh; 1 = as stiff as in tension)",
        "0 to 1",
        "material",
        default_doc="the material's (1)",
        key="set",
        metavar="PHI",
    ),
    Param(
        "warp_angle",
        angle,
        "rad",
        "angle of the material's warp from the grid's columns (the mesh's UV u axis)",
        "-pi to pi",
        "material",
        default_doc="0",
        key="set",
        metavar="RAD",
    ),
    Param(
        "stretch_damping_ratio",
        non_negative,
        "",
        "damping ratio of each membrane spring of the material",
        ">= 0",
        "material",
        default_doc="the material's (0.05)",
        key="set",
        metavar="ZETA",
    ),
    Param(
        "bend_damping_ratio",
        non_negative,
        "",
        "damping ratio of the material's bending modes at 5 Hz (Rayleigh)",
        ">= 0",
        "material",
        default_doc="the material's (0.02)",
        key="set",
        metavar="ZETA",
    ),
    Param(
        "drag",
        non_negative,
        "1/s",
        "linear air drag rate",
        ">= 0",
        "forces",
        default_doc="the scenario's (sheet 1, flag 0)",
        cli_type=float,
    ),
    Param(
        "collider",
        colliders,
        "",
        "add colliders: KIND:K=V,... (vectors as x/y/z), several joined by '+' or the flag "
        "repeated, e.g. sphere:center=0/1/0,radius=0.3,thickness=0.005,friction=0.4 or mesh:path=table.obj "
        "(docs/colliders.md)",
        "`plane`, `sphere`, `capsule`, `box`, `mesh` with settings",
        "forces",
        default_doc="none (the scenario's own)",
        key="set",
        config="colliders",
        to_config=_colliders_config,
        repeat=True,
        metavar="KIND:K=V,...",
        cli_type=str,
    ),
    Param(
        "collider_edges",
        switch,
        "",
        "box and mesh colliders' edges and corners against the cloth's edges and triangles, so that no "
        "collider edge passes between cloth vertices (the tablecloth's table edge); experimental: where it "
        "fails is in docs/self-collision.md",
        "`on`, `off`",
        "forces",
        default="off",
        key="set",
        to_config=_switch_config,
        choices=("on", "off"),
    ),
    Param(
        "self_collision",
        switch,
        "",
        "the cloth against itself: vertex-triangle and edge-edge contacts kept a thickness apart, Coulomb "
        "friction, for every integrator (docs/self-collision.md)",
        "`on`, `off`",
        "self_collision",
        default_doc="the scenario's (on in fold, drape, tablecloth)",
        key="set",
        to_config=_switch_config,
        choices=("on", "off"),
    ),
    Param(
        "self_collision_thickness",
        positive,
        "m",
        "the distance self-collision keeps between any two parts of the cloth that are not neighbours",
        "> 0",
        "self_collision",
        default=0.005,
        key="set",
        metavar="H",
        cli_type=float,
    ),
    Param(
        "self_collision_friction",
        non_negative,
        "",
        "Coulomb friction coefficient of cloth on cloth",
        ">= 0",
        "self_collision",
        default=0.3,
        key="set",
        metavar="MU",
        cli_type=float,
    ),
    Param(
        "self_collision_interval",
        non_negative,
        "s",
        "the collision time step of the explicit schemes (explicit_euler, midpoint, rk4, verlet): contacts "
        "found at its start, the velocity filter at its end over whole steps (Bridson et al. 2002); the "
        "schemes that hold contacts in their solve find them every step",
        ">= 0 (0: every step)",
        "self_collision",
        default=0.001,
        key="set",
        metavar="S",
        cli_type=float,
    ),
    Param(
        "strain_limit",
        positive,
        "",
        "Provot's deformation constraint tau: after each step no structural or shear spring "
        "stays beyond (1 + tau) L0 (force-based integrators only)",
        "> 0 (e.g. 0.1)",
        "integrator",
        default_doc="off (implicit_euler: its --strain-cap, 0.1)",
        key="set",
        metavar="TAU",
        cli_type=float,
    ),
    Param(
        "mesh",
        text_value,
        "",
        "the cloth's triangle mesh: .obj or .usd/.usda/.usdc/.usdz",
        "a file path",
        "mesh",
        default_doc="the scenario's",
        key="set",
        applies="mesh",
        metavar="FILE",
        multi=True,
    ),
    Param(
        "prim",
        text_value,
        "",
        "the UsdGeom.Mesh prim of a USD mesh",
        "a prim path",
        "mesh",
        default_doc="the first mesh",
        key="set",
        applies="mesh",
        metavar="PATH",
    ),
    Param(
        "pin_group",
        names,
        "",
        "pin the vertex groups of the mesh (comma-separated; the flag may repeat)",
        "group names",
        "mesh",
        default_doc="the scenario's",
        key="set",
        applies="mesh",
        to_config=_group_config,
        repeat=True,
        join=",",
        metavar="NAME",
    ),
    Param(
        "pin",
        text_value,
        "",
        "pin the vertices where a predicate holds, e.g. 'y > 0.95 * y.max()' (x, y, z in m)",
        "a predicate (one per attribute: it holds spaces)",
        "mesh",
        default_doc="the scenario's",
        key="set",
        applies="mesh",
        config="pin_where",
        multi=False,
        metavar="EXPR",
    ),
    Param(
        "dt",
        timestep,
        "s",
        "time step: a value, the integrator's own stable default, or in a test list max / max*F "
        "(a fraction of the largest stable dt)",
        "dt in s, `default`, `max`, `max*F`",
        "run",
        default=TimeStep("default"),
        default_doc="`default` (the integrator's own)",
        cli_help="time step (default: the integrator's own, stable on the scenario; "
        "find the largest stable one with warpcloth max-dt)",
        xml_aliases=("timestep",),
        columns=("dt_request",),
        search=False,
        to_config=_dt_config,
        commands=("run", "sweep"),
        metavar="S",
        cli_type=float,
    ),
    Param(
        "duration",
        positive,
        "s",
        "simulated time: the flag's length, the sheet's upper bound (it ends at equilibrium)",
        "> 0",
        "run",
        default_doc="the scenario's (10); in a test list sheet 60, flag 10",
        sweep_default=SWEEP_DURATION.get,
        search=False,
        commands=("run", "sweep"),
        from_scenario=True,
        cli_type=float,
    ),
    Param(
        "resume_from",
        text_value,
        "",
        "continue a run from this checkpoint (written by --checkpoint of a run of the same scenario and flags): it "
        "runs on to --duration counted from the first run's start, bit-identically to the uninterrupted run on the "
        "same device; outputs get the remaining frames",
        "a checkpoint file (.npz)",
        "run",
        commands=("run",),
        columns=(),
        key="never",
        search=False,
        config=None,
        metavar="FILE",
    ),
    Param(
        "frame_rate",
        positive,
        "1/s",
        "frames per simulated second: metrics are sampled (equilibrium and stability "
        "checked) once a frame, USD frames written",
        "> 0",
        "run",
        default_doc="60; 30 in a test list (the seed's real-time threshold)",
        sweep_default=SWEEP_FRAME_RATE,
        flag_aliases=("--fps",),
        config="fps",
        cli_type=float,
    ),
    Param(
        "wall_cap",
        wall_cap,
        "s",
        "wall-clock cap of one run and of each max-dt trial ('none': no cap)",
        "> 0 or `none`",
        "run",
        default_doc="none; 60 in a test list (the seed's one minute)",
        sweep_default=SWEEP_WALL_CAP,
        xml_aliases=("cap",),
        config=None,
        cli_type=cli_wall_cap,
    ),  # search: a trial that reaches the cap counts as capped
    Param(
        "graph",
        choice("on", "off", "auto", what="graph mode"),
        "",
        "capture a frame's steps as a graph and replay it: "
        "on, off, or auto (where supported); results are the same as plain launches' (bit-identical on the "
        "CPU, and on CUDA with --deterministic on), capture time is reported apart",
        "`on`, `off`, `auto`",
        "run",
        default="auto",
        key="set",
        search=False,
        config="use_graph",
        to_config=_graph_config,
        choices=("on", "off", "auto"),
    ),
    Param(
        "deterministic",
        switch,
        "",
        "bit-reproducible runs on CUDA: Warp's deterministic atomics (RUN_TO_RUN) for every kernel, process-wide; "
        "slower for the explicit schemes (docs/gpu.md); the CPU is bit-reproducible either way",
        "`on`, `off`",
        "run",
        default="off",
        key="set",
        search=False,
        to_config=_switch_config,
        choices=("on", "off"),
    ),
    Param(
        "instability_strain",
        positive,
        "",
        "a spring strained past this makes the run unstable (docs/stability.md)",
        "> 0",
        "run",
        default=DEFAULT_INSTABILITY_STRAIN,
        key="set",
        metavar="STRAIN",
        cli_type=float,
    ),
    Param(
        "maxdt_precision",
        fraction,
        "",
        "relative precision of the max-stable-dt search",
        "0 < p < 1",
        "search",
        default=DEFAULT_MAXDT_PRECISION,
        commands=("max-dt", "sweep"),
        flag_aliases=("--precision",),
        key="with_max",
        config=None,
        cli_type=float,
    ),
    Param(
        "maxdt_duration",
        positive,
        "s",
        "simulated time a max-dt trial must survive",
        "> 0",
        "search",
        default=DEFAULT_MAXDT_DURATION,
        commands=("max-dt", "sweep"),
        flag_aliases=("--duration",),
        key="with_max",
        config=None,
        cli_type=float,
    ),
    Param(
        "dt_min",
        positive,
        "s",
        "smallest dt the max-dt search tries",
        "> 0",
        "search",
        default_doc="1e-7",
        commands=("max-dt",),
        columns=(),
        key="never",
        config=None,
        cli_type=float,
    ),
    Param(
        "dt_max",
        positive,
        "s",
        "largest dt the max-dt search tries",
        "> 0",
        "search",
        default_doc="0.1; one frame in a test list",
        commands=("max-dt",),
        columns=(),
        key="never",
        config=None,
        cli_type=float,
    ),
    Param(
        "dt_start",
        positive,
        "s",
        "first dt the max-dt search tries",
        "> 0",
        "search",
        default_doc="the integrator's default dt",
        commands=("max-dt",),
        columns=(),
        key="never",
        config=None,
        flag_aliases=("--start",),
        cli_type=float,
    ),
)

BY_NAME: dict[str, Param] = {p.name: p for p in PARAMS}

#: Old spellings -> the parameter (XML attributes and RunSpec attributes of earlier releases).
OLD_NAMES: dict[str, str] = {alias: p.name for p in PARAMS for alias in p.xml_aliases}

GROUP_TITLES = {
    "integrator": "integrator",
    "cloth": "cloth",
    "material": "material in physical units (docs/materials.md)",
    "mesh": "mesh scenarios (mesh, scenario files)",
    "forces": "forces and colliders",
    "self_collision": "self-collision",
    "run": "run",
    "search": "max-dt search",
}


def params_for(command: str) -> list[Param]:
    """The parameters ``command`` (``run``, ``max-dt``, ``sweep``) accepts, in declaration order."""
    return [p for p in PARAMS if command in p.commands]


# -- CLI ------------------------------------------------------------------------------------
def argparse_type(param: Param):
    def convert(text: str):
        try:
            return param.parse(text)
        except ValueError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None

    convert.__name__ = param.name  # argparse names the type in "invalid <name> value"
    return convert


def add_flags(parser: argparse.ArgumentParser, command: str, skip: tuple = (), exclusive: dict | None = None) -> None:
    """Add the flags of ``command``'s parameters to ``parser``, grouped; every dest is the
    parameter's name and every default None (unset). ``exclusive`` maps a parameter name to
    ``[(flags, kwargs), ...]``: command-only flags that exclude it (``--num-frames``)."""
    chosen = [p for p in params_for(command) if p.name not in skip]
    groups: dict[str, Any] = {
        g: parser.add_argument_group(title)
        for g, title in GROUP_TITLES.items()
        if any(p.group == g and not p.positional for p in chosen)
    }
    for p in chosen:
        if p.positional:
            parser.add_argument(p.name, type=argparse_type(p), help=p.help)
            continue
        group = groups[p.group]
        if exclusive and p.name in exclusive:
            group = group.add_mutually_exclusive_group()
            for flags, kw in exclusive[p.name]:
                group.add_argument(*flags, **kw)
        unit = f" [{p.unit}]" if p.unit else ""
        if p.cli_help:
            default = ""
        elif p.default is not None and not isinstance(p.default, TimeStep):
            default = f" (default {p.default})"
        elif p.default_doc:
            default = f" (default {p.default_doc.replace('`', '')})"
        else:
            default = ""
        aliases = list(p.flag_aliases)
        kwargs = (
            {"choices": list(p.choices)}
            if p.choices
            else {"type": p.cli_type or argparse_type(p), "metavar": p.metavar or p.name.upper()}
        )
        group.add_argument(
            p.flag,
            *aliases,
            dest=p.name,
            default=None,
            **kwargs,
            action="append" if p.repeat else "store",
            help=((p.cli_help or p.help) + unit + default).replace("%", "%%"),
        )


def cli_value(param: Param, args):
    """The value of ``param`` given on the command line (repeated flags joined), or None."""
    value = getattr(args, param.name, None)
    if param.repeat and isinstance(value, list):
        return param.join.join(value) if value else None
    return value


def resolve_per_type(values: dict, kind: str):
    """``stiffness``/``damping`` and their per-type overrides as one ScenarioConfig value:
    a number, a (structural, shear, bend) tuple, a partial {type: value} dict (the others
    default), or None."""
    base = values.get(kind)
    given = {t: values[f"{kind}_{t}"] for t in SPRING_TYPES if values.get(f"{kind}_{t}") is not None}
    if not given:
        return base
    if base is None:
        return given
    full = base if isinstance(base, tuple) else (base,) * 3
    return tuple(given.get(t, full[i]) for i, t in enumerate(SPRING_TYPES))


def per_type_triple(value):
    """A per-type value (a number, a (structural, shear, bend) tuple, a partial {type: value}
    dict) as (structural, shear, bend), None where the builder's default applies (hashable,
    unlike a partial dict); None stays None."""
    if value is None or isinstance(value, tuple):
        return value
    if isinstance(value, dict):
        return tuple(value.get(t) for t in SPRING_TYPES)
    return (value,) * 3


def check_applies(values: dict, is_mesh: bool, scenario_name: str, spell=lambda p: p.flag) -> None:
    """Grid parameters on a mesh scenario, or mesh parameters on a grid scenario, are refused."""
    for p in PARAMS:
        if p.applies is None or values.get(p.name) is None:
            continue
        if (p.applies == "grid") == is_mesh:
            mesh_names = ", ".join(spell(q) for q in PARAMS if q.applies == "mesh")
            kind = (
                "a mesh: its size comes from the mesh file"
                if is_mesh
                else f"a grid; {mesh_names} apply to the mesh scenario and scenario files"
            )
            raise WarpclothError(f"{spell(p)} does not apply to scenario {scenario_name!r}: its cloth is {kind}")


#: The settings of self-collision, which apply only where it is on.
SELF_COLLISION_SETTINGS = ("self_collision_thickness", "self_collision_friction", "self_collision_interval")


def check_self_collision_settings(values: dict, on: bool, scenario_name: str, spell=lambda p: p.flag) -> None:
    """Self-collision's settings given where it is off are refused (as a material's values on a cloth
    without a material): ``on`` is the run's self-collision, the scenario's own unless given."""
    if on:
        return
    given = next((name for name in SELF_COLLISION_SETTINGS if values.get(name) is not None), None)
    if given is not None:
        switch = spell(BY_NAME["self_collision"])
        raise WarpclothError(
            f"{spell(BY_NAME[given])} applies with self-collision on, and it is off in scenario {scenario_name!r}: "
            f"give {switch} on as well, or leave {spell(BY_NAME[given])} out"
        )


def config_values(values: dict) -> dict:
    """ScenarioConfig keyword arguments from parameter values (None: unset, and left out, so a
    scenario's own value, e.g. a scenario file's, stays)."""
    out = {}
    for kind in ("stiffness", "damping"):
        value = resolve_per_type(values, kind)
        if value is not None:
            out[kind] = value
    if values.get("size") is not None and values.get("rows") is None:
        out["rows"], out["cols"] = values["size"]
    for p in PARAMS:
        field_name = p.config_field
        if (
            field_name is None
            or p.name in ("stiffness", "damping")
            or (field_name in out and out[field_name] is not None)
        ):
            continue
        value = values.get(p.name)
        if value is None:
            continue
        out[field_name] = p.to_config(value) if p.to_config else value
    return out


# -- CSV and run key --------------------------------------------------------------------------
def csv_columns() -> list[str]:
    """The parameter columns of a sweep's CSV, in declaration order."""
    return [c for p in PARAMS if "sweep" in p.commands for c in p.csv_columns]


def canonical(value) -> str:
    """A value as the run key and the CSV write it (floats as Python's shortest repr)."""
    if value is None:
        return "none"
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, tuple):
        return "/".join(canonical(v) for v in value)
    return str(value)


# -- docs ------------------------------------------------------------------------------------
def markdown_table() -> str:
    """The attribute table of docs/sweep.md (between its ``params`` markers)."""
    rows = ["| attribute | CLI flag | values | unit | default | meaning |", "|---|---|---|---|---|---|"]
    for p in params_for("sweep"):
        if p.default_doc is not None:
            default = p.default_doc
        elif isinstance(p.default, str):
            default = f"`{p.default}`"
        else:
            default = "" if p.default is None else f"{p.default:g}" if isinstance(p.default, float) else str(p.default)
        flag = "(positional)" if p.positional else f"`{p.flag}`" + ("" if "run" in p.commands else " (max-dt)")
        names = f"`{p.name}`" + "".join(f" (old: `{a}`)" for a in p.xml_aliases)
        meaning = p.help
        if not p.multi:
            meaning += "; one value per attribute"
        rows.append(f"| {names} | {flag} | {p.values} | {p.unit} | {default} | {meaning} |")
    return "\n".join(rows)


__all__ = [
    "BY_NAME",
    "OLD_NAMES",
    "PARAMS",
    "SELF_COLLISION_SETTINGS",
    "Param",
    "TimeStep",
    "add_flags",
    "argparse_type",
    "canonical",
    "check_self_collision_settings",
    "config_values",
    "csv_columns",
    "markdown_table",
    "params_for",
]


if __name__ == "__main__":  # python -m warpcloth.run.params: the docs table
    print(markdown_table())
