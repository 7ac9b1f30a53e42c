"""Parallel sweeps (CPU): warpcloth.lab.parallel's local worker pool, sweep --workers, --ray
(skipped without Ray: pip install -e '.[cluster]'), killed workers and an interrupted driver."""

import os
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from parallel_toy import toy

import warpcloth.lab.sweep as sweep
from warpcloth.cli import main
from warpcloth.errors import WarpclothError
from warpcloth.lab.parallel import Job, LocalPool, units_of
from warpcloth.lab.testlist import parse_test_list

# 2 time steps x 2 scenarios = 4 runs in 2 max-dt search groups: the fewest that give each of 2 workers (or
# Ray tasks) a group of its own
TINY = """
<test_list size="6" duration="1" wall_cap="30">
  <test id="t" integrator="explicit_euler" dt="max max*0.5" maxdt_duration="0.5"/>
</test_list>
"""
# 8 independent runs of about 1 s each (flags: a sheet ends at equilibrium, within a second on a fast machine), long
# enough that a kill or an interrupt lands mid-sweep and the driver sees it before the last row (a fixed dt: no groups)
SLOW = """
<test_list size="8" duration="5" dt="5e-5" wall_cap="60">
  <test id="s" integrator="explicit_euler verlet" scenario="flag" mass="0.2 0.25" drag="0 0.1"/>
</test_list>
"""
#: Columns that depend on the machine, the clock or the placement, not on the run.
TIMING = {
    "wall_time_s",
    "compile_s",
    "ms_per_step",
    "steps_per_s",
    "frames_per_wall_second",
    "realtime_factor",
    "realtime",
    "integration_ms_mean",
    "other_ms_mean",
    "time_to_equilibrium_wall_s",
    "host",
    "worker",
    "concurrent_runs",
    "solver",
}


def write(tmp_path, text, name="tests.xml"):
    path = tmp_path / name
    path.write_text(text)
    return str(path)


def same_runs(a_rows, b_rows):
    """Rows keyed by run, with every column but the timings and placement."""
    a = {r["key"]: {c: v for c, v in r.items() if c not in TIMING} for r in a_rows}
    b = {r["key"]: {c: v for c, v in r.items() if c not in TIMING} for r in b_rows}
    return a == b


