"""The cache of compiled libraries: shared libraries built from generated C, kept on disk
so that each is compiled once per machine, and never loaded unless whole.

The cache folder (:func:`cache_directory`) holds:

- ``NAME/``, an entry: the library, named by its SHA-256 (``<16 hex digits>.so``), and
  ``manifest.json``, its record (file name, size in bytes, SHA-256, the symbols it
  exports). :func:`build` makes both in a workspace and publishes them together by
  renaming the workspace, so a reader sees a whole entry or none.
- ``.build-*/``, a workspace: the C, the compiler's temporary files (its ``TMPDIR``) and
  its output, locked (``flock``) by the process that made it for as long as that process
  lives. The first use of the cache in a process removes every workspace no live process
  holds: what a killed build left.
- ``.lock``, held shared while a workspace is made and locked, exclusively while dead ones
  are removed.
- anything else (a marker, a library of an older version) counts as an entry too.

:func:`find` checks an entry before its library is loaded (size and SHA-256 against the
record) and after (the symbols), once per process and file; a damaged entry is removed with
one warning, for the caller to build it again. The compiler runs under a small guard, the
leader of its own process group, which kills the whole group (driver, cc1, as, ld) when
the process that started it dies (Linux: a parent-death signal); an exception in that
process (Ctrl-C) kills the group too. After each build the least recently used entries are
removed until the cache fits :func:`size_bound`.
"""

from __future__ import annotations

import contextlib
import ctypes
import errno
import fcntl
import hashlib
import json
import logging
import math
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

from spm_opt.base.errors import InputError

_LOG = logging.getLogger(__name__)

CACHE_ENV = "SPM_OPT_CACHE"
"""Environment variable naming the cache folder (default ``~/.cache/spm_opt``)."""

SIZE_ENV = "SPM_OPT_CACHE_MB"
"""Environment variable bounding the cache's size, MB (10⁶ bytes; default
:data:`DEFAULT_SIZE_MB`)."""

DEFAULT_SIZE_MB = 256
"""The size bound when :data:`SIZE_ENV` is not set, MB."""

MANIFEST = "manifest.json"
"""An entry's record of its library."""

_WORKSPACE = ".build-"
_LOCK = ".lock"

_GUARD = """
import os, signal, sys
def end(*_):
    os.killpg(0, signal.SIGKILL)
signal.signal(signal.SIGTERM, end)
if sys.platform.startswith("linux"):
    import ctypes
    ctypes.CDLL(None).prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG
if os.getppid() != int(sys.argv[1]):
    end()
child = os.posix_spawn(sys.argv[2], sys.argv[2:], os.environ)
sys.exit(os.waitstatus_to_exitcode(os.waitpid(child, 0)[1]))
"""
"""The compiler's guard, run as ``python -c _GUARD PARENT_PID COMMAND...`` in a process
group of its own: it runs COMMAND and, when its parent dies, kills its group."""

_verified: dict[Path, tuple[int, int, int]] = {}  # library -> (inode, size, mtime) checked
_compiling: set[subprocess.Popen] = set()  # the guards of the compilers running now
_stopped = threading.Event()  # stop_compilers was called: no build starts or succeeds
_cleaned: set[Path] = set()  # cache folders whose dead workspaces this process removed
_held: set[int] = set()  # descriptors locking this process's workspaces


@dataclass(frozen=True)
class Entry:
    """An item of the cache, as :func:`entries` lists it.

    Attributes
    ----------
    name : str
        Its name in the cache folder.
    size : int
        Bytes on disk (a folder's files summed).
    used : float
        Its last use (its build, or :func:`find`), s since the epoch.
    """

    name: str
    size: int
    used: float


def compiler() -> str | None:
    """The C compiler: ``$CC`` (a program name or path) when set, else ``cc`` or ``gcc`` on
    the PATH; None when there is none (or ``$CC`` names a missing program)."""
    chosen = os.environ.get("CC")
    if chosen:
        return shutil.which(chosen)
    return shutil.which("cc") or shutil.which("gcc")


def cache_directory() -> Path:
    """Where compiled libraries are kept: ``$SPM_OPT_CACHE``, else ``~/.cache/spm_opt``."""
    return Path(os.environ.get(CACHE_ENV) or Path.home() / ".cache" / "spm_opt")


