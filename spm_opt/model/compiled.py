"""CasADi functions compiled to C and evaluated over many samples in one call.

CasADi's code generator writes the single-sample function; a small C loop around it runs
it over N samples held in NumPy arrays, split over threads by OpenMP when the compiler has
it, and ctypes calls that loop on the arrays' own memory (no conversion to CasADi's
matrices). The shared library is kept in the cache of compiled libraries
(:mod:`spm_opt.model.library_cache`) under a name made from the hash of its source and
flags, so a process compiles each function once per machine, not once per run.

Every input and output is a row-major (N, n) float64 array whose row i is sample i's
vector (an input of shape (n, 1) in CasADi); inputs marked shared are one vector for all
samples. Without a C compiler, or when the build fails, :func:`compile_batch` returns
``None`` (one warning says why) and callers keep CasADi's interpreter.
"""

from __future__ import annotations

import ctypes
import hashlib
import logging
from dataclasses import dataclass

import casadi as ca
import numpy as np

from spm_opt.model.library_cache import build, compiler, find

_LOG = logging.getLogger(__name__)

FLAGS = ("-O3", "-fPIC", "-shared")
"""Compiler flags; OpenMP (``-fopenmp``) is added when the compiler accepts it."""

_LOOP = """
#include <stdlib.h>
int {name}_batch(const double** inputs, const long* strides, double** outputs,
                 const long* out_strides, long n) {{
  int failed = 0;
#ifdef _OPENMP
#pragma omp parallel reduction(|:failed) if(n >= {parallel_min})
#endif
  {{
    const casadi_real* arg[{sz_arg}];
    casadi_real* res[{sz_res}];
    casadi_int iw[{sz_iw} + 1];
    casadi_real w[{sz_w} + 1];
#ifdef _OPENMP
#pragma omp for schedule(static)
#endif
    for (long i = 0; i < n; ++i) {{
      for (int k = 0; k < {n_in}; ++k) arg[k] = inputs[k] + i * strides[k];
      for (int k = 0; k < {n_out}; ++k) res[k] = outputs[k] + i * out_strides[k];
      failed |= {name}(arg, res, iw, w, 0);
    }}
  }}
  return failed;
}}
"""

PARALLEL_MIN_SAMPLES = 4096
"""Below this many samples the loop stays on one thread (starting threads costs more)."""


@dataclass(frozen=True)
class BatchFunction:
    """A compiled CasADi function evaluated over samples; see the module docstring."""

    function: ca.Function
    library: ctypes.CDLL
    entry: ctypes._CFuncPtr

    def __call__(self, *inputs: np.ndarray, shared: tuple[int, ...] = ()) -> list[np.ndarray]:
        """Evaluate over N samples: inputs (N, n_k) except the ``shared`` ones (n_k,);
        returns the outputs, each (N, m_k)."""
        f = self.function
        arrays = [
            np.ascontiguousarray(np.ravel(a) if k in shared else a, dtype=np.float64)
            for k, a in enumerate(inputs)
        ]
        n = next(a.shape[0] for k, a in enumerate(arrays) if k not in shared)
        for k, a in enumerate(arrays):
            expected = (f.size1_in(k),) if k in shared else (n, f.size1_in(k))
            if a.shape != expected:
                raise ValueError(f"input {f.name_in(k)} has shape {a.shape}, wanted {expected}")
        strides = [0 if k in shared else f.size1_in(k) for k in range(f.n_in())]
        outputs = [np.empty((n, f.size1_out(k))) for k in range(f.n_out())]
        pointer = ctypes.POINTER(ctypes.c_double)
        status = self.entry(
            (pointer * len(arrays))(*(a.ctypes.data_as(pointer) for a in arrays)),
            (ctypes.c_long * len(strides))(*strides),
            (pointer * len(outputs))(*(o.ctypes.data_as(pointer) for o in outputs)),
            (ctypes.c_long * len(outputs))(*(f.size1_out(k) for k in range(f.n_out()))),
            ctypes.c_long(n),
        )
        if status:
            raise ArithmeticError(f"compiled {f.name()} failed on some samples")
        return outputs


def _source(function: ca.Function) -> str:
    """The C of ``function`` and of its loop over samples."""
    generator = ca.CodeGenerator(f"{function.name()}.c", {"with_header": False})
    generator.add(function)
    return generator.dump() + _LOOP.format(
        name=function.name(),
        sz_arg=function.sz_arg(),
        sz_res=function.sz_res(),
        sz_iw=function.sz_iw(),
        sz_w=function.sz_w(),
        n_in=function.n_in(),
        n_out=function.n_out(),
        parallel_min=PARALLEL_MIN_SAMPLES,
    )


def compile_batch(function: ca.Function) -> BatchFunction | None:
    """The function compiled for batches (from the cache, else built into it), or None,
    with one warning, when no C compiler works here or the build fails."""
    chosen = compiler()
    if chosen is None:
        _LOG.warning("no C compiler: %s runs in CasADi's interpreter", function.name())
        return None
    code = _source(function)
    key = hashlib.sha256((code + " ".join(FLAGS) + chosen).encode()).hexdigest()[:16]
    name, symbol = f"{function.name()}_{key}", f"{function.name()}_batch"
    try:
        library = find(name, [symbol]) or build(
            name, code, chosen, [(*FLAGS, "-fopenmp"), FLAGS], [symbol]
        )
        loaded = ctypes.CDLL(str(library))
    except OSError as error:
        _LOG.warning("%s runs in CasADi's interpreter: %s", function.name(), error)
        return None
    entry = getattr(loaded, symbol)
    entry.restype = ctypes.c_int
    return BatchFunction(function, loaded, entry)
