"""What `gcs check` prints: the team as understood, with the sufficient conditions evaluated."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from gcs.config.conditions import alpha_p_bound, proposition1_bounds
from gcs.config.fly_schema import FlyModeConfig
from gcs.config.fly_section import check_go_to_start
from gcs.config.modes import ClockMode, ControlMode
from gcs.config.schema import (
    GAIN_NAMES,
    GRAVITY_MPS2,
    THRUST_MARGIN,
    ConfigError,
    FaultConfig,
    TeamConfig,
    VehicleConfig,
    initial_phi,
    proposition2_min_mhat,
)

# --------------------------------------------------------------------------------------------
# describe(): what `gcs check` prints.


def _v3(v: Sequence[float]) -> str:
    return "(" + ", ".join(f"{x:g}" for x in v) + ")"


def _ok(ok: bool) -> str:
    return "OK" if ok else "NOT MET"


def describe(team: TeamConfig) -> str:
    """Multi-line summary of what the config says, with the sufficient conditions evaluated."""
    c, g, sim = team.controller, team.controller.gains, team.sim
    mode = {ControlMode.RATES: "thrust + body rates",
            ControlMode.ACTUATORS: "thrust + torque (26)",
            ControlMode.ATTITUDE: "thrust + attitude; gcs fly only, gcs sim refuses it"}[c.mode]
    deriv = c.derivative.method + (
        f" (L = {c.derivative.levant_lipschitz:g}, substep {c.derivative.levant_substep_s:g} s)"
        if c.derivative.method == "levant"
        else ""
    )
    out = [
        f"team {team.name!r} ({team.source_path}): {team.n} vehicles, "
        f"mission {team.mission.duration_s:g} s",
        f"controller: {c.law} law, {c.mode} mode ({mode}), derivatives: {deriv}",
        "gains: " + ", ".join(f"{name} {getattr(g, name):g}" for name in GAIN_NAMES),
        f"sim: plant {sim.plant_rate_hz:g} Hz, controller {sim.controller_rate_hz:g} Hz "
        f"({sim.plant_steps_per_tick} plant step(s) per tick)",
        "reference velocity v_r(t) [m/s, ENU]:",
    ]
    for name in "xyz":
        axis = getattr(team.reference_velocity, name)
        terms = [f"{axis.constant:g}"] + [
            f"{k.amplitude:g} cos(2 pi t/{k.period_s:g}"
            + (f" + {k.phase_rad:g}" if k.phase_rad else "")
            + ")"
            for k in axis.cosines
        ]
        out.append(f"  {name}: " + " + ".join(terms))
    lam = np.sort(np.linalg.eigvalsh(team.laplacian()))
    out.append(
        f"graph: {len(team.graph.edges)} undirected edge(s) "
        + ", ".join(
            f"{e.i}-{e.j}" + (f" (w {e.weight:g})" if e.weight != 1.0 else "")
            for e in team.graph.edges
        )
        + (f"; connected, lambda_2(L) = {lam[1]:.4g}" if team.n > 1 else "")
    )
    out.append("vehicles (ENU m, z up):")
    for v in team.vehicles:
        plant = (
            f"plant {v.plant.mass_kg:g} kg, J {_v3(v.plant.inertia_kgm2)} kg m^2"
            if v.plant
            else "no plant (true mass unknown)"
        )
        nominal = f", nominal {v.nominal_mass_kg:g} kg" if v.nominal_mass_kg else ""
        out += [
            f"  vehicle {v.id} (sysid {v.sysid}): offset {_v3(v.offset_enu_m)}, start "
            f"{_v3(v.initial.position_enu_m)}, mhat(0) {_mhat0(v)}, Jhat(0) "
            f"{_v3(v.estimates.inertia_kgm2)}",
            f"      max thrust {v.airframe.max_thrust_n:g} N, arm {v.airframe.arm_length_m:g}"
            f" m; link {_link(team, v)}; {plant}{nominal}",
        ]
    fly = team.fly

    def mode_line(name: str, m: FlyModeConfig) -> str:
        gains = ""
        if m.alpha_eps is not None or m.alpha_omega is not None:
            a_eps, a_om = m.alpha_eps or g.alpha_eps, m.alpha_omega or g.alpha_omega
            gains = f", alpha_eps {a_eps:g}, alpha_omega {a_om:g}"
        if m.alpha_rho is not None:
            gains += f", alpha_rho {m.alpha_rho:g}"
        return f"{name} {m.tick_rate_hz:g} Hz{gains}"

    fence = (
        f"geofence {_v3(fly.geofence.min_enu_m)}..{_v3(fly.geofence.max_enu_m)} m"
        if fly.geofence
        else "no geofence"
    )
    out += [
        f"fly: mode {fly.control_mode} (controller.mode is gcs sim's; auto: rates, or attitude "
        "where rates fails the cascade criterion at fly.link_delay_s)",
        f"     {mode_line('rates', fly.rates)} (body-rate limit "
        f"{fly.rates.max_rate_radps:g} rad/s); {mode_line('actuators', fly.actuators)}",
        f"     position {fly.position.tick_rate_hz:g} Hz (the baseline, only by fly.mode or "
        "--mode: each vehicle's formation slot as a position setpoint, the autopilot closes "
        "every loop; no law, no estimation)",
        f"     start {fly.start}, end {fly.end_action}, abort {fly.abort_action}, link loss "
        f"{fly.link_loss_action}; stale after {fly.stale_after_s:g} s, lost after "
        f"{fly.link_lost_after_s:g} s in flight, link timeout {fly.link_timeout_s:g} s, data "
        f"older than {fly.max_data_age_s:g} s stops; max tilt "
        f"{fly.max_tilt_rad:g} rad; {fence}",
        "     delay compensation: " + ("the law reads states predicted to when its setpoints act "
                                       "(fly.predict)" if fly.predict else
                                       "off, the law reads the latest samples (fly.predict)"),
        "     the law's velocity: " + (
            f"the reported position's rate below 1/{fly.velocity_from_position_s:g} s, the "
            "reported velocity above (fly.velocity_from_position_s)"
            if fly.velocity_from_position_s > 0 else
            "the reported velocity as it is (fly.velocity_from_position_s 0)"),
        "     the law's acceleration: " + (
            f"that velocity's rate below 1/{fly.acceleration_from_velocity_s:g} s, the "
            "accelerometer's above (fly.acceleration_from_velocity_s)"
            if fly.acceleration_from_velocity_s > 0 else
            "the accelerometer's alone (fly.acceleration_from_velocity_s 0)"),
        f"     scheduling {fly.scheduling} (fly.scheduling: the operating system's priority for "
        "the tick)",
        _go_to_start_line(team),
        _network_line(team),
    ]
    out.append("faults:" + ("" if team.faults else " none"))
    for f in team.faults:
        plant = team.vehicle(f.vehicle).plant
        mass = (
            f" ({plant.mass_kg:g} -> {plant.mass_kg * (1 - f.fraction):.4g} kg)"
            if isinstance(f, FaultConfig) and plant
            else ""
        )
        out.append(f"  {f.kind}: {f.summary()}{mass}")

    varrho = team.reference_velocity.max_abs_acceleration_z()
    bound = alpha_p_bound(team)
    out += [
        "sufficient conditions:",
        f"  alpha_p < (g - varrho)/(2 sigma_a): {g.alpha_p:g} < ({GRAVITY_MPS2:g} - "
        f"{varrho:.4g})/(2 * {g.sigma_a:g}) = {bound:.4g}: {_ok(g.alpha_p < bound)}, "
        f"margin {bound - g.alpha_p:.4g}",
        "  Proposition 2, mhat(0) >= (phi(0) - 1) mbar / alpha_m:",
    ]
    for v in team.vehicles:
        least = proposition2_min_mhat(v, g)
        out.append(
            f"    vehicle {v.id}: skipped (no mass_bound_kg, no plant)"
            if least is None
            else f"    vehicle {v.id}: from the hover thrust in flight (gcs fly checks it), "
            f"least {least:.4g}"
            if v.estimates.from_hover
            else f"    vehicle {v.id}: {v.estimates.mhat:g} >= ({initial_phi(v, g):.4g} - 1)"
            f" * {v.mass_bound_kg:g} / {g.alpha_m:g} = {least:.4g}: "
            f"{_ok(v.estimates.mhat >= least)}, margin {v.estimates.mhat - least:.4g}"
        )
    out.append(f"  thrust, 4 rotor_thrust_max_n >= {THRUST_MARGIN:g} m g:")
    for v in team.vehicles:
        if v.plant is None:
            out.append(f"    vehicle {v.id}: skipped (no plant)")
            continue
        hover, top = v.plant.mass_kg * GRAVITY_MPS2, v.airframe.max_thrust_n
        out.append(
            f"    vehicle {v.id}: {top:g} N >= "
            f"{THRUST_MARGIN * hover:.4g} N: {_ok(top >= THRUST_MARGIN * hover)},"
            f" {v.airframe.max_thrust_n / hover:.3g} x hover"
        )
    out.append(
        "  Proposition 1 (torque law (26)), c_eps < min{sqrt(a_eps/(2 Jbar)), "
        "a_om/(2 sqrt3 Jbar), 4 a_eps a_om/(a_om^2 + 8 sqrt3 a_eps Jbar)}:"
    )
    for v in team.vehicles:
        if v.plant is None:
            out.append(f"    vehicle {v.id}: skipped (no plant, Jbar unknown)")
            continue
        jbar, b = max(v.plant.inertia_kgm2), proposition1_bounds(v, team)
        out.append(
            f"    vehicle {v.id} (Jbar {jbar:g}): {g.c_eps:g} < min{_v3(round(x, 4) for x in b)}"
            f" = {min(b):.4g}: {_ok(g.c_eps < min(b))}"
        )
    if c.mode == ControlMode.ACTUATORS:
        out.append(
            f"  torque held 1/{sim.controller_rate_hz:g} s: |1 - alpha_omega h / J_min| < 1"
            " (rough discrete-time stability of the rate loop):"
        )
        for v in team.vehicles:
            if v.plant is not None:
                factor = 1 - g.alpha_omega * sim.controller_dt_s / min(v.plant.inertia_kgm2)
                out.append(f"    vehicle {v.id}: {factor:.3g}: {_ok(abs(factor) < 1)}")
    return "\n".join(out)


def _mhat0(v: VehicleConfig) -> str:
    return "from the hover thrust" if v.estimates.from_hover else f"{v.estimates.mhat:g}"


def _link(team: TeamConfig, v: VehicleConfig) -> str:
    """'udp :14550 (shared with 2, 3, by sysid) -> the address its first message comes from'."""
    lk = v.link
    others = [u.id for u in team.vehicles if u.id != v.id and lk.local_port
              and u.link.local_port == lk.local_port]
    text = f"udp :{lk.local_port}"
    if others:
        text += f" (shared with {', '.join(str(i) for i in others)}, by sysid)"
    fixed = f"{lk.remote_host}:{lk.remote_port}"
    if not lk.learn_remote:
        return f"{text} -> {fixed}"
    first = f" (until then {fixed})" if lk.remote_port is not None else ""
    return f"{text} -> the address its first message comes from{first}"


def _go_to_start_line(team: TeamConfig) -> str:
    """fly.go_to_start, and whether `gcs fly` would refuse the start positions."""
    g = team.fly.go_to_start
    if g.enabled == "false":
        return "     go to start: off (the law starts where the vehicles are)"
    text = (f"     go to start {g.enabled}: settled within {g.tolerance_m:g} m, drift < "
            f"{g.max_speed_mps:g} m/s over {g.settle_s:g} s (or, held at rest, within "
            f"{g.tolerance_m:g} m + its wander), timeout {g.timeout_s:g} s, cruise "
            f"{g.cruise_speed_mps:g} m/s; start positions >= {g.min_altitude_m:g} m")
    try:
        check_go_to_start(team)
    except ConfigError as exc:
        text += f"\n     gcs fly refuses this team file: {exc.problem}"
    return text


_CLOCKS = {
    ClockMode.MEASURED: "measured (each peer's offset from the echoes)",
    ClockMode.DISCIPLINED: "disciplined (the hosts' system clocks, checked by the echoes to "
                           "{tol:g} ms)",
    ClockMode.ONE_HOST: "one (one host: offsets taken as 0)",
}


def _network_line(team: TeamConfig) -> str:
    """The `network:` section: who listens where, how the processes meet, the clocks."""
    net = team.network
    explicit = {a.vehicle_id: a.listen for a in net.agents}
    defaults = [v.id for v in team.vehicles if v.id not in explicit]
    where = [f"{vid} on {', '.join(listen)}" for vid, listen in explicit.items()]
    if defaults:
        where.append(f"{'the others' if explicit else 'every one'} on "
                     f"tcp/127.0.0.1:<{net.base_port} + id>")
    meet = (f"through router {net.router}" if net.mode == "client" else
            "each connecting to every other's endpoints" + (
                f" and router {net.router}" if net.router else ""))
    return (f"network: {net.mode} mode, keys {net.key_root(team.name)}/..., supervisor on "
            f"{', '.join(net.supervisor_listen())}, agents: {'; '.join(where)}; {meet}, "
            f"multicast scouting {'on' if net.multicast_scouting else 'off'}, clocks "
            f"{_CLOCKS[net.clocks].format(tol=net.clock_tolerance_s * 1e3)}; the supervisor "
            f"takes a state as stale after {net.stale_after_s:g} s, an agent the supervisor as "
            f"lost after {net.supervisor_lost_after_s:g} s")
