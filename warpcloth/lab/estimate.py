"""An estimate of a study plan's wall time (``warpcloth study --estimate``): per-step costs
measured now (:func:`calibrate`), a model of each phase (:func:`estimate_plan`), and the text
(:func:`format_estimate`). A model, not a measurement: docs/study.md, "Estimate"."""

from __future__ import annotations

import math
import os
from dataclasses import dataclass

from warpcloth.lab.accuracy import FRAME_DT, steps_per_frame_at_most
from warpcloth.lab.plan import SCENARIOS, StudyPlan

#: on the project's 2-core CPU: 5.1 s for the 8x8 sheet's 1 s swing, 15 s at 12x12, 19 s at 16x16)
REFERENCE_S_PER_PARTICLE_S = 0.1
#: the accuracy search of an integrator stable at one frame (implicit_euler, pbd, xpbd, vbd,
#: projective) is modelled as reaching k = this x (n/8)^2 steps per frame: the last standard run
#: found k = 13-76 at 8x8 and 37-416 at 12x12 for them
ACCURATE_K_AT_8 = 64


@dataclass
class PhaseEstimate:
    phase: str
    measurements: int
    seconds: float


def calibrate(plan: StudyPlan, device: str, stream=None) -> dict:
    """Measured ms per step of the sheet for every integrator x size of ``plan`` on ``device`` at
    the integrator's default dt (one frame at most), and at (1/60 s)/64 at the accuracy sizes:
    ``{(integrator, n): (k0, ms at default dt, ms at frame/64 or None)}``. A few steps each
    after a warm-up; seconds in all (the implicit integrators' steps at 128x128 take ~1 s)."""
    from warpcloth.integrators import make_integrator
    from warpcloth.scenarios import get_scenario

    out = {}
    sheet = get_scenario("sheet")

    def ms_per_step(sim, dt):
        """The fastest of 3 windows of about 30 ms (other jobs on the machine only add), with the
        shared timing helper (compile and the first replay excluded)."""
        from warpcloth.run.harness import time_steps

        sim.reset()
        sim.set_dt(dt)
        frame = max(1, math.ceil(FRAME_DT / dt - 1e-9))
        return min(time_steps(sim, windows=3, window_seconds=0.03, batch=min(frame, 20)).ms_per_step)

    for n in plan.all_sizes if plan.grid else []:
        sim = sheet.build(rows=n, cols=n, device=device, integrator="explicit_euler", dt=FRAME_DT)
        for i in plan.integrators:
            sim.set_integrator(make_integrator(i), dt=FRAME_DT)
            k0 = steps_per_frame_at_most(min(make_integrator(i).default_dt(sim.model, sim.control.drag_rate), FRAME_DT))
            small = ms_per_step(sim, FRAME_DT / 64) if n in plan.accuracy_sizes else None
            out[(i, n)] = (k0, ms_per_step(sim, FRAME_DT / k0), small)
            if stream is not None:
                print(f"calibrate {i} {n}x{n} {device}: {out[(i, n)][1]:.3g} ms/step at (1/60 s)/{k0}", file=stream, flush=True)
    return out


