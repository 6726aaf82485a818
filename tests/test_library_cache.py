"""The cache of compiled libraries against what happens to its files and to the processes
that build them: a damaged entry of either kind (a batch function's, an NLP solver's) is
rebuilt and used with one warning line; a killed build leaves no compiler running and the
next process removes what it left; a full disk is one warning line; the cache keeps to its
size bound; ``spm-opt cache info|clear``.

Damaged libraries are loaded in child processes, so that a crash (SIGBUS) fails the test
instead of ending pytest; the libraries this process loads are never damaged in place."""

from __future__ import annotations

import hashlib
import json
import logging
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from test_bad_inputs import assert_one_error, run_cli
from test_compiled import quadratic
from test_nlp_library import solve

from spm_opt.model import compiled, library_cache

TESTS = Path(__file__).resolve().parent
ROOT = TESTS.parent

CHILD = """
import logging, sys
sys.path.insert(0, sys.argv[2])
logging.basicConfig(format="%(levelname)s: %(message)s")
if sys.argv[1] == "batch":
    from test_compiled import quadratic
    from spm_opt.model.compiled import compile_batch
    print("compiled" if compile_batch(quadratic()) is not None else "interpreted")
else:
    from test_nlp_library import solve
    print(solve("rosenbrock", background=False)[0].kind)
"""
"""Builds or loads one library of ``argv[1]``'s kind (batch or nlp) and prints how it got
its function; warnings go to stderr, one line each."""

STEPS = "".join(f"  x = x * 1.0001 + sin(x + {i}.0) * {i % 7 + 1}.0;\n" for i in range(15000))
SLOW_C = f"#include <math.h>\ndouble slow(double x) {{\n{STEPS}  return x;\n}}\n"
"""C that takes gcc half a minute at -O1 (its builds are stopped long before)."""


def tiny_c(name: str) -> str:
    return f"int {name}(void) {{ return 1; }}\n"


def build_tiny(name: str) -> Path:
    return library_cache.build(
        name, tiny_c(name), library_cache.compiler(), [("-shared", "-fPIC")], [name]
    )


@pytest.fixture
def cache(tmp_path, monkeypatch) -> Path:
    monkeypatch.setenv(library_cache.CACHE_ENV, str(tmp_path / "cache"))
    return tmp_path / "cache"


@pytest.fixture(scope="module")
def pristine(tmp_path_factory) -> dict[str, Path]:
    """Whole entries, built once (and loaded by this process, so never damaged): each
    kind's and a foreign library's, by kind."""
    folder = tmp_path_factory.mktemp("pristine")
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv(library_cache.CACHE_ENV, str(folder))
        assert compiled.compile_batch(quadratic()) is not None
        solver, _ = solve("rosenbrock", background=False)
        foreign = build_tiny("foreign")
    (batch,) = folder.glob("quadratic_test_*")
    return {"batch": batch, "nlp": solver.library, "foreign": foreign.parent}


def run_child(kind: str, cache: Path) -> subprocess.CompletedProcess:
    environment = {**os.environ, library_cache.CACHE_ENV: str(cache)}
    return subprocess.run(
        [sys.executable, "-c", CHILD, kind, str(TESTS)],
        env=environment,
        capture_output=True,
        text=True,
        timeout=120,
    )


def library_of(entry: Path) -> Path:
    (library,) = entry.glob("*.so")
    return library


