"""Declarative validation of TOML tables: each key's type, unit, range and default in one place.

A section is described by a ``dict[str, Field]``; :func:`validate_table` checks a parsed table
against it and returns plain Python values, raising :class:`~app.errors.InputError` with a one-line
message naming the file, line (where it can be found), section, key, value and the rule.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from app.errors import InputError

REQUIRED = object()


@dataclass(frozen=True)
class Field:
    """One key of a section.

    kind: ``"float"``, ``"int"``, ``"bool"``, ``"str"``, ``"path"``, ``"vecN"`` (N floats),
    ``"ivecN"`` (N ints), ``"table"`` (validated by the caller) or ``"tables"`` (a list of tables).
    """

    kind: str
    default: Any = REQUIRED
    lo: float | None = None
    hi: float | None = None
    lo_open: bool = False  # lo itself not allowed
    choices: tuple[str, ...] | None = None
    unit: str = ""
    doc: str = ""

    def describe_range(self) -> str:
        if self.choices:
            return "one of " + ", ".join(self.choices)
        left = "(" if self.lo_open else "["
        lo = "-inf" if self.lo is None else f"{self.lo:g}"
        hi = "inf" if self.hi is None else f"{self.hi:g}"
        unit = f" {self.unit}" if self.unit else ""
        return f"in {left}{lo}, {hi}]{unit}"


class SourceText:
    """The scene file's text, to point error messages at a line."""

    def __init__(self, path: Path, text: str):
        self.path = path
        self.lines = text.splitlines()

    def line_of(self, section: str, key: str | None = None) -> int | None:
        """1-based line of ``key`` in the first ``[section]``/``[[section]]``, else the header's."""
        head = re.compile(r"^\s*\[\[?\s*" + re.escape(section) + r"\s*\]\]?\s*(#.*)?$")
        start = None
        for i, line in enumerate(self.lines):
            if head.match(line):
                start = i
                break
        if start is None:
            return None
        if key is None:
            return start + 1
        keyre = re.compile(r"^\s*" + re.escape(key) + r"\s*=")
        for i in range(start + 1, len(self.lines)):
            if re.match(r"^\s*\[", self.lines[i]):
                break
            if keyre.match(self.lines[i]):
                return i + 1
        return start + 1

    def where(self, section: str, key: str | None = None) -> str:
        line = self.line_of(section, key)
        loc = f"{self.path}:{line}" if line else f"{self.path}"
        return f"{loc}: [{section}]" + (f" {key}" if key else "")


def _number(value, kind: str) -> float | int | None:
    if isinstance(value, bool):
        return None
    if kind == "int":
        return value if isinstance(value, int) else None
    if isinstance(value, int | float):
        return float(value)
    return None


def _check_range(field: Field, x: float, where: str, key: str) -> None:
    if not math.isfinite(x):
        raise InputError(f"{where}: {key} = {x} is not finite")
    bad = ((field.lo is not None and (x < field.lo or (field.lo_open and x == field.lo)))
           or (field.hi is not None and x > field.hi))
    if bad:
        raise InputError(f"{where}: {key} = {x:g} is out of range; "
                         f"allowed {field.describe_range()}")


def coerce(field: Field, value, where: str, key: str, base_dir: Path | None = None):
    """``value`` checked and converted to the field's kind (tuples for vectors)."""
    kind = field.kind
    if kind in ("float", "int"):
        x = _number(value, kind)
        if x is None:
            what = "an integer" if kind == "int" else "a number"
            raise InputError(f"{where}: {key} = {value!r} should be {what}")
        _check_range(field, x, where, key)
        return x
    if kind == "bool":
        if not isinstance(value, bool):
            raise InputError(f"{where}: {key} = {value!r} should be true or false")
        return value
    if kind in ("str", "path"):
        if not isinstance(value, str):
            raise InputError(f"{where}: {key} = {value!r} should be a string")
        if field.choices and value not in field.choices:
            raise InputError(f"{where}: {key} = {value!r} is not valid; "
                             f"allowed {field.describe_range()}")
        if kind == "path":
            path = Path(value)
            if not path.is_absolute() and base_dir is not None:
                path = base_dir / path
            if not path.is_file():
                raise InputError(f"{where}: {key} = {value!r}: file {path} does not exist")
            return path
        return value
    m = re.fullmatch(r"(i?)vec(\d)", kind)
    if m:
        n = int(m.group(2))
        elem = "int" if m.group(1) else "float"
        if not isinstance(value, list) or len(value) != n:
            raise InputError(f"{where}: {key} = {value!r} should be a list of {n} "
                             f"{'integers' if elem == 'int' else 'numbers'}")
        out = []
        for v in value:
            x = _number(v, elem)
            if x is None:
                raise InputError(f"{where}: {key} = {value!r} should hold only "
                                 f"{'integers' if elem == 'int' else 'numbers'}")
            _check_range(field, x, where, key)
            out.append(x)
        return tuple(out)
    if kind == "table":
        if not isinstance(value, dict):
            raise InputError(f"{where}: {key} should be a table")
        return value
    if kind == "tables":
        if not isinstance(value, list) or not all(isinstance(v, dict) for v in value):
            raise InputError(f"{where}: {key} should be a list of tables")
        return value
    raise AssertionError(f"unknown field kind {kind}")


def validate_table(table: dict, schema: dict[str, Field], section: str, src: SourceText,
                   base_dir: Path | None = None) -> dict:
    """Checked values for every key of ``schema`` (defaults filled in); unknown keys rejected."""
    if not isinstance(table, dict):
        raise InputError(f"{src.where(section)} should be a table")
    unknown = sorted(set(table) - set(schema))
    if unknown:
        raise InputError(f"{src.where(section, unknown[0])}: unknown key {unknown[0]!r}; valid "
                         f"keys: {', '.join(sorted(schema))}")
    out = {}
    for key, field in schema.items():
        if key not in table:
            if field.default is REQUIRED:
                raise InputError(f"{src.where(section)}: missing required key {key!r} "
                                 f"({field.doc or field.kind})")
            out[key] = field.default
            continue
        out[key] = coerce(field, table[key], src.where(section, key), key, base_dir)
    return out
