"""``warpcloth advise``: the cheapest measured configuration that meets a tolerance within a
budget at a size, answered from a study's results.csv (docs/study.md, "Advice"), never beyond it.

The rule is the study's (:func:`warpcloth.lab.frontier.cheapest` over the configurations timed
within the budget): a configuration's error is the worse of the dynamic transients judged at that
size, its cost the measured ms per 1/60 s frame. A transient is judged on a metric where its
float64 reference was accepted for that metric (its halving estimate of it <= 1e-5:
:func:`~warpcloth.lab.accuracy.reference_refusal`) and the metric's conditioning floor is at most
:data:`~warpcloth.lab.accuracy.FLOOR_FRACTION` of the tolerance; where no transient is, the verdict
is refused. With ``metric="auto"`` the pointwise error decides where its floor allows it, else the
first of the 4 x 4 patch means and the centre of mass whose floor does (:data:`AUTO_ORDER`).

Sizes: a measured size is answered there; a size between two measured ones is answered only when
both give the same configuration (else both answers are said and none is chosen); a size outside
the measured range is not answered (nothing is extrapolated).

The command it prints, ``warpcloth run swing ...``, runs the configuration on the swing the study
timed it on (:mod:`warpcloth.scenarios.swing`), with the exact dt and every option the study used.
"""

from __future__ import annotations

import csv
import math
import os
from dataclasses import dataclass, field
from fractions import Fraction

from warpcloth.errors import WarpclothError
from warpcloth.integrators import all_options
from warpcloth.lab.accuracy import FLOOR_FRACTION, FRAME_DT, reference_refusal, refused
from warpcloth.lab.configs import study_options
from warpcloth.lab.frontier import Point, cheapest
from warpcloth.lab.results import read_rows
from warpcloth.lab.transients import DYNAMIC
from warpcloth.scenarios.swing import SCENARIO as SWING
from warpcloth.scenarios.swing import STUDY_SHEET

#: The metrics advise judges on: name -> (column of a trial row, its floor's column, name for people).
#: damping is taken as its magnitude (|1 - kinetic energy / the reference's|).
METRICS = {
    "point": ("error_rel", "floor_point_rel", "pointwise e"),
    "patch": ("patch_error_rel", "floor_patch_rel", "4 x 4 patch error"),
    "centroid": ("centroid_error_rel", "floor_centroid_rel", "centroid error"),
    "damping": ("damping_rel", "floor_damping_rel", "numerical damping"),
}
#: ``--metric auto``: the first of these whose floor allows a verdict decides (finest first).
AUTO_ORDER = ("point", "patch", "centroid")
#: The columns advise reads (a results.csv without one of them is refused).
NEEDED = (
    "measurement",
    "scenario",
    "transient",
    "integrator",
    "options",
    "device",
    "rows",
    "steps_per_frame",
    "stable",
    "reference",
    "reference_estimate_rel",
    "ms_per_frame",
    *(c for m in METRICS.values() for c in m[:2]),
)
#: The ``warpcloth run`` scenario that reproduces a study scenario's timed runs: the study times
#: every configuration on the swing's sheet from the swing's start, which ``warpcloth run swing``
#: is, to the bit (:mod:`warpcloth.scenarios.swing`).
RUN_SCENARIO = {STUDY_SHEET.name: SWING.name}
#: The committed CPU study shipped in the package (a copy of docs/study/cpu/results.csv).
SHIPPED = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "data", "study_cpu")


def _pct(x) -> str:
    return "∞" if x is None or math.isinf(x) else f"{100 * x:.3g} %"


def _k_text(k: Fraction) -> str:
    return f"dt 1/{60 * k} s" if (60 * k).denominator == 1 else f"dt {FRAME_DT / float(k):.4g} s"


@dataclass(frozen=True)
class Configuration:
    """A measured configuration: integrator, its options as results.csv writes them, k steps per
    1/60 s frame, the study scenario it was timed on."""

    integrator: str
    options: str
    k: Fraction
    scenario: str = "study_sheet"

    @property
    def dt(self) -> float:
        return FRAME_DT / float(self.k)

    def label(self) -> str:
        return f"{self.integrator}, {_k_text(self.k)}" + (f", {self.options}" if self.options else "")

    def option_values(self) -> dict:
        """Every option the study ran it with: its integrator's fixed study options, then the row's."""
        given = dict(item.split("=", 1) for item in self.options.split())
        return study_options(self.integrator, given)

    def run_flags(self, n: int) -> list[str]:
        """The ``warpcloth run`` arguments that run this configuration on the n x n swing: the
        exact dt and every option the study ran it with (its integrator's fixed study options and
        the row's, values as the study wrote them: pbd's ``pbd_bend_stiffness`` mapped from the
        material)."""
        flags = all_options()
        out = [RUN_SCENARIO.get(self.scenario, self.scenario), "--size", str(n), "--integrator", self.integrator]
        out += ["--dt", repr(self.dt)]
        for name, value in self.option_values().items():
            out += [flags[name][0].flag, str(value)]
        return out


