"""NLP solvers whose functions (objective, constraints, their derivatives, the Lagrangian's
Hessian) are compiled C in a shared library cached on disk.

:func:`nlp_solver` takes a cheap ``key`` for the formulation (the caller's: e.g. a hash of
the code that builds it and of its settings) and adds what else makes the binary: CasADi's
version, the compiler, the flags, the plugin and the options that choose which functions
the plugin needs. When the library is in the cache (``$SPM_OPT_CACHE`` or
``~/.cache/spm_opt``, as for :mod:`spm_opt.model.compiled`), the solver is loaded from it
without building the symbolic graph. Otherwise the graph is built and the solver returned
runs in CasADi's interpreter while the C (what ``generate_dependencies`` writes) is
generated here and compiled in a background thread; the :class:`Solver` switches to the
library on its first call after the library appears, and later calls load it. Without a C
compiler, when the build fails, or when the C is too big to compile
(:data:`MAX_SOURCE_BYTES`), the solver stays interpreted and one warning says so. A
process that ends during a build waits for it, so that the next one finds the library.

The C is generated from the MX graph (``expand`` off) whatever the caller's ``expand``:
the expanded SX code is 5 times bigger and 80 times slower to compile for the same speed.
The paper's minimum-time NLP (4 segments, 104 intervals, no torque rows; CasADi 3.8.2,
gcc 12 at -O1, 2 shared cores; one solve from the planner's guess, 47 iterations)::

    solver                 C      build   hess_l  jac_g   grad_f  functions  solve
    SX, interpreted        -      -       3–5 ms  1.1 ms  0.01 ms 0.20–0.29 s 0.36–0.47 s
    MX, interpreted        -      -       20 ms   6.8 ms  0.7 ms  1.38 s     1.61 s
    MX compiled            7 MB   6 s     1.7 ms  0.7 ms  0.07 ms 0.13 s     0.35 s
    SX compiled            38 MB  506 s   2.2 ms  0.65 ms 0.01 ms 0.14 s     0.34 s

Getting the solver: 0.9 s interpreted (graph and SX expansion), 1.5 s on a cache miss
(with the MX solver and 0.5 s of code generation), 7.7 s when compiling before returning,
0.004 s loading the library (a fresh process: 0.9 s of imports, then 0.004 s). Hence the
background build: the first solve waits 1.5 s rather than 7.7 s to save 0.1 s a solve.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import shutil
import tempfile
import threading
import time
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor, wait
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import casadi as ca

from spm_opt.model.compiled import build_library, cache_directory, compiler

_LOG = logging.getLogger(__name__)

BUILD_FLAGS = ("-O1", "-fPIC", "-shared")
"""Compiler flags: -O1 makes the functions 3× faster than -O0 (0.13 against 0.42 s a
minimum-time solve) and compiles in 6 s; -O2 and -O3 take 17–20 s for 6 % more."""

LOADED, COMPILED, INTERPRETED = "loaded", "compiled", "interpreted"
"""How a :class:`Solver` got its function: from the disk cache, compiled in this call, or
CasADi's interpreter (its library absent, still being built, or impossible)."""

MAX_SOURCE_BYTES = 20_000_000
"""Larger C is not compiled: the minimum-time NLP's 7 MB takes 6 s at -O1, but compile
time grows faster than the size (the 38 MB expanded form: 506 s; the 65 MB NLP with the
torque rows: over 20 min and 8.5 GB of memory at -O1, and at -O0 95 s for no gain)."""

_INTERPRETER_ONLY = ("expand",)
"""Options a solver on a compiled library refuses (it cannot expand compiled code)."""

