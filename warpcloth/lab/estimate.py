"""An estimate of a study plan's wall time (``warpcloth study --estimate``): per-step costs
measured now (:func:`calibrate`), or for a CUDA plan where no GPU is, those recorded on an H200
(:func:`recorded_costs`); a model of each phase (:func:`estimate_plan`), and the text
(:func:`format_estimate`). A model, not a measurement: docs/study.md, "Estimate"; docs/gpu.md."""

from __future__ import annotations

import math
import os
from dataclasses import dataclass

from warpcloth.integrators import integrator_class, make_integrator
from warpcloth.lab.accuracy import FRAME_DT, SCIPY_MAX_SIZE
from warpcloth.lab.configs import configurations, static_configurations, steps_for, study_options, work
from warpcloth.lab.plan import StudyPlan
from warpcloth.lab.reference import Float64Model
from warpcloth.lab.reference_warp import stability_limit
from warpcloth.lab.transients import DYNAMIC, TRANSIENTS
from warpcloth.run.harness import time_steps

#: SciPy DOP853 (<= 12 x 12): seconds per particle per simulated second (measured on the
#: project's 2-core CPU: 5.1 s for an 8 x 8 sheet's 1 s swing, 15 s at 12 x 12).
REFERENCE_S_PER_PARTICLE_S = 0.1
#: The float64 Warp RK4 reference: seconds per particle per RK4 step on one CPU core (measured:
#: 6.5 ms per step at 128 x 128, 0.43 ms at 32 x 32: about 0.4 us per particle); a CUDA device
#: is modelled at :data:`GPU_REFERENCE_S_PER_STEP` per step (launch-bound at these sizes).
REFERENCE_S_PER_PARTICLE_STEP = 0.4e-6
GPU_REFERENCE_S_PER_STEP = 0.25e-3
#: The float64 contact equilibrium (Newton with a sparse direct solve): seconds ~ this x N^1.5
#: (measured on the loaded 2-core CPU: 54 s at 64 x 64, 27 Newton steps; 7 s at 32 x 32).
CONTACT_S = 54.0 / 4096**1.5
#: Simulated seconds a contact run takes to come to rest (measured 1.7-2.4 s at 4 x 4 and 6 x 6).
CONTACT_REST_S = 3.0
#: Runs of a Warp reference and its floor: h, h/2, and two floor runs at h/2, in units of the h run.
REFERENCE_RUNS = 7.0
#: Measured / modelled on the standard profile's 16 x 16 groups (``--sizes 16 --workers 2`` on
#: the project's 2-core CPU at load average ~7, 2026-12-02; docs/study.md, "Estimate"): the
#: configuration runs took 2.5x the model (their frames' host copies and metrics, the workers
#: sharing the cores), the timings 3.4x (a warm-up and a graph capture per configuration).
TRIAL_FACTOR = 2.5
TIMING_FACTOR = 3.4
#: Two search workers on 2 cores gave 1.6x, not 2x (measured on the same run).
WORKER_SPEEDUP = {1: 1.0, 2: 1.6}
#: Kernel compilation of a study on a fresh CUDA machine [s]: an allowance, not measured on a GPU
#: (20x a cold ``warpcloth run sheet``'s 6 s on the CPU, bench/results/cold-compile.txt, for the
#: study's 22 kernel modules and Warp's own; docs/gpu.md); a CUDA estimate adds it once.
GPU_COMPILE_ALLOWANCE_S = 120.0
#: Where :data:`H200_COSTS` were measured (:func:`format_estimate` names it).
RECORDED_ON = "one NVIDIA H200 on 2026-12-04 (bench/results/cuda-h200.txt)"
#: :func:`calibrate`'s costs recorded on :data:`RECORDED_ON` for the study's sheet at 64 x 64 and
#: 128 x 128 (its ``calibrate`` lines: k0 steps per 1/60 s frame, ms per step; k0 is what the code
#: gives today), and the sheet's highest frequency [rad/s] (Lanczos on the CPU: the device does not
#: change it). Its larger sizes were another cloth (clamped membrane springs: docs/gpu.md).
H200_COSTS = {
    ("explicit_euler", 64): (142, 0.00846),
    ("midpoint", 64): (218, 0.0159),
    ("rk4", 64): (128, 0.032),
    ("verlet", 64): (142, 0.00874),
    ("implicit_euler", 64): (1, 2.73),
    ("pbd", 64): (1, 1.35),
    ("xpbd", 64): (1, 1.66),
    ("vbd", 64): (1, 1.84),
    ("projective", 64): (1, 3.07),
    ("explicit_euler", 128): (341, 0.0108),
    ("midpoint", 128): (435, 0.0208),
    ("rk4", 128): (307, 0.0417),
    ("verlet", 128): (341, 0.0111),
    ("implicit_euler", 128): (1, 6.24),
    ("pbd", 128): (1, 1.41),
    ("xpbd", 128): (1, 1.72),
    ("vbd", 128): (1, 2.48),
    ("projective", 128): (1, 5.3),
    ("omega", 64): 8923.9,
    ("omega", 128): 17749.3,
}