@dataclass
class SizeAnswer:
    """The answer at one measured size.

    status: ``answer`` (``best`` meets the tolerance within the budget), ``none`` (nothing
    measured does), ``refused`` (every transient's floor or reference refuses the metric).
    metric: the metric that decided; judged: the transients it was judged on; why: the
    refusal, or the transients left out and why; skipped: the finer metrics ``auto`` passed over
    (refused there) and why; over_budget: the cheapest configuration meeting
    the tolerance at any cost (status ``none``); closest: the least error within the budget."""

    n: int
    status: str
    metric: str
    judged: tuple = ()
    why: str = ""
    best: Point | None = None
    over_budget: Point | None = None
    closest: Point | None = None
    skipped: str = ""

    def same_as(self, other: SizeAnswer) -> bool:
        if self.status != other.status:
            return False
        return self.status != "answer" or self.best.label == other.best.label


@dataclass
class Advice:
    """The advice for size ``n``: ``kind`` is ``measured`` (n was measured), ``same`` (between
    two measured sizes that agree), ``differ`` (between two that do not: no answer), ``outside``
    (beyond the measured range: no answer); ``answers``: the bracketing sizes' answers."""

    n: int
    device: str
    tolerance: float
    budget_ms: float
    metric: str
    kind: str
    sizes: tuple
    answers: list = field(default_factory=list)
    source: str = ""

    @property
    def answer(self) -> SizeAnswer | None:
        """The answer that holds at n (None where there is none: outside or differing)."""
        return self.answers[0] if self.kind in ("measured", "same") else None


class Study:
    """A study's rows, indexed for advice: floors, trials and timings per device and size."""

    def __init__(self, rows: list[dict], source: str = ""):
        self.source = source
        self.floors, self.trials, self.timings = {}, {}, {}
        for r in rows:
            if r["rows"] is None:
                continue
            d, n = r["device"], int(r["rows"])
            if r["measurement"] == "floor" and r["transient"] in DYNAMIC:
                self.floors[(d, n, r["transient"])] = r
                continue
            if r["steps_per_frame"] is None:
                continue
            cfg = (r["integrator"], r["options"] or "", Fraction(float(r["steps_per_frame"])).limit_denominator(1000))
            if r["measurement"] == "trial" and r["transient"] in DYNAMIC:
                self.trials[(d, n, r["transient"], cfg)] = r
            elif r["measurement"] == "timing" and r["ms_per_frame"] is not None:
                self.timings[(d, n, cfg)] = r  # a re-timed configuration: its last row
        self.devices = tuple(dict.fromkeys(d for (d, _, _, _) in self.trials))

    def sizes(self, device: str) -> tuple:
        return tuple(sorted({n for (d, n, _, _) in self.trials if d == device}))

    def refusal(self, device: str, n: int, transient: str, metric: str, tolerance: float) -> str:
        """Why ``metric`` at ``tolerance`` cannot be judged on ``transient`` at n ("" when it can)."""
        f = self.floors.get((device, n, transient))
        if f is None:
            return f"no {transient} reference"
        why = reference_refusal(f, transient, metric, METRICS[metric][2])
        if why:
            return why
        floor = f[METRICS[metric][1]]
        if refused(floor, tolerance):
            return (
                f"the {transient} floor of the {METRICS[metric][2]} is {_pct(floor)} > {FLOOR_FRACTION:g} x "
                f"{_pct(tolerance)}"
            )
        return ""

    def points(self, device: str, n: int, metric: str, judged) -> list[Point]:
        """Every configuration at n measured on the ``judged`` transients and timed, as a Point
        (cost: ms per 1/60 s frame; error: the worse transient's metric, inf where one went unstable)."""
        col = METRICS[metric][0]
        out = []
        for (d, nn, cfg), t in self.timings.items():
            if (d, nn) != (device, n):
                continue
            trials = [self.trials.get((d, n, name, cfg)) for name in judged]
            if any(r is None for r in trials):
                continue
            if not all(r["stable"] for r in trials):
                err = math.inf
            elif any(r[col] is None for r in trials):
                continue
            else:
                err = max(abs(r[col]) for r in trials)
            conf = Configuration(cfg[0], cfg[1], cfg[2], t["scenario"] or "study_sheet")
            out.append(Point(cost=t["ms_per_frame"], error=err, label=conf))
        return out

    def answer_at(self, device: str, n: int, tolerance: float, budget_ms: float, metric: str = "auto") -> SizeAnswer:
        """The answer at the measured size n (:class:`SizeAnswer`)."""
        reasons = []
        for m in AUTO_ORDER if metric == "auto" else (metric,):
            why = {t: self.refusal(device, n, t, m, tolerance) for t in DYNAMIC}
            judged = tuple(t for t in DYNAMIC if not why[t])
            if not judged:
                reasons.append(f"{METRICS[m][2]}: " + "; ".join(why.values()))
                continue
            left_out = "; ".join(w for w in why.values() if w)
            pts = self.points(device, n, m, judged)
            within = [p for p in pts if p.cost <= budget_ms]
            best = cheapest(within, tolerance)
            skipped = "; ".join(reasons)
            if best is not None:
                return SizeAnswer(n, "answer", m, judged, left_out, best=best, skipped=skipped)
            finite = [p for p in within if math.isfinite(p.error)]
            closest = min(finite, key=lambda p: (p.error, p.cost)) if finite else None
            over = cheapest(pts, tolerance)
            return SizeAnswer(n, "none", m, judged, left_out, over_budget=over, closest=closest, skipped=skipped)
        return SizeAnswer(n, "refused", metric, why="; ".join(reasons))


