"""Hostile files and paths (issue 50): ``warpcloth check-intersections FILE`` opens the file through
the guarded path of ``--mesh`` (every layer checked before it is opened, bounded, never a FIFO or a
file of /proc or /dev) and refuses non-finite or inconsistent geometry; ``python -m
warpcloth.examples [DIR]`` parses its arguments and writes each file atomically, never through a
link. Every case ends in one ``warpcloth: error: ...`` line (exit 2; 74 for a failed write).

The cases that hung (a FIFO layer, a 2 GiB file read whole) run in a subprocess with a timeout, so a
regression fails the test instead of hanging the suite."""

from __future__ import annotations

import errno
import json
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from warpcloth.cli import main
from warpcloth.examples import __main__ as examples

REPO = Path(__file__).resolve().parents[1]

#: A two-triangle cloth at /World/Cloth; ``{points}`` and the rest filled per case.
CLOTH = """#usda 1.0
(
    timeCodesPerSecond = 60
    {layer}
)
def Xform "World" (
    {world}
)
{{
    def Mesh "Cloth"
    {{
        int[] faceVertexCounts = {counts}
        int[] faceVertexIndices = {indices}
        point3f[] points = {points}
    }}
    def Scope "Colliders"
    {{
{colliders}
    }}
{extra}
}}
"""
POINTS = "[(0, 0, 0), (1, 0, 0), (0, 0, 1), (1, 0, 1)]"


def usda(
    path, layer="", world="", counts="[3, 3]", indices="[0, 1, 2, 1, 3, 2]", points=POINTS, colliders="", extra=""
):
    text = CLOTH.format(
        layer=layer, world=world, counts=counts, indices=indices, points=points, colliders=colliders, extra=extra
    )
    Path(path).write_text(text)
    return str(path)


def clips(asset: str) -> str:
    """``/World`` metadata naming ``asset`` as its one value clip."""
    return textwrap.dedent(
        f"""\
        clips = {{
            dictionary default = {{
                asset[] assetPaths = [@{asset}@]
                double2[] active = [(0, 0)]
                string primPath = "/World"
                double2[] times = [(0, 0)]
            }}
        }}"""
    )


def check(capsys, path):
    code = main(["check-intersections", str(path)])
    out, err = capsys.readouterr()
    return code, out, err


def refused(capsys, path, *words):
    code, out, err = check(capsys, path)
    assert code == 2, (code, out, err)
    assert err.startswith("warpcloth: error: ") and err.count("\n") == 1 and "Traceback" not in err, err
    for w in words:
        assert w in err, (w, err)
    return err


# -- check-intersections: the cases that hung, in a subprocess ------------------------------------------
def _fifo_cases(tmp_path) -> dict:
    """Files each naming a FIFO in one more way: sublayer, reference, payload, value clip, the
    selected variant's reference, a referenced layer's sublayer."""
    os.mkfifo(tmp_path / "fifo.usda")
    variant = textwrap.dedent(
        """\
            def "V" (
                variants = { string look = "a" }
                prepend variantSets = "look"
            )
            {
                variantSet "look" = {
                    "a" ( references = @./fifo.usda@ ) { }
                }
            }"""
    )
    usda(tmp_path / "inner.usda", layer="subLayers = [@./fifo.usda@]")
    return {
        "sublayer": usda(tmp_path / "sub.usda", layer="subLayers = [@./fifo.usda@]"),
        "reference": usda(tmp_path / "ref.usda", extra='    def "R" ( references = @./fifo.usda@ ) { }'),
        "payload": usda(tmp_path / "pay.usda", extra='    def "P" ( payload = @./fifo.usda@ ) { }'),
        "value clip": usda(tmp_path / "clip.usda", world=clips("./fifo.usda")),
        "variant": usda(tmp_path / "var.usda", extra=variant),
        "nested sublayer": usda(tmp_path / "nest.usda", extra='    def "N" ( references = @./inner.usda@ ) { }'),
    }


DRIVER = """
import contextlib, io, json, sys
from warpcloth.cli import main
out = {}
for path in sys.argv[1:]:
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        code = main(["check-intersections", path])
    out[path] = [code, err.getvalue()]
    print(json.dumps({path: out[path]}), flush=True)
"""


