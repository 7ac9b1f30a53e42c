"""XML test lists (seed 4.3): parse, validate and expand into runs.

A test list is a ``test_list`` root of ``test`` elements. Each ``test`` names an integrator and
its parameters; an attribute holding several values separated by spaces expands to the product
of all such lists, so the seed's "all combinations of test parameters" is one short file::

    <test_list cap="60">
      <test id="euler" integrator="explicit_euler rk4" size="10 25" timestep="max max*0.5"/>
      <test id="cg" integrator="implicit_euler" rows="50" cols="50" timestep="1e-2" cg_tol="1e-6"/>
    </test_list>

Attributes of the root are defaults for every ``test``. Integrator options (``cg_tol``, ...) are
the :class:`~warpcloth.integrators.Option` names the registered integrators declare, so an
integrator added later is usable here without changes. The whole file is validated before any
run: every problem raises :class:`~warpcloth.errors.WarpclothError` as
``FILE:LINE: problem`` (docs/sweep.md lists every attribute).
"""

from __future__ import annotations

import difflib
import itertools
import math
import re
import xml.parsers.expat as expat
from dataclasses import dataclass, field

from warpcloth.errors import WarpclothError, warn
from warpcloth.integrators import all_options, integrator_class, integrator_names
from warpcloth.io.files import read_input
from warpcloth.run import params
from warpcloth.run.params import (
    SPRING_TYPES,
    Param,
    TimeStep,
    canonical,
    config_values,
    per_type_triple,
    resolve_per_type,
)
from warpcloth.scenarios import check_scenario, get_scenario
from warpcloth.sim.material import MATERIAL_VALUES, material_with
from warpcloth.sim.model import default_spring_params

ROOT_TAG = "test_list"
TEST_TAG = "test"

#: Most runs a test list may expand to unless raised (``warpcloth sweep --max-runs N``): a
#: 2 KB file can name 20^12 combinations; the count is computed before anything is expanded.
DEFAULT_MAX_RUNS = 10_000

#: The test id: an attribute of ``test`` only, not a run parameter.
TEST_ID = Param(
    "id",
    str,
    "",
    "name of the test, carried into the CSV as test_id (default: its position, 1, 2, ...)",
    "one name",
    "run",
    commands=("sweep",),
    columns=(),
    key="never",
)


def attributes() -> dict[str, Param]:
    """Every attribute of ``test`` by name: the test id and the run parameters (:data:`warpcloth.run.params.PARAMS`)."""
    return {"id": TEST_ID, **{p.name: p for p in params.params_for("sweep")}}


ATTRIBUTES: dict[str, Param] = attributes()  # as declared at import

_UNSET = object()  # an attribute not given (None is a value: wall_cap="none")


def resolved_params() -> tuple[Param, ...]:
    """Parameters a :class:`RunSpec` holds once resolved (per-type springs and size fold into others)."""
    return tuple(p for p in params.params_for("sweep") if not p.folds_into)


