"""Scenario I from the ground, twice, against the px4 and ardupilot personalities and a mixed team.

What a user does with real vehicles, measured against the emulator's calibrated personalities:
one `vehicle-emu --fleet` of configs/square4.yaml's team booted on the ground at places up to
50 m apart (each vehicle's EKF origin below where it booted, as on real vehicles; the
ArduPilot ones on their ephemeral source port, learned), then `gcs fly --team FILE` exactly as
shipped (`fly.mode: auto`, go to start, 60 s of formation, land, disarm), and the same again
without restarting the vehicles. Per flight, from the flight's own records:

- exit status;
- formation error (report.json) mean and max for t >= 30 s;
- mass estimate error at t = 20 s, max over vehicles, in % of the truth (ArduPilot vehicles: of
  the thrust-equivalent mass m / thrust_scale, what its reported hover thrust gives);
- share of setpoints with the roll/pitch body-rate limit active (|p, q| at
  fly.rates.max_rate_radps; from the SET_ATTITUDE_TARGET in the tlog), rates mode only;
- heading error, max over vehicles and samples: ATTITUDE_QUATERNION's yaw against the yaw at
  the formation start (fly.heading: hold), from the tlog.
The last two from t = 10 s to the formation's end: the formation starts at the first
SET_ATTITUDE_TARGET to the vehicle after its last position setpoint and lasts the report's
time span; the landing that may follow in the same setpoints is not counted.

    python -m benchmarks.bench_from_ground [--team px4 --team mixed] [--duration-s 60] [--no-write]
        [--keep DIR]

Writes the "## From the ground, twice" section of docs/benchmarks.md (about 17 min). The team
`px4-sih-2026-12-04` flies the recorded SIH team file instead, beside the recorded flight.
"""

from __future__ import annotations

import argparse
import gzip
import json
import math
import platform
import shutil
import tempfile
from pathlib import Path

import numpy as np
import yaml

from flightkit import jitcache

jitcache.configure()  # numba's cache, before the compiled modules below are imported

from benchmarks.calibration.fit_heading_estimate import heading_mismatch  # noqa: E402
from benchmarks.docsection import write_section  # noqa: E402
from benchmarks.fleet import fleet, fly  # noqa: E402
from tests.harness import free_udp_port_block  # noqa: E402
from vehicle_emulator.calibration.replay import data_dir  # noqa: E402
from vehicle_emulator.config.personality import ARDUPILOT_DYNAMICS  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "benchmarks.md"
HEADING = "## From the ground, twice"
#: the section of the px4-sih-2026-12-04 team's rows and SIH's recorded one
SIH_HEADING = "## From the ground, twice: the px4 personality against the 2026-12-04 SIH flights"
TEAMS = {"px4": ("px4",) * 4, "ardupilot": ("ardupilot",) * 4,
         "mixed": ("px4", "ardupilot", "px4", "ardupilot"), "px4-sih-2026-12-04": ("px4",) * 4,
         "px4-sih": ("px4",) * 4}
#: the bundled team file for four real PX4 SIH vehicles (the docs' defaults): the kind px4-sih
#: flies it against the personality, booted where SIH boots (all four at its home)
SIH_CONFIG = "configs/square4_px4sih.yaml"
#: the section where flights of that file against real vehicles (--records) and the
#: personality's stand side by side
REAL_HEADING = "## Real PX4 SIH and the px4 personality: one team file, from the ground, twice"
#: the team file of the 2026-12-04 flights of four real PX4 SIH vehicles, flown as it was then
#: (the law read the reported velocity: fly.velocity_from_position_s 0), and what SIH gave
SIH_TEAM = "flights/2026-12-04/team_px4sih.yaml"
SIH_REPORT = "flights/2026-12-04/px4_rates_1st/report.json"
SIH_RECORDED = "real PX4 SIH, recorded"  # its row's team cell
SIH_FLOWN = {"fly": {"velocity_from_position_s": 0.0}}
# where each vehicle boots (team frame ENU, on the ground): a 50 m diamond around the formation
BOOT_XY_M = ((25.0, 0.0), (0.0, -25.0), (-25.0, 0.0), (0.0, 25.0))
FLIGHTS = ("first", "second")
#: per phase (hold: the 10 s before the formation; formation: from 10 s to its end), RMS over
#: the vehicles: the heading's 1 s drift beyond its yaw rate and the roll/pitch rate
PHASE_FIGURES = ("heading_d1_hold_deg", "heading_d1_formation_deg", "rp_rate_hold_dps",
                 "rp_rate_formation_dps")


