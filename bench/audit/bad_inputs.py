# ruff: noqa
# One-off audit script of issues 26, 30 and 31 (2026-12-03, branch audit); outputs in bench/results/audit-26-30-31.txt.
"""Issue 31's bad-input list (and a few of my own), run as a user runs them: the CLI in a subprocess
(timeout 60 s), API calls in a fresh interpreter. A case passes when it exits within the timeout with
exactly one stderr line 'warpcloth: error: ...' (CUDA driver warning aside), no Traceback, no NumPy
warning, the line <= 300 chars; 'ok' cases must exit 0 and are checked for what they should do."""

import json
import os
import pathlib
import subprocess
import sys
import textwrap
import time

BIN = sys.argv[1]  # venv bin
W = pathlib.Path(os.environ.get("AUDIT_DIR", "/tmp/audit/bad"))  # holds cape.obj, FIFOs and the generated files
os.chdir(W)
WC = [f"{BIN}/warpcloth"]
PY = f"{BIN}/python"
BASE = (
    (pathlib.Path(__file__).resolve().parents[2] / "tests" / "test_scenario_files.py")
    .read_text()
    .split('SCENARIO_TOML = """', 1)[1]
    .split('"""', 1)[0]
)
results = []


def toml(name, text):
    (W / name).write_text(text)
    return name


def variant(name, *changes):
    t = BASE
    for a, b in changes:
        assert a in t, a
        t = t.replace(a, b, 1)
    return toml(name, t)


def run(label, argv, expect="error", timeout=60, shell=False, check=None, stdin=None):
    t0 = time.time()
    try:
        p = subprocess.run(
            argv, capture_output=True, text=True, timeout=timeout, shell=shell, errors="replace", stdin=stdin
        )
    except subprocess.TimeoutExpired:
        results.append((label, "HANG", f">{timeout}s"))
        print(f"HANG  {label}", flush=True)
        return
    wall = time.time() - t0
    err = [l for l in p.stderr.splitlines() if l.strip() and "CUDA" not in l]
    tb = "Traceback" in p.stderr
    npw = "RuntimeWarning" in p.stderr or "numpy" in p.stderr.lower() and "warning" in p.stderr.lower()
    if expect == "error":
        ok = (
            p.returncode != 0
            and len(err) == 1
            and err[0].startswith("warpcloth: error:")
            and not tb
            and not npw
            and len(err[0]) <= 300
        )
        detail = f"rc={p.returncode} lines={len(err)} len={len(err[0]) if err else 0}: {err[0][:230] if err else p.stdout[-200:]!r}"
        if not ok and err:
            detail += " || " + " | ".join(err[1:4])[:300]
    else:
        ok = p.returncode == 0 and not tb and not npw
        detail = f"rc={p.returncode}"
        if check:
            good, why = check(p)
            ok = ok and good
            detail += " " + why
        if not ok:
            detail += " stderr: " + " | ".join(err)[:300]
    results.append((label, "ok" if ok else "FAIL", detail))
    print(f"{'ok  ' if ok else 'FAIL'}  {label} ({wall:.1f}s): {detail}", flush=True)


def dt_of(p):
    try:
        return json.loads(p.stdout.strip().splitlines()[-1])["dt"]
    except Exception as e:
        return f"? {e}"


