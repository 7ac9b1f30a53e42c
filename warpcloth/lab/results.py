"""The study's results file: its columns and what each means (docs/study.md is generated from
the same text), its format (:data:`RESULTS`: a :class:`~warpcloth.io.results.ResultsFile` of these
columns, cells parsed back to values) and :func:`read_rows`, shared by the study that writes it
and the report that reads it."""

from warpcloth.io.results import ResultsFormat, parse_cell

COLUMNS = [
    "measurement", "scenario", "integrator", "options", "device", "rows", "cols", "particles", "springs",
    "dt_s", "steps_per_frame", "bound_dt_s", "search_bounded", "tolerance_rel", "error_rel", "floor_error_rel",
    "transient_s", "max_strain_rel", "stable",
    "ms_per_step_median", "ms_per_step_min", "ms_per_step_max", "timed_windows", "steps_per_window",
    "wall_s_per_sim_s", "realtime_factor", "realtime_30fps", "realtime_60fps",
    "equilibrium_reached", "time_to_equilibrium_sim_s", "time_to_equilibrium_wall_s", "static_error_rel",
    "sag_error_rel", "iterations", "substeps", "trials", "measure_wall_s", "note",
    "host", "worker", "concurrent_runs", "warpcloth_version", "warp_version", "key",
]

#: Descriptions of the columns (docs/study.md is generated from the same text).
COLUMN_DOCS = {
    "measurement": "max_stable_dt, floor, error, max_accurate_dt, static, max_static_accurate_dt, timing, match, match_result",
    "scenario": "sheet or flag", "integrator": "integrator name", "options": "integrator options (k=v, space-separated)",
    "device": "Warp device", "rows": "particles per column", "cols": "particles per row", "particles": "rows x cols",
    "springs": "spring count",
    "dt_s": "the time step [s] (of the run, or the search's answer)", "steps_per_frame": "k: dt = (1/60 s) / k",
    "bound_dt_s": "the search bracket's other side [s] (the smallest unstable / largest inaccurate dt)",
    "search_bounded": "true: the answer is the search's upper bound (one frame, or the max stable dt), not a found boundary",
    "tolerance_rel": "accuracy tolerance, fraction of the cloth size", "error_rel": "e = max |x - x_ref| / size",
    "floor_error_rel": "the float32 noise floor of the transient (rk4 at a tiny dt), fraction of the size",
    "transient_s": "length of the transient [s]", "max_strain_rel": "largest spring strain reached",
    "stable": "the run stayed stable",
    "ms_per_step_median": "median over the timed windows [ms]", "ms_per_step_min": "fastest window [ms]",
    "ms_per_step_max": "slowest window [ms]", "timed_windows": "windows timed", "steps_per_window": "steps per window",
    "wall_s_per_sim_s": "wall seconds per simulated second (median ms/step / dt)",
    "realtime_factor": "simulated seconds per wall second", "realtime_30fps": "a 1/30 s frame's steps take <= 1/30 s",
    "realtime_60fps": "a 1/60 s frame's steps take <= 1/60 s", "equilibrium_reached": "the sheet came to rest",
    "time_to_equilibrium_sim_s": "simulated time to equilibrium [s]", "time_to_equilibrium_wall_s": "wall time to equilibrium [s]",
    "static_error_rel": "max |x - x_eq| / size against the float64 equilibrium",
    "sag_error_rel": "relative error of the sag (largest displacement from rest)",
    "iterations": "pbd/xpbd iterations", "substeps": "pbd/xpbd substeps", "trials": "runs the search made",
    "measure_wall_s": "wall seconds the measurement took", "note": "why a value is missing or bounded",
    "host": "machine the measurement ran on", "worker": "main (serial), local:N (a --workers process) or ray:PID (a Ray task)",
    "concurrent_runs": "most measurement jobs running at once on that host while it ran (1: alone; timings are alone by default)",
    "warpcloth_version": "", "warp_version": "", "key": "identity of the measurement (resume)",
}

#: why a fixed-mesh scenario has no accuracy rows
MESH_NOTE = ("no float64 reference for this scenario (warpcloth.lab.reference integrates the sheet and flag transients; "
             "a scenario file's mesh, kinematic pin tracks and colliders are not modelled there): accuracy not measured")

#: The study's results.csv: these columns, values parsed back (:func:`~warpcloth.io.results.parse_cell`).
RESULTS = ResultsFormat(tuple(COLUMNS), what="study", unit="measurement", parse=parse_cell)


def read_rows(path) -> list[dict]:
    """The rows of a study's results.csv, values parsed."""
    return RESULTS.read(path)


__all__ = ["COLUMNS", "COLUMN_DOCS", "MESH_NOTE", "RESULTS", "parse_cell", "read_rows"]
