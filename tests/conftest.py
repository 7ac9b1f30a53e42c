"""Shared fixtures: tests run on the CPU device; CUDA-parametrised cases skip without a GPU."""

import contextlib
import os
import shutil
from dataclasses import replace

import pytest
import warp as wp

import warpcloth  # noqa: F401  (sets Warp's log level before init)
from warpcloth.lab.measure import Measurements
from warpcloth.lab.plan import make_plan

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


@pytest.fixture(scope="session")
def study_references(tmp_path_factory):
    """The quick profile's 4x4 float64 references and conditioning floors (swing, flag, contact) in the
    study's own cache format (``StudyPlan.reference_cache``: one file each, made under a lock), made once
    per test session and shared by the xdist workers: about 20 s of CPU that every 4x4 quick study would
    otherwise repeat. Studies whose tests are about rows, resuming, workers, Ray or the report start from
    it: ``reference_cache=`` in a plan, or :func:`seed_references` for a study run through the CLI."""
    root = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):
        root = root.parent  # this session's folder, shared by its workers (each has its own below it)
    folder = root / "study-references-quick-4"
    plan = replace(make_plan("quick", integrators=["explicit_euler"], sizes=[4]), reference_cache=str(folder))
    study = Measurements(plan, out=None)
    for transient in ("swing", "flag", "contact"):
        study.problem(transient, 4, "cpu")
    return folder


def seed_references(references, out) -> None:
    """Copy the shared references into ``out``/.references, where a study into ``out`` looks for them
    (as a resumed study finds its own)."""
    (out / ".references").mkdir(parents=True, exist_ok=True)
    for f in references.glob("*.npz"):
        shutil.copy(f, out / ".references" / f.name)


@pytest.fixture
def tmp_cwd(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    return tmp_path


def pytest_collection_modifyitems(config, items):
    """Under README's test command (``-n auto --dist loadgroup``) every test goes to whichever worker is
    free, but the tests of a file that share a module-scoped fixture (a study, a sweep, a Ray cluster, a
    reference) form one xdist group: they run on one worker, so the fixture is made once, not once per
    worker."""
    for item in items:
        info = getattr(item, "_fixtureinfo", None)
        if info is None:
            continue
        if any(defs[-1].scope in ("module", "class", "package") for defs in info.name2fixturedefs.values()):
            item.add_marker(pytest.mark.xdist_group(item.nodeid.split("::", 1)[0]))


def pytest_report_header(config):
    cache = os.environ.get("WARP_CACHE_PATH", "default")
    return f"warp {wp.config.version}, cuda available: {CUDA_AVAILABLE}, WARP cache: {cache}"