if not os.environ.get("SKIP"):
    # -- silent wrong results
    a = variant("soft.toml", ("mass = 0.25", "mass = 0.25\nstiffness = 1"))
    b = variant("stiff.toml", ("mass = 0.25", "mass = 0.25\nstiffness = 1000000"))
    outs = {}
    for f in (a, b):
        p = subprocess.run(
            WC + ["run", f, "--integrator", "explicit_euler", "--duration", "0.01", "--json"],
            capture_output=True,
            text=True,
            timeout=120,
        )
        outs[f] = dt_of(p)
    ok = isinstance(outs[a], float) and isinstance(outs[b], float) and outs[a] != outs[b]
    results.append(("file stiffness 1 vs 1e6 change the run (dt)", "ok" if ok else "FAIL", str(outs)))
    print(results[-1], flush=True)
    run("file [run] device = cuda:7", WC + ["run", variant("cuda7.toml", ("[run]", '[run]\ndevice = "cuda:7"'))])
    run('file quads = "no"', WC + ["run", variant("q.toml", ("quads = true", 'quads = "no"'))])
    run('file bend = "false"', WC + ["run", variant("bd.toml", ("quads = true", 'quads = true\nbend = "false"'))])
    run(
        'file stop_at_equilibrium = "false"',
        WC + ["run", variant("se.toml", ("name =", 'stop_at_equilibrium = "false"\nname ='))],
    )
    run("file pins indices = [1.5]", WC + ["run", variant("pi.toml", ("[pins]", "[pins]\nindices = [1.5]"))])
    run("file wind = [nan,0,0]", WC + ["run", variant("wn.toml", ("wind = [2, 0, 1]", "wind = [nan, 0, 0]"))])
    run("file name = { a = 1 }", WC + ["run", variant("nm.toml", ('name = "windy-cape"', "name = { a = 1 }"))])
    run("file unknown key", WC + ["run", variant("uk.toml", ("mass = 0.25", "mass = 0.25\nstifness = 3"))])
    run("file unknown table", WC + ["run", variant("ut.toml", ("[run]", "[extra]\na = 1\n[run]"))])
    for pin in (
        "1",
        "x",
        "y + 0.5",
        "y.max()",
        "0.5",
        "1e30",
        "10 ** 400 > y",
        "1 / 0 < y",
        " + ".join(["y"] * 5000) + " > 0",
        "9" * 100000 + " < y",
        "__import__('os').system('id') or y > 0",
        "y > 0.5 and",
        "(y > 0.5) * 2",
    ):
        run(f"--pin {pin[:40]!r}", WC + ["run", "sheet", "--size", "8", "--num-frames", "1", "--pin", pin])
    # usd scale 1e30
    mk = textwrap.dedent("""
    from pxr import Usd, UsdGeom, Gf, Sdf
    import sys
    s = Usd.Stage.CreateNew(sys.argv[1]); x = UsdGeom.Xform.Define(s, "/World"); x.AddScaleOp().Set(Gf.Vec3f(1e30,1e30,1e30))
    m = UsdGeom.Mesh.Define(s, "/World/Cloth"); m.CreatePointsAttr([(0,0,0),(1,0,0),(1,1,0),(0,1,0)]); m.CreateFaceVertexCountsAttr([3,3]); m.CreateFaceVertexIndicesAttr([0,1,2,0,2,3]); s.GetRootLayer().Save()
    """)
    subprocess.run([PY, "-c", mk, "scale.usda"], check=True)
    run(
        "usd mesh under xform scale 1e30",
        WC + ["run", "mesh", "--mesh", "scale.usda", "--pin", "y > 0.9 * y.max()", "--num-frames", "1"],
    )
    run("--collider ''", WC + ["run", "sheet", "--size", "8", "--num-frames", "1", "--collider", ""])
    run("--html ''", WC + ["run", "sheet", "--size", "8", "--num-frames", "1", "--html", ""])
    run("--usd ''", WC + ["run", "sheet", "--size", "8", "--num-frames", "1", "--usd", ""])
# -- hangs
if not os.path.exists("pipe.usda"):
    os.mkfifo("pipe.usda")
if not os.path.exists("pipe.obj"):
    os.mkfifo("pipe.obj")
mk2 = textwrap.dedent("""
from pxr import Sdf, Usd, UsdGeom
import sys, os
how = sys.argv[1]
if not os.path.exists("good.usda"):
    st = Usd.Stage.CreateNew("good.usda"); m = UsdGeom.Mesh.Define(st, "/World/Cloth")
    m.CreatePointsAttr([(0, 0, 0), (1, 0, 0), (0, 1, 0), (1, 1, 0)]); m.CreateFaceVertexCountsAttr([4]); m.CreateFaceVertexIndicesAttr([0, 1, 3, 2]); st.GetRootLayer().Save()
layer = Sdf.Layer.CreateNew(how + ".usda"); layer.subLayerPaths.append("./good.usda")
w = Sdf.CreatePrimInLayer(layer, "/World"); w.specifier = Sdf.SpecifierDef
if how == "sublayer": layer.subLayerPaths.append("./pipe.usda")
elif how == "reference": w.referenceList.Prepend(Sdf.Reference("./pipe.usda"))
elif how == "payload": w.payloadList.Prepend(Sdf.Payload("./pipe.usda"))
else: w.SetInfo("clips", {"default": {"assetPaths": Sdf.AssetPathArray(["./pipe.usda"]), "primPath": "/World"}})
layer.Save()
""")
for how in ("sublayer", "reference", "payload", "clip"):
    subprocess.run([PY, "-c", mk2, how], check=True, timeout=30)
    run(f"usd {how} FIFO via --mesh", WC + ["run", "mesh", "--mesh", f"{how}.usda", "--num-frames", "1"], timeout=40)
    t = variant(
        f"fifo_{how}.toml",
        ('mesh = "cape.obj"', f'mesh = "{how}.usda"'),
        ("[pins]\n", "[pins]\nindices = [0]\n"),
        ('groups = ["shoulders"]', "indices = [1]"),
    )
    run(f"usd {how} FIFO via scenario file", WC + ["run", t], timeout=40)
    run(
        f"usd {how} FIFO via --collider mesh:path=",
        WC + ["run", "sheet", "--size", "8", "--num-frames", "1", "--collider", f"mesh:path={how}.usda"],
        timeout=40,
    )
