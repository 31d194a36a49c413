"""ArduCopter-like autopilot logic of one vehicle: boot, arming, modes, guided targets. Pure.

The same interface as ``autopilot.Autopilot`` (``start``, ``arm``, ``set_mode``, ``takeoff``,
``land``, ``tick``, ``demand``/``demand_version``, ``events``), for the ``ardupilot``
personality: ArduCopter 4.7.0-dev SITL as recorded (docs/emulator.md,
"ArduPilot personality"). No clock, no I/O: ``now_s`` is the emulator's simulated time since start.

* Modes: ``custom_mode`` is the mode number (``Mode``). Disarmed, every mode the emulator flies is
  accepted (ArduPilot skips its checks then); armed, a mode that needs a position estimate is
  refused until the EKF has one. The modes with pilot input (STABILIZE, ALT_HOLD, LOITER, POSHOLD)
  see SITL's default RC: throttle stick low, other sticks centred.
* Boot (``BootTimeline``, scaled by EMU_BOOT_SCALE): "Arm: System not initialised", then accel,
  gyro and EKF reasons, ready in STABILIZE at 23.6 s; EKF origin at 20.03 s (HOME_POSITION and
  GPS_GLOBAL_ORIGIN), position estimate at 41.63 s ("Arm: Need Position Estimate" before it in
  the modes that need one). A vehicle that starts in the air is past boot (GUIDED, holding).
* Arming: one COMMAND_ACK, FAILED with an "Arm: <reason>" STATUSTEXT per failed check; "<MODE>
  mode not armable" (LAND, BRAKE, RTL, ...); 2989 forces (mandatory checks stay); disarm in the
  air refused unless forced (21196). DISARM_DELAY after landing or arming without takeoff.
* GUIDED: NAV_TAKEOFF to a relative altitude (spool-up, then a climb limited by WPNAV_SPEED_UP
  and WPNAV_ACCEL_Z), then holds; position/velocity targets (``on_position_target``) flown by the
  onboard position controller; a velocity target lasts GUID_TIMEOUT. LAND descends at
  LAND_SPEED, disarms 0.5 s after the land detector (1.6 s after touchdown) and stays in LAND.
* Guided attitude targets (``on_attitude_target``), in GUIDED and GUIDED_NOGPS only: used for
  exactly GUID_TIMEOUT after arrival, then level attitude and altitude hold, mode unchanged, no
  STATUSTEXT. GUID_OPTIONS bit 3 (8): thrust is normalised thrust (echoed in ATTITUDE_TARGET),
  else a climb rate (0.5 holds, 1 climbs at WPNAV_SPEED_UP, 0 descends at WPNAV_SPEED_DN).
  Altitude hold and climb rates are flown by a vertical-speed loop at the autopilot rate.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from vehicle_emulator.autopilots.ardupilot.boot import PAST_BOOT, BootTimeline
from vehicle_emulator.autopilots.ardupilot.flight import (
    LAND_DETECT_S,
    LAND_DISARM_S,
    MAX_TICK_DT_S,
    STOPPED_MPS,
    AngleTarget,
    CopterFlight,
)
from vehicle_emulator.autopilots.ardupilot.modes import (
    ARMABLE,
    FLOWN,
    GUIDED_MODES,
    NEEDS_POSITION,
    Mode,
)
from vehicle_emulator.autopilots.ardupilot.reports import CopterReports
from vehicle_emulator.autopilots.demand import (
    Demand,
    Idle,
    MavResult,
    MotorsOff,
    Observation,
    PositionTarget,
    Severity,
)
from vehicle_emulator.config.params import ParamStore

__all__ = ["ArduCopter", "CopterObservation"]

FORCE_ARM_MAGIC = 2989
FORCE_DISARM_MAGIC = 21196
MSG_HOME_POSITION = 242
MSG_GPS_GLOBAL_ORIGIN = 49


@dataclass(frozen=True, slots=True)
class CopterObservation(Observation):
    """Observation plus the cosine of the tilt (body z against up), for angle boost."""

    tilt_cos: float = 1.0


@dataclass(slots=True)
class ArduCopter(CopterFlight, CopterReports):
    """One vehicle's ArduCopter-like state machine. Call ``tick`` regularly (>= 10 Hz)."""

    vehicle_id: int
    params: ParamStore
    boot: BootTimeline = field(default_factory=BootTimeline)
    armed: bool = False
    mode: Mode = Mode.STABILIZE
    demand: Demand = field(default_factory=MotorsOff)
    demand_version: int = 0
    events: list[tuple[Severity, str]] = field(default_factory=list)
    requests: list[int] = field(default_factory=list)  # msgids to send now (HOME, ORIGIN)
    first_offboard_s: float | None = None  # first GUIDED_NOGPS entry (the fault clock)
    setpoint: AngleTarget | None = None
    home_enu_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    land_complete: bool = True
    auto_armed: bool = False
    angle_control: bool = False  # guided angle submode (GUIDED_NOGPS, or GUIDED after one)
    guided_timeouts: int = 0  # attitude targets that expired (GUID_TIMEOUT) while flown
    deadline_s: float = math.inf  # when a guided target expires (``expire``); inf: none pending
    _setpoint_s: float = -math.inf
    _expiry_counted: bool = True
    _velocity_target_s: float | None = None  # GUIDED velocity target: its arrival
    _taking_off: str = ""  # "" | "spool" | "climb"
    _takeoff_started_s: float = 0.0
    _takeoff_from_m: float = 0.0
    _takeoff_alt_m: float = 0.0
    _ground_since_s: float | None = None
    _landed_since_s: float | None = None
    _z_ref_m: float | None = None
    _vz_int: float = 0.0
    _braking: bool = False
    _texts_done: int = 0
    _origin_sent: bool = False
    _next_prearm_s: float = 0.0
    _tick_s: float | None = None  # the previous tick's time

    # --- construction ---------------------------------------------------------------------------

    @classmethod
    def start(
        cls, vehicle_id: int, params: ParamStore, now_s: float, obs: Observation,
        ready_after_s: float = 0.0,
    ) -> ArduCopter:
        """At boot on the ground: disarmed in STABILIZE, the boot timeline ahead (EMU_BOOT_SCALE;
        ``ready_after_s``, the personality's single readiness time, is PX4's, unused here).
        In the air: past boot, armed in GUIDED, holding its position."""
        ap = cls(vehicle_id, params, BootTimeline(params["EMU_BOOT_SCALE"]))
        ap.home_enu_m = (obs.position_enu_m[0], obs.position_enu_m[1], 0.0)
        ap._next_prearm_s = ap.boot.at(BootTimeline.PREARM_FIRST_S)
        if not obs.on_ground:
            ap.boot = PAST_BOOT
            ap._texts_done = len(BootTimeline.TEXTS)
            ap._origin_sent = True
            ap.armed = ap.auto_armed = True
            ap.land_complete = False
            ap.mode = Mode.GUIDED
            ap._set(ap._position_hold(obs))
        return ap

    # --- queries -------------------------------------------------------------------------------

    @property
    def nav_state(self) -> Mode:
        """The current mode (the name the PX4 state machine uses)."""
        return self.mode

    @property
    def custom_mode(self) -> int:
        """HEARTBEAT custom_mode: the mode number."""
        return int(self.mode)

    @property
    def mode_name(self) -> str:
        return self.mode.name

    def setpoint_driven(self) -> bool:
        """Armed and flying guided attitude targets (lockstep follows these vehicles)."""
        return self.armed and self.angle_control and self.mode in GUIDED_MODES

    # --- commands ------------------------------------------------------------------------------

    def arm(self, now_s: float, obs: Observation, arm: bool, magic: int = 0) -> MavResult:
        """COMPONENT_ARM_DISARM: FAILED with an "Arm: ..." text per failed check."""
        if arm:
            if self.armed:
                return MavResult.ACCEPTED
            failures = self.arm_failures(now_s, forced=magic == FORCE_ARM_MAGIC)
            if failures:
                for reason in failures:
                    self._event(Severity.CRITICAL, f"Arm: {reason}")
                return MavResult.FAILED
            self.armed = True
            self.auto_armed = not obs.on_ground
            self._landed_since_s = now_s if self.land_complete else None
            self.home_enu_m = (obs.position_enu_m[0], obs.position_enu_m[1], 0.0)
            if self.boot.origin_set(now_s):
                self.requests += [MSG_GPS_GLOBAL_ORIGIN, MSG_HOME_POSITION]
            self._event(Severity.INFO, "Arming motors")
            self._enter(self.mode, now_s, obs)
            return MavResult.ACCEPTED
        if not self.armed:
            return MavResult.ACCEPTED
        if not self.land_complete and magic != FORCE_DISARM_MAGIC:
            return MavResult.FAILED  # ArduPilot: no text
        self._disarm()
        return MavResult.ACCEPTED

    def arm_failures(self, now_s: float, forced: bool = False, mode_check: bool = True
                     ) -> list[str]:
        """Reasons an arming attempt would fail now (without "Arm: "); [] if it would arm.
        ``mode_check=False``: the pre-arm checks only."""
        out = [] if self.boot.initialised(now_s) else ["System not initialised"]
        if not out and not forced and self.params.get_int("ARMING_CHECK") != 0:
            out = self.boot.sensor_reasons(now_s)
        if self.mode in NEEDS_POSITION and not self.position_ok(now_s):
            out.append("Need Position Estimate")  # mandatory, even forced
        if not out and not forced and mode_check and self.mode not in ARMABLE:
            out.append(f"{self.mode.name} mode not armable")
        return out

    def set_mode(self, now_s: float, obs: Observation, number: int) -> MavResult:
        """DO_SET_MODE / SET_MODE with an ArduCopter mode number. Disarmed: accepted for every
        mode the emulator flies (no checks); armed: a mode that needs a position estimate is
        refused without one. A mode the emulator does not fly is refused (FAILED)."""
        try:
            target = Mode(number)
        except ValueError:
            self._event(Severity.WARNING, f"No such mode {number}")
            return MavResult.FAILED
        if target not in FLOWN:
            self._event(Severity.WARNING, f"Mode change to {target.name} failed: not emulated")
            return MavResult.FAILED
        if self.armed and target in NEEDS_POSITION and not self.position_ok(now_s):
            self._event(Severity.WARNING, f"Mode change to {target.name} failed: requires position")
            return MavResult.FAILED
        if target is self.mode:
            return MavResult.ACCEPTED
        if target is Mode.GUIDED_NOGPS and self.first_offboard_s is None:
            self.first_offboard_s = now_s
        self.mode = target
        self._enter(target, now_s, obs)
        return MavResult.ACCEPTED

    def takeoff(self, now_s: float, obs: Observation, altitude_rel_m: float) -> MavResult:
        """NAV_TAKEOFF in GUIDED (param7 above home): armed, landed, above the ground; after
        TAKEOFF_SPOOL_S it climbs, then holds the altitude in GUIDED."""
        alt = altitude_rel_m
        if (not self.armed or not self.land_complete or self.mode is not Mode.GUIDED
                or not math.isfinite(alt) or alt <= obs.position_enu_m[2] - self.home_enu_m[2]):
            return MavResult.FAILED
        self.auto_armed = True
        self.angle_control = False
        self._taking_off = "spool"
        self._takeoff_started_s = now_s
        self._takeoff_from_m = obs.position_enu_m[2]
        self._takeoff_alt_m = self.home_enu_m[2] + alt
        self._set(Idle())
        return MavResult.ACCEPTED

    def land(self, now_s: float, obs: Observation) -> MavResult:
        """MAV_CMD_NAV_LAND: the LAND mode."""
        return self.set_mode(now_s, obs, Mode.LAND)

    # --- the tick ------------------------------------------------------------------------------

    def tick(self, now_s: float, obs: Observation) -> None:
        """Boot timeline, takeoff, land detector, auto-disarm, timeouts, the vertical loop (which
        integrates over the time since the previous tick, at most MAX_TICK_DT_S)."""
        dt_s = 0.0 if self._tick_s is None else min(max(now_s - self._tick_s, 0.0), MAX_TICK_DT_S)
        self._tick_s = now_s
        self._boot_progress(now_s)
        self._land_detector(now_s, obs)
        if not self.armed:
            self._prearm_report(now_s)
            return
        if self._taking_off:
            self._takeoff_progress(now_s, obs)
        elif self.angle_control and self.mode in GUIDED_MODES:
            self._fly_angle(now_s, obs, dt_s)
        elif self._velocity_target_expired(now_s):
            self._stop_guided(obs)
        elif self._braking and math.hypot(*obs.velocity_enu_mps[:2]) < STOPPED_MPS:
            self._braking = False
            self._set(self._position_hold(obs))
        elif self.mode is Mode.ALT_HOLD and not self.land_complete:
            self._set(self._level_climb(obs, -self._pilot_down_mps(), dt_s))
        elif self.mode is Mode.LAND:
            self._land_speed_update(obs)
        if self.land_complete and not self._taking_off:
            angle = self.angle_control and self.mode in GUIDED_MODES
            if not angle and not isinstance(self.demand, Idle):
                self._set(Idle())  # every mode idles a landed vehicle (the angle mode decides)
            since = self._landed_since_s if self._landed_since_s is not None else now_s
            landed_s = now_s - since
            land_done = self.mode is Mode.LAND and landed_s >= LAND_DISARM_S
            if land_done or 0 < self.params["DISARM_DELAY"] <= landed_s:
                self._disarm()

    # --- internals -----------------------------------------------------------------------------

    def _event(self, severity: Severity, text: str) -> None:
        self.events.append((severity, text))

    def _set(self, demand: Demand) -> None:
        self.demand = demand
        self.demand_version += 1

    def _disarm(self) -> None:
        self.armed = self.auto_armed = False
        self.angle_control = False
        self._taking_off = ""
        self._velocity_target_s = None
        self._event(Severity.INFO, "Disarming motors")
        self._set(MotorsOff())

    def _grounded(self) -> bool:
        """ArduPilot's is_disarmed_or_landed: the mode's controllers idle the motors."""
        return not self.armed or not self.auto_armed or self.land_complete

    def _boot_progress(self, now_s: float) -> None:
        texts = BootTimeline.TEXTS
        while self._texts_done < len(texts) and now_s >= self.boot.at(texts[self._texts_done][0]):
            self._event(Severity.INFO, texts[self._texts_done][1])
            self._texts_done += 1
        if not self._origin_sent and self.boot.origin_set(now_s):
            self._origin_sent = True
            self.requests += [MSG_GPS_GLOBAL_ORIGIN, MSG_HOME_POSITION]

    def _prearm_report(self, now_s: float) -> None:
        """Every 30 s while disarmed (first at 29.46 s of the boot timeline): "PreArm: <first
        reason>" if a pre-arm check fails (the mode check is an arming check, not one)."""
        if now_s < self._next_prearm_s:
            return
        self._next_prearm_s = now_s + BootTimeline.PREARM_PERIOD_S
        failures = self.arm_failures(now_s, mode_check=False)
        if failures and self.boot.initialised(now_s):
            self._event(Severity.CRITICAL, f"PreArm: {failures[0]}")

    def _land_detector(self, now_s: float, obs: Observation) -> None:
        if not obs.on_ground:
            self._ground_since_s = None
            if self.land_complete and self._taking_off != "spool":
                self.land_complete = False
                self._landed_since_s = None
            return
        if self._ground_since_s is None:
            self._ground_since_s = now_s
        if (not self.land_complete and self._taking_off != "climb"
                and now_s - self._ground_since_s >= LAND_DETECT_S):
            self.land_complete = True
            self._landed_since_s = now_s
            self._taking_off = ""
            self.angle_control = self.mode is Mode.GUIDED_NOGPS

    def _enter(self, mode: Mode, now_s: float, obs: Observation) -> None:
        """A mode's start: its demand now (armed) or motors off."""
        self._taking_off = ""
        self._velocity_target_s = None
        self._braking = False
        self.angle_control = mode is Mode.GUIDED_NOGPS
        if mode is Mode.GUIDED_NOGPS:
            self.setpoint = None  # ArduPilot's angle_control_start: level, climb rate 0
            self._setpoint_s = -math.inf
            self._expiry_counted = True
            self._z_ref_m = obs.position_enu_m[2]
            self._vz_int = 0.0
        if not self.armed:
            self._set(MotorsOff())
        elif self.land_complete:
            self._set(Idle())
        elif mode is Mode.GUIDED_NOGPS:
            self._fly_angle(now_s, obs, 0.0)
        elif mode is Mode.STABILIZE:
            self._set(Idle())  # throttle stick low: the motors idle in the air too
        elif mode is Mode.ALT_HOLD:
            self._z_ref_m = obs.position_enu_m[2]
            self._set(self._level_climb(obs, -self._pilot_down_mps(), 0.0))
        elif mode in (Mode.LOITER, Mode.POSHOLD):
            self._set(PositionTarget(obs.position_enu_m, (0.0, 0.0, -self._pilot_down_mps()),
                                     (1.0, 1.0, 0.0), obs.yaw_enu_rad))
        elif mode is Mode.LAND:
            self._set(PositionTarget(obs.position_enu_m, (0.0, 0.0, -self._land_speed_mps(obs)),
                                     (1.0, 1.0, 0.0), obs.yaw_enu_rad))
        else:  # GUIDED, BRAKE: stop, then hold
            self._stop_guided(obs)

    def _stop_guided(self, obs: Observation) -> None:
        """Decelerate to zero velocity holding the altitude, then hold the position."""
        self.angle_control = self.mode is Mode.GUIDED_NOGPS
        self._velocity_target_s = None
        if self._grounded():
            return
        self._braking = True
        self._set(PositionTarget(obs.position_enu_m, (0.0, 0.0, 0.0), (0.0, 0.0, 1.0),
                                 obs.yaw_enu_rad))

    @staticmethod
    def _position_hold(obs: Observation) -> PositionTarget:
        return PositionTarget(obs.position_enu_m, yaw_enu_rad=obs.yaw_enu_rad)
