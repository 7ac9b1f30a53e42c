"""A deforming mesh collider (MeshTrack.keyframes) through the outputs and back in: the USD output
samples its points and extent at every frame (identity transform; a static mesh's points are not
sampled), the HTML player's per-frame vertices equal those samples within its quantisation step, a
USD mesh with time-sampled points loads as a keyframed collider (seconds = time code /
timeCodesPerSecond) that carries a cloth, and the USD written reads back as the same keys."""

import base64
import json

import numpy as np
import pytest
from pxr import Gf, Usd, UsdGeom, Vt

from warpcloth import Control, Simulator, build_grid_cloth
from warpcloth.io.frames import FrameSinks
from warpcloth.io.meshio import load_mesh_collider
from warpcloth.io.player import HtmlWriter
from warpcloth.io.usd import UsdWriter
from warpcloth.run.harness import RunHarness
from warpcloth.sim.colliders import MeshCollider, MeshTrack

FPS = 30.0
DURATION = 0.2  # frames at 0, 1/30, ..., 6/30 s
QUAD = np.array([[-0.4, 0.0, -0.4], [0.4, 0.0, -0.4], [0.4, 0.0, 0.4], [-0.4, 0.0, 0.4]])
TRIS = [[0, 2, 1], [0, 3, 2]]  # normal +Y
KEY_TIMES = np.array([0.0, 0.07, 0.3])  # keys between frames: the frames are interpolated


def key_points():
    """(K, 4, 3): the quad breathes in x and rises, at a different rate on each key interval."""
    scale = np.array([1.0, 1.3, 0.8])
    rise = np.array([0.0, 0.03, 0.05])
    return np.stack([QUAD * [s, 1.0, 1.0] + [0.0, r, 0.0] for s, r in zip(scale, rise)])


def expected_points(t):
    """The keyframed quad at time t by linear interpolation in float64 (NumPy), held outside the keys."""
    keys = key_points()
    out = np.empty(keys.shape[1:])
    for i in range(keys.shape[1]):
        for a in range(3):
            out[i, a] = np.interp(t, KEY_TIMES, keys[:, i, a])
    return out


@pytest.fixture(scope="module")
def run_outputs(tmp_path_factory):
    """One run (xpbd, a 5x5 cloth over the deforming quad, a static mesh far below) written to USD and HTML
    by the frame sinks the CLI's --usd and --html use."""
    folder = tmp_path_factory.mktemp("deforming_io")
    body = MeshCollider(
        vertices=QUAD, triangles=TRIS, thickness=0.005, track=MeshTrack.keyframes(KEY_TIMES, key_points())
    )
    floor = MeshCollider(vertices=QUAD + [0.0, -2.0, 0.0], triangles=TRIS, thickness=0.005)
    model = build_grid_cloth(5, 5, 0.3, 0.3, 0.02, plane="horizontal", origin=(-0.15, 0.05, -0.15), device="cpu")
    control = Control(colliders=(body, floor), device="cpu")
    sim = Simulator(model, "xpbd", control)
    usd_path, html_path = str(folder / "run.usda"), str(folder / "run.html")
    sinks = FrameSinks(
        [
            UsdWriter(usd_path, model, FPS, colliders=control.colliders),
            HtmlWriter(html_path, model, FPS, colliders=control.colliders),
        ]
    )
    result = RunHarness(sim).run(DURATION, fps=FPS, frames=sinks)
    sinks.close()
    assert result.stable
    return {"usd": usd_path, "html": html_path, "body": body, "frames": sinks.frames}


def usd_samples(path, prim_path):
    """(time codes, points (K, V, 3) float32, extents (K, 2, 3), stage) of a mesh prim's samples."""
    stage = Usd.Stage.Open(path)
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath(prim_path))
    codes = mesh.GetPointsAttr().GetTimeSamples()
    points = np.stack([np.asarray(mesh.GetPointsAttr().Get(c), dtype=np.float32) for c in codes]) if codes else None
    extents = np.stack([np.asarray(mesh.GetExtentAttr().Get(c), dtype=np.float32) for c in codes]) if codes else None
    return np.asarray(codes), points, extents, stage


