"""The paper's Section V figures (Figs. 2-9) drawn from FlightLogs, one PNG per figure.

Uses matplotlib's Agg canvas directly (no pyplot, no display, no global backend switch), so it is
safe to call from any thread or process. Plots are in the app's world frame ENU (x east, y north,
z up), which is the paper's frame, so they read like the paper's figures.

Files written by ``write_figures(log, out_dir)`` (Scenario I):
  fig2_formation.png          Fig. 2: 3-D trajectories and x-y top view, with the formation polygon
                              at t = 0, 10, 30, 60 s (those within the run) and at the end; the
                              dashed polygon is the desired shape placed on the team
  fig3_position_offsets.png   Fig. 3: p_i - p_j - theta_ij, x / y / z, for every pair i < j (or the
                              given pairs, e.g. the graph's edges)
  fig4_velocity_errors.png    Fig. 4: v_i - v_r, x / y / z
  fig5_attitude_errors.png    Fig. 5: tr(I - R_i^e) and |omega_i^e|
  fig6_mass_estimates.png     Fig. 6: alpha_m mhat_i / phi_i (solid) and the true mass (dashed)
  fig7_inertia_estimates.png  Fig. 7: Jhat_i x / y / z
  errors_semilogy.png         (not in the paper) formation, velocity and attitude error of the team
                              on a log scale, to read convergence down to the numerical floor
Files written by ``write_comparison_figures(adaptive_log, baseline_log, out_dir)`` (Scenario II):
  fig8_adaptive_z.png         Fig. 8: z and v_z of each UAV with the adaptive law
  fig9_baseline_z.png         Fig. 9: the same with the non-adaptive baseline
A change of the true mass (e.g. the 30 % drop of Scenario II) is marked with a dotted line.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from gcs import metrics
from gcs.flightlog import FlightLog

SNAPSHOT_TIMES_S = (0.0, 10.0, 30.0, 60.0)
DPI = 120
AXES = ("x", "y", "z")


def _color(j: int) -> str:
    return f"C{j % 10}"


def _new_figure(rows: int, title: str, height_per_row: float = 2.4) -> tuple[Figure, list[Axes]]:
    fig = Figure(figsize=(8.0, 1.3 + height_per_row * rows), dpi=DPI, layout="constrained")
    FigureCanvasAgg(fig)
    axes = list(fig.subplots(rows, 1, sharex=True, squeeze=False)[:, 0])
    fig.suptitle(title)
    for ax in axes:
        ax.grid(True, alpha=0.3)
    axes[-1].set_xlabel("t [s]")
    return fig, axes


def _save(fig: Figure, out_dir: Path, filename: str) -> Path:
    path = out_dir / filename
    fig.savefig(path, dpi=DPI)
    return path


def _subtitle(log: FlightLog) -> str:
    return f"{log.name} ({log.source}, {log.controller})"


def _legend(ax: Axes, n_entries: int) -> None:
    ax.legend(loc="upper right", fontsize="small", ncols=2 if n_entries > 4 else 1)


def _mass_change_times(log: FlightLog) -> list[float]:
    """Times at which some vehicle's known true mass changes (e.g. a payload drop)."""
    m = log.mass_true_kg
    changed = (np.abs(np.diff(m, axis=0)) > 1e-12 * np.nanmax(np.abs(m), initial=1.0)).any(axis=1)
    return [float(log.t_s[i + 1]) for i in np.flatnonzero(changed)]


def _mark_events(ax: Axes, times: Sequence[float], label: bool) -> None:
    for i, t in enumerate(times):
        ax.axvline(t, color="k", ls=":", lw=1.0, label="mass change" if label and i == 0 else None)


# --------------------------------------------------------------------------------------------------
# Fig. 2


def _snapshot_indices(log: FlightLog, times_s: Sequence[float]) -> list[int]:
    t0, t1 = float(log.t_s[0]), float(log.t_s[-1])
    chosen = [t for t in times_s if t0 <= t <= t1]
    if not chosen or t1 - chosen[-1] > 0.05 * max(t1 - t0, 1e-9):
        chosen.append(t1)
    if len(chosen) == 1 and t1 > t0:
        chosen.insert(0, t0)
    idx = [metrics.nearest_index(log.t_s, t) for t in chosen]
    return sorted(set(idx))


