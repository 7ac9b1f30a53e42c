"""Shared fixtures: tests run on the CPU device; CUDA-parametrised cases skip without a GPU."""

import os

import pytest
import warp as wp

import warpcloth  # noqa: F401  (sets Warp's log level before init)

wp.init()

CUDA_AVAILABLE = wp.is_cuda_available()

#: ``@pytest.mark.parametrize("device", DEVICES)``: cpu always, cuda:0 where present (else skipped).
DEVICES = ["cpu", pytest.param("cuda:0", marks=pytest.mark.skipif(not CUDA_AVAILABLE, reason="no CUDA device"))]


@pytest.fixture
def device():
    return "cpu"


@pytest.fixture
def tmp_cwd(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    return tmp_path


def pytest_report_header(config):
    return f"warp {wp.config.version}, cuda available: {CUDA_AVAILABLE}, WARP cache: {os.environ.get('WARP_CACHE_PATH', 'default')}"
