"""The configurations the study evaluates (design.md: "an integrator is judged over its knobs"):
each integrator's options x its time step, a :class:`Config` each, from :func:`configurations`.

A step is dt = (1/60 s) / k, k a whole number of steps per 60 FPS frame or k = 1/2 (dt =
1/30 s). Per integrator (the grids of :data:`GRIDS`, per plan level ``full`` / ``quick``):

* explicit schemes (explicit_euler, midpoint, verlet, rk4): no knobs but dt, at fractions 1, 1/2,
  1/4, 1/8 of their max stable dt (rounded down to (1/60 s)/k);
* implicit_euler: preconditioner {jacobi, multigrid} x cg_tol x dt;
* pbd, xpbd: substeps 1 ... 256 x iterations 1 ... 20 at dt = 1/30 and 1/60 s, and at smaller dts;
* vbd: iterations x dt; projective: local/global iterations x CG iterations x dt.

:func:`work` is a configuration's relative cost per step (for pruning before running); the
study measures each configuration's cost (:mod:`warpcloth.lab.measure`) and error and keeps the
Pareto front (:mod:`warpcloth.lab.frontier`): no monotonicity in dt is assumed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from fractions import Fraction

from warpcloth.integrators import integrator_class
from warpcloth.integrators.multigrid import MIN_COARSE_SIDE
from warpcloth.lab.accuracy import FRAME_DT

EXPLICIT = ("explicit_euler", "midpoint", "verlet", "rk4")

#: Per integrator and level: (option grids {name: values}, steps per frame k or, for the explicit
#: schemes, fractions of the max stable dt). Every combination is one configuration.
GRIDS = {
    "full": {
        "explicit": ({}, (1, 2, 4, 8)),
        "implicit_euler": (
            {"preconditioner": ("jacobi", "multigrid"), "cg_tol": (1e-2, 1e-3, 1e-5)},
            (Fraction(1, 2), 1, 2, 4, 8, 16),
        ),
        "pbd": ({"substeps": (1, 4, 16, 64, 256), "iterations": (1, 5, 20)}, (Fraction(1, 2), 1, 4)),
        "xpbd": ({"substeps": (1, 4, 16, 64, 256), "iterations": (1, 5, 20)}, (Fraction(1, 2), 1, 4)),
        "vbd": ({"vbd_iterations": (1, 2, 4, 10, 20)}, (Fraction(1, 2), 1, 2, 4, 8)),
        "projective": ({"pd_iterations": (1, 5, 20), "pd_cg_iterations": (5, 20)}, (Fraction(1, 2), 1, 2, 4, 8)),
    },
    "quick": {
        "explicit": ({}, (1, 2, 4)),
        "implicit_euler": ({"preconditioner": ("jacobi", "multigrid"), "cg_tol": (1e-2, 1e-4)}, (Fraction(1, 2), 1, 4)),
        "pbd": ({"substeps": (1, 16), "iterations": (1, 10)}, (Fraction(1, 2), 1)),
        "xpbd": ({"substeps": (1, 16), "iterations": (1, 10)}, (Fraction(1, 2), 1)),
        "vbd": ({"vbd_iterations": (1, 4, 20)}, (Fraction(1, 2), 1, 4)),
        "projective": ({"pd_iterations": (1, 20), "pd_cg_iterations": (5, 20)}, (Fraction(1, 2), 1, 4)),
    },
}

#: Options the study holds fixed outside the grids (a configuration's key does not name them).
#: implicit_euler's strain cap (default 0.1, for scenes that land on colliders) is off: it would bind in
#: the swing and the flag (structural and shear strain up to 0.20 at dt 1/30 s and 0.40 at 1/60 s on the
#: 32 x 32 sheet without it), so a run with it is another configuration than the ones measured so far;
#: the study measures the bare scheme (a grid over the cap would be its own axis).
FIXED_OPTIONS = {"implicit_euler": {"strain_cap": 0.0}}


def study_options(integrator: str, options: dict | None = None) -> dict:
    """The options a study run of ``integrator`` gets: :data:`FIXED_OPTIONS`, then ``options``."""
    return {**FIXED_OPTIONS.get(integrator, {}), **(options or {})}


@dataclass(frozen=True)
class Config:
    """One configuration: an integrator, its options (sorted (name, value) pairs) and its step,
    k steps per 1/60 s frame (a Fraction: 1/2 is dt = 1/30 s)."""

    integrator: str
    options: tuple
    k: Fraction

    @property
    def dt(self) -> float:
        return FRAME_DT / float(self.k)

    @property
    def option_dict(self) -> dict:
        return dict(self.options)

    def options_text(self) -> str:
        """The options as results.csv writes them (k=v, space-separated, sorted)."""
        return " ".join(f"{k}={v}" for k, v in self.options)

    def label(self) -> str:
        """For people: ``dt 1/240 s, substeps=16 iterations=5``."""
        k = self.k
        step = f"dt 1/{60 * k} s" if (60 * k).denominator == 1 else f"dt {self.dt:.3g} s"
        return step + (f", {self.options_text()}" if self.options else "")

    def work(self) -> float:
        """Relative cost per 1/60 s frame (:func:`work`)."""
        return work(self.integrator, self.option_dict) * float(self.k)


def work(integrator: str, options: dict) -> float:
    """Relative cost of one step of ``integrator`` with ``options`` against its defaults (1): the
    iterations x substeps of the position-based schemes, vbd's and projective's iterations; for
    pruning configurations, not a measurement."""
    defaults = {o.name: o.default for o in integrator_class(integrator).options}
    o = {**defaults, **options}
    if integrator in ("pbd", "xpbd"):
        return o["substeps"] * o["iterations"] / (defaults["substeps"] * defaults["iterations"])
    if integrator == "vbd":
        return o["vbd_iterations"] / defaults["vbd_iterations"]
    if integrator == "projective":
        per = lambda it, cg: it * (2.0 + cg)  # noqa: E731 (local step + CG iterations)
        return per(o["pd_iterations"], o["pd_cg_iterations"]) / per(
            defaults["pd_iterations"], defaults["pd_cg_iterations"]
        )
    if integrator == "implicit_euler":
        return max(1.0, math.log10(1e-3 / o["cg_tol"]) / 3.0 + 1.0) if o["cg_tol"] < 1e-3 else 1.0
    return 1.0


def steps_for(dt: float) -> int:
    """The smallest k with (1/60 s)/k <= dt (1 for dt None or >= a frame)."""
    if dt is None or dt >= FRAME_DT:
        return 1
    return max(1, math.ceil(FRAME_DT / dt - 1e-9))


def configurations(integrator: str, stable_dt: float | None, level: str = "full", n: int | None = None) -> list[Config]:
    """Every configuration of ``integrator`` at ``level`` (:data:`GRIDS`), cheapest (by
    :meth:`Config.work`) first. ``stable_dt``: the max stable dt [s] (None: not stable at any
    dt searched), from which the explicit schemes' steps are fractions; the others take their
    steps as they are (a step above their max stable dt runs, and is recorded unstable). ``n``:
    the grid's side; below the multigrid's smallest grid, no multigrid preconditioner (it would
    fall back to block Jacobi)."""
    grids = GRIDS[level]
    explicit = integrator in EXPLICIT
    options, steps = grids["explicit" if explicit else integrator]
    if n is not None and n < 2 * MIN_COARSE_SIDE - 1 and "preconditioner" in options:
        options = {**options, "preconditioner": tuple(p for p in options["preconditioner"] if p != "multigrid")}
    if explicit:
        if stable_dt is None:
            return []
        ks = sorted({Fraction(steps_for(stable_dt / f)) for f in steps})
    else:
        ks = sorted(Fraction(k) for k in steps)
    names = sorted(options)
    combos = [()]
    for name in names:
        combos = [c + ((name, v),) for c in combos for v in options[name]]
    out = [Config(integrator, c, k) for c in combos for k in ks]
    return sorted(out, key=lambda c: (c.work(), c.k, c.options))


def static_configurations(integrator: str, stable_dt: float | None) -> list[Config]:
    """The configurations of ``integrator`` run to rest on the contact transient, at its default
    options: at 1/60 s and 1/240 s, or for an explicit scheme at its max stable dt alone (its
    steps are small already: a run to rest is thousands of them)."""
    if integrator in EXPLICIT:
        return [] if stable_dt is None else [Config(integrator, (), Fraction(steps_for(stable_dt)))]
    return [Config(integrator, (), Fraction(1)), Config(integrator, (), Fraction(4))]


__all__ = ["Config", "EXPLICIT", "GRIDS", "configurations", "static_configurations", "steps_for", "work"]
