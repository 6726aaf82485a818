"""How large an input may be, and the checks that keep a careless one from exhausting the
machine before it gets its one-line :class:`~spm_opt.base.errors.InputError`.

Every limit lies far above any real input (each says by how much), so it only stops a
mistake, and each is checked before the work it bounds: a file's size before it is read, a
TOML text's nesting before ``tomllib`` parses it (``tomllib`` recurses once per level of
brackets, and is quadratic in a dotted key's depth: 20,000 levels cost 2.4 GB), an
execution log's rows before pandas parses them. A message quotes at most a short
:func:`excerpt` of a value.
"""

from __future__ import annotations

import itertools
import json
import os
import re
import stat
from pathlib import Path
from typing import TYPE_CHECKING, Any

from spm_opt.base.errors import InputError

if TYPE_CHECKING:
    pass

MAX_TOML_BYTES = 1 << 20
"""Largest problem, robot or sweep file, bytes (1 MiB). The shipped ones hold 0.4 to 4.2
kB; a problem of :data:`MAX_LANDMARKS` landmarks takes about 12 kB."""
MAX_NESTING_DEPTH = 32
"""Deepest nesting in a TOML file: brackets (arrays, inline tables) inside each other, the
parts of one dotted key, and the tables and arrays of the parsed data. The shipped files
nest 3 deep."""
MAX_ARRAY_LENGTH = 10_000
"""Longest array in a TOML file (values, or ``[[tables]]``). The longest real ones are a
problem's ``segment_durations_s`` (one per segment) and a sweep's grid axes (tens of
values)."""
MAX_KEY_CHARS = 100
"""Longest key in a TOML file, characters (the longest shipped: 31)."""
MAX_STRING_CHARS = 10_000
"""Longest string in a TOML file, characters (a description: a sentence or two)."""
MAX_LANDMARKS = 200
"""Most landmarks a problem may have. A craniotomy has 3 to 12 (the paper's 4; a sweep's
flaps at most 12). Measured at 200 landmarks: the cubic planner takes 0.3 s, toppra 9 s,
ruckig 15 s, ocp-min-time 250 s and 1.2 GB; at 1,000 the cubic planner's dense system alone
takes 1.2 GB, and at 10⁶ it would take 466 TiB."""
MAX_TRAJECTORY_ROWS = 1_000_000
"""Most samples in a trajectory CSV: 2.8 hours at the default 100 Hz, 17 minutes at 1 kHz
(the paper's plan: 40 s, 4,000 samples). Reading 1,000,000 takes 7 s and 0.7 GB."""
MAX_TRAJECTORY_BYTES = 256 << 20
"""Largest trajectory CSV, bytes (256 MiB): :data:`MAX_TRAJECTORY_ROWS` rows of seven
numbers to full precision take 130 to 175 MB."""
MAX_SIDECAR_BYTES = 64 << 20
"""Largest JSON sidecar of a plan or header of a log, bytes (64 MiB; a plan's holds its
breakpoints and statistics: tens of kB)."""
MAX_LOG_ROWS = 2_000_000
"""Most rows of execution logs identified together, or of one log judged: 33 minutes at
1 kHz, 5.5 hours at 100 Hz (an identification log: minutes; the shipped excitation, 120 s
at 500 Hz, 60,000 rows). Identification holds every row in memory, its regressor's
included: about 2.5 kB a row, so 2,000,000 rows take about 5 GB (measured: 600,000 rows,
1.8 GB)."""
MAX_LOG_BYTES = 1 << 30
"""Largest execution log, bytes (1 GiB; a row takes about 220 bytes: :data:`MAX_LOG_ROWS`
rows about 440 MB)."""
MAX_TRACE_BYTES = 1 << 30
"""Largest trace of the plant's state (``.npz``), bytes (1 GiB; 72 bytes a sample: the
simulated robot's 16 s run at 100 Hz takes 118 kB, an hour at 1 kHz 260 MB)."""
MAX_HEADER_CHARS = 4096
"""Longest first line of a CSV read to tell its kind (a log's header: 330 characters)."""
EXCERPT_CHARS = 60
"""Longest excerpt of a value in a message."""
_EXCERPT_ITEMS = 4  # items shown of a long list, tuple or dict


def excerpt(value: Any, width: int = EXCERPT_CHARS) -> str:
    """A short ``repr`` of ``value`` for a message, at most ``width`` characters; a
    numpy scalar or array as the Python number or list it holds (``2.0``, not
    ``np.float64(2.0)``)."""
    text = _short_repr(value, width)
    return text if len(text) <= width else text[: width - 3] + "..."


def _short_repr(value: Any, width: int) -> str:
    """``repr(value)``, but of a long string only its start, and of a long list, tuple or
    dict its first items and its length: never the ``repr`` of what will not be shown."""
    import numpy as np

    if isinstance(value, np.generic | np.ndarray):
        value = value.tolist()
    if isinstance(value, str):
        return repr(value[: width + 1])
    if isinstance(value, dict):
        items = [
            f"{_short_repr(k, width)}: {_short_repr(v, width)}"
            for k, v in itertools.islice(value.items(), _EXCERPT_ITEMS)
        ]
        return "{" + ", ".join(items + _more(value)) + "}"
    if isinstance(value, list | tuple):
        items = [_short_repr(item, width) for item in value[:_EXCERPT_ITEMS]]
        if isinstance(value, list):
            return "[" + ", ".join(items + _more(value)) + "]"
        return "(" + ", ".join(items + _more(value)) + ("," if len(value) == 1 else "") + ")"
    return repr(value)


