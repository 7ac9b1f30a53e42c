"""Calibration: fit a material's values so that a chosen resolution and integrator reproduce measured
textile-test values (docs/materials.md, "Calibration").

Targets (what a laboratory measured):

* ``bending_length`` [m]: the cantilever test (ASTM D1388), simulated by the ``cantilever``
  scenario at the overhang 2.0004 c_target, where the exact elastica's chord is 41.5 deg at the
  target; the simulated bending length inverts the exact elastica from the simulated chord angle.
* ``drape_coefficient``: the Cusick test (``cusick`` scenario), DC in [0, 1].

Unknowns: ``bend`` (a factor on B_warp and B_weft, the anisotropy kept), ``stretch`` (a factor on
C11 and C22, the shear kept), ``compression`` (phi itself, in [0.01, 1]). The fit is a robust
least squares in the unknowns' logarithms (SciPy ``least_squares``, soft-L1 loss, bounds, forward
differences of 5 %), each residual relative to its target; one unknown and one target is a root
found by Brent's method on a bracket grown from the closed-form start (B = w c^3 for a bending
length). Every simulation is a full scenario run to rest: the cost is reported (runs, wall time).
"""

from __future__ import annotations

import contextlib
import io
import math
import re
import sys
import time
from dataclasses import dataclass, field

import numpy as np

from warpcloth.errors import WarpclothError, require, require_int, require_positive
from warpcloth.scenarios import get_scenario
from warpcloth.scenarios.cantilever import ASTM_OVERHANG_RATIO
from warpcloth.sim.material import PRESETS, Material, material

#: What each target means and its scenario.
TARGETS = {
    "bending_length": ("bending length [m] of the cantilever test (ASTM D1388)", "cantilever"),
    "drape_coefficient": ("drape coefficient of the Cusick test (BS 5058), 0..1", "cusick"),
}
#: The unknowns a fit may take, and their bounds (factors on the material's value; phi itself).
UNKNOWNS = {"bend": (1e-3, 1e3), "stretch": (1e-2, 1e2), "compression": (0.01, 1.0)}


@dataclass
class Evaluation:
    """One simulation of a fit: the unknowns tried and what each target's scenario measured."""

    values: dict
    measured: dict
    wall_s: float


@dataclass
class Calibration:
    """The outcome of :func:`calibrate`.

    Attributes:
        material: the fitted :class:`~warpcloth.sim.material.Material` (named ``<base>-fit``).
        start: the material the fit started from.
        unknowns: the fitted values (``bend`` / ``stretch``: factors on the start's values;
            ``compression``: phi).
        targets: the target values.
        measured: what the fitted material gives, per target.
        residual: (measured - target) / target per target.
        evaluations: every simulation run, in order.
        wall_s: the fit's wall time [s].
        converged: whether the solver met its tolerance.
        message: the solver's own words.
    """

    material: Material
    start: Material
    unknowns: dict
    targets: dict
    measured: dict
    residual: dict
    evaluations: list = field(default_factory=list)
    wall_s: float = 0.0
    converged: bool = False
    message: str = ""

    @property
    def runs(self) -> int:
        return len(self.evaluations)

    def flags(self) -> str:
        """The ``warpcloth run`` flags of the fitted material (a preset and its changed values)."""
        m, s = self.material, self.start
        parts = [f"--material {s.name if s.name in _presets() else 'custom'}"]
        if s.name not in _presets():
            parts += [f"--density {m.density:.6g}", f"--shear {m.shear:.6g}"]
        if "stretch" in self.unknowns or s.name not in _presets():
            parts.append(f"--stretch {_pair(m.stretch_warp, m.stretch_weft)}")
        if "bend" in self.unknowns or s.name not in _presets():
            parts.append(f"--bend-rigidity {_pair(m.bend_warp, m.bend_weft)}")
        if "compression" in self.unknowns:
            parts.append(f"--compression {m.compression:.4g}")
        return " ".join(parts)

    def to_dict(self) -> dict:
        return {
            "material": self.material.to_dict(),
            "start": self.start.name,
            "unknowns": self.unknowns,
            "targets": self.targets,
            "measured": self.measured,
            "residual": self.residual,
            "runs": self.runs,
            "wall_s": self.wall_s,
            "converged": self.converged,
            "message": self.message,
            "flags": self.flags(),
        }


