"""Today's `gcs fly` against each emulator personality, beside the team's recorded SITL flights.

For each autopilot, the team file of the recorded formation flight
(FLIGHTS below, `<autopilot>/`: the team's recordings, $SITL_DATA_DIR/flights or outside this repository) is flown with `gcs fly --mode rates --emulators`
against `vehicle-emu` with that personality, and with `nominal` (the paper's nominal model) for
contrast, on free loopback ports. The SITL vehicles all booted at one home (their origins
coincided by accident: `gcs fly` cannot yet tie separate origins together), so the emulated team
shares one origin too; each vehicle starts on the ground below its team-file position (the
ground station refuses coinciding start positions) and takes off. Figures are computed by the same code from the recorded
report.json and from ours: formation error at 30 s, mean / max over t >= 30 s and at the end,
velocity error at the end, mass estimate error at 10 s, and how often the body-rate limit was
active in the formation phase. Writes the "## Emulator personalities against SITL" section of
docs/benchmarks.md.

    python -m benchmarks.bench_personalities [--autopilot px4] [--no-write]
    python -m benchmarks.bench_personalities --autopilot px4 --mode attitude --from-hover --no-write
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml

from flightkit import jitcache

jitcache.configure()  # numba's cache, before the compiled modules below are imported

from benchmarks.docsection import write_section  # noqa: E402
from benchmarks.fleet import fleet  # noqa: E402
from benchmarks.fleet import fly as gcs_fly  # noqa: E402
from tests.harness import free_udp_port_block  # noqa: E402
from vehicle_emulator.calibration.replay import data_dir  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "benchmarks.md"
HEADING = "## Emulator personalities against SITL"
TEAMS = {"px4": "px4/square4_px4sih.yaml", "ardupilot": "ardupilot/sitl4_relay.yaml"}
TAKEOFF_M = 5.0
BOOTED_S = 10.0  # the fleet runs this long before `gcs fly` starts (past every arming readiness)
SITL_NAMES = {"px4": "PX4 v1.16.0 SIH", "ardupilot": "ArduCopter 4.7.0-dev SITL"}

#: the recorded flights: $SITL_DATA_DIR/flights, else the shared data folder beside the checkout
FLIGHTS = data_dir() / "flights"


def team_for(autopilot: str, personality: str, work: Path, from_hover: bool = False) -> Path:
    """The recorded flight's team file on free ports, every vehicle on the ground below its
    initial position, flown by the given emulator personality (from_hover: every vehicle's
    initial mass estimate from its hover, `estimates.mhat: from_hover`)."""
    data = yaml.safe_load((FLIGHTS / TEAMS[autopilot]).read_text())
    gcs_base = free_udp_port_block(len(data["vehicles"]))
    emu_base = free_udp_port_block(len(data["vehicles"]))
    for k, v in enumerate(data["vehicles"]):
        v["link"] = {"local_port": gcs_base + k, "remote_host": "127.0.0.1",
                     "remote_port": emu_base + k}
        v["initial"]["position_enu_m"][2] = 0.0
        if from_hover:
            v["estimates"]["mhat"] = "from_hover"
    data["fly"]["start"] = "takeoff"
    # at the recorded 2.5 m the vehicles whose initial mass estimate is half their mass sink
    # through the 0.5 m geofence floor at the formation start, against both personalities (one
    # of the team's SITL attempts did the same); 5 m leaves room for that sink
    data["fly"]["takeoff_altitude_m"] = TAKEOFF_M
    # the gains today's gcs fly flies in rates and attitude mode (the bundled configs'; the
    # recorded flights' paper gains are refused by the cascade criterion on both autopilots)
    bundled = yaml.safe_load((ROOT / "configs" / "square4.yaml").read_text())["fly"]
    for mode in ("rates", "attitude"):
        data["fly"][mode] = bundled[mode]
    # and each vehicle's initial mass estimate from its hover: at those gains the recorded
    # estimates (half the mass on two vehicles) sink it through the floor at the formation start
    data["fly"]["initial_mass"] = bundled["initial_mass"]
    # as the recorded SITL flights: the law starts where the takeoff left the vehicles
    data["fly"]["go_to_start"] = {"enabled": False}
    data["emulator"] = {"autopilot": personality, "origin": "shared"}
    path = work / f"{autopilot}-{personality}.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def ardupilot_args(team: Path) -> list[str]:
    """What the team's ArduCopter SITL flight set up around today's `gcs fly` (its README): a
    relay to fixed ports (here a forced bind), GUID_OPTIONS 8 (vehicle1.parm), the
    message-intervals file (HEARTBEAT and EXTENDED_SYS_STATE at 5 Hz), and vehicles past their
    boot (the flight was the second of the same SITL processes)."""
    data = yaml.safe_load(team.read_text())
    intervals = team.with_suffix(".intervals")
    intervals.write_text("0 200\n245 200\n")
    return ["--bind-base", str(data["vehicles"][0]["link"]["remote_port"]),
            "--param", "GUID_OPTIONS=8", "--param", "EMU_BOOT_SCALE=0",
            "--message-intervals", str(intervals)]


def fly(team: Path, out: Path, personality: str, mode: str = "rates") -> dict:
    """The fleet first, as the SITL vehicles were up before the ground station started: today's
    `gcs fly` arms once, and PX4 refuses to arm for its first 3 s after boot."""
    extra = ardupilot_args(team) if personality == "ardupilot" else []
    with fleet(team, *extra):
        time.sleep(BOOTED_S)
        flight = gcs_fly(team, out, "--mode", mode, timeout_s=600.0)
    if flight.report is None:
        raise SystemExit(f"gcs fly exited {flight.exit} without a report:\n"
                         f"{flight.stdout[-2000:]}\n{flight.stderr[-2000:]}")
    return {"exit": flight.exit, "report": flight.report,
            "last_line": (flight.stdout.strip().splitlines() or [""])[0]}


def figures(report: dict) -> dict:
    t = np.asarray(report["t_s"], dtype=float)
    fe = np.asarray(report["formation_error_m"], dtype=float)
    ve = np.asarray(report["velocity_error_mps"], dtype=float)
    late = t >= 30.0
    if not late.any():  # the flight ended early (its outcome says why)
        late = t >= t[-1]
    k10 = int(np.argmin(np.abs(t - 10.0)))
    m_err = np.abs(np.asarray(report["mass_estimate_kg"][k10], dtype=float)
                   - np.asarray(report["mass_true_kg"][k10], dtype=float))
    formation_ticks = report["tick"]["ticks"]
    limited = [v["limited_ticks"] / max(formation_ticks, 1) for v in report["link"].values()]
    return {
        "fe_30": float(fe[int(np.argmin(np.abs(t - 30.0)))]),
        "fe_mean_30": float(np.nanmean(fe[late])),
        "fe_max_30": float(np.nanmax(fe[late])),
        "fe_end": float(fe[-1]),
        "ve_end": float(ve[-1]),
        "mass_err_10": float(m_err.max()),
        "limited_pct": 100.0 * float(np.mean(limited)),
        "late_pct": float(report["tick"]["late_pct"]),
        "t_end": float(t[-1]),
        "outcome": report["extra"]["outcome"]["reason"],
    }


def row(label: str, f: dict) -> str:
    if f["t_end"] < 30.0:
        return (f"| {label} | ended at {f['t_end']:.1f} s: {f['outcome']} | | | | | "
                f"{f['limited_pct']:.0f} % | {f['late_pct']:.1f} % |")
    return (f"| {label} | {f['fe_30']:.3f} | {f['fe_mean_30']:.3f} / {f['fe_max_30']:.3f} | "
            f"{f['fe_end']:.3f} | {f['ve_end']:.3f} | {f['mass_err_10']:.3f} | "
            f"{f['limited_pct']:.0f} % | {f['late_pct']:.1f} % |")


def _bundled_rates_gains() -> str:
    """configs/square4.yaml's fly.rates gains as the docs write them ("k_eps 1.5, ...")."""
    rates = yaml.safe_load((ROOT / "configs" / "square4.yaml").read_text())["fly"]["rates"]
    return ", ".join(f"{k} {rates[k]:g}" for k in ("k_eps", "k_eps_yaw", "alpha_p", "c_p"))


