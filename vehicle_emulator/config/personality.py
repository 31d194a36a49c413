"""Autopilot personalities: what makes an emulated vehicle behave like PX4, ArduPilot or the
paper's nominal model, where a ground station can notice.

A personality is chosen per vehicle (team file ``emulator.autopilot`` or
``vehicles[].emulator.autopilot``; ``vehicle-emu --autopilot`` overrides both). It bundles

* ``protocol``: the MAVLink face (HEARTBEAT autopilot type, reported firmware version, which
  setpoint messages are honoured, the ACK pattern, arming readiness after boot, whether the local
  frame is the vehicle's own EKF origin);
* ``dynamics``: the onboard inner loops as fitted to the recorded SITL responses (docs/emulator.md,
  "Calibration");
* ``sensors``: telemetry noise as fitted to the recorded hover.

``nominal`` is not an autopilot: it is the paper's nominal model behind PX4's protocol as of
v1.13 (actuator setpoints honoured), with noise-free telemetry, stiff inner loops and the team's
shared origin, for reproducing the paper's figures over MAVLink. ``px4`` (the default) is PX4
v1.16.0 SITL (SIH) as recorded; ``ardupilot`` is ArduCopter 4.7.0-dev SITL as recorded.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import IntEnum

__all__ = [
    "AUTOPILOT_NAMES",
    "DEFAULT_AUTOPILOT",
    "Dynamics",
    "PERSONALITIES",
    "Personality",
    "Protocol",
    "RateLoop",
    "Sensors",
    "personality_of",
]

MAV_AUTOPILOT_ARDUPILOTMEGA = 3
MAV_AUTOPILOT_PX4 = 12


@dataclass(frozen=True, slots=True)
class Protocol:
    """The MAVLink face of an autopilot."""

    family: str  # "px4" | "ardupilot": which mode table and command rules apply
    mav_autopilot: int  # HEARTBEAT.autopilot
    version: tuple[int, int, int]  # AUTOPILOT_VERSION.flight_sw_version (major, minor, patch)
    actuator_setpoints: bool  # SET_ACTUATOR_CONTROL_TARGET honoured (PX4 <= 1.13 only)
    ack_twice: bool  # default of EMU_ACK_TWICE (PX4 v1.16.0 answers DO_SET_MODE twice)
    arming_ready_s: float  # a vehicle booted on the ground refuses to arm before this [s]
    own_origin: bool  # LOCAL_POSITION_NED relative to the vehicle's own EKF origin
    param_defaults: tuple[tuple[str, float], ...] = ()  # parameter defaults as recorded
    statustext_end: str = ""  # appended to every STATUSTEXT (PX4 v1.16.0 ends each in a TAB)
    # appended to each TIMESYNC reply's payload: PX4 v1.16.0 sends the newer TIMESYNC, whose
    # target_system/target_component it leaves unset (recorded: b8 34 in 132 of 162 replies)
    timesync_reply_targets: bytes = b""

    @property
    def version_word(self) -> int:
        """AUTOPILOT_VERSION.flight_sw_version: major << 24 | minor << 16 | patch << 8 | 255
        (255: release build)."""
        major, minor, patch = self.version
        return (major << 24) | (minor << 16) | (patch << 8) | 255


class RateLoop(IntEnum):
    """Which onboard rate loop a vehicle flies (the plant kernel branches on it)."""

    NOMINAL = 0  # the paper's stiff loop (inner.py rate_control): inertia-scaled PID, 1 kHz
    PX4 = 1  # PX4's RateControl in normalised torque on the filtered gyro (inner.py)
    REFERENCE = 2  # a fitted closed-loop reference model, tracked by a stiff loop (ArduPilot)


@dataclass(frozen=True, slots=True)
class Dynamics:
    """Onboard inner loops and airframe effects of a personality (docs/emulator.md,
    "Calibration"). Body axes FLU; per-axis tuples are (roll, pitch, yaw).

    The defaults are the nominal model exactly. The plant kernel gets these as per-vehicle
    arrays (plant.py); nothing here is looked at per physics step.
    """

    rate_loop: RateLoop = RateLoop.NOMINAL
    control_period_s: float = 0.001  # sensors and inner loops run this often (whole steps)
    # RateLoop.PX4: PX4's RateControl, gains in normalised torque per rad/s
    rate_p: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rate_i: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rate_d: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rate_int_limit: tuple[float, float, float] = (0.0, 0.0, 0.0)
    # angular acceleration per unit of normalised torque [rad/s^2] (multiplied by the
    # vehicle's own inertia in the kernel, so every airframe gets this response)
    accel_per_unit_radps2: tuple[float, float, float] = (0.0, 0.0, 0.0)
    dterm_cutoff_hz: float = 0.0  # IMU_DGYRO_CUTOFF: 2nd-order low pass of d(gyro)/dt
    yaw_torque_cutoff_hz: float = 0.0  # MC_YAW_TQ_CUTOFF: first-order low pass, yaw torque
    output_delay_periods: int = 0  # the loop's output reaches the motors this much later
    # RateLoop.REFERENCE: rate command -> acceleration limit -> gain -> 2nd order, plus an
    # angle-error feedback (the integral of shaped command minus measured rate)
    accel_max_radps2: tuple[float, float, float] = (0.0, 0.0, 0.0)
    ref_gain: tuple[float, float, float] = (1.0, 1.0, 1.0)
    ref_wn_radps: tuple[float, float, float] = (1.0, 1.0, 1.0)
    ref_zeta: tuple[float, float, float] = (1.0, 1.0, 1.0)
    angle_p: tuple[float, float, float] = (0.0, 0.0, 0.0)  # [1/s]
    ref_delay_periods: tuple[int, int, int] = (0, 0, 0)  # dead time before the 2nd order
    track_p: float = 40.0  # the stiff loop that makes the body follow the reference [1/s]
    track_i: float = 200.0  # [1/s^2]
    # airframe and actuators
    motor_time_constant_s: float | None = None  # None: the team file's value
    linear_drag_per_s: float = 0.0  # drag force -m k v, world frame (SIH_KDV / SIH_MASS)
    angular_damping_per_s: tuple[float, float, float] = (0.0, 0.0, 0.0)  # torque -J k w
    # process noise (EMU_NOISE = 1): an angular-acceleration disturbance, 1 sigma per axis
    # [rad/s^2], a new value every control period: white, or, on an axis with a resonance
    # frequency, white noise through a 2nd-order resonator (a limit cycle's narrow band)
    disturbance_std_radps2: tuple[float, float, float] = (0.0, 0.0, 0.0)
    disturbance_resonance_hz: tuple[float, float, float] = (0.0, 0.0, 0.0)  # 0: white
    disturbance_zeta: float = 0.05  # the resonator's damping ratio
    thrust_scale: float = 1.0  # collective thrust [N] = scale * normalised thrust * 4 f_max


@dataclass(frozen=True, slots=True)
class Sensors:
    """What a vehicle measures and reports.

    ``model`` False (nominal): telemetry is the true state, plus, with EMU_NOISE = 1, white
    noise of the ``telemetry_*`` sizes drawn per telemetry tick. ``model`` True: an IMU sample
    every control period with white noise (1 sigma per sample, with EMU_NOISE = 1), the gyro low
    pass the rate loop flies on (ATTITUDE rates report it), HIGHRES_IMU as the autopilot
    reports it, and estimates that carry their own sample times.
    """

    model: bool = False
    noise_default: bool = False  # EMU_NOISE at start
    telemetry_position_std_m: float = 0.01
    telemetry_velocity_std_mps: float = 0.02
    telemetry_attitude_std_rad: float = 0.002
    telemetry_gyro_std_radps: float = 0.003
    telemetry_accel_std_mps2: float = 0.05
    gyro_noise_std_radps: tuple[float, float, float] = (0.0, 0.0, 0.0)  # per sample, FLU axes
    accel_noise_std_mps2: tuple[float, float, float] = (0.0, 0.0, 0.0)
    gyro_noise_off_std_radps: float = 0.0  # every axis, with the motors off
    accel_noise_off_std_mps2: float = 0.0
    gyro_cutoff_hz: float = 0.0  # 2nd-order low pass the rate loop flies on (0: none)
    imu_filtered: bool = False  # HIGHRES_IMU: the filtered gyro and accel (else raw means)
    imu_average_samples: int = 1  # raw samples averaged into HIGHRES_IMU (1 or 2)
    accel_cutoff_hz: float = 0.0  # 2nd-order low pass of the accel when imu_filtered
    position_delay_periods: int = 0  # LOCAL_POSITION_NED is this many periods older
    # estimate errors (EMU_NOISE = 1): Gauss-Markov processes, 1 sigma, ENU/FLU; the position
    # error integrates the velocity error and decays with its own time constant. The attitude
    # errors are first order, or second order (two poles at 1/tau: autocorrelation
    # (1 + w/tau) exp(-w/tau) at lag w, smooth where a first-order one jumps) per axis
    attitude_error_std_rad: tuple[float, float, float] = (0.0, 0.0, 0.0)  # roll, pitch, yaw
    attitude_error_tau_s: tuple[float, float, float] = (1.0, 1.0, 1.0)
    attitude_error_order: tuple[int, int, int] = (1, 1, 1)
    # the heading error's size over a flight (EMU_NOISE = 1; heading_takeoff_s 0: the stationary
    # attitude_error_std_rad[2] throughout): from leaving the ground, heading_takeoff_factor
    # times it for heading_takeoff_s, then from it down to heading_floor_rad with time constant
    # heading_settle_s; heading_floor_rad on the ground. Each takeoff starts it again. It sizes
    # the process's input, so the error itself follows within the process's time constant
    heading_takeoff_factor: float = 1.0
    heading_takeoff_s: float = 0.0
    heading_settle_s: float = 1.0
    heading_floor_rad: float = 0.0
    # attitude estimate as a complementary filter, per body axis (0: off): it integrates the
    # raw gyro samples (noise included) and is pulled to the true attitude with this time
    # constant (tilt from the accelerometer and velocity fusion, heading from the magnetometer),
    # so its error is the gyro noise integrated and forgotten over tau
    gyro_integration_tau_s: tuple[float, float, float] = (0.0, 0.0, 0.0)
    # HIGHRES_IMU gyro bias the estimator removes (ATTITUDE rates and the rate loop do not see
    # it): a Gauss-Markov process per axis, 1 sigma [rad/s]
    gyro_bias_std_radps: tuple[float, float, float] = (0.0, 0.0, 0.0)
    gyro_bias_tau_s: float = 10.0
    velocity_error_std_mps: tuple[float, float, float] = (0.0, 0.0, 0.0)  # north, east, up
    velocity_error_tau_s: float = 1.0
    # a slow drift added to that velocity error, per axis (north, east, up; 1 sigma [m/s]):
    # a second first-order process, independent of the first
    velocity_drift_std_mps: tuple[float, float, float] = (0.0, 0.0, 0.0)
    velocity_drift_tau_s: float = 20.0
    position_error_tau_s: float = 1.0
    # the share of the velocity error the position estimate integrates: 1, the two agree; below
    # 1, the reported position moves by less than the reported velocity's error says
    velocity_error_in_position: float = 1.0
    # the autopilot's own position hold (Hold, takeoff, OFFBOARD position setpoints), airborne,
    # with EMU_NOISE = 1: the loop chases its setpoint plus a slow wander, a band-pass resonator
    # per axis (north, east, up; 1 sigma [m]) at ``hold_wander_hz`` with damping
    # ``hold_wander_zeta``; the vehicle and its estimate wander about the setpoint alike
    hold_wander_std_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    hold_wander_hz: float = 0.1
    hold_wander_zeta: float = 0.5


# PX4 v1.16.0 SITL with SIH (airframe 10040 sihsim_quadx), parameters as read back
# (the recording's parameter dump). SIH: square X, rotors at (+-L, +-L) with L =
# SIH_L_ROLL = SIH_L_PITCH = 0.2 m, SIH_T_MAX 5 N and SIH_Q_MAX 0.1 N m per rotor at full command,
# inertia SIH_IXX/IYY/IZZ 0.025/0.025/0.030 kg m^2. PX4's control allocation (pseudo-inverse of
# CA_ROTOR*, then normalised: roll and pitch columns to +-1/sqrt(2) for four rotors, yaw to +-1)
# turns a unit torque command into motor commands of +-0.7071 (roll, pitch) or +-1 (yaw), i.e.
# 4 * L * T_MAX / sqrt(2) = 2.83 N m and 4 * Q_MAX = 0.4 N m.
SIH_L_M, SIH_T_MAX_N, SIH_Q_MAX_NM = 0.2, 5.0, 0.1
SIH_INERTIA_KGM2 = (0.025, 0.025, 0.030)
PX4_ACCEL_PER_UNIT_RADPS2 = (
    4.0 * SIH_L_M * SIH_T_MAX_N / math.sqrt(2.0) / SIH_INERTIA_KGM2[0],
    4.0 * SIH_L_M * SIH_T_MAX_N / math.sqrt(2.0) / SIH_INERTIA_KGM2[1],
    4.0 * SIH_Q_MAX_NM / SIH_INERTIA_KGM2[2],
)
PX4_DYNAMICS = Dynamics(
    rate_loop=RateLoop.PX4,
    control_period_s=0.004,  # SIH lockstep: min(IMU_GYRO_RATEMAX 800, IMU_INTEG_RATE 250) Hz
    rate_p=(0.15, 0.15, 0.2),  # MC_ROLLRATE_P, MC_PITCHRATE_P, MC_YAWRATE_P (MC_*RATE_K 1)
    rate_i=(0.2, 0.2, 0.1),
    rate_d=(0.003, 0.003, 0.0),
    rate_int_limit=(0.3, 0.3, 0.3),  # MC_RR_INT_LIM, MC_PR_INT_LIM, MC_YR_INT_LIM
    accel_per_unit_radps2=PX4_ACCEL_PER_UNIT_RADPS2,
    dterm_cutoff_hz=30.0,  # IMU_DGYRO_CUTOFF
    yaw_torque_cutoff_hz=2.0,  # MC_YAW_TQ_CUTOFF
    output_delay_periods=1,  # lockstep: SIH reads the motor outputs at its next step
    motor_time_constant_s=0.05,  # SIH_T_TAU
    linear_drag_per_s=1.0,  # SIH_KDV 1 N/(m/s) on SIH_MASS 1 kg
    angular_damping_per_s=(1.0, 1.0, 0.025 / 0.030),  # SIH_KDW 0.025 N m/(rad/s) / inertia
)
PX4_SENSORS = Sensors(
    model=True,
    noise_default=True,
    gyro_noise_std_radps=(0.14, 0.07, 0.03),  # SIH, armed (thrust > 0), per 4 ms sample
    accel_noise_std_mps2=(0.5, 1.7, 1.4),
    gyro_noise_off_std_radps=0.01,  # SIH, disarmed (no thrust)
    accel_noise_off_std_mps2=0.1,
    gyro_cutoff_hz=40.0,  # IMU_GYRO_CUTOFF
    imu_filtered=False,
    imu_average_samples=2,  # HIGHRES_IMU: recorded std = SIH's / 1.37 (two-sample means)
    position_delay_periods=1,  # LOCAL_POSITION_NED timestamps 4 ms older than attitude's
    # EKF2's estimate wander (fitted stand-in, benchmarks/calibration/fit_emulator.py --fit; the
    # vertical one by hand, docs/emulator.md "What is not fitted"), kept out of the position as
    # SIH's is (benchmarks/calibration/fit_velocity_consistency.py), so the position error's time
    # constant has nothing to act on
    velocity_error_std_mps=(0.126, 0.126, 0.10),
    velocity_error_tau_s=1.5,  # recorded vz autocorrelation 0.72 at 0.5 s
    # plus a slow drift: SIH's reported position departs from its reported velocity's integral
    # almost in proportion to the window up to 5 s (D(1 s) 0.14-0.22 m, D(5 s) 0.61-0.70 m
    # hovering); the two parts give 0.13-0.16 and 0.48-0.74 m (fit_velocity_consistency.py), and
    # PX4's own position loop, which flies the drift, still holds as SIH does (bench_px4_hold.py)
    velocity_drift_std_mps=(0.10, 0.10, 0.10),
    velocity_drift_tau_s=10.0,
    position_error_tau_s=6.0,
    velocity_error_in_position=0.0,
    # PX4's position hold on SIH (OFFBOARD position setpoints, 2026-12-04 go-to-start recording,
    # four vehicles, 48 s each): 0.32-0.38 m RMS about the setpoint, 2 s means 0.26-0.31 m off
    # and drifting 0.12-0.13 m/s (medians), 10 s means 0.16-0.22 m off; this wander with the
    # velocity drift above gives four personality vehicles 0.34-0.36 m, 0.29-0.34 m,
    # 0.11-0.15 m/s and 0.18-0.27 m (fitted by hand, benchmarks/bench_px4_hold.py)
    hold_wander_std_m=(0.135, 0.21, 0.10),
    hold_wander_hz=0.05,
    hold_wander_zeta=0.25,
    # the attitude EKF2 reports: tilt integrates the noisy gyro and is pulled back to the truth
    # over 6 s (the recorded roll is a quarter of the true wander's size), plus slow errors on
    # pitch and heading (recorded autocorrelation 0.92 at 1 s, 0.33 at 3 s) (fitted)
    gyro_integration_tau_s=(6.0, 6.0, 0.0),
    attitude_error_std_rad=(0.0, 0.016, 0.058),
    attitude_error_tau_s=(4.0, 4.0, 4.0),
    attitude_error_order=(1, 1, 2),
    # SIH's heading moves most in the first 20 s after "Takeoff detected" (its 1 s mismatch
    # 1.3-1.7 deg there, 0.3-0.8 deg at 25-60 s, 0.1-0.3 deg from 65 s; the 2026-12-04
    # formation flight's four vehicles and the hover's one) (fitted: fit_heading_estimate --fit)
    heading_takeoff_factor=1.95,
    heading_takeoff_s=20.5,
    heading_settle_s=42.0,
    heading_floor_rad=0.001,
)

# ArduCopter 4.7.0-dev SITL, frame "quad" (plus), 3 kg. Its attitude controller in GUIDED_NOGPS
# body-rate mode is not modelled term by term (the SITL frame's torque scales are not
# identifiable from these recordings): a reference model per axis, fitted to the recorded rate
# doublets by benchmarks/calibration/fit_emulator.py, with ArduPilot's own acceleration limits
# ATC_ACCEL_R_MAX/P_MAX 110000 and ATC_ACCEL_Y_MAX 27000 cdeg/s^2.
ARDUPILOT_DYNAMICS = Dynamics(
    rate_loop=RateLoop.REFERENCE,
    control_period_s=0.002,  # ArduCopter's 400 Hz loop, rounded to whole physics steps
    accel_max_radps2=(math.radians(1100.0), math.radians(1100.0), math.radians(270.0)),
    # fitted by benchmarks/calibration/fit_emulator.py --fit (docs/emulator.md, "Calibration")
    ref_gain=(0.98, 0.98, 0.857),
    ref_wn_radps=(250.0, 250.0, 8.48),
    ref_zeta=(1.4, 1.4, 0.790),
    angle_p=(1.0, 1.0, 1.847),
    ref_delay_periods=(0, 0, 3),
    motor_time_constant_s=0.0025,  # thrust steps: vz follows after ~2.5 ms
    # the hover's ~23.4 Hz roll/pitch limit cycle (94 % of the recorded rate power lies within
    # 20-30 Hz; sized to its gyro std) and a slow white yaw disturbance (sized to ATTITUDE's
    # yaw rate)
    disturbance_std_radps2=(0.32, 0.325, 0.045),
    disturbance_resonance_hz=(23.4, 23.4, 0.0),
    disturbance_zeta=0.05,
    # MOT_THST_HOVER 0.39 was learned with battery (1/0.974) and air-density (1/0.945)
    # compensation; the measured hover thrust 0.3649 gives the effective scale 0.39 / 0.3649
    thrust_scale=0.39 / 0.3649,
)
ARDUPILOT_SENSORS = Sensors(
    model=True,
    noise_default=True,
    # SITL has no IMU noise (SIM_GYR*_RND = SIM_ACC*_RND = 0): the gyro's ~2 mrad/s 23 Hz limit
    # cycle is true motion (ARDUPILOT_DYNAMICS.disturbance_std_radps2); this white accelerometer
    # noise stands in for the recorded slow ~3 mm/s^2 wander
    accel_noise_std_mps2=(0.0102, 0.0116, 0.0007),
    gyro_cutoff_hz=20.0,  # INS_GYRO_FILTER
    imu_filtered=True,
    accel_cutoff_hz=20.0,  # INS_ACCEL_FILTER
    # EKF3's estimate wander (fitted stand-in, benchmarks/calibration/fit_emulator.py --fit)
    velocity_error_std_mps=(0.0032, 0.0052, 0.002),
    velocity_error_tau_s=5.0,  # recorded vz autocorrelation 0.90 at 0.5 s
    position_error_tau_s=3.0,
    # attitude estimate errors: fast on roll and pitch (recorded autocorrelation 0.54 at 0.1 s),
    # slow on heading (0.9 at 1 s) (fitted)
    attitude_error_std_rad=(3.0e-5, 3.2e-5, 4.5e-5),
    attitude_error_tau_s=(0.15, 0.15, 3.0),
    # SITL's gyro drift (SIM_DRIFT_*): HIGHRES_IMU's z gyro wanders at < 1 Hz with 1.8 times the
    # std of ATTITUDE's bias-corrected yaw rate (fitted)
    gyro_bias_std_radps=(0.00014, 0.00014, 0.0004),
    gyro_bias_tau_s=2.0,
)


@dataclass(frozen=True, slots=True)
class Personality:
    """One autopilot personality (see the module docstring)."""

    name: str
    protocol: Protocol
    dynamics: Dynamics = field(default_factory=Dynamics)
    sensors: Sensors = field(default_factory=Sensors)


PERSONALITIES: dict[str, Personality] = {
    "nominal": Personality(
        "nominal",
        Protocol("px4", MAV_AUTOPILOT_PX4, (1, 13, 3), actuator_setpoints=True, ack_twice=True,
                 arming_ready_s=0.0, own_origin=False),
    ),
    "px4": Personality(
        "px4",
        # arming: refused until 3.0 s after the first HEARTBEAT (boot 1.36 s, armed at 4.36 s)
        # COM_RC_IN_MODE 4 (no manual control), as the recordings and the team's SITL runs set
        # it: Position and Altitude then descend at MPC_Z_VEL_MAX_DN (1.04 m/s recorded after
        # the offboard-loss failsafe) instead of holding
        Protocol("px4", MAV_AUTOPILOT_PX4, (1, 16, 0), actuator_setpoints=False, ack_twice=True,
                 arming_ready_s=3.0, own_origin=True, param_defaults=(("COM_RC_IN_MODE", 4),),
                 statustext_end="\t", timesync_reply_targets=b"\xb8\x34"),
        dynamics=PX4_DYNAMICS,
        sensors=PX4_SENSORS,
    ),
    "ardupilot": Personality(
        "ardupilot",
        # arming in GUIDED: "Need Position Estimate" until the EKF uses GPS (41-42 s after
        # start; 23 s in STABILIZE); the ardupilot protocol work sets its own readiness timeline
        Protocol("ardupilot", MAV_AUTOPILOT_ARDUPILOTMEGA, (4, 7, 0), actuator_setpoints=False,
                 ack_twice=False, arming_ready_s=0.0, own_origin=True),
        dynamics=ARDUPILOT_DYNAMICS,
        sensors=ARDUPILOT_SENSORS,
    ),
}
AUTOPILOT_NAMES = tuple(PERSONALITIES)
DEFAULT_AUTOPILOT = "px4"


def personality_of(name: str) -> Personality:
    """The personality called ``name``; ValueError naming the known ones otherwise."""
    try:
        return PERSONALITIES[name]
    except KeyError:
        raise ValueError(
            f"unknown autopilot {name!r}; expected one of {', '.join(AUTOPILOT_NAMES)}"
        ) from None
