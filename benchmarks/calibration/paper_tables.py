"""Print our Scenario I / II figures beside the reference values, as markdown tables.

Run: `.venv/bin/python -m benchmarks.calibration.paper_tables` (about 10 s with numba's cache warm). The
output is what docs/reproducing-the-paper.md shows.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from flightkit import jitcache

jitcache.configure()  # numba's cache, before the compiled modules below are imported

from gcs import metrics  # noqa: E402
from gcs.config import load_team  # noqa: E402
from gcs.sim.runner import SimOptions, simulate  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]

Z_SHIFT_M = 10.0
REF_FE = {0: 7.07, 5: 3.14e-2, 10: 1.07e-5, 20: 1.02e-5, 30: 3.6e-6, 60: 9.4e-6}
REF_VE = {0: 0.469, 5: 5.59e-2, 10: 7.4e-6, 20: 7.0e-6, 30: 5.5e-6, 60: 7.1e-6}
REF_MASS = {
    1: (0.7741, 1.4322, 0.3827, 3.0964),
    2: (0.8305, 1.2546, 0.3602, 3.3282),
    5: (0.84964, 1.20091, 0.35043, 3.39500),
    10: (0.8500, 1.2000, 0.3500, 3.4000),
}
REF_Z2 = {40: -0.1903, 45: -0.0232, 50: -0.0231, 60: -0.0231, 80: -0.0231}
REF_Z2B = {40: 0.1811, 45: 2.7309, 50: 5.3006, 60: 10.4398, 80: 20.7184}


def fmt(values) -> str:
    return ", ".join(f"{x:.4f}" for x in values)


def z_row(log, t) -> str:
    return fmt(log.position_enu_m[idx(log, t), :, 2] - Z_SHIFT_M)


def idx(log, t):
    return int(np.argmin(np.abs(log.t_s - t)))


def main() -> int:
    argparse.ArgumentParser(description=__doc__.splitlines()[0]).parse_args()  # --help; no options
    s1 = load_team(ROOT / "configs" / "square4.yaml")
    s2 = load_team(ROOT / "configs" / "square4_massdrop.yaml")
    oracle = simulate(s1, SimOptions(oracle=True)).log
    default = simulate(s1, SimOptions()).log
    levant = simulate(s1, SimOptions(derivative="levant")).log
    rates = simulate(s1, SimOptions(mode="rates")).log
    logs = {"verification": oracle, "default": default, "Levant": levant, "rates": rates}
    fe = {k: metrics.formation_error(v.position_enu_m, v.offsets_enu_m) for k, v in logs.items()}
    ve = {
        k: metrics.velocity_error(v.velocity_enu_mps, v.reference_velocity_enu_mps)
        for k, v in logs.items()
    }
    print(
        "| t (s) | reference formation error (m) | "
        + " | ".join(f"{k}" for k in logs)
        + " | reference velocity error (m/s) | "
        + " | ".join(f"{k}" for k in logs)
        + " |"
    )
    print("|---" * (3 + 2 * len(logs)) + "|")
    for t in REF_FE:
        print(
            f"| {t} | {REF_FE[t]:.3g} | "
            + " | ".join(f"{fe[k][idx(logs[k], t)]:.3g}" for k in logs)
            + f" | {REF_VE[t]:.3g} | "
            + " | ".join(f"{ve[k][idx(logs[k], t)]:.3g}" for k in logs)
            + " |"
        )
    print()
    print("| t (s) | reference UAV1..4 | verification | default |")
    print("|---|---|---|---|")
    for t, ref in REF_MASS.items():
        print(
            f"| {t} | {fmt(ref)} | {fmt(oracle.mass_estimate_kg[idx(oracle, t)])} | "
            f"{fmt(default.mass_estimate_kg[idx(default, t)])} |"
        )
    print()
    a_or = simulate(s2, SimOptions(oracle=True)).log
    b_or = simulate(s2, SimOptions(oracle=True, law="baseline")).log
    a_d = simulate(s2, SimOptions()).log
    b_d = simulate(s2, SimOptions(law="baseline")).log
    print(
        "| t (s) | reference adaptive z | verification z1..z4 | default z1..z4 | reference baseline z1 | verification baseline z1..z4 | default baseline z1..z4 |"
    )
    print("|---|---|---|---|---|---|---|")
    for t in REF_Z2:
        print(
            f"| {t} | {REF_Z2[t]:.4f} | {z_row(a_or, t)} | {z_row(a_d, t)} | {REF_Z2B[t]:.4f} | {z_row(b_or, t)} | {z_row(b_d, t)} |"
        )
    late = a_d.t_s >= 50
    print()
    print(
        f"default adaptive: max |v_z| for t >= 50 s = {np.abs(a_d.velocity_enu_mps[late, :, 2]).max():.2e} m/s; "
        f"formation error at 60 s = {metrics.formation_error(a_d.position_enu_m, a_d.offsets_enu_m)[idx(a_d, 60)]:.2e} m"
    )
    gained = b_d.position_enu_m[idx(b_d, 80), :, 2] - b_d.position_enu_m[idx(b_d, 40), :, 2]
    print(
        f"default baseline: v_z at 60 s = {np.round(b_d.velocity_enu_mps[idx(b_d, 60), :, 2], 4).tolist()} m/s; "
        f"gained 40->80 s = {np.round(gained, 2).tolist()} m"
    )
    print(
        f"min u_z (default, Scenario I) = {np.round(default.force_enu_n[..., 2].min(axis=0), 2).tolist()} N"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
