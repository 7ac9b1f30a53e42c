"""Scenarios described in a small TOML file: ``warpcloth run path/to/scenario.toml``.

The file names a mesh, its pins and pin tracks, the forces and the run's parameters (every key
is optional but ``cloth.mesh``; unknown keys are refused, naming the file and the table)::

    name = "cape"                        # default: the file's stem

    [cloth]
    mesh = "cape.obj"                    # .obj or .usd*, relative to this file
    material = "cotton"                  # or mass [kg], stiffness [N/m], damping [N s/m]

    [pins]
    groups = ["shoulders"]               # and/or where = "y > 0.95 * y.max()", indices = [...]

    [run]
    integrator = "xpbd"
    dt = 0.004                           # s

Tables ``[cloth]``, ``[pins]``, ``[[tracks]]``, ``[[colliders]]``, ``[forces]`` and ``[run]``; every
key with its unit and default: docs/meshes.md, "Scenario files: every key". Command-line flags
override the file (``--integrator``, ``--dt``, ``--mesh``, ``--pin-group``...). Needs Python 3.11
(``tomllib``) or the ``tomli`` package.
"""

from __future__ import annotations

import functools
import os
import re
from dataclasses import replace

import numpy as np

from warpcloth.errors import WarpclothError, require, require_vector, warn
from warpcloth.integrators import make_integrator
from warpcloth.io.files import check_input_file, read_input
from warpcloth.io.meshio import load_mesh, load_mesh_collider
from warpcloth.run.params import (
    BY_NAME,
    SELF_COLLISION_SETTINGS,
    check_self_collision_settings,
    config_values,
    non_negative,
    params_for,
    positive,
)
from warpcloth.scenarios.common import Scenario, ScenarioConfig, check_rigidity, scenario_material
from warpcloth.sim.colliders import COLLIDER_TYPES, ColliderTrack, MeshCollider
from warpcloth.sim.control import GRAVITY, Control, WindSchedule
from warpcloth.sim.material import material_mesh_cloth
from warpcloth.sim.mesh import MASS_MODES, build_mesh_cloth, lumped_masses
from warpcloth.sim.pins import PinTrack
from warpcloth.sim.selection import parse_predicate, resolve_pins

TOP_KEYS = {"name", "description", "stop_at_equilibrium", "cloth", "pins", "tracks", "colliders", "forces", "run"}
#: [cloth] takes the material's run parameters (warpcloth.run.params, group "material"; density is the
#: material's with a material, else the areal density the masses come from) and bend_rigidity.
MATERIAL_KEYS = tuple(p.name for p in params_for("run") if p.group == "material")
CLOTH_KEYS = {
    "mesh",
    "prim",
    "quads",
    "bend",
    "mass",
    "density",
    "mass_mode",
    "stiffness",
    "damping",
    "bend_rigidity",
    *MATERIAL_KEYS,
}
PIN_KEYS = {"groups", "where", "indices"}
TRACK_KEYS = PIN_KEYS | {
    "name",
    "kind",
    "times",
    "offsets",
    "positions",
    "interpolation",
    "tangents",
    "center",
    "axis",
    "angular_velocity",
    "swing_amplitude",
    "swing_frequency",
    "swing_phase",
    "velocity",
}
FORCE_KEYS = {"gravity", "drag", "wind", "gusts", "wind_coefficient"}
GUST_KEYS = {"wind", "on", "off", "base"}
#: [run] takes the run parameters of warpcloth.run.params that set up a run (self-collision among
#: them; ``fps`` is the old spelling of ``frame_rate``) and the integrator's options as a table.
RUN_PARAMS = tuple(
    p.name for p in params_for("run") if p.group in ("run", "integrator", "self_collision") and p.config_field
)
RUN_KEYS = {"integrator_options", "fps", *RUN_PARAMS}
#: The largest scenario file read [bytes] (a scenario file is a page of settings; keyframes of a
#: long track fit many times over).
MAX_FILE_BYTES = 1 << 20
#: The deepest nesting of tables and arrays in a scenario file (the deepest the format needs: a
#: collider's track's offsets, 5).
MAX_DEPTH = 8
_NOTED: set = set()  # old spellings already noted in this process


