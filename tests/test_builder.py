"""Several cloths in one model (warpcloth.sim.builder.ClothBuilder): two cloths placed apart step as
the two run apart for every integrator, a one-piece builder gives its builder's model, the pieces'
records, USD (one mesh prim per piece) and player outputs, collision groups, and bad pieces refused."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
import warp as wp

from warpcloth.errors import WarpclothError
from warpcloth.integrators import integrator_names, make_integrator
from warpcloth.integrators.multigrid import grid_structure_reason
from warpcloth.io.player import HtmlWriter, read_player_data
from warpcloth.io.usd import UsdWriter
from warpcloth.lab.bench import bench_one
from warpcloth.sim.builder import ClothBuilder
from warpcloth.sim.control import Control
from warpcloth.sim.grid import build_grid_cloth
from warpcloth.sim.material import material_grid_cloth
from warpcloth.sim.mesh import build_mesh_cloth
from warpcloth.sim.self_collision import SelfCollision
from warpcloth.simulator import Simulator

#: Two small grids 1.5 m apart (they never touch): a per-spring one and a silk one.
GRID_A = {"rows": 6, "cols": 6, "width": 0.5, "height": 0.5, "pins": [0, 5], "origin": (0.0, 1.0, 0.0)}
GRID_B = {"rows": 5, "cols": 7, "width": 0.6, "height": 0.4, "pins": [0, 6], "origin": (2.0, 1.0, 0.0)}
MATERIAL_B = "silk"
DT, STEPS = 1.0 / 1000.0, 5

#: How each integrator's two-cloth run compares with the two run apart, and why:
#: ``exact`` (bit-identical): every kernel acts per particle, per spring or per colour of one piece's
#: own colouring (pbd, xpbd, vbd colour each piece alone, warpcloth.sim.coloring.color_model), and on
#: the CPU a particle's sums run in the same order; vbd only without its two whole-model corrections
#: (the rigid translation of all pieces at once and the aggregation multigrid of their union).
#: ``solve``: a global reduction couples the pieces (CG's dot products in implicit Euler and projective
#: dynamics), so the two agree to the solve's accuracy: within SOLVE_TOLERANCE of the steps'
#: displacement, plus float32 rounding of the positions. (vbd at its defaults agrees to its iteration
#: error only: its multigrid of the union is not the pieces' own; measured in docs/garments.md.)
EXPECT = {
    "explicit_euler": ({}, "exact"),
    "midpoint": ({}, "exact"),
    "rk4": ({}, "exact"),
    "verlet": ({}, "exact"),
    "pbd": ({}, "exact"),
    "xpbd": ({}, "exact"),
    "vbd": ({"vbd_rigid_mode": 0, "vbd_multigrid_every": 0}, "exact"),
    "implicit_euler": ({}, "solve"),
    "projective": ({}, "solve"),
}
#: implicit Euler's default cg_tol (relative residual), the loosest of the coupled solves here.
SOLVE_TOLERANCE = 1e-3


def _two(device="cpu"):
    b = ClothBuilder()
    b.add_grid(**GRID_A, name="a")
    b.add_grid(**GRID_B, material=MATERIAL_B, name="b")
    return b.finalize(device)


def _run(model, name, options):
    sim = Simulator(model, make_integrator(name, **options), Control(device="cpu"), dt=DT)
    sim.use_graph = False
    for _ in range(STEPS):
        sim.step()
    return sim.state.particle_q.numpy(), sim.state.particle_qd.numpy()


def _apart(name, options):
    a = _run(build_grid_cloth(**GRID_A, device="cpu"), name, options)
    b = _run(material_grid_cloth(MATERIAL_B, **GRID_B, device="cpu"), name, options)
    return np.concatenate([a[0], b[0]]), np.concatenate([a[1], b[1]])


@pytest.mark.parametrize("name", integrator_names())
def test_two_cloths_step_as_the_two_apart(name):
    assert name in EXPECT, f"say how {name} compares when two cloths share a model (EXPECT)"
    options, kind = EXPECT[name]
    x, v = _run(_two(), name, options)
    xs, vs = _apart(name, options)
    assert np.all(np.isfinite(xs))
    if kind == "exact":
        assert np.array_equal(x, xs) and np.array_equal(v, vs)
        return
    x0 = _two().host.q
    moved = float(np.abs(xs - x0).max())
    assert moved > 1e-5  # the cloths moved: the comparison means something
    bound = SOLVE_TOLERANCE * moved + 4.0 * float(np.spacing(np.float32(np.abs(xs).max())))
    assert float(np.abs(x - xs).max()) <= bound


def test_one_piece_is_its_builders_model():
    b = ClothBuilder()
    b.add_grid(**GRID_A, bend="choi_ko")
    one, alone = b.finalize("cpu"), build_grid_cloth(**GRID_A, bend="choi_ko", device="cpu")
    for f in ("q", "pairs", "rest", "mass", "inv_mass", "tris", "uv"):
        assert np.array_equal(getattr(one.host, f), getattr(alone.host, f)), f
    for f in ("spring_stiffness", "spring_damping", "spring_compression", "particle_inv_mass"):
        assert np.array_equal(getattr(one, f).numpy(), getattr(alone, f).numpy()), f
    assert (one.rows, one.cols, one.spring_params) == (alone.rows, alone.cols, alone.spring_params)
    assert [p.name for p in one.pieces] == ["grid0"] and alone.cloth_pieces[0].particle_count == 36


def test_pieces_records_offsets_pins_and_groups():
    b = ClothBuilder()
    ha = b.add_grid(**GRID_A, name="cape")
    tris = np.array([[0, 1, 2], [1, 3, 2]])
    verts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], dtype=float) + [3.0, 0.0, 0.0]
    hb = b.add_mesh(verts, tris, name="skirt", pins=[3], groups={"waist": [2, 3]}, bend=False, collision_group=1)
    m = b.finalize("cpu")
    assert (ha.offset, hb.offset, hb.particle_count) == (0, 36, 4)
    cape, skirt = m.pieces
    assert (skirt.particle_offset, skirt.particle_count, skirt.tri_offset, skirt.tri_count) == (36, 4, 50, 2)
    assert (cape.collision_group, skirt.collision_group) == (0, 1)
    assert sorted(m.pinned.tolist()) == [0, 5, 39]
    assert m.host.groups["skirt/waist"].tolist() == [38, 39]
    assert np.array_equal(m.host.tris[skirt.triangles] - 36, tris)
    assert m.host.collision_group.tolist() == [0] * 36 + [1] * 4
    assert m.particle_count == 40 and m.spring_count == build_grid_cloth(**GRID_A, device="cpu").spring_count + 5
    assert "2 cloths" in grid_structure_reason(m)  # implicit Euler's multigrid falls back, saying why


def test_collision_groups_skip_pairs_of_two_groups():
    """Two sheets 4 mm apart with a 1 cm thickness: candidates between them in one group, none in two."""
    sheet = {"rows": 4, "cols": 4, "width": 0.3, "height": 0.3, "plane": "horizontal"}
    counts = []
    for groups in ((0, 0), (0, 1)):
        b = ClothBuilder()
        b.add_grid(**sheet, origin=(0.0, 0.0, 0.0), collision_group=groups[0], bend="none")
        b.add_grid(**sheet, origin=(0.0, 0.004, 0.0), collision_group=groups[1], bend="none")
        m = b.finalize("cpu")
        sc = SelfCollision(m, thickness=0.01)
        sc.detect(m.particle_q, wp.zeros_like(m.particle_q), DT)
        counts.append(sc.stats()["candidates_vertex_triangle"])
    assert counts[0] > 0 and counts[1] == 0


def test_usd_one_mesh_prim_per_piece_and_player(tmp_path):
    pxr = pytest.importorskip("pxr")
    m = _two()
    x = m.host.q + np.float32(0.01)
    path = str(tmp_path / "two.usda")
    with UsdWriter(path, m, fps=30.0, color="strain") as w:
        w.write_frame(m.host.q, 0.0)
        w.write_frame(x, 1.0 / 30.0)
    stage = pxr.Usd.Stage.Open(path)
    meshes = [p for p in stage.Traverse() if p.IsA(pxr.UsdGeom.Mesh)]
    assert [str(p.GetPath()) for p in meshes] == ["/World/Cloth/a", "/World/Cloth/b"]
    for prim, piece in zip(meshes, m.pieces):
        mesh = pxr.UsdGeom.Mesh(prim)
        pts = np.array(mesh.GetPointsAttr().Get(1.0))
        assert np.array_equal(pts, x[piece.particles])
        assert len(mesh.GetFaceVertexCountsAttr().Get()) == piece.tri_count
        idx = np.array(mesh.GetFaceVertexIndicesAttr().Get())
        assert idx.min() == 0 and idx.max() == piece.particle_count - 1
    html = str(tmp_path / "two.html")
    h = HtmlWriter(html, m)
    h.write_frame(m.host.q, 0.0)
    h.close()
    data = read_player_data(html)
    assert [(p["name"], p["first"], p["count"]) for p in data["pieces"]] == [("a", 0, 36), ("b", 36, 35)]


def test_bench_times_several_pieces():
    row = bench_one("explicit_euler", 4, "cpu", False, 4, 0.1, scenario="pair", windows=2)
    assert row["particles"] == 2 * 16 and row["stable"]


def test_bad_pieces_are_refused():
    b = ClothBuilder()
    with pytest.raises(WarpclothError, match="builder has no piece"):
        b.finalize("cpu")
    with pytest.raises(WarpclothError, match=r"piece 'skirt': mesh is empty"):
        b.add_mesh(np.zeros((0, 3)), np.zeros((0, 3), dtype=int), name="skirt")
    with pytest.raises(WarpclothError, match="material must be a Material, a preset's name or None"):
        b.add_grid(4, 4, material=3.5)
    with pytest.raises(WarpclothError, match="unknown material 'velvet'"):
        b.add_grid(4, 4, material="velvet")
    with pytest.raises(WarpclothError, match="piece name"):
        b.add_grid(4, 4, name="my cape")
    with pytest.raises(WarpclothError, match="piece 'g': .*rows"):
        b.add_grid(1, 4, name="g")
    with pytest.raises(WarpclothError, match="collision_group of piece 'c'"):
        b.add_grid(4, 4, name="c", collision_group=-1)
    b.add_grid(4, 4, name="cape")
    with pytest.raises(WarpclothError, match="'cape' is already taken"):
        b.add_grid(4, 4, name="cape")
    with pytest.raises(WarpclothError, match="piece 'w': .*unexpected keyword argument 'wind'"):
        b.add_grid(4, 4, name="w", wind=1.0)
    assert b.piece_count == 1


def test_mesh_piece_matches_its_builder():
    """A mesh piece beside a grid keeps the mesh builder's springs and masses (offset)."""
    verts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [2, 0.5, 0]], dtype=float)
    tris = np.array([[0, 1, 2], [1, 3, 2], [1, 4, 3]])
    alone = build_mesh_cloth(verts, tris, total_mass=0.1, device="cpu")
    b = ClothBuilder()
    b.add_grid(**GRID_A)
    b.add_mesh(verts, tris, total_mass=0.1)
    m = b.finalize("cpu")
    s = m.spring_count - alone.spring_count
    assert np.array_equal(m.host.pairs[s:] - 36, alone.host.pairs)
    assert np.array_equal(m.host.mass[36:], alone.host.mass)
    assert np.array_equal(m.spring_stiffness.numpy()[s:], alone.spring_stiffness.numpy())


def test_the_documented_example_runs(tmp_path, monkeypatch, capsys):
    """docs/garments.md's example, as printed: its pieces and its USD file."""
    text = (Path(__file__).resolve().parents[1] / "docs" / "garments.md").read_text()
    code = re.search(r"```python\n(.*?)```", text, re.S).group(1)
    monkeypatch.chdir(tmp_path)
    exec(compile(code, "docs/garments.md", "exec"), {})
    printed = capsys.readouterr().out.strip().splitlines()[-1]
    assert printed == re.search(r"# (\[\('cape'.*)", code).group(1)
    assert 'def Mesh "skirt"' in (tmp_path / "garments.usda").read_text()
