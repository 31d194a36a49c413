"""The records of `gcs fly`: what the flight measures for them while it flies, and report.json,
timeseries.csv and the figures written from them at the end; the mission's notes in the log."""

from __future__ import annotations

import dataclasses
import logging
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from gcs.config import ControlMode
from gcs.control.predict import PredictionAudit
from gcs.flightlog import estimates_record
from gcs.flightlog_builder import FlightLogBuilder
from gcs.flightlog_csv import save_timeseries
from gcs.fly.consistent import AccelerationConsistency, VelocityConsistency
from gcs.fly.measure import HoverEstimate
from gcs.fly.sched import Scheduling
from gcs.fly.setup import FlightSetup, FlyOptions, FlyResult
from gcs.fly.stats import (
    AgeStats,
    TickStats,
    clock_report,
    link_report,
    prediction_report,
    round_trip_report,
)
from gcs.link import TlogWriter, VehicleProxy
from gcs.mission.machine import MissionMachine
from gcs.mission.plan import NoteLevel, Outcome
from gcs.report import build_report, write_report

logger = logging.getLogger("gcs.fly")

REPORT_NAME = "report.json"
TIMESERIES_NAME = "timeseries.csv"
TLOG_NAME = "flight.tlog"


def log_notes(machine: MissionMachine, logged: int) -> int:
    """Log the mission's notes after the first `logged` at their level (the outcome itself is
    printed by the command line; a stop before the formation's end is a warning, the normal end
    is not); returns how many are logged now."""
    m = machine
    for text, level in zip(m.notes[logged:], m.note_levels[logged:], strict=True):
        logger.log(logging.WARNING if level is NoteLevel.WARNING else logging.INFO,
                   "mission: %s", text)
    return len(m.notes)


def flight_log_builder(setup: FlightSetup, rhohat: np.ndarray,
                       inertia_estimated: bool) -> FlightLogBuilder:
    """The flight log of `setup`, empty: the team, the mode and why, the gains, the criterion,
    where each estimate starts (`rhohat`: Jhat(0), held or estimated)."""
    team = setup.team
    position_mode = setup.mode == ControlMode.POSITION
    adaptive = setup.law == "adaptive"
    d = team.controller.derivative
    return FlightLogBuilder(
        vehicle_ids=team.ids(), sysids=team.sysids(), offsets_enu_m=team.offsets_enu_m(),
        source="fly", controller=setup.law, team=team.source_path, name=team.name,
        extra={"mode": setup.mode, "mode_choice": setup.mode_choice,
               "tick_rate_hz": setup.tick_rate_hz,
               "derivative": None if position_mode else d.method,
               "gains": None if position_mode else setup.gains._asdict(),
               "stability": setup.stability,
               "estimates": (estimates_record(  # no law, nothing estimated
                   mass_from=["none"] * team.n, inertia_from="none", inertia_kgm2=None,
                   inertia_estimated=False) if position_mode else estimates_record(
                   mass_from=[("hover" if v.estimates.from_hover else "team") if adaptive
                              else "nominal" for v in team.vehicles],
                   inertia_from="team" if adaptive else "nominal",
                   inertia_kgm2=rhohat, inertia_estimated=inertia_estimated))},
    )


@dataclass(eq=False, slots=True)
class Figures:
    """What the flight measures for its records while it flies (the tick loop, the tick, the
    setpoints write it) and `Records.write` writes out at the end."""

    builder: FlightLogBuilder  # the formation's samples
    ticks: TickStats
    ages: AgeStats
    limited_ticks: np.ndarray  # per vehicle: formation ticks with the rate or torque limit applied
    audit: PredictionAudit | None  # delay compensation (gcs/control/predict.py) and its error
    # the law's velocity filter (gcs/fly/consistent.py): the tick feeds and reads it, the report
    # states what it did
    consistency: VelocityConsistency
    # the law's acceleration filter (the same module), fed and read alike
    accel_consistency: AccelerationConsistency
    hover_estimates: dict[int, HoverEstimate] = field(default_factory=dict)
    start_error_m: dict[int, float] = field(default_factory=dict)  # |p(0) - start| at t = 0


