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
  fig6_mass_estimates.png     Fig. 6: alpha_m mhat_i / phi_i (solid) from its initial value (circle)
                              and the true mass (dashed); where the truth is known, a second panel
                              with the estimate's error relative to it [%]. Figs. 5 and 6 only for
                              a run that ran the law: gcs fly's position mode runs none, estimates
                              nothing, and gets neither (one left from an earlier run is removed)
  fig7_inertia_estimates.png  Fig. 7: Jhat_i x / y / z; only for a run whose setpoint is the torque
                              (26) (actuators mode: gcs.config.TORQUE_MODES) or of unknown mode. In
                              rates and attitude mode the autopilot's loops make the torque, Jhat
                              is neither used nor integrated, and no Fig. 7 is written (one left
                              from an earlier run in the directory is removed)
  errors_semilogy.png         (not in the paper) formation, velocity and attitude error of the team
                              on a log scale, to read convergence down to the numerical floor
Files written by ``write_comparison_figures(adaptive_log, baseline_log, out_dir)`` (Scenario II):
  fig8_adaptive_z.png         Fig. 8: z and v_z of each UAV with the adaptive law
  fig9_baseline_z.png         Fig. 9: the same with the non-adaptive baseline
A change of the true mass (e.g. the 30 % drop of Scenario II) is marked with a dotted line.

Every figure's title says what the run was (``run_description``): the source, law and control
mode, the vehicles (gcs fly: the autopilot family each HEARTBEAT named, and the emulator's
personality with --emulators) and where the estimates started (mhat(0) from each vehicle's hover
thrust or from the team file; Jhat(0), and whether it was estimated), read from ``log.extra``
(flightlog.estimates_record); what an older log did not record is said to be "not recorded".
"""

from __future__ import annotations

import logging
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from gcs import metrics
from gcs.config import TORQUE_MODES, ControlMode
from gcs.flightlog import AUTOPILOT_CONTROLLER, FlightLog

logger = logging.getLogger(__name__)

SNAPSHOT_TIMES_S = (0.0, 10.0, 30.0, 60.0)
DPI = 120
AXES = ("x", "y", "z")
FIG7_NAME = "fig7_inertia_estimates.png"
#: what each control mode sends the vehicle (the title's words)
MODE_SETPOINTS = {
    ControlMode.ACTUATORS: "thrust + torque (26)",
    ControlMode.RATES: "thrust + body rates",
    ControlMode.ATTITUDE: "thrust + attitude",
    ControlMode.POSITION: "formation slots as position setpoints",
}
#: the figures of the law's own states (attitude errors, estimates): not written for a run that
#: ran no law (gcs fly's position mode), and one left from an earlier run in the directory is
#: removed
LAW_FIGURES = ("fig5_attitude_errors.png", "fig6_mass_estimates.png")
#: the title's words for estimates_record's mass_from
MASS_FROM_TEXT = {
    "hover": "from hover thrust",
    "team": "from the team file",
    "nominal": "known (baseline, not estimated)",
    "none": "none",
}


def _color(j: int) -> str:
    return f"C{j % 10}"


def _new_figure(
    rows: int, title: str, log: FlightLog, height_per_row: float = 2.4
) -> tuple[Figure, list[Axes]]:
    fig = Figure(figsize=(8.0, 2.0 + height_per_row * rows), dpi=DPI, layout="constrained")
    FigureCanvasAgg(fig)
    axes = list(fig.subplots(rows, 1, sharex=True, squeeze=False)[:, 0])
    _title(fig, title, log)
    for ax in axes:
        ax.grid(True, alpha=0.3)
    axes[-1].set_xlabel("t [s]")
    return fig, axes


def _save(fig: Figure, out_dir: Path, filename: str) -> Path:
    path = out_dir / filename
    fig.savefig(path, dpi=DPI)
    return path


def _title(fig: Figure, title: str, log: FlightLog) -> None:
    """`title` over the run's description (two small lines)."""
    fig.suptitle(f"{title}\n{run_description(log)}", fontsize="medium")


