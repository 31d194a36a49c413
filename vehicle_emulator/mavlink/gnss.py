"""GPS_RAW_INT rows of the fleet: a receiver with a 3D fix that reports the position estimate.

PX4 v1.16.0 SIH (recorded, docs/emulator.md) streams GPS_RAW_INT from its first packet, 8 Hz of
sim time, with fix_type 3 (3D), 10 satellites, eph 70 / epv 110 (HDOP / VDOP x 100), h_acc
0.9 m, v_acc 1.78 m, vel_acc 0.4 m/s and alt_ellipsoid equal to alt, before its estimator is
ready (the fix does not wait for the pre-arm checks). The emulator's receiver reports the same
constants and the position the vehicle's other geodetic messages report, so GPS_RAW_INT and
GLOBAL_POSITION_INT never disagree. Pure: arrays in, rows filled.
"""

from __future__ import annotations

import numpy as np

__all__ = ["GPS_RATE_HZ", "fill_gps_raw_int"]

GPS_RATE_HZ = 8.0
FIX_3D = 3
SATELLITES = 10
EPH_CM = 70  # HDOP 0.70
EPV_CM = 110  # VDOP 1.10
H_ACC_MM = 900
V_ACC_MM = 1780
VEL_ACC_MMPS = 400
UNKNOWN_COG = 65535


def fill_gps_raw_int(
    rows: np.ndarray,
    time_us: np.ndarray,
    lat_deg: np.ndarray,
    lon_deg: np.ndarray,
    alt_amsl_m: np.ndarray,
    vel_ned_mps: np.ndarray,
) -> None:
    """GPS_RAW_INT payload rows from geodetic position (WGS-84 degrees, metres above mean sea
    level) and NED velocity (m/s), (k,) and (k, 3). Course over ground is unknown (65535)
    below 0.1 m/s of ground speed."""
    ground_mps = np.hypot(vel_ned_mps[:, 0], vel_ned_mps[:, 1])
    cog_cdeg = np.round(np.degrees(np.arctan2(vel_ned_mps[:, 1], vel_ned_mps[:, 0])) * 100.0)
    rows["time_usec"] = time_us
    rows["fix_type"] = FIX_3D
    rows["lat"] = np.round(lat_deg * 1e7)
    rows["lon"] = np.round(lon_deg * 1e7)
    rows["alt"] = np.round(alt_amsl_m * 1e3)
    rows["alt_ellipsoid"] = rows["alt"]
    rows["eph"] = EPH_CM
    rows["epv"] = EPV_CM
    rows["vel"] = np.round(ground_mps * 100.0)
    rows["cog"] = np.where(ground_mps < 0.1, UNKNOWN_COG, cog_cdeg.astype(np.int64) % 36000)
    rows["satellites_visible"] = SATELLITES
    rows["h_acc"] = H_ACC_MM
    rows["v_acc"] = V_ACC_MM
    rows["vel_acc"] = VEL_ACC_MMPS
