"""Helpers of the solver checks (bench/solver_checks/*.py): option parsing and the sheet's mesh twin."""

from __future__ import annotations

import numpy as np


def parse_value(text: str):
    """An option value from the command line: int, float or str."""
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


def parse_opts(items) -> dict:
    """``["key=value", ...]`` (or one ``"key=value,key=value"`` string) as integrator options."""
    if isinstance(items, str):
        items = items.split(",")
    opts = {}
    for kv in filter(None, items):
        key, value = kv.split("=")
        opts[key] = parse_value(value)
    return opts


def parse_case(case: str) -> tuple[str, dict]:
    """``"name:key=value,key=value"`` -> (integrator name, options)."""
    name, _, rest = case.partition(":")
    return name, parse_opts(rest)


def mesh_twin(model):
    """The same cloth as a build_mesh_cloth model: the grid's triangles with quads, so the same
    springs, masses and pins, but no grid structure (vbd's geometric multigrid does not apply)."""
    from warpcloth import build_mesh_cloth
    from warpcloth.sim.grid import grid_triangles

    h = model.host
    pins = list(np.flatnonzero(h.inv_mass == 0))
    return build_mesh_cloth(
        h.q,
        grid_triangles(model.rows, model.cols),
        total_mass=float(h.mass.sum()),
        mass_mode="uniform",
        quads=True,
        pins=pins,
        device=str(model.device),
        spring_params=model.spring_params,
    )
