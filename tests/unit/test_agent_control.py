"""The supervisor's and agents' control messages (gcs/agent/control.py): literal JSON, round
trips, every refusal by its reason, arbitrary bytes and JSON raising WireError only."""

from __future__ import annotations

import json

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gcs.agent.control import (
    MAX_CONTROL_BYTES,
    Abort,
    EdgeFigures,
    Gate,
    Heartbeat,
    OpenGate,
    Status,
    decode_control,
    encode_control,
)
from gcs.agent.wire import SUPERVISOR_ID, Echo, WireError
from gcs.config.modes import FlyAction

MESSAGES = [
    Heartbeat(1, 10.5),
    Heartbeat(2, 11.0, (OpenGate("armed", 9.0), OpenGate("formation", 10.9)), "operator",
              FlyAction.HOLD, (Echo(1, 3.0, 0.01), Echo(4, 3.5, 0.2))),
    Gate(3, 11.5, "formation", 10.9),
    Abort(4, 12.0, "geofence: vehicle 2", FlyAction.LAND),
    Status(2, 0, 5.0, "connect"),
    Status(2, 9, 6.0, "formation", "land", "landed", (
        EdgeFigures(1, received=10, lost=1, duplicates=2, corrupt=3, restarts=1,
                    corrupt_reason="magic b'XMST', expected b'FMST'", offset_s=-0.001,
                    uncertainty_s=0.0002),
        EdgeFigures(3))),
]


@pytest.mark.parametrize("message", MESSAGES, ids=lambda m: type(m).__name__)
def test_each_message_round_trips(message):
    assert decode_control(encode_control(message)) == message
    assert decode_control(encode_control(message), ids=(1, 2, 3, 4)) == message


def test_a_gate_and_a_status_as_literal_json():
    assert decode_control(b'{"kind":"gate","seq":3,"sent_s":11.5,"name":"formation",'
                          b'"opened_s":10.9}') == MESSAGES[2]
    assert json.loads(encode_control(Status(2, 1, 5, "connect", edges=(EdgeFigures(1),)))) == {
        "kind": "status", "vehicle_id": 2, "seq": 1, "sent_s": 5, "phase": "connect",
        "edges": [{"neighbour_id": 1, "received": 0, "lost": 0, "duplicates": 0, "corrupt": 0,
                   "restarts": 0}], "done": False}
    # AND an echo is [peer, sent_s, held_s], a gate [name, opened_s]
    beat = json.loads(encode_control(MESSAGES[1]))
    assert beat["echoes"][0] == [1, 3.0, 0.01] and beat["gates"][1] == ["formation", 10.9]


def test_the_loss_fraction():
    assert EdgeFigures(1, received=9, lost=1).loss_fraction == 0.1
    assert EdgeFigures(1).loss_fraction == 0.0


REFUSED = [
    (b"", r"not a JSON object"),
    (b"\xff\xfe\x00", r"not a JSON object"),
    (b"[1, 2]", r"expected a JSON object, got \[1, 2\]"),
    (b'{"seq": 1}', r"kind: expected one of heartbeat, gate, abort, status, got None"),
    (b'{"kind": "hello"}', r"kind: expected one of .* got 'hello'"),
    (b'{"kind": "heartbeat", "seq": 1}', r"heartbeat: missing field 'sent_s'"),
    (b'{"kind": "heartbeat", "seq": 1, "sent_s": 1, "extra": 2}',
     r"heartbeat: unknown field 'extra'"),
    (b'{"kind": "heartbeat", "seq": true, "sent_s": 1}',
     r"heartbeat\.seq: expected an integer in 0\.\.9007199254740992, got True"),
    (b'{"kind": "heartbeat", "seq": -1, "sent_s": 1}', r"heartbeat\.seq: expected an integer"),
    (b'{"kind": "heartbeat", "seq": 1, "sent_s": NaN}', r"not a JSON object: NaN is no JSON"),
    (b'{"kind": "heartbeat", "seq": 1, "sent_s": 1e400}',
     r"heartbeat\.sent_s: expected a finite number, got inf"),
    (b'{"kind": "heartbeat", "seq": 1, "sent_s": "1"}',
     r"heartbeat\.sent_s: expected a number, got '1'"),
    (b'{"kind": "heartbeat", "seq": 1, "sent_s": 1, "echoes": [[1, 2]]}',
     r"heartbeat\.echoes\[0\]: expected a list of 3, got \[1, 2\]"),
    (b'{"kind": "heartbeat", "seq": 1, "sent_s": 1, "echoes": [[0, 2, -1]]}',
     r"heartbeat\.echoes\[0\]\[2\]: expected >= 0, got -1\.0"),
    (b'{"kind": "heartbeat", "seq": 1, "sent_s": 1, "abort_reason": "x"}',
     r"heartbeat: abort_reason and abort_action go together"),
    (b'{"kind": "abort", "seq": 1, "sent_s": 1, "reason": "x", "action": "crash"}',
     r"abort\.action: expected one of land, hold, got 'crash'"),
    (b'{"kind": "gate", "seq": 1, "sent_s": 1, "name": "", "opened_s": 1}',
     r"gate\.name: expected a string of 1\.\.300 characters, got ''"),
    (b'{"kind": "status", "vehicle_id": 0, "seq": 1, "sent_s": 1, "phase": "p"}',
     r"status\.vehicle_id: expected an integer in 1\.\.4294967295, got 0"),
    (b'{"kind": "status", "vehicle_id": 1, "seq": 1, "sent_s": 1, "phase": "p", '
     b'"edges": [{"neighbour_id": 2}, {"neighbour_id": 2}]}',
     r"status\.edges\[1\]: neighbour 2 listed twice"),
    (b'{"kind": "status", "vehicle_id": 1, "seq": 1, "sent_s": 1, "phase": "p", '
     b'"edges": [{"neighbour_id": 2, "lost": 1.5}]}',
     r"status\.edges\[0\]\.lost: expected an integer"),
    (b"[" * 200_000 + b"]" * 200_000, r"400000 bytes, a control message has at most"),
    (b"[" * 60_000 + b"]" * 60_000, r"not a JSON object"),
    (b'{"kind": "gate", "seq": 1' + b"0" * 5000 + b"}", r"not a JSON object"),
]


