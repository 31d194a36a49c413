"""Accuracy of the ways to obtain u', u'' (docs/control-law.md) along the Scenario I closed loop.

Flies Scenario I with the default sampled law at 1 kHz and, at every tick, compares the model-based
closed form (measured acceleration, the law's own mass estimate) and Levant's differentiator (28)
with the exact oracle (true masses, T = |u|; docs/control-law.md) evaluated at the same state.
Run: `.venv/bin/python -m benchmarks.calibration.derivative_accuracy`.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from flightkit import jitcache

jitcache.configure()  # numba's cache, before the compiled modules below are imported

from flightkit.physics import rk4_step  # noqa: E402
from gcs.config import load_team  # noqa: E402
from gcs.control.derivatives import force_derivatives, levant_advance  # noqa: E402
from gcs.control.formation import edge_list, reference_velocity  # noqa: E402
from gcs.control.law import TeamMeasurement, attitude_stage, position_stage  # noqa: E402
from gcs.sim.loop import _acceleration  # noqa: E402
from gcs.sim.runner import law_gains  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]


def main() -> int:
    argparse.ArgumentParser(description=__doc__.splitlines()[0]).parse_args()  # --help; no options
    team = load_team(ROOT / "configs" / "square4.yaml")
    gains = law_gains(team)
    n, dt = team.n, 1e-3
    m = team.true_masses_kg()
    j = team.true_inertias_kgm2()
    p = team.initial_positions_enu_m().copy()
    v = np.zeros((n, 3))
    rot = np.tile(np.eye(3), (n, 1, 1))
    w = np.zeros((n, 3))
    mhat = team.initial_mhat().copy()
    rho = team.initial_inertia_estimates_kgm2().copy()
    adj, off = edge_list(team.adjacency()), team.offsets_enu_m()
    ref_args = team.reference_velocity.as_arrays()
    thrust_hold = m * gains.gravity_mps2
    levant = np.zeros((n, 3, 3))
    u_prev = None
    rows = []
    for step in range(60_000):
        t = step * dt
        ref = reference_velocity(t, *ref_args)
        stage = position_stage(p, v, rot, mhat, m, adj, off, ref, gains, True)
        u, kap, t_n, mrate = stage.force_n, stage.kappa, stage.thrust_n, stage.mhat_rate
        acc_meas = _acceleration(rot, thrust_hold, m, gains.gravity_mps2)
        du_m, ddu_m = force_derivatives(TeamMeasurement(p, v, acc_meas, rot, w), stage, mhat,
                                        1.0 / kap, adj, ref, gains, True)
        acc_true = _acceleration(rot, t_n, m, gains.gravity_mps2)
        du_x, ddu_x = force_derivatives(TeamMeasurement(p, v, acc_true, rot, w), stage, mhat,
                                        1.0 / m, adj, ref, gains, True)
        if u_prev is None:
            levant[:, :, 0] = u
        else:
            levant_advance(levant, u_prev, u, dt, 1e-4, 1e4)
        u_prev = u
        scale1 = np.abs(du_x).max() + 1e-3
        scale2 = np.abs(ddu_x).max() + 1e-3
        rows.append(
            (
                t,
                np.abs(du_m - du_x).max(),
                np.abs(ddu_m - ddu_x).max(),
                np.abs(levant[:, :, 1] - du_x).max(),
                np.abs(levant[:, :, 2] - ddu_x).max(),
                scale1,
                scale2,
            )
        )
        *_, tau, rrate, _, _, _, _ = attitude_stage(rot, w, u, du_m, ddu_m, rho, gains, True,
                                                   np.zeros(u.shape[0]))
        thrust_hold = t_n
        mhat = mhat + dt * mrate
        rho = rho + dt * rrate
        rk4_step(p, v, rot, w, t_n, tau, m, j, dt)
    r = np.array(rows)
    print(
        "window        | model u' max err | model u'' max err | Levant u' max err | Levant u'' max err | max|u'| | max|u''|"
    )
    for lo, hi in ((0.0, 0.1), (0.1, 5.0), (5.0, 10.0), (10.0, 60.0)):
        sel = (r[:, 0] >= lo) & (r[:, 0] < hi)
        print(
            f"t in [{lo:4.1f},{hi:4.1f}) | {r[sel, 1].max():.2e} | {r[sel, 2].max():.2e} | "
            f"{r[sel, 3].max():.2e} | {r[sel, 4].max():.2e} | {r[sel, 5].max():.2e} | {r[sel, 6].max():.2e}"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
