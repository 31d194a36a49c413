"""`gcs sweep` as a user runs it: real worker processes, a real local Ray cluster on loopback, an
interrupt and a resume, and `gcs sim --study --run` replaying a row."""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pyarrow.parquet as pq
import pytest

from tests.harness import free_udp_port

CONFIGS = Path(__file__).resolve().parents[2] / "configs"
GCS = [sys.executable, "-m", "gcs.cli"]

pytestmark = pytest.mark.integration


def small_study(tmp_path: Path, runs: int = 12, batch_runs: int = 4) -> Path:
    path = tmp_path / "small.yaml"
    path.write_text(textwrap.dedent(f"""\
        name: small
        team: {CONFIGS / 'square4.yaml'}
        runs: {runs}
        seed: 11
        batch_runs: {batch_runs}
        set:
          controller.mode: rates
          sim.controller_rate_hz: 100
          mission.duration_s: 8.0
        parameters:
          - key: vehicles[*].plant.mass_kg
            scale: {{uniform: [0.5, 1.5]}}
          - key: vehicles[*].initial.position_enu_m
            add: {{uniform: [-2.0, 2.0]}}
            each: component
        metrics: {{window_from_s: 4.0, converged_below_m: 0.05, log_rate_hz: 20}}
        """))
    return path


def sweep(study: Path, out: Path, *extra: str, timeout: float = 240) -> subprocess.CompletedProcess:
    return subprocess.run([*GCS, "sweep", "--study", str(study), "--out", str(out), *extra],
                          capture_output=True, text=True, timeout=timeout)


def rows(out: Path) -> list[dict]:
    return pq.read_table(out / "runs.parquet").to_pylist()


def same(a: list[dict], b: list[dict]) -> bool:
    """Equal rows, NaN equal to NaN."""
    def eq(x, y):
        return x == y or (isinstance(x, float) and isinstance(y, float)
                          and math.isnan(x) and math.isnan(y))
    return len(a) == len(b) and all(
        r.keys() == s.keys() and all(eq(r[k], s[k]) for k in r) for r, s in zip(a, b, strict=True))


def test_a_sweep_writes_its_table_and_a_replay_reproduces_the_worst_row(tmp_path):
    study = small_study(tmp_path)
    # WHEN swept on two local workers
    done = sweep(study, tmp_path / "out", "--workers", "2", "--csv")
    assert done.returncode == 0, done.stderr
    table = rows(tmp_path / "out")
    # THEN one row per run, in order, and the CSV beside it
    assert [r["run"] for r in table] == list(range(12))
    assert (tmp_path / "out" / "runs.csv").read_text().count("\n") == 13
    assert "12 runs" in done.stdout
    # AND the worst finished run, flown again by the printed command, gives its row exactly
    finished = [r for r in table if r["status"] == "ok"]
    worst = max(finished, key=lambda r: r["max_error_m"])
    replay = subprocess.run(
        [*GCS, "sim", "--study", str(study), "--run", str(worst["run"]), "--out",
         str(tmp_path / "replay"), "--no-figures", "--quiet"],
        capture_output=True, text=True, timeout=120)
    assert replay.returncode == 0, replay.stderr
    again = json.loads((tmp_path / "replay" / "row.json").read_text())
    expected = {k: (None if isinstance(v, float) and math.isnan(v) else v)
                for k, v in worst.items() if k not in ("status", "message")}
    assert again == expected
    assert (tmp_path / "replay" / "timeseries.csv").is_file()


def test_a_replay_refuses_options_that_would_change_the_run(tmp_path):
    study = small_study(tmp_path)
    done = subprocess.run([*GCS, "sim", "--study", str(study), "--run", "0", "--mode", "rates"],
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 2
    assert "--mode: a replay flies the study's run as the sweep did" in done.stderr
    done = subprocess.run([*GCS, "sim", "--study", str(study), "--run", "12"],
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 2 and "the study has runs 0..11" in done.stderr


def test_an_interrupted_sweep_resumes_where_it_stopped(tmp_path):
    study = small_study(tmp_path, runs=40, batch_runs=2)
    whole = sweep(study, tmp_path / "whole", "--workers", "2")
    assert whole.returncode == 0, whole.stderr
    # GIVEN a sweep on one worker, started as a script's background job is (SIGINT ignored, so
    # Python installs no Ctrl-C handler of its own), interrupted once its first batches are
    # written
    out = tmp_path / "cut"
    proc = subprocess.Popen([*GCS, "sweep", "--study", str(study), "--out", str(out),
                             "--workers", "1"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_IGN))
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and len(list((out / "parts").glob("*.parquet"))) < 2:
        time.sleep(0.05)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert "interrupted (SIGINT)" in err and "the same command resumes" in err
    kept = len(list((out / "parts").glob("*.parquet")))
    assert 2 <= kept < 20
    # WHEN the same command runs again
    again = sweep(study, out, "--workers", "2")
    # THEN it flies only what is missing, and the table is the uninterrupted one
    assert again.returncode == 0, again.stderr
    assert f"resuming: {2 * kept} runs already" in again.stderr
    assert same(rows(out), rows(tmp_path / "whole"))


@pytest.mark.alone
def test_a_local_ray_cluster_gives_the_same_rows_as_local_workers(tmp_path):
    study = small_study(tmp_path)
    local = sweep(study, tmp_path / "local", "--workers", "2")
    assert local.returncode == 0, local.stderr
    # GIVEN a one-machine Ray cluster on loopback, started as Ray's docs show
    port = free_udp_port()
    env = {**os.environ, "RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER": "0", "RAY_USAGE_STATS_ENABLED": "0"}
    ray = str(Path(sys.executable).with_name("ray"))
    start = subprocess.run([ray, "start", "--head", "--port", str(port), "--num-cpus", "2",
                            "--node-ip-address", "127.0.0.1", "--include-dashboard", "false",
                            "--disable-usage-stats"], capture_output=True, text=True, env=env,
                           timeout=120)
    assert start.returncode == 0, start.stderr
    try:
        # WHEN the study runs there (`auto`: the cluster this machine runs, as Ray names it)
        done = sweep(study, tmp_path / "ray", "--executor", "ray", "--address", "auto")
        assert done.returncode == 0, done.stderr
    finally:
        subprocess.run([ray, "stop", "--force"], capture_output=True, env=env, timeout=120)
    # THEN every row equals the local workers'
    assert same(rows(tmp_path / "ray"), rows(tmp_path / "local"))