def section(results: dict[str, dict[str, dict]]) -> str:
    lines = [
        HEADING, "",
        "`.venv/bin/python -m benchmarks.bench_personalities`: today's `gcs fly --mode rates` "
        "flies the team file of each recorded SITL formation flight (the team's recordings, "
        "kept outside this repository) against `vehicle-emu` with that autopilot's personality "
        "and with `nominal`; each table's first row is the recorded SITL flight (the paper's "
        "gains, k_eps 8, the recorded initial estimates) through the same figures. Ours fly the "
        f"bundled configs' `fly.rates` gains ({_bundled_rates_gains()}; the cascade criterion "
        "refuses the paper's on both autopilots, docs/gcs.md), `fly.initial_mass: from_hover`, "
        "no go-to-start (the recorded flights started where the takeoff left them) and a "
        "takeoff to 5 m instead of 2.5 m. Errors in m and m/s; mass error = max over vehicles "
        "of |estimate - truth| at 10 s [kg] (ArduPilot: of the thrust-equivalent mass m / "
        "1.069); rate limit = share of formation ticks with the 1 rad/s body-rate limit active "
        "(mean over vehicles). The px4 row is the floor the personality's EKF2-like estimate "
        "wander leaves at these gains (without it: the nominal row). The ardupilot rows have "
        "what the team's ArduCopter flight set up around `gcs fly`: fixed ports (a forced "
        "bind; SITL needed a UDP relay), GUID_OPTIONS 8, the message-intervals file, vehicles "
        "past their boot.",
        "",
    ]
    for autopilot, runs in results.items():
        lines += [f"### {SITL_NAMES[autopilot]} team", "",
                  "| flight | formation error at 30 s | mean / max for t >= 30 s | at the end "
                  "| velocity error at the end | mass error at 10 s | rate limit active "
                  "| late ticks |",
                  "|---|---|---|---|---|---|---|---|"]
        for label, f in runs.items():
            lines.append(row(label, f))
        lines.append("")
    return "\n".join(lines) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--autopilot", choices=sorted(TEAMS), action="append")
    ap.add_argument("--no-write", action="store_true")
    ap.add_argument("--mode", choices=("rates", "attitude"), default="rates",
                    help="gcs fly's control mode (the section written to the docs is rates)")
    ap.add_argument("--from-hover", action="store_true",
                    help="estimates.mhat: from_hover for every vehicle (gcs fly's hover estimate)")
    args = ap.parse_args()
    results: dict[str, dict[str, dict]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        for autopilot in args.autopilot or sorted(TEAMS, reverse=True):  # px4, ardupilot
            recorded = json.loads((FLIGHTS / TEAMS[autopilot]).with_name("report.json")
                                  .read_text())
            runs = {f"recorded {SITL_NAMES[autopilot]}": figures(recorded)}
            for personality in (autopilot, "nominal"):
                r = fly(team_for(autopilot, personality, work, args.from_hover),
                        work / f"{autopilot}-{personality}", personality, args.mode)
                print(f"{autopilot} team, {personality}: exit {r['exit']}: {r['last_line']}",
                      flush=True)
                runs[f"vehicle-emu {personality} (exit {r['exit']})"] = figures(r["report"])
            results[autopilot] = runs
    text = section(results)
    print(text)
    if not args.no_write:
        if args.mode != "rates" or args.from_hover:
            raise SystemExit("the docs' section is today's rates mode with the file's estimates: "
                             "use --no-write with --mode/--from-hover")
        write_section(DOC, HEADING, text)


if __name__ == "__main__":
    main()