def _run_isolated(paths, timeout=300):
    """check-intersections on each path in one child process; {path: (code, stderr)}. A hang is a
    failure after ``timeout`` seconds, not a hung suite."""
    env = dict(os.environ, PYTHONPATH=str(REPO))
    try:
        p = subprocess.run(
            [sys.executable, "-c", DRIVER, *paths], capture_output=True, text=True, env=env, timeout=timeout
        )
    except subprocess.TimeoutExpired as exc:
        done = (exc.stdout or b"").decode() if isinstance(exc.stdout, bytes) else exc.stdout or ""
        pytest.fail(f"check-intersections hung (killed after {timeout} s); finished: {done!r}")
    assert p.returncode == 0, p.stderr[-3000:]
    found = {}
    for line in p.stdout.splitlines():
        found.update(json.loads(line))
    return found


def test_a_fifo_layer_named_in_any_way_is_refused_not_waited_on(tmp_path):
    cases = _fifo_cases(tmp_path)
    big = tmp_path / "big.usda"
    subprocess.run(["truncate", "-s", "2G", str(big)], check=True)  # sparse: no disk used
    found = _run_isolated([*cases.values(), str(big)])
    for kind, path in cases.items():
        code, err = found[path]
        assert code == 2 and err.startswith("warpcloth: error: ") and err.count("\n") == 1, (kind, err)
        assert "fifo.usda" in err and "is a FIFO, not a regular file" in err and os.path.basename(path) in err, (
            kind,
            err,
        )
    code, err = found[str(big)]
    assert code == 2 and err.count("\n") == 1 and "big.usda" in err and "is 2 GiB, more than the 1 GiB" in err, err


# -- check-intersections: files that are not USD -----------------------------------------------------------
@pytest.mark.parametrize(
    ("name", "content", "words"),
    [
        ("junk.usda", b"hello, world\n", ("junk.usda", "cannot be read as USD", "is not a valid usda layer")),
        ("junk.usdc", b"hello, world\n", ("junk.usdc", "cannot be read as USD")),
        ("junk.usdz", b"hello, world\n", ("junk.usdz", "cannot be read as USD")),
        ("empty.usda", b"", ("empty.usda", "cannot be read as USD")),
        ("binary.usda", bytes(range(256)) * 4, ("binary.usda", "cannot be read as USD")),
        ("cloth.txt", None, ("cloth.txt", "must end in one of .usd, .usda, .usdc, .usdz")),
    ],
)
def test_a_file_that_is_not_usd_is_one_line(tmp_path, capsys, name, content, words):
    path = tmp_path / name
    if content is None:
        usda(path)  # good USD text, but not a USD file name
    else:
        path.write_bytes(content)
    err = refused(capsys, path, *words)
    assert "Error in '" not in err and ".cpp" not in err  # pxr's C++ source location is not the user's business


def test_system_files_and_links_to_them_are_one_line(tmp_path, capsys):
    refused(capsys, "/etc/passwd", "'/etc/passwd' must end in one of")
    os.symlink("/etc/passwd", tmp_path / "passwd")
    refused(capsys, tmp_path / "passwd", "passwd' must end in one of")
    os.symlink("/etc/passwd", tmp_path / "passwd.usda")
    refused(capsys, tmp_path / "passwd.usda", "passwd.usda' cannot be read as USD")
    os.symlink("/proc/kmsg", tmp_path / "kmsg.usda")
    refused(capsys, tmp_path / "kmsg.usda", "kmsg.usda' is a system file under /proc")
    refused(capsys, usda(tmp_path / "clip.usda", world=clips("/proc/kmsg")), "'/proc/kmsg' (value clip in clip.usda)")


