"""The study's report: ``report.md`` and PNG plots, generated from results.csv alone.

Every sentence is a template filled from the rows (and the plan): nothing is written by hand
for one run. Without matplotlib the report says that the plots need ``pip install
'warpcloth[plot]'``.
"""

from __future__ import annotations

import math
import os
import sys

from warpcloth.io.files import AtomicFile, write_atomic
from warpcloth.io.provenance import machine
from warpcloth.lab.frontier import frontier
from warpcloth.lab.results import COLUMN_DOCS, COLUMNS, MESH_NOTE

PLOTS = {
    "wall_per_sim_second.png": "Wall seconds per simulated second vs particles (log-log) at each integrator's max accurate dt",
    "max_dt.png": "Max stable dt (sheet, solid) and max accurate dt (the smaller of the two transients', dashed) vs particles",
    "frontier.png": "Real-time frontier (30 FPS) per integrator x device, at the max accurate dt and at the max stable dt",
    "error_vs_dt.png": "Error e vs dt at the smallest accuracy size, every integrator (the slope is the order)",
    "time_to_equilibrium.png": "Time to equilibrium of the sheet (simulated and wall) per integrator x size, at the max stable dt",
}


# -- reading the rows ------------------------------------------------------------------------
def _rows(rows, measurement, /, **match):
    return [r for r in rows if r["measurement"] == measurement and all(r.get(k) == v for k, v in match.items())]


def _one(rows, measurement, /, **match):
    found = _rows(rows, measurement, **match)
    return found[-1] if found else None


def _g(x, unit="", digits=3):
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "–"
    if isinstance(x, float) and math.isinf(x):
        return "∞"
    return f"{x:.{digits}g}{unit}"


def _pct(x):
    return "–" if x is None else ("∞" if isinstance(x, float) and math.isinf(x) else f"{100 * x:.3g} %")


def _yn(x):
    return "–" if x is None else ("yes" if x else "no")


class Data:
    """The rows of a study, indexed."""

    def __init__(self, rows):
        self.mesh_rows = [r for r in rows if r["rows"] is None]  # fixed-mesh scenarios (--scenarios FILE.toml)
        rows = [r for r in rows if r["rows"] is not None]
        self.rows = rows
        self.devices = list(dict.fromkeys(r["device"] for r in rows))
        self.integrators = list(dict.fromkeys(r["integrator"] for r in rows if r["measurement"] == "max_stable_dt"))
        self.sizes = sorted({r["rows"] for r in rows if r["measurement"] == "max_stable_dt"})
        self.accuracy_sizes = sorted({r["rows"] for r in rows if r["measurement"] == "max_accurate_dt"})

    def stable(self, d, i, n, sc="sheet"):
        r = _one(self.rows, "max_stable_dt", device=d, integrator=i, rows=n, scenario=sc)
        return r

    def accurate(self, d, i, n, sc):
        return _one(self.rows, "max_accurate_dt", device=d, integrator=i, rows=n, scenario=sc)

    def accurate_dt(self, d, i, n):
        dts = [self.accurate(d, i, n, sc) for sc in ("sheet", "flag")]
        if any(r is None or r["dt_s"] is None for r in dts):
            return None
        return min(r["dt_s"] for r in dts)

    def timing(self, d, i, n, label, sc="sheet"):
        for r in self.rows:
            if (r["measurement"] == "timing" and r["device"] == d and r["integrator"] == i and r["rows"] == n
                    and r["scenario"] == sc and (r["options"] is None) == (label != "matched") and r["note"] == f"at the {label} dt"):
                return r
        return None

    def static(self, d, i, n, dt):
        if dt is None:
            return None
        for r in self.rows:
            if (r["measurement"] == "static" and r["device"] == d and r["integrator"] == i and r["rows"] == n
                    and r["options"] is None and r["dt_s"] is not None and abs(r["dt_s"] - dt) <= 1e-12 * dt):
                return r
        return None

    def frontier(self, d, i, label):
        pts = [(n * n, t["wall_s_per_sim_s"]) for n in self.sizes + self.accuracy_sizes
               for t in [self.timing(d, i, n, label)] if t is not None and t["wall_s_per_sim_s"]]
        pts = sorted(set(pts))
        if not pts:
            return None
        return frontier([p for p, _ in pts], [c for _, c in pts])


