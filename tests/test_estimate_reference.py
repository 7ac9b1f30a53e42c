"""The estimate's model of the float64 Warp references (issue 48): the steps a reference and its
floor run (h, h/2, ..., h/2^L and two floor runs at h/2^L, L the halvings it takes), checked
against a real reference's steps and against the references of the 2026-12-05 standard
regeneration (docs/study.md, "Estimate"), and printed by ``--estimate``."""

from __future__ import annotations

import math

import pytest

from warpcloth.lab.estimate import (
    _omega,
    estimate_plan,
    format_estimate,
    reference_halvings,
    reference_seconds,
    reference_steps,
)
from warpcloth.lab.plan import make_plan
from warpcloth.lab.reference_warp import RK4_STABILITY_RADIUS
from warpcloth.lab.transients import TRANSIENTS

#: The standard regeneration's floor rows (results.csv): (transient, n) -> (reference_s [s, one core
#: of the shared 2-core CPU, two workers], reference_dt_s [s]: the finest run's step).
MEASURED = {
    ("swing", 16): (2.23, 2.976e-4),
    ("flag", 16): (7.37, 1.488e-4),
    ("swing", 32): (24.2, 1.462e-4),
    ("flag", 32): (50.2, 7.44e-5),
    ("swing", 64): (239.2, 3.655e-5),
    ("flag", 64): (288.5, 3.655e-5),
}


def test_the_model_counts_the_steps_a_reference_and_its_floor_run():
    """A 13x13 swing reference over 4 frames (the study's path): the model's S (each frame in
    ceil(frame / h) steps at h = half the stability limit from the sheet's frequency) and its run
    count give the steps the reference's runs and the two floor runs (at the finest steps) take."""
    from warpcloth.lab.accuracy import reference_for

    tr = TRANSIENTS["swing"]
    sim = tr.scenario.build(rows=13, cols=13)
    ref = reference_for(sim.model, sim.control, 4, tr.start(sim.model))
    halvings = len(ref.estimates)  # runs h, h/2, ..., h/2^L
    finest = sum(ref.piece_steps)
    ran = sum(finest >> (halvings - level) for level in range(halvings + 1)) + 2 * finest
    h = 0.5 * RK4_STABILITY_RADIUS / _omega(13, "cpu")
    assert reference_steps(4, h, halvings) == ran
    assert ref.dt == pytest.approx(h / 2**halvings, rel=0.05)  # frames cut in whole steps: h rounded down


def test_the_halvings_rule_and_the_modelled_time_against_the_regeneration():
    """The halvings the rule gives are those the regeneration's references took (h / finest step),
    and the modelled reference time is within 0.7x-1.4x of each measured one (0.74-1.33 when fitted)."""
    plan = make_plan("standard")
    omega = {n: _omega(n, "cpu") for n in (16, 32, 64)}
    for (name, n), (seconds, dt) in MEASURED.items():
        modelled, halvings, _, h = reference_seconds(name, n, plan.window_frames(name, n), omega[n])
        assert halvings == round(math.log2(h / dt)), (name, n, h, dt)
        assert 0.7 < seconds / modelled < 1.4, (name, n, seconds, modelled)
    assert reference_halvings("swing", 24) == 1 and reference_halvings("flag", 24) == 2  # measured alone
    assert reference_halvings("swing", 128) == reference_halvings("flag", 128) == 2  # the most it takes


def test_estimate_prints_each_references_modelled_halvings_and_time():
    plan = make_plan("standard", integrators=["explicit_euler"], sizes=[16, 64])
    costs = {("explicit_euler", n): (20, 0.05) for n in (16, 64)} | {("omega", 16): 2127.5, ("omega", 64): 8923.9}
    phases = estimate_plan(plan, costs)
    refs = phases[0]
    assert len(refs.details) == 4
    assert refs.details[0].startswith("swing 16x16: h 0.00061 s, 1 halving(s) (finest h/2), 7056 RK4 steps")
    assert refs.details[-1].startswith("flag 64x64: h 0.00015 s, 2 halving(s) (finest h/4), 51300 RK4 steps")
    contact = 1.3 * 54.0 / 4096**1.5 * (256**1.5 + 4096**1.5)
    modelled = sum(
        reference_seconds(t, n, plan.window_frames(t, n), costs[("omega", n)])[0]
        for n in (16, 64)
        for t in ("swing", "flag")
    )
    assert refs.seconds == pytest.approx(modelled + contact)
    text = format_estimate(plan, {"cpu": phases})
    assert "flag 64x64: h 0.00015 s, 2 halving(s)" in text