# -- runs ------------------------------------------------------------------------------------
@dataclass(frozen=True, init=False)
class RunSpec:
    """One run of a sweep: a scenario with every parameter resolved (SI units).

    ``values`` holds each run parameter (:func:`resolved_params`) as ``(name, value)``, readable as an
    attribute (``spec.rows``, ``spec.dt``; the old names ``spec.timestep``, ``spec.cap`` too).
    ``stiffness`` and ``damping`` are the effective per-type values (structural, shear, bend).
    ``options`` are the integrator's options given in the file, as sorted (name, value) pairs.
    """

    test_id: str
    line: int
    values: tuple
    options: tuple = ()

    def __init__(self, test_id: str, line: int, values: tuple, options: tuple = (), **changes):
        """``changes``: parameters to replace in ``values`` (``dataclasses.replace(spec, device="cuda:1")``)."""
        if changes:
            changes = {params.OLD_NAMES.get(k, k): v for k, v in changes.items()}
            unknown = set(changes) - {k for k, _ in values}
            if unknown:
                raise TypeError(f"RunSpec has no parameter {sorted(unknown)[0]!r}")
            values = tuple((k, changes.get(k, v)) for k, v in values)
        object.__setattr__(self, "test_id", test_id)
        object.__setattr__(self, "line", line)
        object.__setattr__(self, "values", tuple(values))
        object.__setattr__(self, "options", tuple(options))

    def __getattr__(self, name):
        if name.startswith("__") or name in ("values", "test_id", "line", "options"):
            raise AttributeError(name)
        name = params.OLD_NAMES.get(name, name)
        for key, value in self.values:
            if key == name:
                return value
        raise AttributeError(f"RunSpec has no parameter {name!r}")

    def get(self, name: str, default=None):
        return dict(self.values).get(name, default)

    @property
    def key(self) -> str:
        """Identity of the run for ``--resume``: every parameter that changes the run, written
        canonically (floats as Python's shortest repr), never the test id or file position;
        made from the declarations (:attr:`Param.key`)."""
        values = dict(self.values)
        parts = []
        for p in resolved_params():
            v = values.get(p.name)
            if (
                p.key == "never"
                or (p.key == "set" and v == p.default)
                or (p.key == "with_max" and not values["dt"].uses_max)
            ):
                continue
            parts.append(f"{p.name}={canonical(v)}")
        parts.append("options=" + ",".join(f"{k}={canonical(v)}" for k, v in self.options))
        return ";".join(parts)

    @property
    def search_key(self) -> tuple:
        """What the max-stable-dt search depends on (every parameter declared ``search``, and the
        run's duration, over which the found dt is verified)."""
        return tuple((k, v) for k, v in self.values if params.BY_NAME[k].search) + (
            self.options,
            ("duration", self.duration),
        )

    def config(self, dt: float | None = None, duration: float | None = None):
        """The :class:`~warpcloth.scenarios.ScenarioConfig` of this run; ``dt`` [s] replaces the spec's
        (the dt a ``max`` search found; None: the spec's value, or the integrator's default)."""
        values = dict(self.values)
        for kind in ("stiffness", "damping"):  # a partial per-type value: the builder fills the rest
            v = values.get(kind)
            if isinstance(v, tuple) and None in v:
                values[kind] = {t: x for t, x in zip(SPRING_TYPES, v) if x is not None}
        if dt is not None:
            values["dt"] = dt
        kwargs = config_values(values)
        kwargs.update(integrator_options=dict(self.options), duration=self.duration if duration is None else duration)
        return get_scenario(self.scenario).config(**kwargs)

    def describe(self) -> str:
        """A short label: ``sheet rk4 10x10 dt=max*0.5``."""
        return f"{self.scenario} {self.integrator} {self.rows}x{self.cols} dt={self.dt}"


@dataclass
class TestList:
    """A parsed, validated and expanded test list."""

    path: str
    runs: list[RunSpec]
    tests: int
    duplicates: int = 0  # expanded runs dropped because an earlier run had the same key


# -- XML ------------------------------------------------------------------------------------
@dataclass
class _Element:
    tag: str
    attrs: dict
    line: int
    byte: int
    children: list = field(default_factory=list)


class _Source:
    """The raw file, to locate attributes of multi-line start tags by line."""

    def __init__(self, path: str, data: bytes):
        self.path = path
        self.data = data
        self.noted: set[str] = set()  # old spellings already noted

    def error(self, line: int, message: str) -> WarpclothError:
        return WarpclothError(f"{self.path}:{line}: {message}")

    def attr_line(self, element: _Element, name: str) -> int:
        m = re.compile(rb"\s(" + re.escape(name.encode()) + rb")\s*=").search(self.data, max(element.byte, 0))
        if m is None:
            return element.line
        return element.line + self.data.count(b"\n", element.byte, m.start(1))


#: The largest test list read [bytes].
MAX_TEST_LIST_BYTES = 16 * 2**20


def _read_tree(path: str) -> tuple[_Source, _Element]:
    try:  # a regular file of bounded size, never a FIFO or a file of /proc, /dev
        data = read_input(path, "file", MAX_TEST_LIST_BYTES)
    except WarpclothError as exc:
        raise WarpclothError(f"cannot read test list {path}: {exc}") from None
    src = _Source(path, data)
    parser = expat.ParserCreate()
    stack: list[_Element] = []
    root: list[_Element] = []

    def start(tag, attrs):
        line = parser.CurrentLineNumber
        if not stack and tag != ROOT_TAG:
            raise src.error(line, f"the root element must be <{ROOT_TAG}>, got <{tag}>")
        if len(stack) == 1 and tag != TEST_TAG:
            raise src.error(line, f"unknown element <{tag}> inside <{ROOT_TAG}>; only <{TEST_TAG}> is allowed")
        if len(stack) >= 2:
            raise src.error(
                line, f"unknown element <{tag}> inside <{stack[-1].tag}>; give parameters as attributes of <{TEST_TAG}>"
            )
        el = _Element(tag, dict(attrs), line, parser.CurrentByteIndex)
        (stack[-1].children if stack else root).append(el)
        stack.append(el)

    def end(tag):
        stack.pop()

    def text(data):
        if data.strip():
            where = stack[-1].tag if stack else "the document"
            lead = len(data) - len(data.lstrip())
            raise src.error(
                parser.CurrentLineNumber + data[:lead].count("\n"),
                f"unexpected text {data.strip()[:40]!r} inside <{where}>; a test list holds only elements and "
                "attributes",
            )

    def doctype(name, *args):
        raise src.error(
            parser.CurrentLineNumber,
            f"<!DOCTYPE {name} ...> is not allowed in a test list (no DTDs, entities "
            "or other declarations; only <test_list> and <test> elements)",
        )

    parser.StartDoctypeDeclHandler = doctype
    parser.StartElementHandler = start
    parser.EndElementHandler = end
    parser.CharacterDataHandler = text
    try:
        parser.Parse(data, True)
    except expat.ExpatError as exc:
        raise src.error(exc.lineno, f"malformed XML: {expat.ErrorString(exc.code)} (column {exc.offset + 1})") from None
    except LookupError as exc:  # <?xml ... encoding="klingon"?>
        raise src.error(
            1,
            f"the XML declaration names an encoding Python does not know ({str(exc)[:60]}); "
            "write the test list in UTF-8",
        ) from None
    return src, root[0]


