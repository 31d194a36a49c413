"""YAML with line numbers -> a node that checks values and names the key path and line in every
ConfigError.

`parse_yaml` is pyyaml's safe loader, except that it keeps the line of every key and list item,
refuses duplicate keys and reads 1e4 as a number; `Dumper` writes YAML that it reads back the
same. A `Node` is one value with its key path and line; each read returns a checked value or raises.
"""

from __future__ import annotations

import difflib
import math
import numbers
import os
import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any, NoReturn

import numpy as np
import yaml

from gcs.config.schema import ConfigError, _choices

# --------------------------------------------------------------------------------------------
# YAML: safe loading that keeps line numbers, rejects duplicate keys and reads 1e4 as a number.


class _YamlMap(dict):
    __slots__ = ("lines",)


class _YamlSeq(list):
    __slots__ = ("lines",)


class _Loader(yaml.SafeLoader):
    """yaml.SafeLoader (nothing but plain data) that records the line of every key and item."""


class Dumper(yaml.SafeDumper):
    """yaml.SafeDumper that quotes every string `_Loader` would read as something else."""


# pyyaml follows YAML 1.1, which reads 1e4 and 1.0e4 as strings; here they are numbers (YAML 1.2),
# and the dumper quotes such strings (a name "1e4") so that what it writes reads back the same.
for _cls in (_Loader, Dumper):
    _cls.add_implicit_resolver(
        "tag:yaml.org,2002:float",
        re.compile(r"^[-+]?(?:[0-9][0-9_]*(?:\.[0-9_]*)?|\.[0-9_]+)[eE][-+]?[0-9]+$"),
        list("-+0123456789."),
    )


def _construct_map(loader: _Loader, node: yaml.MappingNode) -> _YamlMap:
    loader.flatten_mapping(node)
    out = _YamlMap()
    out.lines = {}
    for key_node, value_node in node.value:
        key = loader.construct_object(key_node, deep=True)
        if not isinstance(key, str | int | float | bool | None):
            raise yaml.constructor.ConstructorError(
                None, None, "a key must be a plain scalar", key_node.start_mark
            )
        if key in out:
            raise yaml.constructor.ConstructorError(
                None,
                None,
                f"duplicate key {key!r} (first on line {out.lines[key]})",
                key_node.start_mark,
            )
        out[key] = loader.construct_object(value_node, deep=True)
        out.lines[key] = key_node.start_mark.line + 1
    return out


def _construct_seq(loader: _Loader, node: yaml.SequenceNode) -> _YamlSeq:
    out = _YamlSeq(loader.construct_object(child, deep=True) for child in node.value)
    out.lines = {k: child.start_mark.line + 1 for k, child in enumerate(node.value)}
    return out


_Loader.add_constructor("tag:yaml.org,2002:map", _construct_map)
_Loader.add_constructor("tag:yaml.org,2002:seq", _construct_seq)


#: pyyaml contexts whose mark is where a construct opened that the parser found unfinished: the
#: fault is on that line, however far below the parser gave up (a missing `]` on line 35 is
#: noticed at the next key, line 45). Other contexts (`while parsing a block mapping`) mark the
#: enclosing block; there the fault is where the parser stopped.
_OPENED_AT_CONTEXT = {
    "while parsing a flow mapping": "the flow mapping opened there is not closed",
    "while parsing a flow sequence": "the flow sequence opened there is not closed",
    "while scanning a quoted scalar": "the quoted string opened there is not closed",
    "while scanning a simple key": "the key there has no ':'",
}


