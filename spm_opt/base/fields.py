"""Strict reading of TOML tables: typed values, units in key names, one-line errors.

Every value is read through a :class:`Table`, which knows where it sits (file and dotted
key) so that an error can name the field, the value and what is allowed. Keys a reader
never asked for are errors too: a typo in a limit must not pass silently.
"""

from __future__ import annotations

import difflib
import math
import re
import tomllib
from collections.abc import Iterable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from spm_opt.base.errors import InputError
from spm_opt.base.input_limits import (
    MAX_TOML_BYTES,
    check_toml_data,
    check_toml_nesting,
    decode_text,
    excerpt,
    read_bytes,
)

_REQUIRED = object()


def read_toml(path: str | Path) -> dict[str, Any]:
    """Parse a TOML file of at most :data:`~spm_opt.base.input_limits.MAX_TOML_BYTES`, turning
    every way of failing into an :class:`InputError`."""
    path = Path(path)
    text = decode_text(read_bytes(path, "a TOML file", MAX_TOML_BYTES), path, "a TOML file")
    if not text.strip():
        raise InputError(f"{path}: empty file; expected a TOML file")
    return parse_toml(text, str(path))


def parse_toml(text: str, source: str) -> dict[str, Any]:
    """Parse TOML ``text`` (from ``source``, for messages) within the limits of
    :mod:`spm_opt.base.input_limits`: its size and nesting checked before ``tomllib`` sees it,
    its arrays, keys and strings after; every way of failing is an :class:`InputError`."""
    if len(text) > MAX_TOML_BYTES:
        raise InputError(
            f"{source}: {len(text):,} characters; expected at most {MAX_TOML_BYTES:,} bytes"
        )
    check_toml_nesting(text, source)
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        raise InputError(f"{source}: not valid TOML: {error}") from None
    except ValueError as error:  # an integer of more digits than Python converts
        raise InputError(f"{source}: not valid TOML: {str(error).split(':')[0]}") from None
    check_toml_data(data, source)
    return data


def apply_overrides(data: dict[str, Any], overrides: Mapping[str, Any], source: str) -> None:
    """Set dotted keys (``"limits.max_tool_speed_mm_s"``) in parsed TOML ``data``, making
    missing tables on the way; the readers then validate the values as if the file held
    them. A key whose parent is not a table is an :class:`InputError`."""
    for dotted, value in overrides.items():
        *tables, key = dotted.split(".")
        table = data
        for depth, name in enumerate(tables):
            table = table.setdefault(name, {})
            if not isinstance(table, dict):
                parent = ".".join(tables[: depth + 1])
                raise InputError(f"{source}: override {dotted}: {parent} is not a table")
        if not key:
            raise InputError(f"{source}: override {dotted!r}: expected a dotted key")
        table[key] = value


def _describe(value: Any) -> str:
    """A short excerpt of ``value`` for a message (:func:`~spm_opt.base.input_limits.excerpt`)."""
    return excerpt(value)


@dataclass(frozen=True)
class KeyRecord:
    """One key a :class:`Table` was asked for, as :func:`recording` collects it: the file,
    the dotted key (``[]`` for an array of tables: ``landmarks[].position_mm``), the
    reader (number, vector, string, boolean, table, tables or raw; has: only asked whether
    it is there, so optional), and what it allows."""

    source: str
    key: str
    kind: str
    required: bool
    default: Any = None
    minimum: float | None = None
    maximum: float | None = None
    exclusive_minimum: bool = False
    length: int | None = None
    choices: tuple[str, ...] = ()


_RECORDINGS: list[list[KeyRecord]] = []


@contextmanager
def recording() -> Iterator[list[KeyRecord]]:
    """Collect a :class:`KeyRecord` for every key any :class:`Table` is asked for meanwhile,
    present in its file or not (the documentation's file reference is made from them)."""
    records: list[KeyRecord] = []
    _RECORDINGS.append(records)
    try:
        yield records
    finally:
        _RECORDINGS.remove(records)


