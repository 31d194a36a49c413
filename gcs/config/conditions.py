"""The paper's sufficient conditions on a team, as numbers (docs/control-law.md, "Sufficient
conditions"): what `gcs check` prints and what `gcs sweep` records per run.

The condition on u_z > 0 along the flight is the run's to show (gcs.sweep.measure); the ones here
are known before the flight, from the gains, the reference and each vehicle's plant.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from gcs.config.schema import GRAVITY_MPS2, TeamConfig, VehicleConfig, proposition2_min_mhat


def alpha_p_bound(team: TeamConfig) -> float:
    """(g - varrho) / (2 sigma_a): alpha_p must stay below it (varrho = sup|v_r,z'|)."""
    varrho = team.reference_velocity.max_abs_acceleration_z()
    return (GRAVITY_MPS2 - varrho) / (2.0 * team.controller.gains.sigma_a)


def proposition1_bounds(vehicle: VehicleConfig, team: TeamConfig) -> tuple[float, float, float]:
    """The three upper bounds on c_eps of Proposition 1 (corrected form) with Jbar the largest
    principal inertia of the vehicle's plant; c_eps must stay below all three."""
    g = team.controller.gains
    jbar, ae, ao = max(vehicle.plant.inertia_kgm2), g.alpha_eps, g.alpha_omega
    s3 = math.sqrt(3.0)
    return (math.sqrt(ae / (2 * jbar)), ao / (2 * s3 * jbar),
            4 * ae * ao / (ao**2 + 8 * s3 * ae * jbar))


@dataclass(frozen=True, slots=True)
class Conditions:
    """Which conditions hold before the flight (None: cannot be judged, e.g. no plant)."""

    alpha_p: bool
    proposition1: bool | None
    proposition2: bool | None


def conditions(team: TeamConfig) -> Conditions:
    g = team.controller.gains
    with_plant = [v for v in team.vehicles if v.plant is not None]
    prop1 = (all(g.c_eps < min(proposition1_bounds(v, team)) for v in with_plant)
             if len(with_plant) == team.n else None)
    least = [proposition2_min_mhat(v, g) for v in team.vehicles]
    prop2 = (None if any(x is None for x in least) else
             all(v.estimates.mhat >= x * (1.0 - 1e-12)
                 for v, x in zip(team.vehicles, least, strict=True)))
    return Conditions(alpha_p=g.alpha_p < alpha_p_bound(team), proposition1=prop1,
                      proposition2=prop2)