def _more(value: list | tuple | dict) -> list[str]:
    """What an excerpt says of a container's items beyond the first ones."""
    return [f"... ({len(value):,} items)"] if len(value) > _EXCERPT_ITEMS else []


def read_bytes(path: Path, kind: str, limit: int) -> bytes:
    """The bytes of the regular file at ``path``, at most ``limit`` of them, or an
    :class:`InputError` (``kind`` says what the file should be: "a TOML file")."""
    check_file(path, kind, limit)
    try:
        with open(path, "rb") as file:
            data = file.read(limit + 1)
    except OSError as error:
        raise InputError(f"{path}: cannot be read ({error.strerror or error})") from None
    if len(data) > limit:  # it grew since
        raise _too_large(path, kind, len(data), limit)
    return data


def decode_text(data: bytes, path: Path, kind: str) -> str:
    """``data``, the bytes of the file at ``path``, as UTF-8 text, or an
    :class:`InputError`."""
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as error:
        raise InputError(
            f"{path}: not UTF-8 text (byte {error.start:,} is {data[error.start]:#04x}); "
            f"expected {kind}"
        ) from None


def check_file(path: Path, kind: str, limit: int) -> int:
    """The size, bytes, of the regular file at ``path`` if at most ``limit``, else an
    :class:`InputError`; so is a missing path, a directory, and a device or a pipe (whose
    reading could block or never end)."""
    try:
        status = os.stat(path)
    except FileNotFoundError:
        raise InputError(f"{path}: no such file") from None
    except OSError as error:
        raise InputError(f"{path}: cannot be read ({error.strerror or error})") from None
    if stat.S_ISDIR(status.st_mode):
        raise InputError(f"{path}: is a directory, expected {kind}")
    if not stat.S_ISREG(status.st_mode):
        raise InputError(f"{path}: not a regular file (a device or a pipe?), expected {kind}")
    if status.st_size > limit:
        raise _too_large(path, kind, status.st_size, limit)
    return status.st_size


def _too_large(path: Path, kind: str, size: int, limit: int) -> InputError:
    return InputError(f"{path}: {size:,} bytes; expected {kind} of at most {limit:,} bytes")


# --- TOML -------------------------------------------------------------------------------

_KEY_PART = re.compile(r"""[A-Za-z0-9_-]+|"(?:[^"\\\n]|\\.)*"|'[^'\n]*'""")
_TOML_TOKEN = re.compile(
    "|".join(
        [
            r"(?P<comment>#[^\n]*)",
            # multi-line strings: up to two quotes in a row inside, up to five at the end
            r'(?P<multiline>"""(?:[^"\\]|\\[\s\S]|"{1,2}(?!"))*(?:"{3,5}|\Z)'
            r"|'''(?:[^']|'{1,2}(?!'))*(?:'{3,5}|\Z))",
            rf"(?P<key>(?:{_KEY_PART.pattern})(?:[ \t]*\.[ \t]*(?:{_KEY_PART.pattern}))*)",
            r"(?P<open>[\[{])",
            r"(?P<close>[\]}])",
            # an unterminated string: tomllib stops there, so its line may be skipped
            r"""(?P<other>["'][^\n]*|[^\[\]{}"'#A-Za-z0-9_-]+)""",
        ]
    )
)
"""TOML's tokens as far as nesting goes: comments and strings (whose brackets and dots do
not count), keys dotted or not (numbers and dates too: a float has 2 parts), brackets."""


def check_toml_nesting(text: str, source: str) -> None:
    """Refuse TOML ``text`` whose brackets nest, or whose dotted keys have parts, beyond
    :data:`MAX_NESTING_DEPTH`, before ``tomllib`` parses it: one pass of a regular
    expression, linear in the text's length."""
    depth = 0
    for token in _TOML_TOKEN.finditer(text):
        kind = token.lastgroup
        if kind == "open":
            depth += 1
            if depth > MAX_NESTING_DEPTH:
                found = f"arrays or inline tables nested more than {MAX_NESTING_DEPTH} deep"
                raise _too_deep(text, token.start(), source, found)
        elif kind == "close":
            depth = max(depth - 1, 0)
        elif kind == "key" and "." in token.group():
            parts = len(_KEY_PART.findall(token.group()))
            if parts > MAX_NESTING_DEPTH:
                raise _too_deep(text, token.start(), source, f"a dotted key of {parts:,} parts")


