"""In-process emulator (no sockets): telemetry rates, faults, parameters, noise, purity."""

from __future__ import annotations

import ast
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink

from vehicle_emulator.codec import PeerDecoder
from vehicle_emulator.faults import LinkImpairment
from vehicle_emulator.runner import Emulator
from vehicle_emulator.team import FaultSpec, default_vehicle
from vehicle_emulator.telemetry import DEFAULT_RATES_HZ

ROOT = Path(__file__).resolve().parents[2]
GCS = mavlink.MAVLink(None, srcSystem=245, srcComponent=190)


class FakeLink:
    """Collects what the emulator sends; decodes it for assertions."""

    name = "fake"

    def __init__(self) -> None:
        self.decoder = PeerDecoder()
        self.msgs: list = []

    def send(self, data: bytes, addr=None) -> None:
        self.msgs.extend(self.decoder.feed(data, "emu"))

    def types(self) -> Counter:
        return Counter(m.get_type() for m in self.msgs)


def _emu(n=1, in_air=True, **kw) -> tuple[Emulator, list[FakeLink]]:
    emu = Emulator([default_vehicle(i + 1, on_ground=not in_air) for i in range(n)], **kw)
    links = []
    for node in emu.nodes:
        link = FakeLink()
        node.links.append(link)
        links.append(link)
    return emu, links


def _run(emu: Emulator, until_s: float, tick_s: float = 0.002) -> None:
    t = emu.now_s
    while t < until_s - 1e-9:
        t += tick_s
        emu.advance_to(t)


def _send(emu: Emulator, i: int, msg, link) -> None:
    decoded = PeerDecoder().feed(msg.pack(GCS), "gcs")
    emu.on_messages(emu.nodes[i], link, decoded, ("127.0.0.1", 1))


def test_px4_telemetry_rates_over_ten_simulated_seconds():
    emu, (link,) = _emu()
    _run(emu, 10.0)
    counts = link.types()
    for name, hz in DEFAULT_RATES_HZ.items():
        assert counts[name] == pytest.approx(10.0 * hz, abs=1.01), name
    assert link.decoder.stats.rejected == 0


def test_set_message_interval_changes_one_vehicles_rate():
    emu, links = _emu(2)
    _send(
        emu,
        0,
        mavlink.MAVLink_command_long_message(1, 1, 511, 0, 30, 50_000, 0, 0, 0, 0, 0),
        links[0],
    )
    _run(emu, 2.0)
    assert links[0].types()["ATTITUDE"] == pytest.approx(40, abs=1)
    assert links[1].types()["ATTITUDE"] == pytest.approx(200, abs=1)
    ack = [m for m in links[0].msgs if m.get_type() == "COMMAND_ACK"]
    assert ack[0].result == 0 and ack[0].target_system == 245


def test_mass_drop_fires_on_the_fault_clock_at_the_first_tick_at_or_after_its_time():
    emu, (link,) = _emu(faults=[FaultSpec("mass_drop", 1, 3.0, fraction=0.3)])
    node = emu.nodes[0]
    assert node.params["EMU_MDROP_T"] == 3.0
    _run(emu, 5.0)
    assert emu.plant.mass_kg[0] == 0.85  # no OFFBOARD yet: the fault clock has not started
    node.autopilot.first_offboard_s = 5.0  # formation start
    _run(emu, 7.998)
    assert emu.plant.mass_kg[0] == 0.85
    _run(emu, 8.0)
    assert emu.plant.mass_kg[0] == pytest.approx(0.595)
    texts = [m.text for m in link.msgs if m.get_type() == "STATUSTEXT"]
    assert any(t.startswith("Fault: mass 0.850->0.595 kg at 3.000 s") for t in texts)


def test_fault_clock_from_boot_option():
    emu, _ = _emu(
        faults=[FaultSpec("mass_drop", 1, 1.0, fraction=0.5)], param_overrides={"EMU_FLT_T0": 1}
    )
    _run(emu, 1.0)
    assert emu.plant.mass_kg[0] == pytest.approx(0.425)