def team_file(kind: str, work: Path, duration_s: float) -> Path:
    """configs/square4.yaml as shipped (the SIH team file as flown, for that kind), on free
    ports, each vehicle of its autopilot booting on the ground at BOOT_XY_M with its own EKF
    origin below it."""
    if kind == "px4-sih-2026-12-04":
        data = yaml.safe_load((data_dir() / SIH_TEAM).read_text())
        data["fly"].update(SIH_FLOWN["fly"])
    elif kind == "px4-sih":
        data = yaml.safe_load((ROOT / SIH_CONFIG).read_text())
    else:
        data = yaml.safe_load((ROOT / "configs" / "square4.yaml").read_text())
    data["name"] = f"square4-{kind}"
    data["mission"]["duration_s"] = duration_s
    data["faults"] = []
    data["emulator"] = {"origin": "own"}
    gcs_base, bind_base = free_udp_port_block(4), free_udp_port_block(4)
    for k, (v, autopilot) in enumerate(zip(data["vehicles"], TEAMS[kind], strict=True)):
        boot = (v["emulator"]["boot_position_enu_m"] if kind == "px4-sih"
                else [*BOOT_XY_M[k], 0.0])
        v["emulator"] = {"autopilot": autopilot, "boot_position_enu_m": boot}
        v["link"] = ({"local_port": gcs_base + k, "remote_port": bind_base + k}
                     if autopilot == "px4" else {"local_port": gcs_base + k, "learn_remote": True})
    path = work / f"{kind}.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def tlog_figures(tlog: Path, sysids: list[int], max_rate: float, formation_s: float) -> dict:
    """Heading error [deg] and the rate-limit share over the formation from t = 10 s to its end
    (``formation_s`` after its first rates setpoint; the landing that follows is not in it), per
    vehicle, from what was sent and reported (pymavlink reads the tlog)."""
    from pymavlink import mavutil

    conn = mavutil.mavlink_connection(str(tlog))
    last_pos = {k: -math.inf for k in sysids}
    setpoints: dict[int, list[tuple[float, float]]] = {k: [] for k in sysids}
    yaws: dict[int, list[tuple[float, ...]]] = {k: [] for k in sysids}
    types = ["SET_POSITION_TARGET_LOCAL_NED", "SET_ATTITUDE_TARGET", "ATTITUDE_QUATERNION"]
    while (msg := conn.recv_match(type=types)) is not None:
        t = msg._timestamp
        kind = msg.get_type()
        if kind == "ATTITUDE_QUATERNION":
            k = msg.get_srcSystem()
            if k in yaws:
                q1, q2, q3, q4 = msg.q1, msg.q2, msg.q3, msg.q4
                yaws[k].append((t, math.atan2(2 * (q1 * q4 + q2 * q3), 1 - 2 * (q3 * q3 + q4 * q4)),
                                msg.time_boot_ms * 1e-3, msg.yawspeed,
                                math.hypot(msg.rollspeed, msg.pitchspeed)))
        elif msg.target_system in sysids:
            k = msg.target_system
            if kind == "SET_POSITION_TARGET_LOCAL_NED":
                last_pos[k] = t
            else:
                setpoints[k].append((t, math.hypot(msg.body_roll_rate, msg.body_pitch_rate)))
    heading, limited = {}, {}
    phases: dict[str, dict[int, float]] = {key: {} for key in PHASE_FIGURES}
    for k in sysids:
        sp = np.array([s for s in setpoints[k] if s[0] > last_pos[k]])
        yw = np.array(yaws[k])
        if len(sp) == 0 or len(yw) == 0:
            heading[k] = limited[k] = math.nan
            for key in PHASE_FIGURES:
                phases[key][k] = math.nan
            continue
        t0 = sp[0, 0]
        t1 = min(sp[-1, 0], t0 + formation_s)
        after = sp[(sp[:, 0] >= t0 + 10.0) & (sp[:, 0] <= t1)]
        limited[k] = 100.0 * float(np.mean(after[:, 1] >= max_rate - 1e-4)) if len(after) else 0.0
        start = yw[np.searchsorted(yw[:, 0], t0), 1]
        late = yw[(yw[:, 0] >= t0 + 10.0) & (yw[:, 0] <= t1)]
        err = np.angle(np.exp(1j * (late[:, 1] - start)))
        heading[k] = float(np.degrees(np.abs(err).max())) if len(err) else math.nan
        # the 10 s before the formation (the autopilot holding the start) against the formation
        # from 10 s on: how far the heading moves in 1 s beyond its yaw rate's integral (the
        # estimate's own motion), and the roll/pitch rate RMS
        hold = yw[(yw[:, 0] >= t0 - 10.0) & (yw[:, 0] < t0)]
        for name, part in (("hold", hold), ("formation", late)):
            drift = heading_mismatch(part[:, 2], part[:, 1], part[:, 3])[1] if len(part) > 50 \
                else math.nan
            phases[f"heading_d1_{name}_deg"][k] = float(drift)
            phases[f"rp_rate_{name}_dps"][k] = (float(np.degrees(np.sqrt(np.mean(part[:, 4] ** 2))))
                                                if len(part) else math.nan)
    return {"heading_deg": heading, "limited_pct": limited, **phases}


