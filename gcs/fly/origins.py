"""Each vehicle's local frame tied to the team frame through its own origin (docs/gcs.md, "One
team frame"). Pure: the composition root feeds it the vehicles' GPS_GLOBAL_ORIGIN and
HOME_POSITION messages and reads the ties.

A vehicle's LOCAL_POSITION_NED is relative to its EKF origin. GPS_GLOBAL_ORIGIN gives that origin
(latitude, longitude in 1e-7 deg, altitude in mm); HOME_POSITION gives home's geodetic position
and its local x, y, z, from which the origin follows (home minus its local position, in the
tangent frame at home). Vehicles whose frames are the team frame (the team file's
`frame.vehicles: shared`) are tied at once with the identity.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from gcs import frames
from gcs.geodesy import FrameTie, Geodetic, TeamFrame
from gcs.link.samples import GpsGlobalOrigin, HomePosition

#: The problem text of a vehicle whose origin has not arrived (yet).
WAITING = "no origin yet (GPS_GLOBAL_ORIGIN or HOME_POSITION)"


def origin_from_gps_global_origin(origin: GpsGlobalOrigin) -> Geodetic:
    """GPS_GLOBAL_ORIGIN -> the vehicle's EKF origin (raises ValueError for a bad one)."""
    return Geodetic(origin.latitude_deg, origin.longitude_deg, origin.altitude_amsl_m)


def origin_from_home_position(home_position: HomePosition) -> Geodetic:
    """HOME_POSITION -> the EKF origin: home's geodetic position moved back by home's local
    position (x, y, z NED [m], relative to the origin)."""
    hp = home_position
    home = Geodetic(hp.latitude_deg, hp.longitude_deg, hp.altitude_amsl_m)
    local_home_enu = frames.enu_from_ned(np.array(hp.local_ned_m, dtype=float))
    if not np.isfinite(local_home_enu).all():
        raise ValueError(f"HOME_POSITION local position not finite: {local_home_enu.tolist()}")
    lat, lon, alt = TeamFrame(home).geodetic_from_enu(-local_home_enu)
    return Geodetic(float(lat), float(lon), float(alt))


class TeamTies:
    """The team's ties, one per vehicle (rows in team order), and why a vehicle has none."""

    def __init__(self, team_frame: TeamFrame, names: Sequence[str], shared: bool,
                 max_origin_distance_m: float) -> None:
        self.frame = team_frame
        self.names = list(names)
        self.max_origin_distance_m = max_origin_distance_m
        n = len(self.names)
        self.ties: list[FrameTie | None] = [team_frame.shared_tie() if shared else None] * n
        self.problems: list[str | None] = [None if shared else WAITING] * n
        self.offsets_enu_m = np.zeros((n, 3))
        self.rotations = np.tile(np.eye(3), (n, 1, 1))

    @property
    def complete(self) -> bool:
        return all(t is not None for t in self.ties)

    def tie(self, i: int, origin: Geodetic, source: str) -> str:
        """Tie vehicle i through `origin` (from message `source`); returns the line to log, or
        the problem (kept in `problems[i]`) when the origin is too far from the team frame."""
        tie = self.frame.tie(origin)
        horizontal = math.hypot(tie.offset_enu_m[0], tie.offset_enu_m[1])
        if horizontal > self.max_origin_distance_m or abs(tie.offset_enu_m[2]) > \
                self.max_origin_distance_m:
            self.problems[i] = (
                f"{self.names[i]}: its origin ({origin}, {source}) is {horizontal:.6g} m from the "
                f"team frame's origin ({self.frame.origin}) and {tie.offset_enu_m[2]:+.6g} m above "
                f"it, more than frame.max_origin_distance_m {self.max_origin_distance_m:g}: set "
                "frame.origin to where the team flies")
            return self.problems[i]
        self.ties[i], self.problems[i] = tie, None
        self.offsets_enu_m[i] = tie.offset_enu_m
        self.rotations[i] = tie.rotation
        o = tie.offset_enu_m
        return (f"{self.names[i]}: origin {origin} ({source}): at ({o[0]:.3f}, {o[1]:.3f}, "
                f"{o[2]:.3f}) m in the team frame")

    def refuse(self, i: int, text: str) -> None:
        """Record why vehicle i cannot be tied (e.g. a malformed origin message)."""
        if self.ties[i] is None:
            self.problems[i] = f"{self.names[i]}: {text}"

    def rotations_to_local(self, rotation_team: np.ndarray) -> np.ndarray:
        """Attitudes (n, 3, 3) body -> team ENU into body -> each vehicle's local ENU."""
        return np.einsum("nji,njk->nik", self.rotations, rotation_team)
