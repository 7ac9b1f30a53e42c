"""Vertex colouring of meshes through Warp's graph_coloring_assign (MCS): valid, no more colours
than the greedy colouring it replaces, greedy kept as the fallback; grids keep their pattern."""

import numpy as np
import pytest

from warpcloth.scenarios.mesh import make_cape
from warpcloth.sim import coloring
from warpcloth.sim.coloring import color_vertices, greedy_vertex_colors, is_valid_vertex_coloring, warp_vertex_colors
from warpcloth.sim.grid import build_grid_cloth
from warpcloth.sim.mesh import build_mesh_cloth


def _pairs(model):
    return model.spring_indices.numpy().reshape(-1, 2).astype(np.int64)


@pytest.mark.parametrize("mesh", ["cape", "grid"])
def test_meshes_are_coloured_by_warp_with_no_more_colours_than_greedy(mesh):
    if mesh == "cape":
        cape = make_cape()
        model = build_mesh_cloth(cape.vertices, cape.triangles, device="cpu")
    else:  # a grid read as a mesh: no grid pattern (cols unknown)
        grid = build_grid_cloth(20, 20, device="cpu")
        model = build_mesh_cloth(grid.host.q, grid.host.tris, device="cpu")
    pairs, n = _pairs(model), model.particle_count
    got = color_vertices(pairs, n)
    assert is_valid_vertex_coloring(pairs, got.colors)
    assert np.array_equal(got.colors, warp_vertex_colors(pairs, n))  # Warp's, not greedy's
    assert got.color_count <= greedy_vertex_colors(pairs, n).max() + 1


def test_greedy_is_the_fallback(monkeypatch):
    cape = make_cape()
    model = build_mesh_cloth(cape.vertices, cape.triangles, device="cpu")
    pairs, n = _pairs(model), model.particle_count
    monkeypatch.setattr(coloring, "warp_vertex_colors", lambda pairs, n: None)  # a Warp without it
    assert np.array_equal(color_vertices(pairs, n).colors, greedy_vertex_colors(pairs, n))
    monkeypatch.setattr(coloring, "warp_vertex_colors", lambda pairs, n: np.zeros(n, dtype=np.int32))  # invalid
    assert np.array_equal(color_vertices(pairs, n).colors, greedy_vertex_colors(pairs, n))


def test_grids_keep_their_nine_colour_pattern():
    model = build_grid_cloth(10, 12, device="cpu")
    got = color_vertices(_pairs(model), model.particle_count, cols=12)
    assert got.color_count == 9 and np.array_equal(got.colors, coloring.grid_vertex_colors(120, 12))
