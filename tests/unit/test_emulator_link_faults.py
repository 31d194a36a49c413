"""packet_loss link faults: jitter (uniform, half-normal), reordering, seeding, run-time
parameters, team-file keys in both readers (emulator and ground station), duration_s windows."""

from __future__ import annotations

import copy
import math
from pathlib import Path

import numpy as np
import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st
from pymavlink.dialects.v20 import common as mavlink

from gcs.config import ConfigError, PacketLossFault, describe, team_from_dict, team_to_dict
from tests.harness import RecordingLink, run_until
from vehicle_emulator.config.faults import REORDER_HOLD_S, Jitter, LinkImpairment
from vehicle_emulator.config.team import FaultSpec, TeamFileError, default_vehicle, parse_team
from vehicle_emulator.fleet.runner import Emulator
from vehicle_emulator.mavlink.codec import PeerDecoder

SQUARE4 = Path(__file__).resolve().parents[2] / "configs" / "square4.yaml"
GCS = mavlink.MAVLink(None, srcSystem=245, srcComponent=190)
N = 20_000


def _delays(imp: LinkImpairment, n: int = N) -> np.ndarray:
    """admit() n times at t = 0 (lost packets as NaN), in seconds."""
    return np.array([math.nan if (d := imp.admit(0.0)) is None else d for _ in range(n)])


def _impairment(seed: int = 1, **kw) -> LinkImpairment:
    return LinkImpairment(np.random.default_rng(seed), **kw)


# --- the delay distributions -------------------------------------------------------------------


def test_uniform_jitter_is_latency_plus_u_0_to_jitter():
    # GIVEN 30 ms latency and 10 ms uniform jitter
    d_ms = 1e3 * _delays(_impairment(latency_s=0.030, jitter_s=0.010))
    # THEN every delay lies in [30, 40] ms, the mean is 35 ms and the spread 10/sqrt(12) ms
    # (standard errors 0.02 and 0.015 ms for 20000 draws: the bounds are > 7 of them)
    assert d_ms.min() >= 30.0 and d_ms.max() <= 40.0
    assert d_ms.mean() == pytest.approx(35.0, abs=0.15)
    assert d_ms.std() == pytest.approx(10.0 / math.sqrt(12.0), abs=0.1)
    # AND it is flat: each millisecond holds a tenth of the packets (binomial sd 0.2 %)
    counts, _ = np.histogram(d_ms, bins=10, range=(30.0, 40.0))
    assert np.all(np.abs(counts / N - 0.1) < 0.012)


def test_normal_jitter_is_latency_plus_a_half_normal():
    # GIVEN 30 ms latency and 10 ms normal jitter: delay = 30 + |N(0, 10^2)| ms
    d_ms = 1e3 * _delays(_impairment(latency_s=0.030, jitter_s=0.010, jitter=Jitter.NORMAL))
    # THEN never below the latency, mean 30 + 10 sqrt(2/pi) = 37.98, sd 10 sqrt(1 - 2/pi) = 6.03
    assert d_ms.min() >= 30.0
    assert d_ms.mean() == pytest.approx(30.0 + 10.0 * math.sqrt(2.0 / math.pi), abs=0.25)
    assert d_ms.std() == pytest.approx(10.0 * math.sqrt(1.0 - 2.0 / math.pi), abs=0.2)
    # AND 68.3 % of the packets are within one jitter of the latency, 95.4 % within two
    assert np.mean(d_ms <= 40.0) == pytest.approx(0.6827, abs=0.015)
    assert np.mean(d_ms <= 50.0) == pytest.approx(0.9545, abs=0.008)