@dataclass
class PhaseEstimate:
    phase: str
    measurements: int
    seconds: float
    parallel: bool = True  # split over the workers (the timings are not)


def _omega(n: int, device: str) -> float:
    """The study sheet's highest frequency [rad/s] at n x n (Lanczos, as the reference)."""
    tr = TRANSIENTS["swing"]
    sim = tr.scenario.build(rows=n, cols=n, device="cpu", integrator="explicit_euler")
    return stability_limit(Float64Model.from_model(sim.model, sim.control), tr.start(sim.model)).rho


def calibrate(plan: StudyPlan, device: str, stream=None) -> dict:
    """Measured ms per step of the study's sheet for every integrator x size of ``plan`` on
    ``device`` at the integrator's default options and dt (one frame at most), and each size's
    highest frequency: ``{(integrator, n): (k0, ms), ("omega", n): rad/s}``. A few steps each after
    a warm-up; seconds to a minute in all."""
    out = {}
    sheet = TRANSIENTS["swing"].scenario

    def ms_per_step(sim, dt):
        """The fastest of 3 windows of about 30 ms (other jobs on the machine only add)."""
        sim.reset()
        sim.set_dt(dt)
        frame = max(1, math.ceil(FRAME_DT / dt - 1e-9))
        return min(time_steps(sim, windows=3, window_seconds=0.03, batch=min(frame, 20)).ms_per_step)

    for n in plan.all_sizes if plan.grid else []:
        sim = sheet.build(rows=n, cols=n, device=device, integrator="explicit_euler", dt=FRAME_DT)
        out[("omega", n)] = _omega(n, device)
        for i in plan.integrators:
            sim.set_integrator(make_integrator(i, **study_options(i)), dt=FRAME_DT)
            k0 = steps_for(min(make_integrator(i).default_dt(sim.model, sim.control.drag_rate), FRAME_DT))
            out[(i, n)] = (k0, ms_per_step(sim, FRAME_DT / k0))
            if stream is not None:
                print(
                    f"calibrate {i} {n}x{n} {device}: {out[(i, n)][1]:.3g} ms/step at (1/60 s)/{k0}",
                    file=stream,
                    flush=True,
                )
    return out


def recorded_costs(plan: StudyPlan) -> dict | None:
    """:data:`H200_COSTS` for every integrator x size of ``plan`` (:func:`calibrate`'s form), or
    None where one is not recorded (or the plan has no grid): then there is no figure to give."""
    need = [key for n in plan.all_sizes for key in [("omega", n)] + [(i, n) for i in plan.integrators]]
    if not plan.grid or any(key not in H200_COSTS for key in need):
        return None
    return {key: H200_COSTS[key] for key in need}


