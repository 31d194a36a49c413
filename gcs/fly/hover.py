"""mhat(0) from the hover (`estimates.mhat: from_hover`): the thrust each vehicle reports
while it holds before the formation, turned into its initial mass estimate at t = 0."""

from __future__ import annotations

import logging

import numpy as np

from gcs.control.law import TeamLaw
from gcs.control.position import phi
from gcs.fly.measure import (
    HOVER_MIN_SAMPLES,
    HOVER_WINDOW_S,
    HoverEstimate,
    HoverThrust,
    TeamSample,
)
from gcs.fly.setup import FlightSetup
from gcs.link import HotTable, VehicleProxy, fastpath
from gcs.link.samples import AttitudeTarget
from gcs.mission.machine import MissionMachine

logger = logging.getLogger("gcs.fly")


class HoverStart:
    """mhat(0) from the hover (`estimates.mhat: from_hover`): the thrust each such vehicle
    reports while it holds in PRIME (`record`), turned into its initial mass estimate at the
    formation start (`initial_mass`)."""

    def __init__(self, setup: FlightSetup, machine: MissionMachine, law: TeamLaw, hot: HotTable,
                 proxies: list[VehicleProxy], estimates: dict[int, HoverEstimate],
                 law_rows: np.ndarray | None = None) -> None:
        self.setup = setup
        # the law's row of each vehicle of the flight (an agent's law has its neighbours' too)
        self.law_rows = np.arange(setup.team.n) if law_rows is None else law_rows
        self.team = setup.team
        self.machine = machine
        self.law = law
        self.hot = hot
        self.proxies = proxies  # the team's, in team order once the links are open
        self.thrust = HoverThrust(setup.team.n)
        self.estimates = estimates  # vehicle id -> its estimate (the records')

    def record(self) -> None:
        """PRIME: the vehicles hold on their own; keep the thrust they report (from_hover)."""
        hot = self.hot
        for i, (v, p) in enumerate(zip(self.team.vehicles, self.proxies, strict=True)):
            if not v.estimates.from_hover:
                continue
            if p.slot == i and hot.count[i, fastpath.ATTITUDE_TARGET] > 0:  # no decode per tick
                self.thrust.add(i, float(hot.rx_s[i, fastpath.ATTITUDE_TARGET]),
                                float(hot.misc[i, fastpath.TARGET_THRUST]))
            elif (at := p.sample(AttitudeTarget)) is not None:
                self.thrust.add(i, at.rx_time_s, at.thrust)

    def initial_mass(self, sample: TeamSample, now_s: float) -> bool:
        """At the formation start: mhat_i(0) from the hover of each `mhat: from_hover` vehicle,
        checked against Proposition 2; False (and the flight stops) when one cannot be taken
        or fails the check."""
        if self.setup.law != "adaptive":
            return True
        g = self.setup.gains
        phi0_all = phi(np.ascontiguousarray(sample.velocity_mps), g.sigma_a,
                        g.phi_horizontal)  # the law's (23)
        for i, v in enumerate(self.team.vehicles):
            if not v.estimates.from_hover:
                continue
            name = f"vehicle {v.id} (sysid {v.sysid})"
            phi0 = float(phi0_all[i])
            est = self.thrust.estimate(i, now_s, v.airframe.max_thrust_n, g.alpha_m, phi0,
                                       v.mass_bound_kg)
            if est is None:
                self.machine.request_abort(
                    f"{name}: no hover thrust to take mhat(0) from (fewer than "
                    f"{HOVER_MIN_SAMPLES} ATTITUDE_TARGET in the {HOVER_WINDOW_S:g} s before the "
                    "formation start)", operator=False)
                return False
            self.estimates[v.id] = est
            bound = ("no mass_bound_kg" if est.least_mhat0 is None else
                     f"Proposition 2: mhat(0) >= (phi(0) - 1) mbar / alpha_m = "
                     f"{est.least_mhat0:.4g} {'holds' if est.proposition2_holds else 'FAILS'}")
            logger.info("%s: hover thrust %.4f (%d samples) -> %.4g kg, mhat(0) %.4g; %s", name,
                        est.thrust_norm, est.samples, est.mass_kg, est.mhat0, bound)
            if not est.proposition2_holds:
                self.machine.request_abort(
                    f"{name}: mhat(0) {est.mhat0:.4g} from the hover ({est.mass_kg:.4g} kg) is "
                    f"below Proposition 2's {est.least_mhat0:.4g} (mass_bound_kg "
                    f"{v.mass_bound_kg:g})", operator=False)
                return False
            self.law.mhat[self.law_rows[i]] = est.mhat0
        return True
