"""Independent jobs in parallel: N local worker processes, or Ray tasks on a cluster.

A job is a picklable payload and a function ``fn(payload, place) -> dict`` (a row); ``place``
is a :class:`Place` (host, worker, device) that the function uses to choose its device and may
copy into its row. :func:`run_jobs` yields a :class:`Done` per job as it completes, in
completion order; the caller (the only writer of its results file) writes each one.

* **Local** (:class:`LocalPool`): long-lived worker processes of the ``spawn`` context (Warp and
  ``fork`` do not mix), each importing and compiling once, each on its own pipe (no shared queue
  whose lock a killed worker could hold). A worker that dies is replaced; its unreported jobs run
  again, at most ``max_retries`` more times each, then come back as failed (``Done.error``).
* **Ray** (:class:`RayPool`): one Ray task per group of jobs, asking ``num_gpus=1`` for a CUDA job
  and ``num_cpus=1`` for a CPU job; Ray retries a task whose worker dies (``max_retries``).
* **Groups**: jobs with the same ``group`` run in order on one worker (one task on Ray), so that
  what they share (a per-process cache, e.g. the sweep's max-dt search) is computed once.
* Each job is reported once. ``Done.concurrent`` is the most jobs running at once on the job's host
  while it ran (local: busy workers; Ray: the driver's tasks in flight, capped by the node's CPUs
  for a CPU job, its GPUs for a CUDA job).

The study and the sweep run their jobs through :func:`run_jobs` (pools from :func:`open_pool`,
workers started by :func:`init_worker`); neither this module nor its workers write files
(docs/study.md, "In parallel").
"""

from __future__ import annotations

import multiprocessing
import os
import socket
import threading
import time
import traceback
from collections.abc import Callable, Hashable, Iterable, Iterator
from dataclasses import dataclass, field
from multiprocessing.connection import wait as wait_any

from warpcloth.errors import WarpclothError
from warpcloth.sim.device import init_warp


@dataclass(frozen=True)
class Job:
    """One unit of work. ``key`` is unique; ``device`` (``cpu``, ``cuda``, ``cuda:N``) chooses
    the resources it asks for; jobs with the same ``group`` run on one worker, in order."""

    key: str
    payload: object
    device: str = "cpu"
    group: Hashable = None


@dataclass
class Place:
    """Where a job ran: the host name, a worker label (``local:2``, ``ray:<pid>``), the device
    the job should use (None: its own), and the worker's pid."""

    host: str
    worker: str
    device: str | None = None
    pid: int = 0


@dataclass
class Done:
    """A finished job: its row (None when it failed: ``error`` says why), where it ran, the most
    jobs running at once on its host while it ran, and how many times it was started."""

    job: Job
    row: dict | None
    place: Place | None
    concurrent: int = 1
    attempts: int = 1
    error: str = ""


@dataclass
class _Unit:
    jobs: list
    attempts: int = 0


def units_of(jobs: Iterable[Job]) -> list[_Unit]:
    """Jobs cut into units: one per group (in first-seen order) and one per ungrouped job."""
    units: list[_Unit] = []
    by_group: dict = {}
    for job in jobs:
        if job.group is None:
            units.append(_Unit([job]))
        elif job.group in by_group:
            by_group[job.group].jobs.append(job)
        else:
            by_group[job.group] = _Unit([job])
            units.append(by_group[job.group])
    return units


def is_cuda(device: str | None) -> bool:
    return bool(device) and str(device).startswith("cuda")


# -- local worker processes --------------------------------------------------------------------
#: Exit status of a worker that stops because its driver died.
EXIT_DRIVER_GONE = 70