def _toml():
    try:
        import tomllib  # noqa: PLC0415 (tomllib is Python 3.11+; 3.10 reads tomli)
    except ImportError:  # Python 3.10
        try:
            import tomli as tomllib  # noqa: PLC0415 (tomllib is Python 3.11+; 3.10 reads tomli)
        except ImportError:
            raise WarpclothError(
                "reading scenario files (.toml) needs Python 3.11 (tomllib) or the tomli package (pip install tomli)"
            ) from None
    return tomllib


def is_scenario_file(name: str) -> bool:
    return str(name).lower().endswith(".toml")


def load_scenario(path: str) -> Scenario:
    """The :class:`~warpcloth.scenarios.common.Scenario` described by the TOML file at ``path``
    (cached while the file is unchanged)."""
    path = os.path.abspath(os.fspath(path))
    check_input_file(path, "scenario file", MAX_FILE_BYTES)
    st = os.stat(path)
    return _load(path, st.st_mtime_ns, st.st_size)


def read_toml(path: str, where: str) -> dict:
    """The table of a TOML file, read within bounds: at most :data:`MAX_FILE_BYTES`, UTF-8,
    nested at most :data:`MAX_DEPTH` deep; any failure is one line naming the file."""
    tomllib = _toml()
    data = read_input(path, "scenario file", MAX_FILE_BYTES)
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise WarpclothError(
            f"{where}: not UTF-8 text (byte 0x{data[exc.start]:02x} at offset {exc.start}); a scenario "
            "file is TOML, which is UTF-8"
        ) from None
    depth = _bracket_depth(text)
    if depth > MAX_DEPTH:
        raise WarpclothError(
            f"{where}: tables and arrays nested {depth} deep; a scenario file nests at most {MAX_DEPTH}"
        )
    try:
        table = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise WarpclothError(f"{where}: not valid TOML: {_cut(str(exc))}") from None
    except (RecursionError, MemoryError):
        raise WarpclothError(f"{where}: too deeply nested or too large to read as TOML") from None
    if _table_depth(table) > MAX_DEPTH:  # dotted keys nest tables without brackets
        raise WarpclothError(
            f"{where}: tables and arrays nested more than {MAX_DEPTH} deep; a scenario file nests at most {MAX_DEPTH}"
        )
    return table


def _bracket_depth(text: str) -> int:
    """The deepest nesting of ``[`` and ``{`` outside strings and comments (an upper bound on the
    depth TOML's reader recurses to, checked before it runs)."""
    deepest = depth = 0
    k, n = 0, len(text)
    while k < n:
        ch = text[k]
        if ch == "#":
            k = text.find("\n", k)
            k = n if k < 0 else k
            continue
        if ch in "\"'":
            quote = ch * 3 if text.startswith(ch * 3, k) else ch
            k += len(quote)
            while k < n and not text.startswith(quote, k):
                k += 2 if ch == '"' and text[k] == "\\" else 1
            k += len(quote)
            continue
        if ch in "[{":
            depth += 1
            deepest = max(deepest, depth)
        elif ch in "]}":
            depth = max(0, depth - 1)
        k += 1
    return deepest


def _table_depth(value) -> int:
    """The nesting depth of a parsed TOML value (dotted keys nest tables without brackets)."""
    deepest, todo = 0, [(value, 0)]
    while todo:
        v, d = todo.pop()
        if isinstance(v, dict):
            todo.extend((x, d + 1) for x in v.values())
        elif isinstance(v, list):
            todo.extend((x, d + 1) for x in v)
        else:
            continue
        deepest = max(deepest, d + 1)
        if deepest > MAX_DEPTH:
            break
    return deepest


def _cut(text: str, limit: int = 160) -> str:
    text = " ".join(text.split())
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _shown(value) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