def figures(out: Path, kind: str, max_rate: float) -> dict:
    report = json.loads((out / "report.json").read_text())
    t = np.asarray(report["t_s"], dtype=float)
    fe = np.asarray(report["formation_error_m"], dtype=float)
    late = t >= 30.0
    k20 = int(np.argmin(np.abs(t - 20.0)))
    mhat = np.asarray(report["mass_estimate_kg"][k20], dtype=float)
    truth = np.asarray(report["mass_true_kg"][k20], dtype=float)
    scale = np.array([ARDUPILOT_DYNAMICS.thrust_scale if a == "ardupilot" else 1.0
                      for a in TEAMS[kind]])
    mass_pct = 100.0 * np.abs(mhat - truth / scale) / (truth / scale)
    tl = tlog_figures(out / "flight.tlog", [1, 2, 3, 4], max_rate,  # square4's sysids
                      float(t[-1]) if len(t) else 0.0)
    mode = report["extra"]["mode"]
    return {
        "mode": mode,
        "t_end": float(t[-1]) if len(t) else 0.0,
        "fe_mean_30": float(np.nanmean(fe[late])) if late.any() else math.nan,
        "fe_max_30": float(np.nanmax(fe[late])) if late.any() else math.nan,
        "mass_pct_20": float(np.nanmax(mass_pct)),
        "limited_pct": (float(np.nanmax(list(tl["limited_pct"].values())))
                        if mode == "rates" else math.nan),
        "heading_deg": float(np.nanmax(list(tl["heading_deg"].values()))),
        # RMS over the vehicles
        **{key: float(np.sqrt(np.nanmean(np.square(list(tl[key].values())))))
           for key in PHASE_FIGURES},
        "late_pct": float(report["tick"]["late_pct"]),
        "outcome": report["extra"]["outcome"]["reason"].splitlines()[0],
    }


def fly_team(kind: str, work: Path, duration_s: float) -> list[dict]:
    team = team_file(kind, work, duration_s)
    max_rate = float(yaml.safe_load(team.read_text())["fly"]["rates"].get("max_rate_radps", 1.0))
    guided = ["--param", "GUID_OPTIONS=8"] if "ardupilot" in TEAMS[kind] else []
    rows = []
    # the same vehicles fly every flight: one fleet for all of them
    with fleet(team, *guided, log=work / f"{kind}-fleet.log"):
        for flight in FLIGHTS:
            out = work / f"{kind}-{flight}"
            f = fly(team, out, timeout_s=900.0)
            row = {"team": kind, "flight": flight, "exit": f.exit, "wall_s": f.wall_s}
            if f.report is not None:
                row |= figures(out, kind, max_rate)
            else:
                row["outcome"] = (f.stderr.strip().splitlines() or ["no report"])[-1]
            print(json.dumps(row), flush=True)
            rows.append(row)
    return rows


