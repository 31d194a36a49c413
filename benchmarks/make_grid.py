"""Write a grid team file: rows x cols heterogeneous quadrotors (the four Table I airframes in
turn) on a grid graph (each vehicle talks to its row and column neighbours), 4 m apart, flying
Scenario I's reference like configs/grid16.yaml. The scale benchmark (bench_scale.py) flies
these; configs/grid240.yaml is ``--rows 15 --cols 16 --shared-port 14550``.

    python -m benchmarks.make_grid --rows 15 --cols 16 [--shared-port 14550] [--out FILE]

Links: vehicle i (sysid i) binds 14580 + i - 1 (PX4 SITL's numbering). With ``--shared-port P``
every vehicle sends to the one GCS port P and the ground station tells them apart by sysid
(one MAVLink network: sysids 1-254 for vehicles, so at most 254 on a port; the generator gives
vehicle i sysid i, so at most 254 in any case); without it vehicle i has GCS port G + i - 1,
G = 14640 up to 60 vehicles, else the first port after the vehicles' (14580 + n), so that no GCS
port is a vehicle's. Initial positions: the grid point plus a deterministic perturbation
(seeded), 14-16 m up.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SPACING_M = 4.0
MAX_SYSID = 254
VEHICLE_PORT_BASE = 14580  # vehicle i binds 14580 + i - 1 (PX4 SITL's numbering)
GCS_PORT_BASE = 14640
#: The four airframes of the paper's Table I: mass, inertia, arm, max rotor thrust, and the
#: initial mass estimate mhat (1/mass factor) as configs/grid16.yaml starts them.
AIRFRAMES = (
    (0.85, (0.04856, 0.04856, 0.08801), 0.2, 6.0, 1.0),
    (1.2, (0.1522, 0.1522, 0.3), 0.25, 8.0, 4.0),
    (0.35, (0.0256, 0.0256, 0.052), 0.12, 3.0, 1.0),
    (3.4, (0.354, 0.354, 0.654), 0.35, 20.0, 6.0),
)

HEADER = """\
# {n} heterogeneous quadrotors (the four Table I airframes in turn) on a {rows} x {cols} grid
# graph (each vehicle talks to its row and column neighbours: {m} edges) keep a 4 m grid while
# tracking Scenario I's v_r(t). Positions ENU. Written by
#   python -m benchmarks.make_grid {args}
# and flown by benchmarks/bench_scale.py (docs/benchmarks.md, "Scale").
#
# Links: {links}
name: {name}

mission:
  duration_s: 60.0

controller:
  law: adaptive
  mode: rates
  gains: {{c_p: 4.0, alpha_p: 2.0, alpha_m: 1.0, sigma_a: 1.0, alpha_eps: 32.0, alpha_omega: 32.0,
          c_eps: 0.5, alpha_rho: 0.5, k_eps: 8.0}}
  derivative: {{method: model}}

reference_velocity:
  x: {{constant: 0.0, cosines: [{{amplitude: 0.3, period_s: 23.0}}]}}
  y: {{constant: 0.0, cosines: [{{amplitude: 0.3, period_s: 11.5}}]}}
  z: {{constant: 0.2}}

graph:
  edges: {edges}

# Gains as configs/grid16.yaml (the cascade criterion's, PX4 and ArduPilot default tuning).
fly:
  rates: {{tick_rate_hz: 100, max_rate_radps: 1.0, k_eps: 1.5, k_eps_yaw: 1.0, alpha_p: 1.0, c_p: 1.0}}
  attitude: {{tick_rate_hz: 100, alpha_p: 1.0, c_p: 0.4}}
  actuators: {{tick_rate_hz: 250, alpha_eps: 2.0, alpha_omega: 2.0, alpha_rho: 0.03}}
  initial_mass: from_hover
  end_action: land
  abort_action: land
  link_loss_action: hold
  stale_after_s: 0.1
  link_lost_after_s: 0.5
  geofence: {{min_enu_m: [-{fence:g}, -{fence:g}, 1.0], max_enu_m: [{fence:g}, {fence:g}, 60.0]}}
  # the largest over all pairs: with PX4-like estimate noise it grows with the team's size
  formation_check: {{after_s: 10.0, max_error_m: {check:g}, max_fraction: 0.5}}

