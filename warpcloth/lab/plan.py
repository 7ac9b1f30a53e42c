"""What a study measures: the :class:`StudyPlan`, its :data:`PROFILES` and :func:`make_plan`
(a profile and the command line's overrides, checked), and the groups it is measured in
(:func:`plan_groups`)."""

from __future__ import annotations

from dataclasses import dataclass, field

from warpcloth.errors import WarpclothError, require
from warpcloth.lab.accuracy import DEFAULT_TOLERANCE, Transient, check_tolerance

#: The study's two grid scenarios (the accuracy uses both).
SCENARIOS = ("sheet", "flag")


@dataclass
class StudyPlan:
    """What a study measures. ``sizes``: the timing/stability ladder (n x n); ``accuracy_sizes``:
    where the float64 references are computed (their timing is measured too)."""

    profile: str
    integrators: list
    sizes: list
    accuracy_sizes: list
    devices: list
    tolerance: float = DEFAULT_TOLERANCE
    sheet_transient: float = 1.0  # s
    flag_transient: float = 0.5  # s
    maxdt_duration: float = 1.0  # s each stability trial must survive
    maxdt_durations: tuple = ()  # ((n_min, seconds), ...): shorter trials from size n_min up (large sizes)
    maxdt_precision: float = 0.05
    maxdt_wall_cap: float | None = 30.0
    accurate_precision: float = 0.05
    accuracy_k_max: int = 4096  # the accuracy search's bound: dt >= (1/60 s) / max(this, 64 k_stable)
    windows: int = 5
    window_seconds: float = 0.1
    equilibrium_duration: float = 10.0  # s simulated at most
    equilibrium_wall_cap: float | None = 30.0
    static_max_size: int = 64  # the float64 equilibrium (Newton) up to this n
    error_ladder: tuple = (1, 2, 4, 8, 16, 32, 64)  # steps per frame, at the smallest accuracy size
    timing_scenarios: tuple = ("sheet",)
    extra_dt_fractions: tuple = ()  # timing also at max stable dt x each (the seed's "two smaller")
    match_accuracy: bool = False
    grid: bool = True  # the sheet and flag at the sizes above
    scenario_files: list = field(default_factory=list)  # fixed-mesh scenarios (files or registered names): stability, equilibrium, timing

    def maxdt_duration_at(self, n: int) -> float:
        """The stability trial's simulated duration [s] at size ``n`` (``maxdt_durations``)."""
        out = self.maxdt_duration
        for n_min, seconds in sorted(self.maxdt_durations):
            if n >= n_min:
                out = seconds
        return out

    @property
    def all_sizes(self) -> list:
        return sorted(set(self.sizes) | set(self.accuracy_sizes))

    def transient(self, scenario: str) -> Transient:
        return Transient(scenario, self.sheet_transient if scenario == "sheet" else self.flag_transient, swing=scenario == "sheet")


PROFILES = {
    "quick": dict(sizes=[4, 6, 8], accuracy_sizes=[4, 6], sheet_transient=0.5, flag_transient=0.25, maxdt_duration=0.5,
                  maxdt_precision=0.1, accurate_precision=0.1, window_seconds=0.03, equilibrium_duration=4.0,
                  equilibrium_wall_cap=5.0, maxdt_wall_cap=5.0, error_ladder=(1, 2, 4, 8, 16, 32)),
    # every integrator, 16-128 on a 2-core CPU within about 40 minutes (docs/study.md, "Profiles"):
    # stability trials shortened with size (a 1 s trial of rk4 at 128x128 is ~9k steps of ~4.5 ms);
    # accuracy at 8 and 12 (implicit-type integrators search to k of hundreds there; at 16 the
    # last standard run spent 25 min on them), bisection to 15 %.
    "standard": dict(sizes=[16, 32, 64, 128], accuracy_sizes=[8, 12], maxdt_durations=((64, 0.5), (128, 0.25)),
                     maxdt_wall_cap=30.0, equilibrium_wall_cap=10.0, accurate_precision=0.15),
    "seed": dict(sizes=[32, 64, 128], accuracy_sizes=[8, 16], timing_scenarios=("sheet", "flag"),
                 extra_dt_fractions=(0.5, 0.25), maxdt_duration=2.0, maxdt_precision=0.02, equilibrium_wall_cap=60.0,
                 maxdt_wall_cap=60.0),
}