def recorded_sih_row(work: Path) -> dict:
    """The 2026-12-04 first flight of four real PX4 SIH vehicles through the same figures (its
    report.json and tlog from the recordings)."""
    src = data_dir() / SIH_REPORT
    out = work / "sih-recorded"
    out.mkdir(exist_ok=True)
    shutil.copy(src, out / "report.json")
    with gzip.open(src.parent / "flight.tlog.gz") as tlog, open(out / "flight.tlog", "wb") as dst:
        shutil.copyfileobj(tlog, dst)
    max_rate = float(yaml.safe_load((data_dir() / SIH_TEAM).read_text())["fly"]["rates"].get(
        "max_rate_radps", 1.0))
    return {"team": SIH_RECORDED, "flight": "first", "exit": 0,
            **figures(out, "px4-sih-2026-12-04", max_rate)}


def recorded_rows(label: str, folder: Path) -> list[dict]:
    """Flights of configs/square4_px4sih.yaml flown elsewhere (real vehicles): each subfolder
    of ``folder`` holding a `gcs fly --out` (report.json, flight.tlog), in name order, through
    the same figures, the rows' team cell ``label``."""
    max_rate = float(yaml.safe_load((ROOT / SIH_CONFIG).read_text())["fly"]["rates"].get(
        "max_rate_radps", 1.0))
    flights = sorted(d for d in folder.iterdir() if (d / "report.json").exists())
    if not flights:
        raise SystemExit(f"--records {label}={folder}: no subfolder holds a report.json")
    return [{"team": label, "flight": d.name, "exit": 0 if figs["outcome"] ==
             "formation complete" else 1, **figs}
            for d in flights for figs in [figures(d, "px4-sih", max_rate)]]


def _cell(x: float, fmt: str) -> str:
    return "-" if x is None or (isinstance(x, float) and math.isnan(x)) else format(x, fmt)


def kept_real_lines(doc: Path = DOC, replaced: frozenset[str] = frozenset()) -> list[str]:
    """The real vehicles' rows of the section as the doc has them, but those labelled as one of
    `replaced` (flights of real SITL are not rerun by this script: rows not given again by
    --records stay as measured)."""
    text = doc.read_text() if doc.exists() else ""
    if REAL_HEADING not in text:
        return []
    body = text.split(REAL_HEADING, 1)[1].split("\n## ", 1)[0]
    return [line for line in body.splitlines()
            if line.startswith("| ") and not line.startswith(("| team ", "| px4-sih "))
            and line.split("|")[1].strip() not in replaced]