run("FIFO as --mesh obj", WC + ["run", "mesh", "--mesh", "pipe.obj", "--num-frames", "1"], timeout=40)
for special in ("/proc/kmsg", "/proc/self/environ", "/dev/zero", "/sys/kernel/notes"):
    run(f"{special} as --mesh", WC + ["run", "mesh", "--mesh", special, "--num-frames", "1"], timeout=40)
    run(
        f"{special} as --collider mesh:path",
        WC + ["run", "sheet", "--size", "8", "--num-frames", "1", "--collider", f"mesh:path={special}"],
        timeout=40,
    )
    run(f"{special} as a scenario file", WC + ["run", special], timeout=40)
    t = variant("special.toml", ('mesh = "cape.obj"', f'mesh = "{special}"'))
    run(f"{special} as a scenario file's mesh", WC + ["run", t], timeout=40)
    run(f"{special} as a test list", WC + ["sweep", special, "--out", "x.csv"], timeout=40)
run("bench --seconds 1e40", WC + ["bench", "--sizes", "8", "--seconds", "1e40"], timeout=60)
run("bench --seconds inf", WC + ["bench", "--sizes", "8", "--seconds", "inf"], timeout=60)
run("bench --seconds nan", WC + ["bench", "--sizes", "8", "--seconds", "nan"], timeout=60)
run("bench --steps 1e40", WC + ["bench", "--sizes", "8", "--steps", "1e40"], timeout=60)
# -- tracebacks
(W / "deep.toml").write_bytes(b"a = " + b"[" * 2000 + b"]" * 2000)
run("TOML nested 2000 deep", WC + ["run", "deep.toml"])
(W / "deep2.toml").write_bytes(b"a = " + b"{ b = " * 2000 + b"1" + b" }" * 2000)
run("TOML inline tables 2000 deep", WC + ["run", "deep2.toml"])
(W / "utf.toml").write_bytes(b'name = "caf\xe9"\n')
run("TOML invalid UTF-8", WC + ["run", "utf.toml"])
(W / "dotted.toml").write_bytes(b"".join(b"k%d.a.b.c = 1\n" % i for i in range(60000)))
run(f"TOML {os.path.getsize(W / 'dotted.toml') / 1e6:.1f} MB of dotted keys", WC + ["run", "dotted.toml"])
with open(W / "big.toml", "wb") as f:
    f.truncate(2 * 1024**3)
run("TOML 2 GB (sparse) file", WC + ["run", "big.toml"])
with open(W / "big.obj", "wb") as f:
    f.truncate(2 * 1024**3)
