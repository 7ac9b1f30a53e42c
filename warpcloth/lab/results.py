"""The study's results file: its columns and what each means (docs/study.md is generated from
the same text), its format (:data:`RESULTS`: a :class:`~warpcloth.io.results.ResultsFile` of these
columns, cells parsed back to values) and :func:`read_rows`, shared by the study that writes it
and the report that reads it."""

from warpcloth.io.results import ResultsFormat, parse_cell

COLUMNS = [
    "measurement",
    "scenario",
    "transient",
    "integrator",
    "options",
    "device",
    "rows",
    "cols",
    "particles",
    "springs",
    "dt_s",
    "steps_per_frame",
    "bound_dt_s",
    "search_bounded",
    "transient_s",
    "error_rel",
    "centroid_error_rel",
    "patch_error_rel",
    "damping_rel",
    "max_strain_rel",
    "ref_max_strain_rel",
    "strain_excess_rel",
    "stable",
    "floor_point_rel",
    "floor_centroid_rel",
    "floor_patch_rel",
    "floor_damping_rel",
    "floor_stretch_rel",
    "floor_rest_rel",
    "floor_sag_rel",
    "reference",
    "reference_estimate_rel",
    "reference_estimate_centroid_rel",
    "reference_estimate_patch_rel",
    "reference_estimate_damping_rel",
    "reference_estimate_stretch_rel",
    "reference_dt_s",
    "reference_s",
    "ms_per_step_median",
    "ms_per_step_min",
    "ms_per_step_max",
    "timed_windows",
    "timing_spread_rel",
    "retimed",
    "steps_per_window",
    "ms_per_frame",
    "wall_s_per_sim_s",
    "realtime_factor",
    "realtime_30fps",
    "realtime_60fps",
    "equilibrium_reached",
    "time_to_equilibrium_sim_s",
    "time_to_equilibrium_wall_s",
    "static_error_rel",
    "sag_error_rel",
    "iterations",
    "substeps",
    "trials",
    "measure_wall_s",
    "note",
    "host",
    "worker",
    "concurrent_runs",
    "warpcloth_version",
    "warp_version",
    "key",
]

