#!/usr/bin/env bash
# One GPU session, in order of value, each step under its own timeout, everything under $OUT:
#   0. the machine: nvidia-smi, Warp's CUDA devices, driver and toolkit as warp.init() prints them
#      (no CUDA device: every step below is skipped, said in summary.txt, exit 2);
#   1. tests: the CUDA tests, pytest -k cuda tests (every outcome listed, JUnit XML beside the log);
#   2. bench: bench/devices.py on cuda at 32, 128, 512 (with the roofline; graph on and off);
#   3. study: the gpu study profile on cuda (resumable: a rerun continues where a timeout stopped it;
#      its estimate, from the H200's recorded costs, is <= 8 min with compilation: docs/gpu.md);
#   4. bench1024: bench/devices.py on cuda at 1024 (last: the least known; it did not finish in 140 s
#      on the H200 before its windows were bounded).
# Run from the project root on the GPU machine:
#   OUT=/path/to/out bash bench/gpu_session.sh
#   OUT=/path/to/out STEPS="tests bench" bash bench/gpu_session.sh    # a subset, in the order above
# A device call is at most 10 minutes: run "tests bench" in one call and "study bench1024" in the next
# while the machine is warm (the kernel cache is kept). Python: the project root first on the path (the
# checkout's warpcloth everywhere), then warp-lang from $HOME/wc-site when the unbundled wheels are
# there (the machine has no network; a last part found under .gpu/ is unbundled first), else the
# $PYTHON (default python3) that already imports warp. Per-step limits [s], overridable:
#   T_TESTS (120), T_BENCH (120), T_STUDY (480), T_BENCH_1024 (90): 13.5 min at most, about 11 expected.
# A step that fails or times out is recorded and the next one runs.
set -uo pipefail
OUT=${OUT:-gpu-session-out}
STEPS=${STEPS:-tests bench study bench1024}
T_TESTS=${T_TESTS:-120}
T_BENCH=${T_BENCH:-120}
T_STUDY=${T_STUDY:-480}
T_BENCH_1024=${T_BENCH_1024:-90}
PY=${PYTHON:-python3}
mkdir -p "$OUT"
export PYTHONUNBUFFERED=1
SUMMARY="$OUT/summary.txt"
: > "$SUMMARY"

# -- the Python that runs it ----------------------------------------------------------------
if [ ! -d "$HOME/wc-site/warp" ]; then
    last=$(ls .gpu/*/unbundle.sh 2>/dev/null | tail -1)
    if [ -n "$last" ]; then
        echo "unbundling the wheels ($last) into \$HOME/wc-site" | tee -a "$SUMMARY"
        bash "$last" > "$OUT/unbundle.log" 2>&1 || echo "unbundle failed (see unbundle.log)" | tee -a "$SUMMARY"
    fi
fi
site=""
[ -d "$HOME/wc-site/warp" ] && site=":$HOME/wc-site"
export PYTHONPATH="$PWD$site${PYTHONPATH:+:$PYTHONPATH}"
echo "python: $PY with PYTHONPATH=$PYTHONPATH" | tee -a "$SUMMARY"
if ! "$PY" -c "import warp, warpcloth" 2> "$OUT/import.log"; then
    echo "cannot import warp and warpcloth with $PY (see import.log): nothing run" | tee -a "$SUMMARY"
    exit 1
fi

step() {  # step NAME LIMIT_S LOG COMMAND...: run under timeout, log, record status and wall seconds
    local name=$1 limit=$2 log=$3
    shift 3
    case " $STEPS " in *" $name "*) ;; *) return 0 ;; esac
    local start=$SECONDS
    echo "== $name (limit ${limit} s): $*" | tee -a "$SUMMARY"
    timeout --signal=TERM --kill-after=15 "$limit" "$@" > "$OUT/$log" 2>&1
    local rc=$?
    local what="exit $rc"
    { [ "$rc" -eq 124 ] || [ "$rc" -eq 137 ]; } && what="timed out after ${limit} s (exit $rc)"
    echo "   $name: $what, $((SECONDS - start)) s; log $log" | tee -a "$SUMMARY"
    tail -n 3 "$OUT/$log" | sed 's/^/   | /' | tee -a "$SUMMARY"
}

# -- 0. the machine (seconds) ---------------------------------------------------------------
{ nvidia-smi || echo "nvidia-smi: not found"; } > "$OUT/machine.log" 2>&1
"$PY" -c "import warp as wp; wp.init(); print('cuda devices:', [(d.alias, d.name) for d in wp.get_cuda_devices()])" \
    >> "$OUT/machine.log" 2>&1
grep -iE "cuda devices|driver|toolkit|Warp [0-9]" "$OUT/machine.log" | head -8 | tee -a "$SUMMARY"
if ! "$PY" -c "import sys, warp as wp; wp.config.quiet = True; sys.exit(wp.get_cuda_device_count() == 0)" \
    >> "$OUT/machine.log" 2>&1; then
    echo "no CUDA device here: steps skipped ($STEPS); see machine.log" | tee -a "$SUMMARY"
    exit 2
fi
XDIST=""
"$PY" -c "import xdist" 2> /dev/null && XDIST="-n 8 --dist loadfile"

# -- 1. the CUDA tests ------------------------------------------------------------------------
# shellcheck disable=SC2086
step tests "$T_TESTS" pytest-cuda.log \
    "$PY" -m pytest -q -rA -p no:cacheprovider $XDIST -k cuda --junitxml "$OUT/pytest-cuda.xml" tests

# -- 2. the device benchmark at 32, 128, 512 ----------------------------------------------------
step bench "$T_BENCH" bench.log \
    "$PY" bench/devices.py --devices cuda --sizes 32,128,512 --seconds 0.2 --roofline --out "$OUT/bench-cuda.csv"

# -- 3. the gpu study ---------------------------------------------------------------------------
step study "$T_STUDY" study.log \
    "$PY" -m warpcloth study --profile gpu --devices cuda --out "$OUT/study-cuda" --resume

# -- 4. the device benchmark at 1024 ------------------------------------------------------------
step bench1024 "$T_BENCH_1024" bench-1024.log \
    "$PY" bench/devices.py --devices cuda --sizes 1024 --seconds 0.2 --roofline --out "$OUT/bench-cuda-1024.csv"

echo "done: $OUT (summary.txt, the logs, bench-cuda*.csv, study-cuda/)" | tee -a "$SUMMARY"