def make_plan(profile: str = "quick", integrators=None, sizes=None, devices=None, tolerance=DEFAULT_TOLERANCE,
              match_accuracy: bool = False, accuracy_sizes=None, scenarios=None) -> StudyPlan:
    """A :class:`StudyPlan` from a profile and explicit overrides (checked; one-line errors)."""
    from warpcloth.integrators import integrator_names

    if profile not in PROFILES:
        raise WarpclothError(f"unknown profile {profile!r}; choose one of {', '.join(PROFILES)}")
    names = integrator_names()
    if integrators is None:
        integrators = list(names)
    integrators = list(integrators)
    require(bool(integrators), "the integrator list is empty")
    for name in integrators:
        if name not in names:
            raise WarpclothError(f"unknown integrator {name!r}; choose from {', '.join(names)}")
    base = dict(PROFILES[profile])
    if sizes is not None:
        sizes = list(sizes)
        require(bool(sizes), "the size list is empty: give sizes like --sizes 8,16")
        for s in sizes:
            require(isinstance(s, int) and s >= 3, f"sizes must be integers >= 3 (n x n particles), got {s!r}")
        base["sizes"] = sizes
        if accuracy_sizes is None:
            base["accuracy_sizes"] = [s for s in sizes if s <= max(PROFILES[profile]["accuracy_sizes"])] or [min(sizes)]
    if accuracy_sizes is not None:
        base["accuracy_sizes"] = list(accuracy_sizes)
    if devices is None:
        devices = ["cpu", "cuda"] if profile == "seed" else ["cpu"]
    devices = list(devices)
    require(bool(devices), "the device list is empty")
    grid, files = check_scenarios(scenarios)
    if grid:
        check_memory(sorted(set(base["sizes"]) | set(base["accuracy_sizes"])), devices)
    return StudyPlan(profile=profile, integrators=integrators, devices=devices, tolerance=check_tolerance(tolerance),
                     match_accuracy=bool(match_accuracy), grid=grid, scenario_files=files, **base)


def check_memory(sizes, devices) -> None:
    """Refuse, before the first run, a size whose n x n cloth a device cannot hold (the grid's
    up-front estimate, :func:`~warpcloth.sim.grid.grid_memory_estimate`); a device that is not
    present is left to the study (it is reported and skipped there)."""
    from warpcloth.sim.device import require_memory, resolve_device
    from warpcloth.sim.grid import grid_memory_estimate

    for device in devices:
        try:
            resolve_device(device)
        except WarpclothError:
            continue
        for n in sorted(sizes, reverse=True):  # the largest first: the one that fails
            require_memory(f"the study's {n} x {n} cloth (--sizes)", grid_memory_estimate(n, n), device)


def check_scenarios(scenarios) -> tuple[bool, list]:
    """``--scenarios``: (whether the sheet/flag grid study runs, the other scenarios). None: the
    grid only. ``sheet`` and ``flag`` go together (the accuracy metric uses both); any other
    item is a scenario file (.toml) or a registered scenario, loaded here so that a bad one is
    refused before any work."""
    if scenarios is None:
        return True, []
    from warpcloth.scenarios import get_scenario

    items = list(dict.fromkeys(scenarios))
    require(bool(items), "the scenario list is empty: give e.g. --scenarios sheet,flag,examples/cape.toml")
    grid = [s for s in items if s in SCENARIOS]
    if len(grid) == 1:
        raise WarpclothError(f"--scenarios: {grid[0]} without {'flag' if grid[0] == 'sheet' else 'sheet'}: the study's sheet and "
                             "flag go together (the accuracy uses both); give both or neither")
    files = [s for s in items if s not in SCENARIOS]
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


__all__ = ["PROFILES", "SCENARIOS", "StudyPlan", "check_scenarios", "group_label", "make_plan", "plan_groups"]
