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
from dataclasses import dataclass, field
from typing import Callable

import xml.parsers.expat as expat

from ..errors import FLOAT32_MAX, WarpclothError
from ..metrics import DEFAULT_INSTABILITY_STRAIN

ROOT_TAG = "test_list"
TEST_TAG = "test"

#: Default wall-clock cap of one run [s] (the seed's one minute).
DEFAULT_CAP = 60.0
#: Default simulated duration [s]: an upper bound for the sheet (it ends at equilibrium), the
#: length of a flag run.
DEFAULT_DURATION = {"sheet": 60.0, "flag": 10.0}
#: Default sampling frame rate [1/s] (the seed's real-time threshold, 30 FPS).
DEFAULT_FRAME_RATE = 30.0
#: Defaults of the max-stable-dt search used by ``timestep="max"``.
DEFAULT_MAXDT_PRECISION = 0.02
DEFAULT_MAXDT_DURATION = 2.0
#: Most runs a test list may expand to unless raised (``warpcloth sweep --max-runs N``): a
#: 2 KB file can name 20^12 combinations; the count is computed before anything is expanded.
DEFAULT_MAX_RUNS = 10_000

SPRING_TYPES = ("structural", "shear", "bend")


# -- values ----------------------------------------------------------------------------------
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


def _positive(text: str) -> float:
    v = _float(text)
    if not v > 0.0:
        raise ValueError(f"{text!r} must be > 0")
    return v


def _non_negative(text: str) -> float:
    v = _float(text)
    if not v >= 0.0:
        raise ValueError(f"{text!r} must be >= 0")
    return v


