"""NLP solvers whose functions run as compiled C from a shared library cached on disk.

The NLP is made of a few small functions (the optimal-control NLP: one interval's value,
Jacobian and Hessian, :mod:`spm_opt.planners.ocp.assembly`) and an ``assemble`` step that
builds the NLP and its derivative functions from them, in SX or compiled alike.
:func:`nlp_solver` takes a cheap ``key`` for those functions (the caller's: e.g. a hash of
the code that builds them) and adds what else makes the binary: CasADi's version, the
compiler and its flags. When the library is in the cache of compiled libraries
(:mod:`spm_opt.model.library_cache`) and whole, the functions are loaded from it without
building their symbolic graph. Otherwise the solver returned runs the SX functions in
CasADi's interpreter while their C is generated here and compiled in a background thread;
the :class:`Solver` switches to the library on its first call after the library appears,
and later calls load it. Without a C compiler, when the build fails, or when the C is too
big to compile (:data:`MAX_SOURCE_BYTES`), the solver stays interpreted and one warning
says so. A process that ends during a build waits for it, so that the next one finds the
library, unless it was interrupted (:func:`spm_opt.model.library_cache.stop_compilers`).

Besides the functions, the library holds the reverse derivatives of the value functions
(the first, unless the caller names others): CasADi's ``nlpsol`` asks for them when it is
created, even with every derivative given. Building the paper's minimum-time interval
library takes about 1 s at -O1, the minimum-jerk one (three check points) 2.5 s, the one
with the torque table 12 s (36 MB of C, most of it the table's coefficients); loading takes
milliseconds.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import logging
import os
import threading
import time
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import casadi as ca

from spm_opt.model.library_cache import BuildStopped, build, cache_directory, compiler, find

_LOG = logging.getLogger(__name__)

BUILD_FLAGS = ("-O1", "-fPIC", "-shared")
"""Compiler flags: -O1, as measured for whole NLPs, made the functions 3× faster than -O0
at a fraction of -O2's and -O3's build time for 6 % less speed."""

LOADED, COMPILED, INTERPRETED = "loaded", "compiled", "interpreted"
"""How a :class:`Solver` got its function: from the disk cache, compiled in this call, or
CasADi's interpreter (its library absent, still being built, or impossible)."""

MAX_SOURCE_BYTES = 64_000_000
"""Larger C is not compiled. Compile time grows with the size of each function, faster
than linearly (a whole NLP's Hessian expanded to 38 MB of SX took 506 s at -O1), and only
linearly with constant tables: the interval library with the torque table, 36 MB of C of
which most are the table's coefficients, compiles in 12 s."""

_FORMAT = 2
"""The libraries' layout (2: interval functions and the value's reverse); a new layout is
a new library."""


@dataclass
class Solver:
    """An NLP solver and how it was obtained; call it as the CasADi solver.

    Attributes
    ----------
    function : ca.Function
        The solver (``nlpsol``) now in use.
    kind : str
        :data:`LOADED`, :data:`COMPILED` or :data:`INTERPRETED`: how ``function`` was made.
    seconds : float
        Time it took to make ``function``, s (graph, solver and compiler included).
    library : Path or None
        The cache's entry of the library it uses or waits for (a folder); None without a
        compiler.
    """

    function: ca.Function
    kind: str
    seconds: float
    library: Path | None
    _load: Callable[[], ca.Function | None] | None = field(default=None, repr=False)

    def __call__(self, **arguments: Any) -> dict[str, ca.DM]:
        """Solve (CasADi's keywords: x0, p, lbx, ...), with the library if it is there."""
        self._switch_to_library()
        return self.function(**arguments)

    def stats(self) -> dict[str, Any]:
        """The last solve's statistics (CasADi's ``stats()``)."""
        return self.function.stats()

    def name(self) -> str:
        """The solver's name (CasADi's ``name()``)."""
        return self.function.name()

    def _switch_to_library(self) -> None:
        """Load the library once it exists, if this solver is interpreted."""
        if self.kind != INTERPRETED or self._load is None or not self.library.exists():
            return
        started = time.perf_counter()
        function, self._load = self._load(), None
        if function is not None:
            self.function, self.kind = function, LOADED
            self.seconds = time.perf_counter() - started


_builds: dict[Path, Future] = {}  # each library is built at most once per process
_lock = threading.Lock()
_executor: ThreadPoolExecutor | None = None