def estimate_plan(plan: StudyPlan, costs: dict) -> list[PhaseEstimate]:
    """Seconds per phase of ``plan`` on one device from ``costs`` (:func:`calibrate`), serially.
    A model, not a measurement (docs/study.md, "Estimate"): stability trials at 1.5x the default
    dt (6 trials per search, 1 for an integrator stable at one frame), each capped by the wall cap;
    equilibrium runs to their simulated or wall cap; the float64 references at
    :data:`REFERENCE_S_PER_PARTICLE_S`; accuracy searches of 3 trials at k0 for the explicit
    schemes and doubling to k = :data:`ACCURATE_K_AT_8` (n/8)^2 (bounded by ``accuracy_k_max``)
    then bisection ((3 + log2(0.5 / precision)) k frames) for those stable at one frame; timings their warm-up, capture and windows of whole frames."""
    stab = eq = acc = tim = 0.0
    counts = {"stability": 0, "equilibrium": 0, "accuracy": 0, "timing": 0}
    for n in plan.all_sizes if plan.grid else []:
        for i in plan.integrators:
            k0, ms, ms_small = costs[(i, n)]
            dt0 = FRAME_DT / k0
            # the search's trials straddle the max stable dt, ~1.5-2x the default dt of the explicit
            # schemes (those above it stop early when they blow up): 6 trials at 1.5 dt0
            dt_trial = dt0 if k0 == 1 else 1.5 * dt0
            trial = plan.maxdt_duration_at(n) / dt_trial * ms / 1000.0
            trial = min(trial, plan.maxdt_wall_cap) if plan.maxdt_wall_cap else trial
            stab += len(SCENARIOS) * (1 if k0 == 1 else 6) * trial
            counts["stability"] += len(SCENARIOS)
            run_eq = plan.equilibrium_duration / dt0 * ms / 1000.0
            run_eq = min(run_eq, plan.equilibrium_wall_cap) if plan.equilibrium_wall_cap else run_eq
            eq += run_eq
            counts["equilibrium"] += 1
            frame = k0 * ms / 1000.0
            one_timing = (3 + plan.windows * max(1.0, math.ceil(plan.window_seconds / max(frame, 1e-9)))) * frame
            timings = len(plan.timing_scenarios) * (1 + len(plan.extra_dt_fractions))
            if n in plan.accuracy_sizes:
                timings += len(plan.timing_scenarios)
                eq += 3 * run_eq  # the static-accurate search and the static run at the accurate dt
                counts["equilibrium"] += 2
                for sc in SCENARIOS:
                    T = plan.transient(sc).duration
                    if k0 > 1:
                        acc += 3 * 60 * T * k0 * ms / 1000.0
                    else:
                        k = min(max(plan.accuracy_k_max, 64), ACCURATE_K_AT_8 * (n / 8) ** 2)
                        # doubling to the first k past the answer (~3 k in all), then bisection
                        # trials of ~k each down to the precision
                        trials_k = 3 + math.log2(0.5 / max(plan.accurate_precision, 0.01))
                        acc += 60 * T * trials_k * k * (ms_small if ms_small is not None else ms) / 1000.0
                    counts["accuracy"] += 1
            tim += timings * one_timing
            counts["timing"] += timings
    for n in plan.accuracy_sizes if plan.grid else []:  # references and floors, once per size (per worker process in parallel)
        for sc in SCENARIOS:
            T = plan.transient(sc).duration
            acc += REFERENCE_S_PER_PARTICLE_S * n * n * T
            k0, ms, _ = costs.get(("rk4", n), (1, 0.0, None))
            acc += 60 * T * 4 * k0 * ms / 1000.0
            counts["accuracy"] += 1
    return [PhaseEstimate("stability (max stable dt)", counts["stability"], stab),
            PhaseEstimate("equilibrium and static accuracy", counts["equilibrium"], eq),
            PhaseEstimate("accuracy (references, floors, searches)", counts["accuracy"], acc),
            PhaseEstimate("timing", counts["timing"], tim)]


def format_estimate(plan: StudyPlan, by_device: dict, workers: int = 1) -> str:
    """The estimate as text: per device, per phase, and in all."""
    lines = [f"estimate of profile {plan.profile}: integrators {', '.join(plan.integrators)}; sizes "
             f"{', '.join(map(str, plan.all_sizes))}; accuracy at {', '.join(map(str, plan.accuracy_sizes)) or 'none'}"]
    total = 0.0
    for d, phases in by_device.items():
        for ph in phases:
            lines.append(f"  {d:6s} {ph.phase:42s} {ph.measurements:4d} measurements  {ph.seconds / 60:7.1f} min")
            total += ph.seconds
    lines.append(f"  total about {total / 60:.0f} min serially" + (f"; the searches split over {workers} workers, the timings not" if workers > 1 else ""))
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else None
    if load is not None:
        lines.append(f"  load average {load:.1f} on {os.cpu_count()} cores while calibrating: other jobs' share is in the per-step costs")
    lines.append("  (a model from per-step costs measured now: see docs/study.md, 'Estimate'; --match-accuracy is not included"
                 + (f"; nor the scenarios {', '.join(plan.scenario_files)}" if plan.scenario_files else "") + ")")
    return "\n".join(lines)


__all__ = ["ACCURATE_K_AT_8", "PhaseEstimate", "REFERENCE_S_PER_PARTICLE_S", "calibrate", "estimate_plan",
           "format_estimate"]