def _too_deep(text: str, position: int, source: str, found: str) -> InputError:
    """The error of nesting too deep at ``position`` of ``text``: its line and its start."""
    line = text.count("\n", 0, position) + 1
    start = text.rfind("\n", 0, position) + 1
    shown = excerpt(text[start : start + EXCERPT_CHARS + 1].split("\n")[0])
    return InputError(
        f"{source}: line {line}: {found} ({shown}); expected at most {MAX_NESTING_DEPTH} levels"
    )


def check_toml_data(data: dict[str, Any], source: str) -> None:
    """Refuse parsed TOML ``data`` nested deeper than :data:`MAX_NESTING_DEPTH`, with an
    array longer than :data:`MAX_ARRAY_LENGTH`, a key longer than :data:`MAX_KEY_CHARS` or
    a string longer than :data:`MAX_STRING_CHARS`, naming the first such key."""
    stack: list[tuple[str, Any, int]] = [("", data, 0)]
    while stack:
        name, value, depth = stack.pop()
        if depth > MAX_NESTING_DEPTH:
            raise _data_error(source, name, f"nested {depth} deep", MAX_NESTING_DEPTH, "levels")
        if isinstance(value, dict):
            for key in value:
                if len(key) > MAX_KEY_CHARS:
                    found = f"a key of {len(key):,} characters, {excerpt(key)}"
                    raise _data_error(
                        source, name or "the top level", found, MAX_KEY_CHARS, "characters"
                    )
            stack += [(_join(name, key), item, depth + 1) for key, item in value.items()]
        elif isinstance(value, list):
            if len(value) > MAX_ARRAY_LENGTH:
                found = f"= {excerpt(value)}: {len(value):,} values"
                raise _data_error(source, name, found, MAX_ARRAY_LENGTH, "values")
            stack += [(f"{name}[{index}]", item, depth + 1) for index, item in enumerate(value)]
        elif isinstance(value, str) and len(value) > MAX_STRING_CHARS:
            found = f"= {excerpt(value)}: {len(value):,} characters"
            raise _data_error(source, name, found, MAX_STRING_CHARS, "characters")


def _data_error(source: str, name: str, found: str, limit: int, unit: str) -> InputError:
    """The error of a value of parsed TOML beyond a limit."""
    name = name if len(name) <= 2 * EXCERPT_CHARS else name[: 2 * EXCERPT_CHARS - 3] + "..."
    found = f" {found}" if found.startswith("=") else f": {found}"
    return InputError(f"{source}: {name}{found}; expected at most {limit:,} {unit}")


def _join(table: str, key: str) -> str:
    """The dotted name of ``key`` in ``table`` (quoted where it holds a dot)."""
    key = f'"{key}"' if "." in key else key
    return f"{table}.{key}" if table else key


# --- execution logs ---------------------------------------------------------------------

LOG_KIND = "an execution log (CSV) of spm-opt execute"
_CHUNK_BYTES = 1 << 20


def log_rows(path: Path) -> int:
    """The rows of the execution log at ``path`` (its lines after the header), counted
    without parsing it; an :class:`InputError` unless it is a file of at most
    :data:`MAX_LOG_BYTES` whose first line is UTF-8 text of at most
    :data:`MAX_HEADER_CHARS`."""
    if check_file(path, LOG_KIND, MAX_LOG_BYTES) == 0:
        raise InputError(f"{path}: empty file; expected {LOG_KIND}")
    with open(path, "rb") as file:
        _check_header_line(path, file.readline(MAX_HEADER_CHARS + 1))
        rows, last = 0, b"\n"
        while chunk := file.read(_CHUNK_BYTES):
            rows += chunk.count(b"\n")
            last = chunk
    return rows + (not last.endswith(b"\n"))


def _check_header_line(path: Path, line: bytes) -> None:
    """Refuse a log whose first line is not a line of UTF-8 text a header could be."""
    if len(line.rstrip(b"\r\n")) > MAX_HEADER_CHARS:
        shown = excerpt(line[:EXCERPT_CHARS].decode("utf-8", "replace"))
        raise InputError(
            f"{path}: a first line of more than {MAX_HEADER_CHARS:,} characters ({shown}); "
            f"expected {LOG_KIND}"
        )
    try:
        line.decode("utf-8")
    except UnicodeDecodeError:
        raise InputError(f"{path}: not UTF-8 text; expected {LOG_KIND}") from None


def check_log_header(header: Path) -> None:
    """Refuse a log's JSON header (when there is one) that is too large or not a JSON
    object."""
    if not header.is_file():
        return
    kind = "a log's JSON header"
    text = decode_text(read_bytes(header, kind, MAX_SIDECAR_BYTES), header, kind)
    try:
        parsed = json.loads(text)
    except (ValueError, RecursionError) as error:  # JSONDecodeError, a huge integer
        raise InputError(f"log header {header}: is not JSON ({first_line(error)})") from None
    if not isinstance(parsed, dict):
        raise InputError(f"log header {header}: {excerpt(parsed)}: expected a JSON object")


def first_line(error: BaseException) -> str:
    """An exception's message, its first line and at most 120 characters of it."""
    line = (str(error).splitlines() or [type(error).__name__])[0]
    return line if len(line) <= 2 * EXCERPT_CHARS else line[: 2 * EXCERPT_CHARS - 3] + "..."