@pytest.mark.parametrize(
    ("sublayer", "words"),
    [
        ("./missing.usda", ("'./missing.usda' (sublayer in top.usda), which does not exist",)),
        ("./folder.usda", ("'./folder.usda' (sublayer in top.usda)", "is a folder, not a file")),
        ("./top.usda", ("'./top.usda' (sublayer in top.usda), which is the layer itself (a cycle of sublayers)",)),
        ("/proc/kmsg", ("'/proc/kmsg' (sublayer in top.usda)", "is a system file under /proc")),
        ("/dev/zero", ("'/dev/zero' (sublayer in top.usda)", "is a system file under /dev")),
        ("/etc/passwd", ("'/etc/passwd' (sublayer in top.usda), which cannot be read as USD",)),
        ("../" * 30 + "etc/passwd", ("etc/passwd' (sublayer in top.usda), which cannot be read as USD",)),
    ],
)
def test_a_sublayer_that_is_not_a_usd_file_is_refused_not_skipped(tmp_path, capsys, sublayer, words):
    (tmp_path / "folder.usda").mkdir()
    top = usda(tmp_path / "top.usda", layer=f"subLayers = [@{sublayer}@]")
    refused(capsys, top, "top.usda", *words)


def test_a_sublayer_cycle_through_another_layer_is_refused(tmp_path, capsys):
    usda(tmp_path / "a.usda", layer="subLayers = [@./b.usda@]")
    Path(tmp_path / "b.usda").write_text("#usda 1.0\n(\n    subLayers = [@./a.usda@]\n)\n")
    refused(capsys, tmp_path / "a.usda", "'./a.usda' (sublayer in b.usda), which is a layer it is a sublayer of")


# -- check-intersections: geometry ---------------------------------------------------------------------
CUBE = '        def Cube "box_0"\n        {{\n            double size = {size}\n        }}'
COLLIDER_MESH = """        def Mesh "mesh_0"
        {{
            int[] faceVertexCounts = {counts}
            int[] faceVertexIndices = {indices}
            point3f[] points = [(0, 1, 0), (1, 1, 0), (0, 1, 1)]
        }}"""


@pytest.mark.parametrize(
    ("case", "fields", "words"),
    [
        ("nan", {"points": "[(0, 0, 0), (nan, 0, 0), (0, 0, 1), (1, 0, 1)]"}, "/World/Cloth: point 1 = (nan"),
        ("inf", {"points": "[(0, 0, 0), (1, 0, 0), (0, -inf, 1), (1, 0, 1)]"}, "/World/Cloth: point 2 = (0.0, -inf"),
        ("short", {"indices": "[0, 1, 2, 1, 3]"}, "faceVertexCounts sum to 6 but there are 5 faceVertexIndices"),
        ("long", {"indices": "[0, 1, 2, 1, 3, 2, 0]"}, "faceVertexCounts sum to 6 but there are 7 faceVertexIndices"),
        ("no points", {"points": "[]"}, "/World/Cloth has no points"),
        ("no faces", {"counts": "[]", "indices": "[]"}, "/World/Cloth has no faces"),
        ("range", {"indices": "[0, 1, 2, 1, 4, 2]"}, "faceVertexIndices[4] = 4 is out of range: its 4 points"),
        ("quad", {"counts": "[4]", "indices": "[0, 1, 3, 2]"}, "face 0 has 4 vertices"),
        ("cube nan", {"colliders": CUBE.format(size="nan")}, "/World/Colliders/box_0 has size nan"),
        ("cube 0", {"colliders": CUBE.format(size="0")}, "/World/Colliders/box_0 has size 0.0"),
        (
            "cube string",
            {"colliders": CUBE.replace("double", "string").format(size='"big"')},
            "/World/Colliders/box_0: size must be numbers, got a str",
        ),
        (
            "collider range",
            {"colliders": COLLIDER_MESH.format(counts="[3]", indices="[0, 1, 3]")},
            "/World/Colliders/mesh_0: faceVertexIndices[2] = 3 is out of range",
        ),
        (
            "collider quad",  # was skipped: the checker counted no edge of it
            {"colliders": COLLIDER_MESH.format(counts="[4]", indices="[0, 1, 2, 0]")},
            "/World/Colliders/mesh_0: face 0 has 4 vertices",
        ),
    ],
)
def test_geometry_that_is_not_finite_or_consistent_is_refused(tmp_path, capsys, case, fields, words):
    refused(capsys, usda(tmp_path / "cloth.usda", **fields), "cloth.usda", words)


