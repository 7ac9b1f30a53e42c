"""The float64 Warp reference is accepted per metric (issue 48): each metric's halving estimate is
recorded (the metric between the reference's last two runs), a verdict on a metric needs both its
floor and its reference estimate to allow it, and where the pointwise estimate of a chaotic window
does not converge the report and ``advise`` fall back to the metric whose estimate does, naming it
and why the finer ones were refused. Rows written before the per-metric estimates read as before."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from warpcloth.lab.accuracy import (
    METRICS,
    REFERENCE_ESTIMATE_COLUMNS,
    REFERENCE_TOLERANCE,
    Reference,
    _Shape,
    deciding_metric,
    halving_estimates,
    reference_estimate,
    reference_refusal,
)
from warpcloth.lab.reference import cloth_size, swing_from_horizontal
from warpcloth.lab.reference_warp import warp_reference
from warpcloth.lab.results import COLUMNS, RESULTS
from warpcloth.lab.transients import DYNAMIC
from warpcloth.scenarios import sheet

#: The 32x32 flag's reference on the standard profile (0.5 s), measured (docs/study.md, "References"):
#: its pointwise halving estimates 6.8e-4 then 3.8e-5 (not accepted), its coarse shape's converged.
FLAG_32 = {"point": 3.8e-5, "centroid": 3.6e-8, "patch": 6.9e-7, "damping": 2.9e-8, "stretch": 2.2e-6}


def test_every_metric_has_its_halving_estimate_and_the_coarse_ones_are_bounded_by_the_pointwise():
    """On the 6x6 sheet's swing halved three times: per halving an estimate of every metric; the
    pointwise one is the reference's own estimate, the centroid's and the patches' are at most it
    (a mass-weighted mean moves no more than its farthest particle), and all converge (RK4)."""
    sim = sheet.build(rows=6, cols=6, device="cpu")
    model, control = sim.model, sim.control
    x0 = swing_from_horizontal(model)
    estimate = halving_estimates(_Shape(model), cloth_size(model))
    r = warp_reference(model, control, 0.3, 1 / 60, x0=x0, dt=4e-3, tolerance=2e-7, metrics=estimate)
    assert len(r.estimates) >= 3 and len(r.metric_estimates) == len(r.estimates)
    for point, per in zip(r.estimates, r.metric_estimates):
        assert set(per) == set(METRICS) and all(math.isfinite(v) and v >= 0 for v in per.values())
        assert per["point"] == pytest.approx(point, rel=1e-12)
        assert per["centroid"] <= point and per["patch"] <= point
    for m in ("point", "centroid", "patch", "stretch"):
        history = [per[m] for per in r.metric_estimates]
        assert history[-1] < history[0] / 8, (m, history)  # fourth order: 16x per halving, 8x allowed
    # a non-finite run gives inf for every metric (never accepted)
    bad = np.full((3, model.particle_count, 3), np.nan)
    assert set(estimate(bad, bad).values()) == {math.inf}


def test_a_reference_is_accepted_for_the_metrics_whose_estimates_converge():
    ref = Reference(np.zeros((2, 1, 3)), FLAG_32["point"], False, "Warp RK4", metric_estimates=dict(FLAG_32))
    assert [m for m in METRICS if ref.accepted_for(m)] == ["centroid", "patch", "damping", "stretch"]
    assert ref.estimate_of("point") == FLAG_32["point"] and ref.estimate_of("centroid") == FLAG_32["centroid"]
    old = Reference(np.zeros((2, 1, 3)), FLAG_32["point"], False, "Warp RK4")  # a cache made before: pointwise
    assert not any(old.accepted_for(m) for m in METRICS) and old.estimate_of("patch") == FLAG_32["point"]
    assert all(Reference(np.zeros((2, 1, 3)), None, True, "DOP853").accepted_for(m) for m in METRICS)
    small = dict.fromkeys(("point", "patch", "centroid"), 1e-6)
    assert deciding_metric(small, 0.01, FLAG_32) == "patch"  # the floors allow all; the reference not e
    assert deciding_metric(small, 0.01, {**FLAG_32, "patch": 2e-5}) == "centroid"
    assert deciding_metric(small, 0.01, {"point": math.inf, "patch": None, "centroid": 2e-5}) is None


def test_a_floor_row_records_every_metrics_estimate_and_reads_back():
    """The study's own path (Measurements.floor) at 13x13, the smallest Warp reference, over the
    quick profile's flag window cut to 4 frames: the four new columns written, read back, shown."""
    from dataclasses import replace

    from warpcloth.lab import measure
    from warpcloth.lab.plan import make_plan
    from warpcloth.lab.report import Data, floor_table

    plan = make_plan("quick", integrators=["explicit_euler"], sizes=[13])
    plan = replace(plan, windows=(("swing", 4), ("flag", 4)))
    out = SimpleNamespace(done={})
    out.write = lambda row: out.done.__setitem__(row["key"], RESULTS.as_written(row))
    row = measure.Measurements(plan, out).floor("swing", "cpu", 13)
    assert row["reference"] == "Warp RK4" and row["reference_estimate_rel"] <= REFERENCE_TOLERANCE
    for m in METRICS:
        assert 0 <= row[REFERENCE_ESTIMATE_COLUMNS[m]] <= REFERENCE_TOLERANCE, m
        assert reference_refusal(row, "swing", m) == ""
    assert row["reference_estimate_centroid_rel"] <= row["reference_estimate_rel"]
    assert row["note"].endswith("accepted for every metric")
    text = "\n".join(floor_table(Data([row])))
    assert "halving estimates (per metric)" in text and " centroid " in text and "not accepted" not in text


