"""The faults an emulator injects, their text form ``kind:field=value,...``, and their state
while it serves.

Faults are timed from the first goal-position write (a write or sync write covering
address 596) made while torque is on, so that a run is deterministic relative to its own
start.
"""

from __future__ import annotations

import math
import termios
from collections.abc import Iterable
from dataclasses import dataclass, fields

from spm_opt.base.errors import InputError
from spm_opt.base.input_limits import excerpt
from spm_opt.execution.protocol import (
    MAX_ID,
)


def _check_time(kind: str, name: str, value: float) -> None:
    if not (math.isfinite(value) and value >= 0.0):
        raise InputError(f"fault {kind}: {name} must be a time >= 0 s, got {excerpt(value)}")


def _check_count(kind: str, count: int | None) -> None:
    if count is not None and (isinstance(count, bool) or not isinstance(count, int) or count < 1):
        raise InputError(
            f"fault {kind}: count must be an integer >= 1 (or omitted), got {excerpt(count)}"
        )


def _check_id(kind: str, device_id: int) -> None:
    if (
        isinstance(device_id, bool)
        or not isinstance(device_id, int)
        or not 0 <= device_id <= MAX_ID
    ):
        raise InputError(
            f"fault {kind}: id must be an integer 0-{MAX_ID}, got {excerpt(device_id)}"
        )


def _spec(kind: str, **values: float | int | None) -> str:
    text = ",".join(f"{k}={excerpt(v)}" for k, v in values.items() if v is not None)
    return f"{kind}:{text}"


@dataclass(frozen=True)
class DropReplies:
    """Status packets are not sent, from ``at`` s on, ``count`` of them (None: all)."""

    at: float = 0.0
    count: int | None = None

    def __post_init__(self) -> None:
        _check_time("drop", "at", self.at)
        _check_count("drop", self.count)

    def spec(self) -> str:
        """The text form read by :func:`parse_fault`."""
        return _spec("drop", at=self.at, count=self.count)


@dataclass(frozen=True)
class CorruptReplies:
    """Status packets go out with a wrong CRC, from ``at`` s on, ``count`` of them."""

    at: float = 0.0
    count: int | None = None

    def __post_init__(self) -> None:
        _check_time("crc", "at", self.at)
        _check_count("crc", self.count)

    def spec(self) -> str:
        """The text form read by :func:`parse_fault`."""
        return _spec("crc", at=self.at, count=self.count)


@dataclass(frozen=True)
class DelayReplies:
    """Status packets go out ``seconds`` late, from ``at`` s on, ``count`` of them."""

    seconds: float
    at: float = 0.0
    count: int | None = None

    def __post_init__(self) -> None:
        _check_time("delay", "at", self.at)
        _check_count("delay", self.count)
        if not (math.isfinite(self.seconds) and self.seconds > 0.0):
            raise InputError(f"fault delay: seconds must be > 0, got {excerpt(self.seconds)}")

    def spec(self) -> str:
        """The text form read by :func:`parse_fault`."""
        return _spec("delay", at=self.at, seconds=self.seconds, count=self.count)


@dataclass(frozen=True)
class Overload:
    """At ``at`` s the actuator ``id`` reports an overload (Hardware Error Status bit 5),
    sets the alert bit in its status packets and turns its torque off (until a reboot)."""

    id: int
    at: float = 0.0

    def __post_init__(self) -> None:
        _check_id("overload", self.id)
        _check_time("overload", "at", self.at)

    def spec(self) -> str:
        """The text form read by :func:`parse_fault`."""
        return _spec("overload", id=self.id, at=self.at)


@dataclass(frozen=True)
class StuckEncoder:
    """From ``at`` s on, the actuator ``id`` reports a frozen Present Position."""

    id: int
    at: float = 0.0

    def __post_init__(self) -> None:
        _check_id("stuck", self.id)
        _check_time("stuck", "at", self.at)

    def spec(self) -> str:
        """The text form read by :func:`parse_fault`."""
        return _spec("stuck", id=self.id, at=self.at)


@dataclass(frozen=True)
class RefusedWrites:
    """From ``at`` s, for ``seconds``, the line takes no byte from the host: every packet it
    sends (a sync write of goals, the instruction of a read) fails at its port.

    The pseudo-terminal's output is suspended (``tcflow(TCOOFF)``) as a stalled adapter's
    would be; a host write waits for room and fails when its write timeout expires.
    """

    seconds: float
    at: float = 0.0

    def __post_init__(self) -> None:
        _check_time("write", "at", self.at)
        if not (math.isfinite(self.seconds) and self.seconds > 0.0):
            raise InputError(f"fault write: seconds must be > 0, got {excerpt(self.seconds)}")

    def spec(self) -> str:
        """The text form read by :func:`parse_fault`."""
        return _spec("write", at=self.at, seconds=self.seconds)


Fault = DropReplies | CorruptReplies | DelayReplies | RefusedWrites | Overload | StuckEncoder

_KINDS: dict[str, type] = {
    "drop": DropReplies,
    "crc": CorruptReplies,
    "delay": DelayReplies,
    "write": RefusedWrites,
    "overload": Overload,
    "stuck": StuckEncoder,
}
_REQUIRED = {"delay": ("seconds",), "write": ("seconds",), "overload": ("id",), "stuck": ("id",)}


