"""The supervisor's and the agents' control messages as small JSON objects (sans-IO): one frozen
dataclass per `kind`, `encode_control` / `decode_control`; every problem is a WireError.

Supervisor -> agents, on `<root>/supervisor`: `heartbeat` (periodic: the gates open so far, the
abort order if any, and an echo of each vehicle's newest state sample for the agents' clock
offsets), `gate` (a gate opens now) and `abort`. Agent -> supervisor, on
`<root>/agent/<id>/status`: `status` (phase, the gate it waits at, its outcome, its edges'
figures). A gate or an abort sent once is repeated in every later heartbeat, so a lost message
costs one heartbeat period. Times are the sender's wire clock [s] (gcs/agent/table.py).
"""

from __future__ import annotations

import dataclasses
import enum
import json
import math
from collections.abc import Callable, Collection
from dataclasses import dataclass
from typing import Any

from gcs.agent.wire import MAX_ECHOES, MAX_U32, SUPERVISOR_ID, Echo, WireError
from gcs.config.modes import FlyAction

MAX_CONTROL_BYTES = 256 * 1024
MAX_TEXT = 300  # characters of a phase, gate name, outcome or reason
MAX_PATH = 4096  # characters of a records directory
MAX_COUNT = 2**53  # counters: exact in a JSON number


class ControlKind(enum.StrEnum):
    HEARTBEAT = "heartbeat"
    GATE = "gate"
    ABORT = "abort"
    STATUS = "status"


@dataclass(frozen=True, slots=True)
class OpenGate:
    """Gate `name`, opened at `opened_s` (the supervisor's clock)."""

    name: str
    opened_s: float


@dataclass(frozen=True, slots=True)
class Heartbeat:
    """Supervisor -> agents, periodic. `echoes`: each vehicle's newest state sample since the
    last heartbeat (peer id the vehicle, its sent_s, held since); `abort_reason` and
    `abort_action` both or neither."""

    seq: int
    sent_s: float
    gates: tuple[OpenGate, ...] = ()
    abort_reason: str | None = None
    abort_action: FlyAction | None = None
    echoes: tuple[Echo, ...] = ()


@dataclass(frozen=True, slots=True)
class Gate:
    """Supervisor -> agents: gate `name` opened at `opened_s` (the supervisor's clock; a
    re-sent gate keeps it, so it can serve as a common start instant)."""

    seq: int
    sent_s: float
    name: str
    opened_s: float


@dataclass(frozen=True, slots=True)
class Abort:
    """Supervisor -> agents: stop flying the formation, do `action`."""

    seq: int
    sent_s: float
    reason: str
    action: FlyAction


@dataclass(frozen=True, slots=True)
class EdgeFigures:
    """What one process received from one neighbour: samples accepted, lost (gaps in seq),
    duplicates or out of order (dropped), corrupt (WireError; the last reason), restarts (a
    new epoch), and the neighbour's clock offset as the echoes measure it (its wire clock -
    ours, gcs/agent/table.py: with clocks disciplined, how far the two system clocks disagree)
    with a bound on its error (gcs/agent/clocks.py), None before the first echo."""

    neighbour_id: int
    received: int = 0
    lost: int = 0
    duplicates: int = 0
    corrupt: int = 0
    restarts: int = 0
    corrupt_reason: str | None = None
    offset_s: float | None = None
    uncertainty_s: float | None = None

    @property
    def loss_fraction(self) -> float:
        """lost / (received + lost); 0 before anything arrived."""
        total = self.received + self.lost
        return self.lost / total if total else 0.0


@dataclass(frozen=True, slots=True)
class Status:
    """Agent -> supervisor: vehicle `vehicle_id`'s phase, the gate it waits at (None: none),
    why it stops (`outcome`, with `exit_code`) from its stop on, `done` once its flight has
    ended (then `outcome` is its outcome), `records` where it wrote them, its formation time,
    and its edges' figures."""

    vehicle_id: int
    seq: int
    sent_s: float
    phase: str
    waiting_gate: str | None = None
    outcome: str | None = None
    edges: tuple[EdgeFigures, ...] = ()
    exit_code: int | None = None
    done: bool = False
    records: str | None = None
    formation_t_s: float | None = None


ControlMessage = Heartbeat | Gate | Abort | Status
_KINDS: dict[type, ControlKind] = {Heartbeat: ControlKind.HEARTBEAT, Gate: ControlKind.GATE,
                                   Abort: ControlKind.ABORT, Status: ControlKind.STATUS}

# --------------------------------------------------------------------------------------------
# Checks: (value, where, ids) -> the value as the dataclass holds it, or WireError.