def test_a_nan_frame_of_a_clipped_file_is_refused_and_a_clean_one_counted(tmp_path, capsys):
    from warpcloth.io.usd import UsdWriter
    from warpcloth.sim.grid import build_grid_cloth

    model = build_grid_cloth(4, 4, 1.0, 1.0, 0.2, plane="horizontal", device="cpu")
    q = model.host.q.astype("float64")
    path = str(tmp_path / "run.usda")
    with UsdWriter(path, model, fps=60.0, clip_frames=2) as writer:  # value clips under run.usda.clips
        for k in range(5):
            writer.write_frame(q, k / 60)
    assert os.path.isdir(path + ".clips")
    code, out, _err = check(capsys, path)
    assert code == 0 and "5 frames: 0 with self-intersections" in out
    bad = str(tmp_path / "bad.usda")
    with UsdWriter(bad, model, fps=60.0, clip_frames=2) as writer:
        for k in range(5):
            writer.write_frame(q * (float("nan") if k == 3 else 1.0), k / 60)
    refused(capsys, bad, "bad.usda: /World/Cloth at time code 3: point 0 = (nan")


# -- python -m warpcloth.examples ---------------------------------------------------------------------
SHIPPED = {os.path.basename(p): Path(p).read_bytes() for _kind, p in examples.example_files()}


def run_examples(capsys, *argv):
    code = examples.main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def one_line(err, *words):
    assert err.startswith("warpcloth: error: ") and err.count("\n") == 1 and "Traceback" not in err, err
    for w in words:
        assert w in err, (w, err)