_FUNCTION_OPTIONS = ("hessian_approximation",)
"""The plugin's own options that change which functions it needs (its other options,
tolerances and the like, share one library)."""


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
        The shared library it uses or waits for; None without a compiler.
    """

    function: ca.Function
    kind: str
    seconds: float
    library: Path | None
    _load: Callable[[], ca.Function] | None = field(default=None, repr=False)

    def __call__(self, **arguments: Any) -> dict[str, ca.DM]:
        """Solve (CasADi's keywords: x0, p, lbx, ...), with the library if it is there."""
        self._switch_to_library()
        return self.function(**arguments)

    def stats(self) -> dict[str, Any]:
        """The last solve's statistics (CasADi's ``stats()``)."""
        return self.function.stats()

    def _switch_to_library(self) -> None:
        """Load the library once it exists, if this solver is interpreted."""
        if self.kind != INTERPRETED or self._load is None or not self.library.exists():
            return
        started = time.perf_counter()
        try:
            self.function = self._load()
        except RuntimeError as error:
            _LOG.warning("%s does not load, staying interpreted: %s", self.library.name, error)
        else:
            self.kind, self.seconds = LOADED, time.perf_counter() - started
        self._load = None


_builds: dict[Path, Future] = {}  # each library is built at most once per process
_lock = threading.Lock()
_executor: ThreadPoolExecutor | None = None


def nlp_solver(
    name: str,
    plugin: str,
    key: str,
    build: Callable[[], dict[str, Any]],
    options: dict[str, Any],
    background: bool = True,
) -> Solver:
    """The solver ``nlpsol(name, plugin, build(), options)``, its functions compiled.

    ``key`` identifies what ``build`` returns (the dict of x, p, f, g) without calling it;
    with ``background`` a missing library is compiled in a thread while the interpreted
    solver is returned (:func:`wait_for_builds` waits for it), else before returning.
    """
    started = time.perf_counter()
    chosen = compiler()
    if chosen is None:
        _LOG.warning("no C compiler: the NLP %r runs in CasADi's interpreter", name)
        solver = ca.nlpsol(name, plugin, build(), options)
        return Solver(solver, INTERPRETED, time.perf_counter() - started, None)
    library = library_path(chosen, plugin, key, options)

    def load() -> ca.Function:
        return ca.nlpsol(name, plugin, str(library), _compiled_options(options))

    if library.exists():
        try:
            return Solver(load(), LOADED, time.perf_counter() - started, library)
        except RuntimeError as error:
            _LOG.warning("%s does not load (%s); building it again", library.name, error)
            library.unlink(missing_ok=True)
    nlp = build()
    solver = ca.nlpsol(name, plugin, nlp, options)

    def mx_solver() -> ca.Function:  # the C comes from the MX graph: see the module docstring
        if options.get("expand"):
            return ca.nlpsol(name, plugin, nlp, _compiled_options(options))
        return solver

    pending = _start_build(chosen, library, mx_solver)
    if pending is not None and not background:
        pending.result()
        if library.exists():
            return Solver(load(), COMPILED, time.perf_counter() - started, library)
    return Solver(solver, INTERPRETED, time.perf_counter() - started, library, load)


def library_path(compiler_path: str, plugin: str, key: str, options: dict[str, Any]) -> Path:
    """Where the library for ``key``, compiled by ``compiler_path`` with ``options``, lives."""
    identity = json.dumps(
        [
            key,
            ca.__version__,
            compiler_path,
            BUILD_FLAGS,
            MAX_SOURCE_BYTES,
            plugin,
            _binary_options(plugin, options),
        ],
        sort_keys=True,
        default=repr,
    )
    digest = hashlib.sha256(identity.encode()).hexdigest()[:16]
    return cache_directory() / f"nlp_{plugin}_{digest}.so"


def wait_for_builds() -> None:
    """Wait until every build this process started has finished (or failed)."""
    with _lock:
        pending = list(_builds.values())
    wait(pending)


def _binary_options(plugin: str, options: dict[str, Any]) -> dict[str, Any]:
    """The options that shape the compiled functions: the generic ones but ``expand``, and
    the plugin's :data:`_FUNCTION_OPTIONS` (given nested or dotted)."""
    own = {k: v for k, v in options.get(plugin, {}).items() if k in _FUNCTION_OPTIONS}
    chosen = {}
    for option, value in options.items():
        head, _, tail = option.partition(".")
        if head == plugin:
            if tail in _FUNCTION_OPTIONS:
                own[tail] = value
        elif option not in _INTERPRETER_ONLY:
            chosen[option] = value
    return {**chosen, plugin: own}


def _compiled_options(options: dict[str, Any]) -> dict[str, Any]:
    """``options`` without those a solver on a compiled library refuses."""
    return {k: v for k, v in options.items() if k not in _INTERPRETER_ONLY}


def _start_build(chosen: str, library: Path, mx_solver: Callable[[], ca.Function]) -> Future | None:
    """Generate the C here (CasADi is not thread-safe) and compile it in the build thread,
    unless this process has built or is building ``library``; the build's future (None
    when there is nothing to compile)."""
    with _lock:
        if library in _builds:
            return _builds[library]
    source = _source(library, mx_solver)
    if source is None:
        return None
    with _lock:
        future = _build_executor().submit(_compile, chosen, source, library)
        _builds[library] = future
    return future


def _source(library: Path, mx_solver: Callable[[], ca.Function]) -> Path | None:
    """The C for ``library`` in a new temporary directory; None (with a warning) when it
    cannot be generated or is too big to compile, which a marker next to the library
    remembers."""
    too_big = library.with_suffix(".too-big")
    if not too_big.exists():
        directory = Path(tempfile.mkdtemp(prefix="spm_opt_nlp_"))
        try:
            source = _generate(mx_solver(), directory, library.stem)
        except RuntimeError as error:
            shutil.rmtree(directory, ignore_errors=True)
            _LOG.warning("no C for %s, the NLP stays interpreted: %s", library.name, error)
            return None
        size = source.stat().st_size
        if size <= MAX_SOURCE_BYTES:
            return source
        shutil.rmtree(directory, ignore_errors=True)
        too_big.parent.mkdir(parents=True, exist_ok=True)
        too_big.write_text(f"its C ({size / 1e6:.0f} MB) is too big to compile")
    _LOG.warning("%s: %s; the NLP stays interpreted", library.name, too_big.read_text())
    return None


def _generate(solver: ca.Function, directory: Path, stem: str) -> Path:
    """What ``solver.generate_dependencies`` writes (the NLP and every function the plugin
    made from it), but into ``directory`` rather than the working directory."""
    generator = ca.CodeGenerator(f"{stem}.c")
    generator.add(solver.oracle())
    for function in solver.get_function():
        generator.add(solver.get_function(function))
    generator.generate(f"{directory}{os.sep}")
    return directory / f"{stem}.c"


def _compile(chosen: str, source: Path, library: Path) -> None:
    """The build thread's job: compile, log a failure, remove the source."""
    started = time.perf_counter()
    try:
        build_library(chosen, source, library, BUILD_FLAGS)
        _LOG.info("compiled %s in %.1f s", library.name, time.perf_counter() - started)
    except OSError as error:
        _LOG.warning("%s not built, the NLP stays interpreted: %s", library.name, error)
    finally:
        shutil.rmtree(source.parent, ignore_errors=True)


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
