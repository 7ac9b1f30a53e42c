"""The force evaluation shared by the integrators: f = gravity + drag + springs + hinges + wind
(seed eq. 2.5-2.8; the dihedral hinges of ``bend="dihedral"``, :mod:`warpcloth.kernels.bending`), and
the external part alone for the position-based schemes."""

from __future__ import annotations

import warp as wp

from warpcloth.kernels import bending as bk
from warpcloth.kernels import forces as fk
from warpcloth.sim.control import Control


def eval_forces(model, x: wp.array, v: wp.array, control: Control, f: wp.array) -> None:
    """f = gravity + drag + springs + hinges + wind at positions ``x`` and velocities ``v`` (overwrites f)."""
    device = model.device
    wp.launch(
        fk.eval_particle_forces,
        dim=model.particle_count,
        inputs=[v, model.particle_mass, wp.vec3(*control.gravity), float(control.drag_rate)],
        outputs=[f],
        device=device,
    )
    if model.spring_count:
        wp.launch(
            fk.eval_springs,
            dim=model.spring_count,
            inputs=[
                x,
                v,
                model.spring_indices,
                model.spring_rest_length,
                model.spring_stiffness,
                model.spring_damping,
                model.spring_compression,
            ],
            outputs=[f],
            device=device,
        )
    if model.hinge_count:
        eval_hinge_forces(model, x, v, f)
    if control.has_wind:
        wp.launch(
            fk.eval_wind,
            dim=model.tri_count,
            inputs=[x, v, model.tri_indices, control.wind, float(control.wind_coefficient)],
            outputs=[f],
            device=device,
        )


def eval_hinge_forces(model, x: wp.array, v: wp.array, f: wp.array) -> None:
    """f += the dihedral hinges' -(k_e C + kd_e sum_b g_b . v_b) g_a at ``x``, ``v`` (none without hinges)."""
    if model.hinge_count:
        wp.launch(
            bk.eval_hinge_forces,
            dim=model.hinge_count,
            inputs=[x, v, *model.hinge_arrays()],
            outputs=[f],
            device=model.device,
        )


def eval_external_forces(model, x: wp.array, v: wp.array, control: Control, f: wp.array) -> None:
    """f = gravity + drag + wind at ``x``, ``v``, without springs (overwrites f): the external
    forces f_ext of the position-based integrators, whose springs are constraints."""
    device = model.device
    wp.launch(
        fk.eval_particle_forces,
        dim=model.particle_count,
        inputs=[v, model.particle_mass, wp.vec3(*control.gravity), float(control.drag_rate)],
        outputs=[f],
        device=device,
    )
    if control.has_wind:
        wp.launch(
            fk.eval_wind,
            dim=model.tri_count,
            inputs=[x, v, model.tri_indices, control.wind, float(control.wind_coefficient)],
            outputs=[f],
            device=device,
        )
