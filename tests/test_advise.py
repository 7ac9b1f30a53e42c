"""``warpcloth advise`` (warpcloth.lab.advise, warpcloth.cli.advise): the cheapest measured
configuration meeting a tolerance within a budget, from a small results.csv written here in the
study's real columns, and from the CPU study shipped in the package."""

from __future__ import annotations

import csv
import filecmp
import json
import math
import shlex
from pathlib import Path

import pytest

from warpcloth.cli import build_parser, main
from warpcloth.cli.model import config_from_args
from warpcloth.io.checkpoint import load_checkpoint
from warpcloth.lab.advise import SHIPPED, advise, format_advice, load_study
from warpcloth.lab.results import COLUMNS
from warpcloth.scenarios import get_scenario

REPO = Path(__file__).resolve().parents[1]

EULER = ("explicit_euler", "", 21.0)
PBD = ("pbd", "iterations=1 pbd_bend_stiffness=0.0123 substeps=16", 0.5)  # the bend as the study maps it
IMPLICIT = ("implicit_euler", "cg_tol=0.001 preconditioner=jacobi", 4.0)

#: size -> floor of the pointwise e (32: 1 % refuses it at any tolerance below 10 %)
POINT_FLOORS = {16: 1e-6, 32: 0.01, 64: 1e-6}
#: (size, configuration) -> (pointwise e, patch error, ms per 1/60 s frame, stable)
MEASURED = {
    (16, EULER): (0.01, 0.004, 0.5, True),
    (16, PBD): (0.2, 0.1, 0.1, True),
    (16, IMPLICIT): (0.03, 0.01, 2.0, True),
    (32, EULER): (0.02, 0.005, 5.0, True),
    (32, PBD): (0.04, 0.02, 1.0, True),
    (32, IMPLICIT): (0.03, 0.01, 3.0, True),
    (64, EULER): (0.03, 0.01, 40.0, True),
    (64, PBD): (0.04, 0.03, 3.0, True),
    (64, IMPLICIT): (None, None, 2.0, False),
}


def write_study(folder: Path, rows=None, device="cpu", ill_posed=()) -> Path:
    """A results.csv of floors, trials (swing and flag alike) and timings in the study's columns;
    at the sizes ``ill_posed`` every metric's floor is 1 % (every verdict below 10 % refused)."""
    folder.mkdir(parents=True, exist_ok=True)
    out = []
    for n, point_floor in POINT_FLOORS.items():
        for transient in ("swing", "flag"):
            out.append(
                {
                    "measurement": "floor",
                    "scenario": "study_sheet" if transient == "swing" else "study_flag",
                    "transient": transient,
                    "integrator": "reference",
                    "device": device,
                    "rows": n,
                    "cols": n,
                    "reference": "Warp RK4",
                    "reference_estimate_rel": 1e-6,
                    "floor_point_rel": point_floor,
                    "floor_centroid_rel": 0.01 if n in ill_posed else 1e-7,
                    "floor_patch_rel": 0.01 if n in ill_posed else 1e-6,
                    "floor_damping_rel": 1e-7,
                    "floor_stretch_rel": 1e-7,
                }
            )
    for (n, (integrator, options, k)), (e, patch, ms, stable) in MEASURED.items():
        common = {"integrator": integrator, "options": options, "device": device, "rows": n, "cols": n}
        common["steps_per_frame"] = k
        common["dt_s"] = 1 / 60 / k
        for transient in ("swing", "flag"):
            out.append(
                {
                    **common,
                    "measurement": "trial",
                    "scenario": "study_sheet" if transient == "swing" else "study_flag",
                    "transient": transient,
                    "error_rel": e,
                    "patch_error_rel": patch,
                    "centroid_error_rel": None if e is None else e / 10,
                    "damping_rel": None if e is None else -e / 5,
                    "stable": "true" if stable else "false",
                }
            )
        out.append(
            {**common, "measurement": "timing", "scenario": "study_sheet", "ms_per_frame": ms, "note": "at the dt"}
        )
    with open(folder / "results.csv", "w", newline="", encoding="utf-8") as fh:
        w = csv.DictWriter(fh, COLUMNS)
        w.writeheader()
        for r in rows if rows is not None else out:
            w.writerow({k: "" if v is None else v for k, v in r.items()})
    return folder


