# ruff: noqa
# One-off audit script of issues 26, 30 and 31 (2026-12-03, branch audit); outputs in bench/results/audit-26-30-31.txt.
import os
import pathlib
import subprocess
import sys
import textwrap

BIN = sys.argv[1]
W = pathlib.Path(os.environ.get("AUDIT_DIR", "/tmp/audit/bad"))  # holds cape.obj, FIFOs and the generated files
os.chdir(W)
WC = [f"{BIN}/warpcloth"]


def run(label, argv, timeout=40, expect_rc=2):
    try:
        p = subprocess.run(argv, capture_output=True, text=True, timeout=timeout, errors="replace")
    except subprocess.TimeoutExpired:
        print("HANG ", label, flush=True)
        return
    err = [l for l in p.stderr.splitlines() if l.strip() and "CUDA" not in l]
    ok = (
        p.returncode == expect_rc
        and len(err) == 1
        and "Traceback" not in p.stderr
        and len(err[0]) <= 300
        and err[0].startswith("warpcloth: error:")
    )
    print(
        "ok   " if ok else "FAIL ",
        label,
        f"rc={p.returncode} n={len(err)}:",
        (err[0][:220] if err else "") + ("" if ok else " | " + " | ".join(err[1:3])[:300]),
        flush=True,
    )


for name, target in (
    ("kmsg.obj", "/proc/kmsg"),
    ("kmsg.usda", "/proc/kmsg"),
    ("kmsg.toml", "/proc/kmsg"),
    ("environ.obj", "/proc/self/environ"),
    ("zero.obj", "/dev/zero"),
    ("notes.obj", "/sys/kernel/notes"),
    ("kmsg.xml", "/proc/kmsg"),
):
    if not os.path.lexists(name):
        os.symlink(target, name)
run("kmsg.obj -> /proc/kmsg as --mesh", WC + ["run", "mesh", "--mesh", "kmsg.obj", "--num-frames", "1"])
run("kmsg.usda -> /proc/kmsg as --mesh", WC + ["run", "mesh", "--mesh", "kmsg.usda", "--num-frames", "1"])
run(
    "kmsg.obj as --collider mesh:path",
    WC + ["run", "sheet", "--size", "8", "--num-frames", "1", "--collider", "mesh:path=kmsg.obj"],
)
run("kmsg.toml as a scenario file", WC + ["run", "kmsg.toml"])
run("kmsg.xml as a test list", WC + ["sweep", "kmsg.xml", "--out", "k.csv"])
run("environ.obj -> /proc/self/environ", WC + ["run", "mesh", "--mesh", "environ.obj", "--num-frames", "1"])
run("zero.obj -> /dev/zero", WC + ["run", "mesh", "--mesh", "zero.obj", "--num-frames", "1"])
run("notes.obj -> /sys/kernel/notes", WC + ["run", "mesh", "--mesh", "notes.obj", "--num-frames", "1"])
base = (
    (pathlib.Path(__file__).resolve().parents[2] / "tests" / "test_scenario_files.py")
    .read_text()
    .split('SCENARIO_TOML = """', 1)[1]
    .split('"""', 1)[0]
)
pathlib.Path("kmsgmesh.toml").write_text(base.replace('mesh = "cape.obj"', 'mesh = "kmsg.obj"'))
run("scenario file mesh = kmsg.obj", WC + ["run", "kmsgmesh.toml"])
mk = textwrap.dedent("""
from pxr import Sdf
layer = Sdf.Layer.CreateNew("kmsgsub.usda"); layer.subLayerPaths.append("./good.usda"); layer.subLayerPaths.append("/proc/kmsg")
w = Sdf.CreatePrimInLayer(layer, "/World"); w.specifier = Sdf.SpecifierDef; layer.Save()
layer = Sdf.Layer.CreateNew("kmsgref.usda"); layer.subLayerPaths.append("./good.usda")
w = Sdf.CreatePrimInLayer(layer, "/World"); w.specifier = Sdf.SpecifierDef; w.referenceList.Prepend(Sdf.Reference("./kmsg.usda")); layer.Save()
""")
for f in ("kmsgsub.usda", "kmsgref.usda"):
    if os.path.exists(f):
        os.remove(f)
subprocess.run([f"{BIN}/python", "-c", mk], check=True, timeout=30)
run("usd sublayer /proc/kmsg via --mesh", WC + ["run", "mesh", "--mesh", "kmsgsub.usda", "--num-frames", "1"])
run("usd reference kmsg.usda (symlink) via --mesh", WC + ["run", "mesh", "--mesh", "kmsgref.usda", "--num-frames", "1"])
# big USD sublayer: a 2 GB sparse layer
with open("big.usda", "wb") as f:
    f.truncate(2 * 1024**3)
mk2 = 'from pxr import Sdf\nl = Sdf.Layer.CreateNew("bigsub.usda"); l.subLayerPaths.append("./good.usda"); l.subLayerPaths.append("./big.usda")\nw = Sdf.CreatePrimInLayer(l, "/World"); w.specifier = Sdf.SpecifierDef; l.Save()'
if os.path.exists("bigsub.usda"):
    os.remove("bigsub.usda")
subprocess.run([f"{BIN}/python", "-c", mk2], check=True, timeout=30)
run("usd sublayer of 2 GB via --mesh", WC + ["run", "mesh", "--mesh", "bigsub.usda", "--num-frames", "1"], timeout=60)