def _subtitle(log: FlightLog) -> str:
    mode = log.extra.get("mode")
    mode_text = f"{mode} mode" if mode else "mode not recorded"
    law = f"{log.controller} law" if law_ran(log) else "no law"
    return f"{log.name}: {log.source}, {law}, {mode_text}"


def law_ran(log: FlightLog) -> bool:
    """False for a run that ran no law (controller "autopilot": gcs fly's position mode): it
    has no attitude errors, estimates, thrust or force to draw."""
    return log.controller != AUTOPILOT_CONTROLLER


def _estimates(log: FlightLog) -> dict[str, Any] | None:
    est = log.extra.get("estimates")
    return est if isinstance(est, dict) else None


def torque_commanded(log: FlightLog) -> bool | None:
    """True when the run's setpoint was the law's torque (26) (TORQUE_MODES), False when it was
    not, None when the log does not say (no ``extra["mode"]``)."""
    mode = log.extra.get("mode")
    return None if mode is None else mode in TORQUE_MODES


def inertia_estimated(log: FlightLog) -> bool | None:
    """Whether the run integrated Jhat (27): as recorded, else (older logs) the adaptive law in a
    torque mode; None when neither says."""
    est = _estimates(log)
    if est is not None and "inertia_estimated" in est:
        return bool(est["inertia_estimated"])
    torque = torque_commanded(log)
    return None if torque is None else torque and log.controller == "adaptive"


def _vehicles_text(log: FlightLog) -> str:
    kinds = log.extra.get("vehicle_kinds")
    if not isinstance(kinds, list) or len(kinds) != log.n_vehicles:
        if log.source == "sim":
            return "vehicles: the nominal model (6)-(9) in-process"
        return "vehicles: not recorded"
    groups: dict[str, list[str]] = {}
    for vid, kind in zip(log.vehicle_ids.tolist(), kinds, strict=True):
        groups.setdefault(str(kind), []).append(str(vid))
    if len(groups) == 1:
        return f"vehicles: {next(iter(groups))}"
    return "vehicles: " + "; ".join(f"UAV {', '.join(v)}: {k}" for k, v in groups.items())


def _mass_from_text(log: FlightLog) -> str:
    est = _estimates(log)
    mass_from = est.get("mass_from") if est is not None else None
    if not isinstance(mass_from, list) or len(mass_from) != log.n_vehicles:
        return r"$\hat m(0)$ source not recorded"
    groups: dict[str, list[str]] = {}
    for vid, source in zip(log.vehicle_ids.tolist(), mass_from, strict=True):
        groups.setdefault(MASS_FROM_TEXT.get(source, str(source)), []).append(str(vid))
    if len(groups) == 1:
        return rf"$\hat m(0)$ {next(iter(groups))}"
    return "; ".join(rf"$\hat m(0)$ of UAV {', '.join(v)} {k}" for k, v in groups.items())


def _inertia_text(log: FlightLog) -> str:
    est = _estimates(log)
    j0 = np.asarray(est["inertia_kgm2"], dtype=float) if est and "inertia_kgm2" in est else None
    start = (
        rf"$\hat J(0)$ = {j0.flat[0]:g} kg m$^2$"
        if j0 is not None and j0.size and np.all(j0 == j0.flat[0])
        else r"$\hat J(0)$ per vehicle"
        if j0 is not None
        else r"$\hat J(0)$ not recorded"
    )
    estimated, torque = inertia_estimated(log), torque_commanded(log)
    if torque is False:
        held = est is not None and est.get("inertia_estimated") is False
        unused = f"not used in {log.extra['mode']} mode"
        return f"{start}, held there ({unused})" if held else rf"$\hat J$ {unused}"
    if estimated is None:
        return f"{start}, estimation not recorded"
    if not estimated:
        return f"{start}, known (baseline, not estimated)"
    return f"{start}, estimated and used in the torque"