def _yaml_error(exc: yaml.MarkedYAMLError, source: str) -> ConfigError:
    """One line naming the line of the fault and the line where pyyaml gave up, if another."""
    context, problem = exc.context_mark, exc.problem_mark
    opened = _OPENED_AT_CONTEXT.get(exc.context or "")
    fault = context if opened is not None and context is not None else problem or context
    if fault is None:
        return ConfigError(source, "(top level)", f"invalid YAML: {exc.problem or exc}")
    notes = []
    if opened is not None:
        notes.append(opened)
    elif exc.context and context is not None and context.line != fault.line:
        what = exc.context.removeprefix("while parsing a ")
        notes.append(f"in the {what} that starts at line {context.line + 1}"
                     if what != exc.context else f"{exc.context} at line {context.line + 1}")
    if problem is not None and problem.line != fault.line:
        notes.append(f"the parser gave up at line {problem.line + 1}")
    syntax = isinstance(exc, yaml.scanner.ScannerError | yaml.parser.ParserError)
    kind = "YAML syntax error" if syntax else "invalid YAML"
    where = f"{kind} at line {fault.line + 1}, column {fault.column + 1}" + (
        f" ({'; '.join(notes)})" if notes else "")
    err = ConfigError(source, where, exc.problem or exc.context or "syntax error")
    err.line = fault.line + 1
    return err


def read_text(path: str | os.PathLike[str]) -> tuple[str, str]:
    """(the path as given, the file's text); an unreadable file is one ConfigError."""
    source = os.fspath(path)
    try:
        return source, Path(source).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(source, "(file)", f"cannot read: {exc}") from None


def parse_yaml(text: str, source: str) -> Any:
    try:
        return yaml.load(text, Loader=_Loader)  # _Loader is a SafeLoader: plain data only
    except yaml.MarkedYAMLError as exc:
        raise _yaml_error(exc, source) from None
    except yaml.YAMLError as exc:
        raise ConfigError(source, "(top level)", f"invalid YAML: {exc}") from None


# --------------------------------------------------------------------------------------------
# Reading: a value with its key path; each read either returns a checked value or raises.

MISSING: Any = object()


def kind_of(value: Any) -> str:
    if value is MISSING:
        return "nothing"
    if value is None:
        return "null"
    if isinstance(value, bool):
        return f"bool {value}"
    if isinstance(value, dict):
        return "a mapping"
    if isinstance(value, list | tuple):
        return f"a list of {len(value)} item{'' if len(value) == 1 else 's'}"
    text = repr(value)
    text = text if len(text) <= 40 else text[:37] + "..."
    return f"{'string' if isinstance(value, str) else type(value).__name__} {text}"


def _is_number(value: Any) -> bool:
    return isinstance(value, numbers.Real) and not isinstance(value, bool | np.bool_)


def _interval(gt: float | None, ge: float | None, lt: float | None, le: float | None) -> str:
    lo = f"({gt:g}" if gt is not None else f"[{ge:g}" if ge is not None else None
    hi = f"{lt:g})" if lt is not None else f"{le:g}]" if le is not None else None
    if lo and hi:
        return f"a value in {lo}, {hi}"
    if lo:
        return f"{'>' if lo[0] == '(' else '>='} {lo[1:]}"
    return f"{'<' if hi[-1] == ')' else '<='} {hi[:-1]}"


