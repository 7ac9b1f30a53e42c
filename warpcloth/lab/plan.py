"""What a study measures: the :class:`StudyPlan`, its :data:`PROFILES` and :func:`make_plan`
(a profile and the command line's overrides, checked), and the groups it is measured in
(:func:`plan_groups`)."""

from __future__ import annotations

import contextlib
import io
from dataclasses import dataclass, field

from warpcloth.errors import WarpclothError, require
from warpcloth.integrators import check_integrator_name, integrator_names
from warpcloth.lab.accuracy import DEFAULT_TOLERANCE, FRAME_DT, TOLERANCES, check_tolerance
from warpcloth.lab.transients import TRANSIENTS
from warpcloth.scenarios import get_scenario
from warpcloth.scenarios.swing import STUDY_MATERIAL
from warpcloth.sim.device import require_memory, resolve_device
from warpcloth.sim.grid import grid_memory_estimate
from warpcloth.sim.material import grid_spring_params
from warpcloth.sim.model import BendModel

#: The study's grid transients (lab/transients.py): swing and flag frame by frame, contact at rest.
SCENARIOS = ("swing", "flag", "contact")
#: The swing's window is at least this long [s] at every size: it holds the whip (the free edge
#: passes the vertical near 0.5 s) and the start of the over-swing (0.6-1.0 s), where the
#: non-explicit integrators make their error (docs/study.md, "Windows").
MIN_SWING_S = 0.6
#: The 60 FPS frame budget the study answers for by default [ms], and the whole frame [ms].
DEFAULT_BUDGET_MS = 2.0
WHOLE_FRAME_MS = 1000.0 / 60.0


@dataclass
class StudyPlan:
    """What a study measures: every integrator's configurations (:mod:`warpcloth.lab.configs`) on
    the transients (:mod:`warpcloth.lab.transients`) at every n x n size of ``sizes``, against
    float64 references, with their conditioning floors, costs and the max stable dt.

    ``windows``: per dynamic transient, its window in 1/60 s frames, the same at every size (design.md,
    "One question at every size": the swing's holds its whip and over-swing, >= :data:`MIN_SWING_S`;
    even: dt = 1/30 s runs compare every other frame); ``level``: the
    configuration grids (``full`` / ``quick``, each integrator's ``study_grid``);
    ``max_frame_ms``: a configuration whose cost per 1/60 s frame, predicted from its group's
    calibration row (measured once, stated in the report), exceeds this is not run (15x the whole
    frame: no budget question reaches it; None: every configuration runs), so the rows are a function
    of the profile and the calibration, never of the load at each configuration; ``run_wall_cap``:
    a run is stopped at twice this [s] (its row says so);
    ``reference_cache``: a folder where
    references and floors are kept for workers and ``--resume`` (set by the study)."""

    profile: str
    integrators: list
    sizes: list
    devices: list
    tolerance: float = DEFAULT_TOLERANCE
    tolerances: tuple = TOLERANCES
    budget_ms: float = DEFAULT_BUDGET_MS
    windows: tuple = (("swing", 36), ("flag", 30))
    level: str = "full"
    run_wall_cap: float = 60.0
    max_frame_ms: float | None = 250.0
    maxdt_precision: float = 0.05
    maxdt_wall_cap: float | None = 30.0
    timing_windows: int = 5
    window_seconds: float = 0.05
    equilibrium_duration: float = 10.0  # s simulated at most (the contact transient)
    equilibrium_wall_cap: float | None = 60.0
    contact_max_size: int = (
        64  # the contact transient up to this n (its equilibrium: SciPy's sparse direct solve, on the CPU)
    )
    reference_cache: str = ""
    grid: bool = True  # the study's transients at the sizes above
    scenario_files: list = field(default_factory=list)  # fixed-mesh scenarios: stability, equilibrium, timing

    def window_frames(self, transient: str, n: int | None = None) -> int:
        """The window of a dynamic transient [1/60 s frames]: the same at every size ``n``."""
        windows = dict(self.windows)
        require(transient in windows, f"no window for the {transient} transient")
        return int(windows[transient])

    def maxdt_duration_at(self, n: int) -> float:
        """The stability trial's simulated duration [s] at size ``n``: the swing's window there."""
        return self.window_frames("swing", n) * FRAME_DT

    @property
    def all_sizes(self) -> list:
        return sorted(set(self.sizes))