def _polygon_order(offsets: np.ndarray) -> np.ndarray:
    """Vehicle order around the centroid of the offsets (a closed, non-crossing outline)."""
    c = offsets[:, :2] - offsets[:, :2].mean(axis=0)
    return np.argsort(np.arctan2(c[:, 1], c[:, 0]))


def fig2_formation(log: FlightLog, snapshot_times_s: Sequence[float] = SNAPSHOT_TIMES_S) -> Figure:
    p = log.position_enu_m
    n = log.n_vehicles
    order = _polygon_order(log.offsets_enu_m)
    ring = np.append(order, order[0]) if n > 2 else order
    snaps = _snapshot_indices(log, snapshot_times_s)

    fig = Figure(figsize=(13.0, 6.0), dpi=DPI, layout="constrained")
    FigureCanvasAgg(fig)
    fig.suptitle(f"Fig. 2 - Formation snapshots: {_subtitle(log)}")
    ax3 = fig.add_subplot(1, 2, 1, projection="3d")
    ax2 = fig.add_subplot(1, 2, 2)

    for j in range(n):
        label = f"UAV {log.vehicle_ids[j]}"
        ax3.plot(p[:, j, 0], p[:, j, 1], p[:, j, 2], color=_color(j), lw=1.0, label=label)
        ax2.plot(p[:, j, 0], p[:, j, 1], color=_color(j), lw=1.0, label=label)
    for s, i in enumerate(snaps):
        q = p[i]
        shade = 0.25 + 0.75 * s / max(len(snaps) - 1, 1)
        grey = str(round(0.6 * (1.0 - shade), 3))
        ax3.plot(q[ring, 0], q[ring, 1], q[ring, 2], color=grey, lw=1.4)
        ax2.plot(q[ring, 0], q[ring, 1], color=grey, lw=1.4)
        # the desired shape, placed where the team is: mean(p_i - theta_i) + theta_i
        desired = np.nanmean(q - log.offsets_enu_m, axis=0) + log.offsets_enu_m
        ax2.plot(desired[ring, 0], desired[ring, 1], color=grey, lw=0.8, ls="--")
        for j in range(n):
            ax3.scatter(*q[j], color=_color(j), s=18, depthshade=False)
            ax2.scatter(q[j, 0], q[j, 1], color=_color(j), s=18, zorder=3)
        # label each snapshot at a different corner of the polygon, pushed outwards
        label = f"t = {log.t_s[i]:g} s"
        anchor = int(order[s % n])
        out = q[anchor, :2] - np.nanmean(q[:, :2], axis=0)
        out = 14.0 * out / max(float(np.linalg.norm(out)), 1e-9) if np.all(np.isfinite(out)) else 0
        ax2.annotate(
            label,
            (q[anchor, 0], q[anchor, 1]),
            textcoords="offset points",
            xytext=tuple(np.broadcast_to(out, 2)),
            ha="center",
            va="center",
            fontsize="small",
        )
        ax3.text(*q[anchor], f" {label}", fontsize="small")

    ax3.set_xlabel("x (east) [m]")
    ax3.set_ylabel("y (north) [m]")
    ax3.set_zlabel("z (up) [m]")
    ax3.set_title("trajectories (polygons: formation at the snapshot times)", fontsize="medium")
    ax2.set_xlabel("x (east) [m]")
    ax2.set_ylabel("y (north) [m]")
    ax2.set_aspect("equal", adjustable="datalim")
    ax2.grid(True, alpha=0.3)
    ax2.set_title("top view (dashed: desired shape)", fontsize="medium")
    ax2.legend(loc="best", fontsize="small")
    return fig


# --------------------------------------------------------------------------------------------------
# Figs. 3-7


def _pair_indices(log: FlightLog, pairs: Sequence[tuple[int, int]] | None) -> np.ndarray:
    if pairs is None:
        return np.array(np.triu_indices(log.n_vehicles, k=1)).T.reshape(-1, 2)
    return np.array([[log.vehicle_index(a), log.vehicle_index(b)] for a, b in pairs]).reshape(-1, 2)