def _presets():
    return PRESETS


def _pair(a: float, b: float) -> str:
    return f"{a:.6g}" if a == b else f"{a:.6g},{b:.6g}"


def apply(start: Material, values: dict) -> Material:
    """``start`` with the unknowns' values applied (module docstring)."""
    changes = {}
    if "bend" in values:
        changes.update(bend_warp=start.bend_warp * values["bend"], bend_weft=start.bend_weft * values["bend"])
    if "stretch" in values:
        changes.update(
            stretch_warp=start.stretch_warp * values["stretch"], stretch_weft=start.stretch_weft * values["stretch"]
        )
    if "compression" in values:
        changes["compression"] = values["compression"]
    return start.replace(name=f"{start.name}-fit", source="", estimated=(), note="", **changes)


def measure(
    mat: Material,
    targets: dict,
    size: int | None = None,
    integrator: str | None = None,
    device: str | None = None,
    options: dict | None = None,
    bend: str | None = None,
) -> dict:
    """What ``mat`` gives for each target, each by a scenario run to rest at ``size`` (particles along
    the cantilever strip; points across the Cusick disc; None: the scenario's) with ``integrator``."""
    out = {}
    for name, target in targets.items():
        scenario = get_scenario(TARGETS[name][1])
        overrides = {"material": mat, "device": device}
        if integrator is not None:
            overrides["integrator"] = integrator
        if options:
            overrides["integrator_options"] = dict(options)
        if bend is not None:
            overrides["bend"] = bend
        if name == "bending_length":
            cols = size or scenario.defaults.cols
            overrides.update(cols=cols, width=ASTM_OVERHANG_RATIO * target * (cols - 1) / (cols - 1.5))
            if bend in ("provot", "choi_ko"):  # bend springs span two rows
                overrides["rows"] = 3
        elif size is not None:
            overrides.update(rows=size, cols=size)
        result = scenario.run(scenario.config(**overrides))
        if not result.stable:
            raise WarpclothError(
                f"calibrate: the {scenario.name} run went unstable ({result.unstable_reason}); try another integrator "
                "or size"
            )
        key = "bending_length_m" if name == "bending_length" else "drape_coefficient"
        if "refused" in result.measurements:
            raise WarpclothError(
                f"calibrate: the {scenario.name} run measured nothing: {result.measurements['refused']}"
            )
        if key not in result.measurements:
            raise WarpclothError(f"calibrate: the {scenario.name} run measured no {name} (the strip did not bend)")
        out[name] = float(result.measurements[key])
    return out


