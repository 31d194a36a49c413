"""Each team-file key declared once, as a dataclass field.

A field made with `key(...)` carries what the team file needs to know about it: its default (the
dataclass default is the file's default), its bounds or choices, its YAML name where that is not
the field's name, and, for the few values that are not a plain number, integer, flag, string,
vector, enum or section, its own reader. `read_section` reads a mapping from those declarations
(the allowed keys, which are required, every value's check, the key path and line in each
error); `to_plain` writes a section back under the same names. The field's type annotation says
how its value is read:

| annotation                    | read as                                                      |
|-------------------------------|--------------------------------------------------------------|
| float, int, bool, str         | a finite number within the bounds, an integer, a flag, a string |
| an enum                       | one of its values (or `choices`), as the member              |
| tuple[float, float, float]    | a list of 3 numbers (`gt` bounds each)                       |
| a dataclass                   | a nested section, read by the same rules                     |
| tuple[a dataclass, ...]       | a list of such sections (absent: empty)                      |
| X | None                      | X, or None when the key is absent (its default must be None) |
"""

from __future__ import annotations

import dataclasses
import enum
import functools
import types
import typing
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from gcs.config.yamlnode import Node

#: A field's reader: (its node, its default or dataclasses.MISSING) -> its value.
Reader = Callable[["Node", Any], Any]
#: A check run on a value once it is read: (its node, the value) -> None, or node.fail(...).
Check = Callable[["Node", Any], None]

_VEC3 = tuple[float, float, float]


def key(
    default: Any = dataclasses.MISSING,
    *,
    gt: float | None = None,
    ge: float | None = None,
    lt: float | None = None,
    le: float | None = None,
    choices: Sequence[Any] = (),
    name: str | None = None,
    read: Reader | None = None,
    check: Check | None = None,
    optional: bool = False,
    internal: bool = False,
    write: Callable[[Any], Any] | None = None,
) -> Any:
    """A dataclass field that is a team-file key. `name`: its YAML key (default: the field's
    name); `optional`: the key may be left out although the field has no default (the section's
    reader supplies the value, as `given` to read_section); `internal`: no team-file key at all
    (a value the reader adds, such as the file's path); `write`: the value's plain form, for a
    value its own reader reads from a shape `to_plain` does not write (a mapping keyed by id)."""
    bounds = {k: v for k, v in (("gt", gt), ("ge", ge), ("lt", lt), ("le", le)) if v is not None}
    meta = {"bounds": bounds, "choices": tuple(choices), "name": name, "read": read,
            "check": check, "optional": optional, "internal": internal, "write": write}
    return dataclasses.field(default=default, metadata=meta)


def yaml_name(f: dataclasses.Field[Any]) -> str:
    """The team-file key of dataclass field `f`."""
    return f.metadata.get("name") or f.name


def section_keys(cls: type, default: Any = None) -> tuple[list[str], list[str]]:
    """(required, optional) YAML keys of section `cls`; with a `default` instance every key is
    optional (the instance gives the values left out)."""
    required, optional = [], []
    for f in _keys(cls):
        needed = (default is None and f.default is dataclasses.MISSING
                  and not f.metadata.get("optional"))
        (required if needed else optional).append(yaml_name(f))
    return required, optional


def read_section(node: Node, cls: type, default: Any = None, *,
                 given: dict[str, Callable[[dict[str, Any]], Any]] | None = None,
                 extra_keys: Sequence[str] = ()) -> Any:
    """Section `cls` from mapping `node`: `default` (an instance) when the node is absent, else
    each declared key read and checked, in field order. `given`: field -> a function of the
    values read so far giving its value (what the section's own reader works out: values that
    depend on other keys or sections);
    `extra_keys`: further allowed keys that are no field (read elsewhere). The declared keys are
    read in field order, then the given ones in the order of `given`."""
    if node.absent and default is not None:
        return default
    required, optional = section_keys(cls, default)
    node.keys(" ".join(required), " ".join([*optional, *extra_keys]))
    hints = _hints(cls)
    given = given or {}
    values = {}
    for f in dataclasses.fields(cls):
        fallback = getattr(default, f.name) if default is not None else f.default
        if f.name not in given:
            values[f.name] = read_value(node.child(yaml_name(f)), hints[f.name], f.metadata,
                                        fallback)
    for name, work_out in given.items():
        values[name] = work_out(values)
    return cls(**values)