def fig3_position_offsets(log: FlightLog, pairs: Sequence[tuple[int, int]] | None = None) -> Figure:
    idx = _pair_indices(log, pairs)
    d = metrics.relative_offsets(log.position_enu_m, log.offsets_enu_m, idx)
    fig, axes = _new_figure(3, f"Fig. 3 - Position offsets: {_subtitle(log)}")
    for a, ax in enumerate(axes):
        for q, (i, j) in enumerate(idx):
            ax.plot(
                log.t_s,
                d[:, q, a],
                color=_color(q),
                lw=1.0,
                label=f"UAV {log.vehicle_ids[i]} - UAV {log.vehicle_ids[j]}",
            )
        ax.set_ylabel(rf"$p_{{i,{AXES[a]}}} - p_{{j,{AXES[a]}}} - \theta_{{ij,{AXES[a]}}}$ [m]")
    _legend(axes[0], len(idx))
    return fig


def fig4_velocity_errors(log: FlightLog) -> Figure:
    e = log.velocity_enu_mps - log.reference_velocity_enu_mps[:, None, :]
    fig, axes = _new_figure(3, f"Fig. 4 - Velocity errors: {_subtitle(log)}")
    for a, ax in enumerate(axes):
        for j in range(log.n_vehicles):
            ax.plot(log.t_s, e[:, j, a], color=_color(j), lw=1.0, label=f"UAV {log.vehicle_ids[j]}")
        ax.set_ylabel(rf"$v_{{i,{AXES[a]}}} - v_{{r,{AXES[a]}}}$ [m/s]")
    _legend(axes[0], log.n_vehicles)
    return fig


def fig5_attitude_errors(log: FlightLog) -> Figure:
    fig, axes = _new_figure(2, f"Fig. 5 - Attitude errors: {_subtitle(log)}", 2.8)
    for j in range(log.n_vehicles):
        label = f"UAV {log.vehicle_ids[j]}"
        axes[0].plot(log.t_s, log.attitude_error[:, j], color=_color(j), lw=1.0, label=label)
        axes[1].plot(log.t_s, log.omega_error_radps[:, j], color=_color(j), lw=1.0, label=label)
    axes[0].set_ylabel(r"tr$(I - R_i^e)$ [-]")
    axes[1].set_ylabel(r"$|\omega_i^e|$ [rad/s]")
    _legend(axes[0], log.n_vehicles)
    return fig


def fig6_mass_estimates(log: FlightLog) -> Figure:
    fig, axes = _new_figure(1, f"Fig. 6 - Mass estimates: {_subtitle(log)}", 4.2)
    ax = axes[0]
    for j in range(log.n_vehicles):
        vid = log.vehicle_ids[j]
        ax.plot(log.t_s, log.mass_estimate_kg[:, j], color=_color(j), lw=1.2, label=f"UAV {vid}")
        if np.isfinite(log.mass_true_kg[:, j]).any():
            ax.plot(
                log.t_s,
                log.mass_true_kg[:, j],
                color=_color(j),
                lw=1.0,
                ls="--",
                label=f"UAV {vid} true",
            )
    ax.set_ylabel(r"$\alpha_m \hat m_i / \phi_i$ [kg]")
    _legend(ax, 2 * log.n_vehicles)
    return fig


def fig7_inertia_estimates(log: FlightLog) -> Figure:
    fig, axes = _new_figure(3, f"Fig. 7 - Inertia estimates: {_subtitle(log)}")
    for a, ax in enumerate(axes):
        for j in range(log.n_vehicles):
            ax.plot(
                log.t_s,
                log.inertia_estimate_kgm2[:, j, a],
                color=_color(j),
                lw=1.0,
                label=f"UAV {log.vehicle_ids[j]}",
            )
        ax.set_ylabel(rf"$\hat J_{{i,{AXES[a]}}}$ [kg m$^2$]")
    _legend(axes[0], log.n_vehicles)
    return fig