run("OBJ 2 GB (sparse) file", WC + ["run", "mesh", "--mesh", "big.obj"])
run("file pins indices wrong type (string)", WC + ["run", variant("pit.toml", ("[pins]", '[pins]\nindices = "0"'))])
run(
    "file wind_coefficient wrong type",
    WC + ["run", variant("wc.toml", ("wind = [2, 0, 1]", "wind = [2, 0, 1]\nwind_coefficient = [1]"))],
)
run(
    "file collider track angular_velocity wrong type",
    WC
    + [
        "run",
        variant(
            "av.toml",
            (
                "[run]",
                '[[colliders]]\nkind = "sphere"\nradius = 0.2\ntrack = { kind = "rigid", angular_velocity = [1, "a"] }\n[run]',
            ),
        ),
    ],
)
run("file prim = 5", WC + ["run", variant("pr.toml", ("quads = true", "quads = true\nprim = 5"))])
run(
    "file integrator_options = 'abc'",
    WC + ["run", variant("io.toml", ("integrator_options = { iterations = 8 }", 'integrator_options = "abc"'))],
)
run(
    "file integrator_options unknown option",
    WC
    + [
        "run",
        variant("io2.toml", ("integrator_options = { iterations = 8 }", "integrator_options = { itrations = 8 }")),
    ],
)
(W / "enc.xml").write_text(
    '<?xml version="1.0" encoding="klingon"?>\n<test_list><test integrator="rk4"/></test_list>\n'
)
run("XML unknown encoding", WC + ["sweep", "enc.xml", "--out", "enc.csv"])
run("list >&- (closed stdout)", f"{BIN}/warpcloth list >&-", shell=True, expect="any")
# 10-million-triangle OBJ: generated as a file of 10M 'f' lines over a few vertices? a memory estimate must refuse it up front
# (a 10M-triangle OBJ is ~150 MB: make it once)
if not (W / "huge.obj").exists():
    with open(W / "huge.obj", "w") as f:
        n = 2237  # 2237^2 vertices ~ 5M, ~10M triangles
        f.write("".join(f"v {i} {j} 0\n" for i in range(0, 1) for j in range(0)))

        for i in range(n):
            f.write("".join(f"v {i} {j} 0\n" for j in range(n)))
        for i in range(n - 1):
            base = i * n
            f.write(
                "".join(
                    f"f {base + j + 1} {base + j + 2} {base + n + j + 2}\nf {base + j + 1} {base + n + j + 2} {base + n + j + 1}\n"
                    for j in range(n - 1)
                )
            )
print("huge.obj", os.path.getsize(W / "huge.obj") / 1e6, "MB", flush=True)
run("10M-triangle OBJ", WC + ["run", "mesh", "--mesh", "huge.obj", "--num-frames", "1"], timeout=300)
# API calls
for label, code in (
    (
        "API integrator_options='abc'",
        "from warpcloth.scenarios import sheet; sheet.build(integrator='xpbd', integrator_options='abc')",
    ),
    (
        "API usd_path=123",
        "from warpcloth.scenarios import get_scenario; get_scenario('sheet').run(usd_path=123, duration=0.01)",
    ),
    (
        "API WindSchedule.gusts('abc', ...)",
        "from warpcloth import WindSchedule; WindSchedule.gusts('abc', [1,0,0], [0, 1])",
    ),
):
    p = subprocess.run(
        [
            PY,
            "-c",
            f"import warpcloth\ntry:\n    {code}\nexcept warpcloth.WarpclothError as e:\n    print('WarpclothError:', e)\n",
        ],
        capture_output=True,
        text=True,
        timeout=60,
    )
    good = p.stdout.startswith("WarpclothError:") and "Traceback" not in p.stderr
    results.append((label, "ok" if good else "FAIL", (p.stdout.strip() or p.stderr.strip().splitlines()[-1])[:200]))
    print(results[-1], flush=True)
# -- messages
run(
    "--collider sphere:radius=1e+3 accepted",
    WC + ["run", "sheet", "--size", "8", "--num-frames", "1", "--collider", "sphere:center=0/-5/0,radius=1e+3"],
    expect="ok",
    check=lambda p: ("collider" in p.stdout.lower() or True, ""),
)
import shutil

shutil.copy("cape.obj", "a+b.obj")
run(
    "--collider mesh path with '+'",
    WC + ["run", "sheet", "--size", "8", "--num-frames", "1", "--collider", "mesh:path=a+b.obj"],
    expect="ok",
)
run(
    "--collider duplicate keys",
    WC + ["run", "sheet", "--size", "8", "--num-frames", "1", "--collider", "sphere:radius=0.1,radius=0.2"],
)
run(
    "--collider exponent in center",
    WC + ["run", "sheet", "--size", "8", "--num-frames", "1", "--collider", "sphere:center=0/-5e+0/0,radius=1e-1"],
    expect="ok",
)
run("100,000-digit literal in --stiffness", WC + ["run", "sheet", "--size", "8", "--stiffness", "9" * 100000])
run("100,000-digit --size", WC + ["run", "sheet", "--size", "9" * 100000])
run(
    "study --sizes 8 99999 (refused before any run)",
    WC + ["study", "--profile", "quick", "--integrators", "xpbd", "--sizes", "8", "99999", "--out", "st"],
    timeout=60,
)
for label, r in results:
    pass
print("\nSUMMARY:", sum(1 for r in results if r[1] == "ok"), "ok of", len(results))
for r in results:
    if r[1] != "ok":
        print("  ", r)
