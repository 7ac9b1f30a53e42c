"""The cantilever bending test's float64 reference: the heavy inextensible elastica (Peirce 1930;
ASTM D1388 option A). docs/materials.md.

A strip of length L [m] (overhang), bending rigidity B [N m] (per width) and weight w = rho g
[N/m^2] (per length and width), clamped horizontally at s = 0 and free at s = L; theta(s) is the
angle below the horizontal:

    B theta'' = -w (L - s) cos(theta),  theta(0) = 0,  theta'(L) = 0;  x' = cos(theta), y' = -sin(theta).

It depends on lambda = w L^3 / B only. Solved by shooting from the **free end** on the tip angle
theta_L in (0, pi/2): brentq has a guaranteed bracket there (theta_L = 0 gives theta(0) < 0,
theta_L = pi/2 gives theta = pi/2 everywhere). Shooting on theta'(0) fails for lambda >~ 10.

Peirce's bending length c = (B / w)^(1/3); ASTM reads c = L / 2 at the overhang L where the chord
from the clamp to the tip is 41.5 deg below the horizontal, then B = w c^3. The exact elastica
reaches 41.5 deg at lambda = 8.004 (L / c = 2.0004), so the ASTM rule is exact to 0.02 % in c.

The shooting is solved for lambda <= :data:`MAX_LAMBDA` (100, a chord of 80.36 deg): beyond about
150 the tip angle is so near pi/2 that the integration from the free end loses the root (brentq
finds a wrong one, or none). A heavier or limper strip, which hangs nearly straight down, is refused.
"""

from __future__ import annotations

import math

import numpy as np

from warpcloth.errors import require, require_int, require_positive

#: The ASTM D1388 / Peirce chord angle [rad] (41.5 degrees).
ASTM_ANGLE = math.radians(41.5)

#: The largest lambda = w L^3 / B the shooting solves (module docstring), and its chord angle [rad].
MAX_LAMBDA = 100.0
MAX_CHORD_ANGLE = math.radians(80.36)

_RTOL, _ATOL = 1e-12, 1e-14


def _rhs(lam: float):
    def rhs(sig, u):  # sigma = s / L
        th, dth, _x, _y = u
        return [dth, -lam * (1.0 - sig) * math.cos(th), math.cos(th), -math.sin(th)]

    return rhs


def _integrate(lam: float, tip_angle: float, t_eval=None):
    from scipy.integrate import solve_ivp  # noqa: PLC0415 (SciPy loads only where this solve runs: stepping loads none)

    return solve_ivp(
        _rhs(lam), (1.0, 0.0), [tip_angle, 0.0, 0.0, 0.0], method="DOP853", rtol=_RTOL, atol=_ATOL, t_eval=t_eval
    )


def tip_angle(lam: float) -> float:
    """The tip slope theta(L) [rad] of the elastica with lambda = w L^3 / B."""
    from scipy.optimize import brentq  # noqa: PLC0415 (SciPy loads only where this solve runs: stepping loads none)

    lam = require_positive("lambda = w L^3 / B", lam)
    require(
        lam <= MAX_LAMBDA,
        f"lambda = w L^3 / B must be <= {MAX_LAMBDA:g} (a chord up to {math.degrees(MAX_CHORD_ANGLE):.2f} deg below the "
        f"clamp), got {lam:.6g}: the strip hangs nearly straight down, where the elastica's shooting loses its root",
    )
    return brentq(lambda th: _integrate(lam, th).y[0, -1], 0.0, 0.5 * math.pi, xtol=1e-15, rtol=1e-15)


def cantilever_elastica(length: float, rigidity: float, weight: float, n: int = 201):
    """The deflected strip: (s, theta, x, y), each (n,) float64, from the clamp (s = 0, x = y = 0)
    to the tip; y <= 0 below the clamp.

    Args:
        length: overhang L [m].
        rigidity: bending rigidity B [N m] (per width).
        weight: weight per area w = rho g [N/m^2].
        n: points along the strip (>= 2).
    """
    length = require_positive("length", length, "m")
    rigidity = require_positive("rigidity", rigidity, "N m")
    weight = require_positive("weight", weight, "N/m^2")
    n = require_int("n", n, 2)
    lam = weight * length**3 / rigidity
    th_tip = tip_angle(lam)
    sig = np.linspace(1.0, 0.0, n)
    th, _, x, y = _integrate(lam, th_tip, t_eval=sig).y
    x, y = (x - x[-1]) * length, (y - y[-1]) * length
    return (sig * length)[::-1], th[::-1], x[::-1], y[::-1]


