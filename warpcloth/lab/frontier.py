"""Work-precision answers from measured points (design.md, "Accuracy and the study"): the Pareto
front of (cost, error) points, the cheapest configuration reaching a tolerance, the largest
measured size that fits a budget, and power-law fits of cost against size.

Rules (nothing is ranked at an accuracy that was not measured, nothing extrapolated far):

* :func:`pareto_front`: the points no other point beats in both cost and error (ties: the
  cheaper, then the more accurate, kept);
* :func:`cheapest`: the least costly point whose error is at most the tolerance (None: none);
* :func:`budget_frontier`: the largest *measured* size whose cost fits the budget;
* :func:`fit_power_law`: cost = a N^p in log-log, only from >= :data:`MIN_FIT_SIZES` distinct
  sizes (else None: the report prints "n/a"); :meth:`PowerLaw.solve` never answers beyond
  :data:`MAX_EXTRAPOLATION` x the largest measured size (nor below the smallest / that factor).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: A power law is fitted only through this many distinct sizes or more.
MIN_FIT_SIZES = 3
#: A fitted size is never reported beyond this factor outside the measured range.
MAX_EXTRAPOLATION = 2.0


@dataclass(frozen=True)
class Point:
    """A measured configuration: cost (e.g. ms per 1/60 s frame), error (a fraction of the size),
    and what it is (``label``, any object the caller needs back)."""

    cost: float
    error: float
    label: object = None


def _finite(p: Point) -> bool:
    return (
        p.cost is not None and p.error is not None and math.isfinite(p.cost) and math.isfinite(p.error) and p.cost > 0
    )


def pareto_front(points) -> list[Point]:
    """The non-dominated points, by increasing cost (and decreasing error): a point is dropped when
    another is at most as costly and at most as inaccurate, and better in one of the two. Points
    with a non-finite cost or error (unstable runs) are never on it."""
    pts = sorted((p for p in points if _finite(p)), key=lambda p: (p.cost, p.error))
    front, best = [], math.inf
    for p in pts:
        if p.error < best:
            front.append(p)
            best = p.error
    return front


def cheapest(points, tolerance: float) -> Point | None:
    """The least costly measured point with error <= ``tolerance`` (the more accurate on a tie);
    None when none reaches it."""
    ok = [p for p in points if _finite(p) and p.error <= tolerance]
    return min(ok, key=lambda p: (p.cost, p.error)) if ok else None


@dataclass(frozen=True)
class PowerLaw:
    """cost = a N^p fitted through ``points`` distinct sizes in ``range`` (min, max);
    ``residual``: root mean square of log10(cost / fit) (decades)."""

    a: float
    p: float
    residual: float
    points: int
    range: tuple

    def __call__(self, n):
        return self.a * np.asarray(n, dtype=np.float64) ** self.p

    def solve(self, cost: float):
        """(N with a N^p = cost, where): where is "" inside the measured range, "above"/"below"
        within :data:`MAX_EXTRAPOLATION` of it; (None, "beyond") farther out, and (None, "") when
        the cost does not grow with N."""
        if not (self.p > 0 and self.a > 0 and cost > 0):
            return None, ""
        n = (cost / self.a) ** (1.0 / self.p)
        lo, hi = self.range
        if n > MAX_EXTRAPOLATION * hi or n < lo / MAX_EXTRAPOLATION:
            return None, "beyond"
        return n, "above" if n > hi else "below" if n < lo else ""


def fit_power_law(n, cost) -> PowerLaw | None:
    """Least-squares fit of log cost = log a + p log N over the finite, positive points; None
    with fewer than :data:`MIN_FIT_SIZES` distinct sizes."""
    n = np.asarray(n, dtype=np.float64)
    c = np.asarray(cost, dtype=np.float64)
    keep = np.isfinite(n) & np.isfinite(c) & (n > 0) & (c > 0)
    n, c = n[keep], c[keep]
    if np.unique(n).size < MIN_FIT_SIZES:
        return None
    x, y = np.log(n), np.log(c)
    p, log_a = np.polyfit(x, y, 1)
    resid = (y - (log_a + p * x)) / math.log(10.0)
    return PowerLaw(
        a=float(math.exp(log_a)),
        p=float(p),
        residual=float(np.sqrt(np.mean(resid**2))),
        points=int(n.size),
        range=(float(n.min()), float(n.max())),
    )


@dataclass(frozen=True)
class Frontier:
    """The budget frontier of one integrator at one tolerance.

    measured: the largest measured size (particles) whose cost fits the budget (None: none);
    sizes: the measured sizes with a point reaching the tolerance; missing: sizes measured where
    nothing reached it; fit: the :class:`PowerLaw` of those costs (None below 3 sizes);
    fitted, where: the fit's size at the budget and "" / "above" / "below" / "beyond"."""

    measured: int | None
    sizes: tuple
    missing: tuple
    fit: PowerLaw | None
    fitted: float | None
    where: str

    def describe(self, unit: str = "particles") -> str:
        head = "none fits" if self.measured is None else f"{self.measured} {unit}"
        if self.sizes and self.measured == max(self.sizes):
            head += " (the largest measured)"
        if self.fit is None:
            return head
        if self.fitted is None:
            return head + (
                "; fit beyond 2x the measured range: not extrapolated" if self.where == "beyond" else "; fit n/a"
            )
        where = {
            "": "within the measured range",
            "above": "extrapolated, < 2x above the measured range",
            "below": "below the measured range",
        }[self.where]
        return head + f"; fit {self.fitted:.3g} ({where})"


def budget_frontier(costs: dict, budget: float, all_sizes=()) -> Frontier:
    """``costs``: {size (particles): the cheapest cost reaching the tolerance there}; the largest
    measured size with cost <= ``budget`` and the power law through the costs. ``all_sizes``: every
    size measured (those without a cost are listed as missing: nothing reached the tolerance)."""
    pts = sorted((int(n), float(c)) for n, c in costs.items() if c is not None and math.isfinite(c) and c > 0)
    ok = [n for n, c in pts if c <= budget]
    fit = fit_power_law([n for n, _ in pts], [c for _, c in pts])
    fitted, where = fit.solve(budget) if fit is not None else (None, "")
    missing = tuple(sorted(int(n) for n in all_sizes if int(n) not in dict(pts)))
    return Frontier(
        measured=max(ok) if ok else None,
        sizes=tuple(n for n, _ in pts),
        missing=missing,
        fit=fit,
        fitted=fitted,
        where=where,
    )


__all__ = [
    "MAX_EXTRAPOLATION",
    "MIN_FIT_SIZES",
    "Frontier",
    "Point",
    "PowerLaw",
    "budget_frontier",
    "cheapest",
    "fit_power_law",
    "pareto_front",
]
