"""The agents' state samples as bytes (sans-IO): one fixed little-endian layout, encoded and
decoded with struct; every problem with the bytes is a WireError with its reason.

A sample says what one vehicle's state was when its vehicle took it, in the world ENU frame:

| field                 | type          | meaning                                                |
|-----------------------|---------------|--------------------------------------------------------|
| magic, version        | 4s, u8        | b"FMST", 1                                             |
| flags                 | u8            | 0 (reserved)                                           |
| n_echoes              | u16           | number of echoes at the end                            |
| vehicle_id            | u32           | the sender's vehicle (>= 1)                            |
| epoch                 | u32           | the sending process's start: a new one resets seq      |
| seq                   | u32           | +1 per sample of this vehicle and epoch                |
| taken_s, sent_s       | f64, f64      | sender's wire clock: vehicle took it; published        |
| position_enu_m        | 3 f64         | world ENU [m]                                          |
| velocity_enu_mps      | 3 f64         | world ENU [m/s]                                        |
| acceleration_enu_mps2 | 3 f64         | world ENU [m/s^2]                                      |
| attitude_wxyz         | 4 f64         | quaternion FLU -> ENU, w first                         |
| omega_flu_radps       | 3 f64         | body rates, FLU [rad/s]                                |
| echoes[n]             | u32, f64, f64 | peer id, a sent_s of that peer received, held_s        |

An echo hands a peer back its own send time with how long the sender held it: with the peer's
receive time the four timestamps of an NTP exchange (gcs/agent/clocks.py). A sample echoes
each message heard since its vehicle's last sample, so a peer may appear more than once, or not
at all (gcs/agent/table.py). Peer id 0 is the supervisor (its heartbeats carry sent_s;
gcs/agent/control.py).
"""

from __future__ import annotations

import math
import struct
from collections.abc import Collection
from dataclasses import dataclass

MAGIC = b"FMST"
VERSION = 1
#: The echo peer id that names the supervisor (vehicle ids are >= 1).
SUPERVISOR_ID = 0
MAX_U32 = 2**32 - 1
MAX_ECHOES = 1024

_HEAD = struct.Struct("<4sBBHIIIdd")
_BODY = struct.Struct("<16d")
_ECHO = struct.Struct("<Idd")
HEAD_BYTES, BODY_BYTES, ECHO_BYTES = _HEAD.size, _BODY.size, _ECHO.size

Vec3 = tuple[float, float, float]
Quat = tuple[float, float, float, float]


class WireError(ValueError):
    """Bytes that are no valid message (or a message that cannot be encoded); `reason` says
    why in one line."""

    def __init__(self, reason: str) -> None:
        super().__init__(reason)
        self.reason = reason


@dataclass(frozen=True, slots=True)
class Echo:
    """Peer `peer_id`'s last sample received: its `sent_s` (the peer's clock) and how long the
    sender of the echo held it before sending the echo, `held_s` (>= 0)."""

    peer_id: int
    sent_s: float
    held_s: float


@dataclass(frozen=True, slots=True)
class StateSample:
    """One vehicle's state as its agent publishes it (frames and units in the field names;
    times on the sender's wire clock: its monotonic clock, or its system clock with
    network.clocks disciplined; gcs/agent/table.py)."""

    vehicle_id: int
    epoch: int
    seq: int
    taken_s: float
    sent_s: float
    position_enu_m: Vec3
    velocity_enu_mps: Vec3
    acceleration_enu_mps2: Vec3
    attitude_wxyz: Quat  # FLU -> ENU
    omega_flu_radps: Vec3
    echoes: tuple[Echo, ...] = ()


def _check_id(vid: int, what: str, ids: Collection[int] | None, *, supervisor: bool) -> None:
    low = SUPERVISOR_ID if supervisor else 1
    if not low <= vid <= MAX_U32:
        raise WireError(f"{what} {vid} is outside {low}..{MAX_U32}")
    if ids is not None and vid not in ids and not (supervisor and vid == SUPERVISOR_ID):
        raise WireError(f"{what} {vid} is no vehicle of the team")


def _check_finite(values: tuple[float, ...], names: tuple[str, ...]) -> None:
    for value, name in zip(values, names, strict=True):
        if not math.isfinite(value):
            raise WireError(f"{name} is {value!r}, expected a finite number")


