"""PX4-like autopilot logic of one vehicle: arming, modes, offboard rules, failsafes. Pure.

No clock, no I/O: every call takes ``now_s`` (the emulator's simulated time) and an
``Observation``; the result is a MAV_RESULT, the current ``demand`` (what the inner loops fly,
see plant.ControlMode) and queued ``events`` (STATUSTEXT lines) that the runner drains.

PX4 rules reproduced (recorded on PX4 v1.16.0 SITL; docs/emulator.md): custom_mode = main << 16 |
sub << 24; offboard is available while the newest setpoint is younger than COM_OF_LOSS_T (PX4's
offboardCheck.cpp: ``now < last_setpoint + COM_OF_LOSS_T``), so a single setpoint just before
DO_SET_MODE is enough (MAVSDK's ``set_attitude_rate`` then ``start``). Armed, OFFBOARD without one
is TEMPORARILY_REJECTED with "Switching to Offboard is currently not available"; disarmed, every
mode the emulator flies is accepted, OFFBOARD too, and arming in OFFBOARD without one is then
TEMPORARILY_REJECTED with "Arming denied: Resolve system health failures first". There is no
minimum stream duration or rate (PX4's docs ask for one; its code does not). Setpoint silence
> COM_OF_LOSS_T while armed leaves OFFBOARD ("Failsafe activated") and runs COM_OBL_RC_ACT; disarm
in the air is refused unless forced (21196); auto-disarm COM_DISARM_LAND after landing and
COM_DISARM_PRFLT after arming without takeoff.

Intended mode (PX4's ``user_intended_mode``): the mode last selected by a command (DO_SET_MODE,
SET_MODE, NAV_TAKEOFF, NAV_LAND; and Hold after a takeoff, which PX4's navigator selects itself).
Failsafes change the mode, not the intended mode. The mode after disarming (PX4's
``UserModeIntention::_nav_state_after_disarming``) is the last selected mode that allows arming:
Land and Takeoff never become it. After "Disarmed by landing" the vehicle is in that mode, so a
flight that ended OFFBOARD -> NAV_LAND sits disarmed in OFFBOARD (PX4 v1.16.0, 2026-12-04:
HEARTBEAT base_mode 1, custom_mode 393216), where arming is refused until a fresh setpoint
arrives and no ATTITUDE_TARGET is sent (``attitude_target_published``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from vehicle_emulator.autopilots.demand import (
    ActuatorSetpoint,
    AttitudeSetpoint,
    Demand,
    Idle,
    MavResult,
    MotorsOff,
    Observation,
    OffboardSetpoint,
    PositionTarget,
    RatesSetpoint,
    Severity,
    capture,
    climb,
    descent,
    hold,
)
from vehicle_emulator.autopilots.px4.modes import (
    MANUAL,
    MODE_NAMES,
    PREVENTS_ARMING,
    NavState,
    custom_mode_of,
    nav_state_of,
    not_emulated,
)
from vehicle_emulator.autopilots.px4.reports import Px4Reports
from vehicle_emulator.config.params import ParamStore

__all__ = [
    "ActuatorSetpoint",
    "AttitudeSetpoint",
    "Autopilot",
    "Demand",
    "MavResult",
    "NavState",
    "Observation",
    "PositionTarget",
    "RatesSetpoint",
    "Severity",
    "custom_mode_of",
    "nav_state_of",
    "not_emulated",
]

# PX4's wording (recorded, v1.16.0)
OFFBOARD_UNAVAILABLE_TEXT = "Switching to Offboard is currently not available"
ARMING_HEALTH_TEXT = "Arming denied: Resolve system health failures first"
FAILSAFE_TEXT = "Failsafe activated"
ALREADY_HIGHER_TEXT = "Already higher than takeoff altitude"  # PX4 navigator, takeoff.cpp
FORCE_MAGIC = 21196
TAKEOFF_DONE_M = 0.15




@dataclass(slots=True)
class Autopilot(Px4Reports):
    """One vehicle's mode/arming state machine. Call ``tick`` regularly (>= 10 Hz)."""

    vehicle_id: int
    params: ParamStore
    armed: bool = False
    nav_state: NavState = NavState.AUTO_LOITER
    intended_state: NavState = NavState.AUTO_LOITER  # last mode a command selected (see module)
    after_disarm_state: NavState = NavState.AUTO_LOITER  # last selected mode that allows arming
    demand: Demand = field(default_factory=MotorsOff)
    demand_version: int = 0
    events: list[tuple[Severity, str]] = field(default_factory=list)
    first_offboard_s: float | None = None
    setpoint: OffboardSetpoint | None = None
    home_enu_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    ready_s: float = 0.0  # arming is refused before this time (estimator not ready after boot)
    failsafe_active: bool = False  # a failsafe chose the mode; cleared by a mode command or disarm
    # nothing of PX4's falls due between ticks (ArduCopter's guided timeout does)
    deadline_s: float = math.inf
    _last_setpoint_s: float = -math.inf  # time of the newest offboard setpoint (-inf: none yet)
    _armed_s: float = 0.0
    _taken_off: bool = False
    _landed_since_s: float | None = None
    _takeoff_alt_m: float = 2.5
    _takeoff_climbing: bool = False

    # --- construction helpers ---------------------------------------------------------------

    @classmethod
    def start(
        cls,
        vehicle_id: int,
        params: ParamStore,
        now_s: float,
        obs: Observation,
        ready_after_s: float = 0.0,
    ) -> Autopilot:
        """A vehicle at boot: in the air -> armed, holding position (Hold); else disarmed, and
        unable to arm for ``ready_after_s`` (PX4 v1.16.0 SIH: 3.0 s after its first HEARTBEAT).
        """
        ap = cls(vehicle_id=vehicle_id, params=params)
        ap.ready_s = now_s + (ready_after_s if obs.on_ground else 0.0)
        ap.home_enu_m = (obs.position_enu_m[0], obs.position_enu_m[1], 0.0)
        if not obs.on_ground:
            ap.armed = True
            ap._taken_off = True
            ap._armed_s = now_s
        ap._set_demand(hold(ap.armed, obs))
        return ap

    # --- queries ------------------------------------------------------------------------------

    @property
    def custom_mode(self) -> int:
        """PX4 custom_mode for HEARTBEAT."""
        return custom_mode_of(self.nav_state)

    @property
    def mode_name(self) -> str:
        """Human name of the current mode (QGroundControl's wording)."""
        return MODE_NAMES[self.nav_state]

    def offboard_available(self, now_s: float) -> bool:
        """True while the newest setpoint is younger than COM_OF_LOSS_T (PX4's offboardCheck):
        OFFBOARD may then be entered while armed, or armed in."""
        return now_s - self._last_setpoint_s < self.params["COM_OF_LOSS_T"]

    # --- inputs -------------------------------------------------------------------------------

    def on_setpoint(self, now_s: float, setpoint: OffboardSetpoint) -> None:
        """A valid offboard setpoint arrived (already range-checked by the codec layer)."""
        self._last_setpoint_s = now_s
        self.setpoint = setpoint
        if self.nav_state is NavState.OFFBOARD and self.armed:
            self._set_demand(setpoint)

    def arm(self, now_s: float, obs: Observation, arm: bool, force: bool = False) -> MavResult:
        """MAV_CMD_COMPONENT_ARM_DISARM; PX4 pre-arm and in-air disarm rules."""
        if arm:
            if self.armed:
                return MavResult.ACCEPTED
            if not force:
                if obs.battery_remaining < 0.1:
                    return self._deny("Arming denied: battery low")
                if now_s < self.ready_s:  # recorded: three refusals in the first 3 s after boot
                    self._event(Severity.CRITICAL, ARMING_HEALTH_TEXT)
                    return MavResult.TEMPORARILY_REJECTED
                if self.nav_state is NavState.OFFBOARD and not self.offboard_available(now_s):
                    self._event(Severity.CRITICAL, ARMING_HEALTH_TEXT)
                    return MavResult.TEMPORARILY_REJECTED
                if not obs.on_ground:
                    return self._deny("Arming denied: not landed")
            self.armed = True
            self._armed_s = now_s
            self._taken_off = not obs.on_ground
            self._landed_since_s = None
            self._event(Severity.INFO, "Armed by external command")
            if self.nav_state is NavState.AUTO_TAKEOFF:
                self._begin_takeoff(obs, self._takeoff_alt_m)
            else:
                self._set_demand(self._mode_demand(obs))
            return MavResult.ACCEPTED
        if not self.armed:
            return MavResult.ACCEPTED
        if not obs.on_ground and not force:
            return self._deny("Disarming denied: not landed")
        self._disarm("Disarmed by external command")
        return MavResult.ACCEPTED

    def set_mode(self, now_s: float, obs: Observation, main_mode: int, sub_mode: int) -> MavResult:
        """DO_SET_MODE / SET_MODE with PX4 custom main and sub modes; an accepted mode is also the
        intended mode. OFFBOARD needs a recent setpoint only when armed (PX4 v1.16.0)."""
        if not_emulated(main_mode, sub_mode):
            self._event(Severity.CRITICAL, f"Mode main {main_mode} sub {sub_mode} not emulated")
            return MavResult.UNSUPPORTED
        target = nav_state_of(main_mode, sub_mode)
        if target is None:
            return self._deny(f"Mode change denied: main {main_mode} sub {sub_mode} not available")
        if target is NavState.OFFBOARD:
            if self.armed and not self.offboard_available(now_s):
                self._event(Severity.CRITICAL, OFFBOARD_UNAVAILABLE_TEXT)
                return MavResult.TEMPORARILY_REJECTED
            if self.first_offboard_s is None:
                self.first_offboard_s = now_s
        if target is NavState.AUTO_TAKEOFF:
            self._takeoff_alt_m = self.params["MIS_TAKEOFF_ALT"]
        self._select(target)
        self.failsafe_active = False
        self._enter(target, obs)
        return MavResult.ACCEPTED

    def takeoff(self, now_s: float, obs: Observation, altitude_above_ground_m: float) -> MavResult:
        """MAV_CMD_NAV_TAKEOFF: climb to the altitude (MIS_TAKEOFF_ALT if not finite/positive)."""
        alt = altitude_above_ground_m
        if not math.isfinite(alt) or alt < 0.5:
            alt = self.params["MIS_TAKEOFF_ALT"]
        self._takeoff_alt_m = alt
        self.nav_state = NavState.AUTO_TAKEOFF
        self._select(NavState.AUTO_TAKEOFF)
        self.failsafe_active = False
        self._event(Severity.INFO, f"Takeoff to {alt:.1f} m")
        if self.armed:
            self._begin_takeoff(obs, alt)
        return MavResult.ACCEPTED

    def land(self, now_s: float, obs: Observation) -> MavResult:
        """MAV_CMD_NAV_LAND: descend at MPC_LAND_SPEED, then disarm. A user mode selection in PX4:
        Land becomes the intended mode, but not the mode after disarming (Land prevents arming),
        so after the landing the vehicle returns to the mode selected before it."""
        self._select(NavState.AUTO_LAND)
        self.failsafe_active = False
        self._enter(NavState.AUTO_LAND, obs)
        return MavResult.ACCEPTED

    def tick(self, now_s: float, obs: Observation) -> None:
        """Failsafes and mode progress: offboard loss (armed only: PX4 v1.16.0 stayed in OFFBOARD
        disarmed with no setpoint), takeoff done, landing, auto-disarm."""
        if not self.armed:
            return
        if self.nav_state is NavState.OFFBOARD:
            loss_s = self.params["COM_OF_LOSS_T"]
            if now_s - self._last_setpoint_s > loss_s:
                self._offboard_lost(obs)
                if not self.armed:  # COM_OBL_RC_ACT 7
                    return
        if not obs.on_ground:
            self._taken_off = True
            self._landed_since_s = None
        elif self._landed_since_s is None:
            self._landed_since_s = now_s
            if self._taken_off:
                self._event(Severity.INFO, "Landing detected")
        if self.nav_state is NavState.AUTO_TAKEOFF and self._takeoff_climbing:
            self._takeoff_progress(obs)
        if obs.on_ground and self.nav_state is not NavState.OFFBOARD:
            climbing = self.nav_state is NavState.AUTO_TAKEOFF and self._takeoff_climbing
            if not climbing and not isinstance(self.demand, Idle):
                self._set_demand(Idle())
        if self._landed_since_s is not None:
            on_ground_s = now_s - self._landed_since_s
            if self._taken_off:
                limit = self.params["COM_DISARM_LAND"]
                if limit >= 0.0 and on_ground_s > limit:
                    self._disarm("Disarmed by landing")
                    self._resume_after_disarm(obs)
            else:
                limit = self.params["COM_DISARM_PRFLT"]
                if limit >= 0.0 and now_s - self._armed_s > limit:
                    self._disarm("Disarmed: no takeoff after arming")

    # --- internals ----------------------------------------------------------------------------

    def _event(self, severity: Severity, text: str) -> None:
        self.events.append((severity, text))

    def _deny(self, text: str) -> MavResult:
        self._event(Severity.CRITICAL, text)
        return MavResult.DENIED

    def _set_demand(self, demand: Demand) -> None:
        self.demand = demand
        self.demand_version += 1

    def _disarm(self, text: str) -> None:
        self.armed = False
        self.failsafe_active = False
        self._takeoff_climbing = False
        self._landed_since_s = None
        self._event(Severity.INFO, text)
        self._set_demand(MotorsOff())

    def _select(self, target: NavState) -> None:
        """A user's mode selection: the intended mode, and the mode after disarming unless the
        mode prevents arming (PX4's UserModeIntention::change)."""
        self.intended_state = target
        if target not in PREVENTS_ARMING:
            self.after_disarm_state = target

    def _resume_after_disarm(self, obs: Observation) -> None:
        """After "Disarmed by landing": the mode after disarming becomes the intended and the
        current mode (PX4's UserModeIntention::onDisarm; v1.16.0 recorded OFFBOARD, base_mode 1,
        after both a failsafe landing and a NAV_LAND from OFFBOARD)."""
        self.intended_state = self.after_disarm_state
        self._enter(self.after_disarm_state, obs)

    def _mode_demand(self, obs: Observation) -> Demand:
        if not self.armed:
            return MotorsOff()
        if self.nav_state is NavState.OFFBOARD:
            return self.setpoint if self.setpoint is not None else hold(self.armed, obs)
        if self.nav_state is NavState.AUTO_LAND:
            return descent(obs, self.params["MPC_LAND_SPEED"])
        if self.nav_state in MANUAL and self.params.get_int("COM_RC_IN_MODE") == 4:
            # no manual control input: PX4 reads the throttle stick as full down
            return descent(obs, self.params["MPC_Z_VEL_MAX_DN"])
        return hold(self.armed, obs)

    def _enter(self, target: NavState, obs: Observation) -> None:
        if target is not self.nav_state:
            self._event(Severity.INFO, f"Mode: {MODE_NAMES[target]}")
        self.nav_state = target
        self._takeoff_climbing = False
        if target is NavState.AUTO_TAKEOFF and self.armed:
            self._begin_takeoff(obs, self._takeoff_alt_m)
        else:
            self._set_demand(self._mode_demand(obs))

    def _begin_takeoff(self, obs: Observation, alt_m: float) -> None:
        """PX4's navigator never descends to a takeoff altitude: above it, it keeps its own."""
        if obs.position_enu_m[2] > alt_m:
            alt_m = self._takeoff_alt_m = obs.position_enu_m[2]
            self._event(Severity.CRITICAL, ALREADY_HIGHER_TEXT)
        self._takeoff_climbing = True
        self._set_demand(climb(obs, alt_m, self.params["MPC_TKO_SPEED"]))

    def _takeoff_progress(self, obs: Observation) -> None:
        """Climb at MPC_TKO_SPEED, then let the position loop (gain 1/s) capture the altitude
        from ``speed / 1 s`` below it; Hold once within TAKEOFF_DONE_M."""
        z = obs.position_enu_m[2]
        alt = self._takeoff_alt_m
        demand = self.demand
        if isinstance(demand, PositionTarget) and demand.mask[2] == 0.0:
            if z >= alt - self.params["MPC_TKO_SPEED"]:
                self._set_demand(capture(demand, alt))
        elif z >= alt - TAKEOFF_DONE_M:
            self._takeoff_climbing = False
            self._event(Severity.INFO, "Takeoff complete, holding")
            # PX4's navigator selects Hold itself: the intended mode follows (CURRENT_MODE, v1.16.0)
            self.nav_state = NavState.AUTO_LOITER
            self._select(NavState.AUTO_LOITER)

    def _offboard_lost(self, obs: Observation) -> None:
        """COM_OBL_RC_ACT; PX4's STATUSTEXT, then the emulator's "Mode: ..." line names the
        action. The intended mode stays OFFBOARD."""
        action = self.params.get_int("COM_OBL_RC_ACT")
        self._event(Severity.CRITICAL, FAILSAFE_TEXT)
        self.failsafe_active = True
        if action in (3, 4):
            target = NavState.AUTO_LAND
        elif action == 7:
            self.nav_state = NavState.AUTO_LOITER
            self._disarm("Disarmed by failsafe")
            return
        elif action == 0:
            target = NavState.POSCTL
        elif action == 1:
            target = NavState.ALTCTL
        else:
            target = NavState.AUTO_LOITER
        self._enter(target, obs)
