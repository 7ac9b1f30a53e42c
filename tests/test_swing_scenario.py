"""``warpcloth run swing`` is the study's swing transient to the bit (warpcloth.scenarios.swing):
the same start and the same steps as the lab's run of it, so the flags ``warpcloth advise`` prints
reproduce what the study measured; and the scenario's start hook and its refusals."""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest

from warpcloth.cli import main
from warpcloth.errors import WarpclothError
from warpcloth.integrators import make_integrator
from warpcloth.io.checkpoint import load_checkpoint
from warpcloth.lab.accuracy import FRAME_DT, Reference, TransientProblem
from warpcloth.lab.advise import Configuration
from warpcloth.lab.configs import study_options
from warpcloth.lab.transients import TRANSIENTS
from warpcloth.scenarios import get_scenario, scenario_names
from warpcloth.scenarios.swing import STUDY_SHEET, SWING_TILT, tilted_start

N = 6
FRAMES = 4
#: (integrator, options, steps per 1/60 s frame): a scheme with history, one with the study's
#: mapped bend stiffness at dt = 1/30 s, and one with fixed study options (strain_cap 0).
CONFIGS = [
    ("verlet", {}, 8),
    ("pbd", {"iterations": 2, "pbd_bend_stiffness": 0.0123, "substeps": 4}, 0.5),
    ("implicit_euler", {"cg_tol": 0.001, "preconditioner": "jacobi"}, 1),
]


def lab_swing(integrator: str, options: dict, k: float) -> np.ndarray:
    """The lab's swing at N x N (the study's build of its sheet, then TransientProblem.run, the
    study's own trial run): positions (samples, N*N, 3) from the start."""
    tr = TRANSIENTS["swing"]
    sim = tr.scenario.build(
        rows=N, cols=N, integrator=integrator, integrator_options=study_options(integrator), dt=FRAME_DT
    )
    sim.set_integrator(make_integrator(integrator, **study_options(integrator, options)), dt=FRAME_DT)
    sim.reset()
    unused = Reference(np.zeros((FRAMES + 1, N * N, 3)), None, True, "not used: run() does not compare")
    traj, _ = TransientProblem(sim, tr, FRAMES, reference=unused).run(sim, k)
    return traj


@pytest.mark.parametrize("integrator, options, k", CONFIGS)
def test_run_swing_starts_and_steps_as_the_lab_swing(tmp_path, integrator, options, k):
    text = " ".join(f"{name}={value}" for name, value in sorted(options.items()))  # as results.csv writes them
    conf = Configuration(integrator, text, Fraction(k))
    lab = lab_swing(integrator, options, k)
    # the start: the scenario's build is the lab's start, float32 bit for bit
    swing = get_scenario("swing")
    start = swing.build(rows=N, cols=N, integrator=integrator, dt=conf.dt).state.particle_q.numpy()
    assert np.array_equal(start.astype(np.float64), lab[0])
    # the steps: the CLI run of advise's flags for this configuration ends where the lab's run does
    path = tmp_path / "end.npz"
    flags = conf.run_flags(N)
    assert flags[0] == "swing"
    assert main(["run", *flags, "--num-frames", str(FRAMES), "--checkpoint", str(path), "--quiet"]) == 0
    snap = load_checkpoint(str(path))
    end = snap.arrays["state.particle_q"].view(np.float32).reshape(-1, 3)
    assert snap.clock["steps"] == round(FRAMES * k)
    assert np.array_equal(end.astype(np.float64), lab[-1])
    assert not np.array_equal(lab[-1], lab[0])  # it moved


def test_swing_is_listed_and_is_the_study_sheet_released_from_horizontal(capsys):
    assert "swing" in scenario_names()
    assert main(["list"]) == 0
    assert "  swing " in capsys.readouterr().out
    swing = get_scenario("swing")
    assert TRANSIENTS["swing"].tilt == SWING_TILT == 90.0
    a = STUDY_SHEET.build(rows=N, cols=N)
    b = swing.build(rows=N, cols=N)
    for name in ("spring_stiffness", "spring_damping", "particle_mass", "particle_inv_mass", "spring_rest_length"):
        assert np.array_equal(getattr(a.model, name).numpy(), getattr(b.model, name).numpy()), name
    assert np.array_equal(a.model.host.q, b.model.host.q)  # the same rest shape ...
    q = b.state.particle_q.numpy()
    top, bottom = q[:N], q[-N:]
    assert np.allclose(bottom[:, 1], top[:, 1], atol=1e-6)  # ... started horizontal: the free edge level
    assert np.allclose(bottom[:, 2] - top[:, 2], 1.0, atol=1e-6)  # the pinned row, the sheet 1 m out
    assert np.array_equal(q, np.asarray(tilted_start(b.model, 90.0), dtype=np.float32))
    b.reset()  # reset goes back to the rest shape
    assert np.array_equal(b.state.particle_q.numpy(), a.state.particle_q.numpy())


def test_swing_refuses_what_it_cannot_build():
    swing = get_scenario("swing")
    with pytest.raises(WarpclothError, match="Provot"):
        swing.build(rows=N, cols=N, bend="dihedral")
    with pytest.raises(WarpclothError, match="material none"):
        swing.build(rows=N, cols=N, material="none")
    with pytest.raises(WarpclothError, match="per-spring value"):
        swing.config(mass=1.0)
    heavier = swing.build(rows=N, cols=N, density=0.4)
    assert heavier.model.total_mass == pytest.approx(0.4)