def nlp_solver(
    name: str,
    plugin: str,
    key: str,
    names: tuple[str, ...],
    functions: Callable[[], list[ca.Function]],
    assemble: Callable[[list[ca.Function]], tuple[dict[str, Any], dict[str, Any]]],
    options: dict[str, Any],
    background: bool = True,
    reversed_: tuple[int, ...] = (0,),
    interpreted: Callable[[], ca.Function] | None = None,
) -> Solver:
    """``nlpsol(name, plugin, nlp, {**options, **derivatives})`` with ``nlp, derivatives =
    assemble(fs)``, where ``fs`` are ``functions()`` compiled.

    ``key`` identifies what ``functions`` returns (functions named ``names``) without
    calling it; with ``background`` a missing library is compiled in a thread while the
    solver returned runs the SX functions (:func:`wait_for_builds` waits for it), else
    before returning. The library also holds the reverse derivatives of the functions at
    ``reversed_`` (those whose rows are the NLP's g). ``interpreted``, when given, makes
    the solver that runs until the library is there (else the SX functions assembled).
    """
    started = time.perf_counter()

    def solver_of(fs: list[ca.Function]) -> ca.Function:
        nlp, derivatives = assemble(fs)
        return ca.nlpsol(name, plugin, nlp, {**options, **derivatives})

    def uncompiled(symbolic: Callable[[], list[ca.Function]]) -> ca.Function:
        return interpreted() if interpreted is not None else solver_of(symbolic())

    chosen = compiler()
    if chosen is None:
        _LOG.warning("no C compiler: the NLP %r runs in CasADi's interpreter", name)
        solver = uncompiled(functions)
        return Solver(solver, INTERPRETED, time.perf_counter() - started, None)
    library = library_path(chosen, key)

    def load() -> ca.Function | None:
        """The solver on the library, if it is in the cache and whole."""
        found = find(library.name, names)
        if found is None:
            return None
        try:
            externals = [ca.external(function, str(found)) for function in names]
        except RuntimeError as error:
            _LOG.debug("CasADi cannot load %s: %s", found, error)
            _LOG.warning("CasADi cannot load %s: the NLP stays interpreted", library.name)
            return None
        return solver_of(externals)

    loaded = load()
    if loaded is not None:
        return Solver(loaded, LOADED, time.perf_counter() - started, library)
    symbolic = functions()
    pending = _start_build(chosen, library, symbolic, reversed_, names)
    if pending is not None and not background:
        pending.result()
        loaded = load()
        if loaded is not None:
            return Solver(loaded, COMPILED, time.perf_counter() - started, library)
    solver = uncompiled(lambda: symbolic)
    return Solver(solver, INTERPRETED, time.perf_counter() - started, library, load)


def library_path(compiler_path: str, key: str) -> Path:
    """The cache's entry (a folder) of the library for ``key``, compiled by
    ``compiler_path``."""
    identity = json.dumps(
        [key, ca.__version__, compiler_path, BUILD_FLAGS, MAX_SOURCE_BYTES, _FORMAT],
        sort_keys=True,
    )
    digest = hashlib.sha256(identity.encode()).hexdigest()[:16]
    return cache_directory() / f"nlp_{digest}"


WAIT_POLL_S = 0.05
"""How often :func:`wait_for_builds` looks whether the builds are done, s."""


def wait_for_builds() -> None:
    """Wait until every build this process started has finished (or failed). It sleeps
    between looks rather than waiting on the futures' locks: a Ctrl-C then lands in a
    sleep, never while the wait holds a lock the build thread needs to finish."""
    with _lock:
        pending = [build for build in _builds.values() if not build.done()]
    if pending:
        _LOG.info("waiting for the libraries compiling in the background (%d)", len(pending))
    while not all(build.done() for build in pending):
        time.sleep(WAIT_POLL_S)


def _start_build(
    chosen: str,
    library: Path,
    functions: list[ca.Function],
    reversed_: tuple[int, ...],
    names: tuple[str, ...],
) -> Future | None:
    """Generate the C here (CasADi is not thread-safe) and compile it in the build thread,
    unless this process has built or is building ``library``; the build's future (None
    when there is nothing to compile)."""
    with _lock:
        if library in _builds:
            return _builds[library]
    code = _source(library, functions, reversed_)
    if code is None:
        return None
    with _lock:
        future = _build_executor().submit(_compile, chosen, code, library, names)
        _builds[library] = future
    return future


def _source(library: Path, functions: list[ca.Function], reversed_: tuple[int, ...]) -> str | None:
    """The C for ``library``; None (with a warning) when it cannot be generated or is too
    big to compile, which a marker in the cache remembers."""
    too_big = library.with_name(f"{library.name}.too-big")
    try:
        verdict = too_big.read_text()
    except OSError:
        try:
            code = _generate(functions, reversed_, library.name)
        except RuntimeError as error:
            reason = " ".join(str(error).split())  # CasADi's message, in one line
            _LOG.warning("no C for %s, the NLP stays interpreted: %s", library.name, reason)
            return None
        if len(code) <= MAX_SOURCE_BYTES:
            return code
        verdict = f"its C ({len(code) / 1e6:.0f} MB) is too big to compile"
        with contextlib.suppress(OSError):  # then it is only not remembered
            too_big.parent.mkdir(parents=True, exist_ok=True)
            too_big.write_text(verdict)
    _LOG.warning("%s: %s; the NLP stays interpreted", library.name, verdict)
    return None


def _generate(functions: list[ca.Function], reversed_: tuple[int, ...], stem: str) -> str:
    """The C of ``functions`` and of the reverse derivatives of those at ``reversed_``."""
    generator = ca.CodeGenerator(f"{stem}.c")
    for function in [*functions, *(functions[k].reverse(1) for k in reversed_)]:
        generator.add(function)
    return generator.dump()


def _compile(chosen: str, code: str, library: Path, names: tuple[str, ...]) -> None:
    """The build thread's job: compile into the cache, or say in one line why not."""
    try:
        build(library.name, code, chosen, [BUILD_FLAGS], names)
    except BuildStopped:
        _LOG.debug("the build of %s was stopped", library.name)
    except Exception as error:  # else it would stay in the thread's future, unseen
        _LOG.warning("the NLP stays interpreted: %s", error)


def _build_executor() -> ThreadPoolExecutor:
    """One build thread: compilers run one at a time, next to the solves."""
    global _executor
    if _executor is None:
        _executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix="nlp-build")
    return _executor


def _forget_builds() -> None:
    """In a forked child the parent's build thread, its futures and lock mean nothing."""
    global _executor, _lock
    _executor, _lock = None, threading.Lock()
    _builds.clear()


os.register_at_fork(after_in_child=_forget_builds)