@pytest.mark.parametrize(("data", "match"), REFUSED)
def test_each_bad_message_is_refused_with_its_reason(data, match):
    with pytest.raises(WireError, match=match):
        decode_control(data)


def test_the_team_ids_bound_every_vehicle_id():
    with pytest.raises(WireError, match=r"status\.vehicle_id: vehicle id 2 is no vehicle of"):
        decode_control(encode_control(MESSAGES[4]), ids=(1, 3))
    with pytest.raises(WireError, match=r"heartbeat\.echoes\[1\]\[0\]: vehicle id 4 is no"):
        decode_control(encode_control(MESSAGES[1]), ids=(1, 2))
    with pytest.raises(WireError, match=r"status\.edges\[1\]\.neighbour_id: vehicle id 3 is no"):
        decode_control(encode_control(MESSAGES[5]), ids=(1, 2))
    # AND the supervisor's id 0 is a valid echo peer whatever the team
    beat = Heartbeat(1, 1.0, echoes=(Echo(SUPERVISOR_ID, 1.0, 0.0),))
    assert decode_control(encode_control(beat), ids=(1,)) == beat


@pytest.mark.parametrize(("message", "match"), [
    (Gate(1, float("nan"), "g", 1.0), r"cannot encode Gate: Out of range float"),
    (Gate(1, 1.0, "g" * 301, 1.0), r"gate\.name: expected a string of 1\.\.300"),
    (Heartbeat(1, 1.0, abort_action=FlyAction.LAND), r"abort_reason and abort_action go"),
    (Status(0, 1, 1.0, "p"), r"status\.vehicle_id: expected an integer in 1"),
    ("hello", r"expected a control message, got str"),
])
def test_encode_refuses_what_decode_would(message, match):
    with pytest.raises(WireError, match=match):
        encode_control(message)
    assert len(MESSAGES) < MAX_CONTROL_BYTES


@settings(max_examples=1000, deadline=None)
@given(st.binary(max_size=300))
def test_arbitrary_bytes_raise_wire_error_only(data):
    try:
        decode_control(data)
    except WireError as exc:
        assert exc.reason and "\n" not in exc.reason


json_values = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=8),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=12), inner,
                                                                 max_size=5),
    max_leaves=12)
field_names = st.sampled_from(["seq", "sent_s", "gates", "abort_reason", "abort_action",
                               "echoes", "name", "opened_s", "reason", "action", "vehicle_id",
                               "phase", "waiting_gate", "outcome", "edges"])


@settings(max_examples=1000, deadline=None)
@given(st.sampled_from(["heartbeat", "gate", "abort", "status"]),
       st.dictionaries(field_names, json_values, max_size=8))
def test_arbitrary_json_of_each_kind_decodes_or_raises_wire_error_only(kind, fields):
    data = json.dumps({"kind": kind, **fields}).encode()
    try:
        message = decode_control(data)
    except WireError as exc:
        assert exc.reason and "\n" not in exc.reason
    else:
        assert decode_control(encode_control(message)) == message
