"""No capped solve is a silent result (issue 51): a step whose solve stops at its iteration cap or whose
strain cap engages is counted on the device and reported in the run's result, and the cantilever and
Cusick refuse to report a bending length or a drape coefficient from such a run, naming the cause and
the settings that fix it."""

from __future__ import annotations

import json
from dataclasses import replace
from fractions import Fraction

import numpy as np
import pytest
from helpers import assert_replay_matches_launches

from warpcloth.cli.run import summary
from warpcloth.lab.configs import Config
from warpcloth.lab.measure import Measurements
from warpcloth.lab.plan import make_plan
from warpcloth.run.harness import RunHarness
from warpcloth.scenarios import flag, get_scenario

CANTILEVER = get_scenario("cantilever")


def cantilever(cols: int = 10, **overrides):
    """The cotton strip at ``cols`` particles with the default overhang, on the CPU."""
    d = CANTILEVER.defaults
    width = d.width * (d.cols - 1.5) / (d.cols - 1) * (cols - 1) / (cols - 1.5)
    return CANTILEVER.config(cols=cols, width=width, device="cpu", **overrides)


def test_a_run_at_its_cg_cap_reports_it_and_the_cantilever_refuses_its_bending_length():
    # 0.25 s, not the scene's 3 s: a solve capped at 2 iterations never reaches equilibrium, and the refusal
    # reads the run's counts whatever its length
    result = CANTILEVER.run(cantilever(duration=0.25, integrator_options={"cg_max_iter": 2}))
    assert result.stable and result.steps > 0
    assert result.capped_steps == result.solver["cg_capped_steps"] == result.steps  # 2 iterations: every step
    got = result.measurements
    assert "bending_length_m" not in got and "tip_drop_error" not in got and "rigidity_Nm" not in got
    why = got["refused"]
    assert why.startswith("no bending length from this run: implicit_euler's solve stopped at its iteration cap")
    assert f"in {result.steps} of {result.steps} steps" in why
    assert "--dt" in why and "--cg-max-iter (now 2" in why  # the settings that fix it
    assert got["capped_steps"] == result.steps and result.capped_cause in why
    text = summary(result)
    assert f"solver capped in {result.steps} of {result.steps} steps" in text
    assert "not measured: no bending length" in text and "bending_length_m=" not in text
    data = json.loads(result.to_json())
    assert data["capped_steps"] == result.steps and data["capped_cause"] == result.capped_cause


def test_a_converged_cantilever_reports_no_capped_step_and_measures():
    result = CANTILEVER.run(cantilever())
    assert result.stable and result.equilibrium_reached
    assert result.capped_steps == 0 and result.strain_capped_steps == 0 and result.capped_cause == ""
    assert result.strain_limit_source == "strain_cap" and result.strain_limit_tau == pytest.approx(0.1)
    assert "refused" not in result.measurements and abs(result.measurements["tip_drop_error"]) < 0.02
    text = summary(result)
    assert f"solver capped in 0 of {result.steps} steps" in text
    assert f"strain cap (10 %) engaged in 0 of {result.steps} steps" in text


def test_the_strain_cap_engaging_is_counted_and_no_measurement():
    """implicit_euler's own strain cap (here 0.05 %, below the hanging strip's stretch) binds: counted
    per step, and the cantilever names it and --strain-cap 0; the user's strain limit at the same tau
    is counted too, but is the model asked for: the strip is measured."""
    result = CANTILEVER.run(cantilever(integrator_options={"strain_cap": 5e-4}))
    assert result.stable and result.capped_steps == 0
    assert result.strain_limit_source == "strain_cap" and 0 < result.strain_capped_steps <= result.steps
    why = result.measurements["refused"]
    assert "strain cap engaged in" in why and "--strain-cap 0" in why and "iteration cap" not in why
    user = CANTILEVER.run(cantilever(strain_limit=5e-4))
    assert user.stable and user.strain_limit_source == "strain_limit" and user.strain_capped_steps > 0
    assert user.capped_cause == "" and "bending_length_m" in user.measurements


def test_strain_limit_counters_survive_graph_replay_and_observe_only():
    """The counters are device arrays a kernel in the step increments: a captured frame replayed
    counts what plain launches count, and the positions are the same to the bit."""
    a = flag.build(rows=6, cols=7, integrator="explicit_euler", strain_limit=1e-4, device="cpu")
    b = flag.build(rows=6, cols=7, integrator="explicit_euler", strain_limit=1e-4, device="cpu")
    if not b.graph_enabled:
        pytest.skip("no CPU capture")
    for sim in (a, b):
        sim.warm_up()
        sim.strain_limiter.reset_stats()  # the warm-up's step counts (a run's harness zeroes them at its start)
    assert_replay_matches_launches(a, b)  # 24 steps each
    sa, sb = a.strain_limiter.stats(), b.strain_limiter.stats()
    assert sa == sb and sa["steps"] == 24 and 0 < sa["engaged_steps"] <= 24
    runs = []
    for graph in (True, False):  # a run's result: the same counts from replayed frames and from launches
        c = flag.build(rows=6, cols=7, integrator="explicit_euler", strain_limit=1e-4, device="cpu")
        c.use_graph = graph
        runs.append((RunHarness(c).run(0.2), c))
    (replayed, c), (launched, d) = runs
    assert replayed.graph and not launched.graph and replayed.steps == launched.steps
    assert replayed.strain_limit_source == "strain_limit" and replayed.strain_capped_steps > 0
    assert replayed.strain_capped_steps == launched.strain_capped_steps
    assert np.array_equal(c.state.particle_q.numpy(), d.state.particle_q.numpy())
    assert c.strain_limiter.stats()["steps"] == 0  # read once and zeroed at the run's end


def test_a_capped_cusick_run_refuses_its_drape_coefficient():
    cusick = get_scenario("cusick")
    cfg = cusick.config(rows=12, cols=12, duration=0.05, device="cpu", integrator_options={"cg_max_iter": 1})
    result = cusick.run(cfg)
    assert result.capped_steps == result.steps > 0
    assert "drape_coefficient" not in result.measurements
    assert result.measurements["refused"].startswith("no drape coefficient from this run")


def test_schemes_without_a_capped_solve_report_zero():
    sim = flag.build(rows=5, cols=6, integrator="projective", device="cpu")
    result = RunHarness(sim).run(0.1)
    assert result.capped_steps == 0 and result.strain_limit_source == "" and result.capped_cause == ""
    assert np.isfinite(sim.state.particle_q.numpy()).all()


def test_the_study_records_a_capped_trial_as_capped_not_as_a_measurement(study_references):
    class Out:  # a worker's stand-in for results.csv
        def __init__(self):
            self.done = {}

        def write(self, row):
            self.done[row["key"]] = row

    plan = make_plan("quick", integrators=["implicit_euler"], sizes=[4])
    m = Measurements(replace(plan, reference_cache=str(study_references)), out=Out())  # the session's references
    capped = m.trial("swing", Config("implicit_euler", (("cg_max_iter", 1),), Fraction(1)), "cpu", 4)
    assert capped["stable"] and capped["note"].startswith("capped: the solve stopped at its iteration cap in")
    assert capped["error_rel"] is None and capped["centroid_error_rel"] is None and capped["max_strain_rel"] is None
    converged = m.trial("swing", Config("implicit_euler", (), Fraction(1)), "cpu", 4)
    assert converged["note"] == "" and converged["error_rel"] > 0.0