# -- the verdict -----------------------------------------------------------------------------
def verdict(data: Data, tolerance) -> list[str]:
    out = []
    tol = _pct(tolerance)
    for d in data.devices:
        sizes = [n for n in data.accuracy_sizes if any(data.timing(d, i, n, "accurate") for i in data.integrators)]
        held, rejected, alt = [], [], []
        for n in sizes:
            rt, slow, none = [], [], []
            for i in data.integrators:
                t = data.timing(d, i, n, "accurate")
                if t is None:
                    none.append(i)
                elif t["realtime_30fps"]:
                    rt.append(i)
                else:
                    slow.append(i)
            if not slow and not none:
                held.append(f"{n}x{n}")
            else:
                rejected.append(f"{n}x{n} (not real-time at 30 FPS: {', '.join(slow + [f'{i} (no accurate dt)' for i in none])})")
            if rt and (slow or none):
                alt.append(f"{n}x{n} (real-time: {', '.join(rt)})")
        out.append(f"**Null hypothesis** (every integrator real-time) on {d}, at {tol} accuracy and 30 FPS: "
                   + (f"holds at {', '.join(held)}" if held else "holds at no measured size")
                   + (f"; rejected at {'; '.join(rejected)}." if rejected else "."))
        out.append(f"**Alternative hypothesis** (some integrators prohibitively expensive, others real-time) on {d}: "
                   + (f"supported at {'; '.join(alt)}." if alt else "not shown at any measured size (either all or none are real-time there)."))
        for n in sizes:
            costs = sorted((t["wall_s_per_sim_s"], i) for i in data.integrators
                           for t in [data.timing(d, i, n, "accurate")] if t is not None and t["wall_s_per_sim_s"])
            if costs:
                c0, i0 = costs[0]
                c1, i1 = costs[-1]
                out.append(f"Cheapest per simulated second at {n}x{n} on {d} (at its max accurate dt): {i0}, "
                           f"{_g(c0)} wall s per simulated s" + (f"; the most expensive, {i1}, costs {_g(c1 / c0)}x as much." if len(costs) > 1 else
                                                                 " (the only integrator with an accurate dt here)."))
        for n in [s for s in data.sizes if s not in data.accuracy_sizes]:
            costs = sorted((t["wall_s_per_sim_s"], i) for i in data.integrators
                           for t in [data.timing(d, i, n, "stable")] if t is not None and t["wall_s_per_sim_s"])
            if costs:
                rt = [i for c, i in costs if data.timing(d, i, n, "stable")["realtime_30fps"]]
                out.append(f"At {n}x{n} on {d} (no float64 reference at this size, so at the max stable dt, accuracy not measured): "
                           f"cheapest {costs[0][1]} ({_g(costs[0][0])} wall s per simulated s); real-time at 30 FPS: "
                           f"{', '.join(rt) if rt else 'none'}.")
        force = [i for i in data.integrators if i not in ("pbd", "xpbd")]
        for i in [i for i in data.integrators if i in ("pbd", "xpbd")]:
            for n in data.accuracy_sizes:
                dt_i = data.accurate_dt(d, i, n)
                best_force = [data.accurate_dt(d, f, n) for f in force]
                best_force = max([x for x in best_force if x is not None], default=None)
                m = _one(data.rows, "match_result", device=d, integrator=i, rows=n)
                head = (f"{i} at {n}x{n} on {d} with its default iterations and substeps: max accurate dt "
                        f"{_g(dt_i, ' s')}" + (f" (the force-based integrators' best: {_g(best_force, ' s')})" if best_force else ""))
                if m is not None and m["iterations"] is not None:
                    head += (f"; to reach {tol} on both transients at dt = 1/60 s it needs {m['iterations']} iterations x "
                             f"{m['substeps']} substeps ({_g(m['wall_s_per_sim_s'])} wall s per simulated s, real-time at 30 FPS: "
                             f"{_yn(m['realtime_30fps'])}).")
                elif m is not None:
                    head += f"; at dt = 1/60 s (--match-accuracy), {m['note']}."
                else:
                    head += "; the iterations needed at 1/60 s were not searched (run with --match-accuracy)."
                out.append(head)
    return out


