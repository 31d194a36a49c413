"""Scenario I over impaired links: each control mode x latency x loss, with 10 ms jitter.

Every case flies configs/square4.yaml's Scenario I (60 s, from 10 m) with `gcs fly` against
`vehicle-emu --fleet` with the nominal personality (the paper's model, its loops declared as
`fly.response`, as the integration tests do), on free loopback ports. From the formation's
start every link, both directions, gets `packet_loss` with the case's latency, 0-10 ms uniform
jitter and loss probability. The gains are what a user gets by following the ground station:
`fly.link_delay_s` is set to latency + jitter (the most a packet waits), and where the paper's
gains (alpha_p 2, c_p 4, k_eps 6, k_eps_yaw 4) fail the cascade criterion there, its proposal is
flown (gcs/control/cascade.py `stable_gains`); the initial mass comes from the hover
(`fly.initial_mass: from_hover`, the bundled default). Beside each, `gcs sim` of the same team and
gains in-process (no link; rates only, as this benchmark has always compared them).

Each case is flown with delay compensation (`fly.predict: true`, gcs/control/predict.py; the criterion
then judges the compensated loops) and without it; the gains are the criterion's for that setting.

Figures: formation error at 30 s and 60 s, its max for t >= 30 s, the largest mass-estimate error
at 20 s, the true telemetry age p50 and the TIMESYNC round trip p50 of the flight, and with
compensation the predictor's position error p99 against what the vehicles later reported for the
same instant (the nominal personality reports its true state) beside the error of the sample
held without prediction. Writes the "## Link latency, jitter and loss" section and
docs/figures/bench_links.png.

    python -m benchmarks.bench_links [--latency-ms 0 50] [--loss 0 0.2] [--mode rates]
                                     [--predict on off] [--no-write]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import yaml

from flightkit import jitcache

jitcache.configure()  # numba's cache, before the compiled modules below are imported

from benchmarks.docsection import write_section  # noqa: E402
from benchmarks.fleet import fleet  # noqa: E402
from benchmarks.fleet import fly as gcs_fly  # noqa: E402
from gcs.config import load_team  # noqa: E402
from gcs.control.cascade import (  # noqa: E402
    NOMINAL_RESPONSE,
    CascadeGains,
    laplacian_eigenvalues,
    stable_gains,
    verdict,
)
from gcs.control.position import phi  # noqa: E402
from tests.harness import free_udp_port_block  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]

DOC = ROOT / "docs" / "benchmarks.md"
FIGURE = ROOT / "docs" / "figures" / "bench_links.png"
HEADING = "## Link latency, jitter and loss"
SQUARE4 = ROOT / "configs" / "square4.yaml"
JITTER_MS = 10.0
DURATION_S = 60.0
PAPER = CascadeGains(alpha_p=2.0, c_p=4.0, k_eps=6.0, k_eps_yaw=4.0)
TICK_HZ = 100.0


def gains_at(mode: str, delay_s: float, predicted: bool) -> tuple[CascadeGains | None, str]:
    """The paper's gains if the criterion passes them at delay_s, else its proposal."""
    team = load_team(SQUARE4)
    eig = laplacian_eigenvalues(team.laplacian())
    ok, _ = verdict(mode, PAPER, NOMINAL_RESPONSE, eig, TICK_HZ, delay_s, "nominal", predicted)
    if ok:
        return PAPER, "paper"
    g = stable_gains(mode, PAPER, NOMINAL_RESPONSE, eig, TICK_HZ, delay_s, predicted)
    return g, "proposed" if g is not None else "none stable"