def size_bound() -> int:
    """The cache's size bound, bytes: ``$SPM_OPT_CACHE_MB`` MB, else
    :data:`DEFAULT_SIZE_MB`. InputError when the variable is not a number >= 0."""
    text = os.environ.get(SIZE_ENV, "").strip()
    if not text:
        return DEFAULT_SIZE_MB * 10**6
    try:
        megabytes = float(text)
    except ValueError:
        megabytes = math.nan
    if not (math.isfinite(megabytes) and megabytes >= 0):
        raise InputError(
            f"{SIZE_ENV} = {text!r}: expected the cache's size bound in MB, a number >= 0 "
            f"(default {DEFAULT_SIZE_MB})"
        )
    return round(megabytes * 10**6)


def find(name: str, symbols: Sequence[str]) -> Path | None:
    """The library of the entry ``name``, checked; None when there is none, or when it is
    damaged or another library (then removed, with one warning)."""
    directory = cache_directory()
    _clean_once(directory)
    entry = directory / name
    if not os.path.lexists(entry):
        return None
    library, damage = _check(entry, symbols)
    if damage is None:
        with contextlib.suppress(OSError):
            os.utime(entry)  # its last use, for the size bound
        return library
    _LOG.warning("%s in the cache %s: removed, to be built again", name, damage)
    with contextlib.suppress(OSError):
        _remove(entry)
    return None


def build(
    name: str, code: str, compiler: str, flags: Sequence[Sequence[str]], symbols: Sequence[str]
) -> Path:
    """Compile the C ``code`` with the first of the sets of ``flags`` that works into the
    entry ``name``, which must export ``symbols``; its library. OSError, in one line, when
    it cannot be built (the compiler's message, or the system's: e.g. a full disk)."""
    directory = cache_directory()
    started = time.perf_counter()
    try:
        with _workspace(directory) as work:
            source = work / f"{name}.c"
            source.write_text(code)
            output = work / "library.so"
            failures = []
            for chosen in flags:
                try:
                    _compile(compiler, source, output, chosen)
                    break
                except OSError as failure:
                    failures.append(failure)
            else:
                raise failures[-1]
            library = _publish(work, name, output, symbols)
    except BuildStopped:
        raise
    except OSError as error:  # the compiler's (no errno), or the system's (a full disk)
        reason = str(error)
        if error.errno is not None:
            reason = f"{error.strerror}: {error.filename or directory}"
        raise OSError(f"{name} not built: {reason}") from None
    _LOG.info("compiled %s in %.1f s", name, time.perf_counter() - started)
    with contextlib.suppress(OSError):  # pruning is best effort: the library is built
        _evict(directory, keep=name)
    return library


def entries() -> list[Entry]:
    """The cache's entries, least recently used first (a build in progress is none)."""
    directory = cache_directory()
    _clean_once(directory)
    found = []
    for path in directory.iterdir() if directory.is_dir() else ():
        if path.name == _LOCK or path.name.startswith(_WORKSPACE):
            continue
        with contextlib.suppress(FileNotFoundError):  # removed meanwhile
            found.append(Entry(path.name, _size(path), path.lstat().st_mtime))
    return sorted(found, key=lambda entry: entry.used)


def builds() -> int:
    """How many builds live processes are running in the cache now."""
    directory = cache_directory()
    _clean_once(directory)
    return sum(_live(path) for path in directory.glob(f"{_WORKSPACE}*"))


def clear() -> list[Entry]:
    """Remove every entry and dead build (builds in progress stay, and publish theirs); the
    entries removed."""
    directory = cache_directory()
    if directory.is_dir():
        _clean(directory)
    removed = entries()
    for entry in removed:
        _remove(directory / entry.name)
    return removed


class BuildStopped(OSError):
    """A build :func:`stop_compilers` stopped (not a failure to report)."""


def stop_compilers() -> None:
    """Kill every compiler this process runs, and start none from now on (the command was
    interrupted: its process need not wait for them); their builds raise
    :class:`BuildStopped`."""
    _stopped.set()
    for process in list(_compiling):
        with contextlib.suppress(ProcessLookupError):
            os.killpg(process.pid, signal.SIGKILL)