def _keys(cls: type) -> list[dataclasses.Field[Any]]:
    return [f for f in dataclasses.fields(cls) if not f.metadata.get("internal")]


def read_field(node: Node, cls: type, name: str, **bounds: float) -> Any:
    """Field `name` of section `cls` read from mapping `node` by its declaration; `bounds` add
    to the declared ones (bounds known only when the file is read, such as the mission's end)."""
    f = cls.__dataclass_fields__[name]
    meta = {**f.metadata, "bounds": {**f.metadata.get("bounds", {}), **bounds}}
    return read_value(node.child(yaml_name(f)), _hints(cls)[name], meta, f.default)


@functools.cache
def _hints(cls: type) -> dict[str, Any]:
    """The resolved annotations of section `cls` (a class's annotations do not change)."""
    return typing.get_type_hints(cls)


def read_value(node: Node, hint: Any, meta: typing.Mapping[str, Any], fallback: Any) -> Any:
    """One declared value (see the module's table); `fallback` is its default or MISSING."""
    default = {} if fallback is dataclasses.MISSING else {"default": fallback}
    hint = _strip_none(hint)
    bounds, choices = meta.get("bounds", {}), meta.get("choices", ())
    if meta.get("read") is not None:
        value = meta["read"](node, fallback)
    elif typing.get_origin(hint) is tuple and dataclasses.is_dataclass(typing.get_args(hint)[0]):
        item = typing.get_args(hint)[0]
        names = ", ".join(yaml_name(f) for f in dataclasses.fields(item))
        value = tuple(read_section(n, item)
                      for n in node.items(f"{node.path.rsplit('.', 1)[-1]} {{{names}}}"))
    elif dataclasses.is_dataclass(hint):
        if node.absent and fallback is not dataclasses.MISSING:
            return fallback
        value = read_section(node, hint, None if fallback is dataclasses.MISSING else fallback)
    elif isinstance(hint, type) and issubclass(hint, enum.Enum):
        value = hint(node.string(**default, choices=choices or tuple(hint)))
    elif hint is bool:
        value = node.boolean(**default)
    elif hint is int:
        value = node.integer(**default, **bounds)
    elif hint is float:
        value = node.number(**default, **bounds)
    elif hint is str:
        value = node.string(**default, choices=choices)
    elif hint == _VEC3:
        value = node.vec3(**default, **bounds)
    else:
        raise TypeError(f"no reader for a field of type {hint!r}: declare key(read=...)")
    if meta.get("check") is not None and not node.absent:
        meta["check"](node, value)
    return value


def _strip_none(hint: Any) -> Any:
    """X for X | None (the None is the absent key's default)."""
    if isinstance(hint, types.UnionType) or typing.get_origin(hint) is typing.Union:
        args = [a for a in typing.get_args(hint) if a is not type(None)]
        return args[0] if len(args) == 1 else hint
    return hint


def to_plain(x: Any, special: Callable[[Any], Any] | None = None) -> Any:
    """A section (or any value in one) as plain YAML data under its declared names: None fields
    left out, an enum as its value, tuples as lists. `special(x)`: the plain form of a value
    that is written otherwise, or None to write it by these rules."""
    if special is not None and (out := special(x)) is not None:
        return out
    if isinstance(x, enum.Enum):
        return x.value
    if dataclasses.is_dataclass(x):
        return {yaml_name(f): (f.metadata["write"](getattr(x, f.name)) if f.metadata.get("write")
                               else to_plain(getattr(x, f.name), special))
                for f in _keys(type(x)) if getattr(x, f.name) is not None}
    return [to_plain(v, special) for v in x] if isinstance(x, tuple) else x
