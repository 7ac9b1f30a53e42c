"""USD that other tools take: no empty prim (an empty /World/Pins point cloud crashed Blender 5.0's
Cycles), colliders as guides unless asked to render, the output line naming a long run's clip
folder; and, where Blender's bpy is installed, Blender 5.0 imports and renders the drape, the
tablecloth and a clipped run (skipped otherwise, like the Chromium test in test_player.py)."""

import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest
from pxr import Usd, UsdGeom

from warpcloth.io.usd import UsdWriter
from warpcloth.scenarios import get_scenario


def _write(path, scenario, frames=4, **kw):
    sim = get_scenario(scenario).build(rows=8, cols=8, device="cpu")
    writer = UsdWriter(str(path), sim.model, 60.0, colliders=sim.control.colliders, **kw)
    steps = max(1, round(1.0 / 60.0 / sim.dt))  # 1/60 s frames: one time code each
    for _ in range(frames):
        sim.simulate(steps)
        writer.write_frame(sim.state.particle_q.numpy(), sim.sim_time)
    writer.close()
    return writer


def _empty_prims(stage):
    """Geometry prims with nothing to draw (no points, or no faces)."""
    empty = []
    for prim in stage.Traverse():
        if prim.IsA(UsdGeom.PointBased):
            attr = UsdGeom.PointBased(prim).GetPointsAttr()
            times = attr.GetTimeSamples() or [Usd.TimeCode.Default()]
            if all(len(attr.Get(t) or []) == 0 for t in times):
                empty.append(str(prim.GetPath()))
        elif prim.IsA(UsdGeom.Scope) and not prim.GetChildren():
            empty.append(str(prim.GetPath()))
    return empty


@pytest.mark.parametrize("scenario", ["drape", "tablecloth", "sheet"])
def test_no_prim_is_written_empty(tmp_path, scenario):
    # the drape and the tablecloth have no pins: no /World/Pins at all; the sheet's pins are there
    writer = _write(tmp_path / f"{scenario}.usda", scenario)
    stage = Usd.Stage.Open(writer.path)
    assert _empty_prims(stage) == []
    pinned = len(get_scenario(scenario).build(rows=8, cols=8, device="cpu").model.pinned) > 0
    assert stage.GetPrimAtPath("/World/Pins").IsValid() == pinned


def test_colliders_are_guides_unless_asked_to_render(tmp_path):
    # UsdGeom purpose: "guide" prims are drawn in viewports and skipped by renderers (the cloth
    # renders without its collision proxies); "render" draws them as well
    for purpose in ("guide", "render"):
        writer = _write(tmp_path / f"{purpose}.usda", "drape", colliders_purpose=purpose)
        stage = Usd.Stage.Open(writer.path)
        colliders = stage.GetPrimAtPath("/World/Colliders").GetChildren()
        assert colliders and all(UsdGeom.Imageable(p).ComputePurpose() == purpose for p in colliders)
        assert UsdGeom.Imageable(stage.GetPrimAtPath("/World/Cloth")).ComputePurpose() == "default"
    with pytest.raises(Exception, match="guide, render"):
        _write(tmp_path / "bad.usda", "drape", colliders_purpose="hidden")


def test_a_clipped_run_names_its_clip_folder(tmp_path):
    # a run longer than one chunk keeps its samples in OUT.usdc.clips/: the output line says so
    writer = _write(tmp_path / "long.usdc", "drape", frames=6, clip_frames=2)
    assert writer.clip_folder == str(tmp_path / "long.usdc.clips")
    line = writer.describe()
    assert "long.usdc.clips" in line and "3 clips" in line and "6 frames" in line
    assert "clips" not in _write(tmp_path / "short.usdc", "drape").describe()


