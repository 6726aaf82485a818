"""CasADi functions compiled for batches: the same numbers as CasADi, a cache on disk, and
the interpreter when no compiler works."""

import logging
import stat

import casadi as ca
import numpy as np
import pytest

from spm_opt.model import compiled, library_cache


def quadratic() -> ca.Function:
    x, p = ca.SX.sym("x", 2), ca.SX.sym("p", 3)
    y = ca.vertcat(p[0] * ca.sin(x[0]) * x[1], p[1] * x[0] ** 2 + p[2], ca.cos(x[1]))
    return ca.Function("quadratic_test", [x, p], [y, x[0] * x[1]])


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv(library_cache.CACHE_ENV, str(tmp_path / "cache"))
    return tmp_path / "cache"


@pytest.mark.parametrize("n", [1, 7, compiled.PARALLEL_MIN_SAMPLES + 3])
def test_same_numbers_as_casadi(cache, n):
    function = quadratic()
    batch = compiled.compile_batch(function)
    assert batch is not None
    x, p = np.random.default_rng(n).normal(size=(n, 2)), np.array([0.5, -2.0, 3.0])
    y, z = batch(x, p, shared=(1,))
    expected_y, expected_z = function(x.T, p)
    np.testing.assert_array_equal(y, expected_y.full().T)
    np.testing.assert_array_equal(z, expected_z.full().T)
    assert y.shape == (n, 3) and z.shape == (n, 1)


def test_library_is_cached_on_disk(cache):
    compiled.compile_batch(quadratic())
    libraries = list(cache.glob("quadratic_test_*/*.so"))
    assert len(libraries) == 1
    before = libraries[0].stat().st_mtime_ns
    compiled.compile_batch(quadratic())
    assert [p.stat().st_mtime_ns for p in cache.glob("*/*.so")] == [before]
    assert sorted(p.name for p in libraries[0].parent.iterdir()) == [
        libraries[0].name,
        library_cache.MANIFEST,
    ]
    assert not list(cache.glob(".build-*"))


def test_wrong_shape_is_refused(cache):
    batch = compiled.compile_batch(quadratic())
    with pytest.raises(ValueError, match="input i0 has shape"):
        batch(np.zeros((4, 3)), np.zeros(3), shared=(1,))


def test_no_compiler_means_the_interpreter(cache, monkeypatch):
    monkeypatch.setenv("CC", str(cache / "no-such-compiler"))
    assert compiled.compile_batch(quadratic()) is None


def test_failed_build_means_the_interpreter_one_warning_and_nothing_left(
    cache, monkeypatch, caplog
):
    failing = cache.parent / "failing-cc"
    failing.write_text("#!/bin/sh\necho 'fatal: out of luck' >&2\nexit 1\n")
    failing.chmod(failing.stat().st_mode | stat.S_IXUSR)
    monkeypatch.setenv("CC", str(failing))
    with caplog.at_level(logging.WARNING):
        assert compiled.compile_batch(quadratic()) is None
    (message,) = [record.getMessage() for record in caplog.records]
    assert message.startswith("quadratic_test runs in CasADi's interpreter: quadratic_test_")
    assert "not built: failing-cc could not compile quadratic_test_" in message
    assert message.endswith(".c: fatal: out of luck")
    assert library_cache.entries() == []
    assert not list(cache.glob(".build-*"))
