# ruff: noqa
# One-off audit script of issues 26, 30 and 31 (2026-12-03, branch audit); outputs in bench/results/audit-26-30-31.txt.
import subprocess
import sys

BIN = sys.argv[1]
cases = [
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
    "y > 1e400",
    "x ** 1e6 > 1",
    "-" * 3000 + "y > 0",
    "(" * 500 + "y > 0" + ")" * 500,
    "y > 0.95 * y.max()",
]
for pin in cases:
    p = subprocess.run(
        [f"{BIN}/warpcloth", "run", "mesh", "--num-frames", "1", "--pin", pin],
        capture_output=True,
        text=True,
        timeout=120,
    )
    err = [l for l in p.stderr.splitlines() if l.strip() and "CUDA" not in l]
    good = (
        (p.returncode == 2 and len(err) == 1 and err[0].startswith("warpcloth: error:") and len(err[0]) <= 300)
        if pin != "y > 0.95 * y.max()"
        else p.returncode == 0
    )
    print(
        "ok  " if good else "FAIL",
        repr(pin[:40]),
        f"rc={p.returncode} n={len(err)} len={len(err[0]) if err else 0}:",
        (err[0][:200] if err else p.stdout.splitlines()[0][:100]),
        flush=True,
    )