def run_description(log: FlightLog) -> str:
    """Three lines for a figure's title: the run (source, law, mode and what it sends), the
    vehicles, and where the estimates started (or that nothing was estimated)."""
    mode = log.extra.get("mode")
    sends = f" ({MODE_SETPOINTS[mode]})" if mode in MODE_SETPOINTS else ""
    estimates = (f"{_mass_from_text(log)}; {_inertia_text(log)}" if law_ran(log)
                 else "the autopilots' own loops fly the slots; no mass or inertia estimation")
    return f"{_subtitle(log)}{sends}\n{_vehicles_text(log)}\n{estimates}"


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
    _title(fig, "Fig. 2 - Formation snapshots", log)
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
    fig, axes = _new_figure(3, "Fig. 3 - Position offsets", log)
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
    fig, axes = _new_figure(3, "Fig. 4 - Velocity errors", log)
    for a, ax in enumerate(axes):
        for j in range(log.n_vehicles):
            ax.plot(log.t_s, e[:, j, a], color=_color(j), lw=1.0, label=f"UAV {log.vehicle_ids[j]}")
        ax.set_ylabel(rf"$v_{{i,{AXES[a]}}} - v_{{r,{AXES[a]}}}$ [m/s]")
    _legend(axes[0], log.n_vehicles)
    return fig


def fig5_attitude_errors(log: FlightLog) -> Figure:
    fig, axes = _new_figure(2, "Fig. 5 - Attitude errors", log, 2.8)
    for j in range(log.n_vehicles):
        label = f"UAV {log.vehicle_ids[j]}"
        axes[0].plot(log.t_s, log.attitude_error[:, j], color=_color(j), lw=1.0, label=label)
        axes[1].plot(log.t_s, log.omega_error_radps[:, j], color=_color(j), lw=1.0, label=label)
    axes[0].set_ylabel(r"tr$(I - R_i^e)$ [-]")
    axes[1].set_ylabel(r"$|\omega_i^e|$ [rad/s]")
    _legend(axes[0], log.n_vehicles)
    return fig


def fig6_mass_estimates(log: FlightLog) -> Figure:
    """The mass estimates from their initial values (circles) against the true masses (dashed,
    where known: the simulated plant, or the team file's plant that the emulator flies); with a
    known truth, a second panel with the error relative to it."""
    known = np.isfinite(log.mass_true_kg).any(axis=0)
    rows = 2 if known.any() else 1
    fig, axes = _new_figure(rows, "Fig. 6 - Mass estimates", log, 4.2 if rows == 1 else 3.0)
    ax = axes[0]
    m = log.mass_estimate_kg
    first = np.array([_first_finite(m[:, j]) for j in range(log.n_vehicles)])
    for j in range(log.n_vehicles):
        vid = log.vehicle_ids[j]
        ax.plot(log.t_s, m[:, j], color=_color(j), lw=1.2, label=f"UAV {vid}")
        if known[j]:
            ax.plot(
                log.t_s,
                log.mass_true_kg[:, j],
                color=_color(j),
                lw=1.0,
                ls="--",
                label=f"UAV {vid} true",
            )
        k0, m0 = first[j]
        if np.isfinite(m0):
            ax.plot(log.t_s[int(k0)], m0, "o", color=_color(j), mfc="none", ms=7, mew=1.5)
    ax.set_ylabel(r"$\alpha_m \hat m_i / \phi_i$ [kg]")
    ax.set_title(_mass_panel_title(log, first[:, 1]), fontsize="small")
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small")
    if rows == 2:
        rel = 100.0 * (m - log.mass_true_kg) / log.mass_true_kg
        for j in np.flatnonzero(known):
            axes[1].plot(
                log.t_s, rel[:, j], color=_color(j), lw=1.0, label=f"UAV {log.vehicle_ids[j]}"
            )
        axes[1].axhline(0.0, color="k", lw=0.8)
        axes[1].set_ylabel(r"$(\alpha_m \hat m_i / \phi_i - m_i) / m_i$ [%]")
        axes[1].set_title("estimate error relative to the true mass", fontsize="small")
    return fig