#: Blender in a subprocess (it owns its process): import the stage, go to its last frame, read the
#: cloth, render one Cycles frame.
_BLENDER = textwrap.dedent("""
    import json, sys
    import bpy
    stage, out = sys.argv[1], sys.argv[2]
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.wm.usd_import(filepath=stage)
    scene = bpy.context.scene
    names = sorted(o.name for o in bpy.data.objects)
    cloth = next(o for o in bpy.data.objects if o.type == "MESH" and o.name.startswith("Cloth"))
    scene.frame_set(scene.frame_end)
    depsgraph = bpy.context.evaluated_depsgraph_get()
    points = [tuple(v.co) for v in cloth.evaluated_get(depsgraph).to_mesh().vertices]
    cam = bpy.data.objects.new("cam", bpy.data.cameras.new("cam"))
    scene.collection.objects.link(cam)
    cam.location = (0.5, 1.5, 4.0)
    scene.camera = cam
    light = bpy.data.objects.new("sun", bpy.data.lights.new("sun", "SUN"))
    scene.collection.objects.link(light)
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = 1
    scene.render.resolution_x = scene.render.resolution_y = 32
    scene.render.filepath = out
    bpy.ops.render.render(write_still=True)
    print(json.dumps({"objects": names, "frame_end": scene.frame_end, "points": points[:3], "count": len(points)}))
""")


def _blender(stage_path, png):
    pytest.importorskip("bpy", reason="Blender's bpy module is not installed (pip install bpy: Python 3.11)")
    proc = subprocess.run(
        [sys.executable, "-c", _BLENDER, str(stage_path), str(png)],
        capture_output=True,
        text=True,
        timeout=600,
        env=dict(os.environ, PYTHONWARNINGS="ignore"),
    )
    assert proc.returncode == 0, (proc.returncode, proc.stdout[-2000:], proc.stderr[-2000:])  # a segfault is -11
    import json

    return json.loads(proc.stdout.strip().splitlines()[-1])


@pytest.mark.parametrize("scenario,frames,clip", [("drape", 4, None), ("tablecloth", 4, None), ("drape", 6, 2)])
def test_blender_imports_and_renders_the_stage(tmp_path, scenario, frames, clip):
    path = tmp_path / f"{scenario}.usdc"
    sim_writer = _write(path, scenario, frames=frames, **({"clip_frames": clip} if clip else {}))
    assert (sim_writer.clip_folder is not None) == bool(clip)
    got = _blender(path, tmp_path / "render.png")
    assert (tmp_path / "render.png").exists()
    stage = Usd.Stage.Open(str(path))
    last = np.array(UsdGeom.Mesh(stage.GetPrimAtPath("/World/Cloth")).GetPointsAttr().Get(sim_writer.last_code))
    assert got["count"] == len(last) and got["frame_end"] == int(sim_writer.last_code)
    assert np.allclose(got["points"], last[:3], atol=1e-5)  # the last frame's points (Blender turns Y up by the object)


def test_the_run_line_names_the_clip_folder_and_the_purpose_flag(tmp_path, capsys, monkeypatch):
    # warpcloth run ... --usd OUT.usdc on a run longer than a chunk: the line after "wrote" says
    # where the samples went; --usd-colliders render draws the colliders
    import warpcloth.io.usd as usd
    from warpcloth.cli import main

    monkeypatch.setattr(usd, "CLIP_BYTES", 1)  # the smallest chunk: 60 frames
    out = tmp_path / "long.usdc"
    assert (
        main(["run", "drape", "--size", "4", "--num-frames", "130", "--usd", str(out), "--usd-colliders", "render"])
        == 0
    )
    line = next(x for x in capsys.readouterr().out.splitlines() if "wrote" in x)
    assert f"its samples are in {out}.clips{os.sep} (3 clips): copy the folder with the file" in line
    stage = Usd.Stage.Open(str(out))
    assert all(
        UsdGeom.Imageable(p).ComputePurpose() == "render" for p in stage.GetPrimAtPath("/World/Colliders").GetChildren()
    )


def test_a_written_stage_reads_back_as_a_mesh_input(tmp_path):
    # README: `warpcloth run mesh --mesh cape.usda --prim /World/Cloth` on the stage a run wrote:
    # the cloth's points have a default value (the first frame) besides their time samples
    from warpcloth.io.meshio import load_mesh

    writer = _write(tmp_path / "sheet.usda", "sheet")
    mesh = load_mesh(writer.path, prim="/World/Cloth")
    stage = Usd.Stage.Open(writer.path)
    points = UsdGeom.Mesh(stage.GetPrimAtPath("/World/Cloth")).GetPointsAttr()
    assert len(points.GetTimeSamples()) == writer.frames  # still animated
    assert np.allclose(mesh.vertices, np.array(points.Get(points.GetTimeSamples()[0])), atol=1e-6)