class _Keys:
    """Typed access to one table of a scenario file: every error names the file, the key and
    the value (``cape.toml: cloth.mass: '-1.0' must be > 0``)."""

    def __init__(self, where: str, table: dict, prefix: str):
        self.where, self.table, self.prefix = where, table, prefix

    def name(self, key: str) -> str:
        return f"{self.prefix}.{key}" if self.prefix else key

    def fail(self, key: str, message: str):
        return WarpclothError(f"{self.where}: {self.name(key)}: {message}")

    def param(self, key: str, name: str | None = None):
        """The value of ``key`` parsed by the run parameter ``name`` (default ``key``) of
        :mod:`warpcloth.run.params`: the CLI flag's and the XML attribute's type and range."""
        if key not in self.table:
            return None
        try:
            return BY_NAME[name or key].from_typed(self.table[key])
        except ValueError as exc:
            raise self.fail(key, f"{exc}") from None

    def boolean(self, key: str, default: bool) -> bool:
        value = self.table.get(key, default)
        if not isinstance(value, bool):
            raise self.fail(key, f"must be true or false, got {_shown(value)}")
        return value

    def text(self, key: str, default=None):
        value = self.table.get(key, default)
        if value is not None and (not isinstance(value, str) or not value.strip()):
            raise self.fail(key, f"must be a non-empty string, got {_shown(value)}")
        return value

    def number(self, key: str, parse, default=None):
        if key not in self.table:
            return default
        value = self.table[key]
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self.fail(key, f"must be a number, got {_shown(value)}")
        try:
            return parse(repr(float(value)))
        except ValueError as exc:
            raise self.fail(key, f"{exc}") from None

    def vector(self, key: str, default=None, unit: str = ""):
        if key not in self.table:
            return default
        return _vec3(self.table[key], f"{self.where}: {self.name(key)}", unit)

    def names(self, key: str) -> tuple:
        value = self.table.get(key, [])
        items = [value] if isinstance(value, str) else value
        if not isinstance(items, list) or any(not isinstance(v, str) or not v.strip() for v in items):
            raise self.fail(key, f"must be a list of names (strings), got {_shown(value)}")
        return tuple(items)

    def indices(self, key: str) -> list:
        value = self.table.get(key, [])
        if not isinstance(value, list):
            raise self.fail(key, f"must be a list of vertex indices (integers), got {_shown(value)}")
        for v in value:
            if isinstance(v, bool) or not isinstance(v, int):
                raise self.fail(key, f"must be a list of vertex indices (integers), got {_shown(v)} in {_shown(value)}")
            if v < 0:
                raise self.fail(key, f"vertex index {v} is negative")
        return list(value)


def _predicate(keys: _Keys, key: str):
    """A pin predicate (``where``) of a file: a string, parsed now (an error names the key)."""
    text = keys.text(key)
    if text is None:
        return None
    try:
        parse_predicate(text)
    except WarpclothError as exc:
        raise keys.fail(key, str(exc)) from None
    return text