def real_intro(rows: list[dict], kept: list[str] = ()) -> str:
    labels = sorted({r["team"] for r in rows} - {"px4-sih"}
                    | {line.split("|")[1].strip() for line in kept})
    records = " ".join(f'--records "{label}"=DIR' for label in labels)
    return (
        f"`python -m benchmarks.bench_from_ground --team px4-sih {records}` on "
        f"{platform.machine()}, Python {platform.python_version()}: `{SIH_CONFIG}` (Scenario I "
        "written for four PX4 v1.16 SIH vehicles after docs/gcs.md \"Flying PX4 / ArduPilot\", "
        "the docs' defaults) flown from the ground twice without restarting the vehicles: by "
        "`gcs fly --team " + SIH_CONFIG + " --out DIR/fN` (N = 1, 2) against four real PX4 "
        "v1.16.0 SIH SITL vehicles (airframe 10040, `px4 -i 0..3` in one loopback-only network "
        "namespace, COM_RC_IN_MODE 4, COM_RCL_EXCEPT 4, NAV_DLL_ACT 0; the rows of --records; "
        "a row in position mode was flown with `--mode position`: PX4's own position "
        "controller flying each vehicle's slot, no law), "
        "and by this script against one `vehicle-emu --fleet --team` of the same file (the px4 "
        "personality, booted where SIH boots; the rows px4-sih). The figures are those of "
        "\"From the ground, twice\", and two per phase, RMS over the vehicles, in the 10 s "
        "before the formation (hold: PX4 holding the start position) and in the formation from "
        "10 s on: the heading's drift in 1 s beyond its yaw rate's integral (D(1 s) of "
        "`benchmarks.calibration.fit_heading_estimate`: the estimate's own motion) and the "
        "roll/pitch rate RMS. Rows labelled `T_a 0` were flown before "
        "`fly.acceleration_from_velocity_s` (docs/gcs.md, \"The law's acceleration\"): the law "
        "read the accelerometer's acceleration alone; every other row flies its default, 0.5 s. "
        "Rows labelled `phi_h 0` and px4-sih fly the file as it is, with the vertical mass "
        "estimator (controller.gains.phi_horizontal 0, docs/gcs.md \"What the mass estimate "
        "reads\"); the other real rows were flown before it, with the paper's (1). Rows labelled "
        "`c 0.5` were flown with the law velocity's correction bounded at 0.5 m/s per axis "
        "(every other row: 1.5 m/s, docs/gcs.md \"The law's velocity\"); earlier real rows "
        "were too."
        + (" The real vehicles' rows not given by --records were measured by an earlier run "
           "with --records and are kept as they were (`--team px4-sih` alone flies the "
           "personality only)." if kept else ""))


def section(rows: list[dict], duration_s: float, heading: str = HEADING,
            kept: list[str] = ()) -> str:
    if heading == REAL_HEADING:
        head, rule, *body = table(rows, phases=True)
        lines = [heading, "", real_intro(rows, kept), "", head, rule, *kept, *body]
        return "\n".join(lines) + "\n"
    where = f"on {platform.machine()}, Python {platform.python_version()}"
    if heading == SIH_HEADING:
        intro = (
            f"`python -m benchmarks.bench_from_ground --team px4-sih-2026-12-04` {where}, "
            f"flown and measured as in \"From the ground, twice\" ({duration_s:g} s of "
            "formation): the team file of the 2026-12-04 flights of four real PX4 v1.16.0 SIH "
            f"vehicles (`{SIH_TEAM}` in the recordings: alpha_p 1, c_p 2, go-to-start tolerance "
            "0.5 m) as it was then, reading the reported velocity "
            "(`fly.velocity_from_position_s: 0`), against the px4 personality. \"real PX4 SIH, "
            "recorded\" is that day's first flight through the same figures (the second ended in "
            "preflight; five first flights that day held 0.26-0.59 / 0.53-0.95 m).")
        return "\n".join([heading, "", intro, ""] + table(rows)) + "\n"
    lines = [
        heading, "",
        f"`python -m benchmarks.bench_from_ground` {where}: configs/square4.yaml (Scenario I) as "
        "shipped, flown by `gcs fly --team FILE` with no other option (`fly.mode: auto`) "
        "against one `vehicle-emu --fleet` booted on the ground on a 50 m diamond, each vehicle "
        "with its own EKF origin below it (the team frame tied through four origins up to 50 m "
        "apart; ArduPilot vehicles on their own source port, learned). Each flight: go to "
        f"start, {duration_s:g} s of formation, land, disarm; then the same vehicles fly again. "
        "Formation error: the largest over the pairs (report.json), t >= 30 s. Mass: max over "
        "vehicles of |mhat - m| / m at 20 s (ArduPilot: of m / 1.069, the thrust-equivalent "
        "mass). From t = 10 s to the formation's end (not the landing): rate limit, the share "
        "of setpoints with the roll/pitch rate command at its limit, worst vehicle; heading, "
        "the largest |yaw - yaw at the formation start| (ATTITUDE_QUATERNION). The file keeps "
        "the paper's mass estimator (controller.gains.phi_horizontal 1), whose estimate wanders "
        "with PX4's tilt and velocity errors; the docs' file for real PX4 flies the vertical one "
        "(\"Real PX4 SIH and the px4 personality\" below).",
        "",
    ] + table(rows)
    return "\n".join(lines) + "\n"