def _exit_with_driver() -> None:
    """Stop this worker process as soon as its driver is gone (``kill -9`` of the driver leaves
    nobody to read its rows, and its runs would go on for their whole wall cap): a thread waits
    on the parent's sentinel, which becomes readable when the parent process ends."""
    parent = multiprocessing.parent_process()
    if parent is None or getattr(parent, "sentinel", None) is None:
        return

    def watch() -> None:
        try:
            wait_any([parent.sentinel])
        except (OSError, ValueError):  # pragma: no cover - the sentinel closed under us
            return
        os._exit(EXIT_DRIVER_GONE)

    threading.Thread(target=watch, name="warpcloth-driver-watch", daemon=True).start()


def _worker_main(conn, fn, place: Place, init) -> None:
    """A local worker: receive a list of (key, payload), send ("row", key, row) per job, then
    ("idle",); stop on None. A job that raises sends ("error", key, message). The worker exits
    when its driver dies (:func:`_exit_with_driver`)."""
    place.pid = os.getpid()
    _exit_with_driver()
    try:
        if init is not None:
            init(place)
        conn.send(("ready", place.pid))
        while True:
            batch = conn.recv()
            if batch is None:
                return
            for key, payload in batch:
                try:
                    row = fn(payload, place)
                except Exception as exc:
                    conn.send(("error", key, " ".join(f"{type(exc).__name__}: {exc}".split()), traceback.format_exc()))
                else:
                    conn.send(("row", key, row))
            conn.send(("idle",))
    except (EOFError, BrokenPipeError, KeyboardInterrupt):
        return


@dataclass
class _Worker:
    index: int
    device: str | None
    process: object = None
    conn: object = None
    unit: _Unit | None = None
    pending: list = field(default_factory=list)  # keys of its unit not yet reported
    ready: bool = False