def parse_test_list(path: str, max_runs: int = DEFAULT_MAX_RUNS) -> TestList:
    """Parse, validate and expand the test list at ``path``.

    Args:
        max_runs: refuse a list whose tests expand to more runs than this (counted as the
            product of each test's value lists, before expanding; duplicates count).

    Raises:
        WarpclothError: ``FILE:LINE: problem`` for the first problem found; no run has started.
    """
    if isinstance(max_runs, bool) or not isinstance(max_runs, int) or max_runs < 1:
        raise WarpclothError(f"--max-runs must be an integer >= 1, got {max_runs!r}")
    src, root = _read_tree(str(path))  # checks the structure: test_list > test, nothing else
    if "id" in root.attrs:
        raise src.error(src.attr_line(root, "id"), f"attribute 'id' belongs on <{TEST_TAG}>, not on <{ROOT_TAG}>")
    if not root.children:
        raise src.error(root.line, f"empty test list: <{ROOT_TAG}> holds no <{TEST_TAG}> element")

    defaults = _parse_attributes(src, root, "test_list defaults")
    runs: list[RunSpec] = []
    seen_ids: dict[str, int] = {}
    for index, el in enumerate(root.children, start=1):
        values = _parse_attributes(src, el, f"test {el.attrs.get('id', str(index))!r}")
        test_id = values.pop("id", [str(index)])[0]
        if test_id in seen_ids:
            raise src.error(el.line, f"duplicate test id {test_id!r} (first used on line {seen_ids[test_id]})")
        seen_ids[test_id] = el.line
        runs.extend(_expand(src, el, root, test_id, defaults, values, max_runs - len(runs), max_runs))
    unique: dict[str, RunSpec] = {}
    for run in runs:
        unique.setdefault(run.key, run)
    return TestList(
        path=str(path), runs=list(unique.values()), tests=len(root.children), duplicates=len(runs) - len(unique)
    )


def _parse_attributes(src: _Source, el: _Element, what: str) -> dict[str, list]:
    """Every attribute of ``el`` as a list of parsed values (old spellings mapped to their
    parameter, with a note); integrator options stay text."""
    options = all_options()
    declared = attributes()
    out: dict[str, list] = {}
    spelled: dict[str, str] = {}
    for raw_name, raw in el.attrs.items():
        line = src.attr_line(el, raw_name)
        name = params.OLD_NAMES.get(raw_name, raw_name)
        if name != raw_name and raw_name not in src.noted:
            src.noted.add(raw_name)
            warn(
                f"{src.path}:{line}: attribute {raw_name!r} is now spelled {name!r} (the old name is accepted for now)"
            )
        if name in spelled:
            raise src.error(
                line, f"{what}: {raw_name!r} and {spelled[name]!r} name the same parameter; give it once, as {name!r}"
            )
        spelled[name] = raw_name
        attr = declared.get(name)
        if attr is None and name not in options:
            known = list(declared) + list(options)
            close = difflib.get_close_matches(name, known + list(params.OLD_NAMES), n=1)
            hint = f" (did you mean {params.OLD_NAMES.get(close[0], close[0])!r}?)" if close else ""
            raise src.error(line, f"{what}: unknown attribute {raw_name!r}{hint}; allowed: {', '.join(known)}")
        tokens = raw.split() if attr is None or attr.multi else ([raw.strip()] if raw.strip() else [])
        if not tokens:
            raise src.error(
                line, f"{what}: attribute {raw_name!r} is empty; give one or more values separated by spaces"
            )
        if attr is None:
            out[name] = tokens  # integrator option: checked against the test's integrators in _expand
            continue
        if attr is TEST_ID and len(tokens) > 1:
            raise src.error(line, f"{what}: attribute {raw_name!r} takes one value, got {raw!r}")
        parsed = []
        for tok in tokens:
            try:
                parsed.append(attr.parse(tok))
                if attr.name == "scenario":
                    check_scenario(parsed[-1])
            except (ValueError, WarpclothError) as exc:
                raise src.error(line, f"{what}: {raw_name}: {exc}") from None
        if len(set(map(repr, parsed))) != len(parsed):
            raise src.error(line, f"{what}: attribute {raw_name!r} repeats a value in {raw!r}")
        out[name] = parsed
    return out