#: Descriptions of the columns (docs/study.md is generated from the same text).
COLUMN_DOCS = {
    "measurement": "max_stable_dt, floor, trial (a configuration on a dynamic transient), static (one run to rest on "
    "the contact transient), timing (a configuration's cost), calibration (a group's ms/step at the integrator's defaults: the "
    "plan's not-run rule reads it)",
    "scenario": "the cloth: study_sheet, study_flag, study_contact (or a scenario file's)",
    "transient": "swing, flag or contact",
    "integrator": "integrator name",
    "options": "integrator options (k=v, space-separated; empty: the defaults)",
    "device": "Warp device",
    "rows": "particles per column",
    "cols": "particles per row",
    "particles": "rows x cols",
    "springs": "spring count",
    "dt_s": "the time step [s] (of the run, or the search's answer)",
    "steps_per_frame": "k: dt = (1/60 s) / k (0.5: dt = 1/30 s)",
    "bound_dt_s": "the stability search's other side [s] (the smallest unstable dt)",
    "search_bounded": "true: the answer is the search's upper bound (one frame), not a found boundary",
    "transient_s": "the window [s] (a stability trial's duration)",
    "error_rel": "pointwise e = max over frames and particles |x - x_ref| / size (static: the rest shape's)",
    "centroid_error_rel": "max over frames |centre of mass - the reference's| / size",
    "patch_error_rel": "max over frames and 4 x 4 patches |patch mean - the reference's| / size",
    "damping_rel": "numerical damping: 1 - (kinetic energy summed over the frames) / the reference's (< 0: energy "
    "gained)",
    "max_strain_rel": "largest strain of a structural spring in the run (stretch along warp or weft); max_stable_dt: "
    "the largest of any spring at that dt",
    "ref_max_strain_rel": "the reference's largest strain",
    "strain_excess_rel": "over-stretch: max over frames of (the run's largest structural strain - the reference's at the "
    "same instant); > 0.02: over-stretched (the reference's own strain is not a defect)",
    "stable": "the run stayed finite",
    "floor_point_rel": "conditioning floor of e: float64 growth of a 1e-7 m perturbation of the start (2 seeds, max), "
    "/ size",
    "floor_centroid_rel": "floor of the centroid error",
    "floor_patch_rel": "floor of the patch error",
    "floor_damping_rel": "floor of |damping|",
    "floor_stretch_rel": "floor of the largest strain (its change)",
    "floor_rest_rel": "floor of the rest-shape error (contact: the equilibrium solved again from a perturbed start)",
    "floor_sag_rel": "floor of the sag error",
    "reference": "the float64 reference: DOP853 (SciPy), Warp RK4 (with its halving run), Newton+contact",
    "reference_estimate_rel": "the Warp reference's halving estimate / size: max over frames and particles of "
    "|x_h - x_h/2| of its last two runs (accepted for the pointwise e at <= 1e-5)",
    "reference_estimate_centroid_rel": "the same two runs' centroid difference / size (the reference accepted for the "
    "centroid error at <= 1e-5; empty in rows written before it: the pointwise estimate, a bound, stands for it)",
    "reference_estimate_patch_rel": "the same for the 4 x 4 patch means (accepted for the patch error at <= 1e-5)",
    "reference_estimate_damping_rel": "the same two runs' |damping| against each other (accepted for damping at "
    "<= 1e-5)",
    "reference_estimate_stretch_rel": "the same two runs' largest change of the largest strain at one instant "
    "(accepted for stretch at <= 1e-5)",
    "reference_dt_s": "the Warp reference's step [s]",
    "reference_s": "wall seconds of the reference (and its floor runs)",
    "ms_per_step_median": "median over the timed windows [ms]",
    "ms_per_step_min": "fastest window [ms]",
    "ms_per_step_max": "slowest window [ms]",
    "timed_windows": "windows timed",
    "timing_spread_rel": "spread of the timed windows: (slowest - fastest) / median (re-timed above 0.2)",
    "retimed": "how many times the timing was taken again because its spread exceeded 0.2 (the least spread kept)",
    "steps_per_window": "steps per window",
    "ms_per_frame": "median ms per 1/60 s of simulated time (ms/step x k)",
    "wall_s_per_sim_s": "wall seconds per simulated second (median ms/step / dt)",
    "realtime_factor": "simulated seconds per wall second",
    "realtime_30fps": "a 1/30 s frame's steps take <= 1/30 s",
    "realtime_60fps": "a 1/60 s frame's steps take <= 1/60 s",
    "equilibrium_reached": "the cloth came to rest",
    "time_to_equilibrium_sim_s": "simulated time to equilibrium [s]",
    "time_to_equilibrium_wall_s": "wall time to equilibrium [s]",
    "static_error_rel": "max |x - x_eq| / size at rest against the float64 equilibrium with the contact",
    "sag_error_rel": "relative error of the sag (largest displacement from the hanging rest shape)",
    "iterations": "pbd/xpbd iterations",
    "substeps": "pbd/xpbd substeps",
    "trials": "runs the search made",
    "measure_wall_s": "wall seconds the measurement took",
    "note": "why a value is missing, refused or bounded",
    "host": "machine the measurement ran on",
    "worker": "main (serial), local:N (a --workers process) or ray:PID (a Ray task)",
    "concurrent_runs": "most measurement jobs running at once on that host while it ran (1: alone; timings are alone "
    "by default)",
    "warpcloth_version": "",
    "warp_version": "",
    "key": "identity of the measurement (resume)",
}

#: why a fixed-mesh scenario has no accuracy rows
MESH_NOTE = (
    "no float64 reference for this scenario (the study's references are of its own transients; "
    "a scenario file's mesh, kinematic pin tracks and colliders are not modelled there): accuracy not measured"
)

#: The study's results.csv: these columns, values parsed back (:func:`~warpcloth.io.results.parse_cell`).
RESULTS = ResultsFormat(tuple(COLUMNS), what="study", unit="measurement", parse=parse_cell)


def read_rows(path) -> list[dict]:
    """The rows of a study's results.csv, values parsed."""
    return RESULTS.read(path)


__all__ = ["COLUMNS", "COLUMN_DOCS", "MESH_NOTE", "RESULTS", "parse_cell", "read_rows"]