@functools.lru_cache(maxsize=16)
def _load(path: str, mtime_ns: int, size: int) -> Scenario:
    where = os.path.basename(path)
    data = read_toml(path, where)

    def table(parent: dict, key: str, allowed: set, what: str) -> dict:
        value = parent.get(key, {})
        require(isinstance(value, dict), f"{where}: {what} must be a table, got {_shown(value)}")
        _check_keys(value, allowed, f"{where}: [{what}]")
        return value

    _check_keys(data, TOP_KEYS, f"{where}: the top level")
    top = _Keys(where, data, "")
    cloth = table(data, "cloth", CLOTH_KEYS, "cloth")
    pins = table(data, "pins", PIN_KEYS, "pins")
    forces = table(data, "forces", FORCE_KEYS, "forces")
    run = table(data, "run", RUN_KEYS, "run")
    tracks = data.get("tracks", [])
    require(isinstance(tracks, list), f"{where}: tracks must be an array of tables ([[tracks]]), got {_shown(tracks)}")
    for k, t in enumerate(tracks):
        require(isinstance(t, dict), f"{where}: tracks[{k}] must be a table")
        _check_keys(t, TRACK_KEYS, f"{where}: [[tracks]] #{k + 1}")
        tk = _Keys(where, t, f"tracks[{k}]")
        tk.indices("indices"), tk.names("groups"), _predicate(tk, "where"), tk.text("name"), tk.text("kind")
    if "gusts" in forces:
        require(
            isinstance(forces["gusts"], dict), f"{where}: forces.gusts must be a table, got {_shown(forces['gusts'])}"
        )
        _check_keys(forces["gusts"], GUST_KEYS, f"{where}: forces.gusts")
        require("wind" not in forces, f"{where}: give forces.wind (constant) or forces.gusts, not both")

    c = _Keys(where, cloth, "cloth")
    require("mesh" in cloth, f"{where}: cloth.mesh (the mesh file) is required")
    mesh_path = c.param("mesh")
    mesh_path = os.path.join(os.path.dirname(path), os.path.expanduser(mesh_path))
    prim = c.param("prim")
    mesh = load_mesh(mesh_path, prim)
    # indices in the file number the mesh file's vertices; a mesh read without its loose vertices renumbers them
    tracks = [
        dict(t, indices=mesh.file_indices(t["indices"], f"{where}: tracks[{k}].indices")) if "indices" in t else t
        for k, t in enumerate(tracks)
    ]
    mass_mode = c.text("mass_mode", "area")
    if mass_mode not in MASS_MODES:
        raise c.fail("mass_mode", f"must be one of {', '.join(MASS_MODES)}, got {_shown(mass_mode)}")
    require("mass" not in cloth or "density" not in cloth, f"{where}: give cloth.mass or cloth.density, not both")
    mass = c.param("mass")
    density = c.number("density", positive)
    material = c.param("material")
    material_values = {k: c.param(k) for k in MATERIAL_KEYS if k not in ("material", "density")}
    if material is not None and material != "none":
        clash = next((k for k in ("mass", "mass_mode", "stiffness", "damping") if k in cloth), None)
        if clash is not None:
            raise c.fail(clash, f"does not go with cloth.material {material!r} (its density and stiffnesses give them)")
        material_values["density"], density = density, None
    else:
        clash = next((k for k, v in material_values.items() if v is not None), None)
        if material == "none" and density is not None:  # as the CLI's --material none --density
            clash = "density"
        if clash is not None:
            raise c.fail(
                clash,
                "is a material's value and cloth.material is 'none' (no material): give a material (a preset, or "
                "custom), or the per-spring cloth's cloth.mass [kg], or cloth.density without material = 'none'"
                if material == "none"
                else "is a material's value: give cloth.material (a preset, or custom)",
            )
    if density is not None:
        mass = float(lumped_masses(mesh.vertices, mesh.triangles, density=density, mode=mass_mode).sum())
    bend = cloth.get("bend", True)
    if isinstance(bend, bool):
        bend = "provot" if bend else "none"
    else:
        bend = c.param("bend")
    quads = c.boolean("quads", False)
    stiffness, damping = c.param("stiffness"), c.param("damping")
    bend_rigidity = c.param("bend_rigidity")

    # the pins, the tracks, the forces and the colliders checked now, so a bad file fails before any run
    p = _Keys(where, pins, "pins")
    pin_indices, pin_groups, pin_where = p.indices("indices"), p.names("groups"), _predicate(p, "where")
    pin_indices = mesh.file_indices(pin_indices, f"{where}: pins.indices")
    for k, t in enumerate(tracks):
        _track(t, mesh.vertices, mesh.groups, f"{where}: [[tracks]] #{k + 1}")
    f = _Keys(where, forces, "forces")
    gravity = f.vector("gravity", GRAVITY, "m/s^2")
    drag_given = f.param("drag")
    schedule, coefficient = WindSchedule(), f.number("wind_coefficient", non_negative)
    try:
        if "wind" in forces:
            schedule = WindSchedule.constant(f.vector("wind", unit="m/s"))
        elif "gusts" in forces:
            g = _Keys(where, forces["gusts"], "forces.gusts")
            for key in ("wind", "on", "off"):
                require(key in forces["gusts"], f"{where}: forces.gusts.{key} is required")
            schedule = WindSchedule.gusts(
                g.vector("wind", unit="m/s"),
                g.number("on", positive),
                g.number("off", positive),
                base=g.vector("base", (0.0, 0.0, 0.0), "m/s"),
            )
    except WarpclothError as exc:
        raise WarpclothError(_prefixed(where, exc)) from None
    if coefficient is None:
        coefficient = 0.6 if ("wind" in forces or "gusts" in forces) else 0.0
    colliders = _colliders(data.get("colliders", []), where, path)

    def model(config: ScenarioConfig, device: str):
        m = load_mesh(config.mesh, config.prim) if config.mesh != mesh_path or config.prim != prim else mesh
        tracked = [
            p
            for k, t in enumerate(tracks)
            for p in _track(t, m.vertices, m.groups, f"{where}: [[tracks]] #{k + 1}").particles
        ]
        mat = scenario_material(config)
        if mat is not None:
            return material_mesh_cloth(
                mat,
                m,
                pins=pin_indices + tracked,
                pin_groups=config.pin_group or (),
                pin_where=config.pin_where,
                quads=bool(config.quads),
                bend=config.bend,
                device=device,
            )
        check_rigidity(config.bend_rigidity)
        return build_mesh_cloth(
            m,
            total_mass=config.mass,
            mass_mode=mass_mode,
            stiffness=config.stiffness,
            damping=config.damping,
            pins=pin_indices + tracked,
            pin_groups=config.pin_group or (),
            pin_where=config.pin_where,
            quads=bool(config.quads),
            bend=config.bend,
            bend_rigidity=config.bend_rigidity,
            device=device,
        )

    def pin_tracks(config: ScenarioConfig, model_):
        rest = model_.host.q.astype(np.float64)
        return [_track(t, rest, model_.host.groups, f"{where}: [[tracks]] #{k + 1}") for k, t in enumerate(tracks)]

    def control(config: ScenarioConfig, device: str) -> Control:
        drag = (0.0 if drag_given is None else drag_given) if config.drag is None else config.drag
        try:
            return Control(
                gravity=gravity,
                drag_rate=drag,
                wind_coefficient=coefficient,
                wind_schedule=schedule,
                device=device,
                colliders=colliders,
            )
        except WarpclothError as exc:
            raise WarpclothError(f"{where}: [forces]: {exc}") from None

    options = run.get("integrator_options", {})
    require(isinstance(options, dict), f"{where}: run.integrator_options must be a table, got {_shown(options)}")
    require(
        not ("fps" in run and "frame_rate" in run),
        f"{where}: give run.frame_rate (or its old spelling run.fps), not both",
    )
    r = _Keys(where, run, "run")
    given = {}
    for key in run:  # checked as the declarations say, like the CLI and the XML
        if key == "integrator_options":
            continue
        name = "frame_rate" if key == "fps" else key
        if key == "fps" and "fps" not in _NOTED:
            _NOTED.add("fps")
            warn(f"{where}: run.fps is now spelled run.frame_rate (the old name is accepted for now)")
        if name == "device":  # a file names a device a machine may lack: its presence is checked where it runs
            value = run[key]
            if not isinstance(value, str) or re.fullmatch(r"cpu|cuda(:\d+)?", value) is None:
                raise r.fail(key, f"must be cpu, cuda or cuda:N, got {_shown(value)}")
            given[name] = value
            continue
        given[name] = r.param(key, name)
    require(
        given.get("dt") is None or not given["dt"].uses_max,
        f"{where}: run.dt must be a time step in s or 'default' (max is for test lists)",
    )
    require(given.get("integrator") != "all", f"{where}: run.integrator must name one integrator, not 'all'")
    defaults = ScenarioConfig(
        rows=1,
        cols=int(mesh.vertices.shape[0]),
        mass=0.2 if mass is None else mass,
        integrator="explicit_euler",
        duration=10.0,
        fps=60.0,
        stiffness=stiffness,
        damping=damping,
        drag=None,
        bend=bend,
        mesh=mesh_path,
        prim=prim,
        pin_group=pin_groups or None,
        pin_where=pin_where,
        quads=quads,
        bend_rigidity=bend_rigidity,
        material=material,
        **material_values,
    )
    defaults = replace(defaults, **config_values(given))
    # the file's options are its integrator's scene settings: a flag for one of them wins, and another
    # integrator chosen by a flag runs with its own (in the configuration, the CLI's options replaced them)
    integrator_defaults = {defaults.integrator: dict(options)} if options else {}
    scenario = Scenario(
        name=top.text("name", os.path.splitext(where)[0]),
        description=top.text("description", f"scenario file {where}"),
        defaults=defaults,
        pins=lambda rows, cols: [],
        control=control,
        origin=lambda config: (0.0, 0.0, 0.0),
        stop_at_equilibrium=top.boolean("stop_at_equilibrium", True),
        model=model,
        tracks=pin_tracks,
        integrator_defaults=integrator_defaults,
    )
    try:  # the integrator, its options and the pins, checked now
        make_integrator(defaults.integrator, **options)
        scenario_material(defaults)
        resolve_pins(mesh.vertices, pin_indices, defaults.pin_group or (), defaults.pin_where, mesh.groups)
        on = scenario.self_collision if defaults.self_collision is None else defaults.self_collision
        given = {name: getattr(defaults, name) for name in SELF_COLLISION_SETTINGS}  # the CLI's rule, for [run]
        check_self_collision_settings(given, on, scenario.name, spell=lambda p: f"[run] {p.name}")
    except WarpclothError as exc:
        raise WarpclothError(f"{where}: {exc}") from None
    return scenario


