"""The accuracy study (warpcloth.lab: accuracy, frontier, study, report; ``warpcloth study``)."""

from __future__ import annotations

import csv
import math
import os
import socket

import numpy as np
import pytest

from warpcloth.errors import WarpclothError
from warpcloth.lab.accuracy import FRAME_DT, AccuracyProblem, Transient, check_tolerance, search_steps_per_frame, steps_per_frame_at_most
from warpcloth.lab.frontier import fit_power_law, frontier


# -- the metric means what it says -------------------------------------------------------------
@pytest.fixture(scope="module")
def swing5():
    from warpcloth.scenarios import sheet

    sim = sheet.build(rows=5, cols=5, integrator="explicit_euler", dt=1e-3)
    return sim, AccuracyProblem(sim, Transient("sheet", 0.5, swing=True))


def test_explicit_euler_error_halves_when_dt_halves(swing5):
    sim, problem = swing5
    sim.set_integrator("explicit_euler")
    e16, e32 = problem.error(sim, 16), problem.error(sim, 32)
    assert 1e-4 < e32 < e16 < 0.05
    assert 1.8 < e16 / e32 < 2.2  # first order: dt/2 -> e/2


def test_rk4_error_falls_sixteenfold_before_the_float32_floor():
    from warpcloth.scenarios import sheet

    sim = sheet.build(rows=5, cols=5, integrator="rk4", dt=1e-3, stiffness=20)  # soft: truncation measurable
    problem = AccuracyProblem(sim, Transient("sheet", 0.5, swing=True))
    e1, e2, floor = problem.error(sim, 1), problem.error(sim, 2), problem.error(sim, 64)
    assert e2 > 3 * floor  # both points above the float32 floor
    assert 10 < e1 / e2 < 25  # fourth order: dt/2 -> e/16
    assert floor < 1e-5  # the floor is far below the 1 % tolerance


def test_unstable_run_is_infinitely_inaccurate(swing5):
    sim, problem = swing5
    sim.set_integrator("explicit_euler")
    assert problem.error(sim, 1) == math.inf  # dt = 1/60 s: explicit Euler blows up


def test_transient_must_be_whole_frames(swing5):
    sim, _ = swing5
    with pytest.raises(WarpclothError, match="whole number"):
        AccuracyProblem(sim, Transient("sheet", 0.51, swing=True))


# -- the search ------------------------------------------------------------------------------
@pytest.mark.parametrize("C,p,tol,k_start", [(50.0, 1, 0.01, 1), (3e4, 2, 0.01, 3), (1e6, 4, 1e-3, 1), (2.0, 1, 0.01, 40)])
def test_search_finds_the_largest_accurate_dt_of_a_synthetic_curve(C, p, tol, k_start):
    calls = []

    def error(k):
        calls.append(k)
        return C * (FRAME_DT / k) ** p

    found = search_steps_per_frame(error, tol, k_start=k_start, precision=0.0)
    k_true = max(k_start, math.ceil(FRAME_DT / (tol / C) ** (1 / p) - 1e-12))
    assert found.k == k_true
    assert error(found.k) <= tol
    if found.k > k_start:
        assert found.k_inaccurate == found.k - 1 and error(found.k - 1) > tol
        assert not found.bounded
    else:
        assert found.bounded  # accurate at the search's upper dt bound
    assert len(calls) <= 2 * math.log2(k_true + 1) + 4  # bracket + bisection, not a scan


def test_search_with_precision_stops_early_but_stays_accurate():
    found = search_steps_per_frame(lambda k: 100.0 * (FRAME_DT / k), 0.01, precision=0.05)
    k_true = math.ceil(FRAME_DT * 100.0 / 0.01)
    assert found.k >= k_true and (found.k - found.k_inaccurate) / found.k_inaccurate <= 0.05
    assert 100.0 * FRAME_DT / found.k <= 0.01


def test_search_reports_nothing_when_the_floor_is_above_the_tolerance():
    found = search_steps_per_frame(lambda k: 0.02 + 1.0 / k, 0.01, k_max=256)
    assert found.k is None and found.dt() is None and found.k_inaccurate == 256 and not found.stalled
    calls = []
    flat = search_steps_per_frame(lambda k: calls.append(k) or 0.05 * (1 + 0.01 / k), 0.01, k_max=4096)
    assert flat.k is None and flat.stalled and calls == [1, 2, 4, 8]  # a plateau: gives up after 3 doublings
    noisy = search_steps_per_frame(lambda k: float("inf") if k < 16 else 0.5 / k, 0.01, precision=0.0)
    assert noisy.k == 50 and not noisy.stalled  # unstable (inf) trials do not count as a plateau


