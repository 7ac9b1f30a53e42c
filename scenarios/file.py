"""Scenarios described in a small TOML file: ``warpcloth run path/to/scenario.toml``.

The file names a mesh, its pins and pin tracks, the forces and the run's parameters (every key
is optional but ``cloth.mesh``; unknown keys are refused, naming the file and the table)::

    name = "cape"                        # default: the file's stem
    description = "a cape on a walking character"
    stop_at_equilibrium = true           # default true

    [cloth]
    mesh = "cape.obj"                    # .obj or .usd*, relative to this file
    prim = "/World/Cape"                 # USD only (default: the first mesh)
    quads = true                         # quad detection: shear and straight-line bend springs
    bend = true
    mass = 0.3                           # kg in all, or
    # density = 0.2                      # kg/m^2
    mass_mode = "area"                   # or "uniform"
    stiffness = [1000, 1000, 200]        # N/m: one number or structural, shear, bend
    damping = 0.05                       # N s/m (default scales with the particle mass)

    [pins]                               # pinned vertices: the union of
    groups = ["shoulders"]
    where = "y > 0.95 * y.max()"         # a predicate (see warpcloth.sim.selection.parse_predicate)
    indices = [0, 1]

    [[tracks]]                           # kinematic pins (pinned automatically)
    groups = ["shoulders"]               # or where = ..., indices = [...]
    kind = "keyframes"
    times = [0.0, 1.0, 2.0]              # s, increasing
    offsets = [[0, 0, 0], [0.3, 0, 0], [0.3, 0.1, 0]]   # m, added to the rest positions
    interpolation = "catmull_rom"        # linear | catmull_rom | hermite (with tangents)

    [[tracks]]
    indices = [5]
    kind = "rigid"
    center = [0, 1.5, 0]
    axis = [1, 0, 0]
    swing_amplitude = 0.5                # rad; also angular_velocity, swing_frequency, swing_phase, velocity

    [[colliders]]                        # warpcloth.sim.colliders: plane, sphere, capsule, box
    kind = "sphere"
    center = [0, 1.0, 0.3]
    radius = 0.25
    thickness = 0.005                    # m
    friction = 0.4                       # Coulomb mu
    track = { kind = "keyframes", times = [0, 2], offsets = [[0, 0, 0], [0.5, 0, 0]] }   # optional; or
    # track = { kind = "rigid", velocity = [0.2, 0, 0], center = [0, 1, 0.3], axis = [0, 1, 0], angular_velocity = 1.0 }

    [[colliders]]                        # a static triangle mesh (OBJ or USD, relative to this file)
    kind = "mesh"
    path = "table.obj"
    thickness = 0.005

    [forces]
    gravity = [0, -9.81, 0]
    drag = 1.0                           # 1/s
    wind = [4, 0, 1]                     # m/s, constant; or
    # gusts = { wind = [8, 0, 3], on = 1.5, off = 1.0, base = [2, 0, -1] }
    wind_coefficient = 0.6

    [run]
    integrator = "xpbd"
    integrator_options = { iterations = 20 }
    dt = 0.004
    duration = 5.0
    frame_rate = 60                      # 1/s (old spelling: fps)
    device = "cpu"
    strain_limit = 0.1

Command-line flags override the file (``--integrator``, ``--dt``, ``--mesh``, ``--pin-group``...).
Needs Python 3.11 (``tomllib``) or the ``tomli`` package.
"""

from __future__ import annotations

import functools
import os
import re
from dataclasses import replace

import numpy as np

from warpcloth.errors import WarpclothError, require, warn
from warpcloth.sim.control import GRAVITY, Control, WindSchedule
from warpcloth.sim.mesh import build_mesh_cloth, lumped_masses
from warpcloth.io.meshio import load_mesh, load_mesh_collider
from warpcloth.sim.pins import PinTrack
from warpcloth.sim.selection import resolve_pins
from warpcloth.run.params import BY_NAME, config_values, params_for
from warpcloth.scenarios.common import Scenario, ScenarioConfig

TOP_KEYS = {"name", "description", "stop_at_equilibrium", "cloth", "pins", "tracks", "colliders", "forces", "run"}
CLOTH_KEYS = {"mesh", "prim", "quads", "bend", "mass", "density", "mass_mode", "stiffness", "damping"}
PIN_KEYS = {"groups", "where", "indices"}
TRACK_KEYS = PIN_KEYS | {"name", "kind", "times", "offsets", "positions", "interpolation", "tangents", "center", "axis",
                         "angular_velocity", "swing_amplitude", "swing_frequency", "swing_phase", "velocity"}