# -- the report and advise fall back to the metric the reference is accepted for ---------------------
def rows_at(n: int, estimates: dict | None, reference: str = "Warp RK4") -> list:
    """A study's rows at n x n for one configuration of explicit_euler: every floor far below the
    tolerance, the reference's halving estimates ``estimates`` (metric -> value; None: a row
    written before the per-metric estimates, its pointwise estimate ``FLAG_32``'s)."""
    base = dict.fromkeys(COLUMNS)
    base.update(device="cpu", rows=n, cols=n, integrator="explicit_euler", options=None, steps_per_frame=1.0)
    out = [dict(base, measurement="max_stable_dt", scenario="study_sheet", dt_s=1 / 60, stable=True)]
    for t in DYNAMIC:
        floor = dict(base, measurement="floor", integrator="reference", transient=t, reference=reference)
        floor.update({f"floor_{m}_rel": 1e-7 for m in ("point", "centroid", "patch", "damping", "stretch")})
        if estimates is None:
            floor["reference_estimate_rel"] = FLAG_32["point"]
            for m in METRICS:
                if m != "point":
                    del floor[REFERENCE_ESTIMATE_COLUMNS[m]]  # an old results.csv has no such column
        else:
            floor.update({REFERENCE_ESTIMATE_COLUMNS[m]: v for m, v in estimates.items()})
        trial = dict(base, measurement="trial", transient=t, stable=True, error_rel=0.02)
        trial.update(centroid_error_rel=0.004, patch_error_rel=0.008, damping_rel=0.001, max_strain_rel=0.01)
        trial.update(ref_max_strain_rel=0.01, strain_excess_rel=0.0)
        out += [floor, trial]
    timing = dict(base, measurement="timing", note="at the configuration dt", ms_per_frame=0.5)
    return out + [dict(timing, scenario="study_sheet", timing_spread_rel=0.04)]


def test_the_report_falls_back_to_the_centroid_where_the_reference_is_accepted_for_it_alone():
    from warpcloth.lab.report import Data, cheapest_tables, deciding_table, floor_table, verdict

    # at 24x24 the reference is accepted for the centroid alone: e and the patch means refused
    data = Data(rows_at(24, {**FLAG_32, "patch": 2e-5}))
    assert data.deciding("cpu", 24, 0.01) == "centroid"
    assert data.cheapest("cpu", "explicit_euler", 24, 0.01, "centroid").error == 0.004
    text = "\n".join(verdict(data, 0.01, 2.0))
    assert (
        "At 24x24, ≤ 1 %: decided on the centroid error over the same window; refused before it: the pointwise e "
        "(the swing reference is not accepted for the pointwise e (its halving estimate 3.8e-05 > 1e-05)" in text
    )
    assert "the 4 x 4 patch error (the swing reference is not accepted for the 4 x 4 patch error (its halving " in text
    table = "\n".join(deciding_table(data, (0.01,)))
    assert "| 24x24 | centroid error (pointwise e, 4 x 4 patch error refused) |" in table
    assert "dt 1/60 s: 0.5 ms ±2 % (centroid 0.4 %)" in "\n".join(cheapest_tables(data, (0.01,)))
    floors = "\n".join(floor_table(data))
    assert "e 3.8e-05 (not accepted), centroid 3.6e-08, patch 2e-05 (not accepted), damping 2.9e-08" in floors
    # the measured 32x32 flag's estimates: the patch means decide (the finer of the two coarse metrics)
    assert Data(rows_at(24, FLAG_32)).deciding("cpu", 24, 0.01) == "patch"


def test_advise_falls_back_to_the_centroid_and_says_why_the_finer_metrics_were_refused():
    from warpcloth.lab.advise import Study, advise, format_advice

    advice = advise(Study(rows_at(24, {**FLAG_32, "patch": 2e-5})), 24, 0.01, 2.0)
    a = advice.answer
    assert a.status == "answer" and a.metric == "centroid" and a.best.error == 0.004
    text = format_advice(advice)
    assert "decided by: centroid error, on swing and flag" in text
    assert "refused first: pointwise e: the swing reference is not accepted for the pointwise e" in text
    assert "4 x 4 patch error: the swing reference is not accepted for the 4 x 4 patch error" in text


def test_rows_written_before_the_per_metric_estimates_are_judged_as_before():
    """An old results.csv (no per-metric columns): the pointwise estimate stands for every metric,
    so a reference not accepted pointwise refuses every verdict, and one accepted allows them."""
    from warpcloth.lab.advise import Study, advise
    from warpcloth.lab.report import Data

    old = rows_at(24, None)
    floor = old[1]
    assert REFERENCE_ESTIMATE_COLUMNS["centroid"] not in floor
    assert reference_estimate(floor, "centroid") == FLAG_32["point"] and reference_refusal(floor, "flag", "centroid")
    assert Data(old).deciding("cpu", 24, 0.10) is None
    assert advise(Study(old), 24, 0.01, 2.0).answer.status == "refused"
    for r in old:
        if r["measurement"] == "floor":
            r["reference_estimate_rel"] = 5e-6  # accepted pointwise: every metric with it, as before
    assert Data(old).deciding("cpu", 24, 0.01) == "point"
    assert Data(rows_at(24, None, reference="DOP853")).deciding("cpu", 24, 0.01) == "point"
