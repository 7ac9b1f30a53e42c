"""Shared fixtures: tests run on the CPU device; CUDA-parametrised cases skip without a GPU."""

import contextlib
import importlib
import os
import pkgutil
import shutil
from dataclasses import replace

import pytest
import warp as wp

import warpcloth.kernels  # warpcloth sets Warp's log level before init; its kernel modules: kernels_compiled_once
from warpcloth.lab.measure import Measurements
from warpcloth.lab.plan import make_plan

try:
    import fcntl
except ImportError:  # pragma: no cover - not POSIX: each worker compiles what it needs, as Warp does
    fcntl = None

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


@pytest.fixture(scope="session", autouse=True)
def kernels_compiled_once(tmp_path_factory):
    """Under xdist (README's test command) the workers compile warpcloth's kernel modules between them,
    each module once, before their first test. Warp compiles a module missing from its cache in every
    process that loads it, and the workers, given neighbouring tests, load the same modules at about the
    same time: with an empty cache (CI) each worker compiled most of the 21 modules (156 s of CPU for all
    of them at the CPU's block size, measured). Here each worker walks the modules from its own offset
    and compiles (or loads from the cache) each one no other worker holds the lock of, then waits for
    the locks of those it skipped and loads them from the cache. The CPU's default block size, as a
    launch uses it (the same cache entries)."""
    worker = os.environ.get("PYTEST_XDIST_WORKER")
    if not worker or fcntl is None:
        return
    package = warpcloth.kernels
    modules = [importlib.import_module(m.name) for m in pkgutil.iter_modules(package.__path__, package.__name__ + ".")]
    count = max(1, int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1")))
    start = int(worker.removeprefix("gw") or 0) * len(modules) // count
    locks = tmp_path_factory.getbasetemp().parent / "warp-compile-locks"  # this session's, shared by its workers
    locks.mkdir(exist_ok=True)
    skipped = []
    for module in modules[start:] + modules[:start]:
        with open(locks / f"{module.__name__}.lock", "w") as lock:
            try:
                fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                skipped.append(module)  # another worker is compiling it
                continue
            wp.load_module(module, device="cpu")
    for module in skipped:
        with open(locks / f"{module.__name__}.lock", "w") as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)  # until the other worker has it in the cache
            wp.load_module(module, device="cpu")


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


@pytest.hookimpl(tryfirst=True)
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
