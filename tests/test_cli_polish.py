"""CLI polish (issue 16): --quiet everywhere, progress with an ETA, bench --json and --out -,
--duration/--num-frames exclusive, --fail-unstable, python -m warpcloth, shipped examples."""

import csv
import io
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from warpcloth.cli import main
from warpcloth.cli.listing import example_path
from warpcloth.io import progress as progress_module
from warpcloth.io.progress import Progress

REPO = Path(__file__).resolve().parents[1]
BENCH = [
    "bench",
    "--integrators",
    "explicit_euler",
    "--sizes",
    "4",
    "--steps",
    "3",
    "--graph",
    "off",
    "--devices",
    "cpu",
]


def _run(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def _usage_error(capsys, *argv):
    with pytest.raises(SystemExit) as exit_:
        main(list(argv))
    err = capsys.readouterr().err
    return exit_.value.code, err


@pytest.mark.parametrize(
    "argv",
    [
        ["run", "sheet", "--rows", "4", "--cols", "4", "--num-frames", "3"],
        ["list"],
        ["list", "--examples"],
        [
            "max-dt",
            "sheet",
            "--rows",
            "4",
            "--cols",
            "4",
            "--duration",
            "0.05",
            "--precision",
            "0.5",
            "--start",
            "1e-3",
        ],
        BENCH,
    ],
)
def test_quiet_prints_nothing_on_success(capsys, argv):
    code, out, err = _run(capsys, *argv)
    assert code == 0 and out.strip(), "without --quiet the command prints something"
    code, out, err = _run(capsys, *argv, "--quiet")
    assert code == 0, err
    assert out == "" and err == ""


def test_quiet_run_still_writes_outputs_and_errors(capsys, tmp_path):
    usd = tmp_path / "q.usda"
    code, out, err = _run(
        capsys, "run", "sheet", "--rows", "4", "--cols", "4", "--num-frames", "2", "--usd", str(usd), "-q"
    )
    assert code == 0 and out == "" and err == "" and usd.exists()
    code, out, err = _run(capsys, "run", "sheet", "--rows", "4", "--cols", "4", "--num-frames", "2", "--json", "-q")
    assert code == 0 and json.loads(out)["rows"] == 4  # what --json asks for still prints
    code, out, err = _run(capsys, "run", "sheet", "--rows", "0", "-q")
    assert code == 2 and err.startswith("warpcloth: error:") and err.count("\n") == 1


def test_duration_and_num_frames_are_exclusive(capsys):
    code, err = _usage_error(capsys, "run", "sheet", "--duration", "1", "--num-frames", "5")
    assert code == 2 and err.startswith("warpcloth: error:") and "not allowed with" in err and err.count("\n") == 1


def test_fail_unstable_exits_3(capsys):
    argv = ["run", "sheet", "--rows", "8", "--cols", "8", "--dt", "0.004", "--duration", "1"]
    code, out, err = _run(capsys, *argv)
    assert code == 0 and "stable: NO" in out  # without the flag an unstable run is a result, status 0
    code, out, err = _run(capsys, *argv, "--fail-unstable")
    assert code == 3 and "went unstable" in err
    code, out, err = _run(capsys, *argv, "--fail-unstable", "--json")
    assert code == 3 and json.loads(out)["stable"] is False
    code, out, err = _run(capsys, "run", "sheet", "--rows", "4", "--cols", "4", "--num-frames", "2", "--fail-unstable")
    assert code == 0


def test_python_dash_m_warpcloth():
    env = dict(os.environ, PYTHONPATH=str(REPO))
    p = subprocess.run(
        [sys.executable, "-m", "warpcloth", "list"], capture_output=True, text=True, env=env, timeout=300
    )
    assert p.returncode == 0 and "scenarios:" in p.stdout and "integrators:" in p.stdout
    p = subprocess.run(
        [sys.executable, "-m", "warpcloth", "run", "nope"], capture_output=True, text=True, env=env, timeout=300
    )
    assert p.returncode == 2 and p.stderr.startswith("warpcloth: error:")


def test_examples_ship_with_the_package(capsys):
    code, out, err = _run(capsys, "list", "--examples")
    assert code == 0
    rows = [line.rsplit(None, 2) for line in out.strip().splitlines()]
    rows = [r for r in rows if len(r) == 3]
    files = {(kind.strip(), name): path for kind, name, path in rows if os.path.isabs(path)}
    assert set(files) == {
        ("test list:", "quick"),
        ("test list:", "seed_plan"),
        ("mesh:", "cape"),
        ("scenario file:", "cape"),
    }
    for (kind, name), path in files.items():
        shipped = REPO / "warpcloth" / "examples" / os.path.basename(path)
        assert os.path.isfile(path) and Path(path).read_bytes() == shipped.read_bytes()
        if kind == "test list:":
            assert path == example_path(name)
    assert "python -m warpcloth.examples.drive" in out and "python -m warpcloth.examples.make_cape" in out
    from warpcloth.lab.testlist import parse_test_list

    assert parse_test_list(example_path("quick")).runs  # a valid test list
    code, out, err = _run(capsys, "sweep", "--example", "nope", "--out", "-")
    assert code == 2 and "quick, seed_plan" in err
    code, out, err = _run(capsys, "sweep", "--out", "-")
    assert code == 2 and "--example" in err
    # the package data declares them (a wheel holds them; checked by building one: see the report)
    text = (REPO / "pyproject.toml").read_text()
    assert '"warpcloth.examples" = ["*.xml", "*.obj", "*.toml"]' in text


def test_bench_json_and_out_dash(capsys):
    code, out, err = _run(capsys, *BENCH, "--json")
    assert code == 0, err
    d = json.loads(out)
    assert len(d["rows"]) == 1 and d["rows"][0]["integrator"] == "explicit_euler" and d["rows"][0]["particles"] == 16
    assert "integrator" in err  # the table went to stderr
    code, out, err = _run(capsys, *BENCH, "--out", "-")
    assert code == 0, err
    rows = list(csv.DictReader(io.StringIO(out)))
    assert len(rows) == 1 and rows[0]["device"] == "cpu"
    code, out, err = _run(capsys, *BENCH, "--out", "-", "--json")
    assert code == 2 and "choose one" in err


def test_bench_plot_without_matplotlib_fails_before_timing(capsys, tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "matplotlib", None)
    code, out, err = _run(capsys, *BENCH, "--plot", str(tmp_path / "b.png"))
    assert code == 2 and out == "" and "pip install -e '.[plot]'" in err and "bench: explicit_euler" not in err


class _Clock:
    def __init__(self):
        self.t = 0.0

    def __call__(self):
        return self.t


def test_progress_tty_line_with_eta():
    stream, clock = io.StringIO(), _Clock()
    p = Progress("run sheet", stream, tty=True, clock=clock)
    clock.t = 2.0
    p.update(1.0, 4.0, unit=" s simulated")
    text = stream.getvalue()
    assert text.startswith("\r") and "25%" in text and "ETA 6 s" in text and "\n" not in text
    p.close()
    assert stream.getvalue().endswith("\r")


def test_progress_plain_lines_are_rare():
    stream, clock = io.StringIO(), _Clock()
    p = Progress("run", stream, tty=False, clock=clock)
    clock.t = 1.0
    p.update(1, 10)
    assert stream.getvalue() == ""  # short work prints nothing
    clock.t = 6.0
    p.update(5, 10)
    clock.t = 7.0
    p.update(6, 10)
    lines = stream.getvalue().splitlines()
    assert len(lines) == 1 and "50%" in lines[0] and "ETA 6 s" in lines[0] and "\r" not in lines[0]


def test_run_shows_progress_on_a_terminal(capsys, monkeypatch):
    monkeypatch.setattr(progress_module, "_isatty", lambda stream: True)
    monkeypatch.setattr(progress_module, "TTY_INTERVAL", 0.0)
    code, out, err = _run(capsys, "run", "flag", "--rows", "4", "--cols", "4", "--num-frames", "6")
    assert code == 0 and "\r" in err and "run flag" in err and "ETA" in err
    assert "\r" not in out
    code, out, err = _run(
        capsys,
        "max-dt",
        "sheet",
        "--rows",
        "4",
        "--cols",
        "4",
        "--duration",
        "0.05",
        "--precision",
        "0.5",
        "--start",
        "1e-3",
    )
    assert code == 0 and "trial 1: dt=" in err and "ETA" in err