def team_file(work: Path, mode: str, gains: CascadeGains, delay_s: float, latency_ms: float,
              loss: float, *, predicted: bool = True, for_sim: bool = False) -> Path:
    data = yaml.safe_load(SQUARE4.read_text())
    data["mission"]["duration_s"] = DURATION_S
    gcs_base, emu_base = free_udp_port_block(4), free_udp_port_block(4)
    for k, v in enumerate(data["vehicles"]):
        v["link"] = {"local_port": gcs_base + k, "remote_port": emu_base + k}
        if for_sim:  # what the hover gives the flight, at rest: phi(0) m / alpha_m (docs/gcs.md)
            g = data["controller"]["gains"]
            phi0 = float(phi(np.zeros((1, 3)), g["sigma_a"])[0])
            v["estimates"]["mhat"] = phi0 * v["plant"]["mass_kg"] / g["alpha_m"]
    data["emulator"] = {"autopilot": "nominal", "origin": "shared"}
    response = dataclasses.asdict(NOMINAL_RESPONSE)
    del response["source"]
    fly = data["fly"]
    fly["response"] = response
    fly["link_delay_s"] = delay_s
    fly["predict"] = predicted
    fly["initial_mass"] = "from_hover"
    fly["geofence"]["min_enu_m"][2] = 0.5
    fly[mode].update(alpha_p=gains.alpha_p, c_p=gains.c_p)
    if mode == "rates":
        fly["rates"].update(k_eps=gains.k_eps, k_eps_yaw=gains.k_eps_yaw)
    if for_sim:  # gcs sim reads controller.gains, not fly.<mode>
        data["controller"]["gains"].update(alpha_p=gains.alpha_p, c_p=gains.c_p,
                                           k_eps=gains.k_eps, k_eps_yaw=gains.k_eps_yaw)
    data["faults"] = [] if for_sim else [
        {"kind": "packet_loss", "vehicle": k, "at_s": 0.0, "probability": loss,
         "latency_ms": latency_ms, "jitter_ms": JITTER_MS} for k in (1, 2, 3, 4)]
    path = work / ("sim.yaml" if for_sim else "team.yaml")
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def fly(team: Path, out: Path, mode: str) -> dict:
    with fleet(team):
        flight = gcs_fly(team, out, "--mode", mode, "--end-action", "hold", timeout_s=600.0)
    if flight.report is None:
        last = (flight.stderr.strip().splitlines() or [""])[-1]
        return {"exit": flight.exit, "report": None, "why": last}
    return {"exit": flight.exit, "report": flight.report, "why": ""}


def sim(team: Path, out: Path) -> dict | None:
    proc = subprocess.run([sys.executable, "-m", "gcs.cli", "sim", "--team", str(team),
                           "--mode", "rates", "--out", str(out), "--no-figures"],
                          capture_output=True, text=True, timeout=600)
    report = out / "report.json"
    return json.loads(report.read_text()) if proc.returncode == 0 and report.exists() else None


def figures(report: dict) -> dict:
    t = np.asarray(report["t_s"], dtype=float)
    fe = np.asarray(report["formation_error_m"], dtype=float)

    def at(ts: float) -> float:
        return float(fe[int(np.argmin(np.abs(t - ts)))]) if t[-1] >= ts - 0.2 else float("nan")

    k20 = int(np.argmin(np.abs(t - 20.0)))
    m_err = np.abs(np.asarray(report["mass_estimate_kg"][k20], dtype=float)
                   - np.asarray(report["mass_true_kg"][k20], dtype=float))
    late = t >= 30.0
    link = report.get("link", {})
    ages = [v["telemetry_age_p50_ms"] for v in link.values()]
    pred = [v.get("prediction", {}) for v in link.values()]
    pred = [p for p in pred if p.get("enabled") and p["position_m"]["p99"] is not None]
    rtts = [v["round_trip"]["p50_ms"] for v in link.values() if v["round_trip"]["n"]]
    return {
        "fe_30": at(30.0), "fe_60": at(60.0),
        "fe_max_30": float(np.nanmax(fe[late])) if late.any() else float("nan"),
        "mass_err_20": float(m_err.max()) if t[-1] >= 19.8 else float("nan"),
        "age_ms": float(np.mean(ages)) if ages else float("nan"),
        "rtt_ms": float(np.mean(rtts)) if rtts else float("nan"),
        "pred_p99": max(p["position_m"]["p99"] for p in pred) if pred else float("nan"),
        "held_p99": max(p["position_held_m"]["p99"] for p in pred) if pred else float("nan"),
        "t_end": float(t[-1]),
        "outcome": report.get("extra", {}).get("outcome", {}).get("reason", ""),
    }