class LocalPool:
    """``workers`` long-lived ``spawn`` processes; worker ``i`` gets ``devices[i % len(devices)]``
    as its :attr:`Place.device` (None without devices).

    Args:
        fn: ``fn(payload, place) -> dict``, a module-level (picklable) function.
        workers: number of processes, >= 1.
        devices: devices handed out round-robin to the workers, or None.
        init: ``init(place)`` run once in each worker before its first job (e.g. Warp's init).
        max_retries: times a job whose worker died is started again.
        on_event: ``on_event(text)`` for one-line notes (a worker died and was replaced).
    """

    def __init__(
        self,
        fn: Callable,
        workers: int,
        devices: list[str] | None = None,
        init: Callable | None = None,
        max_retries: int = 2,
        on_event: Callable | None = None,
    ):
        if workers < 1:
            raise ValueError("workers must be >= 1")
        self.fn, self.init, self.max_retries, self.on_event = fn, init, max_retries, on_event
        self.ctx = multiprocessing.get_context("spawn")
        self.host = socket.gethostname()
        self.workers = [_Worker(i + 1, devices[i % len(devices)] if devices else None) for i in range(workers)]
        self.restarts = 0

    def _place(self, w: _Worker) -> Place:
        return Place(self.host, f"local:{w.index}", w.device, w.process.pid if w.process else 0)

    def _start(self, w: _Worker) -> None:
        parent, child = self.ctx.Pipe()
        w.process = self.ctx.Process(
            target=_worker_main,
            args=(child, self.fn, self._place(w), self.init),
            name=f"warpcloth-worker-{w.index}",
            daemon=True,
        )
        w.process.start()
        child.close()
        w.conn, w.unit, w.pending, w.ready = parent, None, [], False

    def _note(self, text: str) -> None:
        if self.on_event is not None:
            self.on_event(text)

    def run(self, jobs: Iterable[Job]) -> Iterator[Done]:
        queue = units_of(jobs)
        by_key: dict[str, Job] = {j.key: j for u in queue for j in u.jobs}
        attempts: dict[str, int] = {}
        concurrent: dict[str, int] = {}  # key -> most busy workers seen while it ran
        reported: set[str] = set()
        remaining = len(by_key)
        for w in self.workers:
            self._start(w)
        try:
            while remaining:
                busy = sum(1 for w in self.workers if w.unit is not None)
                for w in self.workers:  # hand units to ready, idle workers
                    if w.ready and w.unit is None and queue:
                        unit = queue.pop(0)
                        unit.attempts += 1
                        w.unit, w.pending = unit, [j.key for j in unit.jobs]
                        for k in w.pending:
                            attempts[k] = unit.attempts
                        w.conn.send([(j.key, j.payload) for j in unit.jobs])
                        busy += 1
                if not queue and not any(w.unit is not None for w in self.workers):
                    raise RuntimeError(f"{remaining} job(s) were neither queued nor running (a bug in the pool)")
                for w in self.workers:
                    if w.unit is not None and w.pending:
                        concurrent[w.pending[0]] = max(concurrent.get(w.pending[0], 0), busy)
                conns = {w.conn: w for w in self.workers}
                sentinels = {w.process.sentinel: w for w in self.workers}
                for ready in wait_any(list(conns) + list(sentinels), timeout=1.0):
                    w = conns.get(ready)
                    if w is not None:
                        try:
                            msg = w.conn.recv()
                        except (EOFError, OSError):
                            continue  # its sentinel says it died
                        done = self._handle(w, msg, by_key, attempts, concurrent, reported)
                        if done is not None:
                            remaining -= 1
                            yield done
                        continue
                    w = sentinels[ready]
                    w.process.join(timeout=1)
                    for msg in self._drain(w):  # rows it sent before it died count
                        done = self._handle(w, msg, by_key, attempts, concurrent, reported)
                        if done is not None:
                            remaining -= 1
                            yield done
                    for done in self._replace(w, queue, by_key, attempts, reported):
                        remaining -= 1
                        yield done
        finally:
            self.close()

    def _handle(self, w: _Worker, msg, by_key, attempts, concurrent, reported) -> Done | None:
        kind = msg[0]
        if kind == "ready":
            w.ready = True
            return None
        if kind == "idle":
            w.unit, w.pending = None, []
            return None
        key = msg[1]
        if key in w.pending:
            w.pending.remove(key)
        if key in reported:  # never twice
            return None
        reported.add(key)
        place = self._place(w)
        if kind == "row":
            return Done(by_key[key], msg[2], place, concurrent.get(key, 1), attempts.get(key, 1))
        return Done(by_key[key], None, place, concurrent.get(key, 1), attempts.get(key, 1), error=msg[2])

    @staticmethod
    def _drain(w: _Worker) -> list:
        msgs = []
        try:
            while w.conn.poll():
                msgs.append(w.conn.recv())
        except (EOFError, OSError):
            pass
        return msgs

    def _replace(self, w: _Worker, queue, by_key, attempts, reported) -> Iterator[Done]:
        code = w.process.exitcode
        lost = [k for k in w.pending if k not in reported]
        self.restarts += 1
        how = f"killed by signal {-code}" if code is not None and code < 0 else f"exit status {code}"
        if not w.ready and w.unit is None:
            self._start(w)
            if self.restarts > 3 * len(self.workers) + 3:
                raise RuntimeError(f"worker {w.index} died before its first job ({how}) {self.restarts} times")
            self._note(f"worker {w.index} (pid {w.process.pid}) replaced: the previous one died while starting ({how})")
            return
        retry, failed = [], []
        for k in lost:
            (retry if attempts.get(k, 1) <= self.max_retries else failed).append(by_key[k])
        if retry:
            unit = _Unit(retry, attempts=max(attempts.get(j.key, 1) for j in retry))
            queue.insert(0, unit)
        place = self._place(w)
        self._start(w)
        what = f"{len(lost)} unfinished run(s) run again" if retry else "it was idle"
        if failed:
            what = f"{len(retry)} run(s) run again, {len(failed)} given up after {self.max_retries + 1} attempts"
        self._note(
            f"worker {w.index} (pid {place.pid}) died ({how}); {what}; a new worker (pid {w.process.pid}) took its "
            "place"
        )
        for job in failed:
            reported.add(job.key)
            yield Done(
                job,
                None,
                place,
                1,
                attempts.get(job.key, 1),
                error=f"its worker process died {attempts.get(job.key, 1)} times while running it ({how})",
            )

    def close(self) -> None:
        for w in self.workers:
            if w.process is None:
                continue
            try:
                if w.process.is_alive():
                    w.conn.send(None)
            except (OSError, BrokenPipeError):
                pass
        deadline = time.monotonic() + 5
        for w in self.workers:
            if w.process is None:
                continue
            w.process.join(timeout=max(0.0, deadline - time.monotonic()))
            if w.process.is_alive():  # busy with a job the driver no longer waits for
                w.process.kill()
                w.process.join(timeout=5)
            try:
                w.conn.close()
            except OSError:
                pass
            w.process = None


