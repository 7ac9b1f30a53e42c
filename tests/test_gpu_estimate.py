"""The gpu study profile (docs/gpu.md): the standard profile's question (the same windows, a float64
reference at every size, the study's cloth unclamped) within 8 minutes of device time with
compilation, modelled by the estimate's own function from the per-step costs recorded on an H200;
``warpcloth study --profile gpu --estimate`` gives that figure where no GPU is; a size whose cloth
would be clamped is refused; bench/gpu_session.sh skips cleanly without CUDA."""

from __future__ import annotations

import contextlib
import io
import os
import re
import shutil
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import pytest
import warp as wp

from warpcloth.cli import main
from warpcloth.errors import WarpclothError
from warpcloth.lab.accuracy import SCIPY_MAX_SIZE
from warpcloth.lab.estimate import GPU_COMPILE_ALLOWANCE_S, estimate_plan, recorded_costs, total_seconds
from warpcloth.lab.plan import clamped_transient, make_plan
from warpcloth.lab.transients import DYNAMIC, TRANSIENTS
from warpcloth.scenarios.swing import STUDY_MATERIAL
from warpcloth.sim.material import grid_spring_params
from warpcloth.sim.model import BendModel

ROOT = Path(__file__).resolve().parents[1]
NO_CUDA = pytest.mark.skipif(wp.get_cuda_device_count() > 0, reason="a CUDA device is present: the real thing runs")
BUDGET_S = 8 * 60


def clamped(n: int, name: str) -> int:
    """Membrane springs clamped on the whole n x n cloth of transient ``name``."""
    cfg = TRANSIENTS[name].scenario.defaults
    with contextlib.redirect_stderr(io.StringIO()):
        return grid_spring_params(STUDY_MATERIAL, n, n, cfg.width, cfg.height, bend=BendModel.PROVOT).clamped


def test_the_gpu_profile_asks_the_standard_question_within_8_minutes_with_compilation():
    plan, standard = make_plan("gpu"), make_plan("standard")
    assert plan.devices == ["cuda"] and plan.integrators == standard.integrators
    for name in DYNAMIC:  # the same window at every size, and the standard profile's
        assert {plan.window_frames(name, n) for n in plan.all_sizes} == {standard.window_frames(name)}
    assert all(n > SCIPY_MAX_SIZE for n in plan.all_sizes)  # each size has its float64 Warp reference
    costs = recorded_costs(plan)
    assert costs is not None  # every integrator x size was recorded on the H200
    phases = {p.phase.split(" ")[0]: p for p in estimate_plan(plan, costs, "cuda")}
    assert phases["references"].measurements == len(DYNAMIC) * len(plan.all_sizes) + sum(
        n <= plan.contact_max_size for n in plan.all_sizes
    )
    assert phases["compilation"].seconds == GPU_COMPILE_ALLOWANCE_S > 0
    total = total_seconds(list(phases.values()), 1)
    assert total <= BUDGET_S, f"{total / 60:.1f} min"
    # the bound bites: the same sizes with every configuration (the standard profile's grids) do not fit
    assert total_seconds(estimate_plan(replace(plan, level="full"), costs, "cuda")) > BUDGET_S


def test_the_gpu_profile_runs_the_study_cloth_unclamped_and_a_clamped_size_is_refused():
    for n in make_plan("gpu").all_sizes:
        assert [clamped(n, name) for name in TRANSIENTS] == [0] * len(TRANSIENTS), n
    # the 5 x 5 patch rule make_plan uses agrees with the whole grid on either side of the edge
    assert clamped_transient(244) is None and clamped(244, "swing") == 0
    assert clamped_transient(245) == "swing" and clamped(245, "swing") > 0
    with pytest.raises(WarpclothError, match=r"at 256 x 256 the study's swing cloth .* clamped .* up to 244 x 244"):
        make_plan("gpu", sizes=[64, 256])
    assert make_plan("standard").sizes == [16, 32, 64, 128]  # unchanged, and it holds


@NO_CUDA
def test_gpu_estimate_without_a_gpu_gives_the_model_from_the_recorded_costs(capsys):
    assert main(["study", "--profile", "gpu", "--estimate"]) == 0
    captured = capsys.readouterr()
    assert captured.err.startswith("warpcloth: study: skipping device cuda")
    out = captured.out
    assert "estimate of profile gpu" in out and "sizes 64, 128" in out and "compilation (an allowance" in out
    assert "recorded on one NVIDIA H200" in out and "not measured here" in out
    minutes = float(re.search(r"\(([\d.]+) min of device time\)", out).group(1))
    assert 0 < minutes <= 8.0
    # a plan whose costs were not recorded: no figure, one line
    assert main(["study", "--profile", "gpu", "--sizes", "32", "--estimate"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith("warpcloth: error: no estimate:") and "no recorded costs" in err[-1]


@NO_CUDA
@pytest.mark.skipif(shutil.which("bash") is None or shutil.which("timeout") is None, reason="needs bash, timeout")
def test_gpu_session_script_skips_cleanly_without_cuda(tmp_path):
    script = ROOT / "bench" / "gpu_session.sh"
    assert subprocess.run(["bash", "-n", str(script)]).returncode == 0
    out, home = tmp_path / "out", tmp_path / "home"
    home.mkdir()
    env = {**os.environ, "OUT": str(out), "HOME": str(home), "PYTHON": sys.executable}
    run = subprocess.run(["bash", str(script)], cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)
    summary = (out / "summary.txt").read_text()
    assert run.returncode == 2, run.stdout + run.stderr
    assert "no CUDA device here: steps skipped (tests bench study bench1024)" in summary
    assert "cuda devices: []" in (out / "machine.log").read_text()
    assert {p.name for p in home.iterdir()} <= {".cache"}  # nothing outside $OUT but Warp's kernel cache


def test_gpu_doc_states_the_profiles_expected_device_time():
    """The figure the estimate prints is in docs/gpu.md, with how it was derived."""
    text = (ROOT / "docs" / "gpu.md").read_text(encoding="utf-8")
    section = text.split("## The gpu study profile: expected device time", 1)[1].split("\n## ", 1)[0]
    for what in ("estimate_plan", "cuda-h200.txt", "GPU_COMPILE_ALLOWANCE_S", "clamped", "244"):
        assert what in section, what