frame:
  origin: [47.397742, 8.545594, 488.0]

sim:
  plant_rate_hz: 1000
  controller_rate_hz: 1000

vehicles:
"""

VEHICLE = """\
  - id: {i}
    sysid: {i}
    offset_enu_m: [{ox:g}, {oy:g}, 0.0]
    initial: {{position_enu_m: [{px:.1f}, {py:.1f}, {pz:.1f}]}}
    estimates: {{mhat: {mhat:g}, inertia_kgm2: [0.08, 0.08, 0.08]}}
    nominal_mass_kg: {mass:g}
    nominal_inertia_kgm2: [{jx:g}, {jy:g}, {jz:g}]
    airframe: {{arm_length_m: {arm:g}, anti_torque_m: 0.016, rotor_thrust_max_n: {fmax:g}}}
    plant: {{mass_kg: {mass:g}, inertia_kgm2: [{jx:g}, {jy:g}, {jz:g}]}}
    link: {{local_port: {local}, remote_port: {remote}}}
"""


def grid_edges(rows: int, cols: int) -> list[tuple[int, int]]:
    """Row and column neighbours of a rows x cols grid, ids 1.. row by row."""
    edges = []
    for r in range(rows):
        for c in range(cols):
            i = r * cols + c + 1
            if c + 1 < cols:
                edges.append((i, i + 1))
            if r + 1 < rows:
                edges.append((i, i + cols))
    return edges


def gcs_port_base(n: int) -> int:
    """The GCS port of vehicle 1 without a shared port: 14640, or past the vehicles' own ports
    (14580 .. 14580 + n - 1) when they reach it."""
    return max(GCS_PORT_BASE, VEHICLE_PORT_BASE + n)


def team_text(rows: int, cols: int, shared_port: int | None, seed: int = 1) -> str:
    n = rows * cols
    if n > MAX_SYSID:  # sysid i for vehicle i, and 255 is the ground station's
        raise SystemExit(f"{n} vehicles: a MAVLink network has sysids 1-{MAX_SYSID} for vehicles")
    rng = np.random.default_rng(seed)
    edges = grid_edges(rows, cols)
    x0, y0 = -SPACING_M * (cols - 1) / 2.0, -SPACING_M * (rows - 1) / 2.0
    half = max(rows, cols) * SPACING_M / 2.0
    gcs_base = gcs_port_base(n)
    links = (f"every vehicle sends to one GCS port, {shared_port} (sysids 1-{n}); vehicle i "
             f"binds 14580 + i - 1" if shared_port is not None else
             f"vehicle i binds 14580 + i - 1 and sends to GCS port {gcs_base} + i - 1")
    args = f"--rows {rows} --cols {cols}" + (f" --shared-port {shared_port}"
                                             if shared_port is not None else "")
    out = [HEADER.format(n=n, rows=rows, cols=cols, m=len(edges), args=args, links=links,
                         name=f"grid{n}", edges="[" + ", ".join(f"[{i}, {j}]" for i, j in edges)
                         + "]", fence=round(half + 80.0), check=round(1.0 + 0.1 * n ** 0.5, 1))]
    for k in range(n):
        r, c = divmod(k, cols)
        mass, (jx, jy, jz), arm, fmax, mhat = AIRFRAMES[k % len(AIRFRAMES)]
        ox, oy = x0 + SPACING_M * c, y0 + SPACING_M * r
        dx, dy = rng.uniform(-1.0, 1.0, 2)
        out.append(VEHICLE.format(
            i=k + 1, ox=ox, oy=oy, px=ox + dx, py=oy + dy, pz=rng.uniform(14.0, 16.0),
            mhat=mhat, mass=mass, jx=jx, jy=jy, jz=jz, arm=arm, fmax=fmax,
            local=shared_port if shared_port is not None else gcs_base + k, remote=VEHICLE_PORT_BASE + k))
    return "".join(out)


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", type=int, required=True)
    ap.add_argument("--cols", type=int, required=True)
    ap.add_argument("--shared-port", type=int, default=None)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--out", type=Path, default=None, help="default: stdout")
    args = ap.parse_args(argv)
    text = team_text(args.rows, args.cols, args.shared_port, args.seed)
    if args.out is None:
        sys.stdout.write(text)
    else:
        args.out.write_text(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
