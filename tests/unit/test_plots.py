"""The paper's figures are written as readable PNGs for a synthetic converging formation."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

from gcs import plots
from gcs.flightlog import FlightLog

OFFSETS = np.array([[2.0, 2.0, 0.0], [2.0, -2.0, 0.0], [-2.0, -2.0, 0.0], [-2.0, 2.0, 0.0]])
MASSES = np.array([0.85, 1.2, 0.35, 3.4])
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def synthetic_log(
    controller: str = "adaptive",
    t_end: float = 60.0,
    dt: float = 0.02,
    mass_drop_t_s: float | None = None,
    known_mass: bool = True,
) -> FlightLog:
    """Four vehicles converging exponentially onto the 4 m square while tracking v_r; with a
    mass drop, the baseline team climbs away afterwards (like the paper's Fig. 9)."""
    k = int(round(t_end / dt)) + 1
    t = np.arange(k) * dt
    w = 2 * np.pi / 23
    vr = np.stack([0.3 * np.cos(w * t), 0.3 * np.cos(2 * w * t), np.full(k, 0.2)], axis=-1)
    centre = np.stack(
        [0.3 / w * np.sin(w * t), 0.3 / (2 * w) * np.sin(2 * w * t), 10 + 0.2 * t], axis=-1
    )
    d0 = np.array([[4, 4, 9], [3, -4, 11], [-5, -4, 12], [-1, 3, 8]], float) - OFFSETS
    d0 -= d0.mean(axis=0)
    decay = np.exp(-t / 1.5)[:, None, None]
    p = centre[:, None, :] + OFFSETS + decay * d0
    v = vr[:, None, :] - decay * d0 / 1.5
    mass_true = np.tile(MASSES, (k, 1))
    mass_est = MASSES + (np.array([0.5, 2, 0.5, 2]) - MASSES) * np.exp(-1.5 * t)[:, None]
    if mass_drop_t_s is not None:
        after = t >= mass_drop_t_s
        mass_true[after, 0] *= 0.7
        if controller == "adaptive":
            mass_est[after, 0] = 0.595 + 0.255 * np.exp(-1.5 * (t[after] - mass_drop_t_s))
        else:
            climb = 0.514 * (t[after] - mass_drop_t_s)
            p[after, :, 2] += climb[:, None]
            v[after, :, 2] += 0.514
    force = mass_est[..., None] * np.array([0.05, -0.05, 9.81])
    return FlightLog.from_arrays(
        t_s=t,
        position_enu_m=p,
        velocity_enu_mps=v,
        reference_velocity_enu_mps=vr,
        attitude_error=np.array([0.026, 0.118, 0.173, 0.026]) * np.exp(-3 * t)[:, None],
        omega_error_radps=np.array([0.32, 0.67, 0.81, 0.31]) * np.exp(-3 * t)[:, None],
        mass_estimate_kg=mass_est,
        mass_true_kg=mass_true if known_mass else None,
        inertia_estimate_kgm2=0.08 + 0.04 * (1 - np.exp(-t / 5))[:, None, None] * np.ones((4, 3)),
        thrust_n=np.linalg.norm(force, axis=-1),
        force_enu_n=force,
        vehicle_ids=[1, 2, 3, 4],
        offsets_enu_m=OFFSETS,
        source="sim",
        controller=controller,
        team="configs/square4.yaml",
        name="square4",
    )


def assert_pngs(paths: list[Path], names: list[str]) -> None:
    assert [p.name for p in paths] == names
    for p in paths:
        data = p.read_bytes()
        assert data.startswith(PNG_MAGIC), p
        assert len(data) > 20_000, f"{p.name}: only {len(data)} bytes"


def test_write_figures_writes_figs_2_to_7(tmp_path: Path) -> None:
    # GIVEN an exponentially converging formation WHEN the figures are written into a new dir
    out = tmp_path / "figs" / "nested"
    paths = plots.write_figures(synthetic_log(), out)
    # THEN one non-trivial PNG per figure, named as the module docstring says
    assert_pngs(
        paths,
        [
            "fig2_formation.png",
            "fig3_position_offsets.png",
            "fig4_velocity_errors.png",
            "fig5_attitude_errors.png",
            "fig6_mass_estimates.png",
            "fig7_inertia_estimates.png",
            "errors_semilogy.png",
        ],
    )
    for p in paths:
        assert p.name in plots.__doc__


def test_figures_for_a_short_run_with_unknown_masses_and_graph_edges(tmp_path: Path) -> None:
    # GIVEN a 3 s fly-like run (no true masses) and Fig. 3 restricted to the ring's edges
    log = synthetic_log(t_end=3.0, known_mass=False)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # e.g. an all-NaN reduction on the unknown masses
        paths = plots.write_figures(log, tmp_path, pairs=[(1, 2), (2, 3), (3, 4), (4, 1)])
    assert len(paths) == 7 and all(p.stat().st_size > 10_000 for p in paths)
    with pytest.raises(ValueError, match=r"vehicle 9 is not in the log \[1, 2, 3, 4\]"):
        plots.write_figures(log, tmp_path, pairs=[(1, 9)])


def test_comparison_figures_8_and_9(tmp_path: Path) -> None:
    # GIVEN a mass drop of UAV 1 at 40 s flown by both laws
    adaptive = synthetic_log("adaptive", t_end=80.0, mass_drop_t_s=40.0)
    baseline = synthetic_log("baseline", t_end=80.0, mass_drop_t_s=40.0)
    paths = plots.write_comparison_figures(adaptive, baseline, tmp_path)
    assert_pngs(paths, ["fig8_adaptive_z.png", "fig9_baseline_z.png"])
    assert plots._mass_change_times(adaptive) == [40.0]
    # the logs must be given in the right order
    with pytest.raises(ValueError, match="expected an 'adaptive' and a 'baseline' log"):
        plots.write_comparison_figures(baseline, adaptive, tmp_path)