# -- Ray ---------------------------------------------------------------------------------------
RAY_INSTALL_HINT = "pip install 'warpcloth[cluster]' (from a clone: pip install -e '.[cluster]')"


def import_ray():
    """The ``ray`` module, or an ImportError whose message says how to install it."""
    try:
        import ray  # noqa: PLC0415 (the optional [cluster] extra)
    except ImportError:
        raise ImportError(f"Ray is not installed: {RAY_INSTALL_HINT}") from None
    return ray


def _ray_unit(fn, init, items, device):
    """A Ray task: run a unit's jobs in this Ray worker and return [(key, row | None, error)],
    the place and the node id. A CUDA job runs on the GPU Ray gave the task."""
    import ray  # noqa: PLC0415 (the optional [cluster] extra)

    ctx = ray.get_runtime_context()
    place = Place(socket.gethostname(), f"ray:{os.getpid()}", None, os.getpid())
    if is_cuda(device):
        ids = ray.get_gpu_ids()
        # Ray sets CUDA_VISIBLE_DEVICES to the task's GPU: it is cuda:0 in this process
        place.device = "cuda:0"
        place.worker = f"ray:{os.getpid()}:gpu{ids[0] if ids else '?'}"
    if init is not None and not getattr(_ray_unit, "_initialised", False):
        init(place)
        _ray_unit._initialised = True
    out = []
    for key, payload in items:
        try:
            out.append((key, fn(payload, place), ""))
        except Exception as exc:
            out.append((key, None, " ".join(f"{type(exc).__name__}: {exc}".split())))
    return out, place, ctx.get_node_id()


#: seconds :func:`check_address` waits for a cluster's port to answer.
CONNECT_TIMEOUT = 5.0


def check_address(address: str, timeout: float = CONNECT_TIMEOUT) -> None:
    """Fail fast when a Ray address ``HOST:PORT`` or ``ray://HOST:PORT`` does not answer: a TCP
    connect with ``timeout`` seconds before ``ray.init`` (which otherwise waits its own, much
    longer, timeout). ``auto`` and ``local`` are not network addresses and pass.

    Raises:
        ConnectionError: one line naming the address and what was wrong.
    """
    if address in ("auto", "local"):
        return
    hostport = address[len("ray://") :] if address.startswith("ray://") else address
    host, sep, port = hostport.rpartition(":")
    host = host.strip("[]")
    if not sep or not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise ConnectionError(f"{address!r} is not a Ray address: give auto, local, HOST:PORT or ray://HOST:PORT")
    try:
        with socket.create_connection((host, int(port)), timeout=timeout):
            pass
    except OSError as exc:
        why = "no answer" if isinstance(exc, socket.timeout) else (exc.strerror or type(exc).__name__)
        raise ConnectionError(
            f"nothing answers at {host}:{port} within {timeout:g} s ({why}); "
            "is the cluster's head node started (ray start --head) and reachable?"
        ) from None


