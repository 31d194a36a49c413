"""A small built-in team that `gcs compile` flies and simulates to fill numba's cache: the
programs' own code paths on it compile what they later load (gcs/fly/warmup.py,
gcs/sim/warmup.py)."""

from __future__ import annotations

from gcs.config.reader import team_from_yaml
from gcs.config.schema import TeamConfig

# Two vehicles are enough: numba specialises on array types, not sizes. Both laws and both
# derivative methods are compiled (placeholders filled in by `compile_team`).
_TEAM_YAML = """\
name: compile
mission: {{duration_s: 1.0}}
controller:
  law: {law}
  mode: rates
  gains: {{c_p: 4.0, alpha_p: 2.0, alpha_m: 1.0, sigma_a: 1.0, alpha_eps: 32.0,
          alpha_omega: 32.0, c_eps: 0.5, alpha_rho: 0.5, k_eps: 8.0}}
  derivative: {{method: {derivative}}}
reference_velocity:
  x: {{constant: 0.0, cosines: [{{amplitude: 0.3, period_s: 23.0}}]}}
  y: {{constant: 0.0}}
  z: {{constant: 0.2}}
graph: {{edges: [[1, 2]]}}
fly: {{actuators: {{tick_rate_hz: 250, alpha_eps: 2.0, alpha_omega: 2.0, alpha_rho: 0.03}}}}
vehicles:
  - id: 1
    sysid: 1
    offset_enu_m: [1.0, 0.0, 0.0]
    initial: {{position_enu_m: [1.0, 0.0, 10.0]}}
    estimates: {{mhat: 1.0, inertia_kgm2: [0.08, 0.08, 0.08]}}
    nominal_mass_kg: 0.85
    airframe: {{arm_length_m: 0.2, anti_torque_m: 0.016, rotor_thrust_max_n: 6.0}}
    plant: {{mass_kg: 0.85, inertia_kgm2: [0.04856, 0.04856, 0.08801]}}
  - id: 2
    sysid: 2
    offset_enu_m: [-1.0, 0.0, 0.0]
    initial: {{position_enu_m: [-1.0, 0.0, 10.0]}}
    estimates: {{mhat: 4.0, inertia_kgm2: [0.08, 0.08, 0.08]}}
    nominal_mass_kg: 1.2
    airframe: {{arm_length_m: 0.25, anti_torque_m: 0.016, rotor_thrust_max_n: 8.0}}
    plant: {{mass_kg: 1.2, inertia_kgm2: [0.1522, 0.1522, 0.3]}}
"""

VARIANTS = [(law, derivative) for law in ("adaptive", "baseline")
             for derivative in ("model", "levant")]


def compile_team(law: str, derivative: str) -> TeamConfig:
    """The built-in team flown with `law` and derivative method `derivative`."""
    return team_from_yaml(_TEAM_YAML.format(law=law, derivative=derivative), "<gcs compile>")