def test_search_treats_nan_as_inaccurate():
    found = search_steps_per_frame(lambda k: float("nan") if k < 8 else 0.0, 0.01, precision=0.0)
    assert found.k == 8


def test_steps_per_frame_at_most():
    assert steps_per_frame_at_most(None) == 1 and steps_per_frame_at_most(0.1) == 1
    assert steps_per_frame_at_most(FRAME_DT / 7) == 7
    assert FRAME_DT / steps_per_frame_at_most(1.3e-4) <= 1.3e-4


@pytest.mark.parametrize("bad", [0, -0.1, 1, 1.5, float("nan"), "x"])
def test_tolerance_must_be_a_fraction(bad):
    with pytest.raises(WarpclothError, match="tolerance"):
        check_tolerance(bad)


# -- the frontier ----------------------------------------------------------------------------
def test_power_law_fit_recovers_a_known_exponent():
    rng = np.random.default_rng(0)
    n = np.array([64, 256, 1024, 4096, 16384])
    cost = 2e-4 * n ** 1.3 * np.exp(rng.normal(0, 0.02, n.size))
    fit = fit_power_law(n, cost)
    assert abs(fit.p - 1.3) < 0.03 and 0 < fit.residual < 0.02 and fit.points == 5
    exact = fit_power_law(n, 2e-4 * n ** 1.3)
    assert abs(exact.p - 1.3) < 1e-9 and exact.residual < 1e-9 and abs(exact.a / 2e-4 - 1) < 1e-9


def test_frontier_inside_and_beyond_the_measured_range():
    n = [100, 400, 1600, 6400]
    f = frontier(n, [1e-3 * v for v in n])  # real time up to N = 1000
    assert f.measured == 400 and abs(f.fitted - 1000) < 1e-6 and f.extrapolated == ""
    assert not f.all_realtime and not f.none_realtime
    g = frontier(n, [1e-5 * v for v in n])  # N* = 1e5, beyond 6400
    assert g.measured == 6400 and g.all_realtime and g.extrapolated == "above" and "extrapolated above" in g.describe()
    h = frontier(n, [1e-1 * v for v in n])  # N* = 10, below 100
    assert h.measured is None and h.none_realtime and h.extrapolated == "below"
    assert frontier([100], [0.5]).fit is None  # one size: no fit


# -- the study end to end --------------------------------------------------------------------
from warpcloth.cli import main  # noqa: E402
from warpcloth.lab.report import PLOTS  # noqa: E402
from warpcloth.lab.plan import make_plan  # noqa: E402
from warpcloth.lab.results import COLUMNS, read_rows  # noqa: E402
from warpcloth.lab.study import run_study  # noqa: E402

def cli(argv) -> int:
    """``warpcloth ARGV``'s exit status (argparse's errors exit through SystemExit)."""
    try:
        return main(argv)
    except SystemExit as exc:
        return exc.code


TINY = ["study", "--profile", "quick", "--integrators", "explicit_euler,pbd", "--sizes", "4", "--accuracy-sizes", "4", "--quiet"]


@pytest.fixture(scope="module")
def tiny_study(tmp_path_factory):
    out = tmp_path_factory.mktemp("study") / "out"
    import contextlib
    import io

    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        code = main(TINY + ["--devices", "cpu,cuda:7", "--match-accuracy", "--out", str(out)])
    return code, out, err.getvalue()


