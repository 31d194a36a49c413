"""Smoke tests of every `gcs` command that needs no vehicle: sim, check, plot, and their errors."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

from gcs.cli import main

CONFIGS = Path(__file__).resolve().parents[2] / "configs"


def test_sim_writes_report_timeseries_and_figures(tmp_path, capsys):
    # GIVEN Scenario I WHEN simulated for 3 s
    code = main(
        [
            "sim",
            "--team",
            str(CONFIGS / "square4.yaml"),
            "--out",
            str(tmp_path),
            "--duration-s",
            "3",
            "--quiet",
        ]
    )
    # THEN it succeeds, prints the summary and writes the records
    assert code == 0
    out = capsys.readouterr().out
    assert "formation error" in out and "UAV" in out
    report = json.loads((tmp_path / "report.json").read_text())
    assert report["schema"] == "formation-flight-report/1" and report["source"] == "sim"
    assert report["t_s"][-1] == pytest.approx(3.0)
    assert len(report["mass_estimate_kg"][0]) == 4
    assert (tmp_path / "timeseries.csv").stat().st_size > 10_000
    for name in ("fig2_formation.png", "fig6_mass_estimates.png", "fig7_inertia_estimates.png"):
        assert (tmp_path / name).stat().st_size > 10_000


def test_sim_both_controllers_writes_the_comparison_and_plot_redraws_it(tmp_path, capsys):
    # GIVEN the mass-drop scenario, both laws, 2 s
    code = main(
        [
            "sim",
            "--team",
            str(CONFIGS / "square4_massdrop.yaml"),
            "--controller",
            "both",
            "--out",
            str(tmp_path / "run"),
            "--duration-s",
            "2",
            "--quiet",
        ]
    )
    assert code == 0
    for part in ("adaptive", "baseline"):
        assert (
            json.loads((tmp_path / "run" / part / "report.json").read_text())["controller"] == part
        )
    assert (tmp_path / "run" / "fig8_adaptive_z.png").is_file()
    assert (tmp_path / "run" / "fig9_baseline_z.png").is_file()
    # WHEN the figures are redrawn elsewhere from the time series alone
    assert main(["plot", str(tmp_path / "run"), "--out", str(tmp_path / "redraw")]) == 0
    # THEN the same figure files appear
    assert (tmp_path / "redraw" / "fig9_baseline_z.png").stat().st_size > 10_000
    assert (tmp_path / "redraw" / "adaptive" / "fig2_formation.png").is_file()
    capsys.readouterr()


def test_plot_of_a_directory_without_records_fails_clearly(tmp_path, capsys):
    assert main(["plot", str(tmp_path)]) == 2
    assert "holds no timeseries.csv" in capsys.readouterr().err


@pytest.mark.parametrize("how", ["positional", "--team"])
def test_check_prints_what_it_understood(capsys, how):
    # GIVEN the team file as `gcs check FILE` (as the docs write it) or as `--team FILE`
    path = str(CONFIGS / "square4.yaml")
    argv = ["check", path] if how == "positional" else ["check", "--team", path]
    # WHEN checked THEN it prints what it understood
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "square4" in out and "4 vehicles" in out


@pytest.mark.parametrize(
    ("args", "message"),
    [
        ([], r"gcs check: error: a team file is required: gcs check FILE \(or --team FILE\)"),
        (
            ["a.yaml", "--team", "b.yaml"],
            r"gcs check: error: give the team file once, as FILE or as --team FILE, not both "
            r"\(got a\.yaml and --team b\.yaml\)",
        ),
    ],
)
def test_check_wants_exactly_one_team_file(capsys, args, message):
    # GIVEN no team file, or one as FILE and another as --team
    # WHEN checked THEN a usage error (exit 2) says what to give
    with pytest.raises(SystemExit) as exit_:
        main(["check", *args])
    assert exit_.value.code == 2
    err = capsys.readouterr().err
    assert "usage: gcs check [-h] (FILE | --team FILE)" in err
    assert re.search(message, err), err


def test_bad_config_is_one_clear_line_and_exit_2(tmp_path, capsys):
    # GIVEN a config with a negative mass
    text = (
        (CONFIGS / "square4.yaml")
        .read_text()
        .replace("      mass_kg: 0.35", "      mass_kg: -0.35", 1)
    )
    bad = tmp_path / "bad.yaml"
    bad.write_text(text)
    # WHEN checked or simulated THEN the command fails with one line naming the key path
    for argv in (
        ["check", "--team", str(bad)],
        ["sim", "--team", str(bad), "--out", str(tmp_path)],
    ):
        assert main(argv) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1
        assert "vehicles[2].plant.mass_kg" in err and "-0.35" in err


def test_missing_config_file_is_reported(tmp_path, capsys):
    assert main(["check", "--team", str(tmp_path / "nope.yaml")]) == 2
    assert "nope.yaml" in capsys.readouterr().err


def test_console_script_is_installed_and_runs():
    # GIVEN the installed entry point WHEN asked for help THEN it lists the commands
    exe = Path(sys.executable).with_name("gcs")
    result = subprocess.run([str(exe), "--help"], capture_output=True, text=True, timeout=60)
    assert result.returncode == 0
    assert all(word in result.stdout for word in ("sim", "check", "plot"))


def test_fly_help_says_what_it_does_its_exit_statuses_and_defaults(capsys):
    # GIVEN `gcs fly --help`
    with pytest.raises(SystemExit) as exit_:
        main(["fly", "--help"])
    assert exit_.value.code == 0
    out = capsys.readouterr().out
    # THEN it names the sequence, in order
    steps = [re.search(rf"^  {step} ", out, re.MULTILINE) for step in
             ("connect", "preflight", "arm", "offboard", "formation", "land")]
    assert all(steps), out
    assert [m.start() for m in steps] == sorted(m.start() for m in steps)
    # AND every exit status with its meaning, one per line (the description's line breaks kept)
    for status, meaning in ((0, "flown"), (1, "aborted"), (2, "configuration or setup error"),
                            (130, "operator abort")):
        assert re.search(rf"^  {status} +{meaning}", out, re.MULTILINE), out
    # AND every option that takes a value states its default
    flat = " ".join(out.split())
    for option in ("--mode", "--controller", "--tick-rate-hz", "--duration-s", "--end-action",
                   "--out DIR", "--status", "--connect-timeout-s", "--log-level"):
        help_text = flat.split(f" {option}", 1)[1].split(" --", 1)[0]
        assert "(default: " in help_text, (option, help_text)