def tip_deflection(length: float, rigidity: float, weight: float) -> tuple[float, float]:
    """(drop [m], reach [m]) of the free end below and beyond the clamp."""
    _, _, x, y = cantilever_elastica(length, rigidity, weight, n=2)
    return float(-y[-1]), float(x[-1])


def tip_chord_angle(length: float, rigidity: float, weight: float) -> float:
    """Angle [rad] below the horizontal of the chord from the clamp to the tip."""
    drop, reach = tip_deflection(length, rigidity, weight)
    return math.atan2(drop, reach)


def chord_angle_of(lam: float) -> float:
    """Chord angle [rad] as a function of lambda = w L^3 / B alone."""
    return tip_chord_angle(1.0, 1.0, lam)


def lambda_for_chord_angle(angle: float = ASTM_ANGLE) -> float:
    """The lambda = w L^3 / B at which the chord is ``angle`` [rad] below the horizontal (8.004 at 41.5 deg)."""
    from scipy.optimize import brentq  # noqa: PLC0415 (SciPy loads only where this solve runs: stepping loads none)

    angle = require_positive("angle", angle, "rad")
    require(
        angle <= MAX_CHORD_ANGLE,
        f"angle must be in (0, {math.degrees(MAX_CHORD_ANGLE):.2f}] degrees (lambda <= {MAX_LAMBDA:g}), got "
        f"{math.degrees(angle):.6g}",
    )
    lo, hi = 1e-3, 10.0
    while chord_angle_of(hi) < angle:
        lo, hi = hi, min(hi * 10.0, MAX_LAMBDA)
    while chord_angle_of(lo) > angle:
        lo *= 0.1
    return brentq(lambda lam: chord_angle_of(lam) - angle, lo, hi, xtol=1e-12, rtol=1e-13)


def linear_tip_drop(length: float, rigidity: float, weight: float) -> float:
    """The small-load (Euler-Bernoulli) tip drop w L^4 / (8 B) [m]."""
    return weight * length**4 / (8.0 * rigidity)


def peirce_bending_length(overhang: float, angle: float = ASTM_ANGLE) -> float:
    """Peirce's approximate bending length c = L (cos(theta/2) / (8 tan theta))^(1/3) [m] of a strip
    whose overhang L [m] makes the chord angle ``angle`` [rad] (c / L = 0.5093 at 41.5 deg)."""
    overhang = require_positive("overhang", overhang, "m")
    angle = require_positive("angle", angle, "rad")
    require(angle < 0.5 * math.pi, f"angle must be below 90 degrees, got {math.degrees(angle):.6g}")
    return overhang * (math.cos(0.5 * angle) / (8.0 * math.tan(angle))) ** (1.0 / 3.0)


def bending_length(rigidity: float, weight: float) -> float:
    """Bending length c = (B / w)^(1/3) [m] for rigidity B [N m] and weight w = rho g [N/m^2]."""
    return (require_positive("rigidity", rigidity, "N m") / require_positive("weight", weight, "N/m^2")) ** (1.0 / 3.0)


def rigidity_from_bending_length(bending_length: float, weight: float) -> float:
    """B = w c^3 [N m] from a measured bending length c [m] (ASTM D1388: c = overhang / 2 at 41.5 deg)."""
    return require_positive("weight", weight, "N/m^2") * require_positive("bending length", bending_length, "m") ** 3


def rigidity_from_overhang(overhang: float, weight: float, angle: float = ASTM_ANGLE) -> float:
    """B [N m] such that the exact elastica of overhang L [m] has the chord angle ``angle``: w L^3 / lambda."""
    overhang = require_positive("overhang", overhang, "m")
    return require_positive("weight", weight, "N/m^2") * overhang**3 / lambda_for_chord_angle(angle)


__all__ = [
    "ASTM_ANGLE",
    "MAX_CHORD_ANGLE",
    "MAX_LAMBDA",
    "bending_length",
    "cantilever_elastica",
    "chord_angle_of",
    "lambda_for_chord_angle",
    "linear_tip_drop",
    "peirce_bending_length",
    "rigidity_from_bending_length",
    "rigidity_from_overhang",
    "tip_angle",
    "tip_chord_angle",
    "tip_deflection",
]