def test_usd_output_samples_a_deforming_mesh_at_every_frame(run_outputs):
    codes, points, extents, stage = usd_samples(run_outputs["usd"], "/World/Colliders/Mesh_0")
    per_second = stage.GetTimeCodesPerSecond()
    assert per_second == FPS
    assert len(codes) == run_outputs["frames"] == round(DURATION * FPS) + 1
    np.testing.assert_array_equal(codes, np.arange(len(codes), dtype=np.float64))
    body = run_outputs["body"]
    for code, p, e in zip(codes, points, extents):
        t = code / per_second
        want = expected_points(t).astype(np.float32)
        np.testing.assert_allclose(p, want, rtol=0, atol=2e-7)  # the float32 of the NumPy interpolation
        np.testing.assert_allclose(p, np.asarray(body.at(t).vertices, dtype=np.float32), rtol=0, atol=2e-7)
        np.testing.assert_array_equal(e, np.stack([p.min(axis=0), p.max(axis=0)]))
    assert np.abs(np.diff(points, axis=0)).max() > 1e-3  # animated: the frames differ
    prim = stage.GetPrimAtPath("/World/Colliders/Mesh_0")
    for code in codes:  # the points move, not the prim
        xf = np.asarray(UsdGeom.Xformable(prim).ComputeLocalToWorldTransform(Usd.TimeCode(code)))
        np.testing.assert_array_equal(xf, np.eye(4))
    static = UsdGeom.Mesh(stage.GetPrimAtPath("/World/Colliders/Mesh_1")).GetPointsAttr()
    assert static.GetNumTimeSamples() == 0  # a static mesh: its points are a default value only
    np.testing.assert_allclose(np.asarray(static.Get()), QUAD + [0.0, -2.0, 0.0], atol=1e-7)
    cloth = [p for p in stage.Traverse() if p.IsA(UsdGeom.Mesh) and str(p.GetPath()).startswith("/World/Cloth")]
    assert cloth and all(UsdGeom.Mesh(p).GetPointsAttr().GetNumTimeSamples() == len(codes) for p in cloth)


def player_data(path):
    """The JSON embedded in the page, read here without the package's reader."""
    page = open(path, encoding="utf-8").read()
    tag = '<script id="warpcloth-data" type="application/json">'
    a = page.index(tag) + len(tag)
    return json.loads(page[a : page.index("</script>", a)])


def test_html_player_holds_the_deforming_mesh_at_every_frame(run_outputs):
    data = player_data(run_outputs["html"])
    codes, points, _, _ = usd_samples(run_outputs["usd"], "/World/Colliders/Mesh_0")
    np.testing.assert_allclose(data["times"], codes / FPS, rtol=0, atol=1e-9)
    body, floor = data["colliders"]
    assert "deform" in body and "motion" not in body
    assert "deform" not in floor and "motion" not in floor  # static: no per-frame data
    d = body["deform"]
    q = np.frombuffer(base64.b64decode(d["frames"]), dtype="<u2").reshape(data["frameCount"], body["vertexCount"], 3)
    lo, hi = np.array(d["min"]), np.array(d["max"])
    step = (hi - lo) / 65535.0
    vertices = lo + q * step
    assert vertices.shape == points.shape
    # within half a quantisation step (plus the float32 rounding of the USD's samples)
    assert np.all(np.abs(vertices - points) <= 0.5 * step + 1e-7)
    np.testing.assert_allclose(lo, points.min(axis=(0, 1)), atol=1e-7)
    np.testing.assert_allclose(hi, points.max(axis=(0, 1)), atol=1e-7)
    assert np.abs(np.diff(vertices, axis=0)).max() > 1e-3  # animated


