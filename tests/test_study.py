"""The accuracy study (warpcloth.lab: accuracy, frontier, study, report; ``warpcloth study``)."""

from __future__ import annotations

import csv
import math
import os

import numpy as np
import pytest

from warpcloth.errors import WarpclothError
from warpcloth.lab.accuracy import (FRAME_DT, AccuracyProblem, Transient, check_tolerance, search_steps_per_frame,
                                    steps_per_frame_at_most)
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
