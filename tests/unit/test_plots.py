"""The paper's figures are written as readable PNGs for a synthetic converging formation."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

from gcs import plots
from gcs.flightlog import FlightLog, estimates_record

OFFSETS = np.array([[2.0, 2.0, 0.0], [2.0, -2.0, 0.0], [-2.0, -2.0, 0.0], [-2.0, 2.0, 0.0]])
MASSES = np.array([0.85, 1.2, 0.35, 3.4])
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def synthetic_log(
    controller: str = "adaptive",
    t_end: float = 60.0,
    dt: float = 0.02,
    mass_drop_t_s: float | None = None,
    known_mass: bool = True,
    extra: dict | None = None,
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
        extra=extra,
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


def demo_extra(mode: str, mass_from: str = "hover", estimated: bool = False) -> dict:
    """What gcs fly records of the demo: its mode, the emulated vehicles, the estimates."""
    return {
        "mode": mode,
        "vehicle_kinds": ["PX4 (vehicle-emu px4)"] * 4,
        "estimates": estimates_record(
            mass_from=[mass_from] * 4,
            inertia_from="team",
            inertia_kgm2=np.full((4, 3), 0.08),
            inertia_estimated=estimated,
        ),
    }


@pytest.mark.parametrize("mode", ["rates", "attitude"])
def test_a_run_that_does_not_command_the_torque_has_no_fig7(tmp_path: Path, mode: str) -> None:
    # GIVEN a fly run in `mode` and a Fig. 7 left in the directory by an earlier run
    log = synthetic_log(extra=demo_extra(mode))
    stale = tmp_path / "fig7_inertia_estimates.png"
    stale.write_bytes(PNG_MAGIC)
    # WHEN its figures are written there
    paths = plots.write_figures(log, tmp_path)
    # THEN no Fig. 7 is written and the earlier one is gone: none can be read as this run's
    names = [p.name for p in paths]
    assert "fig7_inertia_estimates.png" not in names and not stale.exists()
    assert "fig6_mass_estimates.png" in names and len(names) == 6


def position_mode_log() -> FlightLog:
    """The synthetic flight as gcs fly's position mode records it: no law ran, so no attitude
    errors, estimates, thrust or force (NaN), controller "autopilot", nothing estimated."""
    log = synthetic_log()
    n, k = log.n_vehicles, log.n_samples
    return FlightLog.from_arrays(
        t_s=log.t_s, position_enu_m=log.position_enu_m, velocity_enu_mps=log.velocity_enu_mps,
        reference_velocity_enu_mps=log.reference_velocity_enu_mps,
        attitude_error=np.full((k, n), np.nan), omega_error_radps=np.full((k, n), np.nan),
        mass_estimate_kg=np.full((k, n), np.nan), mass_true_kg=log.mass_true_kg,
        inertia_estimate_kgm2=np.full((k, n, 3), np.nan), thrust_n=np.full((k, n), np.nan),
        force_enu_n=np.full((k, n, 3), np.nan), vehicle_ids=[1, 2, 3, 4], offsets_enu_m=OFFSETS,
        source="fly", controller="autopilot", team="configs/square4.yaml", name="square4",
        extra={"mode": "position", "estimates": estimates_record(
            mass_from=["none"] * 4, inertia_from="none", inertia_kgm2=None,
            inertia_estimated=False)})


def test_a_position_mode_run_has_the_formation_figures_and_no_estimate_figures(
        tmp_path: Path) -> None:
    # GIVEN a position-mode flight and the law's figures left in the directory by an earlier run
    stale = [tmp_path / name for name in ("fig5_attitude_errors.png", "fig6_mass_estimates.png",
                                          "fig7_inertia_estimates.png")]
    for path in stale:
        path.write_bytes(PNG_MAGIC)
    # WHEN its figures are written there
    paths = plots.write_figures(position_mode_log(), tmp_path)
    # THEN the formation figures are written, and no figure of estimates or attitude errors: no
    # law ran, and none of an earlier run can be read as this run's
    assert_pngs(paths, ["fig2_formation.png", "fig3_position_offsets.png",
                        "fig4_velocity_errors.png", "errors_semilogy.png"])
    assert not any(path.exists() for path in stale)
    # AND every title says what flew and that nothing was estimated
    for fig in (plots.fig2_formation(position_mode_log()),
                plots.errors_semilogy(position_mode_log())):
        title = fig.get_suptitle()
        assert "square4: fly, no law, position mode (formation slots as position setpoints)" \
            in title, title
        assert "the autopilots' own loops fly the slots; no mass or inertia estimation" in title
        assert "hat" not in title, title  # no mhat(0) / Jhat(0) line
    # AND the log-scale figure draws no attitude error
    (ax,) = plots.errors_semilogy(position_mode_log()).axes
    assert [line.get_label().split()[0] for line in ax.get_lines()] == ["formation", "velocity"]


def test_actuators_mode_and_a_log_without_a_mode_keep_fig7(tmp_path: Path) -> None:
    # GIVEN a run that flew the torque (26) (Jhat in use) and an older log that recorded no mode
    for log, out in (
        (synthetic_log(extra=demo_extra("actuators", "team", estimated=True)), tmp_path / "a"),
        (synthetic_log(), tmp_path / "old"),
    ):
        # WHEN their figures are written THEN each has its Fig. 7
        names = [p.name for p in plots.write_figures(log, out)]
        assert "fig7_inertia_estimates.png" in names


def test_every_title_says_the_mode_the_vehicles_and_the_initial_estimates() -> None:
    # GIVEN the demo as recorded: rates mode, emulated PX4 vehicles, mhat(0) from hover thrust
    log = synthetic_log(extra=demo_extra("rates"))
    figures = [
        plots.fig2_formation(log),
        plots.fig3_position_offsets(log),
        plots.fig4_velocity_errors(log),
        plots.fig5_attitude_errors(log),
        plots.fig6_mass_estimates(log),
        plots.errors_semilogy(log),
    ]
    # THEN every title names the mode, the vehicles, where mhat(0) came from, and that Jhat is
    # not in use
    for fig in figures:
        title = fig.get_suptitle()
        assert "rates mode" in title and "thrust + body rates" in title, title
        assert "PX4 (vehicle-emu px4)" in title, title
        assert "from hover thrust" in title, title
        assert "not used in rates mode" in title, title
    # AND a log that recorded none of it says so rather than guessing
    old = plots.fig6_mass_estimates(synthetic_log()).get_suptitle()
    assert "mode not recorded" in old and "source not recorded" in old


def test_fig7_of_a_torque_run_says_jhat_is_estimated_and_the_baseline_that_it_is_known() -> None:
    adaptive = synthetic_log(extra=demo_extra("actuators", "team", estimated=True))
    assert (
        "estimated and used in the torque" in plots.fig7_inertia_estimates(adaptive).get_suptitle()
    )
    baseline = synthetic_log(
        "baseline",
        extra={
            "mode": "actuators",
            "estimates": estimates_record(
                mass_from=["nominal"] * 4,
                inertia_from="nominal",
                inertia_kgm2=np.full((4, 3), 0.05),
                inertia_estimated=False,
            ),
        },
    )
    title = plots.fig7_inertia_estimates(baseline).get_suptitle()
    assert "baseline, not estimated" in title and "actuators mode" in title


def test_fig6_marks_the_initial_estimates_the_truth_and_the_relative_error() -> None:
    # GIVEN a run whose estimates start off the truth (0.5, 2, 0.5, 2 kg against MASSES)
    log = synthetic_log(extra=demo_extra("rates"))
    m0 = log.mass_estimate_kg[0]
    fig = plots.fig6_mass_estimates(log)
    top, bottom = fig.axes[:2]
    # THEN the top panel marks each initial value with a circle at t = 0
    circles = [ln for ln in top.get_lines() if ln.get_marker() == "o"]
    assert sorted(float(ln.get_ydata()[0]) for ln in circles) == sorted(m0.tolist())
    assert all(float(ln.get_xdata()[0]) == 0.0 for ln in circles)
    # AND draws each true mass dashed, and states both sets of values in its title
    dashed = [ln for ln in top.get_lines() if ln.get_linestyle() == "--"]
    assert sorted(float(ln.get_ydata()[0]) for ln in dashed) == sorted(MASSES.tolist())
    assert "from hover thrust: 0.5, 2, 0.5, 2 kg" in top.get_title()
    assert "true (the plant) 0.85, 1.2, 0.35, 3.4 kg" in top.get_title()
    # AND the bottom panel is the error relative to the truth, in %
    rel = [ln.get_ydata() for ln in bottom.get_lines() if len(ln.get_ydata()) == log.n_samples]
    np.testing.assert_allclose(rel[1][0], 100.0 * (2.0 - 1.2) / 1.2)
    # AND without a known truth there is no relative panel and the title says so
    unknown = plots.fig6_mass_estimates(synthetic_log(known_mass=False, extra=demo_extra("rates")))
    assert len(unknown.axes) == 1 and "true masses unknown" in unknown.axes[0].get_title()