# -- tables ----------------------------------------------------------------------------------
def _table(header, rows) -> list[str]:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    return lines


def scenario_tables(rows: list) -> list[str]:
    """The fixed-mesh scenarios' table: max stable dt, ms/step and real time there, time to
    equilibrium; and why there is no accuracy."""
    body, cost = [], []
    for sc in dict.fromkeys(r["scenario"] for r in rows):
        for d in dict.fromkeys(r["device"] for r in rows if r["scenario"] == sc):
            for i in dict.fromkeys(r["integrator"] for r in rows if r["scenario"] == sc and r["device"] == d):
                st = _one(rows, "max_stable_dt", scenario=sc, device=d, integrator=i)
                t = _one(rows, "timing", scenario=sc, device=d, integrator=i)
                eq = _one(rows, "static", scenario=sc, device=d, integrator=i)
                if st is None:
                    continue
                dt = st["dt_s"]
                body.append([f"`{sc}`", i, d, st["particles"], st["springs"],
                             ("≥ " if st["search_bounded"] else "") + _g(dt, " s") + (" (one frame: the search's limit)" if st["search_bounded"] else "")])
                cost.append([f"`{sc}`", i, d, _g(t["ms_per_step_median"]) if t else "–", _g(t["wall_s_per_sim_s"]) if t else "–",
                             _yn(t["realtime_30fps"]) if t else "–", _yn(t["realtime_60fps"]) if t else "–",
                             (_g(eq["time_to_equilibrium_sim_s"], " s") if eq and eq["equilibrium_reached"] else "not at rest") if eq else "–"])
    out = [f"Measured at each scenario's own mesh: the max stable dt, ms/step at it (rounded down to (1/60 s)/k) and "
           f"time to equilibrium there. {MESH_NOTE[0].upper()}{MESH_NOTE[1:]}.", ""]
    out += _table(["scenario", "integrator", "device", "particles", "springs", "max stable dt"], body) + [""]
    out += _table(["scenario", "integrator", "device", "ms/step", "wall s / sim s", "30 FPS", "60 FPS", "to equilibrium (sim)"], cost)
    return out + [""]