def _check(entry: Path, symbols: Sequence[str]) -> tuple[Path | None, str | None]:
    """The entry's library, or what is wrong with the entry."""
    try:
        record = json.loads((entry / MANIFEST).read_text())
        digest, size, exported = str(record["sha256"]), int(record["size"]), record["symbols"]
        if record["library"] != f"{digest[:16]}.so" or not isinstance(exported, list):
            raise ValueError("not a record of this cache")
    except (FileNotFoundError, NotADirectoryError):
        return None, "has no record"
    except (OSError, ValueError, TypeError, KeyError):
        return None, "has an unreadable record"
    missing = [symbol for symbol in symbols if symbol not in exported]
    if missing:
        return None, f"is another library (without {missing[0]})"
    library = entry / record["library"]
    try:
        status = library.stat()
    except OSError:
        return None, "has lost its library"
    identity = (status.st_ino, status.st_size, status.st_mtime_ns)
    if _verified.get(library) == identity:
        return library, None
    if status.st_size != size:
        return None, f"is damaged (its library has {status.st_size} B, its record {size} B)"
    try:
        intact = _sha256(library) == digest
    except OSError as error:
        return None, f"has an unreadable library ({error.strerror})"
    if not intact:
        return None, "is damaged (its library's SHA-256 is not its record's)"
    problem = _exports(library, symbols)
    if problem is not None:
        return None, f"is damaged (its library {problem})"
    _verified[library] = identity
    return library, None


def _sha256(path: Path) -> str:
    with open(path, "rb") as file:
        return hashlib.file_digest(file, "sha256").hexdigest()


def _exports(library: Path, symbols: Sequence[str]) -> str | None:
    """What is wrong when loading ``library`` and looking its ``symbols`` up, if anything."""
    try:
        loaded = ctypes.CDLL(str(library))
    except OSError as error:
        return f"does not load: {error}"
    missing = [symbol for symbol in symbols if not hasattr(loaded, symbol)]
    return f"does not export {missing[0]}" if missing else None


def _compile(compiler: str, source: Path, output: Path, flags: Sequence[str]) -> None:
    """Compile ``source`` into ``output`` under the guard, its temporary files beside them."""
    if _stopped.is_set():
        raise BuildStopped(f"the build of {source.stem} was stopped")
    temporary = source.parent / "tmp"
    temporary.mkdir(exist_ok=True)
    command = [compiler, *flags, str(source), "-o", str(output), "-lm"]
    # The parent-death signal comes when the thread that started the guard ends: this one,
    # which waits for it.
    process = subprocess.Popen(
        [sys.executable, "-I", "-S", "-c", _GUARD, str(os.getpid()), *command],
        stdin=subprocess.DEVNULL,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        errors="replace",
        env={**os.environ, "TMPDIR": str(temporary)},
        process_group=0,
    )
    _compiling.add(process)
    try:
        messages, _ = process.communicate()
    except BaseException:  # Ctrl-C, or anything else: the compiler ends with the call
        with contextlib.suppress(ProcessLookupError):
            os.killpg(process.pid, signal.SIGKILL)
        process.wait()
        raise
    finally:
        _compiling.discard(process)
    if _stopped.is_set():
        raise BuildStopped(f"the build of {source.stem} was stopped")
    if process.returncode != 0:
        reason = _telling_line(messages)
        raise OSError(f"{Path(compiler).name} could not compile {source.name}: {reason}")


def _telling_line(messages: str) -> str:
    """The compiler's message in one line: its first error, else its last line."""
    lines = [line.strip() for line in messages.splitlines() if line.strip()]
    errors = [
        line
        for line in lines
        if ("error" in line or "failed" in line) and not line.startswith("collect2:")
    ]
    return (errors or lines or ["no message"])[0 if errors else -1]


