"""A sweep analysis's text: summary.json's record, summary.md and report.md from its numbers.

Pure: the analysis's records in, strings and JSON-ready dicts out (gcs.sweep.analysis writes
them). Every number that is not finite reads "—" in Markdown and null in JSON.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from gcs.sweep.analysis import AnalysisMeta, Rate, Summary, WorstRun


def strict(value: Any) -> Any:
    """``value`` with every non-finite float replaced by None (strict JSON), numpy scalars as
    Python numbers."""
    if isinstance(value, dict):
        return {k: strict(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [strict(v) for v in value]
    if isinstance(value, float | np.floating):
        return float(value) if math.isfinite(value) else None
    if isinstance(value, np.integer):
        return int(value)
    return value


def _rate_record(r: Rate) -> dict[str, Any]:
    return {"k": r.k, "n": r.n, "missing": r.missing, "rate": r.rate,
            "ci95_wilson": list(r.interval)}


def summary_record(summary: Summary, meta: AnalysisMeta) -> dict[str, Any]:
    """summary.json's content (docs/sweep.md, "Reading the results")."""
    return strict({
        "study": meta.study_name,
        "study_file": meta.study_file,
        "runs_done": summary.runs_done,
        "runs_planned": summary.runs_planned,
        "status": summary.status_counts,
        "window_start_s": meta.window_start_s,
        "converged_below_m": meta.converged_below_m,
        "success": _rate_record(summary.success),
        "rates": {name: _rate_record(r) for name, r in summary.rates.items()},
        "metrics": {name: {"n": s.n, "nan": s.nan, "mean": s.mean,
                           "mean_ci95_t": [s.mean_low, s.mean_high], "median": s.median,
                           "p5": s.p5, "p95": s.p95, "min": s.min, "max": s.max}
                    for name, s in summary.floats.items()},
    })


def fmt(x: Any) -> str:
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "—"
    if isinstance(x, float):
        return f"{x:.4g}"
    return str(x)


def _percent(x: float) -> str:
    return "—" if not math.isfinite(x) else f"{100 * x:.1f} %"


def _range(low: float, high: float, show: Callable[[float], str]) -> str:
    if not (math.isfinite(low) and math.isfinite(high)):
        return "—"
    return f"{show(low)} – {show(high)}"


def summary_lines(summary: Summary) -> list[str]:
    """The run counts, the rates table and the float metrics table."""
    status = ", ".join(f"{name} {count}" for name, count in summary.status_counts.items())
    lines = [f"Runs done: {summary.runs_done} of {summary.runs_planned} planned ({status}).",
             "Rates count the runs that ran (ok or diverged); a diverged run is a failure.", "",
             "| rate | k / n | rate | 95 % CI (Wilson) | null |", "|---|---|---|---|---|"]
    named = [("success (converged, status ok)", summary.success), *summary.rates.items()]
    for name, r in named:
        lines.append(f"| {name} | {r.k} / {r.n} | {_percent(r.rate)} | "
                     f"{_range(*r.interval, _percent)} | {r.missing} |")
    lines += ["", "| metric | n | NaN | mean | 95 % CI of mean (t) | median | p5 | p95 | min "
              "| max |", "|---|---|---|---|---|---|---|---|---|---|"]
    for name, s in summary.floats.items():
        lines.append(f"| {name} | {s.n} | {s.nan} | {fmt(s.mean)} | "
                     f"{_range(s.mean_low, s.mean_high, fmt)} | {fmt(s.median)} | {fmt(s.p5)} | "
                     f"{fmt(s.p95)} | {fmt(s.min)} | {fmt(s.max)} |")
    return lines


def summary_page(summary: Summary, meta: AnalysisMeta) -> str:
    return "\n".join([f"# Sweep {meta.study_name}: summary", "", *summary_lines(summary)]) + "\n"


def worst_lines(worst: list[WorstRun], failures: int, runs_done: int) -> list[str]:
    """Each worst run: status, message, metrics, parameters and the replay command."""
    if runs_done == 0:
        return ["No runs in the table."]
    lines = [f"{failures} of {runs_done} runs are not ok or did not converge; listed: "
             f"{len(worst)} (failures first, then the highest max_error_m).", ""]
    for rank, w in enumerate(worst, start=1):
        lines += [f"### {rank}. run {w.run} (seed {w.seed}): {w.status}", ""]
        if w.message:
            lines += [f"Message: {w.message}", ""]
        lines += [" · ".join(f"{name} {fmt(value)}" for name, value in w.metrics), "",
                  "| parameter | value |", "|---|---|"]
        lines += [f"| {name} | {fmt(value)} |" for name, value in w.parameters]
        lines += ["", "Replay:", "", "```", w.replay, "```", ""]
    return lines


def report_page(summary: Summary, meta: AnalysisMeta, figures: list[Path],
                worst: list[WorstRun]) -> str:
    """report.md: what was run, the summary, the figures linked, the worst runs."""
    lines = [f"# Sweep {meta.study_name}", "",
             f"Study file `{meta.study_file}`. Success: converged (formation error below "
             f"{fmt(meta.converged_below_m)} m from some time on) and status ok; max and mean "
             f"error from t = {fmt(meta.window_start_s)} s on.", "",
             "## Summary", "", *summary_lines(summary), "", "## Figures", ""]
    lines += [f"![{p.stem}]({p.name})" for p in figures] + ["", "## Worst runs", ""]
    lines += worst_lines(worst, summary.runs_done - summary.success.k, summary.runs_done)
    return "\n".join(lines).rstrip() + "\n"
