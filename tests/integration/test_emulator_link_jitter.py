"""packet_loss with latency, jitter and reordering over real UDP on 127.0.0.1, seen by pymavlink:
TIMESYNC round trips and MAVLink sequence numbers, during the fault's window and after it."""

from __future__ import annotations

import logging
import statistics
import time
from dataclasses import dataclass, field

import pytest
import yaml
from pymavlink.dialects.v20 import common as mavlink

from vehicle_emulator.faults import REORDER_HOLD_S
from vehicle_emulator.testing import MavClient, free_udp_port, run_emulator

pytestmark = [pytest.mark.integration, pytest.mark.timeout(90)]

log = logging.getLogger(__name__)

LATENCY_MS, JITTER_MS, REORDER_P = 30.0, 10.0, 0.2
WINDOW_S = 8.0  # the fault's duration_s, from boot (EMU_FLT_T0 = 1)
# mean one-way delay: latency + uniform jitter mean + the hold of the reordered share
ONE_WAY_MS = LATENCY_MS + JITTER_MS / 2.0 + REORDER_P * REORDER_HOLD_S * 1e3  # 39 ms


@dataclass
class Measured:
    """What the ground side saw: TIMESYNC round trips [ms] and sequence steps backwards."""

    rtt_ms: list[float] = field(default_factory=list)
    messages: int = 0
    backwards: int = 0


def _measure(client: MavClient, duration_s: float, rate_hz: float = 100.0) -> Measured:
    """Send TIMESYNC (tc1 = 0, ts1 = our monotonic ns) at ``rate_hz`` for ``duration_s``; time
    the answers (tc1 = the emulator's time, ts1 echoed) and count every message whose MAVLink
    sequence number is behind the one before it (it was overtaken)."""
    out, sent, last_seq = Measured(), set(), None
    end = time.monotonic() + duration_s
    next_send = time.monotonic()
    while (now := time.monotonic()) < end:
        if now >= next_send:
            ts1 = time.monotonic_ns()
            sent.add(ts1)
            client.send(mavlink.MAVLink_timesync_message(0, ts1))
            next_send += 1.0 / rate_hz
        m = client.recv(max(0.0, min(next_send, end) - time.monotonic()))
        if m is None or m.get_srcSystem() != 1:
            continue
        out.messages += 1
        seq = m.get_seq()
        if last_seq is not None and (seq - last_seq) % 256 > 128:
            out.backwards += 1
        last_seq = seq
        if m.get_type() == "TIMESYNC" and m.tc1 != 0 and m.ts1 in sent:
            out.rtt_ms.append((time.monotonic_ns() - m.ts1) * 1e-6)
    return out


def test_latency_jitter_and_reordering_from_boot_then_a_clean_link(tmp_path):
    # GIVEN a packet_loss fault from boot: 30 ms + uniform jitter 10 ms, 20 % reordered, 8 s
    team = tmp_path / "team.yaml"
    team.write_text(yaml.safe_dump({
        "vehicles": [{"id": 1}],
        "faults": [{"kind": "packet_loss", "vehicle": 1, "at_s": 0.0, "probability": 0.0,
                    "latency_ms": LATENCY_MS, "jitter_ms": JITTER_MS, "jitter": "uniform",
                    "reorder_probability": REORDER_P, "duration_s": WINDOW_S}],
    }))
    port = free_udp_port()
    client = MavClient(port)
    args = ["--id", "1", "--team", str(team), "--param", "EMU_FLT_T0=1"]
    with run_emulator(args, remote_port=port, log_dir=str(tmp_path)):
        client.wait("HEARTBEAT", 60)
        # WHEN the ground side times TIMESYNCs and watches sequence numbers for 4 s
        faulty = _measure(client, 4.0)
        texts = [m.text for m in client.seen("STATUSTEXT")]
        assert any(t.startswith("Fault: loss 0.00 +30+U10 ms reorder 0.20") for t in texts)
        assert not any(t.startswith("Fault end") for t in texts), "the window ended too soon"
        # AND again once the window is over and in-flight packets have landed
        client.wait_text(WINDOW_S + 5.0, lambda t: t.startswith("Fault end: loss 0.00 +0 ms"))
        client.collect(0.3)
        clean = _measure(client, 2.0)
    client.close()
    rtt = faulty.rtt_ms
    log.info(
        "fault: %d RTTs mean %.1f ms (expected %.1f) min %.1f p95 %.1f max %.1f sd %.1f; %d of "
        "%d messages behind; clean: mean %.2f ms max %.2f, %d of %d behind",
        len(rtt), statistics.fmean(rtt), 2 * ONE_WAY_MS, min(rtt),
        statistics.quantiles(rtt, n=20)[-1], max(rtt), statistics.stdev(rtt),
        faulty.backwards, faulty.messages,
        statistics.fmean(clean.rtt_ms), max(clean.rtt_ms), clean.backwards, clean.messages,
    )
    # THEN each round trip is at least twice the latency (jitter and hold only add), and 95 % of
    # them are within twice latency + jitter + hold = 120 ms (+ 10 ms for scheduling on a loaded
    # machine, which has made single ones late by 30 ms)
    assert len(rtt) > 300
    assert min(rtt) >= 2 * LATENCY_MS
    p95 = statistics.quantiles(rtt, n=20)[-1]
    assert p95 <= 2 * (LATENCY_MS + JITTER_MS + REORDER_HOLD_S * 1e3) + 10.0
    # AND the mean is 2 (30 + 5 + 0.2 * 20) = 78 ms: the standard error of 300+ samples is
    # < 1 ms; without the reorder hold it would be 70, without the jitter 68
    assert 2 * ONE_WAY_MS - 3.0 <= statistics.fmean(rtt) <= 2 * ONE_WAY_MS + 8.0
    # AND packets overtake each other (held ones, and jittered ones closer than 10 ms)
    assert faulty.backwards > 0.05 * faulty.messages
    # AND after the window the link is clean again: in order, no added delay
    assert clean.backwards == 0 and clean.messages > 500
    assert statistics.fmean(clean.rtt_ms) < 10.0