def estimate_plan(plan: StudyPlan, costs: dict, device: str = "cpu") -> list[PhaseEstimate]:
    """Seconds per phase of ``plan`` on one device from ``costs`` (:func:`calibrate`). A model,
    not a measurement (docs/study.md, "Estimate"):

    * references: DOP853 at :data:`REFERENCE_S_PER_PARTICLE_S`, or the Warp RK4 at half its
      stability limit 2.61 / omega, :data:`REFERENCE_RUNS` runs of the window (with the floor's),
      at :data:`REFERENCE_S_PER_PARTICLE_STEP`; the contact equilibrium at :data:`CONTACT_S` N^1.5;
    * stability: 6 trials of the swing's window (its sheet) at 1.5x the default dt for the
      explicit schemes, 1 trial for those stable at one frame, each at most the wall cap;
    * trials: every configuration x 2 transients, frames x k steps at the calibrated ms/step x
      :func:`~warpcloth.lab.configs.work` per step, each at most twice the plan's ``run_wall_cap``;
      one whose ms per frame so predicted exceeds the plan's ``max_frame_ms`` is not run (the
      study's own rule, from its calibration rows);
    * contact: 2 runs of :data:`CONTACT_REST_S` simulated, at most the wall cap;
    * timings: warm-up, capture and the timed windows of every configuration that ran;
    * on a CUDA device, kernel compilation: :data:`GPU_COMPILE_ALLOWANCE_S` (an allowance);

    the configurations and the timings scaled by :data:`TRIAL_FACTOR` and :data:`TIMING_FACTOR`,
    measured on a standard run."""
    ref = stab = trials = contact = tim = 0.0
    counts = {"ref": 0, "stab": 0, "trial": 0, "contact": 0, "timing": 0}
    cap = plan.run_wall_cap
    for n in plan.all_sizes if plan.grid else []:
        particles = n * n
        omega = costs.get(("omega", n))
        for name in DYNAMIC:
            frames = plan.window_frames(name, n)
            if n <= SCIPY_MAX_SIZE:
                ref += 3 * REFERENCE_S_PER_PARTICLE_S * particles * frames * FRAME_DT
            else:
                steps = frames * FRAME_DT / (0.5 * 2.61 / omega) if omega else 0.0
                per = (
                    GPU_REFERENCE_S_PER_STEP if device.startswith("cuda") else REFERENCE_S_PER_PARTICLE_STEP * particles
                )
                ref += REFERENCE_RUNS * steps * per
            counts["ref"] += 1
        contact_here = n <= plan.contact_max_size
        if contact_here:
            ref += 1.3 * CONTACT_S * particles**1.5  # the solve, and two floor solves from it (a step or two each)
            counts["ref"] += 1
        for i in plan.integrators:
            k0, ms = costs[(i, n)]
            explicit = integrator_class(i).explicit
            dt0 = FRAME_DT / k0
            trial = plan.maxdt_duration_at(n) / (1.5 * dt0 if explicit else dt0) * ms / 1000.0
            trial = min(trial, plan.maxdt_wall_cap) if plan.maxdt_wall_cap else trial
            stab += (6 if explicit else 1) * trial
            counts["stab"] += 1
            configs = configurations(i, dt0 if explicit else None, plan.level, n)
            for c in configs:
                per_step = ms / 1000.0 * work(i, c.option_dict)
                run = 0.0
                if plan.max_frame_ms is not None and 1000.0 * float(c.k) * per_step > plan.max_frame_ms:
                    counts["trial"] += len(DYNAMIC)  # not run: a row each
                    continue
                for name in DYNAMIC:
                    run += min(plan.window_frames(name, n) * float(c.k) * per_step, 2.0 * cap)
                    counts["trial"] += 1
                trials += run
                if run > 0:
                    frame = float(c.k) * per_step
                    tim += (
                        3 + plan.timing_windows * max(1.0, math.ceil(plan.window_seconds / max(frame, 1e-9)))
                    ) * frame
                    counts["timing"] += 1
            for c in static_configurations(i, dt0 if explicit else None) if contact_here else []:
                seconds = CONTACT_REST_S * FRAME_DT**-1 * float(c.k) * ms / 1000.0
                contact += min(seconds, plan.equilibrium_wall_cap or seconds)
                counts["contact"] += 1
    phases = [
        PhaseEstimate("references and floors (shared by the integrators)", counts["ref"], ref),
        PhaseEstimate("stability (max stable dt)", counts["stab"], stab),
        PhaseEstimate("configurations on the swing and the flag", counts["trial"], TRIAL_FACTOR * trials),
        PhaseEstimate("contact runs to rest", counts["contact"], contact),
        PhaseEstimate("timings (one at a time)", counts["timing"], TIMING_FACTOR * tim, parallel=False),
    ]
    if device.startswith("cuda"):
        phases.append(PhaseEstimate("compilation (an allowance, not measured)", 0, GPU_COMPILE_ALLOWANCE_S, False))
    return phases


