"""Strict reading of TOML tables: typed values, units in key names, one-line errors.

Every value is read through a :class:`Table`, which knows where it sits (file and dotted
key) so that an error can name the field, the value and what is allowed. Keys a reader
never asked for are errors too: a typo in a limit must not pass silently.
"""

from __future__ import annotations

import difflib
import math
import tomllib
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from spm_opt.errors import InputError

_REQUIRED = object()


def read_toml(path: str | Path) -> dict[str, Any]:
    """Parse a TOML file, turning every way of failing into an :class:`InputError`."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise InputError(f"{path}: no such file") from None
    except IsADirectoryError:
        raise InputError(f"{path}: is a directory, expected a TOML file") from None
    except (OSError, UnicodeDecodeError) as error:
        raise InputError(f"{path}: cannot be read ({error})") from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        raise InputError(f"{path}: not valid TOML: {error}") from None


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
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


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
        return key in self._data

    def keys(self) -> list[str]:
        """The keys present in the table."""
        return list(self._data)

    def _take(self, key: str, default: Any) -> Any:
        self._taken.add(key)
        if key in self._data:
            return self._data[key]
        if default is _REQUIRED:
            strays = [k for k in self._data if k not in self._taken]
            close = difflib.get_close_matches(key, strays, n=1, cutoff=0.6)
            if close:
                raise InputError(
                    f"{self.name(close[0])}: unknown key; did you mean '{key}'? "
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
        value = self._take(key, default)
        if value is default and default is not _REQUIRED:
            return value
        if not isinstance(value, str) or not value.strip():
            raise self.error(key, value, "expected a non-empty string")
        if choices and value not in choices:
            raise self.error(key, value, f"expected one of {', '.join(choices)}")
        return value

    def boolean(self, key: str, *, default: Any = _REQUIRED) -> bool:
        value = self._take(key, default)
        if not isinstance(value, bool):
            raise self.error(key, value, "expected true or false")
        return value

    def table(self, key: str, *, required: bool = True) -> Table:
        """A sub-table; an empty one when absent and not required."""
        value = self._take(key, _REQUIRED if required else {})
        if not isinstance(value, dict):
            raise self.error(key, value, "expected a table ([" + key + "])")
        return Table(value, self._source, f"{self._prefix}{key}.")

    def tables(self, key: str) -> Iterator[Table]:
        """An array of tables ([[key]])."""
        value = self._take(key, _REQUIRED)
        if not isinstance(value, list) or not value or not all(isinstance(v, dict) for v in value):
            raise self.error(key, value, f"expected one or more [[{key}]] tables")
        for index, item in enumerate(value):
            yield Table(item, self._source, f"{self._prefix}{key}[{index}].")

    def raw(self, key: str, *, default: Any = _REQUIRED) -> Any:
        """A value taken as it is (for parts validated elsewhere)."""
        return self._take(key, default)

    def finish(self) -> None:
        """Raise on the first key nobody asked for, suggesting the closest known key."""
        for key in self._data:
            if key not in self._taken:
                close = difflib.get_close_matches(key, sorted(self._taken), n=1, cutoff=0.6)
                hint = f"; did you mean '{close[0]}'?" if close else ""
                allowed = ", ".join(sorted(self._taken)) or "none"
                raise InputError(
                    f"{self.name(key)}: unknown key{hint} (allowed here: {allowed}; "
                    "keys carry their unit, e.g. _mm, _s, _deg)"
                )


def _bounds_text(minimum: float | None, maximum: float | None, exclusive_minimum: bool) -> str:
    if minimum is not None and maximum is not None:
        low = "<" if exclusive_minimum else "<="
        return f" with {minimum:g} {low} value <= {maximum:g}"
    if minimum is not None:
        return f" {'>' if exclusive_minimum else '>='} {minimum:g}"
    if maximum is not None:
        return f" <= {maximum:g}"
    return ""