def _float(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise ValueError(f"{text!r} is not a number") from None
    if not math.isfinite(v):
        raise ValueError(f"{text!r} is not a finite number")
    if abs(v) > FLOAT32_MAX:
        raise ValueError(f"{text!r} does not fit in float32 (|value| <= {FLOAT32_MAX:.4g})")
    return v


def _grid_dim(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise ValueError(f"{text!r} is not an integer") from None
    if v < 3:
        raise ValueError(f"{text!r} must be an integer >= 3")
    return v


def _size(text: str) -> tuple[int, int]:
    parts = text.lower().split("x")
    if len(parts) == 1:
        n = _grid_dim(parts[0])
        return n, n
    if len(parts) == 2:
        return _grid_dim(parts[0]), _grid_dim(parts[1])
    raise ValueError(f"{text!r} is not N or ROWSxCOLS")


def _timestep(text: str) -> TimeStep:
    t = text.lower()
    if t == "default":
        return TimeStep("default")
    if t == "max":
        return TimeStep("max", 1.0)
    if t.startswith("max*"):
        try:
            return TimeStep("max", _positive(t[4:]))
        except ValueError:
            raise ValueError(f"{text!r}: the factor in max*F must be a number > 0") from None
    try:
        return TimeStep("value", _positive(text))
    except ValueError:
        raise ValueError(f"{text!r} is not a time step > 0 [s], 'max', 'max*F' or 'default'") from None


def _cap(text: str) -> float | None:
    if text.lower() == "none":
        return None
    try:
        return _positive(text)
    except ValueError:
        raise ValueError(f"{text!r} is not a number of seconds > 0 or 'none'") from None


def _precision(text: str) -> float:
    v = _float(text)
    if not 0.0 < v < 1.0:
        raise ValueError(f"{text!r} must be between 0 and 1 (relative, e.g. 0.02)")
    return v


def _choice(choices_fn: Callable[[], list[str]], what: str, keyword_all: bool = False):
    def parse(text: str) -> str:
        choices = choices_fn()
        if keyword_all and text == "all":
            return text
        if text not in choices:
            extra = " or 'all'" if keyword_all else ""
            raise ValueError(f"unknown {what} {text!r}; choose from {', '.join(choices)}{extra}")
        return text

    return parse


def _integrators() -> list[str]:
    from ..integrators import integrator_names

    return integrator_names()


def _scenarios() -> list[str]:
    from ..scenarios import scenario_names

    return scenario_names()


def _scenario(text: str) -> str:
    """A scenario name, or a scenario file (.toml, relative to the working folder) that loads."""
    from ..scenarios import get_scenario

    if text.lower().endswith(".toml"):
        try:
            get_scenario(text)
        except WarpclothError as exc:
            raise ValueError(str(exc)) from None
        return text
    return _choice(_scenarios, "scenario")(text)


def _device(text: str) -> str:
    from ..device import device_name as resolve_device

    try:
        return resolve_device(text)
    except WarpclothError as exc:
        raise ValueError(str(exc)) from None


@dataclass(frozen=True)
class Attribute:
    """One attribute of ``test``: its parser and whether it may hold a list of values."""

    name: str
    parse: Callable[[str], object]
    help: str
    is_list: bool = True


ATTRIBUTES: dict[str, Attribute] = {
    a.name: a
    for a in [
        Attribute("id", str, "name of the test, carried into the CSV (default: its position, 1, 2, ...)", is_list=False),
        Attribute("integrator", _choice(_integrators, "integrator", keyword_all=True), "integrator name(s), or 'all'"),
        Attribute("scenarios", _scenario, "scenarios to run: names or scenario files (.toml) (default: sheet flag)"),
        Attribute("size", _size, "mesh size N (N x N) or ROWSxCOLS; excludes rows/cols"),
        Attribute("rows", _grid_dim, "particles per column (with cols)"),
        Attribute("cols", _grid_dim, "particles per row (with rows)"),
        Attribute("timestep", _timestep, "dt [s], 'max', 'max*F' or 'default'"),
        Attribute("stiffness", _non_negative, "spring stiffness ks [N/m] of every spring type"),
        *[Attribute(f"stiffness_{t}", _non_negative, f"ks [N/m] of {t} springs (overrides stiffness)") for t in SPRING_TYPES],
        Attribute("damping", _non_negative, "spring damping kd [N s/m] of every spring type"),
        *[Attribute(f"damping_{t}", _non_negative, f"kd [N s/m] of {t} springs (overrides damping)") for t in SPRING_TYPES],
        Attribute("mass", _positive, "total cloth mass [kg]"),
        Attribute("width", _positive, "cloth width [m]"),
        Attribute("height", _positive, "cloth height [m]"),
        Attribute("drag", _non_negative, "linear air drag rate [1/s]"),
        Attribute("strain_limit", _positive, "Provot deformation constraint tau (force-based integrators)"),
        Attribute("instability_strain", _positive, "a spring strained past this makes the run unstable (default 0.5)"),
        Attribute("graph", _choice(lambda: ["on", "off", "auto"], "graph mode"), "graph capture: on, off or auto (default; results bit-identical)"),
        Attribute("bend", _choice(lambda: ["provot", "choi_ko", "none"], "bend model"), "bend springs"),
        Attribute("device", _device, "Warp device: cpu, cuda, cuda:N"),
        Attribute("cap", _cap, "wall-clock cap of one run [s], or 'none'"),
        Attribute("duration", _positive, "simulated time [s]: the flag's length, the sheet's upper bound"),
        Attribute("frame_rate", _positive, "sampling frame rate [1/s]"),
        Attribute("maxdt_precision", _precision, "relative precision of the max-dt search"),
        Attribute("maxdt_duration", _positive, "simulated time [s] a max-dt trial must survive"),
    ]
}


# -- runs ------------------------------------------------------------------------------------
@dataclass(frozen=True)
class RunSpec:
    """One run of a sweep: a scenario with every parameter resolved (SI units).

    ``stiffness`` and ``damping`` are the effective per-type values (structural, shear, bend).
    ``options`` are the integrator's options given in the file, as sorted (name, value) pairs.
    """

    test_id: str
    line: int
    scenario: str
    integrator: str
    device: str
    rows: int
    cols: int
    width: float
    height: float
    mass: float
    stiffness: tuple[float, float, float]
    damping: tuple[float, float, float]
    drag: float | None
    bend: str
    timestep: TimeStep
    frame_rate: float
    duration: float
    cap: float | None
    options: tuple = ()
    maxdt_precision: float = DEFAULT_MAXDT_PRECISION
    maxdt_duration: float = DEFAULT_MAXDT_DURATION
    strain_limit: float | None = None
    instability_strain: float = DEFAULT_INSTABILITY_STRAIN
    graph: str = "auto"

    @property
    def key(self) -> str:
        """Identity of the run for ``--resume``: every parameter that changes the run, written
        canonically (floats as Python's shortest repr), never the test id or file position."""
        parts = [
            f"scenario={self.scenario}", f"integrator={self.integrator}", f"device={self.device}",
            f"rows={self.rows}", f"cols={self.cols}", f"width={self.width!r}", f"height={self.height!r}",
            f"mass={self.mass!r}", "ks=" + "/".join(map(repr, self.stiffness)), "kd=" + "/".join(map(repr, self.damping)),
            f"drag={'default' if self.drag is None else repr(self.drag)}", f"bend={self.bend}",
            f"timestep={self.timestep}", f"frame_rate={self.frame_rate!r}", f"duration={self.duration!r}",
            f"cap={'none' if self.cap is None else repr(self.cap)}",
        ]
        if self.strain_limit is not None:
            parts.append(f"strain_limit={self.strain_limit!r}")
        if self.instability_strain != DEFAULT_INSTABILITY_STRAIN:
            parts.append(f"instability_strain={self.instability_strain!r}")
        if self.graph != "auto":
            parts.append(f"graph={self.graph}")
        if self.timestep.uses_max:
            parts.append(f"maxdt={self.maxdt_precision!r}/{self.maxdt_duration!r}")
        parts.append("options=" + ",".join(f"{k}={_canon(v)}" for k, v in self.options))
        return ";".join(parts)

    @property
    def search_key(self) -> tuple:
        """What the max-stable-dt search depends on (everything but dt, cap and duration)."""
        return (self.scenario, self.integrator, self.device, self.rows, self.cols, self.width, self.height, self.mass,
                self.stiffness, self.damping, self.drag, self.bend, self.frame_rate, self.options,
                self.maxdt_precision, self.maxdt_duration, self.strain_limit, self.instability_strain)

    def config(self, dt: float | None = None, duration: float | None = None):
        """The :class:`~warpcloth.scenarios.ScenarioConfig` of this run."""
        from ..scenarios import get_scenario

        return get_scenario(self.scenario).config(
            rows=self.rows, cols=self.cols, width=self.width, height=self.height, mass=self.mass,
            integrator=self.integrator, integrator_options=dict(self.options), dt=dt,
            duration=self.duration if duration is None else duration, fps=self.frame_rate,
            stiffness=self.stiffness, damping=self.damping, drag=self.drag, bend=self.bend, device=self.device,
            strain_limit=self.strain_limit, instability_strain=self.instability_strain,
            use_graph={"on": True, "off": False}.get(self.graph),
        )

    def describe(self) -> str:
        """A short label: ``sheet rk4 10x10 dt=max*0.5``."""
        return f"{self.scenario} {self.integrator} {self.rows}x{self.cols} dt={self.timestep}"


def _canon(value) -> str:
    return repr(value) if isinstance(value, float) else str(value)


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

    def error(self, line: int, message: str) -> WarpclothError:
        return WarpclothError(f"{self.path}:{line}: {message}")

    def attr_line(self, element: _Element, name: str) -> int:
        m = re.compile(rb"\s(" + re.escape(name.encode()) + rb")\s*=").search(self.data, max(element.byte, 0))
        if m is None:
            return element.line
        return element.line + self.data.count(b"\n", element.byte, m.start(1))


def _read_tree(path: str) -> tuple[_Source, _Element]:
    try:
        with open(path, "rb") as fh:
            data = fh.read()
    except OSError as exc:
        raise WarpclothError(f"cannot read test list {path}: {exc.strerror or exc}") from None
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
            raise src.error(line, f"unknown element <{tag}> inside <{stack[-1].tag}>; give parameters as attributes of <{TEST_TAG}>")
        el = _Element(tag, dict(attrs), line, parser.CurrentByteIndex)
        (stack[-1].children if stack else root).append(el)
        stack.append(el)

    def end(tag):
        stack.pop()

    def text(data):
        if data.strip():
            where = stack[-1].tag if stack else "the document"
            lead = len(data) - len(data.lstrip())
            raise src.error(parser.CurrentLineNumber + data[:lead].count("\n"), f"unexpected text {data.strip()[:40]!r} inside <{where}>; a test list holds only elements and attributes")

    def doctype(name, *args):
        raise src.error(parser.CurrentLineNumber, f"<!DOCTYPE {name} ...> is not allowed in a test list (no DTDs, entities "
                                                  "or other declarations; only <test_list> and <test> elements)")

    parser.StartDoctypeDeclHandler = doctype
    parser.StartElementHandler = start
    parser.EndElementHandler = end
    parser.CharacterDataHandler = text
    try:
        parser.Parse(data, True)
    except expat.ExpatError as exc:
        raise src.error(exc.lineno, f"malformed XML: {expat.ErrorString(exc.code)} (column {exc.offset + 1})") from None
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
    return TestList(path=str(path), runs=list(unique.values()), tests=len(root.children), duplicates=len(runs) - len(unique))


def _parse_attributes(src: _Source, el: _Element, what: str) -> dict[str, list]:
    """Every attribute of ``el`` as a list of parsed values; integrator options stay text."""
    from ..integrators import all_options

    options = all_options()
    out: dict[str, list] = {}
    for name, raw in el.attrs.items():
        line = src.attr_line(el, name)
        attr = ATTRIBUTES.get(name)
        if attr is None and name not in options:
            known = list(ATTRIBUTES) + list(options)
            close = difflib.get_close_matches(name, known, n=1)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            raise src.error(line, f"{what}: unknown attribute {name!r}{hint}; allowed: {', '.join(known)}")
        tokens = raw.split()
        if not tokens:
            raise src.error(line, f"{what}: attribute {name!r} is empty; give one or more values separated by spaces")
        if attr is None:
            out[name] = tokens  # integrator option: checked against the test's integrators in _expand
            continue
        if not attr.is_list and len(tokens) > 1:
            raise src.error(line, f"{what}: attribute {name!r} takes one value, got {raw!r}")
        parsed = []
        for tok in tokens:
            try:
                parsed.append(attr.parse(tok))
            except ValueError as exc:
                raise src.error(line, f"{what}: {name}: {exc}") from None
        if len(set(map(repr, parsed))) != len(parsed):
            raise src.error(line, f"{what}: attribute {name!r} repeats a value in {raw!r}")
        out[name] = parsed
    return out


def _expand(src: _Source, el: _Element, root: _Element, test_id: str, defaults: dict, own: dict,
            room: int = DEFAULT_MAX_RUNS, max_runs: int = DEFAULT_MAX_RUNS) -> list[RunSpec]:
    """The runs of one ``test``: the product of its value lists, for each scenario."""
    from ..integrators import all_options, integrator_class, integrator_names
    from ..model import default_spring_params
    from ..scenarios import get_scenario

    what = f"test {test_id!r}"
    values = {**defaults, **own}

    def line_of(name):
        return src.attr_line(el, name) if name in own else src.attr_line(root, name)

    if "integrator" not in values:
        raise src.error(el.line, f"{what}: attribute 'integrator' is required (one of {', '.join(integrator_names())}, or 'all')")
    integrators = []
    for name in values["integrator"]:
        for n in (integrator_names() if name == "all" else [name]):
            if n not in integrators:
                integrators.append(n)

    # Mesh: size, or rows and cols together, or the scenario's default.
    if "size" in values and ("rows" in values or "cols" in values):
        other = "rows" if "rows" in values else "cols"
        raise src.error(line_of(other), f"{what}: give either 'size' or 'rows' and 'cols', not both")
    if ("rows" in values) != ("cols" in values):
        missing = "cols" if "rows" in values else "rows"
        raise src.error(el.line, f"{what}: 'rows' needs 'cols' (and 'cols' needs 'rows'); '{missing}' is missing (or use size=\"N\")")
    if "size" in values:
        meshes = values["size"]
    elif "rows" in values:
        meshes = list(itertools.product(values["rows"], values["cols"]))
    else:
        meshes = [None]

    # Integrator options: each must apply to at least one of the test's integrators.
    option_lists: dict[str, list] = {}
    registry = all_options()
    for name in [n for n in values if n not in ATTRIBUTES]:
        _, owners = registry[name]
        takers = [i for i in integrators if name in {o.name for o in integrator_class(i).options}]
        if not takers:
            raise src.error(line_of(name), f"{what}: option {name!r} does not apply to integrator(s) {', '.join(integrators)} (it applies to {', '.join(owners)})")
        parsed = []
        for tok in values[name]:
            for taker in takers:
                opt = next(o for o in integrator_class(taker).options if o.name == name)
                try:
                    parsed.append(opt.parse(tok))
                except WarpclothError as exc:
                    raise src.error(line_of(name), f"{what}: integrator {taker}: {exc}") from None
        option_lists[name] = list(dict.fromkeys(parsed))

    def one(name, default=None):
        return values.get(name, [default])

    dims = {
        "integrator": integrators,
        "mesh": meshes,
        "timestep": one("timestep", TimeStep("default")),
        "stiffness": one("stiffness"),
        **{f"stiffness_{t}": one(f"stiffness_{t}") for t in SPRING_TYPES},
        "damping": one("damping"),
        **{f"damping_{t}": one(f"damping_{t}") for t in SPRING_TYPES},
        "mass": one("mass"),
        "width": one("width"),
        "height": one("height"),
        "drag": one("drag"),
        "strain_limit": one("strain_limit"),
        "instability_strain": one("instability_strain", DEFAULT_INSTABILITY_STRAIN),
        "graph": one("graph", "auto"),
        "bend": one("bend", "provot"),
        "device": one("device", "cpu"),
        "cap": one("cap", DEFAULT_CAP),
        "duration": one("duration"),
        "frame_rate": one("frame_rate", DEFAULT_FRAME_RATE),
        "maxdt_precision": one("maxdt_precision", DEFAULT_MAXDT_PRECISION),
        "maxdt_duration": one("maxdt_duration", DEFAULT_MAXDT_DURATION),
        **{f"option:{k}": v for k, v in option_lists.items()},
        "scenario": one("scenarios", None) if "scenarios" in values else ["sheet", "flag"],
    }
    names = list(dims)
    count = math.prod(len(v) for v in dims.values())  # without expanding
    if count > room:
        sizes = [str(len(v)) for v in dims.values() if len(v) > 1]
        factors = f" ({' x '.join(sizes)})" if len(sizes) > 1 else ""
        before = f" (after {max_runs - room} runs of the tests before it)" if room < max_runs else ""
        raise src.error(el.line, f"{what}: expands to {count} runs{factors}{before}, more than the limit of "
                                 f"{max_runs} runs; raise it with --max-runs N if you mean it")
    runs = []
    for combo in itertools.product(*dims.values()):
        c = dict(zip(names, combo))
        integrator = c["integrator"]
        taken = {o.name for o in integrator_class(integrator).options}
        if c["strain_limit"] is not None and not integrator_class(integrator).force_based:
            raise src.error(el.line, f"{what}: strain_limit applies to force-based integrators, not {integrator!r}")
        options = tuple(sorted((k[7:], v) for k, v in c.items() if k.startswith("option:") and k[7:] in taken))
        scen = get_scenario(c["scenario"])
        d = scen.defaults
        rows, cols = c["mesh"] if c["mesh"] is not None else (d.rows, d.cols)
        if scen.model is None and c["bend"] != "none" and min(rows, cols) < 3:  # a grid (mesh scenarios: rows 1, cols N)  # pragma: no cover - _grid_dim already requires 3
            raise src.error(el.line, f"{what}: a mesh needs at least 3 x 3 particles with bend springs")
        mass = c["mass"] if c["mass"] is not None else d.mass
        ks = [c[f"stiffness_{t}"] if c[f"stiffness_{t}"] is not None else c["stiffness"] for t in SPRING_TYPES]
        kd = [c[f"damping_{t}"] if c[f"damping_{t}"] is not None else c["damping"] for t in SPRING_TYPES]
        params = default_spring_params(
            mass / (rows * cols),
            {t: v for t, v in zip(SPRING_TYPES, ks) if v is not None} or None,
            {t: v for t, v in zip(SPRING_TYPES, kd) if v is not None} or None,
        )
        eff = [params[k] for k in sorted(params)]
        runs.append(RunSpec(
            test_id=test_id, line=el.line, scenario=c["scenario"], integrator=integrator, device=c["device"],
            rows=rows, cols=cols, width=c["width"] if c["width"] is not None else d.width,
            height=c["height"] if c["height"] is not None else d.height, mass=mass,
            stiffness=tuple(p.stiffness for p in eff), damping=tuple(p.damping for p in eff),
            drag=c["drag"], bend=c["bend"], timestep=c["timestep"], frame_rate=c["frame_rate"],
            duration=c["duration"] if c["duration"] is not None else DEFAULT_DURATION.get(c["scenario"], d.duration),
            cap=c["cap"], options=options, maxdt_precision=c["maxdt_precision"], maxdt_duration=c["maxdt_duration"],
            strain_limit=c["strain_limit"], instability_strain=c["instability_strain"], graph=c["graph"],
        ))
    return runs


def load_runs(path: str) -> list[RunSpec]:
    """The expanded runs of the test list at ``path`` (see :func:`parse_test_list`)."""
    return parse_test_list(path).runs


__all__ = ["ATTRIBUTES", "RunSpec", "TestList", "TimeStep", "load_runs", "parse_test_list"]