def errors_semilogy(log: FlightLog) -> Figure:
    fe = metrics.formation_error(log.position_enu_m, log.offsets_enu_m)
    ve = metrics.velocity_error(log.velocity_enu_mps, log.reference_velocity_enu_mps)
    ae = log.attitude_error.max(axis=1)
    fig, axes = _new_figure(1, f"Team errors (log scale): {_subtitle(log)}", 4.2)
    ax = axes[0]
    floor = np.finfo(np.float64).tiny  # a log axis cannot show exact zeros; clip to the tiniest
    for values, label in (
        (fe, r"formation error $\max_{i<j} |p_i - p_j - \theta_{ij}|$ [m]"),
        (ve, r"velocity error $\max_i |v_i - v_r|$ [m/s]"),
        (ae, r"attitude error $\max_i$ tr$(I - R_i^e)$ [-]"),
    ):
        ax.semilogy(log.t_s, np.maximum(values, floor), lw=1.2, label=label)
    ax.set_ylabel("error")
    ax.legend(loc="upper right", fontsize="small")
    return fig


# --------------------------------------------------------------------------------------------------
# Figs. 8-9


def fig_z(log: FlightLog, number: int, title: str) -> Figure:
    fig, axes = _new_figure(2, f"Fig. {number} - {title}: {_subtitle(log)}", 2.8)
    events = _mass_change_times(log)
    for j in range(log.n_vehicles):
        label = f"UAV {log.vehicle_ids[j]}"
        axes[0].plot(log.t_s, log.position_enu_m[:, j, 2], color=_color(j), lw=1.0, label=label)
        axes[1].plot(log.t_s, log.velocity_enu_mps[:, j, 2], color=_color(j), lw=1.0, label=label)
    for ax in axes:
        _mark_events(ax, events, label=ax is axes[0])
    axes[0].set_ylabel(r"$z_i$ (up) [m]")
    axes[1].set_ylabel(r"$v_{i,z}$ (up) [m/s]")
    _legend(axes[0], log.n_vehicles + (1 if events else 0))
    return fig


# --------------------------------------------------------------------------------------------------
# Entry points


def write_figures(
    log: FlightLog,
    out_dir: str | os.PathLike[str],
    *,
    pairs: Sequence[tuple[int, int]] | None = None,
    snapshot_times_s: Sequence[float] = SNAPSHOT_TIMES_S,
) -> list[Path]:
    """Write Figs. 2-7 (and errors_semilogy.png) of ``log`` into ``out_dir`` (created if needed).

    ``pairs``: vehicle-id pairs for Fig. 3 (e.g. the graph's edges); default every pair i < j.
    Returns the paths written, in figure order, once all are on disk.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    figures = (
        ("fig2_formation.png", fig2_formation(log, snapshot_times_s)),
        ("fig3_position_offsets.png", fig3_position_offsets(log, pairs)),
        ("fig4_velocity_errors.png", fig4_velocity_errors(log)),
        ("fig5_attitude_errors.png", fig5_attitude_errors(log)),
        ("fig6_mass_estimates.png", fig6_mass_estimates(log)),
        ("fig7_inertia_estimates.png", fig7_inertia_estimates(log)),
        ("errors_semilogy.png", errors_semilogy(log)),
    )
    return [_save(fig, out, name) for name, fig in figures]


def write_comparison_figures(
    adaptive_log: FlightLog, baseline_log: FlightLog, out_dir: str | os.PathLike[str]
) -> list[Path]:
    """Write Figs. 8 (adaptive) and 9 (baseline): z and v_z of each UAV, e.g. for the mass drop.

    Raises ValueError if the logs' controllers are not "adaptive" and "baseline" or their vehicles
    differ. Returns the two paths once written.
    """
    if adaptive_log.controller != "adaptive" or baseline_log.controller != "baseline":
        raise ValueError(
            "write_comparison_figures: expected an 'adaptive' and a 'baseline' log, got "
            f"{adaptive_log.controller!r} and {baseline_log.controller!r}"
        )
    if adaptive_log.vehicle_ids.tolist() != baseline_log.vehicle_ids.tolist():
        raise ValueError(
            "write_comparison_figures: the logs fly different vehicles: "
            f"{adaptive_log.vehicle_ids.tolist()} and {baseline_log.vehicle_ids.tolist()}"
        )
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    return [
        _save(
            fig_z(adaptive_log, 8, "z position and velocity, adaptive law"),
            out,
            "fig8_adaptive_z.png",
        ),
        _save(
            fig_z(baseline_log, 9, "z position and velocity, non-adaptive baseline"),
            out,
            "fig9_baseline_z.png",
        ),
    ]
