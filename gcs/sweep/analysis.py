"""A finished sweep's results table read: summary with confidence intervals, figures, and a report
that names the worst runs with the command that replays each.

``write_analysis(table, meta, out_dir)`` writes summary.json, summary.md, the figures of
``gcs.sweep.plots`` and report.md (docs/sweep.md, "Reading the results"). Every function above
the writing section is pure: the table in, numbers out.

Populations: a run whose ``status`` is "error" produced no metrics (its drawn team is not a
valid team: nothing flew), so rates count the runs that ran, "ok" and "diverged"; a diverged
run counts as a failure. Success is ``converged`` and status "ok". Float metrics count every row
whose value is finite and report how many were not.
"""

from __future__ import annotations

import json
import logging
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
from scipy import stats

from gcs.sweep import plots, report
from gcs.sweep.measure import BOOLEAN, METRICS
from gcs.sweep.work import STATUS_DIVERGED, STATUS_ERROR, STATUS_OK

logger = logging.getLogger(__name__)


PARAM_PREFIX = "param."
#: the row's figures (gcs.sweep.measure, which writes them): the true-or-false ones, the numbers
BOOL_METRICS = BOOLEAN
FLOAT_METRICS = tuple(m for m in METRICS if m not in BOOLEAN)
REQUIRED = ("run", "seed", "status", "message", *BOOL_METRICS, *FLOAT_METRICS)
STATUSES = (STATUS_OK, STATUS_DIVERGED, STATUS_ERROR)
CONFIDENCE = 0.95
#: success_vs_<param>: at most this many bins, and about this many runs in each
MAX_BINS = 10
RUNS_PER_BIN = 10
#: the heat map: at most this many bins on each axis
MAX_HEATMAP_BINS = 8


@dataclass(frozen=True, slots=True)
class AnalysisMeta:
    """What the table does not say: the study, how to replay a run, what to plot, the captions.

    ``replay_template`` holds ``{run}`` where the run number goes. ``heatmap_pair`` names two
    ``param.`` columns; None picks the two parameters with the most distinct values.
    """

    study_name: str
    study_file: str
    runs_planned: int
    replay_template: str
    window_start_s: float
    converged_below_m: float
    heatmap_pair: tuple[str, str] | None = None
    worst_count: int = 10

    def __post_init__(self) -> None:
        if "{run}" not in self.replay_template:
            raise ValueError(f"replay_template: expected '{{run}}' in it, got "
                             f"{self.replay_template!r}")
        if self.worst_count < 0:
            raise ValueError(f"worst_count: expected >= 0, got {self.worst_count}")
        if self.runs_planned < 0:
            raise ValueError(f"runs_planned: expected >= 0, got {self.runs_planned}")

    def replay_command(self, run: int) -> str:
        return self.replay_template.replace("{run}", str(run))


@dataclass(frozen=True, slots=True)
class Rate:
    """k of n runs, with the 95 % Wilson interval; ``missing``: runs whose value was null."""

    k: int
    n: int
    missing: int = 0

    @property
    def rate(self) -> float:
        return self.k / self.n if self.n else math.nan

    @property
    def interval(self) -> tuple[float, float]:
        return wilson_interval(self.k, self.n)


@dataclass(frozen=True, slots=True)
class FloatStats:
    """One float metric over the runs where it is finite (``n``); ``nan``: where it is not."""

    n: int
    nan: int
    mean: float
    mean_low: float
    mean_high: float
    median: float
    p5: float
    p95: float
    min: float
    max: float


@dataclass(frozen=True, slots=True)
class Summary:
    runs_done: int
    runs_planned: int
    status_counts: dict[str, int]
    success: Rate
    rates: dict[str, Rate]
    floats: dict[str, FloatStats]


@dataclass(frozen=True, slots=True)
class Bins:
    """Runs grouped by one parameter: run r is in bin ``index[r]`` (-1: its value is missing).

    Numeric parameters have each bin's value range ``[lows[b], highs[b])`` (the last bin closed;
    one value per bin where the parameter takes few values: low == high); strings have None.
    """

    column: str
    labels: tuple[str, ...]
    index: np.ndarray
    lows: np.ndarray | None = None
    highs: np.ndarray | None = None
    quantiles: bool = False


@dataclass(frozen=True, slots=True)
class BinnedRate:
    """Success in each bin of ``bins``: ``k`` of ``n`` runs and the Wilson interval."""

    bins: Bins
    k: np.ndarray
    n: np.ndarray
    low: np.ndarray
    high: np.ndarray

    @property
    def rate(self) -> np.ndarray:
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(self.n > 0, self.k / np.maximum(self.n, 1), np.nan)