FORCE_KEYS = {"gravity", "drag", "wind", "gusts", "wind_coefficient"}
GUST_KEYS = {"wind", "on", "off", "base"}
#: [run] takes the run parameters of warpcloth.run.params that set up a run (``fps`` is the old
#: spelling of ``frame_rate``) and the integrator's options as a table.
RUN_PARAMS = tuple(p.name for p in params_for("run") if p.group in ("run", "integrator") and (p.config_field or p.name == "dt"))
RUN_KEYS = {"integrator_options", "fps", *RUN_PARAMS}
_NOTED: set = set()  # old spellings already noted in this process


def _toml():
    try:
        import tomllib
    except ImportError:  # Python 3.10
        try:
            import tomli as tomllib
        except ImportError:
            raise WarpclothError("reading scenario files (.toml) needs Python 3.11 (tomllib) or the tomli package (pip install tomli)") from None
    return tomllib


def is_scenario_file(name: str) -> bool:
    return str(name).lower().endswith(".toml")


def load_scenario(path: str) -> Scenario:
    """The :class:`~warpcloth.scenarios.common.Scenario` described by the TOML file at ``path``
    (cached while the file is unchanged)."""
    path = os.path.abspath(os.fspath(path))
    if not os.path.isfile(path):
        raise WarpclothError(f"scenario file {path!r} does not exist" if not os.path.exists(path) else f"scenario file {path!r} is not a file")
    st = os.stat(path)
    return _load(path, st.st_mtime_ns, st.st_size)