def calibrate(
    start,
    targets: dict,
    fit=("bend",),
    size: int | None = None,
    integrator: str | None = None,
    device: str | None = None,
    tolerance: float = 1e-3,
    max_runs: int = 40,
    progress=None,
    options: dict | None = None,
    bend: str | None = None,
) -> Calibration:
    """Fit ``fit`` (unknowns, module docstring) of the material ``start`` (a preset's name or a
    :class:`~warpcloth.sim.material.Material`) so that the scenarios reproduce ``targets``
    ({name: value}, :data:`TARGETS`) at ``size`` with ``integrator``.

    Args:
        tolerance: relative residual a fit stops at (Brent: on the unknown's logarithm too).
        max_runs: the most simulation runs (each target is one run per evaluation).
        progress: called with each :class:`Evaluation` as it finishes (None: quiet).
        options: the integrator's options (e.g. ``{"preconditioner": "block_jacobi"}``).
        bend: the scenarios' bending model (``dihedral``, their default, or ``provot``, ``choi_ko``:
            bend springs by the approximate rule, which a fit corrects at this resolution).

    Raises:
        WarpclothError: bad targets or unknowns (one line), or fewer targets than unknowns.
    """
    start = material(start)
    require(isinstance(targets, dict) and targets, "calibrate needs at least one target (name=value)")
    for name, value in targets.items():
        if name not in TARGETS:
            raise WarpclothError(f"unknown calibration target {name!r}; the targets are {', '.join(TARGETS)}")
        require_positive(name, value)
    if "bending_length" in targets:
        _check_reach(start, targets["bending_length"])
    if "drape_coefficient" in targets:
        require(
            targets["drape_coefficient"] < 1.0,
            f"drape_coefficient must be between 0 and 1, got {targets['drape_coefficient']!r}",
        )
    fit = tuple(dict.fromkeys(fit))
    require(fit, "calibrate needs at least one unknown to fit (bend, stretch, compression)")
    for name in fit:
        if name not in UNKNOWNS:
            raise WarpclothError(f"unknown calibration unknown {name!r}; the unknowns are {', '.join(UNKNOWNS)}")
    require(
        len(targets) >= len(fit),
        f"{len(fit)} unknowns ({', '.join(fit)}) need at least as many targets, got {len(targets)}",
    )
    if size is not None:
        size = require_int("size", size, 4)
    tolerance = require_positive("tolerance", tolerance)
    max_runs = require_int("max_runs", max_runs, 1)
    evaluations: list[Evaluation] = []
    cache: dict = {}
    said: set = set()
    t0 = time.perf_counter()

    def key(values: dict) -> tuple:
        return tuple(sorted((k, round(v, 12)) for k, v in values.items()))

    def evaluate(values: dict) -> dict:
        if key(values) in cache:
            return cache[key(values)]
        if len(evaluations) * len(targets) >= max_runs:
            raise _OutOfRuns()
        t = time.perf_counter()
        with _warnings_once(said):
            got = measure(apply(start, values), targets, size, integrator, device, options, bend)
        evaluations.append(Evaluation(dict(values), got, time.perf_counter() - t))
        if progress is not None:
            progress(evaluations[-1])
        cache[key(values)] = got
        return got

    def residuals(values: dict) -> list:
        got = evaluate(values)
        return [(got[k] - v) / v for k, v in targets.items()]

    initial = {name: _initial(name, start, targets) for name in fit}
    converged, message = False, ""
    try:
        if len(fit) == 1 and len(targets) == 1:
            best, converged, message = _brent(fit[0], initial[fit[0]], residuals, tolerance)
        else:
            best, converged, message = _least_squares(fit, initial, residuals, tolerance)
    except _OutOfRuns:
        best = min(evaluations, key=lambda e: _cost(e.measured, targets)).values
        message = f"stopped after {len(evaluations) * len(targets)} runs (max_runs); the best run so far"
    try:
        got = evaluate(best)
    except _OutOfRuns:  # the solver's last point was never run: the best run instead
        best = min(evaluations, key=lambda e: _cost(e.measured, targets)).values
        got = cache[key(best)]
    return Calibration(
        material=apply(start, best),
        start=start,
        unknowns=dict(best),
        targets=dict(targets),
        measured=got,
        residual={k: (got[k] - v) / v for k, v in targets.items()},
        evaluations=evaluations,
        wall_s=time.perf_counter() - t0,
        converged=converged,
        message=message,
    )


class _OutOfRuns(Exception):
    pass


@contextlib.contextmanager
def _warnings_once(said: set):
    """The runs' warning lines (stderr) each said once per fit: a fit repeats one configuration many
    times, and a warning such as a solver's missed tolerance would otherwise come at every run. Two
    lines are the same warning when they differ only in their numbers."""
    buffer = io.StringIO()
    try:
        with contextlib.redirect_stderr(buffer):
            yield
    finally:
        for line in buffer.getvalue().splitlines(keepends=True):
            kind = re.sub(r"[-+]?\d[\d.]*(e[-+]?\d+)?", "#", line)
            if kind not in said:
                said.add(kind)
                sys.stderr.write(line if line.endswith("\n") else line + "\n")
        sys.stderr.flush()


