"""Colliders in USD: each collider is a prim under /World/Colliders whose world transform puts its
geometry where the collider is (read back with pxr and compared with the collider's own surface
points), static ones without time samples, moving ones sampled at every frame along their track;
the stage passes UsdValidation; samples survive value clips."""

import math

import numpy as np
import pytest
from pxr import Usd, UsdGeom

from warpcloth import Box, Capsule, Control, Plane, Simulator, Sphere, build_grid_cloth
from warpcloth.io.usd import UsdWriter
from warpcloth.run.harness import RunHarness
from warpcloth.sim.colliders import ColliderTrack, MeshCollider, quat_matrix

FPS = 30.0
SPIN = ColliderTrack.rigid(center=(0.3, 0.2, 0.0), axis=(0.0, 1.0, 0.0), angular_velocity=1.5, velocity=(0.1, 0.0, 0.0))
SLIDE = ColliderTrack.keyframes([0.0, 0.2], [[0, 0, 0], [0.0, -0.1, 0.2]])
COLLIDERS = (
    Plane(point=(0.0, -1.0, 0.0), normal=(0.0, 1.0, 0.2), thickness=0.01, friction=0.4),
    Sphere(center=(0.5, -0.5, 0.2), radius=0.25, track=SLIDE),
    Capsule(a=(-0.3, -0.6, 0.1), b=(0.4, -0.4, -0.2), radius=0.1, friction=0.2),
    Box(
        center=(0.3, -0.8, 0.0),
        half_extents=(0.3, 0.1, 0.2),
        rotation=(0.0, 0.0, math.sin(0.3), math.cos(0.3)),
        track=SPIN,
    ),
    MeshCollider(
        vertices=[[-0.5, -1.2, 0.0], [0.0, -1.2, 0.3], [0.2, -0.9, -0.1], [0.1, -1.0, 0.4]],
        triangles=[[0, 1, 2], [0, 2, 3]],
        thickness=0.02,
        friction=0.3,
        track=SPIN,
    ),
)


def world(prim, code):
    """4x4 local-to-world matrix (row vectors, as Gf) of a prim at a time code."""
    return np.array(UsdGeom.Xformable(prim).ComputeLocalToWorldTransform(code), dtype=np.float64)


def apply(m, local):
    local = np.atleast_2d(np.asarray(local, dtype=np.float64))
    return local @ m[:3, :3] + m[3, :3]


def check_prim(stage, k, c, code):
    """The prim's geometry, moved by its world transform, lies on the collider ``c``."""
    prim = stage.GetPrimAtPath(f"/World/Colliders/{c.kind.capitalize()}_{k}")
    m = world(prim, code)
    if c.kind == "sphere":
        assert UsdGeom.Sphere(prim).GetRadiusAttr().Get() == pytest.approx(c.radius)
        np.testing.assert_allclose(apply(m, [0, 0, 0])[0], c.center, atol=1e-6)
    elif c.kind == "capsule":
        cap = UsdGeom.Capsule(prim)
        assert cap.GetAxisAttr().Get() == "Z" and cap.GetRadiusAttr().Get() == pytest.approx(c.radius)
        h = cap.GetHeightAttr().Get()
        np.testing.assert_allclose(apply(m, [[0, 0, -h / 2], [0, 0, h / 2]]), [c.a, c.b], atol=1e-6)
    elif c.kind == "box":
        assert UsdGeom.Cube(prim).GetSizeAttr().Get() == 2.0
        corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=np.float64)
        expected = c.center + (corners * c.half_extents) @ quat_matrix(c.rotation).T
        np.testing.assert_allclose(apply(m, corners), expected, atol=1e-6)
    elif c.kind == "mesh":  # its points as given, moved by the prim's transform onto the collider's
        points = np.array(UsdGeom.Mesh(prim).GetPointsAttr().Get(), dtype=np.float64)
        np.testing.assert_allclose(apply(m, points), c.vertices, atol=1e-6)
    else:
        points = np.array(UsdGeom.Mesh(prim).GetPointsAttr().Get(), dtype=np.float64)
        w = apply(m, points)
        np.testing.assert_allclose((w - c.point) @ np.asarray(c.normal), 0.0, atol=1e-6)  # on the plane
        np.testing.assert_allclose(apply(m, [0, 0, 0])[0], c.point, atol=1e-6)
        normal = np.cross(w[1] - w[0], w[2] - w[0])
        np.testing.assert_allclose(normal / np.linalg.norm(normal), c.normal, atol=1e-6)  # faces outward
    assert prim.GetCustomDataByKey("warpcloth:thickness") == pytest.approx(c.thickness)
    assert prim.GetCustomDataByKey("warpcloth:friction") == pytest.approx(c.friction)