@pytest.fixture
def study(tmp_path):
    return load_study(str(write_study(tmp_path / "study")))


def run_args(flags):
    """``warpcloth run FLAGS`` parsed by the run parser, and the ScenarioConfig they give."""
    args = build_parser(("run",)).parse_args(["run", *flags])
    return args, config_from_args(get_scenario(args.scenario), args, "run")


def test_measured_size_gives_the_cheapest_within_budget_and_its_margin(study):
    a = advise(study, 16, 0.05, 8.0)
    assert a.kind == "measured" and a.answer.status == "answer"
    # explicit Euler (0.5 ms, e 1 %) beats implicit Euler (2 ms, e 3 %); pbd (0.1 ms) misses at 20 %
    assert a.answer.best.label.integrator == "explicit_euler"
    assert a.answer.metric == "point" and a.answer.judged == ("swing", "flag")
    a64 = advise(study, 64, 0.05, 8.0)
    # explicit Euler is over the budget (40 ms), implicit Euler went unstable: pbd, margin 1 % of the size
    assert a64.answer.best.label.integrator == "pbd"
    assert math.isclose(a64.tolerance - a64.answer.best.error, 0.01)
    text = format_advice(a64)
    assert "margin 1 %" in text and "decided by: pointwise e" in text
    assert (
        "run it: warpcloth run swing --size 64 --integrator pbd --dt 0.03333333333333333 --iterations 1 "
        "--pbd-bend-stiffness 0.0123 --substeps 16\n" in text
    )
    assert "judged it on its swing and flag transients" in text and "'warpcloth run swing' is that swing" in text


def test_refused_pointwise_falls_back_to_the_patch_metric_and_says_so(study):
    a = advise(study, 32, 0.05, 8.0)
    assert a.answer.status == "answer" and a.answer.metric == "patch"
    assert a.answer.best.label.integrator == "pbd"  # patch 2 % at 1 ms; the pointwise e is not judged
    text = format_advice(a)
    assert "decided by: 4 x 4 patch error" in text and "floor of the pointwise e is 1 %" in text


def test_refused_verdict_is_said_as_refused(study):
    a = advise(study, 32, 0.05, 8.0, metric="point")
    assert a.answer.status == "refused" and a.answer.best is None
    assert "refused" in format_advice(a) and "run it" not in format_advice(a)


def test_refused_by_every_metric_is_said_as_refused_and_brackets_nothing(tmp_path):
    study = load_study(str(write_study(tmp_path / "s", ill_posed=(32,))))
    a = advise(study, 32, 0.05, 8.0)
    assert a.answer.status == "refused" and a.answer.best is None
    text = format_advice(a)
    for what in ("pointwise e", "4 x 4 patch error", "centroid error"):
        assert f"floor of the {what} is 1 %" in text
    assert "refused" in text and "run it" not in text
    between = advise(study, 48, 0.05, 8.0)  # refused at 32, pbd at 64: they differ
    assert between.kind == "differ" and between.answer is None
    # at 10 % the floors (1 %) are at the limit, not above it: judged again
    assert advise(study, 32, 0.10, 8.0).answer.status == "answer"


def test_outside_the_measured_range_is_not_answered(study):
    for n in (8, 15, 65, 1024):
        a = advise(study, n, 0.05, 8.0)
        assert a.kind == "outside" and a.answer is None
        text = format_advice(a)
        assert "outside the measured sizes (16x16 to 64x64)" in text and "run it" not in text


def test_between_sizes_whose_answers_differ_is_not_answered(study):
    a = advise(study, 24, 0.05, 8.0)  # 16: explicit Euler, 32: pbd
    assert a.kind == "differ" and a.answer is None
    assert [x.n for x in a.answers] == [16, 32]
    text = format_advice(a)
    assert "whose answers differ: no answer at 24x24" in text
    assert "--size 24" not in text  # each bracketing answer's command is at its own size


def test_between_sizes_that_agree_answers_at_the_size_asked(study):
    a = advise(study, 48, 0.05, 8.0)  # pbd at 32 and at 64
    assert a.kind == "same" and a.answer.best.label.integrator == "pbd"
    text = format_advice(a)
    assert "whose answers agree" in text and "warpcloth run swing --size 48 --integrator pbd" in text


