"""``warpcloth study --profile gpu --estimate`` where no GPU is: it times steps on the plan's
devices, so it says plainly that there is no estimate and where the expected device time is
written (docs/gpu.md), instead of a bare "not available"."""

from __future__ import annotations

from pathlib import Path

import pytest
import warp as wp

from warpcloth.cli import main


@pytest.mark.skipif(wp.get_cuda_device_count() > 0, reason="a CUDA device is present: the estimate would run")
def test_gpu_estimate_without_a_gpu_says_there_is_none_and_where_the_figure_is(capsys):
    assert main(["study", "--profile", "gpu", "--estimate"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[0].startswith("warpcloth: study: skipping device cuda")
    assert err[-1].startswith("warpcloth: error: no estimate: --estimate times steps on the plan's devices")
    assert "none of cuda is available here" in err[-1] and "docs/gpu.md" in err[-1]


def test_gpu_doc_states_the_profiles_expected_device_time():
    """The figure the refusal points to is there, with how it was derived."""
    text = (Path(__file__).resolve().parents[1] / "docs" / "gpu.md").read_text(encoding="utf-8")
    section = text.split("## The gpu study profile: expected device time", 1)[1].split("\n## ", 1)[0]
    for what in ("estimate_plan", "cuda-h200.txt", "Compilation is not in the"):
        assert what in section, what