def tables(data: Data) -> list[str]:
    out = []
    for d in data.devices:
        out += [f"### Per integrator and size on {d}", ""]
        limits, costs, rest = [], [], []
        for n in sorted(set(data.sizes) | set(data.accuracy_sizes)):
            for i in data.integrators:
                st, fl = data.stable(d, i, n, "sheet"), data.stable(d, i, n, "flag")
                if st is None:
                    continue
                a_s, a_f = data.accurate(d, i, n, "sheet"), data.accurate(d, i, n, "flag")
                ts, ta = data.timing(d, i, n, "stable"), data.timing(d, i, n, "accurate")
                eq = data.static(d, i, n, ts["dt_s"] if ts else None)
                acc_dt = data.accurate_dt(d, i, n)
                seq = data.static(d, i, n, acc_dt)
                msa = _one(data.rows, "max_static_accurate_dt", device=d, integrator=i, rows=n)

                def dtcell(r):
                    if r is None:
                        return "–"
                    v = _g(r["dt_s"], " s")
                    return ("≥ " + v) if r.get("search_bounded") and r["dt_s"] is not None else v

                def ms(t):
                    return "–" if t is None else f"{_g(t['ms_per_step_median'])} [{_g(t['ms_per_step_min'])}–{_g(t['ms_per_step_max'])}]"

                key = [i, f"{n}x{n}"]
                limits.append(key + [dtcell(st), dtcell(fl), _pct(st["max_strain_rel"]),
                                     dtcell(a_s) + (f" (e {_pct(a_s['error_rel'])})" if a_s and a_s["error_rel"] is not None else ""),
                                     dtcell(a_f), dtcell(msa), _pct(seq["static_error_rel"]) if seq else "–"])
                costs.append(key + [ms(ts), ms(ta), _g(ta["wall_s_per_sim_s"]) if ta else "–",
                                    _yn(ta["realtime_30fps"]) if ta else "–", _yn(ta["realtime_60fps"]) if ta else "–",
                                    _g(ts["wall_s_per_sim_s"]) if ts else "–", _yn(ts["realtime_30fps"]) if ts else "–"])
                rest.append(key + [_g(eq["time_to_equilibrium_sim_s"], " s") if eq else "–",
                                   _g(eq["time_to_equilibrium_wall_s"], " s") if eq else "–"])
        # three tables of at most 10 columns (one of 18 did not fit a page): limits, cost, rest
        out += [f"#### Time-step limits and accuracy on {d}", ""]
        out += _table(["integrator", "size", "max stable dt sheet", "max stable dt flag", "max strain at it",
                       "max accurate dt sheet swing", "max accurate dt flag", "max static-accurate dt",
                       "static error at accurate dt"], limits)
        out += ["", f"#### Cost and real time on {d}", ""]
        out += _table(["integrator", "size", "ms/step at stable dt (median [min–max])", "ms/step at accurate dt",
                       "wall s / sim s (accurate)", "RT 30 FPS (accurate)", "RT 60 FPS (accurate)", "wall s / sim s (stable)",
                       "RT 30 FPS (stable)"], costs)
        out += ["", f"#### Time to equilibrium at the max stable dt on {d}", ""]
        out += _table(["integrator", "size", "time to equilibrium (sim)", "(wall)"], rest)
        out += ["", "“≥” marks a search that stopped at its upper bound (one 60 FPS frame, or the max stable dt): "
                "the true limit is at least that. “–”: not measured at this size (no float64 reference above the accuracy sizes) or no dt found.", ""]
        out += [f"### Real-time frontier on {d} (30 FPS: wall s per simulated s ≤ 1)", ""]
        body = []
        for i in data.integrators:
            labels = ("accurate", "matched", "stable") if i in ("pbd", "xpbd") and _rows(data.rows, "match_result", integrator=i) else ("accurate", "stable")
            for label in labels:
                f = data.frontier(d, i, label)
                if f is None:
                    body.append([i, label, "–", "–", "–", "–", "–"])
                    continue
                lo, hi = f.measured_range
                body.append([i, label, f"{lo}–{hi}", f.describe(), _g(f.fit.p) if f.fit else "–",
                             _g(f.fit.residual) if f.fit else "–", f.fit.points if f.fit else len({lo, hi})])
        out += _table(["integrator", "at dt", "measured particles", "frontier [particles]", "cost exponent p", "fit residual [decades rms]", "points"], body)
        out += ["", "The frontier in particles: the largest measured count that is real-time; the power-law fit's N* is shown "
                "with whether it lies within the measured range or is extrapolated beyond it. “matched”: pbd/xpbd at dt = 1/60 s "
                "with the iterations x substeps that --match-accuracy found for the tolerance (accuracy sizes only).", ""]
    floors = _rows(data.rows, "floor")
    if floors:
        out += ["### Float32 noise floor of the transients", ""]
        out += _table(["scenario", "size", "device", "transient", "floor e (rk4 at dt)", "tolerance"],
                      [[r["scenario"], f"{r['rows']}x{r['cols']}", r["device"], _g(r["transient_s"], " s"),
                        f"{_pct(r['error_rel'])} (dt {_g(r['dt_s'], ' s')})",
                        _pct(next((a["tolerance_rel"] for a in _rows(data.rows, "max_accurate_dt") if a["tolerance_rel"]), None))] for r in floors])
        out += [""]
    matches = _rows(data.rows, "match_result")
    if matches:
        out += ["### PBD / XPBD iterations needed for the tolerance (dt = 1/60 s)", ""]
        out += _table(["integrator", "size", "device", "iterations", "substeps", "error", "ms/step", "RT 30 FPS", "note"],
                      [[r["integrator"], f"{r['rows']}x{r['cols']}", r["device"], _g(r["iterations"]), _g(r["substeps"]),
                        _pct(r["error_rel"]), _g(r["ms_per_step_median"]), _yn(r["realtime_30fps"]), r["note"] or ""] for r in matches])
        out += [""]
    return out


# -- plots -----------------------------------------------------------------------------------
#: One marker per integrator (with its colour), the same in every plot.
MARKERS = ("o", "s", "^", "v", "D", "P", "X", "*", "h", "<", ">", "p")
#: The searches' upper bound: one 60 FPS frame.
SEARCH_CAP = 1.0 / 60.0