def test_nothing_within_budget_names_the_closest_and_the_cheapest_over_it(study):
    a = advise(study, 16, 0.05, 0.2)
    assert a.answer.status == "none"
    assert a.answer.closest.label.integrator == "pbd"
    assert a.answer.over_budget.label.integrator == "explicit_euler"


def test_flags_parse_with_the_run_parser_and_give_the_configuration(study):
    for n, integrator, expected in (
        (16, "explicit_euler", {}),
        (64, "pbd", {"iterations": 1, "pbd_bend_stiffness": 0.0123, "substeps": 16}),
    ):
        conf = advise(study, n, 0.05, 8.0).answer.best.label
        assert conf.integrator == integrator
        args, cfg = run_args(conf.run_flags(n))
        assert args.scenario == "swing" and (cfg.rows, cfg.cols, cfg.integrator) == (n, n, integrator)
        assert cfg.dt == conf.dt
        assert cfg.integrator_options == expected
    # an integrator with fixed study options (implicit Euler's strain_cap 0): they are on the command line too
    implicit = next(p.label for p in study.points("cpu", 16, "point", ("swing",)) if p.label.integrator == IMPLICIT[0])
    _, cfg = run_args(implicit.run_flags(20))
    assert cfg.integrator_options == {"cg_tol": 0.001, "preconditioner": "jacobi", "strain_cap": 0.0}
    assert cfg.dt == pytest.approx(1 / 240)


def _printed_commands(text: str) -> list[list[str]]:
    """The argv of every ``run it:`` line of advise's output, as printed."""
    return [shlex.split(line.split("run it: ", 1)[1]) for line in text.splitlines() if "run it: " in line]


