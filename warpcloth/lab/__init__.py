"""The accuracy laboratory: float64 references that warpcloth's float32 runs are measured against.

:mod:`warpcloth.lab.reference` integrates the same model (springs, masses, pins, gravity, wind
schedule, drag) in float64 with NumPy forces and SciPy's ``solve_ivp``, and solves the static
equilibrium under gravity by Newton's method. See ``docs/reference.md``.
"""

from .reference import (
    Convergence,
    Equilibrium,
    Float64Model,
    cloth_size,
    convergence_check,
    reference_forces,
    reference_trajectory,
    simulate_frames,
    static_equilibrium,
    swing_from_horizontal,
    trajectory_error,
    wind_switch_times,
)

__all__ = [
    "Convergence", "Equilibrium", "Float64Model", "cloth_size", "convergence_check", "reference_forces",
    "reference_trajectory", "simulate_frames", "static_equilibrium", "swing_from_horizontal", "trajectory_error",
    "wind_switch_times",
]