@settings(max_examples=60, deadline=None)
@given(
    seed=st.integers(0, 2**31 - 1),
    latency_s=st.floats(0.0, 10.0),
    jitter_s=st.floats(0.0, 10.0),
    dist=st.sampled_from(list(Jitter)),
    reorder=st.floats(0.0, 1.0),
)
def test_a_delay_is_never_below_the_latency_nor_negative(seed, latency_s, jitter_s, dist,
                                                         reorder):
    imp = _impairment(seed, latency_s=latency_s, jitter_s=jitter_s, jitter=dist,
                      reorder_probability=reorder)
    d = _delays(imp, 200)
    assert np.all(d >= latency_s) and np.all(d >= 0.0)
    if dist is Jitter.UNIFORM:
        assert np.all(d <= latency_s + jitter_s + REORDER_HOLD_S)


def test_reordering_holds_a_fraction_of_the_packets_back_by_the_documented_hold():
    # GIVEN 10 ms latency, no jitter, reorder_probability 0.2
    imp = _impairment(latency_s=0.010, reorder_probability=0.2)
    d_ms = 1e3 * _delays(imp)
    # THEN a packet is delayed 10 ms or 10 + 20 ms (docs: the hold is 20 ms), 20 % of them
    # the longer (binomial sd 0.28 %)
    assert REORDER_HOLD_S == 0.020
    held = np.isclose(d_ms, 30.0)
    assert np.all(held | np.isclose(d_ms, 10.0))
    assert held.mean() == pytest.approx(0.2, abs=0.012)
    assert imp.held_back == held.sum()


def _overtaken(send_s: np.ndarray, delay_s: np.ndarray) -> float:
    """Fraction of packets that arrive after a packet sent later than them."""
    arrive = send_s + delay_s
    later_min = np.minimum.accumulate(arrive[::-1])[::-1]  # earliest arrival from i on
    return float(np.mean(arrive[:-1] > later_min[1:]))


def test_held_packets_are_overtaken_by_those_sent_within_the_hold():
    # GIVEN a packet every 5 ms and reorder_probability 0.2, no jitter
    send = np.arange(N) * 0.005
    d = _delays(_impairment(latency_s=0.030, reorder_probability=0.2))
    # THEN a held packet (20 ms) is overtaken by the next ones (3 of them sent within the hold),
    # an unheld one never: the overtaken fraction is the held fraction
    assert _overtaken(send, d) == pytest.approx(0.2, abs=0.012)
    # AND with the packets 25 ms apart (more than the hold) nothing is reordered
    assert _overtaken(np.arange(N) * 0.025, d) == 0.0


def test_jitter_alone_reorders_packets_closer_than_their_delay_difference():
    d = _delays(_impairment(latency_s=0.030, jitter_s=0.010))
    # GIVEN uniform jitter of 10 ms WHEN packets go every 2 ms THEN many are overtaken
    assert _overtaken(np.arange(N) * 0.002, d) > 0.3
    # WHEN they go every 11 ms (more than any two delays differ) THEN none is
    assert _overtaken(np.arange(N) * 0.011, d) == 0.0


# --- seeding -------------------------------------------------------------------------------------


def test_draws_follow_the_documented_order_loss_jitter_reorder():
    # GIVEN every setting on WHEN the same seed drives an independent generator in the documented
    # order (loss, then jitter, then reorder, each only where non-zero) THEN it predicts every delay
    imp = _impairment(7, loss_probability=0.1, latency_s=0.030, jitter_s=0.010,
                      jitter=Jitter.NORMAL, reorder_probability=0.2)
    rng = np.random.default_rng(7)
    for _ in range(2000):
        if rng.random() < 0.1:
            expected = None
        else:
            expected = 0.030 + 0.010 * abs(rng.standard_normal())
            expected += REORDER_HOLD_S if rng.random() < 0.2 else 0.0
        got = imp.admit(0.0)
        assert got == expected if expected is None else got == pytest.approx(expected, abs=1e-15)


def test_without_jitter_and_reordering_the_seeded_loss_sequence_is_unchanged():
    # one draw per packet, as before jitter existed: a seed loses the same packets it always did
    imp = _impairment(5, loss_probability=0.3)
    lost = np.isnan(_delays(imp, 2000))
    assert np.array_equal(lost, np.random.default_rng(5).random(2000) < 0.3)