_BODY_NAMES = tuple(f"{name}[{k}]" for name, n in (
    ("position_enu_m", 3), ("velocity_enu_mps", 3), ("acceleration_enu_mps2", 3),
    ("attitude_wxyz", 4), ("omega_flu_radps", 3)) for k in range(n))


def encode(sample: StateSample) -> bytes:
    """`sample` as bytes; WireError if it holds a value the layout cannot carry (an id, seq or
    epoch out of range, a non-finite number, a negative hold, too many echoes)."""
    s = sample
    _check_id(s.vehicle_id, "vehicle id", None, supervisor=False)
    for name, value in (("epoch", s.epoch), ("seq", s.seq)):
        if not 0 <= value <= MAX_U32:
            raise WireError(f"{name} {value} is outside 0..{MAX_U32}")
    if len(s.echoes) > MAX_ECHOES:
        raise WireError(f"{len(s.echoes)} echoes, at most {MAX_ECHOES}")
    body = (*s.position_enu_m, *s.velocity_enu_mps, *s.acceleration_enu_mps2,
            *s.attitude_wxyz, *s.omega_flu_radps)
    if len(body) != 16:
        raise WireError(f"expected 3 + 3 + 3 + 4 + 3 state values, got {len(body)}")
    body = tuple(float(x) for x in body)
    _check_finite((float(s.taken_s), float(s.sent_s), *body), ("taken_s", "sent_s", *_BODY_NAMES))
    for e in s.echoes:
        _check_echo(e.peer_id, float(e.sent_s), float(e.held_s), None)
    try:
        parts = [_HEAD.pack(MAGIC, VERSION, 0, len(s.echoes), s.vehicle_id, s.epoch, s.seq,
                            s.taken_s, s.sent_s), _BODY.pack(*body)]
        parts += [_ECHO.pack(e.peer_id, e.sent_s, e.held_s) for e in s.echoes]
    except struct.error as exc:  # an id, seq or epoch that is no integer
        raise WireError(f"cannot encode the sample of vehicle {s.vehicle_id!r}: {exc}") from exc
    return b"".join(parts)


def _check_echo(peer_id: int, sent_s: float, held_s: float, ids: Collection[int] | None) -> None:
    _check_id(peer_id, "echo peer id", ids, supervisor=True)
    _check_finite((sent_s, held_s), ("echo sent_s", "echo held_s"))
    if held_s < 0.0:
        raise WireError(f"echo held_s {held_s!r} is negative")


def decode(data: bytes | bytearray | memoryview, ids: Collection[int] | None = None) -> StateSample:
    """The sample in `data`; WireError (and nothing else) for any bytes that are not one whole
    valid sample. `ids`: the team's vehicle ids, when the sender and every echo's peer must be
    one of them (or the supervisor, for a peer)."""
    data = bytes(data)
    if len(data) < HEAD_BYTES + BODY_BYTES:
        raise WireError(f"{len(data)} bytes, a sample has at least {HEAD_BYTES + BODY_BYTES}")
    magic, version, flags, n, vid, epoch, seq, taken_s, sent_s = _HEAD.unpack_from(data)
    if magic != MAGIC:
        raise WireError(f"magic {magic!r}, expected {MAGIC!r}")
    if version != VERSION:
        raise WireError(f"version {version}, this program reads {VERSION}")
    if flags != 0:
        raise WireError(f"reserved flags {flags:#04x} set")
    if n > MAX_ECHOES:
        raise WireError(f"{n} echoes, at most {MAX_ECHOES}")
    size = HEAD_BYTES + BODY_BYTES + n * ECHO_BYTES
    if len(data) != size:
        raise WireError(f"{len(data)} bytes, a sample with {n} echoes has {size}")
    _check_id(vid, "vehicle id", ids, supervisor=False)
    body = _BODY.unpack_from(data, HEAD_BYTES)
    _check_finite((taken_s, sent_s, *body), ("taken_s", "sent_s", *_BODY_NAMES))
    echoes = []
    for k in range(n):
        peer, e_sent, held = _ECHO.unpack_from(data, HEAD_BYTES + BODY_BYTES + k * ECHO_BYTES)
        _check_echo(peer, e_sent, held, ids)
        echoes.append(Echo(peer, e_sent, held))
    return StateSample(vid, epoch, seq, taken_s, sent_s, body[0:3], body[3:6], body[6:9],
                       body[9:13], body[13:16], tuple(echoes))
