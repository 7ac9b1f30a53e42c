"""Kernel compilation of a first run: ``warpcloth run sheet`` with an empty Warp kernel cache.

    python bench/cold_compile.py [--repeats 3] [-- extra warpcloth run flags]

Each repeat runs ``warpcloth run sheet --json`` (the main job's defaults) in a fresh process with
``WARP_CACHE_PATH`` set to a new empty folder, and once more on that now-filled cache, and
prints the run's ``compile_time`` (the warm-up step: kernel compilation and first launches) and
the whole process time; the summary gives medians with their range (min-max).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time


def _spread(values) -> str:
    return f"{statistics.median(values):.2f} [{min(values):.2f}-{max(values):.2f}]"


def run_once(cache: str, extra: list[str]) -> tuple[float, float]:
    env = {**os.environ, "WARP_CACHE_PATH": cache}
    t0 = time.perf_counter()
    out = subprocess.run(
        [sys.executable, "-m", "warpcloth.cli", "run", "sheet", "--json", *extra],
        env=env,
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    return json.loads(out)["compile_time"], time.perf_counter() - t0


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("extra", nargs="*", help="flags passed to 'warpcloth run sheet' (after --)")
    args = p.parse_args(argv)
    print(
        f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, {os.cpu_count()} CPU cores "
        f"({platform.processor() or platform.machine()}), warpcloth run sheet --json {' '.join(args.extra)}".rstrip()
    )
    print(f"{'repeat':>6} {'cache':>6} {'compile_time s':>15} {'process s':>10}")
    results = {"empty": ([], []), "filled": ([], [])}
    for i in range(args.repeats):
        with tempfile.TemporaryDirectory(prefix="warp-cache-") as cache:
            for state in results:
                compile_s, process_s = run_once(cache, args.extra)
                results[state][0].append(compile_s)
                results[state][1].append(process_s)
                print(f"{i + 1:>6} {state:>6} {compile_s:15.2f} {process_s:10.2f}", flush=True)
    print(f"\nmedian [min-max] over {args.repeats} repeats")
    for state, (compile_s, process_s) in results.items():
        print(f"{state:>6} cache: compile_time {_spread(compile_s)} s, process {_spread(process_s)} s")


if __name__ == "__main__":
    main()