Check = Callable[[Any, str, "Collection[int] | None"], Any]


def _show(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def _integer(lo: int, hi: int) -> Check:
    def check(value: Any, where: str, ids: Collection[int] | None) -> int:
        if not isinstance(value, int) or isinstance(value, bool) or not lo <= value <= hi:
            raise WireError(f"{where}: expected an integer in {lo}..{hi}, got {_show(value)}")
        return value
    return check


def _vehicle(value: Any, where: str, ids: Collection[int] | None) -> int:
    vid = _integer(1, MAX_U32)(value, where, ids)
    if ids is not None and vid not in ids:
        raise WireError(f"{where}: vehicle id {vid} is no vehicle of the team")
    return vid


def _number(value: Any, where: str, ids: Collection[int] | None) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise WireError(f"{where}: expected a number, got {_show(value)}")
    x = float(value)
    if not math.isfinite(x):
        raise WireError(f"{where}: expected a finite number, got {_show(value)}")
    return x


def _text(value: Any, where: str, ids: Collection[int] | None) -> str:
    if not isinstance(value, str) or not 1 <= len(value) <= MAX_TEXT:
        raise WireError(f"{where}: expected a string of 1..{MAX_TEXT} characters, got "
                        f"{_show(value)}")
    return value


def _flag(value: Any, where: str, ids: Collection[int] | None) -> bool:
    if not isinstance(value, bool):
        raise WireError(f"{where}: expected true or false, got {_show(value)}")
    return value


def _path(value: Any, where: str, ids: Collection[int] | None) -> str:
    if not isinstance(value, str) or not 1 <= len(value) <= MAX_PATH or "\x00" in value:
        raise WireError(f"{where}: expected a path of 1..{MAX_PATH} characters, got "
                        f"{_show(value)}")
    return value


def _action(value: Any, where: str, ids: Collection[int] | None) -> FlyAction:
    if value not in tuple(FlyAction):
        raise WireError(f"{where}: expected one of {', '.join(FlyAction)}, got {_show(value)}")
    return FlyAction(value)


def _optional(check: Check) -> Check:
    return lambda v, where, ids: None if v is None else check(v, where, ids)


def _tuple_of(check: Check, most: int) -> Check:
    def read(value: Any, where: str, ids: Collection[int] | None) -> tuple[Any, ...]:
        if not isinstance(value, list) or len(value) > most:
            raise WireError(f"{where}: expected a list of at most {most}, got {_show(value)}")
        return tuple(check(v, f"{where}[{k}]", ids) for k, v in enumerate(value))
    return read


def _record(make: Callable[..., Any], *checks: Check) -> Check:
    """A list of len(checks) values, each by its check, made into `make(*values)`."""
    def read(value: Any, where: str, ids: Collection[int] | None) -> Any:
        if not isinstance(value, list) or len(value) != len(checks):
            raise WireError(f"{where}: expected a list of {len(checks)}, got {_show(value)}")
        return make(*(c(v, f"{where}[{k}]", ids)
                      for k, (c, v) in enumerate(zip(checks, value, strict=True))))
    return read


def _peer(value: Any, where: str, ids: Collection[int] | None) -> int:
    return _vehicle(value, where, ids) if value != SUPERVISOR_ID else SUPERVISOR_ID


def _held(value: Any, where: str, ids: Collection[int] | None) -> float:
    x = _number(value, where, ids)
    if x < 0.0:
        raise WireError(f"{where}: expected >= 0, got {x!r}")
    return x


_ECHO = _record(Echo, _peer, _number, _held)
_GATE = _record(OpenGate, _text, _number)
_COUNT = _integer(0, MAX_COUNT)
_OPT_NUMBER = _optional(_number)

#: Per class: (field -> check); the optional fields are those with a dataclass default.
_SPECS: dict[type, dict[str, Check]] = {
    Heartbeat: {"seq": _COUNT, "sent_s": _number, "gates": _tuple_of(_GATE, 1000),
                "abort_reason": _optional(_text), "abort_action": _optional(_action),
                "echoes": _tuple_of(_ECHO, MAX_ECHOES)},
    Gate: {"seq": _COUNT, "sent_s": _number, "name": _text, "opened_s": _number},
    Abort: {"seq": _COUNT, "sent_s": _number, "reason": _text, "action": _action},
    EdgeFigures: {"neighbour_id": _vehicle, "received": _COUNT, "lost": _COUNT,
                  "duplicates": _COUNT, "corrupt": _COUNT, "restarts": _COUNT,
                  "corrupt_reason": _optional(_text), "offset_s": _OPT_NUMBER,
                  "uncertainty_s": _OPT_NUMBER},
}


def _object(cls: type) -> Check:
    """An object of `cls`'s fields (those without a default required), each by its check."""
    spec = _SPECS[cls]
    required = {f.name for f in dataclasses.fields(cls) if f.default is dataclasses.MISSING}

    def read(value: Any, where: str, ids: Collection[int] | None) -> Any:
        if not isinstance(value, dict):
            raise WireError(f"{where}: expected an object, got {_show(value)}")
        unknown = sorted(str(k) for k in value if k not in spec)
        if unknown:
            raise WireError(f"{where}: unknown field {unknown[0]!r}")
        missing = sorted(required - value.keys())
        if missing:
            raise WireError(f"{where}: missing field {missing[0]!r}")
        return cls(**{f: check(value[f], f"{where}.{f}", ids)
                      for f, check in spec.items() if f in value})
    return read


def _unique_edges(edges: tuple[EdgeFigures, ...], where: str) -> None:
    seen = [e.neighbour_id for e in edges]
    for k, vid in enumerate(seen):
        if vid in seen[:k]:
            raise WireError(f"{where}.edges[{k}]: neighbour {vid} listed twice")


_SPECS[Status] = {"vehicle_id": _vehicle, "seq": _COUNT, "sent_s": _number, "phase": _text,
                  "waiting_gate": _optional(_text), "outcome": _optional(_text),
                  "edges": _tuple_of(_object(EdgeFigures), MAX_ECHOES),
                  "exit_code": _optional(_integer(0, 255)), "done": _flag,
                  "records": _optional(_path), "formation_t_s": _OPT_NUMBER}
_READERS = {kind: _object(cls) for cls, kind in _KINDS.items()}
_CLASSES = {kind: cls for cls, kind in _KINDS.items()}


def _no_constant(name: str) -> Any:
    raise ValueError(f"{name} is no JSON number")


def decode_control(data: bytes | bytearray | memoryview,
                   ids: Collection[int] | None = None) -> ControlMessage:
    """The control message in `data` (UTF-8 JSON with a `kind`); WireError, and nothing else,
    for any bytes that are not one valid message. `ids`: the team's vehicle ids, when every
    vehicle id in it must be one of them."""
    data = bytes(data)
    if len(data) > MAX_CONTROL_BYTES:
        raise WireError(f"{len(data)} bytes, a control message has at most {MAX_CONTROL_BYTES}")
    try:
        value = json.loads(data, parse_constant=_no_constant)
    except (ValueError, RecursionError) as exc:  # UnicodeDecodeError, JSONDecodeError: ValueError
        raise WireError(f"not a JSON object: {' '.join(str(exc).split())[:200]}") from exc
    if not isinstance(value, dict):
        raise WireError(f"expected a JSON object, got {_show(value)}")
    kind = value.pop("kind", None)
    if kind not in _READERS:
        raise WireError(f"kind: expected one of {', '.join(ControlKind)}, got {_show(kind)}")
    message = _READERS[kind](value, str(kind), ids)
    if isinstance(message, Heartbeat) and (
            (message.abort_reason is None) != (message.abort_action is None)):
        raise WireError("heartbeat: abort_reason and abort_action go together")
    if isinstance(message, Status):
        _unique_edges(message.edges, "status")
    return message


def _plain(x: Any) -> Any:
    if isinstance(x, Echo):
        return [x.peer_id, x.sent_s, x.held_s]
    if isinstance(x, OpenGate):
        return [x.name, x.opened_s]
    if isinstance(x, enum.Enum):
        return x.value
    if dataclasses.is_dataclass(x):
        return {f.name: _plain(getattr(x, f.name)) for f in dataclasses.fields(x)
                if getattr(x, f.name) is not None}
    if isinstance(x, tuple | list):
        return [_plain(v) for v in x]
    return x


def encode_control(message: ControlMessage) -> bytes:
    """`message` as compact UTF-8 JSON; WireError if it would not decode (a value out of range,
    not finite, a text too long), by the same checks `decode_control` makes."""
    if type(message) not in _KINDS:
        raise WireError(f"expected a control message, got {type(message).__name__}")
    try:
        out = json.dumps({"kind": _KINDS[type(message)].value, **_plain(message)},
                         separators=(",", ":"), allow_nan=False).encode()
    except (TypeError, ValueError) as exc:
        raise WireError(f"cannot encode {type(message).__name__}: {exc}") from exc
    decode_control(out)
    return out
