"""The benchmark runs end to end on tiny sizes and writes a well-formed CSV (no timing asserts)."""

import csv
import math

import pytest

from warpcloth.cli.bench import main
from warpcloth.lab.bench import COLUMNS, format_table


def test_bench_tiny_end_to_end(tmp_path, capsys):
    out = tmp_path / "bench.csv"
    code = main(
        [
            "--sizes",
            "8,16",
            "--steps",
            "5",
            "--devices",
            "cpu",
            "--integrators",
            "explicit_euler,rk4",
            "--roofline",
            "--out",
            str(out),
        ]
    )
    assert code == 0
    stdout = capsys.readouterr().out
    assert "explicit_euler" in stdout and "roofline floor on cpu, 8x8" in stdout
    rows = list(csv.DictReader(out.open()))
    assert rows and list(rows[0].keys()) == COLUMNS
    graphs = {r["graph"] for r in rows}
    assert len(rows) == 2 * 2 * len(graphs)
    for r in rows:
        assert int(r["steps_timed"]) == 5
        assert int(r["particles"]) == int(r["rows"]) * int(r["cols"])
        for key in [
            "ms_per_step_median",
            "steps_per_s",
            "springs_per_s",
            "realtime_factor",
            "roofline_ms",
            "floor_multiple",
            "dt_s",
            "wall_s_per_sim_s",
        ]:
            value = float(r[key])
            assert math.isfinite(value) and value > 0, (key, value)
        assert math.isclose(float(r["steps_per_s"]) * float(r["ms_per_step_median"]), 1000.0, rel_tol=1e-6)
        assert float(r["ms_per_step_min"]) <= float(r["ms_per_step_median"]) <= float(r["ms_per_step_max"])
        assert math.isclose(
            float(r["wall_s_per_sim_s"]), float(r["ms_per_step_median"]) / 1000.0 / float(r["dt_s"]), rel_tol=1e-9
        )
        assert r["host"] and r["cpu"] and r["warp_version"] and r["warpcloth_version"]
        assert int(r["force_evals_per_step"]) == {"explicit_euler": 1, "rk4": 4}[r["integrator"]]
        assert r["stable"] == "true"
        assert r["solver_converged"] == "" and r["solver_capped_steps"] == "0"  # no iterative solver


def test_bench_says_cuda_was_skipped(capsys):
    import warp as wp

    if wp.is_cuda_available():
        pytest.skip("a CUDA device is present")
    assert main(["--sizes", "4", "--steps", "2", "--integrators", "verlet", "--graph", "off"]) == 0
    assert "CUDA skipped: no CUDA device is present" in capsys.readouterr().err


@pytest.mark.parametrize(
    "argv,message",
    [
        (["--sizes", "2"], "--sizes must be"),
        (["--sizes", "x"], "--sizes must be"),
        (["--integrators", "nope"], "unknown integrator 'nope'"),
        (["--devices", "cuda:9"], "not available"),
        (["--steps", "0"], "--steps must be >= 1"),
    ],
)
def test_bench_bad_input(capsys, argv, message):
    assert main(argv) == 2
    assert message in capsys.readouterr().err


@pytest.mark.parametrize("cap, converged", [(2, "false"), (1000, "true")])
def test_bench_records_whether_cg_met_its_tolerance(tmp_path, capsys, monkeypatch, cap, converged):
    import dataclasses

    from warpcloth.integrators.implicit_euler import ImplicitEuler

    # the bench runs each integrator with its defaults: lower the default CG cap
    options = tuple(
        dataclasses.replace(o, default=cap) if o.name == "cg_max_iter" else o for o in ImplicitEuler.options
    )
    monkeypatch.setattr(ImplicitEuler, "options", options)
    out = tmp_path / "bench.csv"
    assert (
        main(
            [
                "--sizes",
                "8",
                "--steps",
                "3",
                "--devices",
                "cpu",
                "--integrators",
                "implicit_euler",
                "--graph",
                "off",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    (row,) = list(csv.DictReader(out.open()))
    assert row["solver_converged"] == converged
    assert row["solver_capped_steps"] == ("3" if cap == 2 else "0")


def _bench_script(name):
    import importlib.util
    import pathlib
    import sys

    folder = pathlib.Path(__file__).resolve().parents[1] / "bench"
    sys.path.insert(0, str(folder))  # a script may import its neighbours (implicit.py)
    try:
        spec = importlib.util.spec_from_file_location(f"bench_{name}", folder / f"{name}.py")
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
    finally:
        sys.path.remove(str(folder))
    return module


def test_bench_implicit_repeats_print_medians_and_ratios(capsys):
    _bench_script("implicit").main(["--sizes", "5", "--steps", "2", "--explicit-steps", "3", "--repeats", "2"])
    out = capsys.readouterr().out
    rows = [line.split() for line in out.splitlines() if line.startswith("   5x5") and "ms/step" not in line]
    assert [r[1] for r in rows] == ["free", "bsr", "free", "bsr"]  # alternating
    (summary,) = [line for line in out.splitlines() if "bsr/free" in line]
    assert summary.startswith("   5x5") and "per step" in summary and "per CG iteration" in summary


def test_bench_plot_tells_graph_replay_from_launches_and_keeps_its_legend_off_the_data(tmp_path):
    # issue 30: the graph and no-graph points of one integrator had the same colour and marker (only a
    # dashed line told them apart, invisible at one size) and the legend sat inside the axes
    pytest.importorskip("matplotlib")
    from warpcloth.lab.bench import bench_figure, plot

    rows = [
        dict(integrator="rk4", device="cpu", graph=g, particles=n, wall_s_per_sim_s=w)
        for g, w in ((False, 2.0), (True, 0.5))
        for n in (64, 256)
    ]
    fig = bench_figure(rows)
    ax = fig.axes[0]
    lines = {line.get_label(): line for line in ax.get_lines() if line.get_label().startswith("rk4")}
    plain, graph = lines["rk4 cpu"], lines["rk4 cpu graph"]
    assert plain.get_markerfacecolor() != graph.get_markerfacecolor()  # hollow against filled
    fig.canvas.draw()
    legend = (ax.get_legend() or fig.legends[0]).get_window_extent()
    assert legend.x0 >= ax.get_window_extent().x1  # right of the plot, not over the data
    assert plot(str(tmp_path / "b.png"), rows) and (tmp_path / "b.png").stat().st_size > 0


def test_the_table_prints_a_grid_as_rows_x_cols_and_a_mesh_or_pieces_as_mesh():
    # a model of several pieces (or a mesh) has one row: "1x8192" read as a grid it is not (issue 49)
    row = dict.fromkeys(COLUMNS, 0.0)
    row.update(integrator="vbd", device="cpu", graph=True, floor_multiple="", speedup_vs_cpu="")
    grid = format_table([{**row, "rows": 16, "cols": 8, "particles": 128}]).splitlines()[-1]
    mesh = format_table([{**row, "rows": 1, "cols": 8192, "particles": 8192}]).splitlines()[-1]
    assert " 16x8 " in grid and " mesh " in mesh and "1x8192" not in mesh