class Node:
    __slots__ = ("source", "path", "value", "line")

    def __init__(self, source: str, path: str, value: Any, line: int | None) -> None:
        self.source, self.path, self.value, self.line = source, path, value, line

    def fail(self, problem: str) -> NoReturn:
        raise ConfigError(self.source, self.path or "(top level)", problem, self.line)

    @property
    def absent(self) -> bool:
        """Key not given, or given as null (null on an optional key means its default)."""
        return self.value is MISSING or self.value is None

    def _sub(self, key: Any, label: str) -> Node:
        container = self.value if isinstance(self.value, dict | list | tuple) else {}
        lines = getattr(container, "lines", {})
        if isinstance(container, dict):
            value = container.get(key, MISSING)
        elif isinstance(key, int) and 0 <= key < len(container):
            value = container[key]
        else:
            value = MISSING
        return Node(self.source, label, value, lines.get(key, self.line))

    def child(self, dotted: str) -> Node:
        node = self
        for key in dotted.split("."):
            node = node._sub(key, f"{node.path}.{key}" if node.path else str(key))
        return node

    def item(self, k: int) -> Node:
        return self._sub(k, f"{self.path}[{k}]")

    def entry(self, key: Any) -> Node:
        """The value under mapping key `key` taken as it is (an integer key such as a vehicle id,
        which `child` would look up as a string), at path `<path>.<key>`."""
        return self._sub(key, f"{self.path}.{key}" if self.path else str(key))

    def keys(self, required: str, optional: str = "") -> Node:
        """Check a mapping: all of `required` present, nothing outside required + optional."""
        req, allowed = required.split(), required.split() + optional.split()
        if not isinstance(self.value, dict):
            self.fail(
                f"expected a mapping with keys {', '.join(allowed)}, got {kind_of(self.value)}"
            )
        for key in self.value:
            if key not in allowed:
                close = difflib.get_close_matches(str(key), allowed, n=1)
                hint = f"did you mean {close[0]!r}? " if close else ""
                self._sub(key, f"{self.path}.{key}" if self.path else str(key)).fail(
                    f"unknown key; {hint}allowed keys: {', '.join(allowed)}"
                )
        for key in req:
            if key not in self.value:
                self.child(key).fail("required key is missing")
        return self

    def items(self, what: str, *, min_len: int = 0) -> list[Node]:
        """Check a list; a missing optional list is empty."""
        if self.absent and min_len == 0:
            return []
        if not isinstance(self.value, list | tuple) or len(self.value) < min_len:
            self.fail(
                f"expected a list of {what}{f' (at least {min_len})' if min_len else ''}, "
                f"got {kind_of(self.value)}"
            )
        return [self.item(k) for k in range(len(self.value))]

    def number(
        self,
        default: Any = MISSING,
        *,
        gt: float | None = None,
        ge: float | None = None,
        lt: float | None = None,
        le: float | None = None,
    ) -> Any:
        """A finite float within the bounds; `default` when absent (required if no default)."""
        if self.absent and default is not MISSING:
            return default
        if self.value is MISSING:
            self.fail("required key is missing")
        if not _is_number(self.value):
            self.fail(f"expected a number, got {kind_of(self.value)}")
        try:
            x = float(self.value)
        except OverflowError:
            self.fail(f"expected a finite number, got {kind_of(self.value)}")
        if not math.isfinite(x):
            self.fail(f"expected a finite number, got {x!r}")
        if (
            (gt is not None and not x > gt)
            or (ge is not None and not x >= ge)
            or (lt is not None and not x < lt)
            or (le is not None and not x <= le)
        ):
            self.fail(f"expected {_interval(gt, ge, lt, le)}, got {x!r}")
        return x

    def integer(
        self, default: Any = MISSING, *, ge: int | None = None, le: int | None = None
    ) -> Any:
        if self.absent and default is not MISSING:
            return default
        if self.value is MISSING:
            self.fail("required key is missing")
        if not isinstance(self.value, numbers.Integral) or isinstance(self.value, bool | np.bool_):
            self.fail(f"expected an integer, got {kind_of(self.value)}")
        x = int(self.value)
        if (ge is not None and x < ge) or (le is not None and x > le):
            self.fail(f"expected {_interval(None, ge, None, le)}, got {x}")
        return x

    def boolean(self, default: Any = MISSING) -> Any:
        if self.absent and default is not MISSING:
            return default
        if self.value is MISSING:
            self.fail("required key is missing")
        if not isinstance(self.value, bool):
            self.fail(f"expected true or false, got {kind_of(self.value)}")
        return self.value

    def string(self, default: Any = MISSING, choices: Sequence[str] = ()) -> Any:
        if self.absent and default is not MISSING:
            return default
        if self.value is MISSING:
            self.fail("required key is missing")
        if choices and self.value not in choices:
            self.fail(f"expected one of {_choices(choices)}, got {kind_of(self.value)}")
        if not isinstance(self.value, str) or not self.value.strip():
            self.fail(f"expected a non-empty string, got {kind_of(self.value)}")
        return self.value

    def vec3(self, default: Any = MISSING, *, gt: float | None = None) -> Any:
        if self.absent and default is not MISSING:
            return default
        if self.value is MISSING:
            self.fail("required key is missing")
        if not isinstance(self.value, list | tuple) or len(self.value) != 3:
            self.fail(f"expected a list of 3 numbers, got {kind_of(self.value)}")
        return tuple(self.item(k).number(gt=gt) for k in range(3))
