"""What `sim.autopilot` puts under the law in `gcs sim`: its loops and its airframe.

`ideal` is the paper's model with an idealised rate loop. `px4`, `ardupilot` and `nominal` stand
for the bundled emulator's personality of that name (vehicle_emulator/config/personality.py, the
source of truth for every size here; tests/unit/test_sim_personality.py checks the drag
against it): its loops as the recorded response models of gcs/control/cascade.py, its attitude
P gains, and its airframe's linear drag. Its telemetry errors are gcs/sim/noise.py's.
"""

from __future__ import annotations

import math

import numpy as np

from gcs.control.cascade import ARDUPILOT_RESPONSE, NOMINAL_RESPONSE, PX4_RESPONSE
from gcs.sim.loop import OnboardResponse

#: The onboard attitude loop's P gains in attitude mode [1/s]: PX4 v1.16's defaults
#: (MC_ROLL_P, MC_PITCH_P, MC_YAW_P); with sim.autopilot, roll and pitch take its response's
#: attitude_p_per_s and yaw YAW_ATTITUDE_GAIN.
ATTITUDE_GAIN = (6.5, 6.5, 2.8)
#: sim.autopilot -> the recorded response its loops fly (gcs/control/cascade.py)
RESPONSES = {"px4": PX4_RESPONSE, "ardupilot": ARDUPILOT_RESPONSE, "nominal": NOMINAL_RESPONSE}
#: yaw attitude P [1/s]: PX4 MC_YAW_P, ArduCopter ATC_ANG_YAW_P, the nominal personality's
YAW_ATTITUDE_GAIN = {"px4": 2.8, "ardupilot": 4.5, "nominal": 2.8}
#: sim.autopilot -> its airframe's linear drag k [1/s], the force -m k v in the world frame:
#: PX4 SIH's SIH_KDV 1 N/(m/s) on SIH_MASS 1 kg; the ArduCopter and nominal personalities have
#: none. `ideal` has none.
LINEAR_DRAG_PER_S = {"px4": 1.0, "ardupilot": 0.0, "nominal": 0.0}
#: The torque makes the body rates follow the response's reference this many times faster than
#: the response itself, and at most TRACK_STEP_LIMIT / dt (stable under RK4 at the plant rate).
TRACK_BANDWIDTHS = 10.0
TRACK_STEP_LIMIT = 0.5


def linear_drag_per_s(autopilot: str) -> float:
    """The linear drag [1/s] of the airframe `autopilot` flies (0 for `ideal`)."""
    return LINEAR_DRAG_PER_S.get(autopilot, 0.0)


def attitude_gains(autopilot: str) -> np.ndarray:
    """The onboard attitude loop's P gains (3,) [1/s] in attitude mode."""
    gain = np.array(ATTITUDE_GAIN)
    if autopilot in RESPONSES:
        gain[:2] = RESPONSES[autopilot].attitude_p_per_s
        gain[2] = YAW_ATTITUDE_GAIN[autopilot]
    return gain


def onboard_response(autopilot: str, plant_hz: float, n: int,
                     thrust_n: np.ndarray) -> OnboardResponse:
    """The loops of n vehicles: inactive for `ideal`, else the autopilot's response model;
    the thrust starts at `thrust_n` (n,)."""
    dt_s = 1.0 / plant_hz
    if autopilot not in RESPONSES:
        return OnboardResponse(False, 0.0, 0.0, 1.0, 0, 0, 1.0, 0.0, np.zeros((n, 3)),
                               np.zeros((n, 3)), np.zeros((1, n, 3)), thrust_n.copy())
    r = RESPONSES[autopilot]
    dead, yaw_dead = (int(round(x / dt_s)) for x in (r.rate_dead_time_s, r.yaw_dead_time_s))
    return OnboardResponse(
        True, r.rate_damping, r.rate_natural_radps, r.yaw_time_constant_s, dead, yaw_dead,
        1.0 - math.exp(-dt_s / r.thrust_time_constant_s),
        min(TRACK_BANDWIDTHS * max(r.rate_natural_radps, 1.0 / r.yaw_time_constant_s),
            TRACK_STEP_LIMIT / dt_s),
        np.zeros((n, 3)), np.zeros((n, 3)), np.zeros((max(dead, yaw_dead) + 1, n, 3)),
        thrust_n.copy())
