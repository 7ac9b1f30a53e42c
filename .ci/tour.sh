#!/usr/bin/env bash
# The README's tour, as printed, run from an empty folder with an installed warpcloth (the wheel with
# the extras README.md's install line names): what a user who did `pip install 'warpcloth[plot]'` types.
# Between the two markers below: README.md's tour block, line for line and in order, each line as
# printed but for the values of its sizes, frame and step counts and durations (--size, --rows, --cols,
# --sizes, --num-frames, --steps, --duration), which may be added, changed or dropped
# (tests/test_ci_tour.py checks that). After them: the docs' own example commands and a few more.
# The tour runs as two streams side by side (CI's machine has two cores and a tour line mostly one):
# `first`, the tour's lines up to the second sweep, in this folder; `second`, the rest of the tour and
# the extra lines, in order, in an empty folder of its own (./second), its output printed after
# first's. No line of one stream reads a file the other writes.
# Usage: .ci/tour.sh BIN  (BIN: the venv's bin folder)
set -euo pipefail
BIN="$1"
export PATH="$BIN:$PATH"
# say: print the command, run it, record its wall seconds; the ten slowest are listed at the end (where CI's time goes)
times="$(mktemp)"
trap 'rm -f "$times"' EXIT
say() {
    printf '\n$ %s\n' "$*"
    local t0
    t0=$(date +%s%N)
    "$@"
    local ms=$((($(date +%s%N) - t0) / 1000000))
    printf '%d.%d\t%s\n' $((ms / 1000)) $((ms % 1000 / 100)) "$*" >>"$times"
}

# -- README.md's tour --
first() {
say python -m warpcloth.examples
say warpcloth list
say warpcloth run sheet --size 8 --num-frames 2
say warpcloth run flag --integrator rk4 --size 8 --num-frames 2 --usd flag.usda
say warpcloth run sheet --rows 16 --cols 16 --dt 5e-5 --stiffness 2000 --damping 0.05 --mass 0.3 --num-frames 2 --json
say python -m warpcloth run flag --integrator verlet --num-frames 2 --size 8 --stage-path flag.usda
say warpcloth run flag --integrator implicit_euler --cg-tol 1e-3 --jacobian approx --size 8 --num-frames 2
say warpcloth run sheet --integrator xpbd --iterations 20 --substeps 8 --size 8 --num-frames 2
say warpcloth run sheet --integrator vbd --vbd-iterations 10 --size 8 --num-frames 2
say warpcloth run flag --integrator projective --pd-iterations 10 --pd-cg-iterations 10 --size 8 --num-frames 2
say warpcloth run sheet --rows 16 --cols 16 --integrator implicit_euler --preconditioner multigrid --num-frames 2
say warpcloth run sheet --rows 20 --cols 20 --stiffness 100 --strain-limit 0.1 --num-frames 2
say warpcloth max-dt sheet --integrator explicit_euler --size 6
say warpcloth sweep examples/quick.xml --out quick.csv --workers 2
say warpcloth bench --sizes 4 --steps 2 --roofline --out bench.csv --plot bench.png
say warpcloth bench --scenario examples/cape.toml --integrators xpbd,implicit_euler --steps 10
say warpcloth run curtain --size 8 --num-frames 2
say warpcloth run drape --size 8 --num-frames 2
say warpcloth run tablecloth --integrator xpbd --size 8 --num-frames 2
say warpcloth run drape --material silk --compression 0.3 --size 8 --num-frames 2
say warpcloth run cantilever --cols 12 --num-frames 2
say warpcloth run cusick --material denim --size 8 --num-frames 2
say warpcloth calibrate silk --target bending_length=0.015 --size 8
say warpcloth run fold --usd fold.usda --rows 12 --cols 6 --num-frames 3
say warpcloth check-intersections fold.usda
say warpcloth run drape --collider capsule:a=-0.6/0.1/0.35,b=0.6/0.1/0.35,radius=0.1,friction=0.5 \
    --size 8 --num-frames 2
say warpcloth run mesh --mesh examples/cape.obj --pin-group shoulders --usd cape.usda --num-frames 2
say warpcloth run mesh --mesh cape.usda --prim /World/Cloth --pin 'y > 0.95 * y.max()' --num-frames 2
say warpcloth run examples/cape.toml --num-frames 2
say warpcloth run character --usd c.usdc --html c.html --size 6 --num-frames 3
say warpcloth run flag --rows 16 --cols 16 --num-frames 3 --html flag.html
say warpcloth run flag --preview flag.gif --usd flag.usdz --usd-color strain --size 8 --num-frames 3
}
second() {
say warpcloth sweep --example quick --out quick2.csv
say python -m warpcloth bench --sizes 4 --steps 2 --json --quiet
say warpcloth study --profile quick --sizes 4 --out study-quick
say warpcloth advise --size 32 --budget-ms 8 --tolerance 0.05
# -- end of README.md's tour --

# beyond the tour (second's too): the top level's flags, the listing of the shipped files
say warpcloth --version
say warpcloth -V
say warpcloth list --examples

# the docs' own example commands (docs/driving.md, docs/meshes.md, docs/colliders.md)
say python -m warpcloth.examples.drive --num-frames 3 --size 8 --usd drive.usda
say python -m warpcloth.examples.make_cape
say warpcloth run mesh --mesh cape.obj --pin 'y > 0.95 * y.max()' --num-frames 2
say warpcloth run drape --size 8 --num-frames 2 --usd drape.usdc --usd-colliders render
say warpcloth run drape --size 8 --num-frames 2 --html d.html
}

mkdir second
log="$(mktemp)"
(cd second; second) >"$log" 2>&1 &
pid=$!
trap 'kill "$pid" 2>/dev/null || true; rm -f "$times" "$log"' EXIT  # a failed first line stops second too
first
status=0
wait "$pid" || status=$?
printf '\n# the second stream (in ./second):\n'
cat "$log"
if [ "$status" -ne 0 ]; then
    echo "tour: the second stream failed (exit $status)" >&2
    exit "$status"
fi
echo "tour: every command ran; the slowest (wall s):"
sort -rn "$times" | head -10
