"""The force evaluation shared by the integrators: f = gravity + drag + springs + wind (seed
eq. 2.5-2.8), and the external part alone for the position-based schemes."""

from __future__ import annotations

import warp as wp

from warpcloth.sim.control import Control
from warpcloth.kernels import forces as fk


def eval_forces(model, x: wp.array, v: wp.array, control: Control, f: wp.array) -> None:
    """f = gravity + drag + springs + wind at positions ``x`` and velocities ``v`` (overwrites f)."""
    device = model.device
    wp.launch(fk.eval_particle_forces, dim=model.particle_count, inputs=[v, model.particle_mass, wp.vec3(*control.gravity), float(control.drag_rate)], outputs=[f], device=device)
    if model.spring_count:
        wp.launch(
            fk.eval_springs,
            dim=model.spring_count,
            inputs=[x, v, model.spring_indices, model.spring_rest_length, model.spring_stiffness, model.spring_damping],
            outputs=[f],
            device=device,
        )
    if control.has_wind:
        wp.launch(fk.eval_wind, dim=model.tri_count, inputs=[x, v, model.tri_indices, control.wind, float(control.wind_coefficient)], outputs=[f], device=device)


def eval_external_forces(model, x: wp.array, v: wp.array, control: Control, f: wp.array) -> None:
    """f = gravity + drag + wind at ``x``, ``v``, without springs (overwrites f): the external
    forces f_ext of the position-based integrators, whose springs are constraints."""
    device = model.device
    wp.launch(fk.eval_particle_forces, dim=model.particle_count, inputs=[v, model.particle_mass, wp.vec3(*control.gravity), float(control.drag_rate)], outputs=[f], device=device)
    if control.has_wind:
        wp.launch(fk.eval_wind, dim=model.tri_count, inputs=[x, v, model.tri_indices, control.wind, float(control.wind_coefficient)], outputs=[f], device=device)