@dataclass(frozen=True)
class Faults:
    """Faults to inject; times in s from the first goal-position write with torque on.

    When several apply to one status packet, a drop wins over a bad CRC, which wins over
    a delay; only the fault applied uses up its count. A sync read of two ids makes two
    status packets.
    """

    drop: DropReplies | None = None
    crc: CorruptReplies | None = None
    delay: DelayReplies | None = None
    write: RefusedWrites | None = None
    overload: tuple[Overload, ...] = ()
    stuck: tuple[StuckEncoder, ...] = ()

    def specs(self) -> list[str]:
        """The faults in the text form read by :func:`parse_faults`."""
        single = [f for f in (self.drop, self.crc, self.delay, self.write) if f is not None]
        return [fault.spec() for fault in (*single, *self.overload, *self.stuck)]

    def ids(self) -> set[int]:
        """Actuator ids that the faults name."""
        return {fault.id for fault in (*self.overload, *self.stuck)}


def _number(kind: str, name: str, text: str) -> float | int:
    try:
        return int(text) if name in ("id", "count") else float(text)
    except ValueError:
        wanted = "an integer" if name in ("id", "count") else "a number of seconds"
        raise InputError(f"fault {kind}: {name} must be {wanted}, got {text!r}") from None


def parse_fault(text: str) -> Fault:
    """One fault from its text form, ``kind:field=value,...``.

    Kinds and fields (times in s from the first goal-position write with torque on;
    ``count`` omitted means every later reply):
    ``drop:at=T[,count=N]``, ``crc:at=T[,count=N]``, ``delay:at=T,seconds=S[,count=N]``,
    ``write:at=T,seconds=S``, ``overload:id=I,at=T``, ``stuck:id=I,at=T``. ``at`` defaults
    to 0.

    Raises
    ------
    InputError
        Unknown kind or field, a missing field, or a value out of range.
    """
    kind, colon, rest = text.strip().partition(":")
    kind = kind.strip().lower()
    if kind not in _KINDS:
        allowed = ", ".join(_KINDS)
        raise InputError(f"fault: unknown kind {kind!r} in {text!r} (allowed: {allowed})")
    cls = _KINDS[kind]
    allowed_fields = [f.name for f in fields(cls)]
    values: dict[str, float | int] = {}
    for part in filter(None, (p.strip() for p in rest.split(","))):
        name, equals, value = (s.strip() for s in part.partition("="))
        if name not in allowed_fields or not equals:
            raise InputError(
                f"fault {kind}: expected field=value with field one of "
                f"{', '.join(allowed_fields)}, got {part!r}"
            )
        if name in values:
            raise InputError(f"fault {kind}: field {name!r} given twice")
        values[name] = _number(kind, name, value)
    for name in _REQUIRED.get(kind, ()):
        if name not in values:
            raise InputError(f"fault {kind}: field {name!r} is required (in {text!r})")
    return cls(**values)


def parse_faults(texts: Iterable[str]) -> Faults:
    """Faults from several text forms (see :func:`parse_fault`).

    Raises
    ------
    InputError
        A text is invalid, or drop, crc, delay or write is given more than once.
    """
    single: dict[str, Fault] = {}
    overload: list[Overload] = []
    stuck: list[StuckEncoder] = []
    for text in texts:
        fault = parse_fault(text)
        if isinstance(fault, Overload):
            overload.append(fault)
        elif isinstance(fault, StuckEncoder):
            stuck.append(fault)
        else:
            kind = text.strip().partition(":")[0].strip().lower()
            if kind in single:
                raise InputError(f"fault {kind}: given more than once (allowed: once)")
            single[kind] = fault
    return Faults(
        drop=single.get("drop"),
        crc=single.get("crc"),
        delay=single.get("delay"),
        write=single.get("write"),
        overload=tuple(overload),
        stuck=tuple(stuck),
    )


class ReplyWindow:
    """A reply fault's state: active from ``at``, for ``count`` replies (None: all)."""

    def __init__(self, at: float, count: int | None) -> None:
        self.at = at
        self.remaining = count

    def take(self, t: float) -> bool:
        if t < self.at or self.remaining == 0:
            return False
        if self.remaining is not None:
            self.remaining -= 1
        return True


def reply_window(fault: DropReplies | CorruptReplies | DelayReplies | None) -> ReplyWindow | None:
    return None if fault is None else ReplyWindow(fault.at, fault.count)


class LineStall:
    """The write fault's state: the line's output suspended in [at, at + seconds)."""

    def __init__(self, fault: RefusedWrites, line: int) -> None:
        self.fault, self.line = fault, line
        self.suspended = False
        self.over = False

    def update(self, t: float) -> None:
        """Suspend or resume the line for the time ``t`` (s) since the fault origin."""
        if self.over or t < self.fault.at:
            return
        inside = t < self.fault.at + self.fault.seconds
        if inside != self.suspended:
            termios.tcflow(self.line, termios.TCOOFF if inside else termios.TCOON)
            self.suspended = inside
        self.over = not inside
