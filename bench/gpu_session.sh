#!/usr/bin/env bash
# One GPU session, in order of value, each step under its own timeout, everything under $OUT:
#   0. the machine: nvidia-smi, Warp's CUDA devices, driver and toolkit as warp.init() prints them;
#   1. the CUDA tests: pytest -q -k cuda tests (every outcome listed, JUnit XML beside the log);
#   2. bench/devices.py on cuda at 32, 128, 512, 1024 (with the roofline and graph on/off);
#   3. the gpu study profile on cuda (resumable: a rerun continues where a timeout stopped it).
# Run from the project root on the GPU machine:
#   OUT=/path/to/out bash bench/gpu_session.sh
# Python: warpcloth and warp-lang from $HOME/wc-site when the unbundled wheels are there (the
# machine has no network: /work/shared/gpu's bundle.sh / unbundle.sh; a last part found under .gpu/
# is unbundled first), else the python3 that already imports warp (an installed warpcloth; the
# project root is on the path for the tests either way). Per-step limits [s], overridable:
#   T_TESTS (180), T_BENCH (150), T_STUDY (480); the sum stays under a 15-minute device lease with
#   room for the start-up. A step that fails or times out is recorded and the next one runs.
set -uo pipefail
OUT=${OUT:-gpu-session-out}
T_TESTS=${T_TESTS:-180}
T_BENCH=${T_BENCH:-150}
T_STUDY=${T_STUDY:-480}
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
if [ -d "$HOME/wc-site/warp" ]; then
    export PYTHONPATH="$HOME/wc-site${PYTHONPATH:+:$PYTHONPATH}"
    echo "python: $PY with PYTHONPATH=$PYTHONPATH" | tee -a "$SUMMARY"
else
    echo "python: $PY (an installed warpcloth; no \$HOME/wc-site)" | tee -a "$SUMMARY"
fi
if ! "$PY" -c "import warp, warpcloth" 2> "$OUT/import.log"; then
    echo "cannot import warp and warpcloth with $PY (see import.log): nothing run" | tee -a "$SUMMARY"
    exit 1
fi

step() {  # step NAME LIMIT_S LOG COMMAND...: run under timeout, log, record status and wall seconds
    local name=$1 limit=$2 log=$3
    shift 3
    local start=$SECONDS
    echo "== $name (limit ${limit} s): $*" | tee -a "$SUMMARY"
    timeout --signal=TERM --kill-after=15 "$limit" "$@" > "$OUT/$log" 2>&1
    local rc=$?
    local what="exit $rc"
    [ "$rc" -eq 124 ] || [ "$rc" -eq 137 ] && what="timed out after ${limit} s (exit $rc)"
    echo "   $name: $what, $((SECONDS - start)) s; log $log" | tee -a "$SUMMARY"
    tail -n 3 "$OUT/$log" | sed 's/^/   | /' | tee -a "$SUMMARY"
}

# -- 0. the machine (seconds) ---------------------------------------------------------------
{ nvidia-smi || echo "nvidia-smi: not found"; } > "$OUT/machine.log" 2>&1
"$PY" -c "import warp as wp; wp.init(); print('cuda devices:', [(d.alias, d.name) for d in wp.get_cuda_devices()])" \
    >> "$OUT/machine.log" 2>&1
grep -iE "cuda devices|driver|toolkit|Warp [0-9]" "$OUT/machine.log" | head -8 | tee -a "$SUMMARY"

# -- 1. the CUDA tests ------------------------------------------------------------------------
step "cuda tests" "$T_TESTS" pytest-cuda.log \
    "$PY" -m pytest -q -rA -p no:cacheprovider -k cuda --junitxml "$OUT/pytest-cuda.xml" tests

# -- 2. the device benchmark --------------------------------------------------------------------
step "bench/devices.py" "$T_BENCH" bench.log \
    "$PY" bench/devices.py --devices cuda --sizes 32,128,512,1024 --seconds 0.5 --roofline \
    --out "$OUT/bench-cuda.csv"

# -- 3. the gpu study ---------------------------------------------------------------------------
step "study --profile gpu" "$T_STUDY" study.log \
    "$PY" -m warpcloth study --profile gpu --devices cuda --out "$OUT/study-cuda" --resume

echo "done: $OUT (summary.txt, the logs, bench-cuda.csv, study-cuda/)" | tee -a "$SUMMARY"