def _publish(work: Path, name: str, output: Path, symbols: Sequence[str]) -> Path:
    """Record ``output`` and rename the workspace ``work`` into the entry ``name`` (or take
    the entry another process published meanwhile); the library's path."""
    problem = _exports(output, symbols)
    if problem is not None:
        raise OSError(f"the compiled library {problem}")
    digest = _sha256(output)
    library = work / f"{digest[:16]}.so"
    output.rename(library)
    record = {
        "library": library.name,
        "size": library.stat().st_size,
        "sha256": digest,
        "symbols": sorted(symbols),
    }
    (work / MANIFEST).write_text(json.dumps(record, indent=1) + "\n")
    for leftover in work.iterdir():
        if leftover.name not in (library.name, MANIFEST):
            _delete(leftover)
    entry = work.parent / name
    try:
        work.rename(entry)
    except OSError as error:
        if error.errno not in (errno.ENOTEMPTY, errno.EEXIST):
            raise
        published = find(name, symbols)  # another process's, or removed if damaged
        if published is not None:
            return published
        work.rename(entry)
    status = (entry / library.name).stat()
    _verified[entry / library.name] = (status.st_ino, status.st_size, status.st_mtime_ns)
    return entry / library.name


def _evict(directory: Path, keep: str) -> None:
    """Remove the least recently used entries, but ``keep``, until the cache fits its
    bound."""
    try:
        bound = size_bound()
    except InputError as error:
        _LOG.warning("the cache is not pruned: %s", error)
        return
    listed = entries()
    total = sum(entry.size for entry in listed)
    for entry in listed:
        if total <= bound:
            break
        if entry.name == keep:
            continue
        with contextlib.suppress(OSError):
            _remove(directory / entry.name)
            total -= entry.size
            _LOG.info("removed %s from the cache (least recently used)", entry.name)


@contextlib.contextmanager
def _locked(directory: Path, operation: int) -> Iterator[None]:
    """Hold the cache's lock (``fcntl.LOCK_SH`` or ``LOCK_EX``)."""
    handle = os.open(directory / _LOCK, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        fcntl.flock(handle, operation)
        yield
    finally:
        os.close(handle)


@contextlib.contextmanager
def _workspace(directory: Path) -> Iterator[Path]:
    """A new folder in the cache, locked by this process, removed on leaving (unless it was
    renamed into an entry)."""
    directory.mkdir(parents=True, exist_ok=True)
    _clean_once(directory)
    with _locked(directory, fcntl.LOCK_SH):
        path = Path(tempfile.mkdtemp(prefix=_WORKSPACE, dir=directory))
        handle = os.open(path, os.O_RDONLY)
        fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
    _held.add(handle)
    try:
        yield path
    finally:
        shutil.rmtree(path, ignore_errors=True)
        _held.discard(handle)
        os.close(handle)


def _live(workspace: Path) -> bool:
    """Whether a live process holds ``workspace``."""
    try:
        handle = os.open(workspace, os.O_RDONLY)
    except OSError:
        return False
    try:
        fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        return True
    finally:
        os.close(handle)
    return False


def _clean_once(directory: Path) -> None:
    """:func:`_clean`, once per process and cache folder."""
    if directory not in _cleaned and directory.is_dir():
        _cleaned.add(directory)
        with contextlib.suppress(OSError):
            _clean(directory)


def _clean(directory: Path) -> None:
    """Remove the workspaces no live process holds."""
    with _locked(directory, fcntl.LOCK_EX):
        for path in directory.glob(f"{_WORKSPACE}*"):
            if not _live(path):
                _delete(path)


def _remove(path: Path) -> None:
    """Remove an entry whole: first renamed into a workspace, so that no reader sees part
    of it and a kill leaves only a dead workspace."""
    with _workspace(path.parent) as trash, contextlib.suppress(FileNotFoundError):
        path.rename(trash / path.name)


def _delete(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    else:
        path.unlink(missing_ok=True)


def _size(path: Path) -> int:
    """Bytes in ``path``, a file or a folder of files."""
    if not path.is_dir() or path.is_symlink():
        return path.lstat().st_size
    return sum(f.lstat().st_size for f in path.rglob("*") if f.is_file() and not f.is_symlink())


def _release_in_child() -> None:
    """A forked child does not hold its parent's workspaces."""
    for handle in _held:
        os.close(handle)
    _held.clear()


os.register_at_fork(after_in_child=_release_in_child)
