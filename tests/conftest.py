"""Shared fixtures: tests run on the CPU device; CUDA-parametrised cases skip without a GPU."""

import contextlib
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


@contextlib.contextmanager
def reproducible(device):
    """Runs inside are bit-reproducible on ``device``: on CUDA, Warp's deterministic atomics
    (:func:`warpcloth.sim.device.set_deterministic`), Warp's default again afterwards; the CPU
    runs a launch's threads in order and is bit-reproducible as it is."""
    from warpcloth.sim.device import set_deterministic

    cuda = str(device).startswith("cuda")
    if cuda:
        set_deterministic(True)
    try:
        yield
    finally:
        if cuda:
            set_deterministic(False)


@pytest.fixture
def count_allocations(monkeypatch):
    """(start, stop): ``start()`` returns a list that collects the size of every CPU device
    allocation until ``stop()``."""
    from warp._src.context import CpuDefaultAllocator

    created = []
    original = CpuDefaultAllocator.allocate

    def counting(self, size_in_bytes):
        created.append(size_in_bytes)
        return original(self, size_in_bytes)

    def start():
        created.clear()
        monkeypatch.setattr(CpuDefaultAllocator, "allocate", counting)
        return created

    def stop():
        monkeypatch.setattr(CpuDefaultAllocator, "allocate", original)

    return start, stop


@pytest.fixture
def tmp_cwd(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    return tmp_path


def pytest_report_header(config):
    cache = os.environ.get("WARP_CACHE_PATH", "default")
    return f"warp {wp.config.version}, cuda available: {CUDA_AVAILABLE}, WARP cache: {cache}"