def test_tiny_study_end_to_end(tiny_study):
    code, out, err = tiny_study
    assert code == 0
    assert "skipping device cuda:7" in err and err.count("\n") == 1  # the missing device: one line, the rest runs
    with open(out / "results.csv", newline="") as fh:
        reader = csv.reader(fh)
        assert next(reader) == COLUMNS
        body = list(reader)
    assert body and all(len(r) == len(COLUMNS) for r in body)
    rows = read_rows(out / "results.csv")
    keys = [r["key"] for r in rows]
    assert len(keys) == len(set(keys))
    kinds = {r["measurement"] for r in rows}
    assert {"max_stable_dt", "floor", "error", "max_accurate_dt", "static", "max_static_accurate_dt", "timing", "match_result"} <= kinds
    for r in rows:
        assert r["device"] == "cpu" and r["particles"] == 16
    for r in [r for r in rows if r["measurement"] == "timing"]:
        assert r["timed_windows"] >= 5 and r["ms_per_step_min"] <= r["ms_per_step_median"] <= r["ms_per_step_max"]
        assert r["wall_s_per_sim_s"] == pytest.approx(r["ms_per_step_median"] / 1000 / r["dt_s"])
    acc = {(r["integrator"], r["scenario"]): r for r in rows if r["measurement"] == "max_accurate_dt"}
    ee = acc[("explicit_euler", "sheet")]
    assert ee["dt_s"] and ee["error_rel"] <= ee["tolerance_rel"] and ee["floor_error_rel"] < ee["tolerance_rel"] / 100
    report = (out / "report.md").read_text()
    for section in ("## Machine and command", "## Method", "## Verdict", "**Null hypothesis**", "**Alternative hypothesis**",
                    "Cheapest per simulated second", "### Real-time frontier", "### Float32 noise floor", "## Plots",
                    "## Columns of results.csv", "pbd at 4x4 on cpu", "warpcloth study --profile quick"):
        assert section in report, section
    for name in PLOTS:
        assert (out / name).stat().st_size > 1000 and f"]({name})" in report
        assert (out / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_study_refuses_to_overwrite_without_a_flag(tiny_study, capsys):
    _, out, _ = tiny_study
    before = (out / "results.csv").read_bytes()
    assert main(TINY + ["--out", str(out)]) == 2
    assert "already exists" in capsys.readouterr().err
    assert (out / "results.csv").read_bytes() == before


def test_resume_after_an_interrupt_does_not_redo_finished_measurements(tmp_path):
    plan = make_plan("quick", integrators=["explicit_euler"], sizes=[4], accuracy_sizes=[4])
    seen = []

    def interrupt_after_five(row):
        seen.append(row["key"])
        if len(seen) == 5:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_study(plan, tmp_path, on_row=interrupt_after_five)
    first = (tmp_path / "results.csv").read_bytes()
    assert first.count(b"\n") == 6  # header + the five finished rows, flushed
    with open(tmp_path / "results.csv", "ab") as fh:
        fh.write(b"timing,sheet,cut sho")  # a row cut by a kill
    again = []
    summary = run_study(plan, tmp_path, resume=True, on_row=lambda r: again.append(r["key"]))
    data = (tmp_path / "results.csv").read_bytes()
    assert data.startswith(first) and b"cut sho" not in data
    assert not set(again) & set(seen)  # nothing finished was measured again
    assert summary["measured"] == len(again) > 0 and summary["reused"] >= 5
    keys = [r["key"] for r in read_rows(tmp_path / "results.csv")]
    assert len(keys) == len(set(keys)) == 5 + len(again)
    again.clear()
    summary = run_study(plan, tmp_path, resume=True, on_row=lambda r: again.append(r["key"]))
    assert summary["measured"] == 0 and not again  # a finished study resumes to nothing


@pytest.mark.parametrize("argv,message", [
    (["--profile", "huge"], "invalid choice: 'huge'"),
    (["--integrators", "euler"], "unknown integrator 'euler'"),
    (["--integrators", ""], "--integrators must be a comma-separated list"),
    (["--sizes", ""], "--sizes must be a comma-separated list"),
    (["--sizes", "8,,16"], "--sizes must be a comma-separated list"),
    (["--sizes", "2"], "integers >= 3"),
    (["--tolerance", "0"], "--tolerance must be in (0, 1)"),
    (["--tolerance", "-0.01"], "--tolerance must be in (0, 1)"),
    (["--tolerance", "1"], "--tolerance must be in (0, 1)"),
    (["--tolerance", "nan"], "--tolerance must be in (0, 1)"),
    (["--devices", "cuda:7"], "none of the devices cuda:7 is available"),
])
def test_bad_input_is_one_line_and_status_2(argv, message, tmp_path, capsys):
    out = tmp_path / "out"
    assert cli(["study", "--quiet", "--out", str(out)] + argv) == 2
    lines = capsys.readouterr().err.splitlines()
    assert lines[-1].startswith("warpcloth: error: ") and message in lines[-1]
    assert len(lines) == (2 if "--devices" in argv else 1)  # a missing device: its skip line, then the error
    assert not (out / "results.csv").exists()


def test_unwritable_out_is_refused_before_any_work(tmp_path, capsys):
    (tmp_path / "file").write_text("x")
    assert main(["study", "--quiet", "--out", str(tmp_path / "file")]) == 2
    assert "is not a folder" in capsys.readouterr().err
    assert main(["study", "--quiet", "--out", str(tmp_path / "missing" / "out")]) == 2
    assert "does not exist" in capsys.readouterr().err
    assert main(["study", "--quiet", "--out", "/proc/warpcloth-study"]) == 2
    assert "cannot be created" in capsys.readouterr().err
    if os.geteuid() != 0:
        locked = tmp_path / "locked"
        locked.mkdir(mode=0o500)
        assert main(["study", "--quiet", "--out", str(locked)]) == 2
        assert "not writable" in capsys.readouterr().err


# -- in parallel (issue 17) --------------------------------------------------------------------
#: the columns that must not depend on where or alongside what a measurement ran (not timings)
SAME = ["measurement", "scenario", "integrator", "options", "device", "particles", "dt_s", "steps_per_frame", "bound_dt_s",
        "search_bounded", "tolerance_rel", "error_rel", "floor_error_rel", "max_strain_rel", "stable", "equilibrium_reached",
        "time_to_equilibrium_sim_s", "static_error_rel", "sag_error_rel", "iterations", "substeps", "trials"]


def same_rows(a: list, b: list) -> None:
    by_key = {r["key"]: r for r in b}
    assert sorted(r["key"] for r in a) == sorted(by_key)
    for r in a:
        assert {c: r[c] for c in SAME} == {c: by_key[r["key"]][c] for c in SAME}, r["key"]


def test_workers_2_gives_the_serial_rows(tiny_study, tmp_path):
    """The tiny study (explicit_euler and pbd, --match-accuracy) in 2 worker processes: the same
    keys and stability/accuracy values as the serial run; the searches ran in both workers, the
    timings one at a time, and the driver wrote every row once."""
    _, serial_out, _ = tiny_study
    out = tmp_path / "par"
    assert main(TINY + ["--devices", "cpu", "--match-accuracy", "--workers", "2", "--out", str(out)]) == 0
    serial, par = read_rows(serial_out / "results.csv"), read_rows(out / "results.csv")
    same_rows(serial, par)
    assert {r["worker"] for r in serial} == {"main"} and {r["concurrent_runs"] for r in serial} == {1}
    searches = [r for r in par if r["measurement"] not in ("timing", "match_result")]
    assert {r["worker"] for r in searches} == {"local:1", "local:2"}  # one group per worker
    timed = [r for r in par if r["measurement"] == "timing"]
    assert timed and all(r["concurrent_runs"] == 1 for r in timed)
    assert all(r["host"] == socket.gethostname() for r in par)
    assert "at most 1 timed run(s) at once, at most 2 search run(s) at once" in (out / "report.md").read_text()


def test_parallel_settings_warn_above_the_cores_and_devices(monkeypatch):
    from warpcloth.lab.study import ParallelSettings

    monkeypatch.setattr(os, "cpu_count", lambda: 2)
    assert ParallelSettings.check(["cpu"], workers=2).warnings == []
    assert not ParallelSettings.check(["cpu"]).parallel
    (w,) = ParallelSettings.check(["cpu"], workers=3).warnings
    assert "--workers 3 is more than the 2 CPU cores" in w and "timings still run alone" in w
    (w,) = ParallelSettings.check(["cpu"], timing_workers=2).warnings
    assert "--timing-workers 2 is more than the 1 device(s) (cpu)" in w
    assert ParallelSettings.check(["cuda:0", "cuda:1"], workers=8, timing_workers=2).warnings == []
    for bad in (0, -1, 1.5, True, "2"):
        with pytest.raises(WarpclothError, match="--workers must be a whole number >= 1"):
            ParallelSettings.check(["cpu"], workers=bad)


@pytest.mark.parametrize("argv,message", [
    (["--workers", "0"], "argument --workers: must be a whole number >= 1, got '0'"),
    (["--workers", "two"], "argument --workers: must be a whole number >= 1, got 'two'"),
    (["--timing-workers", "-1"], "argument --timing-workers: must be a whole number >= 1, got '-1'"),
    (["--ray", "auto", "--workers", "2"], "--ray runs the searches on the cluster's CPUs and GPUs: it takes no --workers"),
    (["--ray", " "], "--ray: give auto, local, HOST:PORT or ray://HOST:PORT"),
])
def test_bad_parallel_flags_are_one_line_and_status_2(argv, message, tmp_path, capsys):
    out = tmp_path / "out"
    assert cli(["study", "--quiet", "--out", str(out)] + argv) == 2
    assert capsys.readouterr().err == f"warpcloth: error: {message}\n"
    assert not (out / "results.csv").exists()


# -- a scenario file through the study (issue 13) ----------------------------------------------
def write_scenario(tmp_path) -> str:
    """A 4 x 4 quad grid hung by its top row, as an OBJ and a scenario file next to it."""
    n, h = 4, 0.5 / 3
    verts = [f"v {c * h:.6f} {1.0 - r * h:.6f} 0" for r in range(n) for c in range(n)]
    faces = [f"f {r * n + c + 1} {r * n + c + 2} {(r + 1) * n + c + 2} {(r + 1) * n + c + 1}" for r in range(n - 1) for c in range(n - 1)]
    (tmp_path / "patch.obj").write_text("\n".join(verts + faces) + "\n")
    (tmp_path / "patch.toml").write_text('name = "patch"\n[cloth]\nmesh = "patch.obj"\nquads = true\nmass = 0.1\n'
                                         '[pins]\nwhere = "y > 0.99 * y.max()"\n[forces]\ndrag = 1.0\n')
    return str(tmp_path / "patch.toml")


def test_a_scenario_file_runs_through_the_quick_profile(tmp_path):
    """sheet, flag and a custom scenario file: the file's rows (stability, equilibrium, timing,
    at its own 16 particles and Provot-equal springs), no accuracy rows for it and the report
    saying why; the grid study as usual."""
    from warpcloth.sim.grid import expected_spring_counts

    path = write_scenario(tmp_path)
    out = tmp_path / "out"
    assert main(["study", "--profile", "quick", "--integrators", "explicit_euler,xpbd", "--sizes", "4", "--accuracy-sizes", "4",
                 "--scenarios", f"sheet,flag,{path}", "--quiet", "--out", str(out)]) == 0
    rows = read_rows(out / "results.csv")
    mine = [r for r in rows if r["scenario"] == path]
    assert {(r["measurement"], r["integrator"]) for r in mine} == {(m, i) for m in ("max_stable_dt", "static", "timing")
                                                                   for i in ("explicit_euler", "xpbd")}
    springs = sum(expected_spring_counts(4, 4, "provot").values())
    assert all(r["particles"] == 16 and r["springs"] == springs and r["rows"] is None for r in mine)
    stable = {r["integrator"]: r for r in mine if r["measurement"] == "max_stable_dt"}
    assert 1e-4 < stable["explicit_euler"]["dt_s"] < FRAME_DT and stable["xpbd"]["dt_s"] == pytest.approx(FRAME_DT)
    for r in mine:
        if r["measurement"] == "timing":
            assert r["dt_s"] <= stable[r["integrator"]]["dt_s"] and r["ms_per_step_median"] > 0
        if r["measurement"] == "static":
            assert "no float64 reference" in r["note"] and r["static_error_rel"] is None
    assert {r["measurement"] for r in rows if r["scenario"] == "sheet"} >= {"max_accurate_dt", "error", "timing"}
    report = (out / "report.md").read_text()
    assert "## Scenarios" in report and f"`{path}`" in report and "accuracy not measured" in report and "## Verdict" in report


def test_a_scenario_file_study_in_workers_gives_the_serial_rows(tmp_path):
    path = write_scenario(tmp_path)
    plan = make_plan("quick", integrators=["explicit_euler", "verlet"], scenarios=[path])
    assert not plan.grid and plan.scenario_files == [path]
    run_study(plan, tmp_path / "serial")
    run_study(plan, tmp_path / "par", workers=2)
    same_rows(read_rows(tmp_path / "serial" / "results.csv"), read_rows(tmp_path / "par" / "results.csv"))
    assert "## Verdict" not in (tmp_path / "serial" / "report.md").read_text()


@pytest.mark.parametrize("scenarios,message", [
    ("sheet", "--scenarios: sheet without flag: the study's sheet and flag go together"),
    ("flag,missing.toml", "--scenarios: flag without sheet"),
    ("sheet,flag,missing.toml", "missing.toml"),
    ("sheet,flag,nosuch", "unknown scenario 'nosuch'"),
])
def test_bad_scenarios_are_one_line_and_status_2(scenarios, message, tmp_path, capsys):
    out = tmp_path / "out"
    assert cli(["study", "--quiet", "--out", str(out), "--scenarios", scenarios]) == 2
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("warpcloth: error: ") and message in lines[0]
    assert not out.exists()


# -- the standard profile and its estimate (issue 12) ---------------------------------------------
def test_standard_profile_is_every_integrator_at_16_to_128():
    from warpcloth.integrators import integrator_names

    plan = make_plan("standard")
    assert plan.integrators == list(integrator_names()) and {"vbd", "projective"} <= set(plan.integrators)
    assert plan.sizes == [16, 32, 64, 128] and plan.devices == ["cpu"]
    assert [plan.maxdt_duration_at(n) for n in (8, 16, 32, 64, 128, 256)] == [1.0, 1.0, 1.0, 0.5, 0.25, 0.25]


def test_estimate_adds_up_the_modelled_steps():
    """One integrator at one size, costs given: each phase is the documented step count x the
    per-step cost, capped by the wall caps; doubling the per-step cost doubles the uncapped phases."""
    from dataclasses import replace

    from warpcloth.lab.estimate import estimate_plan

    plan = replace(make_plan("quick", integrators=["explicit_euler"], sizes=[10], accuracy_sizes=[]), maxdt_wall_cap=None,
                   equilibrium_wall_cap=None)
    k0, ms = 10, 0.5  # dt0 = (1/60 s) / 10
    phases = {p.phase.split(" ")[0]: p for p in estimate_plan(plan, {("explicit_euler", 10): (k0, ms, None)})}
    steps_trial = plan.maxdt_duration / (1.5 * FRAME_DT / k0)  # 6 trials at 1.5x the default dt, per scenario
    assert phases["stability"].seconds == pytest.approx(2 * 6 * steps_trial * ms / 1000)
    assert phases["equilibrium"].seconds == pytest.approx(plan.equilibrium_duration / (FRAME_DT / k0) * ms / 1000)
    assert phases["accuracy"].seconds == 0 and phases["accuracy"].measurements == 0
    frame = k0 * ms / 1000
    assert phases["timing"].seconds == pytest.approx((3 + plan.windows * math.ceil(plan.window_seconds / frame)) * frame)
    double = {p.phase.split(" ")[0]: p for p in estimate_plan(plan, {("explicit_euler", 10): (k0, 2 * ms, None)})}
    assert double["stability"].seconds == pytest.approx(2 * phases["stability"].seconds)
    capped = {p.phase.split(" ")[0]: p for p in estimate_plan(replace(plan, maxdt_wall_cap=0.01),
                                                               {("explicit_euler", 10): (k0, ms, None)})}
    assert capped["stability"].seconds == pytest.approx(2 * 6 * 0.01)  # every trial stopped at the wall cap


def test_estimate_flag_prints_the_phases_and_writes_nothing(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["study", "--profile", "quick", "--integrators", "explicit_euler,xpbd", "--sizes", "4", "--accuracy-sizes", "4",
                 "--estimate", "--quiet"]) == 0
    out = capsys.readouterr().out
    for phase in ("stability (max stable dt)", "equilibrium and static accuracy", "accuracy (references, floors, searches)", "timing"):
        assert phase in out
    assert "estimate of profile quick" in out and "total about" in out
    assert list(tmp_path.iterdir()) == []


def test_out_is_required_but_with_estimate(capsys):
    assert cli(["study", "--quiet"]) == 2
    assert capsys.readouterr().err == ("warpcloth: error: --out DIR is required (where results.csv, report.md and the plots go), "
                                       "except with --estimate\n")


def test_an_interrupted_study_resumes_in_workers(tmp_path):
    """Rows of an interrupted serial study are reused (not remeasured, not duplicated) when it
    resumes with --workers 2; the file ends with the keys of a whole study."""
    plan = make_plan("quick", integrators=["explicit_euler"], sizes=[4], accuracy_sizes=[4])
    seen = []

    def interrupt_after_six(row):
        seen.append(row["key"])
        if len(seen) == 6:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_study(plan, tmp_path / "a", on_row=interrupt_after_six)
    again = []
    summary = run_study(plan, tmp_path / "a", resume=True, workers=2, on_row=lambda r: again.append(r["key"]))
    assert not set(again) & set(seen) and summary["measured"] == len(again) > 0
    keys = [r["key"] for r in read_rows(tmp_path / "a" / "results.csv")]
    assert len(keys) == len(set(keys)) == 6 + len(again)
    run_study(plan, tmp_path / "b")
    assert sorted(keys) == sorted(r["key"] for r in read_rows(tmp_path / "b" / "results.csv"))
