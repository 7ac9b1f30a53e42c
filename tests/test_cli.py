"""The command line: JSON output, summaries, and one-line errors with exit status 2."""

import json
import math
import subprocess
import sys
from pathlib import Path

import pytest

from warpcloth.cli import main

REPO = Path(__file__).resolve().parents[1]


def run_cli(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_run_json_parses_and_is_consistent(capsys):
    code, out, _err = run_cli(capsys, "run", "sheet", "--rows", "6", "--cols", "7", "--duration", "0.5", "--json")
    assert code == 0
    d = json.loads(out)
    for key in [
        "scenario",
        "integrator",
        "device",
        "rows",
        "cols",
        "particles",
        "springs",
        "dt",
        "steps",
        "sim_time",
        "wall_time",
        "ms_per_step",
        "steps_per_sec",
        "realtime_factor",
        "stable",
        "equilibrium_reached",
        "time_to_equilibrium",
        "max_strain",
    ]:
        assert key in d, key
    assert d["scenario"] == "sheet" and d["rows"] == 6 and d["cols"] == 7 and d["particles"] == 42
    assert math.isclose(d["steps"] * d["dt"], d["sim_time"], rel_tol=1e-12)
    assert d["sim_time"] >= 0.5 - d["dt"] or d["equilibrium_reached"]


def test_run_summary_and_flags(capsys, tmp_path):
    usd = tmp_path / "f.usda"
    code, out, err = run_cli(
        capsys,
        "run",
        "flag",
        "-i",
        "rk4",
        "--rows",
        "5",
        "--cols",
        "6",
        "--dt",
        "1e-3",
        "--duration",
        "0.2",
        "--fps",
        "30",
        "--stiffness",
        "800,600,100",
        "--damping",
        "0.1",
        "--mass",
        "0.2",
        "--usd",
        str(usd),
    )
    assert code == 0, err
    assert "flag: rk4 on cpu, 5x6" in out and "dt=0.001" in out and "stable: yes" in out
    assert usd.exists()


def test_num_frames_sets_duration(capsys):
    code, out, _err = run_cli(
        capsys, "run", "sheet", "--rows", "4", "--cols", "4", "--num-frames", "6", "--fps", "60", "--json"
    )
    assert code == 0
    assert math.isclose(json.loads(out)["sim_time"], 0.1, abs_tol=json.loads(out)["dt"])


def test_list(capsys):
    code, out, _ = run_cli(capsys, "list")
    assert code == 0
    for name in ["sheet", "flag", "explicit_euler", "midpoint", "rk4", "verlet"]:
        assert name in out


@pytest.mark.parametrize(
    "argv,message",
    [
        (["run", "sheet", "--rows", "1"], "rows must be an integer >= 3, got 1"),
        (["run", "sheet", "--cols", "2"], "cols must be an integer >= 3, got 2"),
        (
            ["run", "sheet", "--rows", "2", "--cols", "2", "--bend", "none", "--mass", "-1"],
            "mass must be > 0 kg, got -1.0",
        ),
        (["run", "sheet", "--mass", "0"], "mass must be > 0 kg"),
        (["run", "sheet", "--width", "-2"], "width must be > 0 m"),
        (["run", "sheet", "--dt", "0"], "dt must be > 0 s, got 0.0"),
        (["run", "sheet", "--dt=-1e-3"], "dt must be > 0 s"),
        (["run", "sheet", "--duration", "0"], "duration must be > 0 s"),
        (["run", "sheet", "--fps", "-5"], "fps must be > 0"),
        (["run", "sheet", "--stiffness", "-5"], "stiffness must be >= 0 N/m, got -5.0"),
        (["run", "sheet", "--damping", "-0.1"], "damping must be >= 0"),
        (["run", "sheet", "--stiffness", "1,2"], "three comma-separated numbers"),
        (["run", "sheet", "--integrator", "leapfrog"], "unknown integrator 'leapfrog'"),
        (["run", "sail"], "unknown scenario 'sail'"),
        (["run", "sheet", "--device", "cuda:7"], "device 'cuda:7' is not available"),
        (["run", "sheet", "--usd", "/no/such/folder/x.usda"], "does not exist"),
        (["run", "sheet", "--usd", "x.txt"], "must end in one of"),
        (["run", "sheet", "--num-frames", "0"], "--num-frames must be >= 1"),
        (["run", "sheet", "--num-frames", "5", "--fps", "0"], "fps must be > 0"),
        (["run", "sheet", "--stiffness", "1e39"], "must fit in float32"),
        (["run", "sheet", "--rows", "abc"], "invalid int value: 'abc'"),
        (["run", "sheet", "--deterministic", "maybe"], "maybe"),
    ],
)
def test_bad_input_is_one_line_exit_2(capsys, argv, message):
    with pytest.raises(SystemExit) as exc:
        code = main(argv)
        raise SystemExit(code)
    assert exc.value.code == 2
    out, err = capsys.readouterr()
    lines = [line for line in err.splitlines() if line.strip() and "CUDA" not in line]
    assert len(lines) == 1, err
    assert message in lines[0] and "Traceback" not in err
    assert out == ""


def test_missing_cuda_device_error(capsys):
    import warp as wp

    if wp.is_cuda_available():
        pytest.skip("a CUDA device is present")
    code, _out, err = run_cli(capsys, "run", "sheet", "--device", "cuda")
    assert code == 2 and "no CUDA device found" in err


def test_console_script_and_module_entry_points(tmp_path):
    """As a user runs them: python -m warpcloth, a run and a bad input (python -m warpcloth.cli: the
    console error tests below)."""
    out = subprocess.run(
        [sys.executable, "-m", "warpcloth", "run", "flag", "--rows", "4", "--cols", "5", "--num-frames", "3", "--json"],
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    assert json.loads(out)["scenario"] == "flag"
    bad = subprocess.run(
        [sys.executable, "-m", "warpcloth", "run", "sheet", "--rows", "1"], capture_output=True, text=True
    )
    lines = bad.stderr.splitlines()
    assert bad.returncode == 2 and len(lines) == 1 and lines[0].startswith("warpcloth: error: "), bad.stderr
    assert "rows must be an integer >= 3, got 1" in lines[0]


# -- issue 19 item 7, 10.14: messages name what the user typed and why it cannot work ----------
@pytest.mark.parametrize(
    "argv,message",
    [
        (["run", "sheet", "--mass", "1e30"], "default time step computed from --mass 1e+30 is 0.0 s, not a usable dt"),
        (["run", "sheet", "--damping", "1e38"], "computed from --damping 1e+38 is 0.0 s"),
        (["run", "sheet", "--drag", "1e38"], "computed from --drag 1e+38 is 0.0 s"),
        (
            ["run", "sheet", "--height", "1e-30"],
            "--height 1e-30 m over 32 particles puts neighbours 3.23e-32 m apart, below float32's resolution",
        ),
        (["run", "sheet", "--dt", "-inf"], "dt must be a finite number, got -inf"),
        (["run", "sheet", "--mass", "-inf"], "mass must be a finite number, got -inf"),
        (["run", "sheet", "--dt", "-1e-3"], "dt must be > 0 s, got -0.001"),
        (["run", "sheet", "--stiffness", "1,,2,3"], "'1,,2,3' has an empty item"),
        (["run", "sheet", "--integrator", ""], "--integrator is empty; choose one of explicit_euler"),
        (["bench", "--integrators", ","], "--integrators ',' names no integrator"),
        (["bench", "--devices", ""], "--devices '' names no device"),
        (
            ["max-dt", "sheet", "--start", "inf"],
            "start must be a finite dt within [dt_min, dt_max] = [1e-07, 0.1] s, got inf",
        ),
        (["max-dt", "sheet", "--start", "1e40"], "got 1e+40"),
        (["max-dt", "sheet", "--start", "0"], "got 0.0"),
        (["max-dt", "sheet", "--start", "-1"], "got -1.0"),
        (["max-dt", "sheet", "--start", "1e-9"], "within [dt_min, dt_max]"),
    ],
)
def test_messages_name_the_input(capsys, argv, message):
    try:
        code = main(argv)
    except SystemExit as exc:  # argparse's own errors exit from parse_args
        code = exc.code
    _out, err = capsys.readouterr()
    assert code == 2
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("warpcloth: error: ") and message in lines[0], err


# -- issue 19 item 8: one error format, no Warp start-up lines unless --verbose -------------------
@pytest.mark.parametrize("argv", [["run", "sheet", "--rows", "abc"], ["max-dt", "sheet", "--bogus"]])
def test_argument_errors_are_one_line_in_the_programs_name(capsys, argv):
    """argparse's own errors exit from parse_args, before Warp starts (cli.parse.guarded): in-process is
    the console here. "warpcloth: error:", not the subcommand's "warpcloth run: error:"."""
    with pytest.raises(SystemExit) as exc:
        main(argv)
    out, err = capsys.readouterr()
    assert exc.value.code == 2
    assert len(err.splitlines()) == 1 and err.startswith("warpcloth: error: "), err
    assert out == ""


@pytest.mark.parametrize("argv", [["run", "sheet", "--mass", "0"], ["sweep", "x.xml"], ["bench", "--sizes", "2"]])
def test_errors_are_exactly_one_stderr_line_from_the_console(argv):
    """Errors raised after Warp starts: a fresh process, whose Warp start-up lines (the CUDA driver's
    on a machine without a GPU) would reach the console."""
    p = subprocess.run([sys.executable, "-m", "warpcloth.cli", *argv], capture_output=True, text=True)
    assert p.returncode == 2
    lines = p.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("warpcloth: error: "), (
        p.stderr
    )  # not "warpcloth run: error:", no CUDA line
    assert p.stdout == ""


def test_bench_script_and_scenario_module_use_the_same_error_format():
    """bench/devices.py as a script; ``python -m warpcloth`` is test_console_script_and_module_entry_points'."""
    p = subprocess.run(
        [sys.executable, str(REPO / "bench" / "devices.py"), "--sizes", "2"], capture_output=True, text=True
    )
    assert (
        p.returncode == 2
        and p.stderr.splitlines()[0].startswith("warpcloth: error: ")
        and len(p.stderr.splitlines()) == 1
    ), p.stderr


def test_verbose_shows_warp_start_up_messages():
    """The same error with --verbose; without it (test_errors_are_exactly_one_stderr_line_from_the_console's
    ``run sheet --mass 0``) stdout is empty and stderr is the one error line."""
    import warp as wp

    loud = subprocess.run(
        [sys.executable, "-m", "warpcloth.cli", "run", "sheet", "--mass", "0", "--verbose"],
        capture_output=True,
        text=True,
    )
    assert loud.returncode == 2 and "mass must be > 0 kg" in loud.stderr
    assert "Warp" in loud.stdout + loud.stderr  # the banner (and, without a GPU, the CUDA driver line)
    if not wp.is_cuda_available():
        assert "CUDA" in loud.stderr


# -- 10.10: bench and cli do not import each other --------------------------------------------------
def test_bench_does_not_import_cli():
    code = "import sys, warpcloth.lab.bench; assert 'warpcloth.cli' not in sys.modules, 'bench imported cli'"
    subprocess.run([sys.executable, "-c", code], check=True)


# -- issue 31: every input honoured or refused -------------------------------------------------
def _colliders(*argv):
    from warpcloth.cli import build_parser
    from warpcloth.cli.model import config_from_args
    from warpcloth.scenarios import get_scenario

    args = build_parser().parse_args(["run", "sheet", *argv])
    return config_from_args(get_scenario("sheet"), args).colliders


def test_collider_specs_take_exponents_and_file_names_with_plus(tmp_path):
    (a, b) = _colliders("--collider", "sphere:center=0/1e+0/0,radius=2.5e-1+plane:point=0/-1E+1/0")
    assert dict(a.settings) == {"center": (0.0, 1.0, 0.0), "radius": 0.25} and dict(b.settings) == {
        "point": (0.0, -10.0, 0.0)
    }
    (c,) = _colliders("--collider", "sphere:radius=1e+3")
    assert dict(c.settings) == {"radius": 1000.0}
    path = tmp_path / "a+b plane.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 0 0 1\nf 1 2 3\n")
    (m, s) = _colliders("--collider", f"mesh:path={path}", "--collider", "sphere:radius=0.1")
    assert dict(m.settings)["path"] == str(path) and s.kind == "sphere"
    (q,) = _colliders("--collider", f'mesh:path="{tmp_path}/a+b plane.obj",thickness=1e-3')
    assert dict(q.settings) == {"path": str(path), "thickness": 0.001}


@pytest.mark.parametrize(
    "argv,message",
    [
        (["--collider", "sphere:radius=1,radius=2"], "collider sphere: setting 'radius' is given twice"),
        (["--collider", "plane:point=0/0/0,point=0/1/0"], "setting 'point' is given twice"),
        (["--collider", ""], "the collider is empty; give KIND:K=V,..."),
        (["--collider", "sphere:radius=1", "--collider", ""], "has an empty collider"),
        (["--collider", "sphere:radius=1+"], "has an empty collider"),
        (["--collider", 'mesh:path="a.obj'], 'has an unclosed " quote'),
        (["--pin", "1"], None),
        (["--pin", "x"], None),
        (["--pin", "y + 0.5"], None),
        (["--pin", "y.max()"], None),
        (["--pin", "0.5"], None),
        (["--pin", "1e30"], None),
        (["--pin", "10 ** 400 > y"], "'10 ** 400' is out of range"),
        (["--pin", "1 / 0 < y"], "'1 / 0' divides by zero"),
        (["--pin", " + ".join(["y"] * 5000) + " > 0"], "is longer than 1000 characters"),
        (["--pin", "y > " + "9" * 100_000], "is longer than 1000 characters"),
    ],
)
def test_collider_and_pin_inputs_are_refused_in_one_short_line(capsys, argv, message):
    scenario = "mesh" if argv[0] == "--pin" else "sheet"
    with pytest.raises(SystemExit) as exc:
        raise SystemExit(main(["run", scenario, *argv, "--duration", "0.01"]))
    _out, err = capsys.readouterr()
    lines = [line for line in err.splitlines() if line.strip()]
    assert exc.value.code == 2 and len(lines) == 1 and lines[0].startswith("warpcloth: error: "), err
    assert (message or "is a number, not a condition such as") in lines[0]
    assert len(lines[0]) <= 230 and "Warning" not in err


def test_a_predicate_that_divides_by_zero_at_a_vertex_prints_no_numpy_warning(capsys, recwarn):
    code, out, err = run_cli(capsys, "run", "mesh", "--pin", "y / (x - x) > 0", "--duration", "0.01", "--json")
    assert code == 0, err
    assert "RuntimeWarning" not in err and json.loads(out)["scenario"] == "mesh"
    assert [
        str(w.message) for w in recwarn if issubclass(w.category, RuntimeWarning)
    ] == []  # none raised, so none printed


@pytest.mark.parametrize(
    "argv,message",
    [
        (["run", "sheet", "--html", ""], "HTML path is empty"),
        (["run", "sheet", "--usd", ""], "USD path is empty"),
        (["run", "sheet", "--preview", ""], "preview path is empty"),
        (["bench", "--seconds", "1e40"], "argument --seconds: '1e40' does not fit in float32"),
        (["bench", "--seconds", "inf"], "argument --seconds: 'inf' is not a finite number"),
        (["bench", "--seconds", "1e5"], "100000 s is more than 86400 s (a day) per combination"),
        (["bench", "--steps", "10000000000000"], "--steps must be at most 1e+12, got 10000000000000"),
        (
            ["study", "--sizes", "4,99999", "--out", "never-made"],
            "the study's 99999 x 99999 cloth (--sizes) needs about",
        ),
        (["run", "sheet", "--rows", "1" * 100_000], "invalid int value: '" + "1" * 60 + "...' (100,000 characters)"),
    ],
)
def test_more_inputs_are_refused_in_one_line(capsys, tmp_path, monkeypatch, argv, message):
    import warpcloth.lab.bench as lab_bench
    import warpcloth.lab.study as study

    def started(*args, **kwargs):
        raise AssertionError("the work started: the input was not refused first")

    monkeypatch.setattr(lab_bench, "bench_one", started)  # bench --seconds 1e40 would time for ever
    monkeypatch.setattr(study, "Measurements", started)
    monkeypatch.chdir(tmp_path)
    try:
        code = main(argv)
    except SystemExit as exc:
        code = exc.code
    _out, err = capsys.readouterr()
    lines = [line for line in err.splitlines() if line.strip()]
    assert code == 2 and len(lines) == 1 and lines[0].startswith("warpcloth: error: ") and message in lines[0], err
    assert len(lines[0]) < 250
    assert not (tmp_path / "never-made").exists()


def test_the_study_checks_memory_before_its_first_run(capsys, tmp_path, monkeypatch):
    import warpcloth.lab.study as study

    ran = []
    monkeypatch.setattr(
        study, "Measurements", lambda *a, **k: ran.append(a) or (_ for _ in ()).throw(AssertionError("ran"))
    )
    code = main(["study", "--sizes", "4,6,99999", "--integrators", "rk4", "--out", str(tmp_path / "s")])
    assert code == 2 and ran == [] and "99999 x 99999" in capsys.readouterr().err


@pytest.mark.parametrize(
    "argv", [["list"], ["list", "--examples"], ["run", "sheet", "--rows", "4", "--cols", "4", "--duration", "0.01"]]
)
def test_a_closed_stdout_is_one_line_exit_74(argv):
    p = subprocess.run(
        [sys.executable, "-m", "warpcloth.cli", *argv],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=lambda: __import__("os").close(1),
    )
    assert p.returncode == 74, p.stderr
    assert p.stderr.splitlines() == ["warpcloth: error: cannot write to stdout: it is closed"]


def test_a_closed_stdout_is_no_error_when_nothing_is_written():
    q = subprocess.run(
        [sys.executable, "-m", "warpcloth.cli", "list", "--quiet"],
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=lambda: __import__("os").close(1),
    )
    assert q.returncode == 0 and q.stderr == ""


def test_numpy_warnings_never_reach_stderr(capsys, recwarn):
    _code, _out, err = run_cli(
        capsys, "run", "sheet", "--rows", "4", "--cols", "4", "--width", "3e38", "--duration", "0.01", "--json"
    )
    assert "RuntimeWarning" not in err and "encountered" not in err, err
    assert [
        str(w.message) for w in recwarn if issubclass(w.category, RuntimeWarning)
    ] == []  # pytest would hide them from err
