"""The study asks one question at every size (issue 48): the same window at every size of every
profile, a named coarse metric where the pointwise e's floor refuses a verdict, stretch against
the reference's at the same instant, timings re-taken when their spread is large, pbd's bend
stiffness mapped from the study's material, plots that draw only what was measured."""

from __future__ import annotations

import math

import numpy as np
import pytest

from warpcloth.lab.accuracy import (
    DECIDING_METRICS,
    FLOOR_FRACTION,
    OVERSTRETCH,
    _Shape,
    deciding_metric,
    floor_of,
    over_stretched,
    trajectory_metrics,
)
from warpcloth.lab.plan import MIN_SWING_S, PROFILES, make_plan
from warpcloth.lab.transients import DYNAMIC


# -- one window at every size ------------------------------------------------------------------
@pytest.mark.parametrize("profile", sorted(PROFILES))
def test_every_size_of_every_profile_has_the_same_window(profile):
    plan = make_plan(profile)
    for name in DYNAMIC:
        windows = {plan.window_frames(name, n) for n in plan.all_sizes + [3, 1024]}
        assert len(windows) == 1, (profile, name, windows)
    swing = plan.window_frames("swing") / 60.0
    assert swing >= MIN_SWING_S  # the whip (0.5 s) and the over-swing's start are in it
    assert {plan.maxdt_duration_at(n) for n in plan.all_sizes} == {swing}  # stability trials: the same window
    if profile == "quick":
        assert plan.max_frame_ms is None  # every configuration runs: its rows do not depend on the machine


# -- a refused pointwise verdict falls back to a named coarse metric -----------------------------
def test_the_deciding_metric_is_the_first_whose_floor_allows_the_verdict():
    t = 0.01
    allowed, refused_floor = 0.5 * FLOOR_FRACTION * t, 2 * FLOOR_FRACTION * t
    assert DECIDING_METRICS[0] == "point"
    assert deciding_metric(dict.fromkeys(DECIDING_METRICS, allowed), t) == "point"
    assert deciding_metric({"point": refused_floor, "patch": allowed, "centroid": allowed}, t) == "patch"
    assert deciding_metric({"point": refused_floor, "patch": refused_floor, "centroid": allowed}, t) == "centroid"
    assert deciding_metric({"point": refused_floor, "patch": math.nan, "centroid": None}, t) is None


# -- stretch against the reference's at the same instant ---------------------------------------
def chain_shape(n: int) -> _Shape:
    """A chain of n particles of 1 kg joined by structural springs of rest length 1 m."""
    shape = _Shape.__new__(_Shape)
    shape.mass = np.ones(n)
    shape.patches = [np.arange(n)]
    shape.pairs = np.stack([np.arange(n - 1), np.arange(1, n)], axis=1)
    shape.rest = np.ones(n - 1)
    return shape


def chain(strains_per_frame) -> np.ndarray:
    """(F, N, 3) positions of a chain along x whose springs have the given strains per frame."""
    out = []
    for strains in strains_per_frame:
        x = np.concatenate([[0.0], np.cumsum(1.0 + np.asarray(strains, dtype=np.float64))])
        out.append(np.stack([x, np.zeros_like(x), np.zeros_like(x)], axis=1))
    return np.stack(out)


def test_stretch_flags_an_over_stretched_run_and_not_the_reference():
    shape = chain_shape(4)
    # the reference strains 16 % at frame 1 (the material's own: as the flag's at 16x16), 1 % else
    ref = chain([[0.01, 0.01, 0.01], [0.16, 0.01, 0.01], [0.01, 0.01, 0.01]])
    itself = trajectory_metrics(ref, ref, 3.0, shape, 1 / 60)
    assert itself["stretch"] == pytest.approx(0.16) and itself["stretch_excess"] == pytest.approx(0.0, abs=1e-12)
    assert not over_stretched(itself["stretch_excess"])
    # a run as strained as the reference at its peak, but 6 % at frame 2 where the reference is at 1 %:
    # its largest strain (0.16) equals the reference's, and only the same-instant comparison catches it
    run = chain([[0.01, 0.01, 0.01], [0.16, 0.01, 0.01], [0.01, 0.06, 0.01]])
    m = trajectory_metrics(run, ref, 3.0, shape, 1 / 60)
    assert m["stretch"] == pytest.approx(m["stretch_ref"])
    assert m["stretch_excess"] == pytest.approx(0.05) and over_stretched(m["stretch_excess"])
    assert not over_stretched(OVERSTRETCH) and not over_stretched(None)
    # a run that strains less than the reference is not over-stretched (a negative excess)
    soft = chain([[0.0, 0.0, 0.0], [0.10, 0.0, 0.0], [0.0, 0.0, 0.0]])
    assert trajectory_metrics(soft, ref, 3.0, shape, 1 / 60)["stretch_excess"] < 0
    assert floor_of(m)["stretch"] == pytest.approx(0.05)  # the floor of the same-instant comparison