def load_study(folder: str) -> Study:
    """The study in ``folder`` (its results.csv), checked: a missing or unreadable file, or one
    without the columns advise reads, is a WarpclothError naming it."""
    path = os.path.join(folder, "results.csv")
    if not os.path.isdir(folder):
        raise WarpclothError(f"--results {folder}: no such folder (a study's output folder, with its results.csv)")
    try:
        with open(path, newline="", encoding="utf-8") as fh:
            header = next(csv.reader(fh), [])
        rows = read_rows(path)
    except FileNotFoundError:
        raise WarpclothError(f"--results {folder}: no results.csv there (write one with 'warpcloth study')") from None
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise WarpclothError(f"--results {folder}: cannot read results.csv: {exc}") from None
    missing = [c for c in NEEDED if c not in header]
    if missing:
        raise WarpclothError(
            f"--results {folder}: results.csv is not a study's (missing column(s) {', '.join(missing)})"
        )
    try:
        shipped = os.path.abspath(folder) == SHIPPED
        return Study(rows, source="the CPU study shipped with warpcloth (docs/study/cpu)" if shipped else path)
    except (TypeError, ValueError) as exc:
        raise WarpclothError(f"--results {folder}: results.csv has a malformed row ({exc})") from None


def advise(
    study: Study, n: int, tolerance: float, budget_ms: float, metric: str = "auto", device: str | None = None
) -> Advice:
    """The :class:`Advice` for an n x n cloth from ``study``. ``device``: one the study measured
    (None: its only one; with several, an error asks for one)."""
    if metric != "auto" and metric not in METRICS:
        raise WarpclothError(f"unknown metric {metric!r}; choose from auto, {', '.join(METRICS)}")
    if not study.devices:
        raise WarpclothError(f"{study.source}: no accuracy trials on the study's transients: nothing to advise from")
    if device is None:
        if len(study.devices) > 1:
            raise WarpclothError(f"the study measured {', '.join(study.devices)}: choose one with --device")
        device = study.devices[0]
    if device not in study.devices:
        raise WarpclothError(f"unknown device {device!r}: the study measured {', '.join(study.devices)}")
    sizes = study.sizes(device)
    advice = Advice(n, device, tolerance, budget_ms, metric, "outside", sizes, source=study.source)
    if n in sizes:
        advice.kind = "measured"
        advice.answers = [study.answer_at(device, n, tolerance, budget_ms, metric)]
    elif sizes[0] < n < sizes[-1]:
        lo = max(s for s in sizes if s < n)
        hi = min(s for s in sizes if s > n)
        advice.answers = [study.answer_at(device, s, tolerance, budget_ms, metric) for s in (lo, hi)]
        advice.kind = "same" if advice.answers[0].same_as(advice.answers[1]) else "differ"
    return advice


