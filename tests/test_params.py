"""One declaration per run parameter (warpcloth.run.params): the CLI flags, the XML attributes,
the CSV columns, the run key and the docs table all come from it."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

import warpcloth.lab.sweep as sweep
import warpcloth.run.params as params
from warpcloth.cli import build_parser, main
from warpcloth.errors import WarpclothError
from warpcloth.lab.testlist import ATTRIBUTES, RunSpec, parse_test_list

REPO = Path(__file__).resolve().parents[1]


def write(tmp_path, text, name="t.xml"):
    path = tmp_path / name
    path.write_text(text)
    return str(path)


def test_docs_table_is_the_generated_one():
    doc = (REPO / "docs" / "sweep.md").read_text()
    begin = doc.index("<!-- params:begin")
    table = doc[doc.index("\n", begin) + 1 : doc.index("<!-- params:end -->")].strip()
    assert table == params.markdown_table(), (
        "docs/sweep.md is stale: paste `python -m warpcloth.run.params` between the markers"
    )


def test_every_spelling_comes_from_the_declaration():
    run_flags = {a.dest for a in _actions("run")}
    maxdt_flags = {a.dest for a in _actions("max-dt")}
    for p in params.PARAMS:
        if "sweep" in p.commands:
            assert p.name in ATTRIBUTES, p.name
            for column in p.csv_columns:
                assert column in sweep.COLUMNS, column
        if "run" in p.commands:
            assert p.name in run_flags, p.name
        if "max-dt" in p.commands:
            assert p.name in maxdt_flags, p.name
    # one spelling: the CLI flag is the attribute with dashes
    strings = {s for a in _actions("run") for s in a.option_strings}
    assert {"--wall-cap", "--frame-rate", "--dt", "--instability-strain", "--stiffness-shear", "--size"} <= strings


def _actions(command):
    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    return sub.choices[command]._actions


def test_old_xml_spellings_are_accepted_with_a_note(tmp_path, capsys):
    old = write(
        tmp_path,
        '<test_list cap="5" timestep="1e-3" scenarios="sheet">\n<test integrator="rk4" size="4"/>\n'
        '<test integrator="verlet" size="4" cap="none"/></test_list>',
        "old.xml",
    )
    new = write(
        tmp_path,
        '<test_list wall_cap="5" dt="1e-3" scenario="sheet">\n<test integrator="rk4" size="4"/>\n'
        '<test integrator="verlet" size="4" wall_cap="none"/></test_list>',
        "new.xml",
    )
    a = parse_test_list(old)
    err = capsys.readouterr().err
    for word, now in (("cap", "wall_cap"), ("timestep", "dt"), ("scenarios", "scenario")):
        assert err.count(f"attribute '{word}' is now spelled '{now}'") == 1  # once per file
    b = parse_test_list(new)
    assert capsys.readouterr().err == ""
    assert [r.key for r in a.runs] == [r.key for r in b.runs]
    assert a.runs[0].wall_cap == a.runs[0].cap == 5.0 and a.runs[1].wall_cap is None
    assert str(a.runs[0].dt) == str(a.runs[0].timestep) == "0.001"
    both = write(tmp_path, '<test_list>\n<test integrator="rk4" cap="5" wall_cap="6"/></test_list>', "both.xml")
    with pytest.raises(
        WarpclothError,
        match=r"both.xml:2: .*'wall_cap' and 'cap' name the same parameter|'cap' and 'wall_cap' name the same",
    ):
        parse_test_list(both)


def test_new_flags_from_declarations_work_on_the_cli(tmp_path, capsys):
    # --size and the per-type stiffness flags exist because the declarations have them
    code = main(
        [
            "run",
            "sheet",
            "--size",
            "5x6",
            "--stiffness",
            "800",
            "--stiffness-bend",
            "50",
            "--duration",
            "0.05",
            "--wall-cap",
            "30",
            "--json",
            "-q",
        ]
    )
    assert code == 0
    import json

    out = json.loads(capsys.readouterr().out)
    assert (out["rows"], out["cols"]) == (5, 6)
    assert main(["run", "sheet", "--size", "5", "--rows", "6", "--cols", "6"]) == 2
    assert "give either --size or --rows and --cols" in capsys.readouterr().err


def test_per_type_cli_flags_reach_the_model():
    from warpcloth.cli.model import config_from_args
    from warpcloth.scenarios import get_scenario
    from warpcloth.sim.model import SpringType

    parser = build_parser()
    args = parser.parse_args(
        [
            "run",
            "sheet",
            "--rows",
            "4",
            "--cols",
            "4",
            "--stiffness",
            "800",
            "--stiffness-bend",
            "50",
            "--damping-shear",
            "0.3",
        ]
    )
    cfg = config_from_args(get_scenario("sheet"), args)
    sim = get_scenario("sheet").build(cfg)
    p = sim.model.spring_params
    assert (p[SpringType.STRUCTURAL].stiffness, p[SpringType.SHEAR].stiffness, p[SpringType.BEND].stiffness) == (
        800,
        800,
        50,
    )
    assert p[SpringType.SHEAR].damping == pytest.approx(0.3)


def test_dt_reaches_the_config_from_its_declaration_alone(tmp_path):
    """dt goes the way of every Param (config_values): the CLI's float, a test list's value (a scenario
    file's key: tests/test_scenario_files.py); ``default`` leaves the scenario's own (None: the integrator's)."""
    from warpcloth.cli.model import config_from_args
    from warpcloth.scenarios import get_scenario

    assert params.BY_NAME["dt"].config_field == "dt"
    assert params.config_values({"dt": 0.002}) == {"dt": 0.002}
    assert params.config_values({"dt": params.TimeStep("value", 0.004)}) == {"dt": 0.004}
    assert params.config_values({"dt": params.TimeStep("default")}) == {"dt": None}  # None: the scenario's
    args = build_parser().parse_args(["run", "sheet", "--dt", "0.0025"])
    assert config_from_args(get_scenario("sheet"), args).dt == 0.0025
    assert config_from_args(get_scenario("sheet"), build_parser().parse_args(["run", "sheet"])).dt is None
    xml = write(
        tmp_path, '<test_list scenario="sheet"><test integrator="rk4" size="4" dt="1e-3 default max"/></test_list>'
    )
    value, default, most = parse_test_list(xml).runs
    assert value.config().dt == 1e-3 and default.config().dt is None
    assert most.config().dt is None and most.config(dt=2e-3).dt == 2e-3  # max: the dt its search found


def test_adding_a_parameter_is_one_declaration(tmp_path, monkeypatch):
    """A new parameter declared once appears as an XML attribute (checked, with file:line), a
    CSV column, a run-key field and a CLI flag, with no other change but its use."""
    extra = params.Param(
        "gravity_scale", params.positive, "", "multiplies gravity", "> 0", "forces", default=1.0, key="set", config=None
    )
    monkeypatch.setattr(params, "PARAMS", params.PARAMS + (extra,))
    monkeypatch.setitem(params.BY_NAME, "gravity_scale", extra)
    import warpcloth.lab.testlist as testlist

    if True:
        path = write(
            tmp_path,
            '<test_list scenario="sheet">\n<test integrator="rk4" size="4" gravity_scale="0.5 1.0"/></test_list>',
        )
        runs = testlist.parse_test_list(path).runs
        assert sorted(r.gravity_scale for r in runs) == [0.5, 1.0]
        assert sum("gravity_scale=0.5" in r.key for r in runs) == 1 and sum("gravity_scale" in r.key for r in runs) == 1
        assert "gravity_scale" in params.csv_columns()
        bad = write(tmp_path, '<test_list>\n<test integrator="rk4"\n gravity_scale="-1"/></test_list>', "bad.xml")
        with pytest.raises(WarpclothError, match=r"bad.xml:3: test '1': gravity_scale: '-1' must be > 0"):
            testlist.parse_test_list(bad)
        import argparse

        parser = argparse.ArgumentParser()
        params.add_flags(parser, "run")
        assert parser.parse_args(["--gravity-scale", "2", "sheet"]).gravity_scale == 2.0


def test_runspec_pickles_for_worker_processes(tmp_path):
    import pickle

    spec = parse_test_list(
        write(tmp_path, '<test_list><test integrator="rk4" size="4" scenario="sheet"/></test_list>')
    ).runs[0]
    again = pickle.loads(pickle.dumps(spec))
    assert again == spec and again.key == spec.key and isinstance(again, RunSpec)
    assert dataclasses.asdict(again)["test_id"] == "1"


def test_the_max_dt_search_key_holds_the_wall_cap_and_the_duration(tmp_path):
    # a max-dt trial that reaches the wall cap counts as capped, so runs with other caps must not
    # share one search; "max" is verified over the run's own duration (docs/sweep.md), so runs of
    # other durations do not share one either
    runs = parse_test_list(
        write(
            tmp_path,
            '<test_list dt="max" scenario="sheet" integrator="rk4" size="4">\n'
            '<test wall_cap="5"/><test wall_cap="none"/><test wall_cap="5" duration="2"/>'
            '<test wall_cap="5" mass="0.3"/></test_list>',
        )
    ).runs
    assert runs[0].search_key != runs[1].search_key
    assert runs[0].search_key != runs[2].search_key and runs[0].key != runs[2].key
    assert runs[0].search_key != runs[3].search_key  # another model


def test_time_steps_times_exactly_the_steps_asked():
    from warpcloth.run.harness import time_steps
    from warpcloth.scenarios import get_scenario

    sim = get_scenario("sheet").build(rows=4, cols=4, device="cpu", use_graph=False)
    for steps, windows in ((13, 5), (100, 5), (7, 7)):
        before = sim.steps
        t = time_steps(sim, windows=windows, steps=steps)
        assert t.steps == steps and len(t.ms_per_step) == windows
        assert sim.steps - before == steps + sum(
            {steps // windows, steps // windows + (steps % windows > 0)}
        )  # + one untimed replay of each count
    with pytest.raises(WarpclothError, match=r"steps \(3\) must be at least windows \(5\)"):
        time_steps(sim, windows=5, steps=3)


def test_a_cpu_stopwatch_counts_the_threads_cpu_time_not_other_jobs_share():
    """On the CPU a timed block reads the thread's CPU time: a block that sleeps 0.2 s (the
    core given to other jobs) costs ~0, a block that computes costs what it computes."""
    import time

    from warpcloth.run.harness import Stopwatch

    with Stopwatch("cpu") as idle:
        time.sleep(0.2)
    assert idle.seconds < 0.02
    with Stopwatch("cpu") as busy:
        c0, t0 = time.thread_time(), time.perf_counter()
        while time.perf_counter() - t0 < 0.1:
            pass
        used = time.thread_time() - c0  # what the thread computed (under load less than the 0.1 s of wall)
    assert used > 0.01 and abs(busy.seconds - used) < 0.005  # (0.1 s of wall gave 0.049 s of CPU at load 3)
    with Stopwatch() as wall:  # no device: the wall clock
        time.sleep(0.05)
    assert wall.seconds >= 0.045


def test_time_steps_keeps_to_its_windows_when_a_frame_of_steps_outlasts_them():
    """A frame of many steps (dt = 1e-5 s: 1667 steps a 60 Hz frame) is not a window's minimum:
    ``bench --seconds 0.5`` timed five whole frames of the 256 x 256 sheet (24.6 s on the CPU)."""
    from warpcloth.run.harness import time_steps
    from warpcloth.scenarios import get_scenario

    sim = get_scenario("sheet").build(rows=4, cols=4, device="cpu", dt=1e-5)
    chunk = sim.chunk_steps()
    t = time_steps(sim, windows=3, window_seconds=1e-7)
    assert t.steps_per_window == chunk and len(t.ms_per_step) == 3  # whole chunks, at least one
    assert sim.steps < 1667  # not one frame
    whole = time_steps(sim, windows=1, window_seconds=0.2, warm_up=False)
    assert whole.steps_per_window % 1667 == 0  # frames that fit are timed whole, as before


def test_grid_or_mesh_attributes_no_scenario_of_the_test_takes_are_refused(tmp_path):
    path = write(tmp_path, '<test_list>\n<test integrator="rk4" scenario="mesh"\n size="5 7"/></test_list>')
    with pytest.raises(
        WarpclothError,
        match=r":3: test '1': 'size' applies to grid scenarios and none of the test's scenarios \(mesh\)",
    ):
        parse_test_list(path)
    path = write(tmp_path, '<test_list>\n<test integrator="rk4" scenario="sheet" mesh="x.obj"/></test_list>', "m.xml")
    with pytest.raises(WarpclothError, match=r":2: test '1': 'mesh' applies to mesh scenarios"):
        parse_test_list(path)
    # a test naming both kinds: each run takes its own kind's attributes
    ok = write(tmp_path, '<test_list>\n<test integrator="rk4" scenario="sheet mesh" size="5"/></test_list>', "ok.xml")
    runs = parse_test_list(ok).runs
    assert {(r.scenario, r.rows) for r in runs} == {("sheet", 5), ("mesh", 1)}


def test_a_mesh_in_a_test_list_gets_the_damping_of_its_own_particles(tmp_path):
    import csv

    from warpcloth.lab.sweep import run_sweep

    obj = tmp_path / "small.obj"
    obj.write_text(
        "".join(f"v {x} {y} 0\n" for y in range(3) for x in range(3))
        + "f 1 2 5\nf 1 5 4\nf 2 3 6\nf 2 6 5\nf 4 5 8\nf 4 8 7\nf 5 6 9\nf 5 9 8\n"
    )
    path = write(
        tmp_path,
        f'<test_list><test integrator="explicit_euler" scenario="mesh" mesh="{obj}" pin="y &gt; 1.9" '
        'dt="0.001" duration="0.02"/></test_list>',
    )
    (spec,) = parse_test_list(path).runs
    assert spec.rows is None and spec.damping is None  # known once the mesh is built
    from warpcloth.scenarios import get_scenario

    sim = get_scenario("mesh").build(spec.config(dt=1e-3))
    cli = get_scenario("mesh").build(mesh=str(obj), pin_where="y > 1.9", dt=1e-3)
    assert sim.model.particle_count == 9
    assert sim.model.spring_damping.numpy().tolist() == cli.model.spring_damping.numpy().tolist()
    out = tmp_path / "r.csv"
    run_sweep(path, str(out))
    (row,) = list(csv.DictReader(out.open()))
    assert row["particles"] == "9" and row["outcome"] == "completed"