def test_the_report_calls_over_stretched_runs_by_their_excess():
    from warpcloth.lab.report import Data, cheapest_tables, metrics_table
    from warpcloth.lab.results import COLUMNS

    rows = _group(strain=0.16, excess=0.0)
    text = "\n".join(cheapest_tables(Data(rows), (0.01,)) + metrics_table(Data(rows), 0.01))
    assert "over-stretched" not in text.replace("“over-stretched”", "") and "stretchy" not in text
    rows = _group(strain=0.05, excess=0.045)
    text = "\n".join(cheapest_tables(Data(rows), (0.01,)) + metrics_table(Data(rows), 0.01))
    assert "e 0.4 %) over-stretched" in text and "Over-stretched (stable" in text
    assert "strain_excess_rel" in COLUMNS


def _group(strain=0.01, excess=0.0, floor=1e-6, spread=0.04, n=8, error=0.004, ms=0.5, integrator="explicit_euler"):
    from warpcloth.lab.results import COLUMNS

    base = dict.fromkeys(COLUMNS)
    base.update(device="cpu", rows=n, cols=n, integrator=integrator, options=None, steps_per_frame=1.0, stable=True)
    out = [dict(base, measurement="max_stable_dt", scenario="study_sheet", dt_s=1 / 60)]
    for t in DYNAMIC:
        out.append(
            dict(
                base,
                measurement="floor",
                integrator="reference",
                transient=t,
                reference="DOP853",
                floor_point_rel=floor,
                floor_centroid_rel=1e-6,
                floor_patch_rel=1e-6,
            )
        )
        out.append(
            dict(
                base,
                measurement="trial",
                transient=t,
                error_rel=error,
                centroid_error_rel=error / 4,
                patch_error_rel=error / 2,
                max_strain_rel=strain,
                ref_max_strain_rel=strain - excess,
                strain_excess_rel=excess,
                damping_rel=0.0,
            )
        )
    out.append(
        dict(base, measurement="timing", note="at the configuration dt", ms_per_frame=ms, timing_spread_rel=spread)
    )
    return out


def test_the_report_names_the_deciding_metric_per_size_and_prints_the_spread():
    from warpcloth.lab.report import Data, cheapest_tables, deciding_table

    rows = _group(n=8) + _group(n=12, floor=0.002)  # 12x12: the pointwise e's floor refuses 1 %
    data = Data(rows)
    assert [data.deciding("cpu", n, 0.01) for n in (8, 12)] == ["point", "patch"]
    table = "\n".join(deciding_table(data, (0.01, 0.05)))
    assert "| 8x8 | pointwise e | pointwise e |" in table
    assert "| 12x12 | 4 x 4 patch error (pointwise e refused) | pointwise e |" in table
    cells = "\n".join(cheapest_tables(data, (0.01,)))
    assert "0.5 ms ±2 % (e 0.4 %)" in cells and "0.5 ms ±2 % (patch 0.2 %)" in cells


def test_budget_plot_draws_refused_sizes_as_refused_and_work_precision_axes_from_the_points(tmp_path, monkeypatch):
    pytest.importorskip("matplotlib")
    import matplotlib.pyplot as plt

    from warpcloth.lab.report import Data, plots

    rows = _group(n=8) + _group(n=12, ms=0.8) + _group(n=16, ms=1.2)
    for r in rows:  # 12x12: every metric's floor refuses 1 %
        if r["measurement"] == "floor" and r["rows"] == 12:
            r.update(floor_point_rel=0.002, floor_patch_rel=0.002, floor_centroid_rel=0.002)
    rows += [
        dict(r, options="x=1", error_rel=math.inf, stable=False) for r in _group(n=8) if r["measurement"] == "trial"
    ]
    rows += [dict(r, options="x=1", ms_per_frame=500.0) for r in _group(n=8) if r["measurement"] == "timing"]
    figures = []
    monkeypatch.setattr(plt, "close", lambda fig=None: figures.append(fig))
    plots(str(tmp_path), Data(rows), 2.0, 0.01)
    budget = next(f for f in figures if f is not None and f.axes[0].get_title().startswith("cheapest measured"))
    ax = budget.axes[0]  # 1 %
    drawn = [list(line.get_xdata()) for line in ax.get_lines()]
    assert [64] in drawn and [256] in drawn and not any(64 in x and 256 in x for x in drawn)  # never joined over 144
    assert [144, 144] in drawn  # the refused size's band
    assert any(t.get_text() == "refused" for t in ax.texts)
    assert "refused: every metric's floor" in [t.get_text() for t in budget.legends[0].get_texts()]
    wp_fig = next(f for f in figures if f is not None and f.axes[0].get_title() == "8x8 (cpu)")
    lo, hi = wp_fig.axes[0].get_ylim()
    assert lo < 0.5 < hi and hi < 16.7  # the unstable point (its 500 ms) and the whole-frame line set no axis