def total_seconds(phases: list, workers: int = 1) -> float:
    """The wall time of ``phases`` with ``workers`` search workers (the references are shared,
    the timings run alone)."""
    speedup = WORKER_SPEEDUP.get(max(1, workers), 0.8 * max(1, workers))
    return sum(ph.seconds / (speedup if ph.parallel else 1) for ph in phases)


def format_estimate(plan: StudyPlan, by_device: dict, workers: int = 1, recorded: str | None = None) -> str:
    """The estimate as text: per device, per phase, and in all. ``recorded``: where the per-step
    costs were measured when they were not measured now (:data:`RECORDED_ON`)."""
    lines = [
        f"estimate of profile {plan.profile}: integrators {', '.join(plan.integrators)}; sizes "
        f"{', '.join(map(str, plan.all_sizes))} (every size with a float64 reference); configurations {plan.level}"
    ]
    serial = parallel = 0.0
    for d, phases in by_device.items():
        for ph in phases:
            lines.append(f"  {d:6s} {ph.phase:52s} {ph.measurements:5d} measurements  {ph.seconds / 60:7.1f} min")
        serial += total_seconds(phases, 1)
        parallel += total_seconds(phases, workers)
    lines.append(
        f"  total about {serial / 60:.0f} min serially"
        + (f" ({serial / 60:.1f} min of device time)" if recorded else "")
        + (
            f", about {parallel / 60:.0f} min with --workers {workers} (the searches split, the timings not)"
            if workers > 1
            else ""
        )
    )
    if recorded:
        lines.append(
            f"  a model from the per-step costs recorded on {recorded}, not measured here (no such device here); "
            "see docs/gpu.md"
        )
        return "\n".join(lines)
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else None
    if load is not None:
        lines.append(
            f"  load average {load:.1f} on {os.cpu_count()} cores while calibrating: other jobs' share is in the "
            "per-step costs"
        )
    lines.append(
        "  (a model from per-step costs measured now: see docs/study.md, 'Estimate'"
        + (f"; the scenarios {', '.join(plan.scenario_files)} are not included" if plan.scenario_files else "")
        + ")"
    )
    return "\n".join(lines)


__all__ = [
    "CONTACT_REST_S",
    "CONTACT_S",
    "GPU_COMPILE_ALLOWANCE_S",
    "H200_COSTS",
    "RECORDED_ON",
    "REFERENCE_RUNS",
    "REFERENCE_S_PER_PARTICLE_S",
    "REFERENCE_S_PER_PARTICLE_STEP",
    "TIMING_FACTOR",
    "TRIAL_FACTOR",
    "WORKER_SPEEDUP",
    "PhaseEstimate",
    "calibrate",
    "estimate_plan",
    "format_estimate",
    "recorded_costs",
    "total_seconds",
]