PROFILES = {
    # tiny sizes (SciPy references), the quick configuration grids: minutes on 2 CPU cores
    "quick": dict(
        sizes=[4, 6, 8],
        windows=(("swing", 60), ("flag", 30)),  # 1 s: the floor allows it at these sizes
        level="quick",
        run_wall_cap=10.0,
        max_frame_ms=None,  # every configuration runs at these sizes: the rows do not depend on the machine
        maxdt_precision=0.1,
        maxdt_wall_cap=5.0,
        timing_windows=3,
        window_seconds=0.02,
        equilibrium_duration=4.0,
        equilibrium_wall_cap=5.0,
    ),
    # the committed CPU study: 16-128, every configuration, <= 90 min on a 2-core CPU with --workers 2
    # (docs/study.md, "Estimate"); the swing's 0.6 s at every size: 1 s is ill-conditioned from 64x64, where the
    # pointwise e is refused and the coarse metrics decide (docs/study.md, "Windows")
    "standard": dict(sizes=[16, 32, 64, 128], run_wall_cap=60.0, maxdt_wall_cap=30.0, equilibrium_wall_cap=30.0),
    # a GPU (H100/H200): the standard profile's question (swing 0.6 s, flag 0.5 s, every size with its float64
    # reference, the study's cloth) at 64 and 128 with the quick configuration grids and shorter timings, modelled at
    # <= 8 min of device time with compilation from the H200's recorded step costs (docs/gpu.md). Not above 128: from
    # 245x245 the study's bend springs are stiffer than its membrane (make_plan refuses a size that would clamp it),
    # and at 192 the float64 reference alone models at 1.7 min there.
    "gpu": dict(
        sizes=[64, 128],
        devices=["cuda"],
        windows=(("swing", 36), ("flag", 30)),
        level="quick",
        run_wall_cap=20.0,
        maxdt_wall_cap=10.0,
        equilibrium_wall_cap=20.0,
        timing_windows=3,
        window_seconds=0.02,
    ),
}


def make_plan(
    profile: str = "quick",
    integrators=None,
    sizes=None,
    devices=None,
    tolerance=DEFAULT_TOLERANCE,
    scenarios=None,
    budget_ms=None,
) -> StudyPlan:
    """A :class:`StudyPlan` from a profile and explicit overrides (checked; one-line errors)."""
    if profile not in PROFILES:
        raise WarpclothError(f"unknown profile {profile!r}; choose one of {', '.join(PROFILES)}")
    integrators = list(integrator_names() if integrators is None else integrators)
    require(bool(integrators), "the integrator list is empty")
    for name in integrators:
        check_integrator_name(name, flag="--integrators")
    base = dict(PROFILES[profile])
    if sizes is not None:
        sizes = list(sizes)
        require(bool(sizes), "the size list is empty: give sizes like --sizes 8,16")
        for s in sizes:
            require(isinstance(s, int) and s >= 3, f"sizes must be integers >= 3 (n x n particles), got {s!r}")
        base["sizes"] = sizes
    if devices is None:
        devices = base.pop("devices", ["cpu"])
    else:
        base.pop("devices", None)
    devices = list(devices)
    require(bool(devices), "the device list is empty")
    if budget_ms is not None:
        try:
            budget_ms = float(budget_ms)
        except (TypeError, ValueError):
            raise WarpclothError(f"--budget-ms must be a number of milliseconds > 0, got {budget_ms!r}") from None
        require(
            budget_ms > 0 and budget_ms == budget_ms and budget_ms != float("inf"),
            f"--budget-ms must be a number of milliseconds > 0, got {budget_ms!r}",
        )
        base["budget_ms"] = budget_ms
    tol = check_tolerance(tolerance)
    tolerances = tuple(sorted(set(TOLERANCES) | {tol}))
    grid, files = check_scenarios(scenarios)
    if grid:
        check_memory(base["sizes"], devices)
        check_material(base["sizes"])
    return StudyPlan(
        profile=profile,
        integrators=integrators,
        devices=devices,
        tolerance=tol,
        tolerances=tolerances,
        grid=grid,
        scenario_files=files,
        **base,
    )


def check_memory(sizes, devices) -> None:
    """Refuse, before the first run, a size whose n x n cloth a device cannot hold (the grid's
    up-front estimate, :func:`~warpcloth.sim.grid.grid_memory_estimate`); a device that is not
    present is left to the study (it is reported and skipped there)."""
    for device in devices:
        try:
            resolve_device(device)
        except WarpclothError:
            continue
        for n in sorted(sizes, reverse=True):  # the largest first: the one that fails
            require_memory(f"the study's {n} x {n} cloth (--sizes)", grid_memory_estimate(n, n), device)