# -- timings re-taken when their spread is large -----------------------------------------------
def test_the_spread_of_timed_windows():
    from warpcloth.lab import measure

    assert measure.spread_of([1.0, 1.1, 1.2]) == pytest.approx(0.2 / 1.1)
    assert measure.spread_of([2.0]) == 0.0


def test_a_timing_above_the_spread_is_taken_again_and_the_least_spread_kept(monkeypatch):
    from types import SimpleNamespace

    from warpcloth.lab import measure
    from warpcloth.run.harness import StepTiming

    plan = make_plan("quick", integrators=["explicit_euler"], sizes=[4])
    m = measure.Measurements(plan, SimpleNamespace(done={}, write=lambda row: m.out.done.__setitem__(row["key"], row)))
    takes = iter([[1.0, 1.6, 1.1], [1.0, 1.05, 1.02], [9.0, 9.0, 9.0]])

    def fake(sim, windows, window_seconds, batch):
        return StepTiming(dt=1 / 600, steps_per_window=batch, ms_per_step=next(takes))

    monkeypatch.setattr(measure, "time_steps", fake)
    row = m.timing("study_sheet", "explicit_euler", "cpu", 4, 1 / 600, "configuration")
    assert row["retimed"] == 1 and row["timing_spread_rel"] == pytest.approx(0.05 / 1.02)
    assert row["ms_per_step_median"] == pytest.approx(1.02) and row["ms_per_step_max"] == pytest.approx(1.05)


# -- pbd runs the study's material -------------------------------------------------------------
def test_pbd_bend_stiffness_is_mapped_from_the_material_into_the_options():
    from types import SimpleNamespace

    from warpcloth.integrators.pbd import material_bend_stiffness
    from warpcloth.lab import measure
    from warpcloth.lab.configs import configurations
    from warpcloth.lab.transients import TRANSIENTS
    from warpcloth.sim.model import SpringType

    plan = make_plan("quick", integrators=["pbd"], sizes=[8])
    m = measure.Measurements(plan, SimpleNamespace(done={}, write=lambda row: None))
    model = m.sim(TRANSIENTS["swing"].scenario.name, 8, "cpu", "explicit_euler").model
    bend = np.asarray(model.spring_type) == int(SpringType.BEND)
    ks = float(np.median(model.spring_stiffness.numpy()[bend]))
    w = 2.0 / float(np.median(model.host.mass))
    h = 1 / 60 / 16
    k = material_bend_stiffness(model, h)
    assert k == pytest.approx(ks * h * h * w / (1 + ks * h * h * w), rel=2e-2) and 0 < k < 1
    configs = m.material(configurations("pbd", None, "quick", 8), "cpu", 8)
    assert all("pbd_bend_stiffness" in c.option_dict for c in configs)
    by = {(c.option_dict["substeps"], float(c.k)): c.option_dict["pbd_bend_stiffness"] for c in configs}
    assert by[(16, 1.0)] == k and by[(1, 0.5)] > by[(1, 1.0)] > by[(16, 1.0)]  # longer substeps: stiffer per step
    assert m.material(configurations("xpbd", None, "quick", 8), "cpu", 8) == configurations("xpbd", None, "quick", 8)


# -- the plan is a function of the profile and its calibration (issue 50) -------------------------
def test_not_run_is_decided_by_the_stated_calibration_not_the_load(study_references):
    from dataclasses import replace
    from fractions import Fraction
    from types import SimpleNamespace

    from warpcloth.lab import measure
    from warpcloth.lab.configs import Config

    plan = make_plan("quick", integrators=["xpbd"], sizes=[4])
    plan = replace(plan, max_frame_ms=10.0, reference_cache=str(study_references))  # the session's references
    out = SimpleNamespace(done={})
    out.write = lambda row: out.done.__setitem__(row["key"], row)
    m = measure.Measurements(plan, out)
    # the group's calibration, as a resumed study finds it: 1 ms/step at xpbd's defaults
    out.done["calibration|study_sheet|xpbd|cpu|4"] = {"ms_per_step_min": 1.0}
    dear = Config("xpbd", (("iterations", 10), ("substeps", 16)), Fraction(4))  # 4x the default work, 4 steps
    assert m.predicted_ms_per_frame(dear, "cpu", 4) == pytest.approx(16.0)
    row = m.trial("swing", dear, "cpu", 4)
    assert row["note"].startswith("not run: predicted 16 ms per 1/60 s frame from the calibration > 10 ms")
    cheap = Config("xpbd", (("iterations", 10), ("substeps", 4)), Fraction(1))
    assert m.predicted_ms_per_frame(cheap, "cpu", 4) == pytest.approx(1.0)
    assert m.trial("swing", cheap, "cpu", 4)["stable"] is True  # run, whatever the machine's load now