def write_rising_plane(path, per_second=10.0, default=True):
    """A .usda quad whose points are time-sampled at codes 0, 2, 5 (0, 0.2, 0.5 s at 10 codes/s): it
    rises 0.02, then 0.1 m in all; the prim is translated by (0, 0.1, 0)."""
    stage = Usd.Stage.CreateNew(str(path))
    stage.SetTimeCodesPerSecond(per_second)
    UsdGeom.Xform.Define(stage, "/World")
    mesh = UsdGeom.Mesh.Define(stage, "/World/Ground")
    mesh.AddTranslateOp().Set(Gf.Vec3d(0.0, 0.1, 0.0))
    quad = QUAD * [2.0, 1.0, 2.0]
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray([4]))
    mesh.CreateFaceVertexIndicesAttr(Vt.IntArray([0, 3, 2, 1]))  # counter-clockwise seen from +Y
    keys = {0.0: quad, 2.0: quad + [0.0, 0.02, 0.0], 5.0: quad + [0.0, 0.1, 0.0]}
    attr = mesh.CreatePointsAttr()
    if default:
        attr.Set(Vt.Vec3fArray.FromNumpy(quad.astype(np.float32)))
    for code, p in keys.items():
        attr.Set(Vt.Vec3fArray.FromNumpy(p.astype(np.float32)), code)
    stage.GetRootLayer().Save()
    return quad, keys


@pytest.mark.parametrize("default", [True, False], ids=["with_default", "samples_only"])
def test_usd_mesh_with_time_sampled_points_loads_as_keyframes(tmp_path, default):
    path = tmp_path / "rise.usda"
    quad, keys = write_rising_plane(path, default=default)
    c = load_mesh_collider(str(path), thickness=0.005)
    assert c.deforming and c.track.kind == "keyframes"
    np.testing.assert_allclose(c.track.times, [0.0, 0.2, 0.5], rtol=0, atol=1e-12)  # code / timeCodesPerSecond
    want = np.stack([p + [0.0, 0.1, 0.0] for p in keys.values()])  # in the prim's world transform
    np.testing.assert_allclose(c.track.points, want, rtol=0, atol=1e-6)
    np.testing.assert_allclose(c.vertices, quad + [0.0, 0.1, 0.0], rtol=0, atol=1e-6)
    np.testing.assert_allclose(c.at(0.35).vertices, quad + [0.0, 0.16, 0.0], rtol=0, atol=1e-6)


def test_a_cloth_rides_a_rising_usd_mesh(tmp_path):
    """A 4x4 cloth resting on the loaded plane is carried up by it, 0.1 m in 0.1 s against gravity (at 50
    codes/s the keys are at 0, 0.04 and 0.1 s: a short run, a deforming mesh's step costs tens of ms on a CPU)."""
    path = tmp_path / "rise.usda"
    write_rising_plane(path, per_second=50.0)
    thickness = 0.005

    def final_height(collider):
        model = build_grid_cloth(
            4, 4, 0.2, 0.2, 0.02, plane="horizontal", origin=(-0.1, 0.1 + thickness, -0.1), device="cpu"
        )
        sim = Simulator(model, "xpbd", Control(colliders=(collider,), device="cpu"))
        sim.set_dt(1.0 / 300.0)
        sim.simulate(30)  # 0.1 s: to the last key
        return sim.state.particle_q.numpy()[:, 1].astype(np.float64), sim.sim_time

    y, t = final_height(load_mesh_collider(str(path), thickness=thickness))
    assert t == pytest.approx(0.1)
    assert np.all(np.abs(y - (0.2 + thickness)) < 0.25 * thickness)  # on the plane at its last key, 0.2 m


def test_usd_output_reads_back_as_the_same_keys(run_outputs):
    codes, points, _, _ = usd_samples(run_outputs["usd"], "/World/Colliders/Mesh_0")
    c = load_mesh_collider(run_outputs["usd"], prim="/World/Colliders/Mesh_0", thickness=0.005)
    assert c.deforming
    np.testing.assert_allclose(c.track.times, codes / FPS, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(np.asarray(c.track.points, dtype=np.float32), points)
    np.testing.assert_allclose(c.vertices, QUAD, rtol=0, atol=1e-7)  # the rest pose: the default value