def _describe(a: SizeAnswer, advice: Advice, run_n: int | None) -> list[str]:
    """Lines for one size's answer (``run_n``: the size of the reproducing command; None: none)."""
    at = f"at {a.n}x{a.n}"
    if a.status == "refused":
        return [
            f"{at}: refused: {a.why} (no verdict at {_pct(advice.tolerance)}: the float64 conditioning floor, or the "
            "reference not accepted for the metric)"
        ]
    name = METRICS[a.metric][2]
    on = " and ".join(a.judged) + ("" if not a.why else f" (left out: {a.why})")
    if a.skipped:
        on += f"; refused first: {a.skipped}"
    if a.status == "none":
        out = [f"{at}: no measured configuration has {name} ≤ {_pct(advice.tolerance)} within {advice.budget_ms:g} ms"]
        if a.closest is not None:
            out.append(f"  closest within the budget: {a.closest.label.label()}: {name} {_pct(a.closest.error)}")
        if a.over_budget is not None:
            p = a.over_budget
            out.append(f"  cheapest meeting it at any cost: {p.label.label()}: {p.cost:.3g} ms per 1/60 s frame")
        out.append(f"  judged on {on}")
        return out
    p, conf = a.best, a.best.label
    out = [
        f"{at}: {conf.label()}",
        f"  cost {p.cost:.3g} ms per 1/60 s frame (budget {advice.budget_ms:g} ms: {advice.budget_ms - p.cost:.3g} ms "
        "to spare)",
        f"  {name} {_pct(p.error)} ≤ {_pct(advice.tolerance)}: margin {_pct(advice.tolerance - p.error)} of the size",
        f"  decided by: {name}, on {on}",
    ]
    if run_n is not None:
        out.append("  run it: warpcloth run " + " ".join(conf.run_flags(run_n)))
    return out


def format_advice(advice: Advice) -> str:
    """The advice for people: the question, the answer (or why there is none), the reproducing command."""
    metric = (
        "the pointwise e (else the finest metric its floor allows)"
        if advice.metric == "auto"
        else f"the {METRICS[advice.metric][2]}"
    )
    sizes = ", ".join(f"{s}x{s}" for s in advice.sizes)
    lines = [
        f"{advice.n}x{advice.n} on {advice.device}: error ≤ {_pct(advice.tolerance)} of the cloth size by "
        f"{metric}, within {advice.budget_ms:g} ms per 1/60 s frame",
        f"study: {advice.source}; measured sizes {sizes}",
    ]
    if advice.kind == "outside":
        lines.append(
            f"{advice.n}x{advice.n} is outside the measured sizes ({advice.sizes[0]}x{advice.sizes[0]} to "
            f"{advice.sizes[-1]}x{advice.sizes[-1]}): no answer (nothing is extrapolated)"
        )
    elif advice.kind == "measured":
        lines += _describe(advice.answers[0], advice, advice.n)
    else:
        lo, hi = advice.answers
        if advice.kind == "same":
            lines.append(f"{advice.n}x{advice.n} lies between {lo.n}x{lo.n} and {hi.n}x{hi.n}, whose answers agree:")
            lines += _describe(lo, advice, None) + _describe(hi, advice, advice.n if hi.status == "answer" else None)
        else:
            lines.append(
                f"{advice.n}x{advice.n} lies between {lo.n}x{lo.n} and {hi.n}x{hi.n}, whose answers differ: no answer "
                f"at {advice.n}x{advice.n} (not interpolated); measure it with 'warpcloth study --sizes {advice.n}'"
            )
            lines += _describe(lo, advice, lo.n) + _describe(hi, advice, hi.n)
    a = advice.answer
    if a is not None and a.status == "answer":
        lines.append(
            "The study judged it on its swing and flag transients and timed it on the swing (docs/study.md); "
            "'warpcloth run swing' is that swing: the study's cloth, its top row pinned, released from horizontal."
        )
    return "\n".join(lines)


__all__ = [
    "AUTO_ORDER",
    "METRICS",
    "NEEDED",
    "RUN_SCENARIO",
    "SHIPPED",
    "Advice",
    "Configuration",
    "SizeAnswer",
    "Study",
    "advise",
    "format_advice",
    "load_study",
]