@functools.lru_cache(maxsize=16)
def _load(path: str, mtime_ns: int, size: int) -> Scenario:
    tomllib = _toml()
    where = os.path.basename(path)
    try:
        with open(path, "rb") as f:
            data = tomllib.load(f)
    except tomllib.TOMLDecodeError as exc:
        raise WarpclothError(f"{where}: not valid TOML: {exc}") from None
    except OSError as exc:
        raise WarpclothError(f"cannot read scenario file {path!r}: {exc.strerror or exc}") from None

    def table(parent: dict, key: str, allowed: set, what: str) -> dict:
        value = parent.get(key, {})
        require(isinstance(value, dict), f"{where}: {what} must be a table, got {value!r}")
        _check_keys(value, allowed, f"{where}: [{what}]")
        return value

    _check_keys(data, TOP_KEYS, f"{where}: the top level")
    cloth = table(data, "cloth", CLOTH_KEYS, "cloth")
    pins = table(data, "pins", PIN_KEYS, "pins")
    forces = table(data, "forces", FORCE_KEYS, "forces")
    colliders = _colliders(data.get("colliders", []), where, path)
    run = table(data, "run", RUN_KEYS, "run")
    tracks = data.get("tracks", [])
    require(isinstance(tracks, list), f"{where}: tracks must be an array of tables ([[tracks]]), got {tracks!r}")
    for k, t in enumerate(tracks):
        require(isinstance(t, dict), f"{where}: tracks[{k}] must be a table")
        _check_keys(t, TRACK_KEYS, f"{where}: [[tracks]] #{k + 1}")
    if "gusts" in forces:
        require(isinstance(forces["gusts"], dict), f"{where}: forces.gusts must be a table")
        _check_keys(forces["gusts"], GUST_KEYS, f"{where}: forces.gusts")
        require("wind" not in forces, f"{where}: give forces.wind (constant) or forces.gusts, not both")

    require("mesh" in cloth, f"{where}: cloth.mesh (the mesh file) is required")
    mesh_path = cloth["mesh"]
    require(isinstance(mesh_path, str) and mesh_path, f"{where}: cloth.mesh must be a file name, got {mesh_path!r}")
    mesh_path = os.path.join(os.path.dirname(path), os.path.expanduser(mesh_path))
    prim = cloth.get("prim")
    mesh = load_mesh(mesh_path, prim)
    mass_mode = cloth.get("mass_mode", "area")
    require("mass" not in cloth or "density" not in cloth, f"{where}: give cloth.mass or cloth.density, not both")
    mass = cloth.get("mass")
    if "density" in cloth:
        mass = float(lumped_masses(mesh.vertices, mesh.triangles, density=cloth["density"], mode=mass_mode).sum())

    # check every track and pin selection now, so a bad file fails before any run
    for k, t in enumerate(tracks):
        _track(t, mesh.vertices, mesh.groups, f"{where}: [[tracks]] #{k + 1}")
    pin_indices = list(pins.get("indices", []))

    def model(config: ScenarioConfig, device: str):
        m = load_mesh(config.mesh, config.prim) if config.mesh != mesh_path or config.prim != prim else mesh
        tracked = [p for k, t in enumerate(tracks) for p in _track(t, m.vertices, m.groups, f"{where}: [[tracks]] #{k + 1}").particles]
        return build_mesh_cloth(
            m, total_mass=config.mass, mass_mode=mass_mode, stiffness=config.stiffness, damping=config.damping,
            pins=pin_indices + tracked, pin_groups=config.pin_group or (), pin_where=config.pin_where,
            quads=bool(config.quads), bend=config.bend, bend_rigidity=config.bend_rigidity,
            device=device,
        )

    def pin_tracks(config: ScenarioConfig, model_):
        rest = model_.host["q"].astype(np.float64)
        return [_track(t, rest, model_.host.get("groups", {}), f"{where}: [[tracks]] #{k + 1}") for k, t in enumerate(tracks)]

    def control(config: ScenarioConfig, device: str) -> Control:
        drag = forces.get("drag", 0.0) if config.drag is None else config.drag
        schedule, coefficient = WindSchedule(), float(forces.get("wind_coefficient", 0.0))
        try:
            if "wind" in forces:
                schedule = WindSchedule.constant(_vec3(forces["wind"], f"{where}: forces.wind"))
            elif "gusts" in forces:
                g = forces["gusts"]
                schedule = WindSchedule.gusts(_vec3(g.get("wind"), f"{where}: forces.gusts.wind"), g.get("on"), g.get("off"),
                                              base=_vec3(g.get("base", [0, 0, 0]), f"{where}: forces.gusts.base"))
            if (forces.get("wind") or forces.get("gusts")) and "wind_coefficient" not in forces:
                coefficient = 0.6
            return Control(gravity=_vec3(forces.get("gravity", GRAVITY), f"{where}: forces.gravity"), drag_rate=drag,
                           wind_coefficient=coefficient, wind_schedule=schedule, device=device, colliders=colliders)
        except (TypeError, WarpclothError) as exc:
            raise WarpclothError(f"{where}: [forces]: {exc}") from None

    options = run.get("integrator_options", {})
    require(isinstance(options, dict), f"{where}: run.integrator_options must be a table, got {options!r}")
    require(not ("fps" in run and "frame_rate" in run), f"{where}: give run.frame_rate (or its old spelling run.fps), not both")
    given = {}
    for key, value in run.items():  # checked as the declarations say, like the CLI and the XML
        if key == "integrator_options":
            continue
        name = "frame_rate" if key == "fps" else key
        if isinstance(value, bool) or not isinstance(value, (str, int, float)):
            raise WarpclothError(f"{where}: run.{key} must be a number or a string, got {value!r}")
        if key == "fps" and "fps" not in _NOTED:
            _NOTED.add("fps")
            warn(f"{where}: run.fps is now spelled run.frame_rate (the old name is accepted for now)")
        if name == "device":  # a file names a device a machine may lack: its presence is checked where it runs
            require(isinstance(value, str) and re.fullmatch(r"cpu|cuda(:\d+)?", value) is not None,
                    f"{where}: run.device must be cpu, cuda or cuda:N, got {value!r}")
            given[name] = value
            continue
        try:
            given[name] = BY_NAME[name].parse(value if isinstance(value, str) else repr(value))
        except ValueError as exc:
            raise WarpclothError(f"{where}: run.{key}: {exc}") from None
    dt = given.pop("dt", None)
    require(dt is None or dt.kind != "max", f"{where}: run.dt must be a time step in s or 'default' (max is for test lists)")
    require(given.get("integrator") != "all", f"{where}: run.integrator must name one integrator, not 'all'")
    defaults = ScenarioConfig(
        rows=1, cols=int(mesh.vertices.shape[0]), mass=0.2 if mass is None else mass,
        integrator="explicit_euler", integrator_options=dict(options), duration=10.0, fps=60.0,
        stiffness=_per_type(cloth.get("stiffness")), damping=_per_type(cloth.get("damping")), drag=None,
        bend="provot" if cloth.get("bend", True) else "none", mesh=mesh_path, prim=prim,
        pin_group=tuple(pins.get("groups", ())) or None, pin_where=pins.get("where"), quads=bool(cloth.get("quads", False)),
    )
    defaults = replace(defaults, dt=dt.value if dt is not None and dt.kind == "value" else None, **config_values(given))
    scenario = Scenario(
        name=str(data.get("name", os.path.splitext(where)[0])),
        description=str(data.get("description", f"scenario file {where}")),
        defaults=defaults, pins=lambda rows, cols: [], control=control, origin=lambda config: (0.0, 0.0, 0.0),
        stop_at_equilibrium=bool(data.get("stop_at_equilibrium", True)), model=model, tracks=pin_tracks,
    )
    try:  # the integrator, its options and the pins, checked now
        from warpcloth.integrators import make_integrator

        make_integrator(defaults.integrator, **defaults.integrator_options)
        resolve_pins(mesh.vertices, pin_indices, defaults.pin_group or (), defaults.pin_where, mesh.groups)
    except WarpclothError as exc:
        raise WarpclothError(f"{where}: {exc}") from None
    return scenario


