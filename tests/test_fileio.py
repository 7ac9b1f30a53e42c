"""No data loss (issue 19): --resume never changes a file it refuses, one writer per results
file, full disks and closed pipes end with one line, output paths are checked before the work,
stale temporaries are removed, SIGTERM cleans up. CPU only; no wall-clock assertions."""

import errno
import os
import re
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

import warpcloth.lab.sweep as sweep
from warpcloth.cli import main
from warpcloth.io import files as fileio

REPO = Path(__file__).resolve().parents[1]
WARPCLOTH = [sys.executable, "-m", "warpcloth.cli"]

# 3 integrators x 4 sizes x 2 scenarios = 24 short runs
K_XML = """
<test_list dt="1e-3" duration="0.05" wall_cap="30">
  <test integrator="explicit_euler verlet rk4" size="4 5 6 7" scenario="sheet flag"/>
</test_list>
"""


def write(tmp_path, text, name="k.xml"):
    path = tmp_path / name
    path.write_text(textwrap.dedent(text).lstrip())
    return str(path)


def err_lines(err):
    return [line for line in err.splitlines() if line.strip()]


def no_temporaries(folder):
    return [n for n in os.listdir(folder) if n.startswith(".warpcloth-") or n.startswith(".bench-")]


# -- 1. --resume validates before it changes anything -----------------------------------------
@pytest.mark.parametrize(
    "content",
    [b"name,score\nalice,1\nbob,2", bytes(range(256)) * 20 + b"tail without newline"],
    ids=["foreign-csv", "binary"],
)
def test_refused_resume_leaves_the_file_byte_identical(tmp_path, monkeypatch, capsys, content):
    path = write(tmp_path, K_XML)
    out = tmp_path / "s.csv"
    out.write_bytes(content)
    monkeypatch.setattr(sweep, "execute_run", lambda *a: pytest.fail("a run started"))
    assert main(["sweep", path, "-o", str(out), "--resume"]) == 2
    err = capsys.readouterr().err
    assert (
        err_lines(err) == [l for l in err_lines(err) if l.startswith("warpcloth: error: cannot resume")]
        and len(err_lines(err)) == 1
    )
    assert out.read_bytes() == content  # was cut to its last newline before the refusal
    assert sorted(os.listdir(tmp_path)) == ["k.xml", "s.csv"]  # no side file, no lock, no temporary


def test_resume_keeps_a_copy_of_the_dropped_partial_line(tmp_path, capsys):
    path = write(tmp_path, '<test_list><test integrator="verlet" size="4" dt="1e-3" duration="0.05"/></test_list>')
    out = tmp_path / "r.csv"
    assert main(["sweep", path, "-o", str(out), "-q"]) == 0
    full = out.read_bytes()
    cut = full[: full.rstrip(b"\n").rfind(b"\n") + 1 + 30]  # the last row cut after 30 bytes
    out.write_bytes(cut)
    capsys.readouterr()
    assert main(["sweep", path, "-o", str(out), "--resume", "-q"]) == 0  # said even with --quiet
    err = capsys.readouterr().err
    (side,) = [p for p in tmp_path.iterdir() if p.name.startswith("r.csv.dropped-")]
    assert side.read_bytes() == cut[-30:]
    assert "dropped an incomplete last line (30 bytes" in err and side.name in err
    assert len(sweep.read_results(str(out))) == 2


# -- 2. one writer per results file -----------------------------------------------------------
HOLD = textwrap.dedent("""
    import os, sys, time
    import warpcloth.lab.sweep as s
    real, go = s.execute_run, sys.argv.pop(1)
    def run(spec, cache):
        while not os.path.exists(go):
            time.sleep(0.05)
        return real(spec, cache)
    s.execute_run = run
    from warpcloth.cli import main
    sys.exit(main(sys.argv[1:]))
""")