def _emu(**kw) -> tuple[Emulator, RecordingLink]:
    emu = Emulator([default_vehicle(1, on_ground=False)], **kw)
    link = RecordingLink()
    emu.nodes[0].links.append(link)
    return emu, link


def _param_set(emu: Emulator, link: RecordingLink, name: str, value: float) -> None:
    msg = mavlink.MAVLink_param_set_message(1, 1, name.encode(), value, 9)
    emu.on_messages(emu.nodes[0], link, PeerDecoder().feed(msg.pack(GCS), "gcs"),
                    ("127.0.0.1", 1))


def test_same_seed_same_delays_through_the_run_time_parameters():
    def delays(seed: int) -> list[float | None]:
        emu, link = _emu(seed=seed)
        for name, value in [("EMU_PKT_LOSS", 0.1), ("EMU_LATENCY_MS", 30.0),
                            ("EMU_JITTER_MS", 10.0), ("EMU_REORDER_P", 0.2),
                            ("EMU_SEED", seed)]:  # EMU_SEED re-seeds: the same start each time
            _param_set(emu, link, name, value)
        imp = emu.nodes[0].impairment
        return [imp.admit(0.0) for _ in range(500)]

    a = delays(3)
    assert a == delays(3)
    assert a != delays(4)
    assert len({round(d, 9) for d in a if d is not None}) > 100  # jittered, not constant


def test_run_time_parameters_set_jitter_distribution_and_reordering():
    emu, link = _emu()
    imp = emu.nodes[0].impairment
    _param_set(emu, link, "EMU_JITTER_MS", 12.5)
    _param_set(emu, link, "EMU_JITTER_DIST", 1)
    _param_set(emu, link, "EMU_REORDER_P", 0.3)
    # (PARAM_SET carries a float32: 0.3 arrives as 0.30000001)
    assert (imp.jitter_s, imp.jitter) == (0.0125, Jitter.NORMAL)
    assert imp.reorder_probability == pytest.approx(0.3, rel=1e-7)
    _param_set(emu, link, "EMU_JITTER_DIST", 0)
    assert imp.jitter is Jitter.UNIFORM
    # out-of-range values are refused with the limits named, the link keeps its settings
    _param_set(emu, link, "EMU_JITTER_DIST", 2)
    _param_set(emu, link, "EMU_REORDER_P", 1.5)
    assert imp.jitter is Jitter.UNIFORM and imp.reorder_probability == pytest.approx(0.3, rel=1e-7)
    texts = [m.text for m in link.msgs if m.get_type() == "STATUSTEXT"]
    assert any(t.startswith("parameter EMU_JITTER_DIST: value 2 outside [0, 1]") for t in texts)
    assert any(t.startswith("parameter EMU_REORDER_P: value 1.5 outside [0, 1]") for t in texts)


# --- team files: the emulator's reader and the ground station's ---------------------------------


def _team(faults: list[dict]) -> dict:
    data = yaml.safe_load(SQUARE4.read_text())
    data["faults"] = copy.deepcopy(faults)
    return data


FULL = {"kind": "packet_loss", "vehicle": 2, "at_s": 4.0, "probability": 0.05,
        "latency_ms": 30, "jitter_ms": 10, "jitter": "normal", "reorder_probability": 0.2,
        "duration_s": 5.0}


def test_both_readers_take_the_new_keys_alike():
    (emu,) = parse_team(_team([FULL])).faults
    assert emu == FaultSpec("packet_loss", 2, 4.0, duration_s=5.0, probability=0.05,
                            latency_ms=30.0, jitter_ms=10.0, jitter="normal",
                            reorder_probability=0.2)
    team = team_from_dict(_team([FULL]))
    assert team.faults == (PacketLossFault("packet_loss", 2, 4.0, 0.05, 30.0, 10.0, "normal",
                                           0.2, 5.0),)
    assert team_from_dict(team_to_dict(team)) == team
    assert ("packet_loss: vehicle 2 loses 5% of packets, +30 ms latency + normal jitter 10 ms, "
            "20% reordered, from t = 4 s for 5 s") in describe(team)