class Table:
    """One TOML table being read; remembers which keys were taken.

    Parameters
    ----------
    data : dict
        The parsed table.
    source : str
        The file it came from, for messages.
    prefix : str
        The dotted path of this table inside the file, e.g. ``"limits."``.
    """

    def __init__(self, data: dict[str, Any], source: str, prefix: str = "") -> None:
        self._data = data
        self._source = source
        self._prefix = prefix
        self._taken: set[str] = set()

    def name(self, key: str) -> str:
        """The file and dotted name of ``key``, for messages."""
        return f"{self._source}: {self._prefix}{key}"

    def error(self, key: str, value: Any, allowed: str) -> InputError:
        """An error naming ``key``, its ``value`` and what is ``allowed``."""
        return InputError(f"{self.name(key)} = {_describe(value)}: {allowed}")

    def has(self, key: str) -> bool:
        """Whether the table holds ``key``."""
        self._record(key, "has", None)
        return key in self._data

    def keys(self) -> list[str]:
        """The keys present in the table."""
        return list(self._data)

    def _record(self, key: str, kind: str, default: Any, **allowed: Any) -> None:
        """Tell every active :func:`recording` that ``key`` was asked for."""
        if not _RECORDINGS:
            return
        required = default is _REQUIRED
        dotted = re.sub(r"\[\d+\]", "[]", self._prefix + key)
        record = KeyRecord(
            self._source, dotted, kind, required, None if required else default, **allowed
        )
        for records in _RECORDINGS:
            records.append(record)

    def _take(self, key: str, default: Any) -> Any:
        self._taken.add(key)
        if key in self._data:
            return self._data[key]
        if default is _REQUIRED:
            close = closest(key, [k for k in self._data if k not in self._taken])
            if close is not None:
                raise InputError(
                    f"{self.name(close)}: unknown key; did you mean '{key}'? "
                    "(keys carry their unit, e.g. _mm, _s, _deg)"
                )
            raise InputError(f"{self.name(key)}: missing (required)")
        return default

    def number(
        self,
        key: str,
        *,
        default: Any = _REQUIRED,
        minimum: float | None = None,
        maximum: float | None = None,
        exclusive_minimum: bool = False,
    ) -> float:
        """A finite real number within the given bounds."""
        self._record(
            key,
            "number",
            default,
            minimum=minimum,
            maximum=maximum,
            exclusive_minimum=exclusive_minimum,
        )
        value = self._take(key, default)
        if value is default and default is not _REQUIRED:
            return value
        return self._check_number(key, value, minimum, maximum, exclusive_minimum)

    def _check_number(
        self,
        key: str,
        value: Any,
        minimum: float | None,
        maximum: float | None,
        exclusive_minimum: bool,
        shown: Any = None,
    ) -> float:
        shown = value if shown is None else shown
        bounds = _bounds_text(minimum, maximum, exclusive_minimum)
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise self.error(key, shown, f"expected a number{bounds}")
        if not math.isfinite(value):
            raise self.error(key, shown, f"expected a finite number{bounds}")
        too_low = minimum is not None and (
            value <= minimum if exclusive_minimum else value < minimum
        )
        if too_low or (maximum is not None and value > maximum):
            raise self.error(key, shown, f"expected a number{bounds}")
        return float(value)

    def vector(
        self,
        key: str,
        *,
        length: int | None = None,
        default: Any = _REQUIRED,
        minimum: float | None = None,
        maximum: float | None = None,
        exclusive_minimum: bool = False,
    ) -> np.ndarray:
        """A list of finite numbers, of a given length if asked."""
        self._record(
            key,
            "vector",
            default,
            minimum=minimum,
            maximum=maximum,
            exclusive_minimum=exclusive_minimum,
            length=length,
        )
        value = self._take(key, default)
        if value is default and default is not _REQUIRED:
            return value
        want = f"a list of {length} numbers" if length else "a non-empty list of numbers"
        if not isinstance(value, list) or not value or (length and len(value) != length):
            raise self.error(key, value, f"expected {want}")
        for item in value:
            self._check_number(key, item, minimum, maximum, exclusive_minimum, shown=value)
        return np.array(value, dtype=float)

    def string(self, key: str, *, default: Any = _REQUIRED, choices: tuple[str, ...] = ()) -> str:
        """A string, one of ``choices`` if given."""
        self._record(key, "string", default, choices=choices)
        value = self._take(key, default)
        if value is default and default is not _REQUIRED:
            return value
        if not isinstance(value, str) or not value.strip():
            raise self.error(key, value, "expected a non-empty string")
        if choices and value not in choices:
            raise self.error(key, value, f"expected one of {', '.join(choices)}")
        return value

    def boolean(self, key: str, *, default: Any = _REQUIRED) -> bool:
        self._record(key, "boolean", default)
        value = self._take(key, default)
        if not isinstance(value, bool):
            raise self.error(key, value, "expected true or false")
        return value

    def table(self, key: str, *, required: bool = True) -> Table:
        """A sub-table; an empty one when absent and not required."""
        self._record(key, "table", _REQUIRED if required else {})
        value = self._take(key, _REQUIRED if required else {})
        if not isinstance(value, dict):
            raise self.error(key, value, "expected a table ([" + key + "])")
        return Table(value, self._source, f"{self._prefix}{key}.")

    def tables(self, key: str) -> Iterator[Table]:
        """An array of tables ([[key]])."""
        self._record(key, "tables", _REQUIRED)
        value = self._take(key, _REQUIRED)
        if not isinstance(value, list) or not value or not all(isinstance(v, dict) for v in value):
            raise self.error(key, value, f"expected one or more [[{key}]] tables")
        for index, item in enumerate(value):
            yield Table(item, self._source, f"{self._prefix}{key}[{index}].")

    def raw(self, key: str, *, default: Any = _REQUIRED) -> Any:
        """A value taken as it is (for parts validated elsewhere)."""
        self._record(key, "raw", default)
        return self._take(key, default)

    def finish(self) -> None:
        """Raise on the first key nobody asked for, suggesting the closest known key."""
        for key in self._data:
            if key not in self._taken:
                close = closest(key, sorted(self._taken))
                hint = f"; did you mean '{close}'?" if close is not None else ""
                allowed = ", ".join(sorted(self._taken)) or "none"
                raise InputError(
                    f"{self.name(key)}: unknown key{hint} (allowed here: {allowed}; "
                    "keys carry their unit, e.g. _mm, _s, _deg)"
                )


def closest(word: str, known: Iterable[str]) -> str | None:
    """The one of ``known`` closest to ``word``, a likely typo of it, or None if none is
    close (the "did you mean" of every unknown key or name)."""
    close = difflib.get_close_matches(word, list(known), n=1, cutoff=0.6)
    return close[0] if close else None


def _bounds_text(minimum: float | None, maximum: float | None, exclusive_minimum: bool) -> str:
    if minimum is not None and maximum is not None:
        low = "<" if exclusive_minimum else "<="
        return f" with {minimum:g} {low} value <= {maximum:g}"
    if minimum is not None:
        return f" {'>' if exclusive_minimum else '>='} {minimum:g}"
    if maximum is not None:
        return f" <= {maximum:g}"
    return ""