@pytest.mark.parametrize("clip_frames", [None, 4])
def test_colliders_are_prims_that_follow_their_tracks(tmp_path, clip_frames):
    model = build_grid_cloth(4, 4, 0.5, 0.5, 0.1, plane="horizontal", origin=(0.0, 0.5, 0.0), device="cpu")
    sim = Simulator(
        model, "explicit_euler", Control(colliders=COLLIDERS, device="cpu"), dt=1.0 / (64 * FPS)
    )  # frames on steps
    path = str(tmp_path / "c.usda")
    writer = UsdWriter(path, model, FPS, colliders=sim.control.colliders, clip_frames=clip_frames)
    RunHarness(sim).run(10 / FPS, FPS, frames=writer)
    writer.close()
    stage = Usd.Stage.Open(path)
    codes = [float(c) for c in range(11)]
    for k, c in enumerate(COLLIDERS):
        prim = stage.GetPrimAtPath(f"/World/Colliders/{c.kind.capitalize()}_{k}")
        assert prim.IsValid()
        translate = prim.GetAttribute("xformOp:translate")
        if c.track is None:
            assert translate.GetTimeSamples() == []
            check_prim(stage, k, c, Usd.TimeCode.Default())
        else:
            assert translate.GetTimeSamples() == codes
        for code in codes:
            check_prim(stage, k, c.at(code / FPS), code)
    for moving in ("Box_3", "Mesh_4"):
        assert not np.allclose(
            world(stage.GetPrimAtPath(f"/World/Colliders/{moving}"), 9.0),
            world(stage.GetPrimAtPath(f"/World/Colliders/{moving}"), 0.0),
        )


def test_stage_with_colliders_validates(tmp_path):
    from test_usd_pipeline import validation_errors

    model = build_grid_cloth(4, 4, 0.5, 0.5, 0.1, plane="horizontal", origin=(0.0, 0.5, 0.0), device="cpu")
    path = str(tmp_path / "v.usda")
    with UsdWriter(path, model, FPS, colliders=COLLIDERS) as w:
        w.write_frame(model.host.q, 0.0)
        w.write_frame(model.host.q, 1 / FPS)
    assert validation_errors(Usd.Stage.Open(path)) == []


def test_cli_and_run_export_the_scenarios_colliders(tmp_path):
    """`warpcloth run drape --usd` and `Scenario.run(usd_path=path)` write the scenario's colliders
    (the drape's sphere and ground) beside the cloth."""
    from pxr import Usd

    from warpcloth.cli import main
    from warpcloth.scenarios import get_scenario

    out = tmp_path / "drape.usda"
    assert main(["run", "drape", "--rows", "5", "--cols", "5", "--duration", "0.05", "--usd", str(out), "-q"]) == 0
    stage = Usd.Stage.Open(str(out))
    kinds = sorted(p.GetName().split("_")[0] for p in stage.GetPrimAtPath("/World/Colliders").GetChildren())
    assert kinds == sorted(c.kind.capitalize() for c in get_scenario("drape").build(rows=5, cols=5).control.colliders)
    direct = tmp_path / "direct.usda"
    get_scenario("drape").run(usd_path=str(direct), rows=5, cols=5, duration=0.05)
    stage = Usd.Stage.Open(str(direct))
    assert len(stage.GetPrimAtPath("/World/Colliders").GetChildren()) == len(kinds) > 0