def test_both_readers_default_the_new_keys():
    bare = {"kind": "packet_loss", "vehicle": 1, "at_s": 0.0, "probability": 0.1}
    (emu,) = parse_team(_team([bare])).faults
    assert (emu.jitter_ms, emu.jitter, emu.reorder_probability, emu.duration_s) == (
        0.0, "uniform", 0.0, 0.0)
    (gcs,) = team_from_dict(_team([bare])).faults
    assert (gcs.jitter_ms, gcs.jitter, gcs.reorder_probability, gcs.duration_s) == (
        0.0, "uniform", 0.0, 0.0)


@pytest.mark.parametrize(
    "key, value, emulator_says, gcs_says",
    [
        ("jitter_ms", -1, r"expected 0\.0\.\.10000\.0, got -1", r"expected a value in \[0, 10000\], got -1\.0"),
        ("jitter_ms", 10001, r"expected 0\.0\.\.10000\.0, got 10001", r"expected a value in \[0, 10000\], got 10001\.0"),
        ("jitter_ms", "ten", r"expected a number, got 'ten'", r"expected a number, got string 'ten'"),
        ("jitter", "gaussian", r"expected one of uniform, normal, got 'gaussian'",
         r"expected one of 'uniform', 'normal', got string 'gaussian'"),
        ("jitter", 1, r"expected one of uniform, normal, got 1", r"expected one of 'uniform', 'normal', got"),
        ("reorder_probability", 1.5, r"expected 0\.0\.\.1\.0, got 1\.5", r"expected a value in \[0, 1\], got 1\.5"),
        ("reorder_probability", -0.1, r"expected 0\.0\.\.1\.0, got -0\.1", r"expected a value in \[0, 1\], got -0\.1"),
        ("duration_s", -2, r"expected 0\.0\.\.1000000\.0, got -2", r"expected a value in \[0, 1e\+06\], got -2\.0"),
    ],
)
def test_both_readers_refuse_bad_values_naming_the_key(key, value, emulator_says, gcs_says):
    bad = [{**FULL, key: value}]
    with pytest.raises(TeamFileError, match=rf"^faults\[0\]\.{key}: {emulator_says}"):
        parse_team(_team(bad))
    with pytest.raises(ConfigError, match=rf"^<dict>: faults\[0\]\.{key}: {gcs_says}"):
        team_from_dict(_team(bad))


def test_the_ground_station_refuses_a_misspelt_key():
    with pytest.raises(ConfigError, match=r"faults\[0\]\.jitter_dist: unknown key; did you mean "
                                          r"'jitter_ms'\?"):
        team_from_dict(_team([{**FULL, "jitter_dist": "normal"}]))


# --- the fault in the emulator: start, text, and the end of its window --------------------------


def _texts(link: RecordingLink) -> list[str]:
    """STATUSTEXTs sent, chunks joined (a text over 50 bytes comes in chunks of one id)."""
    texts: list[str] = []
    chunks: dict[int, str] = {}
    for m in link.msgs:
        if m.get_type() != "STATUSTEXT":
            continue
        if m.id == 0:
            texts.append(m.text)
            continue
        chunks[m.id] = chunks.get(m.id, "") + m.text
        if len(m.text.encode()) < 50:
            texts.append(chunks.pop(m.id))
    return [t.rstrip("\t") for t in texts]


def _link_state(emu: Emulator) -> tuple[float, float, Jitter, float, float]:
    imp = emu.nodes[0].impairment
    return (imp.loss_probability, round(imp.latency_s, 9), imp.jitter, round(imp.jitter_s, 9),
            imp.reorder_probability)