class RayPool:
    """Units of jobs as Ray tasks on the cluster ``ray.init(address=address)`` connects to (an
    already initialised Ray is used as it is; ``address="local"`` starts a local instance).

    Args:
        fn, init: as for :class:`LocalPool` (``init`` runs once per Ray worker process).
        address: ``auto``, ``ray://HOST:PORT``, ``HOST:PORT`` or ``local``.
        max_retries: Ray's retries of a task whose worker died.
        on_event: one-line notes.
    """

    def __init__(
        self,
        fn: Callable,
        address: str = "auto",
        init: Callable | None = None,
        max_retries: int = 2,
        on_event: Callable | None = None,
    ):
        self.ray = import_ray()
        self.fn, self.init, self.address, self.max_retries, self.on_event = fn, init, address, max_retries, on_event
        self.started = False

    def connect(self) -> None:
        ray = self.ray
        check_address(self.address)  # also when Ray is up already: a wrong address is still a mistake
        if ray.is_initialized():
            return
        kwargs = (
            dict(log_to_driver=False, include_dashboard=False) if self.address == "local" else dict(log_to_driver=False)
        )
        try:
            if self.address == "local":
                ray.init(**kwargs)
            else:
                ray.init(address=self.address, **kwargs)
        except Exception as exc:
            raise ConnectionError(f"cannot connect to the Ray cluster: {' '.join(str(exc).split())[:300]}") from None
        self.started = True

    def _slots(self) -> dict:
        slots = {}
        for node in self.ray.nodes():
            if node.get("Alive", True):
                res = node.get("Resources", {})
                slots[node.get("NodeID")] = (int(res.get("CPU", 1)), int(res.get("GPU", 0)))
        return slots

    def run(self, jobs: Iterable[Job]) -> Iterator[Done]:
        ray = self.ray
        self.connect()
        remote = ray.remote(_ray_unit)
        units = units_of(jobs)
        in_flight: dict = {}  # ref -> unit
        most: dict = {}  # ref -> most tasks in flight while it ran
        reported: set[str] = set()
        for unit in units:
            device = unit.jobs[0].device
            opts = dict(num_gpus=1, num_cpus=0) if is_cuda(device) else dict(num_cpus=1)
            ref = remote.options(max_retries=self.max_retries, retry_exceptions=False, **opts).remote(
                self.fn, self.init, [(j.key, j.payload) for j in unit.jobs], device
            )
            in_flight[ref] = unit
        for ref in in_flight:
            most[ref] = len(in_flight)
        slots = None
        try:
            while in_flight:
                ready, _ = ray.wait(list(in_flight), num_returns=1, timeout=5.0)
                for ref in ready:
                    unit = in_flight.pop(ref)
                    try:
                        rows, place, node = ray.get(ref)
                    except Exception as exc:
                        message = " ".join(f"{type(exc).__name__}: {exc}".split())[:300]
                        if self.on_event is not None:
                            self.on_event(
                                f"a Ray task of {len(unit.jobs)} run(s) failed after {self.max_retries} retries: "
                                f"{message[:120]}"
                            )
                        for job in unit.jobs:
                            if job.key not in reported:
                                reported.add(job.key)
                                yield Done(job, None, None, 1, self.max_retries + 1, error=message)
                        continue
                    if slots is None:
                        slots = self._slots()
                    cpu, gpu = slots.get(node, (most[ref], most[ref]))
                    cap = gpu if is_cuda(unit.jobs[0].device) else cpu
                    by_key = {j.key: j for j in unit.jobs}
                    for key, row, error in rows:
                        if key in reported:
                            continue
                        reported.add(key)
                        yield Done(by_key[key], row, place, max(1, min(most[ref], cap or 1)), 1, error=error)
                # tasks still in flight overlapped with those that just ended; a new count for them
                for ref in in_flight:
                    most[ref] = max(most[ref], len(in_flight))
        finally:
            for ref in in_flight:
                try:
                    ray.cancel(ref, force=True)
                except Exception:
                    pass

    def close(self) -> None:
        if self.started and self.ray.is_initialized():
            self.ray.shutdown()
        self.started = False


