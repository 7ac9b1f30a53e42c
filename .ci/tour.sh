#!/usr/bin/env bash
# The README's tour (and the docs' example commands), short variants (few frames, small sheets),
# run from an empty folder with an installed warpcloth: what a user who did `pip install warpcloth`
# types. Every line of README.md's tour block has its line here, in the same order
# (tests/test_ci_tour.py checks that). Usage: .ci/tour.sh BIN  (BIN: the venv's bin folder)
set -euo pipefail
BIN="$1"
export PATH="$BIN:$PATH"
say() { printf '\n$ %s\n' "$*"; "$@"; }

say python -m warpcloth.examples
say warpcloth --version
say warpcloth list
say warpcloth list --examples
say warpcloth run sheet --size 8 --num-frames 2
say warpcloth run flag --integrator rk4 --size 8 --num-frames 2 --usd flag.usda
say warpcloth run sheet --rows 16 --cols 16 --dt 5e-5 --stiffness 2000 --damping 0.05 --mass 0.3 --num-frames 2 --json
say python -m warpcloth run flag --integrator verlet --size 8 --num-frames 2 --stage-path flag.usda
say warpcloth run flag --integrator implicit_euler --cg-tol 1e-3 --jacobian approx --size 8 --num-frames 2
say warpcloth run sheet --integrator xpbd --iterations 20 --substeps 8 --size 8 --num-frames 2
say warpcloth run sheet --integrator vbd --vbd-iterations 10 --size 8 --num-frames 2
say warpcloth run flag --integrator projective --pd-iterations 10 --pd-cg-iterations 10 --size 8 --num-frames 2
say warpcloth run sheet --rows 16 --cols 16 --integrator implicit_euler --preconditioner multigrid --num-frames 2
say warpcloth run sheet --rows 20 --cols 20 --stiffness 100 --strain-limit 0.1 --num-frames 2
say warpcloth max-dt sheet --integrator explicit_euler --size 6
say warpcloth sweep examples/quick.xml --out quick.csv
say warpcloth sweep examples/quick.xml -o q.csv --workers 2
say warpcloth bench --sizes 8 --steps 20 --roofline --out bench.csv --plot bench.png
say warpcloth bench --scenario examples/cape.toml --integrators xpbd,implicit_euler --steps 10
say warpcloth run curtain --size 8 --num-frames 2
say warpcloth run drape --size 8 --num-frames 2
say warpcloth run tablecloth --integrator xpbd --size 8 --num-frames 2
say warpcloth run drape --material silk --compression 0.3 --size 8 --num-frames 2
say warpcloth run cantilever --cols 12 --num-frames 2
say warpcloth run cusick --size 8 --num-frames 2
say warpcloth calibrate silk --target bending_length=0.015 --size 8 --max-runs 2
say warpcloth run fold --rows 12 --cols 6 --num-frames 3 --usd fold.usda
say warpcloth check-intersections fold.usda
say warpcloth run drape --collider capsule:a=-0.6/0.1/0.35,b=0.6/0.1/0.35,radius=0.1,friction=0.5 \
    --size 8 --num-frames 2
say warpcloth run mesh --mesh examples/cape.obj --pin-group shoulders --usd cape.usda --num-frames 2
say warpcloth run mesh --mesh cape.usda --prim /World/Cloth --pin 'y > 0.95 * y.max()' --num-frames 2
say warpcloth run examples/cape.toml --num-frames 2
say warpcloth run flag --rows 16 --cols 16 --num-frames 3 --html flag.html
say warpcloth run flag --preview flag.gif --usd flag.usdz --usd-color strain --size 8 --num-frames 3
say warpcloth sweep --example quick --out quick2.csv
say python -m warpcloth bench --sizes 8 --steps 20 --json --quiet
say warpcloth study --profile quick --integrators xpbd --sizes 8 --out study-quick
say warpcloth advise --size 64 --budget-ms 8 --tolerance 0.05

# the docs' own example commands (docs/driving.md, docs/meshes.md, docs/colliders.md)
say python -m warpcloth.examples.drive --num-frames 3 --size 8 --usd drive.usda
say python -m warpcloth.examples.make_cape
say warpcloth run mesh --mesh cape.obj --pin 'y > 0.95 * y.max()' --num-frames 2
say warpcloth run drape --size 8 --num-frames 2 --usd drape.usdc --usd-colliders render
say warpcloth run drape --size 8 --num-frames 2 --html d.html
echo "tour: every command ran"