class Records:
    """Writes the flight's records at its end (`write`); the time of its making is the flight's
    start (STATUSTEXT times in the report, on the proxies' clock)."""

    def __init__(self, setup: FlightSetup, options: FlyOptions, machine: MissionMachine,
                 proxies: list[VehicleProxy], figures: Figures) -> None:
        self.team = setup.team
        self.options = options
        self.machine = machine
        self.proxies = proxies  # the team's, in team order once the links are open
        self.ids = setup.team.ids()
        self.figures = figures
        self.t0_s = time.monotonic()

    def statustexts(self) -> dict[str, list[dict[str, Any]]]:
        """Every vehicle's STATUSTEXT (severity, text, time after the flight start in s)."""
        t0 = self.t0_s
        return {str(self.ids[i]): [{"t_s": round(e.rx_time_s - t0, 3), "severity": e.severity_name,
                                    "text": e.text} for e in p.statustexts.texts()]
                for i, p in enumerate(self.proxies)}

    def vehicle_kind(self, vehicle_id: int, vehicle_notes: dict[int, str]) -> str:
        """'PX4', or with a note 'PX4 (vehicle-emu px4)': the autopilot family its HEARTBEAT
        named (the machine's profile) and what the command line knows of the vehicle."""
        name = self.machine.profile(vehicle_id).name
        note = vehicle_notes.get(vehicle_id)
        return f"{name} ({note})" if note else name

    def write(self, outcome: Outcome, *, scheduling: Scheduling | None, tlog: TlogWriter | None,
              vehicle_notes: dict[int, str], compiled_after_ready: list[str],
              more: dict[str, Any] | None = None) -> FlyResult:
        """report.json, timeseries.csv and (options.figures) the figures from the formation's
        samples; none without one. `more`: sections added to the records' extra (an agent's
        neighbour figures)."""
        fig = self.figures
        out = self.options.out_dir
        if len(fig.builder) == 0:
            logger.warning("no formation samples: no report written")
            return FlyResult(outcome, None, out, None)
        stats = [p.stats() for p in self.proxies]
        link = link_report(
            self.ids, fig.ages,
            setpoints_sent=[s.proxy.setpoints_sent for s in stats],
            telemetry_received=[s.proxy.messages_accepted for s in stats],
            telemetry_lost=[s.sequence.lost for s in stats],
            extra=[{"limited_ticks": int(fig.limited_ticks[i]),
                    "thrust_clamped": s.proxy.thrust_clamped,
                    "torque_clamped": s.proxy.torque_clamped,
                    "link_lost_events": s.proxy.link_lost_events,
                    "heartbeat_stale_events": s.proxy.heartbeat_stale_events,
                    "stranger_address": s.proxy.stranger_address,
                    "unknown_sysid_frames": s.port.unknown_sysid_frames,
                    "gcs_socket_dropped": s.udp.rx_dropped_kernel,
                    "command_retries": getattr(s.commands, "retries", None),
                    "lost": self.ids[i] in self.machine.lost,
                    "round_trip": round_trip_report(self.proxies[i].round_trips_s()),
                    "clock": clock_report(self.proxies[i].clock.estimate()),
                    "prediction": prediction_report(
                        fig.audit.figures(i) if fig.audit is not None else None),
                    "velocity_from_position": fig.consistency.report(i),
                    "acceleration_from_velocity": fig.accel_consistency.report(i)}
                   for i, s in enumerate(stats)],
        )
        tick = fig.ticks.report()
        log = fig.builder.build(extra={
            "link": link,
            "tick": {**tick, "scheduling": (scheduling.detail if scheduling is not None
                                             else "not set")},
            "outcome": {"exit_code": outcome.exit_code, "reason": outcome.reason},
            # records the disk could not take in time (dropped, counted; gcs/link/tlog.py)
            "tlog": ({"records": tlog.records, "dropped_records": tlog.dropped_records,
                      "write_errors": tlog.write_errors} if tlog is not None else None),
            "hover_estimates": {str(vid): dataclasses.asdict(e)
                                for vid, e in fig.hover_estimates.items()},
            "go_to_start": {str(vid): {**dataclasses.asdict(r),
                                       "error_at_t0_m": fig.start_error_m.get(vid)}
                            for vid, r in self.machine.goto_results.items()},
            "events": self.machine.notes[-50:],
            "vehicle_kinds": [self.vehicle_kind(vid, vehicle_notes) for vid in self.ids],
            "statustext": self.statustexts(),
            # numba compiles during the flight (each stalled the tick while it ran)
            "compiled_after_ready": compiled_after_ready,
            **(more or {}),
        })
        report = build_report(log)
        write_report(out / REPORT_NAME, report)
        save_timeseries(log, out / TIMESERIES_NAME)
        if self.options.figures:
            from gcs.plots import write_figures

            write_figures(log, out, pairs=[(e.i, e.j) for e in self.team.graph.edges])
        return FlyResult(outcome, log, out, report)