def _prefixed(where: str, exc: Exception) -> str:
    text = str(exc)
    return text if text.startswith(f"{where}:") else f"{where}: [forces]: {text}"


def _colliders(tables, where: str, path: str = "") -> tuple:
    """The [[colliders]] tables: ``kind = "plane" | "sphere" | "capsule" | "box"`` and that
    collider's settings (warpcloth.sim.colliders), e.g. ``center = [0, 1, 0]``, ``radius = 0.3``, and
    optionally a pose ``track = { kind = "rigid" | "keyframes", ... }`` (ColliderTrack); or
    ``kind = "mesh"`` with ``path`` (relative to the scenario file ``path``), ``prim``, ``thickness``,
    ``friction``, ``reach`` (a static MeshCollider)."""
    require(
        isinstance(tables, list), f"{where}: colliders must be an array of tables ([[colliders]]), got {_shown(tables)}"
    )
    out = []
    for k, t in enumerate(tables):
        what = f"{where}: [[colliders]] #{k + 1}"
        require(isinstance(t, dict), f"{what} must be a table")
        kind = t.get("kind")
        cls = COLLIDER_TYPES.get(kind) if isinstance(kind, str) else None
        if cls is None:
            raise WarpclothError(f"{what}: kind must be one of {', '.join(COLLIDER_TYPES)}, got {_shown(kind)}")
        settings = {key: value for key, value in t.items() if key != "kind"}
        if cls is MeshCollider:
            _check_keys(settings, {"path", "prim", "thickness", "friction", "reach", "track", "edge_radius"}, what)
        else:
            _check_keys(settings, set(cls.__dataclass_fields__), what)
        for key, value in settings.items():
            if key in ("track", "path", "prim"):
                continue
            if isinstance(value, list):
                ok = all(not isinstance(v, bool) and isinstance(v, (int, float)) for v in value)
            else:
                ok = not isinstance(value, bool) and isinstance(value, (int, float))
            if not ok:
                raise WarpclothError(f"{what}: {key} must be a number or a list of numbers, got {_shown(value)}")
        try:
            track = ColliderTrack.from_table(settings.pop("track")) if "track" in settings else None
            if cls is MeshCollider:
                mesh = settings.pop("path", None)
                require(
                    isinstance(mesh, str) and mesh.strip() != "",
                    f"path must be a mesh file name (.obj, .usd), got {_shown(mesh)}",
                )
                prim = settings.pop("prim", None)
                require(
                    prim is None or (isinstance(prim, str) and prim.strip() != ""),
                    f"prim must be a prim path such as '/World/Table', got {_shown(prim)}",
                )
                out.append(
                    load_mesh_collider(
                        os.path.join(os.path.dirname(path), os.path.expanduser(mesh)), prim, track=track, **settings
                    )
                )
                continue
            out.append(cls(track=track, **{key: tuple(v) if isinstance(v, list) else v for key, v in settings.items()}))
        except WarpclothError as exc:
            raise WarpclothError(f"{what}: {exc}") from None
        except (TypeError, ValueError) as exc:
            raise WarpclothError(f"{what}: {_cut(str(exc))}") from None
    return tuple(out)


