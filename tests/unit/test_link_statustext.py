"""STATUSTEXT capture without sockets: severity, text, time, MAVLink 2 chunks, odd bytes."""

from __future__ import annotations

import logging

import pytest
from pymavlink.dialects.v20 import common as mavlink

from gcs.link.statustext import CHUNK_TIMEOUT_S, StatusText, StatusTextLog

VEHICLE = mavlink.MAVLink(None, 1, 1)
GCS = mavlink.MAVLink(None, 255, 190)


def wire(severity: int, text: bytes, text_id: int = 0, seq: int = 0) -> mavlink.MAVLink_message:
    """A STATUSTEXT as a ground station decodes it (packed by the vehicle, parsed by pymavlink)."""
    msg = mavlink.MAVLink_statustext_message(severity, text, text_id, seq)
    (decoded,) = GCS.parse_buffer(msg.pack(VEHICLE))
    return decoded


def test_a_text_is_kept_with_severity_and_time_and_logged(caplog) -> None:
    log = StatusTextLog("vehicle 1 (sysid 1)")
    with caplog.at_level(logging.INFO, logger="gcs.link.statustext"):
        got = log.feed(wire(2, b"Arming denied: not landed\t"), 12.5)
    # PX4 v1.16.0's trailing TAB is stripped
    assert got == StatusText(2, "Arming denied: not landed", 12.5)
    assert got.quoted() == 'CRITICAL "Arming denied: not landed"'
    assert log.latest() == got and log.latest(since_s=12.6) is None
    assert "vehicle 1 (sysid 1): STATUSTEXT CRITICAL: Arming denied: not landed" in caplog.text
    assert caplog.records[-1].levelno == logging.WARNING


def test_chunks_of_one_id_are_joined_and_the_short_chunk_ends_the_text() -> None:
    log = StatusTextLog("v")
    # PX4's 52-byte refusal (its text and TAB) comes in two chunks
    text = b"Arming denied: Resolve system health failures first\t"
    assert log.feed(wire(4, text[:50], 7, 0), 1.0) is None
    got = log.feed(wire(4, text[50:], 7, 1), 1.1)
    assert got is not None and got.rx_time_s == 1.1
    assert got.text == "Arming denied: Resolve system health failures first"
    assert log.count == 1


def test_a_chunked_text_whose_end_never_comes_is_completed_marked() -> None:
    log = StatusTextLog("v")
    log.feed(wire(4, b"x" * 50, 3, 0), 1.0)
    log.feed(wire(4, b"y" * 50, 3, 2), 1.1)  # chunk 1 lost, last chunk missing
    # WHEN another text arrives THEN the broken one is completed first, marked where it lacks
    log.feed(wire(6, b"next"), 1.2)
    texts = [t.text for t in log.texts()]
    assert texts == ["x" * 50 + "[...]" + "y" * 50, "next"]
    # AND a lone first chunk is completed after CHUNK_TIMEOUT_S by the next chunk of its own id
    log.feed(wire(4, b"z" * 50, 4, 0), 2.0)
    log.feed(wire(4, b"w" * 50, 4, 0), 2.0 + CHUNK_TIMEOUT_S + 0.1)
    assert log.texts()[2].text == "z" * 50


@pytest.mark.parametrize("raw,expected", [
    (b"Arm: \xff\xfe bad", "Arm: \ufffd\ufffd bad"),
    (b"ok\x00junk after the nul", "ok"),
    (b"tab\tand\nnewline\r", "tab and newline"),
    (b"", ""),
])
def test_odd_bytes_never_raise(raw: bytes, expected: str) -> None:
    log = StatusTextLog("v")
    assert log.feed(wire(6, raw), 0.0).text == expected


def test_a_message_with_missing_or_bad_fields_never_raises() -> None:
    class Odd:
        severity = "x"
        text = b"Arm: \xff"
        id = None
        chunk_seq = "?"

    log = StatusTextLog("v")
    got = log.feed(Odd(), 0.0)
    assert got is not None and got.severity == 6 and got.text == "Arm: \ufffd"
    assert log.feed(object(), 1.0).text == ""
    assert StatusText(42, "t", 0.0).severity_name == "SEVERITY(42)"