@pytest.fixture(scope="module")
def serial(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("serial")
    path = write(tmp, TINY)
    sweep.run_sweep(path, str(tmp / "serial.csv"))
    rows = sweep.read_results(str(tmp / "serial.csv"))
    assert len(rows) == 4 and all(r["worker"] == "main" and r["concurrent_runs"] == "1" for r in rows)
    assert all(r["host"] == socket.gethostname() for r in rows)
    return path, rows


# -- the pool on its own (toy jobs, no Warp) ---------------------------------------------------
def test_units_keep_groups_together_in_order():
    jobs = [Job("a", 1, group="g"), Job("b", 2), Job("c", 3, group="g"), Job("d", 4, group="h")]
    assert [[j.key for j in u.jobs] for u in units_of(jobs)] == [["a", "c"], ["b"], ["d"]]


def test_pool_reports_every_job_once_and_groups_share_a_worker():
    jobs = [Job(f"g{i}", ("ok", i), group="g") for i in range(3)] + [Job(f"j{i}", ("ok", i)) for i in range(4)]
    jobs.append(Job("bad", ("raise", 7)))
    done = list(LocalPool(toy, 2).run(jobs))
    assert sorted(d.job.key for d in done) == sorted(j.key for j in jobs)
    by_key = {d.job.key: d for d in done}
    assert by_key["bad"].row is None and by_key["bad"].error == "ValueError: bad payload 7"
    group = [by_key[f"g{i}"] for i in range(3)]
    assert len({d.row["pid"] for d in group}) == 1  # one worker ran the whole group
    assert [d.job.key for d in done if d.job.key.startswith("g")] == ["g0", "g1", "g2"]  # in order
    assert os.getpid() not in {d.row["pid"] for d in done if d.row}  # run in the workers
    assert all(1 <= d.concurrent <= 2 and d.attempts == 1 for d in done)


def test_concurrent_counts_jobs_running_at_once(tmp_path):
    folder = str(tmp_path)
    jobs = [Job("a", ("barrier", (folder, "a", "b"))), Job("b", ("barrier", (folder, "b", "a")))]
    done = list(LocalPool(toy, 2).run(jobs))
    assert all(d.error == "" for d in done), [d.error for d in done]
    assert [d.concurrent for d in done] == [2, 2]  # neither could finish before the other started


def test_a_worker_killed_mid_job_is_replaced_and_its_unfinished_jobs_run_again(tmp_path):
    marker = str(tmp_path / "died")
    jobs = [
        Job("a", ("ok", "a"), group="g"),
        Job("b", ("die_once", marker), group="g"),
        Job("c", ("ok", "c"), group="g"),
        Job("d", ("ok", "d")),
    ]
    events = []
    done = list(LocalPool(toy, 2, on_event=events.append).run(jobs))
    assert sorted(d.job.key for d in done) == ["a", "b", "c", "d"]  # a reported once, before the kill
    by_key = {d.job.key: d for d in done}
    assert by_key["b"].row["value"] == marker and by_key["b"].attempts == 2
    assert by_key["a"].attempts == 1 and by_key["a"].row["pid"] != by_key["b"].row["pid"]
    assert len(events) == 1 and "died (killed by signal 9); 2 unfinished run(s) run again" in events[0]


def test_a_job_that_always_kills_its_worker_is_given_up():
    events = []
    done = list(
        LocalPool(toy, 1, max_retries=1, on_event=events.append).run([Job("x", ("die", 0)), Job("y", ("ok", 1))])
    )
    by_key = {d.job.key: d for d in done}
    assert by_key["x"].row is None and "died 2 times" in by_key["x"].error
    assert by_key["y"].row["value"] == 1
    assert len(events) == 2 and "given up after 2 attempts" in events[1]


# -- sweep --workers ---------------------------------------------------------------------------
def test_workers_2_gives_the_serial_rows(serial, tmp_path, monkeypatch, capsys):
    path, rows = serial
    monkeypatch.setattr(os, "cpu_count", lambda: 1)  # 2 workers on "1 core": the warning
    out = tmp_path / "p.csv"
    assert main(["sweep", path, "--out", str(out), "--workers", "2"]) == 0
    err = capsys.readouterr().err
    assert "warpcloth: warning: --workers 2 is more than the 1 CPU cores" in err
    assert "running 4 runs in 2 worker processes" in err
    par = sweep.read_results(str(out))
    assert len(par) == 4 and len({r["key"] for r in par}) == 4
    assert same_runs(rows, par)
    assert {r["worker"] for r in par} <= {"local:1", "local:2"} and all(r["host"] == socket.gethostname() for r in par)
    assert {r["concurrent_runs"] for r in par} <= {"1", "2"}
    # the runs of one max-dt search ran on one worker
    by_search = {}
    for spec in parse_test_list(path).runs:
        by_search.setdefault(spec.search_key, set()).add(next(r["worker"] for r in par if r["key"] == spec.key))
    assert all(len(w) == 1 for w in by_search.values())


def _children(pid):
    """Spawned worker processes of ``pid`` (not its resource tracker)."""
    kids = []
    for task in os.listdir(f"/proc/{pid}/task"):
        try:
            kids += [int(k) for k in open(f"/proc/{pid}/task/{task}/children").read().split()]
        except OSError:
            pass
    found = []
    for k in kids:
        try:
            if b"spawn_main" in open(f"/proc/{k}/cmdline", "rb").read():
                found.append(k)
        except OSError:
            pass
    return found


def _alive(pid):
    try:
        with open(f"/proc/{pid}/stat") as fh:
            return fh.read().split(")")[-1].split()[0] != "Z"
    except OSError:
        return False


def _wait_rows(out, proc, n, timeout=180):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline and proc.poll() is None:
        if out.exists() and len(out.read_text().splitlines()) >= n + 1:
            return
        time.sleep(0.1)
    raise AssertionError(f"no {n} rows in {out} (sweep exit status {proc.poll()})")


def test_a_killed_worker_loses_and_duplicates_nothing(tmp_path):
    path = write(tmp_path, SLOW)
    expected = sorted(r.key for r in parse_test_list(path).runs)
    out = tmp_path / "r.csv"
    proc = subprocess.Popen(
        [sys.executable, "-m", "warpcloth", "sweep", path, "--out", str(out), "--workers", "2"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        _wait_rows(out, proc, 1)
        workers = _children(proc.pid)
        assert len(workers) == 2, workers
        os.kill(workers[0], signal.SIGKILL)  # mid-run: 7 runs are left for 2 workers
        stdout, stderr = proc.communicate(timeout=300)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, stderr
    assert f"(pid {workers[0]}) died (killed by signal 9)" in stderr
    assert "8 runs written" in stdout
    keys = [r["key"] for r in sweep.read_results(str(out))]
    assert sorted(keys) == expected  # nothing lost, nothing twice


def test_an_interrupted_parallel_sweep_resumes(tmp_path, capsys):
    # runs of 1.5 s, not 5: the interrupt needs only that the rows come one by one (the test reads the CSV every 0.1 s)
    path = write(tmp_path, SLOW.replace('duration="5"', 'duration="1.5"'))
    expected = sorted(r.key for r in parse_test_list(path).runs)
    out = tmp_path / "r.csv"
    # SIGINT at its default in the child: a shell's background job (`pytest &`) ignores it, and an
    # ignored SIGINT is inherited, so the sweep could not be interrupted there
    proc = subprocess.Popen(
        [sys.executable, "-m", "warpcloth", "sweep", path, "--out", str(out), "--workers", "2"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    try:
        _wait_rows(out, proc, 2)
        workers = _children(proc.pid)
        os.kill(proc.pid, signal.SIGINT)  # the driver only, as `kill -INT`
        _, stderr = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, stderr
    assert "warpcloth: interrupted; finished runs are in" in stderr
    assert workers and not any(_alive(w) for w in workers)  # no worker outlives the driver
    first = [r["key"] for r in sweep.read_results(str(out))]
    assert 2 <= len(first) < 8 and len(set(first)) == len(first)

    assert main(["sweep", path, "--out", str(out), "--resume", "--workers", "2", "--quiet"]) == 0
    assert f"{8 - len(first)} runs written" in capsys.readouterr().out
    keys = [r["key"] for r in sweep.read_results(str(out))]
    assert sorted(keys) == expected and keys[: len(first)] == first


# -- bad input ---------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "args, message",
    [
        (["--workers", "0"], "argument --workers: must be at least 1, got 0"),
        (["--workers", "two"], "argument --workers: 'two' is not a whole number >= 1"),
        (
            ["--workers", "2", "--ray", "auto"],
            "--ray runs the sweep on the cluster's CPUs and GPUs: it takes neither --workers nor --devices",
        ),
        (["--devices", "cuda:0", "--ray", "auto"], "it takes neither --workers nor --devices"),
        (["--devices", "cpu"], "--devices: 'cpu' is not a CUDA device"),
        (["--devices", "cuda:7"], "--devices: device 'cuda:7' is not available")
        if not __import__("warp").is_cuda_available()
        else (["--devices", "cuda:77"], "device 'cuda:77' is not available"),
        (["--devices", "cuda:0,,cuda:1"], "is not a comma-separated list of CUDA devices"),
    ],
)
def test_bad_parallel_flags_are_one_line_exit_2(tmp_path, monkeypatch, capsys, args, message):
    path = write(tmp_path, TINY)
    monkeypatch.setattr(sweep, "execute_run", lambda *a: pytest.fail("a run started"))
    out = tmp_path / "r.csv"
    try:
        code = main(["sweep", path, "--out", str(out), *args])
    except SystemExit as exc:  # argparse's own checks
        code = exc.code
    assert code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("warpcloth: error: ") and message in err, err
    assert not out.exists()


def test_ray_without_ray_says_how_to_install_it(tmp_path, monkeypatch, capsys):
    path = write(tmp_path, TINY)
    monkeypatch.setitem(sys.modules, "ray", None)  # import ray raises ImportError
    assert main(["sweep", path, "--out", str(tmp_path / "r.csv"), "--ray", "auto"]) == 2
    err = capsys.readouterr().err
    assert err == (
        "warpcloth: error: --ray needs Ray: pip install 'warpcloth[cluster]' "
        "(from a clone: pip install -e '.[cluster]')\n"
    )


def test_plan_warns_only_above_the_device_count(monkeypatch):
    monkeypatch.setattr(os, "cpu_count", lambda: 4)
    cpu_runs = [type("R", (), {"device": "cpu"})()]
    assert sweep.ParallelPlan.check(cpu_runs, 4).warning == ""
    assert "more than the 4 CPU cores" in sweep.ParallelPlan.check(cpu_runs, 5).warning
    cuda_runs = [type("R", (), {"device": "cuda:0"})()]
    assert "more than the 1 device(s) of the test list (cuda:0)" in sweep.ParallelPlan.check(cuda_runs, 2).warning
    assert not sweep.ParallelPlan.check(cpu_runs, None).parallel
    with pytest.raises(WarpclothError, match="--workers must be a whole number >= 1"):
        sweep.ParallelPlan.check(cpu_runs, 0)


# -- Ray ---------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def ray_cluster():
    ray = pytest.importorskip("ray", reason="Ray is not installed (pip install -e '.[cluster]')")
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    try:
        yield ray
    finally:
        ray.shutdown()


def _ray_task_pids():
    pids = []
    for d in os.listdir("/proc"):
        if d.isdigit():
            try:
                if open(f"/proc/{d}/cmdline", "rb").read().startswith(b"ray::_ray_unit"):
                    pids.append(int(d))
            except OSError:
                pass
    return pids


def test_ray_gives_the_serial_rows_though_a_task_is_killed(serial, ray_cluster, tmp_path, capsys):
    """sweep --ray on a local cluster, one Ray task killed mid-sweep: Ray runs its unit again and the
    driver writes every run once, with the serial run's values (not timings), each row from a Ray
    worker that lived (one test for both: each sweep through Ray costs its tasks' Warp start-ups)."""
    path, rows = serial
    out = tmp_path / "ray.csv"
    result = {}
    thread = threading.Thread(
        target=lambda: result.setdefault("rc", main(["sweep", path, "--out", str(out), "--ray", "auto"]))
    )
    thread.start()
    killed = None
    deadline = time.monotonic() + 120
    while killed is None and time.monotonic() < deadline and thread.is_alive():
        pids = _ray_task_pids()
        if pids:
            killed = pids[0]
            os.kill(killed, signal.SIGKILL)
        time.sleep(0.05)
    thread.join(timeout=300)
    assert killed is not None, "no Ray task was seen running"
    assert result.get("rc") == 0
    assert "running 4 runs as Ray tasks (auto)" in capsys.readouterr().err
    par = sweep.read_results(str(out))
    assert len(par) == 4 and len({r["key"] for r in par}) == 4  # retried by Ray, written once
    assert same_runs(rows, par)
    assert all(r["worker"].startswith("ray:") and r["host"] == socket.gethostname() for r in par)
    assert f"ray:{killed}" not in {r["worker"].split(":gpu")[0] for r in par}
    assert {r["concurrent_runs"] for r in par} <= {"1", "2"}


def test_a_worker_device_moves_cuda_runs_only_and_keeps_the_key(tmp_path, monkeypatch):
    from warpcloth.lab.parallel import Place

    path = write(tmp_path, TINY)
    spec = parse_test_list(path).runs[0]
    seen = []
    monkeypatch.setattr(
        sweep, "execute_run", lambda s, cache: seen.append(s.device) or {"key": s.key, "device": s.device}
    )
    monkeypatch.setattr(sweep, "_WORKER_CACHE", None)
    cuda = __import__("dataclasses").replace(spec, device="cuda:0")  # as parsed on a GPU machine
    row = sweep.parallel_run(cuda, Place("h", "local:2", "cuda:1"))
    assert seen == ["cuda:1"] and row["device"] == "cuda:1" and row["key"] == cuda.key
    row = sweep.parallel_run(spec, Place("h", "local:2", "cuda:1"))  # a CPU run stays on the CPU
    assert seen[-1] == "cpu" and row["key"] == spec.key


# -- a Ray address that does not answer fails fast (issue 17) -----------------------------------
def _closed_port() -> int:
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


def test_check_address_refuses_malformed_and_silent_addresses():
    from warpcloth.lab.parallel import check_address

    for bad in ("nonsense", "host:", ":6379", "host:99999", "ray://host:port", "host:-1"):
        with pytest.raises(
            ConnectionError, match="is not a Ray address: give auto, local, HOST:PORT or ray://HOST:PORT"
        ):
            check_address(bad)
    port = _closed_port()
    for address in (f"127.0.0.1:{port}", f"ray://127.0.0.1:{port}"):
        with pytest.raises(ConnectionError, match=f"nothing answers at 127.0.0.1:{port} within 5 s"):
            check_address(address)
    with socket.socket() as listening:  # something answers: passes
        listening.bind(("127.0.0.1", 0))
        listening.listen(1)
        check_address(f"127.0.0.1:{listening.getsockname()[1]}")
    check_address("auto")
    check_address("local")


def test_study_with_an_unreachable_ray_address_is_one_line_and_writes_nothing(tmp_path, capsys):
    pytest.importorskip("ray", reason="Ray is not installed (pip install -e '.[cluster]')")
    port = _closed_port()
    out = tmp_path / "out"
    assert (
        main(
            [
                "study",
                "--profile",
                "quick",
                "--integrators",
                "explicit_euler",
                "--sizes",
                "4",
                "--quiet",
                "--out",
                str(out),
                "--ray",
                f"127.0.0.1:{port}",
            ]
        )
        == 2
    )
    err = capsys.readouterr().err
    assert err.startswith(f"warpcloth: error: --ray 127.0.0.1:{port}: nothing answers at 127.0.0.1:{port} within 5 s")
    assert err.count("\n") == 1
    assert not (out / "results.csv").exists()


def test_study_via_ray_gives_the_serial_rows(ray_cluster, tmp_path, study_references):
    """The study of explicit_euler at 4x4 (stability, floors, trials, contact, timings) as Ray tasks:
    the serial run's keys and values (not timings); the driver wrote every row once. The float64
    references and floors are the session's (tests/conftest.py): placement is the point, and every
    float32 run is measured again in the Ray tasks against them."""
    from dataclasses import replace

    from warpcloth.lab.plan import make_plan
    from warpcloth.lab.results import read_rows
    from warpcloth.lab.study import run_study

    plan = make_plan("quick", integrators=["explicit_euler"], sizes=[4])
    plan = replace(plan, reference_cache=str(study_references))
    run_study(plan, tmp_path / "serial")
    run_study(plan, tmp_path / "ray", ray="auto")
    serial, par = read_rows(tmp_path / "serial" / "results.csv"), read_rows(tmp_path / "ray" / "results.csv")
    same = [
        "measurement",
        "scenario",
        "integrator",
        "dt_s",
        "steps_per_frame",
        "bound_dt_s",
        "error_rel",
        "floor_point_rel",
        "max_strain_rel",
        "stable",
        "equilibrium_reached",
        "time_to_equilibrium_sim_s",
        "static_error_rel",
        "trials",
    ]
    assert sorted(r["key"] for r in serial) == sorted(r["key"] for r in par)
    by_key = {r["key"]: r for r in par}
    for r in serial:
        assert {c: r[c] for c in same} == {c: by_key[r["key"]][c] for c in same}, r["key"]
    assert all(r["worker"].startswith("ray:") and r["host"] == socket.gethostname() for r in par)
    assert all(r["concurrent_runs"] == 1 for r in par if r["measurement"] == "timing")
    # the cluster's workers outlive a study: a second study of the same plan still gets every row
    run_study(plan, tmp_path / "ray2", ray="auto")
    assert sorted(r["key"] for r in read_rows(tmp_path / "ray2" / "results.csv")) == sorted(by_key)


# -- issue 31: workers exit when their driver dies -------------------------------------------------
DRIVER = """
import sys, time
sys.path.insert(0, {tests!r})
from parallel_toy import toy
from warpcloth.lab.parallel import Job, LocalPool
if __name__ == "__main__":  # the spawned workers import this file
    for done in LocalPool(toy, 2).run([Job("a", ("ok", "a")), Job("b", ("sleep", 600)), Job("c", ("sleep", 600))]):
        print("done", done.job.key, done.row["pid"], flush=True)
"""


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    try:  # a zombie of ours counts as gone
        with open(f"/proc/{pid}/stat") as f:
            return f.read().split(")")[-1].split()[0] != "Z"
    except OSError:
        return True


def test_workers_exit_when_their_driver_is_killed(tmp_path):
    script = tmp_path / "driver.py"
    script.write_text(DRIVER.format(tests=str(Path(__file__).resolve().parent)))
    proc = subprocess.Popen([sys.executable, str(script)], stdout=subprocess.PIPE, text=True)
    try:
        line = proc.stdout.readline()  # job a is done: both workers are up, the other busy sleeping
        assert line.startswith("done a"), line
        children = [int(p) for p in open(f"/proc/{proc.pid}/task/{proc.pid}/children").read().split()]
        workers = [p for p in children if "spawn_main" in open(f"/proc/{p}/cmdline").read().replace("\0", " ")]
        assert len(workers) == 2, children
        os.kill(proc.pid, signal.SIGKILL)  # the driver only, as `kill -9`
        proc.wait(timeout=60)
        deadline = time.monotonic() + 60  # a liveness bound, not a timing: they would sleep 600 s
        while any(_alive(p) for p in workers) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert not any(_alive(p) for p in workers), "workers ran on after their driver died"
    finally:
        proc.kill()
        for p in workers if "workers" in locals() else []:
            try:
                os.kill(p, signal.SIGKILL)
            except ProcessLookupError:
                pass