@dataclass(frozen=True, slots=True)
class Cells:
    """A 2-D binning: success ``k`` of ``n`` and the median max_error_m in each (x, y) cell."""

    x: Bins
    y: Bins
    k: np.ndarray
    n: np.ndarray
    median_max_error_m: np.ndarray


@dataclass(frozen=True, slots=True)
class WorstRun:
    """One run of the report's worst list: what it was, how it ended, how to replay it."""

    run: int
    seed: int | None
    status: str
    message: str
    metrics: tuple[tuple[str, Any], ...]
    parameters: tuple[tuple[str, Any], ...]
    replay: str


# --- reading the table ---------------------------------------------------------------------


def check_schema(table: pa.Table) -> None:
    missing = [c for c in REQUIRED if c not in table.column_names]
    if missing:
        raise ValueError(f"results table: missing columns {', '.join(missing)}")


def param_columns(table: pa.Table) -> list[str]:
    return [c for c in table.column_names if c.startswith(PARAM_PREFIX)]


def is_numeric(table: pa.Table, column: str) -> bool:
    kind = table.schema.field(column).type
    return pa.types.is_floating(kind) or pa.types.is_integer(kind)


def floats(table: pa.Table, column: str) -> np.ndarray:
    """The column as float64, a null as NaN."""
    return table.column(column).cast(pa.float64()).to_numpy()


def flags(table: pa.Table, column: str) -> tuple[np.ndarray, np.ndarray]:
    """(values with null as False, where not null) of a bool column."""
    col = table.column(column).cast(pa.bool_())
    return (col.fill_null(False).to_numpy().astype(bool),
            col.is_valid().to_numpy().astype(bool))


def texts(table: pa.Table, column: str) -> list[str | None]:
    return [None if v is None else str(v) for v in table.column(column).to_pylist()]


def statuses(table: pa.Table) -> np.ndarray:
    return np.array([s or "" for s in texts(table, "status")], dtype=object)


def ran(table: pa.Table) -> np.ndarray:
    """The runs that ran the law (status "ok" or "diverged"): the rates' population."""
    status = statuses(table)
    return (status == "ok") | (status == "diverged")


def successes(table: pa.Table) -> np.ndarray:
    converged, _ = flags(table, "converged")
    return converged & (statuses(table) == "ok")


# --- statistics ----------------------------------------------------------------------------


def wilson_interval(k: int, n: int, confidence: float = CONFIDENCE) -> tuple[float, float]:
    """The Wilson score interval of k successes in n trials; (nan, nan) for n = 0."""
    if n <= 0:
        return math.nan, math.nan
    z = float(stats.norm.ppf(0.5 + confidence / 2))
    p = k / n
    denominator = 1 + z * z / n
    center = (p + z * z / (2 * n)) / denominator
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denominator
    low = 0.0 if k == 0 else max(0.0, center - half)
    return low, 1.0 if k == n else min(1.0, center + half)


def mean_interval(values: np.ndarray, confidence: float = CONFIDENCE) -> tuple[float, float]:
    """Student's t interval of the mean of finite ``values``; (nan, nan) for fewer than 2."""
    n = values.size
    if n < 2:
        return math.nan, math.nan
    mean = float(np.mean(values))
    half = float(stats.t.ppf(0.5 + confidence / 2, n - 1)) * float(np.std(values, ddof=1))
    half /= math.sqrt(n)
    return mean - half, mean + half


def float_stats(values: np.ndarray) -> FloatStats:
    finite = values[np.isfinite(values)]
    nan_count = int(values.size - finite.size)
    if finite.size == 0:
        return FloatStats(0, nan_count, *([math.nan] * 8))
    low, high = mean_interval(finite)
    p5, median, p95 = (float(v) for v in np.percentile(finite, [5, 50, 95]))
    return FloatStats(int(finite.size), nan_count, float(np.mean(finite)), low, high, median,
                      p5, p95, float(finite.min()), float(finite.max()))