def table(rows: list[dict], phases: bool = False) -> list[str]:
    """The rows as a Markdown table; ``phases``: with the PHASE_FIGURES columns (hold /
    formation)."""
    extra_head = (" heading drift in 1 s, hold / formation | roll/pitch rate RMS, hold / "
                  "formation |" if phases else "")
    lines = [
        "| team | flight | exit | mode | formation error mean / max, t >= 30 s [m] | mass error "
        "at 20 s | rate limit active after 10 s | heading error after 10 s | late ticks |"
        + extra_head,
        "|---|---|---|---|---|---|---|---|---|" + ("---|---|" if phases else ""),
    ]
    for r in rows:
        if "fe_max_30" not in r:
            lines.append(f"| {r['team']} | {r['flight']} | {r['exit']} | | {r['outcome']} | | | "
                         "| |" + (" | |" if phases else ""))
            continue
        extra = (f" {_cell(r['heading_d1_hold_deg'], '.2f')} / "
                 f"{_cell(r['heading_d1_formation_deg'], '.2f')} deg | "
                 f"{_cell(r['rp_rate_hold_dps'], '.1f')} / "
                 f"{_cell(r['rp_rate_formation_dps'], '.1f')} deg/s |" if phases else "")
        lines.append(
            f"| {r['team']} | {r['flight']} | {r['exit']} | {r['mode']} | "
            f"{_cell(r['fe_mean_30'], '.3f')} / {_cell(r['fe_max_30'], '.3f')} | "
            f"{_cell(r['mass_pct_20'], '.1f')} % | {_cell(r['limited_pct'], '.2f')} % | "
            f"{_cell(r['heading_deg'], '.1f')} deg | {r['late_pct']:.2f} % |" + extra)
    return lines


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--team", choices=sorted(TEAMS), action="append")
    ap.add_argument("--duration-s", type=float, default=60.0)
    ap.add_argument("--no-write", action="store_true")
    ap.add_argument("--records", action="append", default=[], metavar="LABEL=DIR",
                    help=f"flights of {SIH_CONFIG} flown against real vehicles (one `gcs fly "
                         "--out` per subfolder of DIR), shown beside the px4-sih team's rows")
    ap.add_argument("--keep", type=Path, metavar="DIR",
                    help="fly in DIR and keep each flight's records there (default: a temporary "
                         "folder, removed)")
    args = ap.parse_args()
    rows: list[dict] = []
    for spec in args.records:
        label, sep, folder = spec.partition("=")
        if not (label and sep and folder and Path(folder).is_dir()):
            raise SystemExit(f"--records {spec!r}: expected LABEL=DIR with DIR a folder")
        rows += recorded_rows(label, Path(folder))
    with tempfile.TemporaryDirectory() as tmp:
        work = args.keep or Path(tmp)
        work.mkdir(parents=True, exist_ok=True)
        for kind in args.team or list(TEAMS):
            if kind == "px4-sih-2026-12-04":
                rows.append(recorded_sih_row(work))
            rows += fly_team(kind, work, args.duration_s)
    # the SIH team files (with SIH's own rows) have their sections; the shipped teams share one
    sih = {"px4-sih-2026-12-04", SIH_RECORDED}
    real = {"px4-sih"} | {spec.partition("=")[0] for spec in args.records}
    for heading, part in ((HEADING, [r for r in rows if r["team"] not in sih | real]),
                          (SIH_HEADING, [r for r in rows if r["team"] in sih]),
                          (REAL_HEADING, [r for r in rows if r["team"] in real])):
        if not part:
            continue
        kept = (kept_real_lines(replaced=frozenset(spec.partition("=")[0]
                                                   for spec in args.records))
                if heading == REAL_HEADING else [])
        text = section(part, args.duration_s, heading, kept)
        print(text)
        if not args.no_write:
            write_section(DOC, heading, text)


if __name__ == "__main__":
    main()