@pytest.mark.parametrize("n", [16, 32])  # explicit Euler; pbd (the patch metric decides at 32)
def test_the_printed_command_runs_the_configuration_it_names(tmp_path, capsys, n):
    """The command as advise prints it (plus 2 frames) is accepted by ``warpcloth run`` and runs the
    swing with the integrator, the exact dt and every option of the configuration."""
    folder = write_study(tmp_path / "s")
    assert main(["advise", "--size", str(n), "--budget-ms", "8", "--tolerance", "0.05", "--results", str(folder)]) == 0
    (argv,) = _printed_commands(capsys.readouterr().out)
    assert argv[:3] == ["warpcloth", "run", "swing"]
    conf = advise(load_study(str(folder)), n, 0.05, 8.0).answer.best.label
    assert conf.integrator == {16: "explicit_euler", 32: "pbd"}[n]
    end = tmp_path / "end.npz"
    assert main([*argv[1:], "--num-frames", "2", "--json", "--checkpoint", str(end)]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert (summary["scenario"], summary["integrator"], summary["rows"], summary["cols"]) == (
        "swing",
        conf.integrator,
        n,
        n,
    )
    assert summary["dt"] == conf.dt and summary["stable"]
    setup = load_checkpoint(str(end)).setup  # what the run's simulator was set up with
    assert setup["integrator"] == conf.integrator and float(setup["dt"]) == conf.dt
    ran = dict(item.split("=", 1) for item in setup["options"].split(", ") if item)
    for name, value in conf.option_values().items():
        assert float(ran[name]) == float(value), (name, ran[name], value)
    if conf.integrator == "pbd":
        assert float(ran["pbd_bend_stiffness"]) == 0.0123  # the study's material bend, not pbd's rigid default


def _exit(argv, capsys) -> tuple[int, str]:
    try:
        code = main(argv)
    except SystemExit as exc:
        code = exc.code
    err = capsys.readouterr().err.strip()
    return code, err


@pytest.mark.parametrize(
    "bad, message",
    [
        (["--size", "0"], "argument --size: '0' must be an integer >= 3"),
        (["--size", "2"], "argument --size: '2' must be an integer >= 3"),
        (["--size", "nan"], "argument --size: 'nan' is not an integer"),
        (["--size", "12.5"], "argument --size: '12.5' is not an integer"),
        (["--budget-ms", "0"], "argument --budget-ms: '0' must be > 0"),
        (["--budget-ms", "-1"], "argument --budget-ms: '-1' must be > 0"),
        (["--budget-ms", "nan"], "argument --budget-ms: 'nan' is not a finite number"),
        (["--budget-ms", "inf"], "argument --budget-ms: 'inf' is not a finite number"),
        (["--tolerance", "0"], "argument --tolerance: '0' must be > 0"),
        (["--tolerance", "-0.1"], "argument --tolerance: '-0.1' must be > 0"),
        (["--tolerance", "five"], "argument --tolerance: 'five' is not a number"),
        (["--metric", "speed"], "argument --metric: invalid choice: 'speed'"),
        (["--device", "cuda"], "unknown device 'cuda'"),
    ],
)
def test_bad_arguments_are_one_error_line(tmp_path, capsys, bad, message):
    folder = write_study(tmp_path / "s")
    argv = {"--size": "16", "--budget-ms": "8", "--tolerance": "0.05", "--results": str(folder)}
    flags = [x for k, v in argv.items() for x in (k, v) if k != bad[0]]
    code, err = _exit(["advise", *flags, *bad], capsys)
    assert code == 2
    assert err.startswith("warpcloth: error:") and "\n" not in err and message in err, err


def test_a_bad_size_is_worded_as_run_words_it(capsys):
    """advise's --size is checked by warpcloth.run.params, as ``warpcloth run --size``: one wording."""
    for text in ("2", "12.5"):
        advise_err = _exit(["advise", "--size", text, "--budget-ms", "8", "--tolerance", "0.05"], capsys)[1]
        run_err = _exit(["run", "sheet", "--size", text], capsys)[1]
        assert advise_err == run_err


def test_bad_results_folders_are_one_error_line(tmp_path, capsys):
    not_a_study = tmp_path / "sweep"
    not_a_study.mkdir()
    (not_a_study / "results.csv").write_text("scenario,integrator\nsheet,pbd\n")
    binary = tmp_path / "binary"
    binary.mkdir()
    (binary / "results.csv").write_bytes(b"\xff\xfe\x00garbage")
    unreadable = tmp_path / "dir"
    (unreadable / "results.csv").mkdir(parents=True)
    for folder, word in (
        (tmp_path / "missing", "no such folder"),
        (tmp_path, "no results.csv"),
        (not_a_study, "missing column(s)"),
        (binary, "cannot read"),
        (unreadable, "cannot read"),
    ):
        code, err = _exit(
            ["advise", "--size", "16", "--budget-ms", "8", "--tolerance", "0.05", "--results", str(folder)], capsys
        )
        assert code == 2, folder
        assert err.startswith("warpcloth: error:") and "\n" not in err and word in err, err


def test_several_devices_need_one_chosen(tmp_path, capsys):
    folder = tmp_path / "two"
    write_study(tmp_path / "a", device="cpu")
    write_study(tmp_path / "b", device="cuda:0")
    folder.mkdir()
    lines = (tmp_path / "a" / "results.csv").read_text().splitlines()
    lines += (tmp_path / "b" / "results.csv").read_text().splitlines()[1:]
    (folder / "results.csv").write_text("\n".join(lines) + "\n")
    base = ["advise", "--size", "16", "--budget-ms", "8", "--tolerance", "0.05", "--results", str(folder)]
    code, err = _exit(base, capsys)
    assert code == 2 and "choose one with --device" in err
    assert main([*base, "--device", "cuda:0"]) == 0
    assert "16x16 on cuda:0" in capsys.readouterr().out


def test_shipped_study_answers_inside_its_range(capsys):
    study = load_study(SHIPPED)
    sizes = study.sizes("cpu")
    assert len(sizes) >= 2
    for n in sizes:
        a = advise(study, n, 0.05, 16.7)
        assert a.kind == "measured" and a.answer.status in ("answer", "none", "refused")
    assert main(["advise", "--size", str(sizes[-1]), "--budget-ms", "1000", "--tolerance", "0.1"]) == 0
    assert "run it: warpcloth run" in capsys.readouterr().out


def test_shipped_study_is_the_committed_one():
    """The package's copy is docs/study/cpu/results.csv (copy it again when the study is regenerated)."""
    assert filecmp.cmp(Path(SHIPPED) / "results.csv", REPO / "docs" / "study" / "cpu" / "results.csv", shallow=False)