def init_worker(place) -> None:
    """The ``init`` of the sweep's and the study's workers: run once in each worker process (local
    or Ray) before its first job: Warp initialised quietly."""
    init_warp(False)


def event_printer(stream, prefix: str = "warpcloth: ") -> Callable:
    """An ``on_event`` for a pool: each note as one line ``PREFIX note`` on ``stream`` (None: dropped)."""

    def note(text: str) -> None:
        if stream is not None:
            stream.write(f"{prefix}{text}\n")
            stream.flush()

    return note


def check_count(flag: str, value) -> None:
    """A worker count given to the library: None, or a whole number >= 1 (WarpclothError names ``flag``)."""
    if value is not None and (isinstance(value, bool) or not isinstance(value, int) or value < 1):
        raise WarpclothError(f"{flag} must be a whole number >= 1, got {value!r}")


def require_ray() -> None:
    """A WarpclothError saying how to install Ray when ``--ray`` is asked for without it."""
    try:
        import_ray()
    except ImportError as exc:
        raise WarpclothError(f"--ray needs Ray: {str(exc).split(': ', 1)[1]}") from None


def open_pool(
    fn: Callable,
    workers: int = 1,
    devices: list[str] | None = None,
    ray: str | None = None,
    init: Callable | None = None,
    max_retries: int = 2,
    on_event: Callable | None = None,
):
    """The pool that runs ``fn``'s jobs: ``workers`` local processes (``devices`` handed out to
    them), or, with ``ray`` (an address), a :class:`RayPool` connected now, so that a cluster that
    does not answer is refused before any file is touched.

    Raises:
        WarpclothError: ``--ray ADDRESS: why`` when the cluster cannot be reached.
    """
    if ray is None:
        return LocalPool(fn, workers, devices=devices, init=init, max_retries=max_retries, on_event=on_event)
    pool = RayPool(fn, ray, init=init, max_retries=max_retries, on_event=on_event)
    try:
        pool.connect()
    except ConnectionError as exc:
        raise WarpclothError(f"--ray {ray}: {exc}") from None
    return pool


def run_jobs(
    fn: Callable,
    jobs: Iterable[Job],
    workers: int = 1,
    devices: list[str] | None = None,
    ray_address: str | None = None,
    init: Callable | None = None,
    max_retries: int = 2,
    on_event: Callable | None = None,
    pool=None,
    at_a_time: int | None = None,
) -> Iterator[Done]:
    """Run ``jobs`` with ``fn`` and yield a :class:`Done` per job as it completes: the one driver
    of the sweep and the study (the caller writes each row).

    ``pool``: an open pool (:func:`open_pool`) to run them on, left open; without it a pool is
    opened for these jobs (``workers`` local processes, or Ray tasks when ``ray_address`` is
    given) and closed after. ``at_a_time``: the jobs go to the pool in slices of this many, one
    slice after the other (on Ray, whose tasks otherwise all start at once: at most that many in
    flight)."""
    jobs = list(jobs)
    own = pool is None
    if own:
        pool = open_pool(
            fn, workers, devices=devices, ray=ray_address, init=init, max_retries=max_retries, on_event=on_event
        )
    try:
        step = at_a_time or max(1, len(jobs))
        for at in range(0, len(jobs), step):
            yield from pool.run(jobs[at : at + step])
    finally:
        if own:
            pool.close()


__all__ = [
    "CONNECT_TIMEOUT",
    "RAY_INSTALL_HINT",
    "Done",
    "Job",
    "LocalPool",
    "Place",
    "RayPool",
    "check_address",
    "check_count",
    "event_printer",
    "import_ray",
    "init_worker",
    "is_cuda",
    "open_pool",
    "require_ray",
    "run_jobs",
    "units_of",
]
