"""The emulated autopilots hold, take off from and fly to what they estimate, as PX4 and
ArduPilot do: a mode that captures "here" (Hold, BRAKE, a position target's free axes) captures
the vehicle's own position estimate, not the plant's true position (the calibrated personalities
report, and fly their position loops on, truth plus an estimate error). Before, Hold captured the
truth, and the reported position jumped by the estimate error at every switch (0.2-0.5 m on the
px4 personality: the go-to-start's settled vehicles moved off their start positions in Hold)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from pymavlink.dialects.v20 import common as mavlink

from tests.harness import RecordingLink, run_until
from vehicle_emulator.config.team import default_vehicle
from vehicle_emulator.fleet.runner import Emulator
from vehicle_emulator.mavlink.codec import PeerDecoder

GCS = mavlink.MAVLink(None, srcSystem=245, srcComponent=190)


def _send(emu: Emulator, msg, link) -> None:
    decoded = PeerDecoder().feed(msg.pack(GCS), "gcs")
    emu.on_messages(emu.nodes[0], link, decoded, ("127.0.0.1", 1))


def test_px4_hold_captures_the_position_estimate_so_the_reported_position_does_not_jump():
    # GIVEN a vehicle of a calibrated personality holding in the air, noise on, long enough for
    # its position estimate to be off the truth by centimetres to decimetres
    spec = replace(default_vehicle(1, on_ground=False), autopilot="px4")
    emu = Emulator([spec], seed=3, param_overrides={"EMU_NOISE": 1})
    # (the px4 personality keeps its velocity error out of its position, as SIH does; here the
    # position integrates it, so that the estimate is off the truth and the test can tell)
    emu.plant.onboard.position_error_share[0] = 1.0
    link = RecordingLink()
    emu.nodes[0].links.append(link)
    run_until(emu, 20.0)
    plant = emu.plant
    estimate = plant.onboard.position_est_enu_m[0].copy()
    assert np.linalg.norm(estimate - plant.position_enu_m[0]) > 0.1  # the test can tell
    # WHEN its hold mode is commanded (again): the autopilot captures "here"
    _send(emu, mavlink.MAVLink_command_long_message(1, 1, 176, 0, 1 | 128, 4, 3, 0, 0, 0, 0), link)
    # THEN "here" is where the vehicle believes it is (what it reports), not the truth
    target = plant.position_sp_enu_m[0]
    assert np.linalg.norm(target - estimate) < 0.01
    assert math.isclose(plant.position_mask[0].min(), 1.0)


def _hold_track(autopilot: str, noise: int, seconds: float = 80.0, seed: int = 5) -> np.ndarray:
    """Reported (estimated) positions [ENU m] of a vehicle holding in the air, every 0.1 s after
    40 s (its wander builds up over ~13 s), relative to its hold setpoint."""
    spec = replace(default_vehicle(1, on_ground=False), autopilot=autopilot)
    emu = Emulator([spec], seed=seed, param_overrides={"EMU_NOISE": noise})
    emu.nodes[0].links.append(RecordingLink())
    run_until(emu, 40.0, tick_s=0.5)
    plant = emu.plant
    track = []
    for k in range(int(seconds * 10)):
        emu.advance_to(40.0 + 0.1 * (k + 1))
        track.append(plant.onboard.position_est_enu_m[0] - plant.position_sp_enu_m[0])
    return np.array(track)


def test_px4_holds_its_position_setpoint_with_the_slow_wander_sih_showed():
    # GIVEN four px4 vehicles holding for 60 s (SIH, 2026-12-04 go-to-start recording, four
    # vehicles: 0.35-0.40 m RMS from the setpoint, moving slowly: their 2 s means 0.26-0.31 m
    # off at the median; benchmarks/bench_px4_hold.py compares the two in full)
    rms, means_2s = [], []
    for seed in range(1, 5):
        track = _hold_track("px4", 1, 60.0, seed)
        rms.append(float(np.sqrt((track ** 2).sum(axis=1).mean())))
        means = track[: len(track) // 20 * 20].reshape(-1, 20, 3).mean(axis=1)
        means_2s.append(float(np.median(np.linalg.norm(means, axis=1))))
    # THEN they wander as much, and slowly (their 2 s means stay off the setpoint); without the
    # wander the personality held 0.16 m RMS, its 2 s means 0.15 m off
    assert 0.25 <= float(np.median(rms)) <= 0.5, rms
    assert 0.2 <= float(np.median(means_2s)) <= 0.4, means_2s
    # AND without noise it holds to the millimetre, and ArduPilot's personality holds tightly
    assert np.abs(_hold_track("px4", 0, 20.0)).max() < 0.01
    ardupilot = _hold_track("ardupilot", 1, 20.0)
    assert float(np.sqrt((ardupilot ** 2).sum(axis=1).mean())) < 0.1
