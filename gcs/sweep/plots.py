"""A sweep's figures drawn from the analysis's binned numbers, one PNG each.

Uses matplotlib's Agg canvas directly (no pyplot, no display, no global backend switch), like
gcs/plots.py. Axis units come from a key path's suffix (``unit``).
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.colors import LogNorm, Normalize
from matplotlib.figure import Figure

if TYPE_CHECKING:
    from gcs.sweep.analysis import BinnedRate, Cells

DPI = 120
SUCCESS = "success rate (converged, status ok)"
#: a key's last word's suffix -> its unit (longest first where one ends another)
UNITS = (("_kgm2", "kg m²"), ("_radps", "rad/s"), ("_pct", "%"), ("_kg", "kg"), ("_deg", "deg"),
         ("_rad", "rad"), ("_hz", "Hz"), ("_m", "m"), ("_s", "s"), ("_n", "N"))


def unit(path: str) -> str | None:
    """The unit of a key path from its last non-numeric part's suffix: ``vehicles.1.initial.
    position_enu_m.0`` -> "m"; None where the suffix names none."""
    words = [w for w in path.split(".") if not w.isdigit()]
    last = words[-1] if words else ""
    return next((u for suffix, u in UNITS if last.endswith(suffix)), None)


def axis_label(column: str) -> str:
    path = column.removeprefix("param.")
    found = unit(path)
    return f"{path} [{found}]" if found else path


def success_filename(column: str) -> str:
    return "success_vs_" + re.sub(r"[^\w.-]", "_", column.removeprefix("param.")) + ".png"


def _figure(width: float, height: float, title: str, subtitle: str) -> Figure:
    fig = Figure(figsize=(width, height), dpi=DPI, layout="constrained")
    FigureCanvasAgg(fig)
    fig.suptitle(f"{title}\n{subtitle}", fontsize=10)
    return fig


def _nothing(ax: Axes, why: str) -> None:
    ax.text(0.5, 0.5, why, transform=ax.transAxes, ha="center", va="center")
    ax.set_xticks([])
    ax.set_yticks([])


def save(fig: Figure, out_dir: Path, filename: str) -> Path:
    path = out_dir / filename
    fig.savefig(path, dpi=DPI)
    return path


def success_figure(binned: BinnedRate, study: str) -> Figure:
    """Success rate in each bin of one parameter with its 95 % Wilson interval: points over
    the bin's value range for a number, bars for strings; each bin's run count beside it."""
    bins = binned.bins
    how = ("quantile bins" if bins.quantiles else "one bin per value")
    fig = _figure(7.5, 4.5, f"Success rate against {axis_label(bins.column)}",
                  f"{study}: runs that ran {int(binned.n.sum())}, {how}; "
                  "bars: 95 % Wilson interval")
    ax = fig.add_subplot()
    shown = binned.n > 0
    if not shown.any():
        _nothing(ax, "no run that ran has a value of this parameter")
        return fig
    rate = binned.rate
    yerr = np.clip(np.vstack([rate - binned.low, binned.high - rate])[:, shown], 0.0, None)
    if bins.lows is None:
        x = np.arange(len(bins.labels))[shown]
        ax.bar(x, rate[shown], yerr=yerr, capsize=4, color="C0", alpha=0.7)
        ax.set_xticks(x, [bins.labels[b] for b in np.flatnonzero(shown)], rotation=30,
                      ha="right")
    else:
        x = ((bins.lows + bins.highs) / 2)[shown]
        xerr = np.vstack([x - bins.lows[shown], bins.highs[shown] - x])
        ax.errorbar(x, rate[shown], yerr=yerr, xerr=xerr, fmt="o", capsize=4, color="C0")
    for xi, ri, ni in zip(x, rate[shown], binned.n[shown], strict=True):
        ax.annotate(f"n={ni}", (xi, ri), textcoords="offset points", xytext=(4, 4), fontsize=7)
    ax.set_ylim(-0.05, 1.1)
    ax.set_xlabel(axis_label(bins.column))
    ax.set_ylabel(SUCCESS)
    ax.grid(True, alpha=0.3)
    return fig


def ecdf_figure(times_s: np.ndarray, runs_ran: int, study: str, converged_below_m: float) -> Figure:
    """ECDF of the time to converge over the runs that converged; the legend states the share
    of the runs that ran which never did."""
    fig = _figure(7.5, 4.5, "Time to converge: empirical CDF over the runs that converged",
                  f"{study}: converged = formation error stays below {converged_below_m:g} m")
    ax = fig.add_subplot()
    if times_s.size == 0:
        _nothing(ax, f"no run converged (of {runs_ran} that ran)")
        return fig
    never = runs_ran - times_s.size
    ax.ecdf(times_s, label=f"converged: {times_s.size} of {runs_ran} runs")
    ax.plot([], [], " ", label=f"never converged: {never} of {runs_ran} "
            f"({100 * never / runs_ran:.1f} %)")
    ax.set_xlabel("time to converge [s]")
    ax.set_ylabel("share of the converged runs")
    ax.set_ylim(0, 1.02)
    ax.grid(True, alpha=0.3)
    ax.legend(loc="lower right")
    return fig


def _grid(ax: Axes, grid: Cells, values: np.ndarray, norm: Normalize, cmap: str,
          text: list[list[str]], label: str) -> None:
    image = ax.pcolormesh(np.ma.masked_invalid(values.T), norm=norm, cmap=cmap)
    ax.set_facecolor("0.85")
    ax.figure.colorbar(image, ax=ax, label=label)
    for i, column in enumerate(text):
        for j, words in enumerate(column):
            ax.text(i + 0.5, j + 0.5, words, ha="center", va="center", fontsize=6)
    ax.set_xticks(np.arange(len(grid.x.labels)) + 0.5, grid.x.labels, rotation=40, ha="right",
                  fontsize=7)
    ax.set_yticks(np.arange(len(grid.y.labels)) + 0.5, grid.y.labels, fontsize=7)
    ax.set_xlabel(axis_label(grid.x.column))
    ax.set_ylabel(axis_label(grid.y.column))


def heatmap_figure(grid: Cells | None, study: str, window_start_s: float) -> Figure:
    """Success rate (left) and median max_error_m (right) over a 2-D binning of two parameters;
    grey: no run in the cell; each cell states its rate or median and its run count."""
    fig = _figure(13.0, 5.5, "Success rate and median max formation error over two parameters",
                  f"{study}: runs that ran, binned on each axis; max error from t = "
                  f"{window_start_s:g} s on; grey: no run (right: none with a finite error)")
    rate_ax, error_ax = fig.subplots(1, 2)
    if grid is None:
        for ax in (rate_ax, error_ax):
            _nothing(ax, "fewer than two parameters vary")
        return fig
    with np.errstate(invalid="ignore", divide="ignore"):
        rate = np.where(grid.n > 0, grid.k / np.maximum(grid.n, 1), np.nan)
    n_text = [[f"{r:.2f}\nn={n}" if n else "" for r, n in zip(rr, nn, strict=True)]
              for rr, nn in zip(rate, grid.n, strict=True)]
    _grid(rate_ax, grid, rate, Normalize(0.0, 1.0), "RdYlGn", n_text, SUCCESS)
    error = grid.median_max_error_m
    finite = error[np.isfinite(error)]
    norm = (LogNorm(finite.min(), finite.max()) if finite.size and finite.min() > 0
            and finite.max() > finite.min() else Normalize())
    e_text = [[f"{e:.2g}" if np.isfinite(e) else "" for e in row] for row in error]
    _grid(error_ax, grid, error, norm, "viridis", e_text, "median max_error_m [m]")
    if finite.size == 0:
        error_ax.text(0.5, 0.5, "no run with a finite max_error_m", transform=error_ax.transAxes,
                      ha="center", va="center")
    rate_ax.set_title(SUCCESS, fontsize=9)
    error_ax.set_title("median max_error_m [m] (runs with a finite value)", fontsize=9)
    return fig