def damage(how: str, entry: Path, foreign: Path) -> None:
    """Damage the cache's ``entry`` (a copy no process has loaded) as ``how`` says."""
    library = library_of(entry)
    if how == "half":
        os.truncate(library, library.stat().st_size // 2)
    elif how == "empty":
        os.truncate(library, 0)
    elif how == "random bytes":
        library.write_bytes(os.urandom(library.stat().st_size))
    elif how == "another library":
        shutil.copyfile(library_of(foreign), library)
    elif how == "another entry":
        shutil.rmtree(entry)
        shutil.copytree(foreign, entry)
    elif how == "forged record":  # another library, its record claiming our symbols
        record = json.loads((entry / library_cache.MANIFEST).read_text())
        data = library_of(foreign).read_bytes()
        digest = hashlib.sha256(data).hexdigest()
        library.unlink()
        (entry / f"{digest[:16]}.so").write_bytes(data)
        record.update(library=f"{digest[:16]}.so", size=len(data), sha256=digest)
        (entry / library_cache.MANIFEST).write_text(json.dumps(record))
    elif how == "no record":
        (entry / library_cache.MANIFEST).unlink()
    elif how == "unreadable record":
        (entry / library_cache.MANIFEST).write_bytes(os.urandom(100))
    elif how == "killed build":  # the entry never published; the dead build's folder
        dead = entry.with_name(".build-dead")
        (dead / "tmp").mkdir(parents=True)
        data = library.read_bytes()
        (dead / "library.so").write_bytes(data[: len(data) // 2])
        (dead / f"{entry.name}.c").write_text("/* half of the C */\n")
        (dead / "tmp" / "ccdead.s").write_text("\t.file\n")
        shutil.rmtree(entry)
    else:
        raise ValueError(how)


DAMAGE = {
    "half": "is damaged (its library has",
    "empty": "is damaged (its library has 0 B",
    "random bytes": "is damaged (its library's SHA-256 is not its record's)",
    "another library": "is damaged (its library has",
    "another entry": "is another library (without",
    "forged record": "is damaged (its library does not export",
    "no record": "has no record",
    "unreadable record": "has an unreadable record",
    "killed build": None,
}
"""Each damage and the warning it gives (None: no warning)."""


@pytest.mark.parametrize("how", list(DAMAGE))
@pytest.mark.parametrize("kind", ["batch", "nlp"])
def test_damaged_entry_is_rebuilt_and_used_with_one_warning_line(cache, pristine, kind, how):
    entry = cache / pristine[kind].name
    shutil.copytree(pristine[kind], entry)  # new files: this process has none of them mapped
    damage(how, entry, pristine["foreign"])
    child = run_child(kind, cache)
    assert child.returncode == 0, child.stderr  # a SIGBUS is -7
    assert child.stdout.split() == ["compiled"], child.stderr
    warnings = child.stderr.splitlines()
    if DAMAGE[how] is None:
        assert warnings == []
    else:
        (line,) = warnings
        assert line.startswith(f"WARNING: {entry.name} in the cache {DAMAGE[how]}"), line
        assert line.endswith(": removed, to be built again"), line
    assert library_cache.find(entry.name, []) == library_of(entry)
    assert sorted(p.name for p in entry.iterdir()) == sorted(
        p.name for p in pristine[kind].iterdir()
    )  # the same library as before the damage, and its record
    assert not list(cache.glob(".build-*"))


@pytest.mark.slow
def test_truncated_torque_library_in_the_command_line(tmp_path):
    """The fault found on the command line: the evaluator's torque library cut to half its
    size crashed every later run (SIGBUS)."""
    environment = {**os.environ, library_cache.CACHE_ENV: str(tmp_path / "cache")}
    plan = tmp_path / "plan.csv"
    problem = str(ROOT / "problems" / "craniotomy_bone_flap.toml")

    def cli(*argv: str) -> subprocess.CompletedProcess:
        command = [sys.executable, "-m", "spm_opt.cli", *argv]
        return subprocess.run(command, env=environment, capture_output=True, text=True, timeout=120)

    assert cli("plan", problem, "--planner", "cubic", "--out", str(plan)).returncode == 0
    first = cli("evaluate", problem, str(plan))  # builds the torque library
    assert "warning" not in first.stderr
    (library,) = (tmp_path / "cache").glob("torque_*/*.so")
    size = library.stat().st_size
    os.truncate(library, size // 2)
    again = cli("evaluate", problem, str(plan))
    assert again.returncode == first.returncode and again.stdout == first.stdout
    assert again.stderr.splitlines() == [
        f"spm-opt: warning: {library.parent.name} in the cache is damaged (its library has "
        f"{size // 2} B, its record {size} B): removed, to be built again",
        *first.stderr.splitlines(),  # the cubic plan's violations
    ]
    assert library.stat().st_size == size  # built again


def compilers_of(cache: Path) -> list[str]:
    """The command lines of the processes working in ``cache`` (the guard, the compiler's
    driver, cc1, as, ld)."""
    found = []
    for process in Path("/proc").iterdir():
        try:
            command = (process / "cmdline").read_bytes().replace(b"\0", b" ").decode()
        except (OSError, ValueError):
            continue
        if str(cache) in command and process.name.isdigit():
            found.append(command)
    return found


def wait_until(condition, seconds: float) -> bool:
    deadline = time.monotonic() + seconds
    while not condition():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.01)
    return True


BUILDER = """
import shutil, sys, threading
from spm_opt.model import library_cache
arguments = ("slow", open(sys.argv[1]).read(), shutil.which("cc"), [("-O1", "-fPIC", "-shared")],
             ["slow"])
if sys.argv[2] == "thread":
    threading.Thread(target=library_cache.build, args=arguments).start()
else:
    library_cache.build(*arguments)
"""


@pytest.mark.skipif(not Path("/proc/self/cmdline").exists(), reason="needs /proc")
@pytest.mark.real_time
@pytest.mark.parametrize(
    "where, stop", [("main", signal.SIGKILL), ("thread", signal.SIGKILL), ("main", signal.SIGINT)]
)
def test_a_stopped_build_leaves_no_compiler_and_the_next_process_cleans_up(
    cache, tmp_path, where, stop
):
    source = tmp_path / "slow.c"
    source.write_text(SLOW_C)
    system_temporary = tmp_path / "system-tmp"
    system_temporary.mkdir()
    environment = {
        **os.environ,
        library_cache.CACHE_ENV: str(cache),
        "TMPDIR": str(system_temporary),
    }
    builder = subprocess.Popen(
        [sys.executable, "-c", BUILDER, str(source), where],
        env=environment,
        stderr=subprocess.DEVNULL,
    )
    try:
        assert wait_until(lambda: any("cc1 " in c for c in compilers_of(cache)), 60)
        assert len(list(cache.glob(".build-*/tmp"))) == 1
        builder.send_signal(stop)
        builder.wait(timeout=30)
    finally:
        builder.kill()
    assert wait_until(lambda: not compilers_of(cache), 5), compilers_of(cache)
    assert not list(system_temporary.iterdir())  # the C and the compiler's files: in the cache
    assert library_cache.entries() == []  # this process's first use cleans up
    assert not list(cache.glob(".build-*"))


def test_verified_once_per_process_and_file(cache, monkeypatch):
    library = build_tiny("once")
    hashed = []
    sha256 = library_cache._sha256
    monkeypatch.setattr(library_cache, "_sha256", lambda path: hashed.append(path) or sha256(path))
    assert library_cache.find("once", ["once"]) == library  # verified when built
    assert hashed == []
    copy = library.with_name("copy")  # the same bytes in a new file (a new inode)
    shutil.copyfile(library, copy)
    copy.rename(library)
    assert library_cache.find("once", ["once"]) == library
    assert library_cache.find("once", ["once"]) == library
    assert hashed == [library]


def test_least_recently_used_entries_go_when_the_cache_outgrows_its_bound(cache, monkeypatch):
    names = ["lru_a", "lru_b", "lru_c"]
    for name in names:
        build_tiny(name)
    size = library_cache.entries()[0].size
    assert {entry.size for entry in library_cache.entries()} == {size}
    now = time.time()
    for age, name in zip([30, 20, 10], names, strict=True):
        os.utime(cache / name, (now - age, now - age))
    assert [entry.name for entry in library_cache.entries()] == names
    assert library_cache.find("lru_a", ["lru_a"]) is not None  # a use: lru_b is now the oldest
    monkeypatch.setenv(library_cache.SIZE_ENV, str(3.5 * size / 1e6))
    build_tiny("lru_d")
    assert [entry.name for entry in library_cache.entries()] == ["lru_c", "lru_a", "lru_d"]
    monkeypatch.setenv(library_cache.SIZE_ENV, "0")
    build_tiny("lru_e")  # the newest stays, whatever the bound
    assert [entry.name for entry in library_cache.entries()] == ["lru_e"]
    assert not list(cache.glob(".build-*"))


def test_size_bound_from_the_environment(monkeypatch):
    monkeypatch.delenv(library_cache.SIZE_ENV, raising=False)
    assert library_cache.size_bound() == library_cache.DEFAULT_SIZE_MB * 10**6
    monkeypatch.setenv(library_cache.SIZE_ENV, "1.5")
    assert library_cache.size_bound() == 1_500_000
    for wrong in ["abc", "-1", "nan", "inf"]:
        monkeypatch.setenv(library_cache.SIZE_ENV, wrong)
        with pytest.raises(ValueError, match=f"SPM_OPT_CACHE_MB = '{wrong}': expected"):
            library_cache.size_bound()


def test_a_wrong_bound_prunes_nothing_and_says_so_once(cache, monkeypatch, caplog):
    monkeypatch.setenv(library_cache.SIZE_ENV, "lots")
    with caplog.at_level(logging.WARNING):
        build_tiny("unbounded")
    (message,) = [record.getMessage() for record in caplog.records]
    assert message.startswith("the cache is not pruned: SPM_OPT_CACHE_MB = 'lots'")
    assert [entry.name for entry in library_cache.entries()] == ["unbounded"]


def test_cache_directory_comes_from_the_environment(cache, monkeypatch):
    assert library_cache.cache_directory() == cache
    monkeypatch.delenv(library_cache.CACHE_ENV)
    assert library_cache.cache_directory() == Path.home() / ".cache" / "spm_opt"


def test_cache_info_and_clear(cache, capsys, monkeypatch):
    monkeypatch.delenv(library_cache.SIZE_ENV, raising=False)
    build_tiny("info_a")
    build_tiny("info_b")
    dead = cache / ".build-dead"
    dead.mkdir()
    with library_cache._workspace(cache) as live:
        status, shown = run_cli(["cache", "info"])
        out = capsys.readouterr().out.splitlines()
        assert status == 0 and not shown
        size = sum(entry.size for entry in library_cache.entries()) / 1e6
        assert out[:3] == [
            f"folder   {cache}",
            f"entries  2, {size:.2f} MB; builds in progress: 1",
            "bound    256 MB ($SPM_OPT_CACHE_MB); least recently used go first",
        ]
        assert [line.split()[0] for line in out[3:]] == ["info_b", "info_a"]
        assert run_cli(["cache", "clear"])[0] == 0
        assert capsys.readouterr().out == f"{cache}: entries removed: 2, {size:.2f} MB\n"
        assert library_cache.entries() == []
        assert live.exists() and not dead.exists()
    monkeypatch.setenv(library_cache.SIZE_ENV, "much")
    status, shown = run_cli(["cache", "info"])
    assert_one_error(status, capsys.readouterr().err, ("SPM_OPT_CACHE_MB = 'much'",), cache, shown)
    status, shown = run_cli(["cache"])
    assert_one_error(status, capsys.readouterr().err, ("required: action",), cache, shown)


FULL_DISK = """
import logging, sys
sys.path.insert(0, sys.argv[1])
logging.basicConfig(format="%(levelname)s: %(message)s")
from test_compiled import quadratic
from test_nlp_library import solve
from spm_opt.model.compiled import compile_batch
from spm_opt.planners.ocp import nlp_library
print(compile_batch(quadratic()) is None, solve("rosenbrock")[0].kind)
nlp_library.wait_for_builds()
"""


@pytest.mark.skipif(shutil.which("unshare") is None, reason="needs unshare")
def test_a_full_disk_is_one_warning_line_per_library(tmp_path):
    """A cache on a full file system (a 16 KiB tmpfs in a mount namespace of its own): each
    build, the background one too, says in one line that it failed, and why."""
    cache = tmp_path / "cache"
    cache.mkdir()
    child_script = tmp_path / "child.py"
    child_script.write_text(FULL_DISK)
    mount = f"mount -t tmpfs -o size=16k tmpfs {cache}"
    script = f"{mount} && {sys.executable} {child_script} {TESTS}"
    environment = {**os.environ, library_cache.CACHE_ENV: str(cache)}
    if subprocess.run(["unshare", "-m", "true"], capture_output=True).returncode != 0:
        pytest.skip("cannot make a mount namespace here (not root?)")
    child = subprocess.run(
        ["unshare", "-m", "sh", "-c", script],
        env=environment,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert child.returncode == 0, child.stderr
    assert child.stdout.split() == ["True", "interpreted"]
    batch, nlp = child.stderr.splitlines()
    assert batch.startswith("WARNING: quadratic_test runs in CasADi's interpreter: quadratic_")
    assert nlp.startswith("WARNING: the NLP stays interpreted: nlp_")
    for line in (batch, nlp):
        assert "not built" in line and "No space left on device" in line