def _f(x: float, spec: str = ".3f") -> str:
    return "-" if not np.isfinite(x) else format(x, spec)


def section(rows: list[dict]) -> str:
    lines = [
        HEADING, "",
        "`benchmarks/bench_links.py` (rerun: `.venv/bin/python -m benchmarks.bench_links`). "
        "Scenario I (configs/square4.yaml, 60 s) flown by `gcs fly` against `vehicle-emu "
        "--fleet`, nominal personality, with every link impaired both ways from the formation's "
        f"start: the latency, 0-{JITTER_MS:g} ms uniform jitter, and the loss; with delay "
        "compensation (`fly.predict`, predict on) and without. `fly.link_delay_s` "
        f"= latency + {JITTER_MS:g} ms; gains: the paper's (alpha_p 2, c_p 4, k_eps 6, k_eps_yaw "
        "4) where the cascade criterion passes them at that delay, else its proposal (the one "
        "the ground station's refusal names, for that fly.predict); initial mass from the hover. "
        "`pred / held p99`: the largest over the vehicles of the predicted position's error p99 "
        "against what the vehicle later reported for that instant (the nominal personality "
        "reports its true state), beside the sample held without prediction [mm]. `sim`: `gcs sim` of "
        "the same team and gains in-process, without a link (rates only). Errors in m, mass "
        "error in kg (largest over the team), age: mean over the vehicles of the true telemetry "
        "age p50, RTT: of the TIMESYNC round trip p50.", "",
        "| mode | predict | latency | loss | gains (alpha_p, c_p, k_eps, k_eps_yaw) | exit | "
        "error 30 s | error 60 s | max t >= 30 s | mass error 20 s | age / RTT [ms] | pred / held "
        "p99 [mm] | sim 30 s / 60 s / mass 20 s |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        g = r["gains"]
        gains = ("none stable" if g is None else
                 f"{g.alpha_p:g}, {g.c_p:g}" + (f", {g.k_eps:g}, {g.k_eps_yaw:g}"
                                                 if r["mode"] == "rates" else "")
                 + f" ({r['source']})")
        head = (f"| {r['mode']} | {'on' if r['predicted'] else 'off'} | {r['latency_ms']:g} ms | "
                f"{100 * r['loss']:.0f} % | {gains} |")
        f, s = r.get("fly"), r.get("sim")
        sim_cell = (f"{_f(s['fe_30'])} / {_f(s['fe_60'])} / {_f(s['mass_err_20'], '.4f')}"
                    if s else "-")
        if f is None:
            lines.append(f"{head} {r.get('exit', '-')} | {r.get('why') or 'not flown'} | | | | | | "
                         f"{sim_cell} |")
            continue
        exit_cell = f"{r['exit']}" + ("" if r["exit"] == 0 else f" ({f['outcome'][:80]})")
        lines.append(f"{head} {exit_cell} | {_f(f['fe_30'])} | {_f(f['fe_60'])} | "
                     f"{_f(f['fe_max_30'])} | {_f(f['mass_err_20'], '.4f')} | "
                     f"{_f(f['age_ms'], '.0f')} / {_f(f['rtt_ms'], '.0f')} | "
                     f"{_f(1e3 * f['pred_p99'], '.1f')} / {_f(1e3 * f['held_p99'], '.0f')} | "
                     f"{sim_cell} |")
    lines += ["", f"![max formation error for t >= 30 s against latency]({FIGURE.relative_to(DOC.parent)})",
              ""]
    return "\n".join(lines) + "\n"


def plot(rows: list[dict]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4))
    for mode in sorted({r["mode"] for r in rows}):
        for predicted in (True, False):
            for loss in sorted({r["loss"] for r in rows}):
                pts = [(r["latency_ms"], r["fly"]["fe_max_30"]) for r in rows
                       if r["mode"] == mode and r["loss"] == loss and r.get("fly")
                       and r["predicted"] == predicted and r["exit"] == 0]
                if pts:
                    x, y = zip(*sorted(pts), strict=True)
                    ax.plot(x, y, "o-" if predicted else "s--",
                            label=f"{mode}, predict {'on' if predicted else 'off'}, "
                                  f"{100 * loss:.0f} % loss")
    sims = sorted({(r["latency_ms"], r["sim"]["fe_max_30"]) for r in rows if r.get("sim")})
    if sims:
        x, y = zip(*sims, strict=True)
        ax.plot(x, y, "k:", marker="x", label="gcs sim, same gains, no link")
    ax.set_yscale("log")
    ax.set_xlabel("one-way latency [ms] (+ 0-10 ms jitter)")
    ax.set_ylabel("max formation error, t >= 30 s [m]")
    ax.set_title("Scenario I over impaired links (exit 0 flights)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    FIGURE.parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    fig.savefig(FIGURE, dpi=110)
    plt.close(fig)


def fly_case(rows: list[dict], sims: dict, tmp: Path, mode: str, predicted: bool,
             latency: float, losses: list[float]) -> None:
    """One mode x predict x latency, for every loss: the flights and the gcs sim reference."""
    delay_s = (latency + JITTER_MS) * 1e-3
    gains, source = gains_at(mode, delay_s, predicted)
    for loss in losses:
        row = {"mode": mode, "predicted": predicted, "latency_ms": latency, "loss": loss,
               "gains": gains, "source": source}
        rows.append(row)
        if gains is None:
            continue
        work = tmp / f"{mode}-{predicted}-{latency:g}-{loss:g}"
        work.mkdir()
        team = team_file(work, mode, gains, delay_s, latency, loss, predicted=predicted)
        r = fly(team, work / "run", mode)
        row.update(exit=r["exit"], why=r["why"])
        if r["report"] is not None:
            row["fly"] = figures(r["report"])
        if mode == "rates":
            key = (latency, gains)
            if key not in sims:
                rep = sim(team_file(work, mode, gains, delay_s, latency, loss, for_sim=True),
                          work / "sim")
                sims[key] = figures(rep) if rep is not None else None
            row["sim"] = sims[key]
        f = row.get("fly")
        print(f"{mode} predict {'on' if predicted else 'off'} {latency:g} ms {100 * loss:.0f} %: "
              f"exit {row['exit']}, "
              + (f"fe30 {_f(f['fe_30'])} fe60 {_f(f['fe_60'])} max {_f(f['fe_max_30'])} "
                 f"mass20 {_f(f['mass_err_20'], '.4f')} pred/held p99 {_f(f['pred_p99'], '.4f')}"
                 f"/{_f(f['held_p99'], '.4f')}" if f else r["why"]), flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mode", nargs="+", default=["rates", "attitude"])
    ap.add_argument("--latency-ms", nargs="+", type=float, default=[0, 10, 20, 50, 100, 200])
    ap.add_argument("--loss", nargs="+", type=float, default=[0.0, 0.2])
    ap.add_argument("--predict", nargs="+", choices=["on", "off"], default=["on", "off"])
    ap.add_argument("--no-write", action="store_true")
    args = ap.parse_args()
    rows = []
    sims: dict[tuple[float, CascadeGains], dict | None] = {}
    with tempfile.TemporaryDirectory(prefix="bench_links_") as tmp:
        for mode in args.mode:
            for predicted in (p == "on" for p in args.predict):
                for latency in args.latency_ms:
                    fly_case(rows, sims, Path(tmp), mode, predicted, latency, args.loss)
    text = section(rows)
    print(text)
    if not args.no_write:
        plot(rows)
        write_section(DOC, HEADING, text)


if __name__ == "__main__":
    main()