def clamped_transient(n: int) -> str | None:
    """The first of the study's transients whose n x n cloth of the study's material would have
    membrane springs clamped at 0 N/m by :func:`~warpcloth.sim.material.grid_spring_params` (its
    Provot bend springs, which grow as h^-4, stiffer than the membrane: another material), or None.
    Decided on a 5 x 5 patch at the same spacing: it has every kind of spring the n x n grid has
    (boundary and interior, line ends and middles) with the same stiffness, so it clamps exactly
    when the whole grid does (tests/test_gpu_estimate.py), in a millisecond at any n."""
    for name, transient in TRANSIENTS.items():
        cfg = transient.scenario.defaults
        patch = 4.0 / (n - 1)
        with contextlib.redirect_stderr(io.StringIO()):  # its warning: the refusal below says it instead
            springs = grid_spring_params(
                STUDY_MATERIAL, 5, 5, cfg.width * patch, cfg.height * patch, bend=BendModel.PROVOT
            )
        if springs.clamped:
            return name
    return None


def largest_unclamped_size(below: int) -> int:
    """The largest n < ``below`` whose study cloth is not clamped (:func:`clamped_transient`; the
    bend springs stiffen monotonically as the spacing shrinks, so a bisection finds it)."""
    lo, hi = 3, below  # lo holds, hi clamps
    while hi - lo > 1:
        mid = (lo + hi) // 2
        lo, hi = (lo, mid) if clamped_transient(mid) else (mid, hi)
    return lo


def check_material(sizes) -> None:
    """Refuse a size whose cloth would not be the study's material (:func:`clamped_transient`): a
    study asks one question of one cloth at every size (docs/study.md, "One cloth at every size")."""
    for n in sorted(set(sizes)):
        name = clamped_transient(n)
        if name is not None:
            largest = largest_unclamped_size(n)
            raise WarpclothError(
                f"--sizes: at {n} x {n} the study's {name} cloth would have membrane springs clamped at 0 N/m (its "
                f"bend springs, growing as h^-4, are stiffer than the membrane there): another material, not the "
                f"study's; sizes up to {largest} x {largest} hold it"
            )


def check_scenarios(scenarios) -> tuple[bool, list]:
    """``--scenarios``: (whether the grid study runs, the other scenarios). None: the grid only.
    ``grid`` (or its old names ``sheet`` and ``flag``, together) names the study's transients; any other
    item is a scenario file (.toml) or a registered scenario, loaded here so that a bad one is
    refused before any work."""
    if scenarios is None:
        return True, []

    items = list(dict.fromkeys(scenarios))
    require(bool(items), "the scenario list is empty: give e.g. --scenarios sheet,flag,examples/cape.toml")
    grid_names = ("grid", "sheet", "flag")
    grid = [s for s in items if s in grid_names]
    if grid in (["sheet"], ["flag"]):
        raise WarpclothError(
            f"--scenarios: {grid[0]} without {'flag' if grid[0] == 'sheet' else 'sheet'}: the study's sheet and "
            "flag go together (the accuracy uses both); give both, or grid, or neither"
        )
    files = [s for s in items if s not in grid_names]
    for name in files:
        get_scenario(name)  # WarpclothError: unknown name, missing or malformed file
    return bool(grid), files


def plan_groups(plan: StudyPlan) -> list:
    """(device, integrator, n or scenario) of every group: the grid sizes, then the scenarios."""
    grid = [(d, i, n) for d in plan.devices for n in plan.all_sizes for i in plan.integrators] if plan.grid else []
    return grid + [(d, i, sc) for d in plan.devices for sc in plan.scenario_files for i in plan.integrators]


def group_label(n) -> str:
    """A group's size for people: ``8x8``, or the scenario of a fixed-mesh group."""
    return n if isinstance(n, str) else f"{n}x{n}"


__all__ = [
    "DEFAULT_BUDGET_MS",
    "MIN_SWING_S",
    "PROFILES",
    "SCENARIOS",
    "WHOLE_FRAME_MS",
    "StudyPlan",
    "check_material",
    "check_scenarios",
    "clamped_transient",
    "group_label",
    "largest_unclamped_size",
    "make_plan",
    "plan_groups",
]