def _expand(
    src: _Source,
    el: _Element,
    root: _Element,
    test_id: str,
    defaults: dict,
    own: dict,
    room: int = DEFAULT_MAX_RUNS,
    max_runs: int = DEFAULT_MAX_RUNS,
) -> list[RunSpec]:
    """The runs of one ``test``: the product of its value lists, for each scenario."""
    what = f"test {test_id!r}"
    values = {**defaults, **own}

    def line_of(name):
        return src.attr_line(el, name) if name in own else src.attr_line(root, name)

    if "integrator" not in values:
        raise src.error(
            el.line, f"{what}: attribute 'integrator' is required (one of {', '.join(integrator_names())}, or 'all')"
        )
    integrators = []
    for name in values["integrator"]:
        for n in integrator_names() if name == "all" else [name]:
            if n not in integrators:
                integrators.append(n)

    # Mesh: size, or rows and cols together, or the scenario's default.
    if "size" in values and ("rows" in values or "cols" in values):
        other = "rows" if "rows" in values else "cols"
        raise src.error(line_of(other), f"{what}: give either 'size' or 'rows' and 'cols', not both")
    if ("rows" in values) != ("cols" in values):
        missing = "cols" if "rows" in values else "rows"
        raise src.error(
            el.line,
            f"{what}: 'rows' needs 'cols' (and 'cols' needs 'rows'); '{missing}' is missing (or use size=\"N\")",
        )
    if "size" in values:
        meshes = values["size"]
    elif "rows" in values:
        meshes = list(itertools.product(values["rows"], values["cols"]))
    else:
        meshes = [None]

    # Integrator options: each must apply to at least one of the test's integrators.
    option_lists: dict[str, list] = {}
    registry = all_options()
    declared = attributes()
    for name in [n for n in values if n not in declared]:
        _, owners = registry[name]
        takers = [i for i in integrators if name in {o.name for o in integrator_class(i).options}]
        if not takers:
            raise src.error(
                line_of(name),
                f"{what}: option {name!r} does not apply to integrator(s) {', '.join(integrators)} (it applies to "
                f"{', '.join(owners)})",
            )
        parsed = []
        for tok in values[name]:
            for taker in takers:
                opt = next(o for o in integrator_class(taker).options if o.name == name)
                try:
                    parsed.append(opt.parse(tok))
                except WarpclothError as exc:
                    raise src.error(line_of(name), f"{what}: integrator {taker}: {exc}") from None
        option_lists[name] = list(dict.fromkeys(parsed))

    # One dimension per parameter (the declarations), the scenario last.
    dims: dict[str, list] = {"integrator": integrators, "grid_size": meshes}
    for p in params.params_for("sweep"):
        if p.name not in ("integrator", "size", "rows", "cols", "scenario"):
            dims[p.name] = values.get(p.name, [_UNSET])
    dims.update({f"option:{k}": v for k, v in option_lists.items()})
    dims["scenario"] = values.get("scenario", list(params.BY_NAME["scenario"].sweep_default))
    kinds = {"mesh" if get_scenario(n).is_mesh else "grid" for n in dims["scenario"]}
    for kind in ("grid", "mesh"):
        given = [p.name for p in params_of_kind(kind) if p.name in own]
        if given and kind not in kinds:
            raise src.error(
                line_of(given[0]),
                f"{what}: {given[0]!r} applies to {kind} scenarios and none of the test's "
                f"scenarios ({', '.join(dims['scenario'])}) is one",
            )
    names = list(dims)
    count = math.prod(len(v) for v in dims.values())  # without expanding
    if count > room:
        sizes = [str(len(v)) for v in dims.values() if len(v) > 1]
        factors = f" ({' x '.join(sizes)})" if len(sizes) > 1 else ""
        before = f" (after {max_runs - room} runs of the tests before it)" if room < max_runs else ""
        raise src.error(
            el.line,
            f"{what}: expands to {count} runs{factors}{before}, more than the limit of "
            f"{max_runs} runs; raise it with --max-runs N if you mean it",
        )
    runs = []
    for combo in itertools.product(*dims.values()):
        explicit = dict(zip(names, combo))
        c = {k: (None if v is _UNSET else v) for k, v in explicit.items()}
        integrator = c["integrator"]
        taken = {o.name for o in integrator_class(integrator).options}
        if c["strain_limit"] is not None and not integrator_class(integrator).force_based:
            raise src.error(el.line, f"{what}: strain_limit applies to force-based integrators, not {integrator!r}")
        options = tuple(sorted((k[7:], v) for k, v in c.items() if k.startswith("option:") and k[7:] in taken))
        scen = get_scenario(c["scenario"])
        d = scen.defaults
        is_mesh = scen.is_mesh
        # a test may name grid and mesh scenarios together: each takes the parameters of its kind
        for p in params_of_kind("mesh" if not is_mesh else "grid"):
            c[p.name], explicit[p.name] = None, _UNSET
        if is_mesh and c["mesh"] is not None:  # another mesh than the scenario's: its size is known once built
            rows = cols = None
        else:
            rows, cols = c["grid_size"] if c["grid_size"] is not None and not is_mesh else (d.rows, d.cols)
        c["rows"], c["cols"] = explicit["rows"], explicit["cols"] = rows, cols
        resolved = {}
        for p in resolved_params():
            v = explicit.get(p.name, _UNSET)
            if v is _UNSET:
                v = p.default_for(True, c["scenario"])
            if v is None and p.from_scenario and p.name not in ("rows", "cols"):
                v = getattr(d, p.config_field)
            resolved[p.name] = v
        material = resolved.get("material")
        if material is not None and material != "none":  # the material gives the masses and springs
            clash = next((n for n in PER_SPRING_NAMES if c.get(n) is not None), None)
            if clash is not None:
                raise src.error(
                    line_of(clash),
                    f"{what}: {clash!r} is a per-spring value and does not go with material {material!r} (its "
                    "density and stiffnesses give the masses and springs); change the material's values or give "
                    'material="none"',
                )
            try:  # bad values fail now, naming the line, not run by run
                material_with(material, **{k: c.get(k) for k in MATERIAL_VALUES})
            except WarpclothError as exc:
                raise src.error(el.line, f"{what}: {exc}") from None
            resolved["mass"] = resolved["stiffness"] = resolved["damping"] = None
            resolved["integrator"] = integrator
            runs.append(RunSpec(test_id=test_id, line=el.line, values=tuple(resolved.items()), options=options))
            continue
        clash = next(
            (
                p.name
                for p in params.PARAMS
                if p.group == "material" and p.name != "material" and c.get(p.name) is not None
            ),
            None,
        )
        if clash is not None:
            raise src.error(
                line_of(clash),
                f"{what}: {clash!r} is a material's value and the run has no material: give material (a preset, "
                "or custom with density, stretch, shear and bend_rigidity)",
            )
        mass = resolved["mass"]
        # the effective per-type values; the default damping scales with the particle mass, which a
        # mesh scenario knows only once its mesh is built: there it stays as given (or None)
        particles = rows * cols if rows is not None and not is_mesh else None
        springs = default_spring_params(
            mass / (particles or 1), resolve_per_type(c, "stiffness"), resolve_per_type(c, "damping")
        )
        eff = [springs[k] for k in sorted(springs)]
        resolved["stiffness"] = tuple(p.stiffness for p in eff)
        resolved["damping"] = (
            tuple(p.damping for p in eff) if particles else per_type_triple(resolve_per_type(c, "damping"))
        )
        resolved["integrator"] = integrator
        runs.append(RunSpec(test_id=test_id, line=el.line, values=tuple(resolved.items()), options=options))
    return runs


#: The per-spring parameters a material replaces (its density and stiffnesses give them).
PER_SPRING_NAMES = ("mass", "stiffness", "damping") + tuple(
    f"{k}_{t}" for k in ("stiffness", "damping") for t in ("structural", "shear", "bend")
)


#: The parameters that apply to one kind of cloth only (``grid`` or ``mesh``).
def params_of_kind(kind: str) -> tuple[Param, ...]:
    return tuple(p for p in params.params_for("sweep") if p.applies == kind)


__all__ = ["ATTRIBUTES", "RunSpec", "TestList", "TimeStep", "parse_test_list"]
