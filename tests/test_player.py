"""The HTML player (``run --html``): one self-contained file holding every frame and the run's
colliders (moving ones posed at every frame), and, where a Chromium is installed, a canvas that
a real browser draws and that changes over time, with the colliders drawn."""

import base64
import json
import os
import re
import shutil
import struct
import subprocess
import zlib

import numpy as np
import pytest

from warpcloth.cli import main
from warpcloth.io.frames import FrameSinks, nice_scale, strain_colors, vertex_strain
from warpcloth.io.player import PLANE_PATCH, HtmlWriter, quantise, read_player_data
from warpcloth.run.harness import RunHarness
from warpcloth.sim.colliders import Box, Capsule, ColliderTrack, MeshCollider, Plane, Sphere, quat_matrix


def _run(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture(scope="module")
def flag_page(tmp_path_factory):
    """A flag run of 30 frames (0.5 s at 60 fps), as a player page and its frames."""
    from warpcloth.scenarios import flag

    path = tmp_path_factory.mktemp("player") / "flag.html"
    sim = flag.build(rows=8, cols=12, integrator="rk4", dt=2e-3)
    writer = HtmlWriter(str(path), sim.model, 60.0, title="flag </script><b>test</b>")
    frames = []

    class Keep:
        def write_frame(self, points, sim_time=None):
            frames.append(np.array(points, dtype=np.float32))

        def close(self):
            return None

        def abort(self):
            pass

    sinks = FrameSinks([writer, Keep()])
    result = RunHarness(sim).run(0.5, fps=60.0, frames=sinks)
    sinks.close()
    return path, result, np.stack(frames), sim.model


def test_page_holds_every_frame_and_vertex(flag_page):
    path, result, frames, model = flag_page
    data = read_player_data(str(path))
    assert data["frameCount"] == result.frames + 1 == len(frames) == 31  # the first frame too
    assert data["vertexCount"] == model.particle_count == 96
    assert len(data["times"]) == data["frameCount"] and data["times"][0] == 0.0
    assert np.all(np.diff(data["times"]) > 0) and abs(data["times"][-1] - 0.5) < 2e-3
    assert data["fps"] == 60.0 and data["pins"] == [int(i) for i in model.pinned] and data["colliders"] == []
    # positions within half a quantisation step of the float32 frames
    step = (np.array(data["bboxMax"]) - np.array(data["bboxMin"])) / 65535
    assert np.all(np.abs(data["positions"] - frames) <= step / 2 + 1e-6)
    assert data["info"] == {}


def test_page_is_self_contained(flag_page):
    path = flag_page[0]
    page = path.read_text(encoding="utf-8")
    assert page.startswith("<!DOCTYPE html>")
    from html.parser import HTMLParser

    class Tags(HTMLParser):
        def __init__(self):
            super().__init__()
            self.tags, self.open = [], []

        def handle_starttag(self, tag, attrs):
            self.tags.append((tag, dict(attrs)))

    parser = Tags()
    parser.feed(page)
    parser.close()
    names = [t for t, _ in parser.tags]
    assert names.count("canvas") == 1 and names.count("script") == 2 and ("link" not in names) and ("img" not in names)
    assert all("src" not in attrs for tag, attrs in parser.tags if tag == "script")  # inline scripts only
    assert "http://" not in page and "https://" not in page
    assert not re.search(r"""(src|href)\s*=\s*["']?(//|[a-z]+:)""", page, re.I), "an external resource"
    assert not re.search(r"@import|url\(", page), "a stylesheet that fetches"
    # the title cannot close the data's script element, and is escaped in <title>
    assert page.count("</script>") == 2
    assert "<title>flag &lt;/script&gt;&lt;b&gt;test&lt;/b&gt;</title>" in page


def test_quantise_error_bound():
    rng = np.random.default_rng(1)
    f = rng.uniform(-3, 5, size=(4, 50, 3)).astype(np.float32)
    q, lo, hi = quantise(f)
    back = lo + q * ((hi - lo) / 65535)
    assert q.dtype == np.dtype("<u2") and np.abs(back - f).max() <= ((hi - lo) / 65535).max() / 2 + 1e-6
    q, lo, hi = quantise(np.zeros((2, 3, 3), np.float32))  # a flat box keeps a usable step
    assert np.all(hi > lo) and np.all(q == 0)


def test_vertex_strain_and_colours():
    pairs = np.array([[0, 1], [1, 2]])
    rest = np.array([1.0, 1.0])
    p = np.array([[0, 0, 0], [1.1, 0, 0], [1.6, 0, 0]], dtype=np.float32)  # +10 %, compressed
    s = vertex_strain(p, pairs, rest)
    assert np.allclose(s, [0.1, 0.1, 0.0], atol=1e-6)
    c = strain_colors(np.array([0.0, 0.2, 1.0]), 0.2)
    assert np.allclose(c[0], [0.10, 0.25, 0.85]) and np.allclose(c[1], [0.85, 0.12, 0.10]) and np.allclose(c[1], c[2])
    assert nice_scale(0.13) == 0.2 and nice_scale(0.021) == 0.025 and nice_scale(0.0) == 0.01


def test_cli_html_with_usd_and_checks_paths_first(capsys, tmp_path):
    html = tmp_path / "s.html"
    usd = tmp_path / "s.usda"
    code, out, err = _run(
        capsys,
        "run",
        "sheet",
        "--rows",
        "5",
        "--cols",
        "5",
        "--num-frames",
        "6",
        "--html",
        str(html),
        "--usd",
        str(usd),
    )
    assert code == 0, err
    assert f"wrote {html}" in out and f"wrote {usd}" in out
    data = read_player_data(str(html))
    assert data["frameCount"] == 7 and data["vertexCount"] == 25 and data["colliders"] == []  # a run without colliders
    assert data["info"]["scenario"] == "sheet" and data["info"]["command_line"].startswith("warpcloth run sheet")
    # a bad path is refused before the run, in one line, and nothing is written
    code, out, err = _run(capsys, "run", "sheet", "--num-frames", "2", "--html", str(tmp_path / "no" / "x.html"))
    assert code == 2 and err.startswith("warpcloth: error: HTML path") and err.count("\n") == 1 and out == ""
    code, out, err = _run(capsys, "run", "sheet", "--num-frames", "2", "--html", str(tmp_path / "x.txt"))
    assert code == 2 and ".html, .htm" in err
    code, out, err = _run(capsys, "run", "sheet", "--num-frames", "2", "--html", str(html), "--usd", str(html))
    assert code == 2
    assert sorted(os.listdir(tmp_path)) == ["s.html", "s.usda"]  # no temporaries left


# -- colliders ---------------------------------------------------------------------------------

#: A closed tetrahedron, wound outward.
TETRA_V = np.array([[-0.3, 0.0, -0.8], [0.3, 0.0, -0.8], [0.0, 0.5, -0.8], [0.0, 0.0, -1.1]])
TETRA_T = np.array([[0, 1, 2], [0, 3, 1], [1, 3, 2], [2, 3, 0]])
#: 45 degrees about y, (x, y, z, w).
QUAT_Y45 = (0.0, np.sin(np.pi / 8), 0.0, np.cos(np.pi / 8))


def static_colliders():
    return (
        Sphere(center=(0.1, 0.2, -0.3), radius=0.25, thickness=0.005, friction=0.4),
        Capsule(a=(-0.6, 0.1, 0.4), b=(0.2, 0.1, 0.6), radius=0.08),
        Box(center=(0.6, 0.2, 0.3), half_extents=(0.2, 0.1, 0.15), rotation=QUAT_Y45, friction=0.5),
        Plane(point=(0.0, -0.5, 0.0), normal=(0.0, 2.0, 0.5), thickness=0.01),
        MeshCollider(vertices=TETRA_V, triangles=TETRA_T, thickness=0.002),
    )


def moving_colliders():
    """Every kind that may move, on keyframes and on rigid motions that turn and slide."""
    return (
        Sphere(
            center=(0.0, 0.2, 0.0),
            radius=0.2,
            track=ColliderTrack.keyframes([0.0, 0.3], [[0, 0, 0], [0.4, 0.1, -0.2]], interpolation="catmull_rom"),
        ),
        Box(
            center=(0.6, 0.2, 0.3),
            half_extents=(0.2, 0.1, 0.15),
            rotation=QUAT_Y45,
            track=ColliderTrack.rigid(
                center=(0.5, 0.2, 0.1), axis=(0, 1, 0), angular_velocity=3.0, velocity=(0, 0, -0.2)
            ),
        ),
        Capsule(
            a=(-0.6, 0.1, 0.4),
            b=(0.2, 0.1, 0.6),
            radius=0.08,
            track=ColliderTrack.rigid(center=(0, 0.1, 0.5), axis=(1, 1, 0), swing_amplitude=0.6, swing_frequency=2.0),
        ),
        Plane(
            track=ColliderTrack.rigid(
                center=(0, 0, 0), axis=(0, 0, 1), swing_amplitude=0.3, swing_frequency=1.0, velocity=(0.3, 0, 0)
            )
        ),
    )


def _write(path, model, frames, times, colliders):
    writer = HtmlWriter(str(path), model, 60.0, colliders=colliders)
    for p, t in zip(frames, times):
        writer.write_frame(p, sim_time=t)
    writer.close()
    return read_player_data(str(path))


def test_static_colliders_in_the_page(flag_page, tmp_path):
    _, _, frames, model = flag_page
    colliders = static_colliders()
    data = _write(tmp_path / "static.html", model, frames[:5], [k / 60 for k in range(5)], colliders)
    recs = data["colliders"]
    assert [c["kind"] for c in recs] == ["sphere", "capsule", "box", "plane", "mesh"]
    assert all("motion" not in c for c in recs)  # nothing per frame for a static collider
    sphere, capsule, box, plane, mesh = recs
    assert (
        sphere["center"] == [0.1, 0.2, -0.3]
        and sphere["radius"] == 0.25
        and sphere["thickness"] == 0.005
        and sphere["friction"] == 0.4
    )
    assert capsule["a"] == [-0.6, 0.1, 0.4] and capsule["b"] == [0.2, 0.1, 0.6] and capsule["radius"] == 0.08
    assert box["center"] == [0.6, 0.2, 0.3] and box["halfExtents"] == [0.2, 0.1, 0.15] and box["friction"] == 0.5
    assert np.allclose(box["rotation"], QUAT_Y45, atol=1e-12)
    assert np.allclose(plane["normal"], np.array([0.0, 2.0, 0.5]) / np.hypot(2.0, 0.5)) and plane["point"] == [
        0.0,
        -0.5,
        0.0,
    ]
    diagonal = np.linalg.norm(np.array(data["bboxMax"]) - np.array(data["bboxMin"]))
    assert np.isclose(plane["halfSize"], 0.5 * PLANE_PATCH * diagonal)  # a patch around the cloth
    assert mesh["vertexCount"] == 4 and mesh["triangleCount"] == 4 and mesh["thickness"] == 0.002
    assert np.array_equal(mesh["triangleIndices"], TETRA_T)
    step = (np.array(mesh["verticesMax"]) - np.array(mesh["verticesMin"])) / 65535
    assert np.all(np.abs(mesh["vertexPositions"] - TETRA_V) <= step / 2 + 1e-9)  # uint16, as the frames


def _rotate(q, v):
    return quat_matrix(q) @ np.asarray(v, dtype=np.float64)


def test_moving_colliders_posed_at_every_frame(flag_page, tmp_path):
    _, _, frames, model = flag_page
    colliders = moving_colliders() + (Sphere(center=(0, 2, 0), radius=0.1),)
    times = [0.0, 0.01, 0.05, 0.12, 0.2, 0.31, 0.5, 0.9]  # uneven, past the keyframes' end
    bad = np.full_like(frames[0], np.nan)  # an unstable frame is not shown, nor are its poses
    data = _write(
        tmp_path / "moving.html",
        model,
        [frames[0], frames[1], bad, *frames[2:8]],
        [0.0, 0.01, 0.03, *times[2:]],
        colliders,
    )
    assert data["times"] == times and data["frameCount"] == 8
    recs = data["colliders"]
    assert "motion" not in recs[4]  # the static sphere among moving ones
    for c, rec in zip(colliders[:4], recs[:4]):
        m = rec["motion"]
        assert m["translations"].shape == (8, 3) and m["rotations"].shape == (8, 4)
        assert len(base64.b64decode(m["translation"])) == 8 * 3 * 2  # uint16 x y z a frame
        for k, t in enumerate(times):
            want = c.at(t)
            q, tr = m["rotations"][k], m["translations"][k]

            def pose(y):  # the stored pose applied to the collider as given
                return _rotate(q, y) + tr

            if c.kind == "sphere":
                assert np.allclose(pose(rec["center"]), want.center, atol=1e-4), (k, t)
            elif c.kind == "capsule":
                assert np.allclose(pose(rec["a"]), want.a, atol=1e-4) and np.allclose(
                    pose(rec["b"]), want.b, atol=1e-4
                ), (k, t)
            elif c.kind == "box":
                assert np.allclose(pose(rec["center"]), want.center, atol=1e-4), (k, t)
                rot = quat_matrix(q) @ quat_matrix(rec["rotation"])
                assert np.allclose(rot, quat_matrix(want.rotation), atol=1e-4), (k, t)
            else:
                assert np.allclose(pose(rec["point"]), want.point, atol=1e-4), (k, t)
                assert np.allclose(_rotate(q, rec["normal"]), want.normal, atol=1e-4), (k, t)
    # the keyframed sphere only translates: no rotation stored (6 bytes a frame); the others turn
    assert "rotation" not in recs[0]["motion"] and all("rotation" in r["motion"] for r in recs[1:4])
    assert np.allclose(recs[0]["motion"]["translations"][-1], [0.4, 0.1, -0.2], atol=1e-6)  # held after the last key


def test_cli_run_shows_the_scenarios_and_the_command_lines_colliders(capsys, tmp_path):
    html = tmp_path / "t.html"
    code, _out, err = _run(
        capsys,
        "run",
        "tablecloth",
        "--rows",
        "5",
        "--cols",
        "5",
        "--num-frames",
        "3",
        "--html",
        str(html),
        "--collider",
        "sphere:center=0/1/0,radius=0.3",
    )
    assert code == 0, err
    recs = read_player_data(str(html))["colliders"]
    assert [c["kind"] for c in recs] == ["box", "plane", "sphere"]
    assert (
        recs[0]["center"] == [0.0, 0.375, 0.0]
        and recs[0]["halfExtents"] == [0.4, 0.375, 0.4]
        and recs[0]["rotation"] == [0, 0, 0, 1]
    )
    assert recs[1]["normal"] == [0.0, 1.0, 0.0] and recs[2]["center"] == [0.0, 1.0, 0.0] and recs[2]["radius"] == 0.3
    assert all("motion" not in c for c in recs)


# -- in a real browser ------------------------------------------------------------------------


def _chromium():
    for name in ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable"):
        path = shutil.which(name)
        if path:
            return path
    return None


def read_png(path) -> np.ndarray:
    """A non-interlaced 8-bit RGB/RGBA PNG (what Chromium writes) as an (H, W, C) uint8 array."""
    raw = open(path, "rb").read()
    assert raw[:8] == b"\x89PNG\r\n\x1a\n"
    pos, idat, header = 8, b"", None
    while pos < len(raw):
        n, kind = struct.unpack(">I4s", raw[pos : pos + 8])
        body = raw[pos + 8 : pos + 8 + n]
        if kind == b"IHDR":
            header = struct.unpack(">IIBBBBB", body)
        elif kind == b"IDAT":
            idat += body
        pos += 12 + n
    w, h, depth, ctype, _, _, interlace = header
    assert depth == 8 and interlace == 0 and ctype in (2, 6)
    c = 3 if ctype == 2 else 4
    data = zlib.decompress(idat)
    out = np.zeros((h, w * c), dtype=np.int32)
    prev = np.zeros(w * c, dtype=np.int32)
    stride = w * c + 1
    for y in range(h):
        f, line = data[y * stride], np.frombuffer(data, np.uint8, w * c, y * stride + 1).astype(np.int32)
        cur = line.copy()
        if f == 1:
            for x in range(c, w * c):
                cur[x] = (cur[x] + cur[x - c]) & 255
        elif f == 2:
            cur = (line + prev) & 255
        elif f == 3:
            for x in range(w * c):
                left = cur[x - c] if x >= c else 0
                cur[x] = (line[x] + ((left + prev[x]) >> 1)) & 255
        elif f == 4:
            for x in range(w * c):
                a = cur[x - c] if x >= c else 0
                b = prev[x]
                cc = prev[x - c] if x >= c else 0
                pa, pb, pc = abs(b - cc), abs(a - cc), abs(a + b - 2 * cc)
                pred = a if pa <= pb and pa <= pc else (b if pb <= pc else cc)
                cur[x] = (line[x] + pred) & 255
        out[y] = cur
        prev = cur
    return out.reshape(h, w, c)[:, :, :3].astype(np.uint8)


CHROMIUM_FLAGS = [
    "--headless=new",
    "--no-sandbox",
    "--disable-gpu",
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
    "--hide-scrollbars",
    "--window-size=640,480",
    "--virtual-time-budget=4000",
]


def _chromium_run(browser, args, tmp_path, tag):
    p = subprocess.run(
        [browser, *CHROMIUM_FLAGS, f"--user-data-dir={tmp_path / ('profile-' + tag)}", *args],
        capture_output=True,
        text=True,
        timeout=180,
    )
    return p.stdout, p.stderr[-600:]


def _dom(browser, url, tmp_path, tries=3):
    """The DOM after the page ran (one retry: a headless browser on a loaded machine may stop early)."""
    for k in range(tries):
        dom, err = _chromium_run(browser, ["--dump-dom", url], tmp_path, f"dom{k}")
        if "data-frame=" in dom:
            break
    return dom, err


def _screenshot(browser, url, out, tmp_path, ok=lambda img: True, tries=2):
    """A screenshot as an array; taken again once if ``ok`` says it is not what a drawn page shows."""
    img, err = None, ""
    for k in range(tries):
        if os.path.exists(out):
            os.unlink(out)
        _, err = _chromium_run(browser, [f"--screenshot={out}", url], tmp_path, f"{os.path.basename(out)}{k}")
        if os.path.exists(out):
            img = read_png(out)
            if ok(img):
                break
    assert img is not None, f"Chromium wrote no screenshot: {err}"
    return img


@pytest.mark.skipif(_chromium() is None, reason="no Chromium installed (apt-get install chromium)")
def test_chromium_draws_the_canvas_and_it_moves(flag_page, tmp_path):
    browser = _chromium()
    url = flag_page[0].resolve().as_uri()
    dom, err = _dom(browser, url + "#t=0.25", tmp_path)
    assert 'data-frame="15"' in dom and "data-error" not in dom, (dom[-400:], err)

    def view(img):  # the canvas between the labels and the bar
        return img[60 : img.shape[0] - 60].astype(int)

    def cloth(img):  # the cloth's warm beige, not the blue-grey background, floor grid or labels
        v = view(img)
        return (v[:, :, 0] - v[:, :, 2]) > 12

    def drawn(img):
        return cloth(img).mean() > 0.02

    first = _screenshot(browser, url + "#t=0", tmp_path / "t0.png", tmp_path, drawn)
    last = _screenshot(browser, url + "#t=0.5", tmp_path / "t1.png", tmp_path, drawn)
    strain = _screenshot(browser, url + "#t=0.5&strain=1", tmp_path / "t2.png", tmp_path, lambda img: not drawn(img))
    for img in (first, last):
        assert drawn(img), f"the cloth is not drawn ({100 * cloth(img).mean():.2f} % of the canvas)"
    changed = np.abs(view(first) - view(last)).sum(axis=2) > 30
    assert changed.mean() > 0.01, "the picture did not change between t=0 and t=0.5"
    v = view(strain)
    blue = (v[:, :, 2] - v[:, :, 0]) > 60  # the ramp's blue end (low strain) where the cloth was beige
    assert (blue & cloth(last)).sum() > 0.5 * cloth(last).sum(), "strain colours not shown"


@pytest.mark.skipif(_chromium() is None, reason="no Chromium installed (apt-get install chromium)")
def test_chromium_draws_the_colliders_where_their_poses_put_them(flag_page, tmp_path):
    """Every kind, moving and static, drawn without a script error; the page poses each collider
    at the frame shown as collider.at(t) does, and hiding them (#colliders=0) takes grey away."""
    _, _, frames, model = flag_page
    colliders = moving_colliders() + (
        MeshCollider(vertices=TETRA_V, triangles=TETRA_T),
        Sphere(center=(-0.4, 0.3, 0.0), radius=0.15),
    )
    times = [k / 60 for k in range(20)]
    _write(tmp_path / "c.html", model, frames[:20], times, colliders)
    browser = _chromium()
    url = (tmp_path / "c.html").resolve().as_uri()
    for k in (0, 19):
        dom, err = _dom(browser, url + f"#t={times[k]}", tmp_path)
        assert f'data-frame="{k}"' in dom and "data-error" not in dom and 'data-colliders="6"' in dom, (dom[-600:], err)
        points = json.loads(re.search(r'data-collider-points="([^"]*)"', dom).group(1).replace("&quot;", '"'))
        for c, got in zip(colliders, points):
            want = c.at(times[k])
            expect = {
                "sphere": lambda: [want.center],
                "capsule": lambda: [want.a, want.b],
                "box": lambda: [want.center, np.asarray(want.center) + _rotate(want.rotation, want.half_extents)],
                "plane": lambda: [want.point, np.add(want.point, want.normal)],
                "mesh": lambda: [TETRA_V[0]],
            }[c.kind]()
            assert np.allclose(got, expect, atol=2e-4), (c.kind, k, got, expect)

    def grey(img):  # the colliders' neutral grey (and the plane's grid), not the background or the cloth
        v = img[60 : img.shape[0] - 60].astype(int)
        r, g, b = v[:, :, 0], v[:, :, 1], v[:, :, 2]
        return (r > 55) & (b >= r - 2) & (b - r < 30) & (np.abs(g - r) < 14)

    shown = _screenshot(browser, url + "#t=0.3", tmp_path / "c1.png", tmp_path, lambda img: grey(img).mean() > 0.05)
    hidden = _screenshot(
        browser, url + "#t=0.3&colliders=0", tmp_path / "c0.png", tmp_path, lambda img: grey(img).mean() < 0.05
    )
    assert grey(shown).mean() > 0.05 and grey(shown).mean() > grey(hidden).mean() + 0.05, (
        grey(shown).mean(),
        grey(hidden).mean(),
    )


def test_too_many_frames_refused_before_the_run(capsys, tmp_path):
    # 512 x 512 particles x 60 fps x 200 s = 12,001 frames x 3 MiB: far past the 2 GiB the player may hold
    code, out, err = _run(
        capsys,
        "run",
        "flag",
        "--rows",
        "512",
        "--cols",
        "512",
        "--duration",
        "200",
        "--dt",
        "1e-3",
        "--html",
        str(tmp_path / "big.html"),
    )
    assert code == 2 and "would hold 12001 frames" in err and err.count("\n") == 1 and out == ""
    assert os.listdir(tmp_path) == []


def _camera_in_node(page, lo, hi, yaw, pitch, w, h, b) -> tuple[float, np.ndarray]:
    """The page's own camera math (between its markers) run in Node: the fitted distance and the
    view-projection matrix (column-major, as WebGL takes it) for a window w x h whose control bar
    covers the share b of its height."""
    text = page.read_text()
    math = text.split("// -- camera math", 1)[1].split("// -- end of camera math --", 1)[0]
    c = [(a + z) / 2 for a, z in zip(lo, hi)]
    radius = max(0.05, 0.5 * float(np.linalg.norm(np.subtract(hi, lo))))
    script = (
        "\n".join(math.splitlines()[1:])
        + f"\nconst lo = {list(lo)}, hi = {list(hi)}, c = {c};"
        + f"\nconst d = fitDistance(lo, hi, c, {yaw}, {pitch}, {w}, {h}, {b});"
        + f"\nconst P = viewProjection(c, {radius}, {yaw}, {pitch}, d, {w}, {h}, {b});"
        + "\nconsole.log(JSON.stringify({d: d, mvp: Array.from(P.mvp)}));"
    )
    done = subprocess.run(["node", "-e", script], capture_output=True, text=True, timeout=60, check=True)
    out = json.loads(done.stdout)
    return out["d"], np.array(out["mvp"], dtype=np.float64).reshape(4, 4)  # [column, row]


@pytest.mark.skipif(shutil.which("node") is None, reason="no Node.js installed")
def test_the_camera_frames_every_frame_above_the_control_bar_and_the_strain_scale_is_fixed(tmp_path, flag_page):
    """A cloth that starts hanging high and ends lying low and far to one side (as the fold does):
    every vertex of every frame projects inside the window and above the control bar, for wide,
    tall and very wide windows (the camera framed around the first frame: the fold ended in the
    bottom third, its pins behind the bar). The strain legend's end is the fixed 10 % of the USD
    colours on every page (it was each run's own 99th percentile)."""
    from warpcloth.io.usd import DEFAULT_STRAIN_SCALE
    from warpcloth.scenarios import sheet

    model = sheet.build(rows=6, cols=6).model
    rest = model.host.q.astype(np.float32)
    page = tmp_path / "fall.html"
    writer = HtmlWriter(str(page), model, 60.0)
    for k in range(20):
        s = k / 19.0
        p = rest.copy()
        lying = np.stack([p[:, 0], np.zeros(len(p), np.float32), p[:, 1] - rest[:, 1].min()], axis=1)
        p = (1 - s) * p + s * (lying + np.array([1.5, 0.02, 0.8], np.float32))
        writer.write_frame(p.astype(np.float32), k / 60.0)
    writer.close()
    data = read_player_data(str(page))
    positions = data["positions"].reshape(-1, 3).astype(np.float64)
    homogeneous = np.hstack([positions, np.ones((len(positions), 1))])
    yaw, pitch = data["view"]["yaw"], data["view"]["pitch"]
    for w, h, bar in ((1280, 720, 44), (700, 1000, 44), (1800, 400, 60)):
        b = bar / h
        d, mvp = _camera_in_node(page, data["bboxMin"], data["bboxMax"], yaw, pitch, w, h, b)
        clip = homogeneous @ mvp  # row vector times the column-major matrix's transpose
        assert np.all(clip[:, 3] > 0), (w, h)  # every vertex in front of the eye
        x, y = clip[:, 0] / clip[:, 3], clip[:, 1] / clip[:, 3]
        assert np.all(np.abs(x) <= 1.0) and np.all(y <= 1.0) and np.all(y >= -1.0 + 2.0 * b), (w, h, x, y)
        # and framed, not merely far away: the box fills most of the view one way or the other
        assert max(np.abs(x).max(), (np.abs(y - b) / (1.0 - b)).max()) > 0.6, (w, h, d)
    assert data["strainScale"] == DEFAULT_STRAIN_SCALE == 0.1
    flag = read_player_data(str(flag_page[0]))
    assert flag["strainScale"] == data["strainScale"] and flag["maxStrain"] != data["maxStrain"]
