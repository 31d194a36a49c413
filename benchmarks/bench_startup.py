"""Benchmark of start-up: how long each program takes to be ready, on an empty cache and a warm one.

    python -m benchmarks.bench_startup [--repeat 2] [--no-write]

"Cold" is a new, empty HOME (so numba's, matplotlib's and pip's caches are empty: a fresh
machine after `pip install` without `gcs compile`); "warm" runs again with the same HOME, which
is also what every run after `make install` (it runs `gcs compile`) sees. Measured:

* `vehicle-emu --id 1`: from the process start to its `vehicle-emu: ready:` line;
* `gcs sim --team configs/square4.yaml --duration-s 1 --no-figures`: the whole run;
* `gcs fly --emulators` (Scenario I on free ports, 1 s of formation, end action hold): from the
  start to every vehicle heard (the `phase preflight` log line), to the formation start, and to
  the exit;
* `gcs compile`: the whole run (what `make install` adds).

Writes the "## Start-up" section of docs/benchmarks.md.
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import yaml

from benchmarks.bench_sim import update_section
from flightkit.fleet_protocol import READY_PREFIX
from tests.harness import free_udp_port, free_udp_port_block

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "benchmarks.md"
HEADING = "## Start-up"


def _env(home: Path) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items()
           if k not in ("NUMBA_CACHE_DIR", "XDG_CACHE_HOME", "XDG_CONFIG_HOME", "MPLCONFIGDIR")}
    env.update(HOME=str(home), PYTHONUNBUFFERED="1")
    return env


def _until(argv: list[str], env: dict[str, str], marks: dict[str, str],
           timeout_s: float = 300.0, stop_after: str | None = None) -> dict[str, float]:
    """Run argv; seconds from the start to the first output line containing each mark, and
    'exit' (the exit time, or the time `stop_after` was seen when the process is then stopped)."""
    t0 = time.monotonic()
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            env=env, cwd=ROOT)
    seen: dict[str, float] = {}
    out: list[str] = []
    assert proc.stdout is not None
    for line in proc.stdout:
        out.append(line)
        now = time.monotonic() - t0
        for key, text in marks.items():
            if key not in seen and text in line:
                seen[key] = now
        if stop_after is not None and stop_after in seen:
            proc.terminate()
            break
        if now > timeout_s:
            proc.kill()
            break
    code = proc.wait(timeout=60)
    seen["exit"] = time.monotonic() - t0
    missing = [k for k in marks if k not in seen]
    if missing or (stop_after is None and code != 0):
        raise SystemExit(f"{argv[2:4]}: exit {code}, missing {missing}:\n{''.join(out)[-3000:]}")
    return seen


def _team(work: Path) -> Path:
    data = yaml.safe_load((ROOT / "configs" / "square4.yaml").read_text())
    bind, gcs = free_udp_port_block(4), free_udp_port_block(4)
    for k, v in enumerate(data["vehicles"]):
        v["link"] = {"local_port": gcs + k, "remote_port": bind + k}
    path = work / "team.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def measure(work: Path, cold: dict[str, float], warm: dict[str, float]) -> None:
    """Each program on its own new HOME (cold), then again on it (warm)."""
    py = sys.executable

    def twice(name: str, run) -> None:  # noqa: ANN001
        home = work / f"home-{name}"
        home.mkdir()
        cold.update(run(_env(home)))
        warm.update(run(_env(home)))

    def emu(env: dict[str, str]) -> dict[str, float]:
        seen = _until([py, "-m", "vehicle_emulator", "--id", "1", "--bind",
                       f"127.0.0.1:{free_udp_port()}", "--remote", f"127.0.0.1:{free_udp_port()}"],
                      env, {"ready": READY_PREFIX}, stop_after="ready")
        return {"emu_ready": seen["ready"]}

    def sim(env: dict[str, str]) -> dict[str, float]:
        seen = _until([py, "-m", "gcs.cli", "sim", "--team", "configs/square4.yaml",
                       "--duration-s", "1", "--no-figures", "--quiet", "--out",
                       str(work / "sim")], env, {})
        return {"sim_total": seen["exit"]}

    def fly(env: dict[str, str]) -> dict[str, float]:
        seen = _until([py, "-m", "gcs.cli", "fly", "--team", str(_team(work)), "--emulators",
                       "--mode", "rates", "--duration-s", "1", "--end-action", "hold",
                       "--no-figures", "--status", "off", "--log-level", "INFO", "--out",
                       str(work / "fly")],
                      env, {"heard": "phase preflight", "formation": "phase formation"})
        return {"fly_heard": seen["heard"], "fly_formation": seen["formation"],
                "fly_total": seen["exit"]}

    twice("emu", emu)
    twice("sim", sim)
    twice("fly", fly)


def measure_compile(home: Path) -> float:
    return _until([sys.executable, "-m", "gcs.cli", "compile"], _env(home), {})["exit"]


def section(cold: list[dict[str, float]], warm: list[dict[str, float]],
            compile_s: list[float]) -> str:
    def cell(rows: list[dict[str, float]], key: str) -> str:
        values = [r[key] for r in rows]
        return f"{statistics.median(values):.1f}" + (
            f" ({min(values):.1f}-{max(values):.1f})" if len(values) > 1 else "")

    rows = [
        ("`vehicle-emu --id 1`: ready line", "emu_ready"),
        ("`gcs sim` (1 s of Scenario I, no figures): whole run", "sim_total"),
        ("`gcs fly --emulators`: every vehicle heard", "fly_heard"),
        ("`gcs fly --emulators`: formation starts", "fly_formation"),
        ("`gcs fly --emulators` (1 s of formation, hold): whole run", "fly_total"),
    ]
    lines = [
        "",
        f"`python -m benchmarks.bench_startup` on {platform.machine()}, {os.cpu_count()} CPU(s), "
        f"Python {platform.python_version()}; median (range) of {len(cold)} run(s) each, in "
        "seconds. Cold: a new empty HOME (nothing compiled, as after a bare `pip install`); warm: "
        "the same HOME again (as every run after `make install`, which runs `gcs compile`).",
        "",
        "| start-up | cold (s) | warm (s) |",
        "|---|---|---|",
    ]
    lines += [f"| {label} | {cell(cold, key)} | {cell(warm, key)} |" for label, key in rows]
    med = statistics.median(compile_s)
    lines += [
        f"| `gcs compile` on an empty cache (part of `make install`) | {med:.1f} | - |",
        "",
        "In `gcs fly --emulators` the fleet and the ground station compile at the same time, one "
        "core each; the connect timeout (60 s by default) only starts once the ground station's "
        "own compile is done, and the fleet is waited for until it reports ready.",
    ]
    return "\n".join(lines)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=2)
    parser.add_argument("--no-write", action="store_true")
    args = parser.parse_args()
    cold, warm, compile_s = [], [], []
    for _ in range(args.repeat):
        with tempfile.TemporaryDirectory() as tmp:
            cold.append({})
            warm.append({})
            measure(Path(tmp), cold[-1], warm[-1])
            print(f"cold {cold[-1]}\nwarm {warm[-1]}", flush=True)
        with tempfile.TemporaryDirectory() as tmp:
            compile_s.append(measure_compile(Path(tmp)))
            print(f"gcs compile {compile_s[-1]:.1f} s", flush=True)
    body = section(cold, warm, compile_s)
    print(body)
    if not args.no_write:
        update_section(DOC, HEADING, body)
        print(f"updated {DOC}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