def _first_finite(a: np.ndarray) -> tuple[float, float]:
    """(index, value) of the first finite sample of a (k,) series; (0, NaN) if there is none."""
    ok = np.flatnonzero(np.isfinite(a))
    return (0.0, np.nan) if ok.size == 0 else (float(ok[0]), float(a[ok[0]]))


def _mass_panel_title(log: FlightLog, initial_kg: np.ndarray) -> str:
    """E.g. 'mhat(0) from hover thrust: 0.845, 1.23 kg; dashed: true (the plant) 0.85, 1.2 kg'."""

    def values(a: np.ndarray) -> str:
        return ", ".join("?" if not np.isfinite(x) else f"{x:.3g}" for x in a)

    text = f"\u25cb {_mass_from_text(log)}: {values(initial_kg)} kg"
    true0 = np.array([_first_finite(log.mass_true_kg[:, j])[1] for j in range(log.n_vehicles)])
    if np.isfinite(true0).any():
        text += f"; dashed: true (the plant) {values(true0)} kg"
    else:
        text += "; true masses unknown"
    return text


def fig7_inertia_estimates(log: FlightLog) -> Figure:
    """Jhat_i per axis; for a run that commands the torque (TORQUE_MODES), see write_figures."""
    fig, axes = _new_figure(3, "Fig. 7 - Inertia estimates", log)
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
    fig, axes = _new_figure(1, "Team errors (log scale)", log, 4.2)
    ax = axes[0]
    floor = np.finfo(np.float64).tiny  # a log axis cannot show exact zeros; clip to the tiniest
    curves = [
        (fe, r"formation error $\max_{i<j} |p_i - p_j - \theta_{ij}|$ [m]"),
        (ve, r"velocity error $\max_i |v_i - v_r|$ [m/s]"),
    ]
    if law_ran(log):  # the law's R^e: no such error without a law
        curves.append((ae, r"attitude error $\max_i$ tr$(I - R_i^e)$ [-]"))
    for values, label in curves:
        ax.semilogy(log.t_s, np.maximum(values, floor), lw=1.2, label=label)
    ax.set_ylabel("error")
    ax.legend(loc="upper right", fontsize="small")
    return fig


# --------------------------------------------------------------------------------------------------
# Figs. 8-9


def fig_z(log: FlightLog, number: int, title: str) -> Figure:
    fig, axes = _new_figure(2, f"Fig. {number} - {title}", log, 2.8)
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

    Fig. 7 only where the run commanded the torque (or its mode is not recorded): in rates and
    attitude mode Jhat is not used, and a Fig. 7 already in ``out_dir`` (an earlier run's) is
    removed so that none is read as this run's. Figs. 5 and 6 only where the law ran (not in
    position mode: no attitude errors, nothing estimated), removed likewise. ``pairs``:
    vehicle-id pairs for Fig. 3 (e.g. the graph's edges); default every pair i < j. Returns the
    paths written, in figure order, once all are on disk.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    figures = [
        ("fig2_formation.png", fig2_formation(log, snapshot_times_s)),
        ("fig3_position_offsets.png", fig3_position_offsets(log, pairs)),
        ("fig4_velocity_errors.png", fig4_velocity_errors(log)),
    ]
    if law_ran(log):
        figures += [(LAW_FIGURES[0], fig5_attitude_errors(log)),
                    (LAW_FIGURES[1], fig6_mass_estimates(log))]
    else:
        for name in LAW_FIGURES:
            _remove_stale(out / name, "this run ran no law (no attitude errors, no estimates)")
    if torque_commanded(log) is False:
        _remove_stale(out / FIG7_NAME,
                      f"this run ({log.extra['mode']} mode) does not use the inertia estimate")
    else:
        figures.append((FIG7_NAME, fig7_inertia_estimates(log)))
    figures.append(("errors_semilogy.png", errors_semilogy(log)))
    return [_save(fig, out, name) for name, fig in figures]


def _remove_stale(path: Path, why: str) -> None:
    """An earlier run's figure that this run does not write: removed, so that none is read as
    this run's."""
    if path.exists():
        path.unlink()
        logger.info("%s: removed: %s", path, why)


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