def test_a_second_writer_is_refused_while_the_first_finishes_intact(tmp_path, capsys):
    path = write(tmp_path, K_XML)
    out = tmp_path / "r.csv"
    go = tmp_path / "go"
    first = subprocess.Popen(
        [sys.executable, "-c", HOLD, str(go), "sweep", path, "-o", str(out), "--overwrite", "-q"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        deadline = time.monotonic() + 120
        while not (out.exists() and out.stat().st_size > 0) and first.poll() is None and time.monotonic() < deadline:
            time.sleep(0.05)
        assert first.poll() is None, first.communicate()
        for mode in ("--overwrite", "--resume"):
            assert main(["sweep", path, "-o", str(out), mode, "-q"]) == 2
            (line,) = err_lines(capsys.readouterr().err)
            assert line.startswith(f"warpcloth: error: {out} is being written by another warpcloth (pid {first.pid}")
        go.touch()
        stdout, stderr = first.communicate(timeout=300)
    finally:
        if first.poll() is None:
            first.kill()
    assert first.returncode == 0, stderr
    assert "24 runs written" in stdout
    keys = [r["key"] for r in sweep.read_results(str(out))]
    assert len(keys) == len(set(keys)) == 24
    assert not (tmp_path / ".r.csv.lock").exists()  # released
    assert main(["sweep", path, "-o", str(out), "--resume", "-q"]) == 0  # and free again


def test_writer_lock_in_process(tmp_path):
    target = tmp_path / "x.csv"
    with fileio.WriterLock(str(target)):
        with pytest.raises(fileio.WarpclothError, match=rf"pid {os.getpid()}"):
            fileio.WriterLock(str(target)).acquire()
    with fileio.WriterLock(str(target)):
        pass


# -- 3. full disks ---------------------------------------------------------------------------
@pytest.fixture
def small_disk(tmp_path):
    """A 64 KiB tmpfs (where the test may mount one), else None: tests then patch a writer to
    raise ENOSPC."""
    folder = tmp_path / "full"
    folder.mkdir()
    if sys.platform != "linux" or os.geteuid() != 0:
        yield None
        return
    mounted = (
        subprocess.run(["mount", "-t", "tmpfs", "-o", "size=64k", "tmpfs", str(folder)], capture_output=True).returncode
        == 0
    )
    if not mounted:
        yield None
        return
    try:
        yield folder
    finally:
        subprocess.run(["umount", str(folder)], capture_output=True)


def _enospc(*args, **kwargs):
    raise OSError(errno.ENOSPC, "No space left on device")


def test_usd_on_a_full_disk_is_one_line_and_leaves_the_target(tmp_path, small_disk, monkeypatch, capsys):
    folder = small_disk or tmp_path
    target = folder / "a.usda"
    target.write_text("old")
    if small_disk is None:
        import warpcloth.io.usd as usd

        monkeypatch.setattr(usd.os, "replace", _enospc)
    code = main(["run", "sheet", "--duration", "1", "--usd", str(target)])
    err = capsys.readouterr().err
    assert code == fileio.EXIT_IO
    (line,) = err_lines(err)
    assert line.startswith(f"warpcloth: error: no space left on the device of {folder} writing the USD file {target}")
    assert "unchanged" in line
    assert target.read_text() == "old"
    assert no_temporaries(folder) == []


def test_sweep_on_a_full_disk_is_one_line_and_resume_recovers(tmp_path, small_disk, monkeypatch, capsys):
    path = write(tmp_path, K_XML)
    folder = small_disk or tmp_path
    out = folder / "r.csv"
    if small_disk is not None:
        (folder / "filler").write_bytes(b"\0" * 50000)
    else:
        real_write, calls = sweep.CsvOutput.write, []

        def failing(self, row):
            calls.append(row)
            if len(calls) == 5:
                self.fh.write(sweep.format_row(row)[:40])  # a partial row, as a full disk leaves it
                self.fh.flush()
                _enospc()
            return real_write(self, row)

        monkeypatch.setattr(sweep.CsvOutput, "write", failing)
    assert main(["sweep", path, "-o", str(out), "-q"]) == fileio.EXIT_IO
    (line,) = err_lines(capsys.readouterr().err)
    assert line.startswith(f"warpcloth: error: no space left on the device of {folder} writing the results CSV {out}")
    assert "Traceback" not in line and "rows before it are kept" in line
    assert no_temporaries(folder) == []
    written = len(sweep.read_results(str(out))) if out.read_bytes().endswith(b"\n") else None
    if small_disk is not None:
        (folder / "filler").unlink()
    else:
        monkeypatch.setattr(sweep.CsvOutput, "write", real_write)
    assert main(["sweep", path, "-o", str(out), "--resume", "-q"]) == 0
    keys = [r["key"] for r in sweep.read_results(str(out))]
    assert len(keys) == len(set(keys)) == 24
    assert written is None or written < 24


def test_bench_csv_on_a_full_disk_is_one_line(tmp_path, small_disk, monkeypatch, capsys):
    from warpcloth.cli.bench import main as bench_main
    from warpcloth.lab import bench

    folder = small_disk or tmp_path
    target = folder / "b.csv"
    target.write_text("old")
    if small_disk is not None:
        (folder / "filler").write_bytes(b"\0" * (64 * 1024 - 8192))
    monkeypatch.setattr(
        bench,
        "bench_one",
        lambda name, size, device, graph, steps, seconds, scenario="sheet", windows=5: (
            dict.fromkeys(bench.COLUMNS, 1)
            | {
                "integrator": name,
                "device": device,
                "graph": graph,
                "rows": size,
                "cols": size,
                "particles": size * size,
                "ms_per_step_median": 1.0,
                "steps_per_s": 1000.0,
                "realtime_factor": 1.0,
                "floor_multiple": "",
                "speedup_vs_cpu": "",
                "solver_iterations_mean": "x" * 4000,
            }
        ),
    )
    if small_disk is None:
        monkeypatch.setattr(fileio.os, "fsync", _enospc)
    code = bench_main(["--sizes", "4,5,6", "--steps", "1", "--devices", "cpu", "--graph", "off", "--out", str(target)])
    err = capsys.readouterr().err
    assert code == fileio.EXIT_IO
    lines = [l for l in err_lines(err) if not l.startswith("bench:")]
    assert len(lines) == 1 and lines[0].startswith(
        f"warpcloth: error: no space left on the device of {folder} writing the benchmark CSV"
    )
    assert "bytes needed" in lines[0]
    assert target.read_text() == "old"
    assert no_temporaries(folder) == []


# -- 4. closed and full output pipes -----------------------------------------------------------
def test_closed_stdout_pipe_ends_quietly(tmp_path):
    path = write(tmp_path, K_XML)
    proc = subprocess.Popen(
        WARPCLOTH + ["sweep", path, "-o", "-", "-q"], stdout=subprocess.PIPE, stderr=subprocess.PIPE
    )
    proc.stdout.read(200)
    proc.stdout.close()  # like `| head -c 200`
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=300) == 141
    assert err == ""


@pytest.mark.skipif(not os.path.exists("/dev/full"), reason="no /dev/full")
def test_full_stdout_is_one_line(tmp_path):
    path = write(tmp_path, K_XML)
    with open("/dev/full", "w") as full:
        proc = subprocess.run(
            WARPCLOTH + ["sweep", path, "-o", "-", "-q"], stdout=full, stderr=subprocess.PIPE, text=True, timeout=300
        )
    assert proc.returncode == fileio.EXIT_IO
    assert err_lines(proc.stderr) == ["warpcloth: error: cannot write the CSV to stdout: No space left on device"]


# -- 5. output paths are checked before the work ------------------------------------------------
def _immutable(path):
    path.write_text("keep")
    if subprocess.run(["chattr", "+i", str(path)], capture_output=True).returncode != 0:
        pytest.skip("chattr +i is not available here")
    return path


@pytest.fixture
def immutable_file(tmp_path):
    made = []

    def make(ext):
        p = tmp_path / f"immutable{ext}"
        made.append(p)
        return _immutable(p)

    yield make
    for p in made:
        subprocess.run(["chattr", "-i", str(p)], capture_output=True)


BAD_TARGETS = {
    "folder": (lambda tmp, ext: (tmp / f"dir{ext}").mkdir() or str(tmp / f"dir{ext}"), "is a folder, not a file"),
    "proc": (lambda tmp, ext: f"/proc/warpcloth{ext}", "folder '/proc' is not writable (creating a file there failed"),
    "long name": (lambda tmp, ext: str(tmp / ("a" * 300 + ext)), "more than the 255 this file system allows"),
    "missing folder": (lambda tmp, ext: str(tmp / "no" / f"x{ext}"), "does not exist"),
}


@pytest.mark.parametrize("case", list(BAD_TARGETS) + ["immutable"])
def test_bench_out_is_refused_before_the_benchmark(tmp_path, monkeypatch, capsys, immutable_file, case):
    from warpcloth.cli.bench import main as bench_main
    from warpcloth.lab import bench

    if case == "immutable":
        target, message = str(immutable_file(".csv")), "cannot be replaced: Operation not permitted"
    else:
        make, message = BAD_TARGETS[case]
        target = make(tmp_path, ".csv")
    monkeypatch.setattr(bench, "bench_one", lambda *a, **k: pytest.fail("the benchmark started"))
    assert bench_main(["--sizes", "4", "--steps", "1", "--devices", "cpu", "--out", target]) == 2
    lines = [l for l in err_lines(capsys.readouterr().err) if not l.startswith("bench:")]
    assert len(lines) == 1 and lines[0].startswith("warpcloth: error: --out path") and message in lines[0]
    assert no_temporaries(tmp_path) == []


@pytest.mark.parametrize("case", list(BAD_TARGETS) + ["immutable"])
def test_usd_path_is_refused_before_the_run(tmp_path, monkeypatch, capsys, immutable_file, case):
    from warpcloth.scenarios.common import Scenario

    if case == "immutable":
        target, message = str(immutable_file(".usda")), "cannot be replaced: Operation not permitted"
    else:
        make, message = BAD_TARGETS[case]
        target = make(tmp_path, ".usda")
    monkeypatch.setattr(Scenario, "build", lambda *a, **k: pytest.fail("the run started"))
    assert main(["run", "sheet", "--usd", target]) == 2
    (line,) = err_lines(capsys.readouterr().err)
    assert line.startswith("warpcloth: error: USD path") and message in line
    assert no_temporaries(tmp_path) == []


# -- 6. stale temporaries, 10.15 SIGTERM ----------------------------------------------------------
def _dead_pid():
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


def test_stale_temporaries_of_dead_processes_are_removed_and_reported(tmp_path, capsys):
    dead = _dead_pid()
    stale = [tmp_path / f".warpcloth-{dead}-0a1b2c3d.usda", tmp_path / f".warpcloth-{dead}-0a1b2c3d.usda.Ab12Cd"]
    for p in stale:
        p.write_text("partial")
    live = tmp_path / f".warpcloth-{os.getpid()}-feedbeef.usda"  # a running writer's: kept
    live.write_text("mine")
    other = tmp_path / ".warpcloth-notapid.usda"  # not our pattern: kept
    other.write_text("?")
    target = tmp_path / "out.usda"
    assert main(["run", "sheet", "--rows", "4", "--cols", "4", "--duration", "0.05", "--usd", str(target)]) == 0
    err = capsys.readouterr().err
    assert not any(p.exists() for p in stale) and live.exists() and other.exists() and target.exists()
    (line,) = [l for l in err_lines(err) if "stale" in l]
    assert line.startswith(f"warpcloth: removed 2 stale temporary file(s) of dead warpcloth processes in {tmp_path}")


def test_sigterm_during_run_usd_removes_the_temporary(tmp_path):
    target = tmp_path / "t.usda"
    proc = subprocess.Popen(
        WARPCLOTH + ["run", "sheet", "--rows", "40", "--cols", "40", "--duration", "600", "--usd", str(target)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        deadline = time.monotonic() + 120
        while not no_temporaries(tmp_path) and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.05)
        assert proc.poll() is None and no_temporaries(tmp_path), proc.communicate()
        time.sleep(0.5)  # inside the run loop
        proc.send_signal(signal.SIGTERM)
        _out, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 143
    assert err_lines(err) == ["warpcloth: terminated (SIGTERM)"]
    assert no_temporaries(tmp_path) == [] and not target.exists()


@pytest.mark.skipif(not os.path.exists("/dev/full"), reason="no /dev/full")
@pytest.mark.parametrize(
    "argv", [["list"], ["run", "sheet", "--rows", "4", "--cols", "4", "--duration", "0.05", "--json"]]
)
def test_any_command_onto_a_full_stdout_is_one_line(argv):
    with open("/dev/full", "w") as full:
        proc = subprocess.run(WARPCLOTH + argv, stdout=full, stderr=subprocess.PIPE, text=True, timeout=300)
    assert proc.returncode == fileio.EXIT_IO
    assert err_lines(proc.stderr) == ["warpcloth: error: cannot write to stdout: No space left on device"]


# -- issue 31: disk full during value clips; inputs that block --------------------------------------
def _enospc_tf(*args):
    raise RuntimeError(
        "\n\tError in 'ArFilesystemWritableAsset::Write' at line 78: 'Error occurred writing file: "
        "No space left on device'\n" * 40
    )


def test_usd_clips_on_a_full_disk_are_one_line_exit_74(tmp_path, small_disk, monkeypatch, capsys):
    import warpcloth.io.usd as usd

    folder = small_disk or tmp_path
    target = folder / "a.usdc"
    monkeypatch.setattr(usd, "CLIP_BYTES", 20_000)  # a clip every few frames of a 16 x 16 sheet
    if small_disk is None:  # pxr's text for a clip that does not fit
        monkeypatch.setattr(usd.UsdWriter, "_flush_clip", _enospc_tf)
    code = main(["run", "sheet", "--rows", "16", "--cols", "16", "--duration", "2", "--usd", str(target), "--quiet"])
    err = capsys.readouterr().err
    assert code == fileio.EXIT_IO, err
    (line,) = err_lines(err)
    assert line.startswith(
        f"warpcloth: error: no space left on the device of {folder} writing the USD file {target}"
    ), line
    assert not target.exists() and no_temporaries(folder) == []


def test_input_files_are_regular_files_of_bounded_size_read_without_blocking(tmp_path):
    from helpers import unblocked_fifo

    (tmp_path / "a.txt").write_bytes(b"x" * 100)
    assert fileio.read_input(str(tmp_path / "a.txt"), "input", 100) == b"x" * 100
    with pytest.raises(
        fileio.WarpclothError, match=r"input '.*a.txt' is 100 bytes, more than the 99 bytes warpcloth reads"
    ):
        fileio.read_input(str(tmp_path / "a.txt"), "input", 99)
    with pytest.raises(fileio.WarpclothError, match="is a folder, not a file"):
        fileio.check_input_file(str(tmp_path), "input")
    with pytest.raises(fileio.WarpclothError, match="does not exist"):
        fileio.check_input_file(str(tmp_path / "none"), "input")
    for special in ("/proc/kmsg", "/proc/self/status", "/sys/kernel/mm/transparent_hugepage/enabled", "/dev/zero"):
        if os.path.exists(special):
            with pytest.raises(fileio.WarpclothError, match="not a regular file"):
                fileio.check_input_file(special, "input")
    with unblocked_fifo(tmp_path / "pipe") as fifo:
        with pytest.raises(fileio.WarpclothError, match="is a FIFO, not a regular file"):
            fileio.read_input(str(tmp_path / "pipe"), "input")
    assert fifo.opened == 0
    with pytest.raises(fileio.WarpclothError, match="input must be a file name, got 123"):
        fileio.check_input_file(123, "input")


# -- folders (an OBJ sequence) and write_obj: the same safety as single files -------------------
FRAMES = re.compile(r"^f\d+\.txt$")


def _fill(folder, texts):
    for k, text in enumerate(texts):
        fileio.write_atomic(folder.file(f"f{k}.txt"), text)


@pytest.mark.parametrize("exchange", [True, False], ids=["swap", "aside-and-back"])
def test_atomic_folder_replaces_an_older_folder_only_on_commit(tmp_path, monkeypatch, exchange):
    target = tmp_path / "out"
    with fileio.AtomicFolder(str(target), "test folder", FRAMES) as f:
        _fill(f, ["a", "b"])
        assert not target.exists() and os.path.isdir(f.tmp)
    assert sorted(p.name for p in target.iterdir()) == ["f0.txt", "f1.txt"]
    if not exchange:  # a system without renameat2's swap: the old folder goes aside, then away
        monkeypatch.setattr(fileio, "_exchange", lambda a, b: False)
    f = fileio.AtomicFolder(str(target), "test folder", FRAMES)
    _fill(f, ["new"])
    assert (target / "f1.txt").read_text() == "b"  # untouched until commit
    assert f.commit() == str(target) and f.commit() == str(target)
    assert sorted(p.name for p in target.iterdir()) == ["f0.txt"] and (target / "f0.txt").read_text() == "new"
    assert no_temporaries(tmp_path) == [] and sorted(os.listdir(tmp_path)) == ["out"]


def test_atomic_folder_abort_and_failed_commit_leave_the_target(tmp_path):
    target = tmp_path / "out"
    target.mkdir()
    (target / "f0.txt").write_text("old")
    with pytest.raises(RuntimeError):
        with fileio.AtomicFolder(str(target), "test folder", FRAMES) as f:
            _fill(f, ["new"])
            raise RuntimeError("the run failed")
    assert [p.name for p in target.iterdir()] == ["f0.txt"] and (target / "f0.txt").read_text() == "old"
    f = fileio.AtomicFolder(str(target), "test folder", FRAMES)
    _fill(f, ["new"])
    (target / "mine.txt").write_text("a user's file, put there during the run")
    with pytest.raises(fileio.WarpclothError, match="holding other files"):
        f.commit()
    assert (target / "f0.txt").read_text() == "old" and (target / "mine.txt").exists()
    assert no_temporaries(tmp_path) == []
    with pytest.raises(fileio.WarpclothError, match="not a file name this folder holds"):
        fileio.AtomicFolder(str(tmp_path / "x"), "test folder", FRAMES).file("../f0.txt")


def test_check_output_folder_refuses_links_files_and_foreign_folders(tmp_path):
    (tmp_path / "real").mkdir()
    (tmp_path / "link").symlink_to(tmp_path / "real")
    (tmp_path / "file").write_text("x")
    ok = tmp_path / "ours"
    ok.mkdir()
    (ok / "f3.txt").write_text("an earlier output")
    assert fileio.check_output_folder(str(ok), "test folder", FRAMES) == str(ok)
    assert fileio.check_output_folder(str(tmp_path / "new"), "test folder", FRAMES) == str(tmp_path / "new")
    (ok / "sub").mkdir()
    for path, why in [
        (tmp_path / "link", "is a link; warpcloth does not write through links"),
        (tmp_path / "file", "exists and is not a folder"),
        (ok, "is a folder holding other files ('sub')"),
        (tmp_path / "none" / "x", "does not exist"),
        ("", "path is empty"),
    ]:
        with pytest.raises(fileio.WarpclothError, match=re.escape(why)):
            fileio.check_output_folder(str(path), "test folder", FRAMES)
    assert no_temporaries(tmp_path) == []


def test_a_stale_temporary_folder_is_swept(tmp_path):
    dead = _dead_pid()
    stale = tmp_path / f".warpcloth-{dead}-0a1b2c3d"
    stale.mkdir()
    (stale / "frame_0000.obj").write_text("partial")
    assert fileio.sweep_stale_temporaries(str(tmp_path)) == [str(stale)]
    assert not stale.exists()


def test_write_obj_is_atomic_and_never_writes_through_a_link(tmp_path):
    from warpcloth.io.meshio import read_obj, write_obj

    v = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    t = np.array([[0, 1, 2]])
    precious = tmp_path / "precious.txt"
    precious.write_text("not a mesh")
    link = tmp_path / "m.obj"
    link.symlink_to(precious)
    write_obj(str(link), v, t)
    assert precious.read_text() == "not a mesh" and not link.is_symlink()
    np.testing.assert_array_equal(read_obj(str(link)).vertices, v)
    with pytest.raises(fileio.OutputError, match="unchanged"):
        write_obj(str(tmp_path / "none" / "m.obj"), v, t)
    assert no_temporaries(tmp_path) == []