BEFORE = (0.0, 0.005, Jitter.UNIFORM, 0.0, 0.0)  # EMU_LATENCY_MS = 5 before the fault
DURING = (0.1, 0.030, Jitter.NORMAL, 0.010, 0.2)


def _windowed(at_s: float, duration_s: float, **kw) -> FaultSpec:
    return FaultSpec("packet_loss", 1, at_s, duration_s=duration_s, probability=0.1,
                     latency_ms=30.0, jitter_ms=10.0, jitter="normal", reorder_probability=0.2,
                     **kw)


def test_a_windowed_fault_restores_the_previous_link_at_its_end_on_the_emulator_clock():
    # GIVEN a fault clock from boot and a 2 s packet_loss fault at 1 s over a 5 ms link
    emu, link = _emu(faults=[_windowed(1.0, 2.0)],
                     param_overrides={"EMU_FLT_T0": 1, "EMU_LATENCY_MS": 5})
    run_until(emu, 0.998)
    assert _link_state(emu) == BEFORE
    run_until(emu, 1.0)  # THEN it starts at its time, announced
    assert _link_state(emu) == DURING
    assert "Fault: loss 0.10 +30+N10 ms reorder 0.20 for 2 s at 1.000 s" in _texts(link)
    assert emu.nodes[0].params["EMU_JITTER_DIST"] == 1
    run_until(emu, 2.998)
    assert _link_state(emu) == DURING
    run_until(emu, 3.0)  # AND ends 2 s later with the 5 ms link back, announced
    assert _link_state(emu) == BEFORE
    assert "Fault end: loss 0.00 +5 ms at 3.000 s" in _texts(link)
    assert [emu.nodes[0].params[n] for n in ("EMU_PKT_LOSS", "EMU_LATENCY_MS", "EMU_JITTER_MS",
                                             "EMU_JITTER_DIST", "EMU_REORDER_P")] == [0, 5, 0, 0, 0]


def test_the_window_ends_on_the_emulator_clock_when_the_fault_clock_starts_late():
    # GIVEN the default fault clock (first OFFBOARD entry), entered at 5 s of emulator time
    emu, link = _emu(faults=[_windowed(1.0, 2.0)], param_overrides={"EMU_LATENCY_MS": 5})
    run_until(emu, 5.0)
    emu.nodes[0].autopilot.first_offboard_s = 5.0
    run_until(emu, 5.998)
    assert _link_state(emu) == BEFORE
    run_until(emu, 6.0)  # fault clock 1 s
    assert _link_state(emu) == DURING
    run_until(emu, 7.998)
    assert _link_state(emu) == DURING
    run_until(emu, 8.0)
    assert _link_state(emu) == BEFORE
    assert "Fault end: loss 0.00 +5 ms at 3.000 s" in _texts(link)


def test_without_duration_the_fault_lasts_the_run_and_nested_windows_unwind():
    emu, _ = _emu(
        faults=[
            FaultSpec("packet_loss", 1, 1.0, latency_ms=30.0),  # for good
            _windowed(2.0, 4.0),  # a window ...
            FaultSpec("packet_loss", 1, 3.0, duration_s=1.0, latency_ms=80.0),  # ... in it
        ],
        param_overrides={"EMU_FLT_T0": 1},
    )
    run_until(emu, 1.5)
    assert _link_state(emu)[1] == 0.030
    run_until(emu, 3.5)
    assert _link_state(emu) == (0.0, 0.080, Jitter.UNIFORM, 0.0, 0.0)
    run_until(emu, 4.5)  # the inner window is over: the outer one's link
    assert _link_state(emu) == DURING
    run_until(emu, 6.5)  # the outer one too: the fault without a window, which stays
    assert _link_state(emu) == (0.0, 0.030, Jitter.UNIFORM, 0.0, 0.0)
    run_until(emu, 20.0)
    assert _link_state(emu) == (0.0, 0.030, Jitter.UNIFORM, 0.0, 0.0)
