"""The real-time frontier: from a ladder of measured sizes N_i and costs c_i (wall seconds per
simulated second), a power law c = a N^p fitted by least squares in log-log, and the largest
particle count at which the cost is at most 1 (real time).

The frontier is reported two ways, never mixed up:

* ``measured``: the largest measured N with c <= 1 (None if none was);
* ``fitted``: N* = (1 / a)^(1/p) from the fit, with ``extrapolated`` set when N* lies outside the
  measured range (above its largest or below its smallest size): a table must say so.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class PowerLaw:
    """c = a N^p; ``residual``: root mean square of log10(c / fit) over the points (decades);
    ``points``: how many points it was fitted to."""

    a: float
    p: float
    residual: float
    points: int

    def __call__(self, n):
        return self.a * np.asarray(n, dtype=np.float64) ** self.p

    def solve(self, cost: float) -> float | None:
        """N with a N^p = cost (None when p is not positive: the cost does not grow with N)."""
        if not (self.p > 0 and self.a > 0):
            return None
        return (cost / self.a) ** (1.0 / self.p)


def fit_power_law(n, cost) -> PowerLaw | None:
    """Least-squares fit of log c = log a + p log N over the finite, positive points; None with
    fewer than two distinct sizes."""
    n = np.asarray(n, dtype=np.float64)
    c = np.asarray(cost, dtype=np.float64)
    keep = np.isfinite(n) & np.isfinite(c) & (n > 0) & (c > 0)
    n, c = n[keep], c[keep]
    if np.unique(n).size < 2:
        return None
    x, y = np.log(n), np.log(c)
    p, log_a = np.polyfit(x, y, 1)
    resid = (y - (log_a + p * x)) / math.log(10.0)
    return PowerLaw(a=float(math.exp(log_a)), p=float(p), residual=float(np.sqrt(np.mean(resid ** 2))), points=int(n.size))


@dataclass(frozen=True)
class Frontier:
    """The real-time frontier of one integrator on one device (see the module docstring).

    measured: largest measured N with cost <= threshold (None: none); measured_range: (min, max)
    of the measured N; fitted: N* of the fit (None without a fit or without growth);
    extrapolated: "" inside the measured range, "above" or "below" it; fit: the PowerLaw."""

    measured: int | None
    measured_range: tuple
    fitted: float | None
    extrapolated: str
    fit: PowerLaw | None
    all_realtime: bool
    none_realtime: bool

    def describe(self) -> str:
        lo, hi = self.measured_range
        if self.measured is None:
            head = f"none real-time in {lo}-{hi}"
        elif self.all_realtime:
            head = f">= {self.measured} (every measured size real-time)"
        else:
            head = f"{self.measured}"
        if self.fitted is not None:
            where = {"": "within the measured range", "above": "extrapolated above the measured range",
                     "below": "extrapolated below the measured range"}[self.extrapolated]
            head += f"; fit N* = {self.fitted:.3g} ({where})"
        return head


def frontier(n, cost, threshold: float = 1.0) -> Frontier:
    """The frontier of measured sizes ``n`` (particles) and costs (wall s per simulated s)."""
    n = [int(v) for v in n]
    cost = [float(v) for v in cost]
    pairs = sorted((a, b) for a, b in zip(n, cost) if math.isfinite(b) and b > 0)
    ns = [a for a, _ in pairs]
    rng = (min(ns), max(ns)) if ns else (None, None)
    ok = [a for a, b in pairs if b <= threshold]
    fit = fit_power_law(ns, [b for _, b in pairs]) if pairs else None
    fitted = fit.solve(threshold) if fit is not None else None
    extrapolated = ""
    if fitted is not None and ns:
        extrapolated = "above" if fitted > rng[1] else "below" if fitted < rng[0] else ""
    return Frontier(measured=max(ok) if ok else None, measured_range=rng, fitted=fitted, extrapolated=extrapolated,
                    fit=fit, all_realtime=bool(pairs) and len(ok) == len(pairs), none_realtime=not ok)


__all__ = ["Frontier", "PowerLaw", "fit_power_law", "frontier"]