def _check_keys(d: dict, allowed: set, where: str) -> None:
    unknown = sorted(set(d) - allowed)
    if unknown:
        raise WarpclothError(f"{where}: unknown key {_shown(unknown[0])} (allowed: {', '.join(sorted(allowed))})")


def _vec3(value, what: str, unit: str = "") -> tuple:
    """Three finite numbers (float32 range), or one line naming ``what`` and the value."""
    if isinstance(value, list) and any(isinstance(v, bool) or not isinstance(v, (int, float)) for v in value):
        raise WarpclothError(f"{what} must be 3 numbers{(' [' + unit + ']') if unit else ''}, got {_shown(value)}")
    return require_vector(what, value, 3, unit)


def _track(t: dict, positions: np.ndarray, groups: dict, where: str) -> PinTrack:
    """The :class:`PinTrack` of one [[tracks]] table on a mesh's rest positions and groups."""
    try:
        sel = resolve_pins(positions, t.get("indices", ()), t.get("groups", ()), t.get("where"), groups)
        require(sel.size > 0, "select its pins with groups, where or indices")
        kind = t.get("kind", "keyframes")
        name = str(t.get("name", "track"))
        if kind == "keyframes":
            require("times" in t, "keyframes need times")
            require(
                ("offsets" in t) != ("positions" in t),
                "give offsets (from the rest positions) or positions, one of them",
            )
            values = t.get("offsets", t.get("positions"))
            extra = set(t) - PIN_KEYS - {"name", "kind", "times", "offsets", "positions", "interpolation", "tangents"}
            if extra:
                raise WarpclothError(f"key {sorted(extra)[0]!r} applies to kind 'rigid', not 'keyframes'")
            return PinTrack.keyframes(
                sel,
                t["times"],
                values,
                interpolation=t.get("interpolation", "linear"),
                tangents=t.get("tangents"),
                name=name,
            )
        if kind == "rigid":
            extra = set(t) & {"times", "offsets", "positions", "interpolation", "tangents"}
            if extra:
                raise WarpclothError(f"key {sorted(extra)[0]!r} applies to kind 'keyframes', not 'rigid'")
            args = {
                k: t[k]
                for k in (
                    "center",
                    "axis",
                    "angular_velocity",
                    "swing_amplitude",
                    "swing_frequency",
                    "swing_phase",
                    "velocity",
                )
                if k in t
            }
            return PinTrack.rigid(sel, name=name, **args)
        raise WarpclothError(f"kind must be 'keyframes' or 'rigid', got {kind!r}")
    except (TypeError, ValueError) as exc:
        raise WarpclothError(f"{where}: {exc}") from None


__all__ = ["is_scenario_file", "load_scenario"]
