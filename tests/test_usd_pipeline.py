"""USD fit for a pipeline: provenance in customLayerData, /World/Pins written once with an extent,
strain displayColor, .usdz packages, and UsdValidation's verdict; the preview PNG/GIF."""

import os
import sys

import numpy as np
import pytest
from pxr import Usd, UsdGeom

from warpcloth.cli import main


def _run(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_provenance_round_trips(capsys, tmp_path):
    usd = tmp_path / "f.usda"
    argv = [
        "run",
        "flag",
        "-i",
        "implicit_euler",
        "--cg-tol",
        "1e-4",
        "--rows",
        "5",
        "--cols",
        "6",
        "--num-frames",
        "4",
        "--stiffness",
        "800,600,100",
        "--mass",
        "0.25",
        "--usd",
        str(usd),
    ]
    code, _out, err = _run(capsys, *argv)
    assert code == 0, err
    stage = Usd.Stage.Open(str(usd))
    info = stage.GetRootLayer().customLayerData["warpcloth"]
    import warp as wp

    import warpcloth

    assert info["warpcloth_version"] == warpcloth.__version__ and info["warp_version"] == wp.config.version
    assert info["scenario"] == "flag" and info["integrator"] == "implicit_euler" and info["device"] == "cpu"
    assert info["integrator_options"]["cg_tol"] == pytest.approx(1e-4)
    assert info["dt"] == pytest.approx(1 / 60) and info["fps"] == 60.0 and info["rows"] == 5 and info["cols"] == 6
    assert info["ks"] == {"structural": 800.0, "shear": 600.0, "bend": 100.0}
    assert set(info["kd"]) == {"structural", "shear", "bend"} and info["mass"] == pytest.approx(0.25)
    assert info["strain_limit"] == "none" and info["strain_limit_applied"] == 0.1  # implicit_euler's strain cap
    assert info["command_line"] == "warpcloth " + " ".join(argv)
    assert info["date"].endswith("+00:00")
    assert stage.GetTimeCodesPerSecond() == 60.0


def test_pins_written_once_with_extent(capsys, tmp_path):
    usd = tmp_path / "s.usda"
    code, _out, err = _run(capsys, "run", "sheet", "--rows", "6", "--cols", "7", "--num-frames", "5", "--usd", str(usd))
    assert code == 0, err
    stage = Usd.Stage.Open(str(usd))
    pins = UsdGeom.Points(stage.GetPrimAtPath("/World/Pins"))
    # markers for viewports, not geometry: Cycles rendered default-purpose pins as white balls
    assert pins.GetPurposeAttr().Get() == UsdGeom.Tokens.guide
    assert UsdGeom.Imageable(pins).ComputePurpose() == UsdGeom.Tokens.guide
    points = pins.GetPointsAttr()
    assert points.GetNumTimeSamples() == 0  # the pins do not move: one value
    p = np.array(points.Get())
    assert len(p) == len(pins.GetWidthsAttr().Get()) > 0
    extent = np.array(pins.GetExtentAttr().Get())
    assert np.all(extent[0] <= p.min(axis=0)) and np.all(extent[1] >= p.max(axis=0))
    computed = UsdGeom.Points.ComputeExtent(points.Get(), pins.GetWidthsAttr().Get())
    assert np.allclose(np.array(computed), extent, atol=1e-6)
    cloth = UsdGeom.Mesh(stage.GetPrimAtPath("/World/Cloth"))
    assert cloth.GetPointsAttr().GetNumTimeSamples() == 6
    assert not cloth.GetPrim().GetAttribute("primvars:displayColor").IsAuthored()  # only with --usd-color strain


def test_pins_time_sampled_when_they_move(tmp_path):
    from warpcloth.io.usd import UsdWriter
    from warpcloth.scenarios import sheet

    sim = sheet.build(rows=4, cols=4)
    w = UsdWriter(str(tmp_path / "m.usda"), sim.model, 10.0)
    q = sim.model.host.q.copy()
    w.write_frame(q, 0.0)
    w.write_frame(q, 0.1)
    q2 = q.copy()
    q2[sim.model.pinned] += 0.5
    w.write_frame(q2, 0.2)
    w.close()
    stage = Usd.Stage.Open(str(tmp_path / "m.usda"))
    pins = UsdGeom.Points(stage.GetPrimAtPath("/World/Pins"))
    assert pins.GetPointsAttr().GetTimeSamples() == [0.0, 1.0, 2.0]
    assert np.allclose(np.array(pins.GetPointsAttr().Get(2.0)), q2[sim.model.pinned])
    assert np.allclose(np.array(pins.GetPointsAttr().Get(1.0)), q[sim.model.pinned])  # held from frame 0


def test_strain_display_color(capsys, tmp_path):
    usd = tmp_path / "c.usda"
    code, _out, err = _run(
        capsys,
        "run",
        "flag",
        "--rows",
        "5",
        "--cols",
        "6",
        "--num-frames",
        "3",
        "--usd",
        str(usd),
        "--usd-color",
        "strain",
    )
    assert code == 0, err
    stage = Usd.Stage.Open(str(usd))
    mesh = stage.GetPrimAtPath("/World/Cloth")
    pv = UsdGeom.PrimvarsAPI(mesh).GetPrimvar("displayColor")
    assert pv.GetInterpolation() == UsdGeom.Tokens.vertex and pv.GetAttr().GetNumTimeSamples() == 4
    c0 = np.array(pv.Get(0.0))
    assert c0.shape == (30, 3) and np.allclose(c0, [0.10, 0.25, 0.85], atol=1e-6)  # at rest: strain 0, blue
    assert not np.allclose(np.array(pv.Get(3.0)), c0)
    with pytest.raises(SystemExit) as exit_:
        main(["run", "flag", "--num-frames", "3", "--usd", str(usd), "--usd-color", "rainbow"])
    assert exit_.value.code == 2 and "invalid choice" in capsys.readouterr().err


def test_usdz_opens_and_validates(capsys, tmp_path):
    usdz = tmp_path / "f.usdz"
    code, _out, err = _run(
        capsys,
        "run",
        "flag",
        "--rows",
        "4",
        "--cols",
        "5",
        "--num-frames",
        "3",
        "--usd",
        str(usdz),
        "--usd-color",
        "strain",
    )
    assert code == 0, err
    assert sorted(os.listdir(tmp_path)) == ["f.usdz"]  # the .usdc and the package temporaries are gone
    assert usdz.read_bytes()[:2] == b"PK"
    stage = Usd.Stage.Open(str(usdz))
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/World/Cloth"))
    assert (
        len(mesh.GetPointsAttr().Get(2.0)) == 20
        and stage.GetRootLayer().customLayerData["warpcloth"]["scenario"] == "flag"
    )
    assert not validation_errors(stage), validation_errors(stage)


def validation_errors(stage) -> list:
    """Errors of every validator usd-core registers (skips where usd-core has no UsdValidation)."""
    try:
        from pxr import UsdValidation
    except ImportError:
        pytest.skip("usd-core without UsdValidation")
    validators = UsdValidation.ValidationRegistry().GetOrLoadAllValidators()
    assert len(validators) > 10
    errors = UsdValidation.ValidationContext(validators).Validate(stage)
    return [
        f"{e.GetName()}: {e.GetMessage()}" for e in errors if e.GetType() == UsdValidation.ValidationErrorType.Error
    ]


def test_usd_validation_passes_usda_and_can_fail(capsys, tmp_path):
    usd = tmp_path / "s.usda"
    code, _out, err = _run(capsys, "run", "sheet", "--rows", "4", "--cols", "4", "--num-frames", "2", "--usd", str(usd))
    assert code == 0, err
    assert validation_errors(Usd.Stage.Open(str(usd))) == []
    bare = Usd.Stage.CreateInMemory()  # no default prim, up axis or units: errors
    UsdGeom.Mesh.Define(bare, "/Bad")
    assert len(validation_errors(bare)) >= 2


# -- preview ----------------------------------------------------------------------------------


def test_preview_png_and_gif(capsys, tmp_path):
    pytest.importorskip("matplotlib")
    png, gif = tmp_path / "p.png", tmp_path / "p.gif"
    code, _out, err = _run(
        capsys, "run", "flag", "--rows", "5", "--cols", "6", "--num-frames", "4", "--preview", str(png)
    )
    assert code == 0, err
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    code, _out, err = _run(
        capsys,
        "run",
        "flag",
        "--rows",
        "5",
        "--cols",
        "6",
        "--num-frames",
        "200",
        "--fps",
        "100",
        "--preview",
        str(gif),
    )
    assert code == 0, err
    from PIL import Image

    from warpcloth.io.preview import MAX_GIF_FRAMES, gif_stride

    im = Image.open(gif)
    assert im.format == "GIF" and im.n_frames <= MAX_GIF_FRAMES + 1 and im.n_frames >= 60
    stride = gif_stride(201)
    assert stride == 3 and im.info["duration"] == pytest.approx(1000 * stride / 100, abs=10)  # plays at simulated speed
    assert sorted(os.listdir(tmp_path)) == ["p.gif", "p.png"]
    code, _out, err = _run(capsys, "run", "flag", "--num-frames", "2", "--preview", str(tmp_path / "p.jpg"))
    assert code == 2 and ".png, .gif" in err


def test_preview_without_matplotlib_is_one_line_before_the_run(capsys, tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "matplotlib", None)  # import matplotlib raises ImportError
    code, out, err = _run(capsys, "run", "sheet", "--duration", "1000", "--preview", str(tmp_path / "p.png"))
    assert code == 2 and out == ""
    assert err.strip() == (
        "warpcloth: error: --preview needs matplotlib: pip install 'warpcloth[plot]' "
        "(from a clone: pip install -e '.[plot]')"
    )
    assert os.listdir(tmp_path) == []