def _colliders(tables, where: str, path: str = "") -> tuple:
    """The [[colliders]] tables: ``kind = "plane" | "sphere" | "capsule" | "box"`` and that
    collider's settings (warpcloth.sim.colliders), e.g. ``center = [0, 1, 0]``, ``radius = 0.3``, and
    optionally a pose ``track = { kind = "rigid" | "keyframes", ... }`` (ColliderTrack); or
    ``kind = "mesh"`` with ``path`` (relative to the scenario file ``path``), ``prim``, ``thickness``,
    ``friction``, ``reach`` (a static MeshCollider)."""
    from warpcloth.sim.colliders import COLLIDER_TYPES, ColliderTrack, MeshCollider

    require(isinstance(tables, list), f"{where}: colliders must be an array of tables ([[colliders]]), got {tables!r}")
    out = []
    for k, t in enumerate(tables):
        what = f"{where}: [[colliders]] #{k + 1}"
        require(isinstance(t, dict), f"{what} must be a table")
        cls = COLLIDER_TYPES.get(t.get("kind"))
        if cls is None:
            raise WarpclothError(f"{what}: kind must be one of {', '.join(COLLIDER_TYPES)}, got {t.get('kind')!r}")
        settings = {key: value for key, value in t.items() if key != "kind"}
        if cls is MeshCollider:
            _check_keys(settings, {"path", "prim", "thickness", "friction", "reach", "track"}, what)
        else:
            _check_keys(settings, set(cls.__dataclass_fields__), what)
        try:
            track = ColliderTrack.from_table(settings.pop("track")) if "track" in settings else None
            if cls is MeshCollider:
                mesh = settings.pop("path", None)
                require(isinstance(mesh, str) and mesh, f"path must be a mesh file name (.obj, .usd), got {mesh!r}")
                out.append(load_mesh_collider(os.path.join(os.path.dirname(path), os.path.expanduser(mesh)), settings.pop("prim", None),
                                              track=track, **settings))
                continue
            out.append(cls(track=track, **{key: tuple(v) if isinstance(v, list) else v for key, v in settings.items()}))
        except WarpclothError as exc:
            raise WarpclothError(f"{what}: {exc}") from None
    return tuple(out)


def _check_keys(d: dict, allowed: set, where: str) -> None:
    unknown = sorted(set(d) - allowed)
    if unknown:
        raise WarpclothError(f"{where}: unknown key {unknown[0]!r} (allowed: {', '.join(sorted(allowed))})")


def _vec3(value, what: str) -> tuple:
    try:
        v = tuple(float(x) for x in value)
    except (TypeError, ValueError):
        raise WarpclothError(f"{what} must be 3 numbers, got {value!r}") from None
    require(len(v) == 3, f"{what} must be 3 numbers, got {value!r}")
    return v


def _per_type(value):
    if value is None or isinstance(value, (int, float)):
        return value
    return tuple(value)


def _track(t: dict, positions: np.ndarray, groups: dict, where: str) -> PinTrack:
    """The :class:`PinTrack` of one [[tracks]] table on a mesh's rest positions and groups."""
    try:
        sel = resolve_pins(positions, t.get("indices", ()), t.get("groups", ()), t.get("where"), groups)
        require(sel.size > 0, "select its pins with groups, where or indices")
        kind = t.get("kind", "keyframes")
        name = str(t.get("name", "track"))
        if kind == "keyframes":
            require("times" in t, "keyframes need times")
            require(("offsets" in t) != ("positions" in t), "give offsets (from the rest positions) or positions, one of them")
            values = t.get("offsets", t.get("positions"))
            extra = set(t) - PIN_KEYS - {"name", "kind", "times", "offsets", "positions", "interpolation", "tangents"}
            if extra:
                raise WarpclothError(f"key {sorted(extra)[0]!r} applies to kind 'rigid', not 'keyframes'")
            return PinTrack.keyframes(sel, t["times"], values, interpolation=t.get("interpolation", "linear"), tangents=t.get("tangents"), name=name)
        if kind == "rigid":
            extra = set(t) & {"times", "offsets", "positions", "interpolation", "tangents"}
            if extra:
                raise WarpclothError(f"key {sorted(extra)[0]!r} applies to kind 'keyframes', not 'rigid'")
            args = {k: t[k] for k in ("center", "axis", "angular_velocity", "swing_amplitude", "swing_frequency", "swing_phase", "velocity") if k in t}
            return PinTrack.rigid(sel, name=name, **args)
        raise WarpclothError(f"kind must be 'keyframes' or 'rigid', got {kind!r}")
    except (TypeError, ValueError) as exc:
        raise WarpclothError(f"{where}: {exc}") from None


__all__ = ["is_scenario_file", "load_scenario"]