def _check_reach(start: Material, target: float) -> None:
    """Refuse a bending length that no fit can reach: c = (B / w)^(1/3) and ``bend`` is a factor on
    B within :data:`UNKNOWNS`, so c moves by at most that factor's cube root from the start's."""
    c0 = (start.bending_rigidity(start.warp_angle) / start.weight()) ** (1.0 / 3.0)  # the strip's, as _initial
    lo, hi = (c0 * b ** (1.0 / 3.0) for b in UNKNOWNS["bend"])
    if not lo <= target <= hi:
        raise WarpclothError(
            f"bending_length {target!r} m is out of reach from {start.name}: its bending length is {c0:.4g} m and "
            f"bend (a factor {UNKNOWNS['bend'][0]:g}..{UNKNOWNS['bend'][1]:g} on B = w c^3) reaches {lo:.4g}..{hi:.4g} m"
        )


def _cost(measured: dict, targets: dict) -> float:
    return sum(((measured[k] - v) / v) ** 2 for k, v in targets.items())


def _initial(name: str, start: Material, targets: dict) -> float:
    """A starting value: the closed form where there is one (B = w c^3 for a bending length)."""
    if name == "bend" and "bending_length" in targets:
        b = start.weight() * targets["bending_length"] ** 3
        return b / max(start.bending_rigidity(start.warp_angle), 1e-30)
    return start.compression if name == "compression" else 1.0


def _from_log(name: str, value: float) -> float:
    lo, hi = UNKNOWNS[name]
    return min(max(math.exp(value), lo), hi)


def _brent(name: str, x0: float, residuals, tolerance: float):
    """One unknown, one target: Brent's root of the residual in log(unknown), on a bracket grown
    by factors of 2 from the start (each side at most 10 times, within the bounds)."""
    from scipy.optimize import brentq  # noqa: PLC0415 (SciPy loads only where this solve runs: stepping loads none)

    lo_bound, hi_bound = (math.log(b) for b in UNKNOWNS[name])

    def f(u: float) -> float:
        return residuals({name: _from_log(name, u)})[0]

    u0 = min(max(math.log(x0), lo_bound), hi_bound)
    r0 = f(u0)
    if abs(r0) <= tolerance:
        return {name: _from_log(name, u0)}, True, "the start meets the tolerance"
    step = math.log(2.0) * (-1.0 if r0 > 0 else 1.0)  # the measured values grow with each unknown
    a, fa = u0, r0
    for _ in range(10):
        b = min(max(a + step, lo_bound), hi_bound)
        fb = f(b)
        if fa * fb <= 0.0:
            break
        if b in (lo_bound, hi_bound):
            return {name: _from_log(name, b)}, False, f"no sign change up to the bound of {name}"
        a, fa = b, fb
    else:
        return {name: _from_log(name, a)}, False, f"no sign change within 2^10 of the start of {name}"
    lo, hi = sorted((a, b))
    root = brentq(f, lo, hi, xtol=max(tolerance * 0.1, 1e-12), rtol=1e-10, maxiter=50)
    return {name: _from_log(name, root)}, abs(f(root)) <= tolerance, "Brent's method on a bracket"


def _least_squares(fit: tuple, initial: dict, residuals, tolerance: float):
    """Several unknowns or targets: SciPy's trust-region least squares in log(unknowns), soft-L1 loss."""
    from scipy.optimize import least_squares  # noqa: PLC0415 (SciPy loads only where this solve runs: stepping loads none)

    lo = np.array([math.log(UNKNOWNS[n][0]) for n in fit])
    hi = np.array([math.log(UNKNOWNS[n][1]) for n in fit])
    x0 = np.clip([math.log(initial[n]) for n in fit], lo + 1e-9, hi - 1e-9)

    def fun(u):
        return np.asarray(residuals({n: _from_log(n, float(v)) for n, v in zip(fit, u)}))

    sol = least_squares(
        fun, x0, bounds=(lo, hi), loss="soft_l1", f_scale=0.05, diff_step=0.05, xtol=tolerance, ftol=tolerance**2
    )
    best = {n: _from_log(n, float(v)) for n, v in zip(fit, sol.x)}
    return best, bool(sol.success) and float(np.max(np.abs(sol.fun))) <= max(tolerance, 1e-2), sol.message


__all__ = ["TARGETS", "UNKNOWNS", "Calibration", "Evaluation", "apply", "calibrate", "measure"]