def test_link_loss_and_motor_efficiency_faults():
    emu, (link,) = _emu(
        faults=[
            FaultSpec("link_loss", 1, 1.0, duration_s=2.0),
            FaultSpec("motor_efficiency", 1, 1.0, motor=2, efficiency=0.6),
        ],
        param_overrides={"EMU_FLT_T0": 1},
    )
    _run(emu, 1.1)
    n_before = len(link.msgs)
    assert emu.plant.rotor_efficiency[0, 1] == 0.6 and emu.nodes[0].params["EMU_MOT2_EFF"] == 0.6
    _run(emu, 2.9)
    assert len(link.msgs) - n_before < 5  # silent (only STATUSTEXT sent before the loss)
    _run(emu, 3.5)
    assert link.types()["ATTITUDE"] > 0 and len(link.msgs) - n_before > 30


def test_seeded_packet_loss_is_reproducible():
    def drops(seed):
        imp = LinkImpairment(np.random.default_rng(seed), loss_probability=0.3)
        return [imp.admit(0.0) is None for _ in range(2000)]

    a, b = drops(5), drops(5)
    assert a == b and 0.25 < sum(a) / len(a) < 0.35


def test_parameter_side_effects_and_run_time_triggers():
    emu, (link,) = _emu()
    for name, value in [("EMU_MOT3_EFF", 0.5), ("EMU_NOISE", 1), ("EMU_MASS_DROP", 0.2)]:
        _send(emu, 0, mavlink.MAVLink_param_set_message(1, 1, name.encode(), value, 9), link)
    assert emu.plant.rotor_efficiency[0, 2] == 0.5
    assert emu.status.noise[0]
    assert emu.plant.mass_kg[0] == pytest.approx(0.68)
    echoed = {m.param_id: m.param_value for m in link.msgs if m.get_type() == "PARAM_VALUE"}
    assert echoed["EMU_MOT3_EFF"] == 0.5


def test_noise_is_off_by_default_and_seeded_when_on():
    def first_positions(noise, seed):
        emu, (link,) = _emu(seed=seed, param_overrides={"EMU_NOISE": noise})
        _run(emu, 0.5)
        return [(m.x, m.y, m.z) for m in link.msgs if m.get_type() == "LOCAL_POSITION_NED"]

    clean = first_positions(0, 1)
    assert all(p == (0.0, 0.0, -10.0) for p in clean)
    noisy = first_positions(1, 1)
    assert noisy == first_positions(1, 1) and noisy != clean
    assert max(abs(p[2] + 10.0) for p in noisy) < 0.1


def test_commands_for_other_systems_are_ignored_and_counted():
    emu, (link,) = _emu()
    _send(emu, 0, mavlink.MAVLink_command_long_message(9, 1, 400, 0, 0, 0, 0, 0, 0, 0, 0), link)
    assert not [m for m in link.msgs if m.get_type() == "COMMAND_ACK"]
    assert emu.nodes[0].counters.other_target == 1


PURE = ["autopilot", "inner", "plant", "setpoints", "frames", "faults", "params", "team"]
IMPURE = {"asyncio", "socket", "time", "pymavlink", "mavsdk", "select", "threading", "gcs"}


@pytest.mark.parametrize("module", PURE)
def test_pure_emulator_layers_do_no_io(module):
    tree = ast.parse((ROOT / "vehicle_emulator" / f"{module}.py").read_text())
    roots = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            roots |= {a.name.split(".")[0] for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module:
            roots.add(node.module.split(".")[0])
            if node.module.startswith("vehicle_emulator."):
                dep = node.module.split(".")[1]
                assert dep in PURE + ["physics", "jitcache"], f"{module} imports {dep}"
    assert not roots & IMPURE