def test_examples_parses_its_arguments(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    code, out, err = run_examples(capsys, "--bogus")
    assert code == 2 and not os.path.exists("--bogus")
    one_line(err, "unrecognized arguments: --bogus")
    code, out, err = run_examples(capsys, "a", "b")
    assert code == 2 and not os.path.exists("a") and not os.path.exists("b")
    one_line(err, "unrecognized arguments: b")
    code, out, err = run_examples(capsys, "--help")
    assert code == 0 and out.startswith("usage: python -m warpcloth.examples") and not os.path.exists("--help")
    code, out, err = run_examples(capsys)
    assert code == 0 and sorted(os.listdir("examples")) == sorted(SHIPPED)
    for name, data in SHIPPED.items():
        assert (tmp_path / "examples" / name).read_bytes() == data


@pytest.mark.parametrize(
    ("folder", "words"),
    [
        ("FILE", "exists and is not a folder"),
        ("FILE/sub", "cannot create the examples folder"),
        ("/dev/null", "'/dev/null' is under /dev"),
        ("/proc/x", "'/proc/x' is under /proc"),
        ("", "the examples folder path is empty"),
        ("x" * 300, "File name too long"),
    ],
)
def test_examples_refuses_a_folder_it_cannot_write_in_one_line(tmp_path, capsys, monkeypatch, folder, words):
    monkeypatch.chdir(tmp_path)
    Path("FILE").write_text("mine\n")
    code, _out, err = run_examples(capsys, folder)
    assert code == 2
    one_line(err, words)
    assert Path("FILE").read_text() == "mine\n"


def test_examples_refuses_an_immutable_folder_in_one_line(tmp_path, capsys):
    folder = tmp_path / "frozen"
    folder.mkdir()
    if shutil.which("chattr") is None or subprocess.run(["chattr", "+i", str(folder)]).returncode != 0:
        pytest.skip("chattr +i is not available here")
    try:
        code, _out, err = run_examples(capsys, str(folder))
        assert code == 2
        one_line(err, "frozen", "not writable")
        code, _out, err = run_examples(capsys, str(folder / "inside"))
        assert code == 2
        one_line(err, "cannot create the examples folder", "inside")
    finally:
        subprocess.run(["chattr", "-i", str(folder)], check=True)


def test_examples_never_write_through_a_link(tmp_path, capsys):
    d = tmp_path / "d"
    d.mkdir()
    os.symlink(tmp_path / "elsewhere.xml", d / "quick.xml")  # dangling
    code, _out, err = run_examples(capsys, str(d))
    assert code == 2
    one_line(err, "quick.xml is a link; warpcloth does not write through links")
    assert not os.path.lexists(tmp_path / "elsewhere.xml") and os.listdir(d) == ["quick.xml"]


def test_a_cut_short_copy_is_replaced_and_an_edited_one_reported(tmp_path, capsys):
    d = tmp_path / "d"
    d.mkdir()
    (d / "cape.obj").write_bytes(SHIPPED["cape.obj"][:8192])  # what a full disk left before
    (d / "cape.toml").write_bytes(SHIPPED["cape.toml"] + b"# my edit\n")
    code, out, _err = run_examples(capsys, str(d))
    assert code == 0
    assert (d / "cape.obj").read_bytes() == SHIPPED["cape.obj"]
    assert f"replaced {d}/cape.obj (mesh; a cut-short copy, 8,192 of {len(SHIPPED['cape.obj']):,} bytes)" in out
    assert (d / "cape.toml").read_bytes().endswith(b"# my edit\n")
    assert "differs from the shipped scenario file; --force replaces it" in out
    code, out, _err = run_examples(capsys, str(d), "--force")
    assert code == 0 and (d / "cape.toml").read_bytes() == SHIPPED["cape.toml"]


def test_a_full_disk_is_one_line_exit_74_and_leaves_no_half_file(tmp_path, capsys, monkeypatch):
    d = tmp_path / "d"
    d.mkdir()
    (d / "cape.obj").write_bytes(SHIPPED["cape.obj"][:8192])

    def full(fd):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(os, "fsync", full)  # the write reaches the disk at fsync, and fails there
    code, _out, err = run_examples(capsys, str(d))
    assert code == 74
    one_line(err, "no space left on the device", "example file", "is unchanged")
    assert os.listdir(d) == ["cape.obj"] and (d / "cape.obj").read_bytes() == SHIPPED["cape.obj"][:8192]


def test_a_really_full_disk_is_one_line_exit_74(tmp_path, capsys):
    folder = tmp_path / "small"
    folder.mkdir()
    mount = ["mount", "-t", "tmpfs", "-o", "size=16k", "tmpfs", str(folder)]
    if subprocess.run(mount, capture_output=True).returncode != 0:
        pytest.skip("cannot mount a small tmpfs here")
    try:
        code, out, err = run_examples(capsys, str(folder))  # the test lists fit, cape.obj (33 kB) does not
        assert code == 74
        one_line(err, "no space left on the device", "cape.obj", "is unchanged")
        assert "copied" in out and not (folder / "cape.obj").exists()
        assert not [n for n in os.listdir(folder) if n.startswith(".warpcloth-")]
    finally:
        subprocess.run(["umount", str(folder)], capture_output=True)


@pytest.mark.parametrize(
    ("old", "new", "words"),
    [
        ("point3f[] points = " + POINTS, 'string points = "abc"', "/World/Cloth: points must be numbers, got a str"),
        ("point3f[] points = " + POINTS, "float[] points = [0, 1, 2, 3]", "points must be 3-vectors, got an array"),
        ("int[] faceVertexCounts = [3, 3]", 'string faceVertexCounts = "x"', "faceVertexCounts must be integers"),
        ("timeCodesPerSecond = 60", "timeCodesPerSecond = 0", "timeCodesPerSecond is 0.0; it must be a positive"),
    ],
)
def test_attributes_of_the_wrong_type_are_one_line(tmp_path, capsys, old, new, words):
    path = usda(tmp_path / "cloth.usda")
    text = Path(path).read_text()
    assert old in text
    Path(path).write_text(text.replace(old, new))
    refused(capsys, path, "cloth.usda", words)


def test_prim_paths_are_checked_not_skipped(tmp_path, capsys):
    path = usda(tmp_path / "cloth.usda")
    for argv, words in [
        (["--cloth", "World"], "the cloth prim path must be an absolute USD path such as '/World/Cloth', got 'World'"),
        (["--colliders", "bad path!"], "the colliders prim path must be an absolute USD path"),
        (["--colliders", "/World/Nope"], "cloth.usda: no prim at '/World/Nope' (the colliders' scope)"),
        (["--cloth", "/World/Nope"], "cloth.usda: no mesh at '/World/Nope'"),
    ]:
        code = main(["check-intersections", path, *argv])
        err = capsys.readouterr().err
        assert code == 2 and err.count("\n") == 1 and err.startswith("warpcloth: error: "), (argv, err)
        assert words in err and "Warning" not in err, (argv, err)
    assert main(["check-intersections", path, "--colliders", "/World/Colliders"]) == 0  # present, empty