def plots(out_dir: str, data: Data, tolerance) -> list[str] | None:
    """The study's PNGs: legends outside the data, one marker and colour per integrator, the
    searches' caps drawn as bounds (hollow markers on a "≥ 1/60 s" line), "not reached" as such."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        from matplotlib.lines import Line2D
        from matplotlib.patches import Patch
        from matplotlib.ticker import NullFormatter, ScalarFormatter
    except ImportError:
        return None
    written = []
    styles = ["-", "--", ":", "-."]
    palette = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    look = {i: (palette[k % len(palette)], MARKERS[k % len(MARKERS)]) for k, i in enumerate(data.integrators)}

    def save(fig, name):
        path = os.path.join(out_dir, name)
        f = AtomicFile(path, "plot", mode="wb")
        try:
            fig.savefig(f.fh, format="png", dpi=90, bbox_inches="tight")  # nothing clipped: legends sit outside
        except BaseException:
            f.abort()
            plt.close(fig)
            raise
        plt.close(fig)
        f.commit()
        written.append(name)

    def legend_outside(ax, handles=None, **kw):
        ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0, fontsize=7, **kw)

    def plain_log_ticks(axis, values):
        """Ticks at the measured values, written plainly (not 7 x 10^1)."""
        values = sorted(set(values))
        if values:
            axis.set_major_formatter(ScalarFormatter())
            axis.set_minor_formatter(NullFormatter())
            axis.set_ticks(values)

    def integrator_handles(names, line=True):
        return [Line2D([], [], color=look[i][0], marker=look[i][1], ls="-" if line else "none", label=i) for i in names]

    # 1. wall s per simulated s at max accurate dt
    fig, ax = plt.subplots(figsize=(7.5, 4.5))
    counts = []
    for di, d in enumerate(data.devices):
        for i in data.integrators:
            pts = sorted((n * n, t["wall_s_per_sim_s"]) for n in data.accuracy_sizes for t in [data.timing(d, i, n, "accurate")] if t)
            if pts:
                counts += [p for p, _ in pts]
                ax.loglog(*zip(*pts), styles[di % 4], color=look[i][0], marker=look[i][1], label=f"{i} ({d})")
    ax.axhline(1.0, color="k", lw=1, label="real time (≤ 1 at 30 and 60 FPS: dt ≤ 1/60 s)")
    plain_log_ticks(ax.xaxis, counts)
    ax.set_xlabel("particles")
    ax.set_ylabel("wall s per simulated s")
    ax.set_title(f"cost at the max accurate dt (e ≤ {_pct(tolerance)})")
    legend_outside(ax)
    save(fig, "wall_per_sim_second.png")

    # 2. max stable and max accurate dt (a stable dt at the search's cap is a bound: hollow, "≥ 1/60 s")
    fig, ax = plt.subplots(figsize=(7.5, 4.5))
    d = data.devices[0] if data.devices else None
    counts, capped_any, drawn = [], False, []
    for i in data.integrators:
        color, marker = look[i]
        st = sorted({(n * n, r["dt_s"], bool(r.get("search_bounded"))) for n in data.sizes + data.accuracy_sizes
                     for r in [data.stable(d, i, n)] if r and r["dt_s"]})
        if st:
            drawn.append(i)
            counts += [p for p, _, _ in st]
            ax.loglog([p for p, _, _ in st], [v for _, v, _ in st], "-", color=color)
            for p, v, capped in st:
                capped_any |= capped
                ax.plot([p], [v], marker=marker, color=color, mfc="none" if capped else color, ls="none")
        ac = sorted((n * n, data.accurate_dt(d, i, n)) for n in data.accuracy_sizes if data.accurate_dt(d, i, n))
        if ac:
            ax.loglog(*zip(*ac), "--", marker=marker, color=color)
    handles = integrator_handles(drawn, line=False)
    handles += [Line2D([], [], color="k", ls="-", label="max stable dt"), Line2D([], [], color="k", ls="--", label="max accurate dt")]
    if capped_any:
        ax.axhline(SEARCH_CAP, color="gray", ls=":", lw=1)
        handles.append(Line2D([], [], color="gray", ls=":", marker="o", mfc="none",
                              label="≥ 1/60 s: the search's cap\n(hollow: stable at least there)"))
    plain_log_ticks(ax.xaxis, counts)
    ax.set_xlabel("particles")
    ax.set_ylabel("dt [s]")
    ax.set_title(f"max stable dt and max accurate dt ({d or ''})")
    legend_outside(ax, handles)
    save(fig, "max_dt.png")

    # 3. frontier bars (real-time at every measured size: the frontier is at least the bar)
    fig, ax = plt.subplots(figsize=(8, 4.5))
    labels, acc, stab, bound = [], [], [], []
    for d in data.devices:
        for i in data.integrators:
            fa, fs = data.frontier(d, i, "accurate"), data.frontier(d, i, "stable")
            labels.append(i if len(data.devices) == 1 else f"{i} ({d})")
            acc.append((fa.measured or 0) if fa else 0)
            stab.append((fs.measured or 0) if fs else 0)
            bound.append((fa is not None and fa.all_realtime, fs is not None and fs.all_realtime))
    x = list(range(len(labels)))
    b1 = ax.bar([v - 0.2 for v in x], acc, 0.4, color=palette[0])
    b2 = ax.bar([v + 0.2 for v in x], stab, 0.4, color=palette[1])
    for bars, k in ((b1, 0), (b2, 1)):
        for bar, h in zip(bars, bound):
            if h[k]:
                bar.set_hatch("//")
                ax.text(bar.get_x() + bar.get_width() / 2, bar.get_height(), r"$\geq$", ha="center", va="bottom", fontsize=12,
                        rotation=0)
    ax.set_xticks(x)
    ax.set_xticklabels(labels, fontsize=8, rotation=30, ha="right")
    ax.set_ylabel("largest real-time particle count (measured)")
    ax.set_title("real-time frontier at 30 FPS")
    ax.margins(y=0.1)
    legend_outside(ax, [Patch(color=palette[0], label="at max accurate dt"), Patch(color=palette[1], label="at max stable dt"),
                        Patch(facecolor="white", edgecolor="k", hatch="//",
                              label="≥: real-time at every measured\nsize (the frontier is higher)")])
    save(fig, "frontier.png")

    # 4. error vs dt (one legend for both panels, right of them)
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.5))
    n0 = data.accuracy_sizes[0] if data.accuracy_sizes else None
    d0 = data.devices[0] if data.devices else None
    drawn = []
    for ax, sc in zip(axes, ("sheet", "flag")):
        for i in data.integrators:
            pts = sorted((r["dt_s"], r["error_rel"]) for r in _rows(data.rows, "error", scenario=sc, integrator=i, rows=n0, device=d0)
                         if r["options"] is None and r["error_rel"] is not None and math.isfinite(r["error_rel"]) and r["error_rel"] > 0)
            if pts:
                ax.loglog(*zip(*pts), color=look[i][0], marker=look[i][1], ms=5)
                drawn.append(i)
        ax.axhline(tolerance, color="k", lw=1)
        fl = _one(data.rows, "floor", scenario=sc, rows=n0, device=d0)
        if fl and fl["error_rel"]:
            ax.axhline(fl["error_rel"], color="gray", ls=":")
        ax.set_xlabel("dt [s]")
        ax.set_ylabel("e (fraction of the cloth size)")
        ax.set_title(f"{sc} transient, {n0}x{n0}")
    handles = integrator_handles(list(dict.fromkeys(drawn)))
    handles += [Line2D([], [], color="k", lw=1, label=f"tolerance ({_pct(tolerance)})"),
                Line2D([], [], color="gray", ls=":", label="float32 floor")]
    legend_outside(axes[-1], handles)
    save(fig, "error_vs_dt.png")

    # 5. time to equilibrium ("×": not reached, instead of a bar of 0)
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.5))
    sizes = sorted(set(data.sizes) | set(data.accuracy_sizes))
    width = 0.8 / max(1, len(sizes))
    size_colors = plt.get_cmap("viridis")([k / max(1, len(sizes) - 1) for k in range(len(sizes))])
    for ax, col, what in zip(axes, ("time_to_equilibrium_sim_s", "time_to_equilibrium_wall_s"), ("simulated", "wall")):
        missed = False
        for si, n in enumerate(sizes):
            xs, vals, none = [], [], []
            for k, i in enumerate(data.integrators):
                t = data.timing(d0, i, n, "stable")
                eq = data.static(d0, i, n, t["dt_s"] if t else None)
                pos = k + si * width
                if eq and eq[col] is not None and eq["equilibrium_reached"]:
                    xs.append(pos)
                    vals.append(eq[col])
                elif t is not None:
                    none.append(pos)
            ax.bar(xs, vals, width, color=size_colors[si], label=f"{n}x{n}")
            if none:
                missed = True
                ax.plot(none, [0.0] * len(none), "x", color=size_colors[si], ms=6, mew=1.5, clip_on=False)
        ax.set_xticks([k + 0.4 - width / 2 for k in range(len(data.integrators))])
        ax.set_xticklabels(data.integrators, fontsize=8, rotation=30, ha="right")
        ax.set_ylabel(f"{what} time to equilibrium [s]")
        ax.set_title(f"sheet at the max stable dt ({d0})")
    handles, _ = axes[-1].get_legend_handles_labels()
    if missed:
        handles.append(Line2D([], [], color="k", marker="x", ls="none", label="not reached"))
    legend_outside(axes[-1], handles, title="sheet size")
    save(fig, "time_to_equilibrium.png")
    return written


# -- the report ------------------------------------------------------------------------------
def sharing_lines(rows: list) -> list:
    """Where the measurements ran and how many ran at once (the host, worker and
    concurrent_runs columns): one line per host and device."""
    out = []
    for host in sorted({str(r.get("host") or "?") for r in rows}):
        for d in sorted({r["device"] for r in rows if str(r.get("host") or "?") == host}):
            mine = [r for r in rows if str(r.get("host") or "?") == host and r["device"] == d]
            workers = sorted({str(r.get("worker") or "?") for r in mine})
            timed = [int(r.get("concurrent_runs") or 1) for r in mine if r["measurement"] == "timing"]
            other = [int(r.get("concurrent_runs") or 1) for r in mine if r["measurement"] != "timing"]
            how = "serially" if workers == ["main"] else f"by {len(workers)} worker(s) ({', '.join(workers[:4])}{', ...' if len(workers) > 4 else ''})"
            line = f"- host {host}, {d}: measured {how}; at most {max(timed, default=0)} timed run(s) at once"
            line += f", at most {max(other, default=0)} search run(s) at once"
            if max(timed, default=1) > 1:
                line += " (timings shared the machine: their ms/step are not those of a machine to itself)"
            out.append(line)
    return out


def write_report(out_dir: str, rows: list[dict], plan=None, command: str = "", stream=None) -> list[str]:
    """Write report.md and the plots into ``out_dir``; returns the file names written."""
    data = Data(rows)
    tolerance = plan.tolerance if plan is not None else next((r["tolerance_rel"] for r in rows if r["tolerance_rel"]), 0.01)
    m = machine()
    written = plots(out_dir, data, tolerance) if data.rows else []  # the plots are of the sheet/flag grid
    lines = ["# warpcloth study", ""]
    lines += ["## Machine and command", ""]
    lines += [f"- CPU: {m['cpu']}, {m['cores']} logical cores visible; OS {m['os']}, Python {m['python']}",
              f"- GPU: {', '.join(m['gpus']) if m['gpus'] else 'none found'}" + (f" (CUDA driver {m['driver']})" if m["driver"] else ""),
              f"- Warp {m['warp']}; report written {m['date']}",
              f"- devices measured: {', '.join(data.devices)}",
              *sharing_lines(rows),
              f"- command: `{command or ' '.join(sys.argv)}`", ""]
    if plan is not None:
        lines += ["## Method", ""]
        lines += [
            (f"- Profile `{plan.profile}`: integrators {', '.join(plan.integrators)}; n x n sheets and flags, timing and stability "
             f"at n = {', '.join(map(str, plan.all_sizes))}; accuracy (float64 references) at n = {', '.join(map(str, plan.accuracy_sizes))}."
             if plan.grid else f"- Profile `{plan.profile}`: integrators {', '.join(plan.integrators)}; no sheet/flag grid "
             "(--scenarios without sheet,flag): the grid's settings below apply to the scenarios' trials."),
            f"- Accuracy: e(dt) = max over frames (1/60 s apart) and particles of |x − x_ref| / cloth size against the float64 "
            f"reference (SciPy DOP853, rtol 1e-10), on the sheet released from horizontal ({plan.sheet_transient:g} s) and the flag "
            f"from rest in its wind ({plan.flag_transient:g} s). Tolerance {_pct(plan.tolerance)}. Trial dts are (1/60 s)/k.",
            f"- Max accurate dt: bracket by doubling k from the max stable dt, then bisection on k to a relative width "
            f"≤ {plan.accurate_precision:g}; the search assumes e grows monotonically with dt. The float32 floor is e of rk4 at a "
            f"quarter of its default dt.",
            f"- Max stable dt: `warpcloth.lab.maxdt.find_max_dt`, {plan.maxdt_duration:g} s simulated per trial"
            + "".join(f", {d:g} s from {m}x{m}" for m, d in sorted(plan.maxdt_durations)) + ", precision "
            f"{plan.maxdt_precision:g}, searched up to one 60 FPS frame (1/60 s), wall cap {plan.maxdt_wall_cap} s per trial.",
            f"- Static accuracy: the sheet run from rest to equilibrium (at most {plan.equilibrium_duration:g} s simulated, "
            f"{plan.equilibrium_wall_cap} s wall) against the float64 Newton equilibrium (up to {plan.static_max_size}x{plan.static_max_size}); "
            f"the max static-accurate dt searched as above from the max stable dt.",
            f"- Timing: the sheet from rest, {plan.windows} timed windows of at least {plan.window_seconds:g} s after a warm-up step "
            f"(compile) and an untimed replay (graph capture); median and [min–max] ms/step. Real time at F FPS: the steps of one "
            f"1/F s frame take at most 1/F s of wall time. dt is rounded down to (1/60 s)/k.",
            "- Frontier: power law wall s per simulated s = a N^p fitted in log-log over the measured sizes at that dt.",
            "",
        ]
        if plan.scenario_files:
            lines.insert(-1, f"- Scenarios at their own mesh: {', '.join(f'`{s}`' for s in plan.scenario_files)}: max stable dt "
                             f"(trials as above at the size of the same particle count), time to equilibrium and ms/step at it; "
                             f"no accuracy (no float64 reference for them).")
    if plan is not None and plan.grid:
        missing = [f"{i} {n}x{n} on {d}" for d in plan.devices for n in plan.all_sizes for i in plan.integrators
                   if not any(r["measurement"] == "timing" and r["device"] == d and r["integrator"] == i and r["rows"] == n for r in rows)]
        if missing:
            lines += ["## Not measured", "",
                      f"The plan has {len(missing)} device x integrator x size groups without a timing row in results.csv "
                      f"(the study was interrupted, or no stable dt was found; `--resume` continues an interrupted one): "
                      f"{', '.join(missing)}.", ""]
    if data.rows:
        lines += ["## Verdict", ""] + [f"- {s}" for s in verdict(data, tolerance)] + [""]
        lines += ["## Tables", ""] + tables(data)
    if data.mesh_rows:
        lines += ["## Scenarios", ""] + scenario_tables(data.mesh_rows)
    lines += ["## Plots", ""]
    if written is None:
        lines += ["The plots need matplotlib: `pip install 'warpcloth[plot]'`; results.csv and this report are complete without them.", ""]
    else:
        for name in written:
            lines += [f"![{PLOTS[name]}]({name})", "", f"*{PLOTS[name]}.*", ""]
    lines += ["## Columns of results.csv", ""]
    lines += _table(["column", "meaning"], [[c, COLUMN_DOCS.get(c, "")] for c in COLUMNS]) + [""]
    write_atomic(os.path.join(out_dir, "report.md"), "\n".join(lines), "study report")
    if written is None and stream is not None:
        print("warpcloth: study: the plots need matplotlib: pip install 'warpcloth[plot]' (results.csv and report.md written)", file=stream)
    return ["results.csv", "report.md"] + (written or [])


__all__ = ["Data", "PLOTS", "verdict", "write_report"]