def summarize(table: pa.Table, runs_planned: int) -> Summary:
    check_schema(table)
    status = statuses(table)
    counts = {s: int(np.sum(status == s)) for s in STATUSES}
    counts |= {str(s): int(np.sum(status == s)) for s in np.unique(status) if s not in counts}
    population = ran(table)
    rates = {}
    for name in BOOL_METRICS:
        value, valid = flags(table, name)
        counted = population & valid
        rates[name] = Rate(int(np.sum(value & counted)), int(np.sum(counted)),
                           int(np.sum(population & ~valid)))
    success = Rate(int(np.sum(successes(table) & population)), int(np.sum(population)))
    return Summary(table.num_rows, runs_planned, counts, success, rates,
                   {name: float_stats(floats(table, name)) for name in FLOAT_METRICS})


# --- binning -------------------------------------------------------------------------------


def _number(x: float) -> str:
    return f"{x:.3g}"


def bin_parameter(table: pa.Table, column: str, max_bins: int = MAX_BINS) -> Bins:
    """One bin per value where the parameter takes at most ``max_bins`` values (and for
    strings); otherwise quantile bins, one per ~RUNS_PER_BIN runs, at least 2, at most
    ``max_bins``."""
    if not is_numeric(table, column):
        values = texts(table, column)
        labels = tuple(sorted({v for v in values if v is not None}))
        where = {v: b for b, v in enumerate(labels)}
        index = np.array([where.get(v, -1) if v is not None else -1 for v in values], dtype=int)
        return Bins(column, labels, index)
    x = floats(table, column)
    finite = np.isfinite(x)
    distinct = np.unique(x[finite])
    index = np.full(x.size, -1, dtype=int)
    if distinct.size <= max_bins:
        index[finite] = np.searchsorted(distinct, x[finite])
        return Bins(column, tuple(_number(v) for v in distinct), index, distinct, distinct.copy())
    count = min(max_bins, max(2, int(np.sum(finite)) // RUNS_PER_BIN))
    edges = np.unique(np.quantile(x[finite], np.linspace(0.0, 1.0, count + 1)))
    index[finite] = np.searchsorted(edges[1:-1], x[finite], side="right")
    labels = tuple(f"[{_number(lo)}, {_number(hi)}{']' if b == edges.size - 2 else ')'}"
                   for b, (lo, hi) in enumerate(zip(edges[:-1], edges[1:], strict=True)))
    return Bins(column, labels, index, edges[:-1].copy(), edges[1:].copy(), quantiles=True)


def binned_rate(bins: Bins, success: np.ndarray, counted: np.ndarray) -> BinnedRate:
    """Success rate in each bin over the ``counted`` runs whose parameter is known."""
    use = counted & (bins.index >= 0)
    size = len(bins.labels)
    n = np.bincount(bins.index[use], minlength=size)
    k = np.bincount(bins.index[use & success], minlength=size)
    intervals = np.array([wilson_interval(int(a), int(b)) for a, b in zip(k, n, strict=True)])
    intervals = intervals.reshape(size, 2)
    return BinnedRate(bins, k, n, intervals[:, 0], intervals[:, 1])


def cells(x: Bins, y: Bins, success: np.ndarray, counted: np.ndarray,
          max_error_m: np.ndarray) -> Cells:
    """Success and the median max_error_m (finite values only) in each cell of x by y."""
    shape = (len(x.labels), len(y.labels))
    use = counted & (x.index >= 0) & (y.index >= 0)
    flat = x.index * shape[1] + y.index
    size = shape[0] * shape[1]
    n = np.bincount(flat[use], minlength=size).reshape(shape)
    k = np.bincount(flat[use & success], minlength=size).reshape(shape)
    median = np.full(size, np.nan)
    measured = use & np.isfinite(max_error_m)
    for cell in np.unique(flat[measured]):
        median[cell] = np.median(max_error_m[measured & (flat == cell)])
    return Cells(x, y, k, n, median.reshape(shape))


def heatmap_pair(table: pa.Table, requested: tuple[str, str] | None) -> tuple[str, str] | None:
    """The requested pair (checked), else the two parameters with the most distinct values
    (at least 2 each; ties in column order); None if fewer than two parameters vary."""
    columns = param_columns(table)
    if requested is not None:
        unknown = [c for c in requested if c not in columns]
        if unknown:
            raise ValueError(f"heatmap_pair: {', '.join(unknown)} is not a parameter column "
                             f"of the table (columns starting {PARAM_PREFIX!r})")
        return requested
    distinct = {c: len({v for v in table.column(c).to_pylist() if v is not None and v == v})
                for c in columns}
    varying = sorted((c for c in columns if distinct[c] >= 2), key=lambda c: -distinct[c])
    return (varying[0], varying[1]) if len(varying) >= 2 else None


def heatmap_bins(table: pa.Table, column: str) -> Bins:
    """A heat-map axis: ~RUNS_PER_BIN runs per cell on a square grid, 2 to MAX_HEATMAP_BINS."""
    per_axis = int(math.sqrt(max(table.num_rows, 1) / RUNS_PER_BIN))
    return bin_parameter(table, column, min(MAX_HEATMAP_BINS, max(2, per_axis)))


# --- the worst runs ------------------------------------------------------------------------


def worst_runs(table: pa.Table, count: int) -> list[int]:
    """Row indices of up to ``count`` runs: diverged first, then error (and any other status
    not "ok"), then ok but not converged, then the rest; within each, the highest max_error_m
    first (NaN last), then the lower run number."""
    status = statuses(table)
    converged, _ = flags(table, "converged")
    group = np.where(status == "diverged", 0,
                     np.where(status != "ok", 1, np.where(converged, 3, 2)))
    error = floats(table, "max_error_m")
    descending = np.where(np.isfinite(error), -error, np.inf)
    order = np.lexsort((floats(table, "run"), descending, group))
    return [int(i) for i in order[:count]]


def _cell(table: pa.Table, column: str, row: int) -> Any:
    return table.column(column)[row].as_py()


#: the metrics the report states for each worst run
WORST_METRICS = ("converged", "converge_time_s", "final_error_m", "max_error_m", "mean_error_m",
                 "mass_error_pct", "min_distance_m", "conditions_held")


def worst_run_records(table: pa.Table, meta: AnalysisMeta) -> list[WorstRun]:
    """The ``meta.worst_count`` worst runs (``worst_runs``'s order), each with its parameters
    (without the ``param.`` prefix) and its replay command."""
    records = []
    for row in worst_runs(table, meta.worst_count):
        run = int(_cell(table, "run", row))
        records.append(WorstRun(
            run, _cell(table, "seed", row), _cell(table, "status", row) or "",
            _cell(table, "message", row) or "",
            tuple((name, _cell(table, name, row)) for name in WORST_METRICS),
            tuple((c.removeprefix(PARAM_PREFIX), _cell(table, c, row))
                  for c in param_columns(table)),
            meta.replay_command(run)))
    return records


# --- writing ---------------------------------------------------------------------------


def _write(path: Path, text: str) -> Path:
    path.write_text(text, encoding="utf-8")
    return path


def write_figures(table: pa.Table, meta: AnalysisMeta, out_dir: Path) -> list[Path]:
    success, counted = successes(table), ran(table)
    written = []
    for column in param_columns(table):
        rate = binned_rate(bin_parameter(table, column), success, counted)
        written.append(plots.save(plots.success_figure(rate, meta.study_name), out_dir,
                                  plots.success_filename(column)))
    times = floats(table, "converge_time_s")[success]
    written.append(plots.save(plots.ecdf_figure(times[np.isfinite(times)], int(np.sum(counted)),
                                                meta.study_name, meta.converged_below_m),
                              out_dir, "ecdf_converge_time.png"))
    pair = heatmap_pair(table, meta.heatmap_pair)
    grid = None if pair is None else cells(heatmap_bins(table, pair[0]),
                                           heatmap_bins(table, pair[1]), success, counted,
                                           floats(table, "max_error_m"))
    written.append(plots.save(plots.heatmap_figure(grid, meta.study_name, meta.window_start_s),
                              out_dir, "heatmap.png"))
    for stale in set(out_dir.glob("success_vs_*.png")) - set(written):
        logger.info("removing %s: no such parameter in this table", stale)
        stale.unlink()
    return written


def write_analysis(table: pa.Table, meta: AnalysisMeta, out_dir: Path | str) -> list[Path]:
    """Write summary.json, summary.md, the figures and report.md into ``out_dir`` (created);
    returns the paths written, in that order. Raises ValueError for a table that lacks a column
    of the results schema or a heat-map pair that is not a parameter of it."""
    check_schema(table)
    heatmap_pair(table, meta.heatmap_pair)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    summary = summarize(table, meta.runs_planned)
    record = json.dumps(report.summary_record(summary, meta), indent=2, allow_nan=False)
    written = [_write(out / "summary.json", record + "\n"),
               _write(out / "summary.md", report.summary_page(summary, meta))]
    figures = write_figures(table, meta, out)
    text = report.report_page(summary, meta, figures, worst_run_records(table, meta))
    return [*written, *figures, _write(out / "report.md", text)]
