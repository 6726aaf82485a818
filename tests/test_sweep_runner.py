"""The sweep runner: the same rows in this process, on a process pool and on a real Dask
cluster on loopback; resuming after ``kill -9``; failures as rows; bad options refused."""

from __future__ import annotations

import fcntl
import json
import math
import os
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from concurrent.futures import Future
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path
from typing import Any

import pytest
import sweep_helpers
from sweep_helpers import (
    fails_by_kind,
    fails_on_three,
    grid_tasks,
    kills_on_three,
    returns_a_set,
    returns_text,
    square,
    thread_settings,
)

from spm_opt.base.errors import InputError, PlanningError
from spm_opt.studies.sweep import dask_cluster
from spm_opt.studies.sweep.pool import THREAD_VARIABLES, threads_per_worker
from spm_opt.studies.sweep.results import load_sweep, write_sweep_report
from spm_opt.studies.sweep.runner import SweepSummary, run_sweep
from spm_opt.studies.sweep.spec import load_sweep_spec
from spm_opt.studies.sweep.task import failure_kind

ROOT = Path(__file__).resolve().parents[1]
TIMING = {"worker", "finished_at", "wall_time_s", "solve_time_s"}
PROC = Path("/proc/self/stat").exists()


@pytest.fixture(scope="module")
def cluster() -> Iterator[Any]:
    """A Dask cluster on loopback: two worker processes of one thread; a task may kill its
    worker once (then it is a KilledWorker)."""
    distributed = pytest.importorskip("distributed")
    import dask

    with dask.config.set({"distributed.scheduler.allowed-failures": 1}):
        with distributed.LocalCluster(
            n_workers=2,
            threads_per_worker=1,
            processes=True,
            host="127.0.0.1",
            dashboard_address=None,
        ) as local:
            yield local


def read_rows(out: Path) -> list[dict[str, Any]]:
    """The results file's rows, refusing anything that is not standard JSON lines."""
    text = (out / "results.jsonl").read_text()
    assert text == "" or text.endswith("\n")

    def refuse(constant: str) -> None:
        raise AssertionError(f"non-standard JSON constant {constant}")

    return [json.loads(line, parse_constant=refuse) for line in text.splitlines()]


def by_key(rows: list[dict[str, Any]], ignore: set[str] = TIMING) -> dict[str, dict[str, Any]]:
    keyed = {row["key"]: {k: v for k, v in row.items() if k not in ignore} for row in rows}
    assert len(keyed) == len(rows), "a key written twice"
    return keyed


@pytest.mark.slow
def test_in_process_pool_and_dask_give_the_same_rows(tmp_path: Path, cluster: Any) -> None:
    tasks = grid_tasks(6, sleep=0.1)
    runs = {
        "in process": {"workers": 1},
        "pool": {"workers": 2},
        "dask": {"scheduler": cluster.scheduler_address},
    }
    rows = {}
    for name, options in runs.items():
        summary = run_sweep(tasks, tmp_path / name, progress=False, task_function=square, **options)
        assert (summary.total, summary.skipped, summary.done, summary.failed) == (6, 0, 6, 0)
        rows[name] = read_rows(tmp_path / name)
    assert by_key(rows["pool"]) == by_key(rows["in process"]) == by_key(rows["dask"])
    first = rows["in process"][0]
    assert list(first)[:4] == ["key", "sweep", "planner", "parameters"]
    assert first["odd"] == 0.0 and rows["in process"][1]["odd"] is None  # NaN is null
    assert rows["in process"][2]["big"] is None  # and so is infinity
    host = socket.gethostname()
    assert {row["worker"] for row in rows["in process"]} == {f"{host}:{os.getpid()}"}
    pool_pids = {row["worker"] for row in rows["pool"]}
    dask_pids = {row["worker"] for row in rows["dask"]}
    assert len(pool_pids) == 2 and f"{host}:{os.getpid()}" not in pool_pids
    assert len(dask_pids) == 2 and not dask_pids & pool_pids
    for row in rows["pool"]:
        assert row["finished_at"].endswith("+00:00")


@pytest.mark.slow
def test_real_tasks_cubic_pool_and_dask_give_the_same_rows(tmp_path: Path, cluster: Any) -> None:
    spec_file = tmp_path / "tiny.toml"
    spec_file.write_text(
        'name = "tiny"\n'
        f'problem = "{ROOT / "problems" / "craniotomy_bone_flap.toml"}"\n'
        'planners = ["cubic"]\n'
        "[grid]\n"
        '"limits.max_tool_speed_mm_s" = [2.0, 3.0]\n'
        '"robot.friction.mu" = [0.04, 0.24]\n'
    )
    tasks = load_sweep_spec(spec_file).tasks()
    assert len(tasks) == 4
    run_sweep(tasks, tmp_path / "pool", workers=2, progress=False)
    run_sweep(tasks, tmp_path / "dask", scheduler=cluster.scheduler_address, progress=False)
    pool, on_dask = read_rows(tmp_path / "pool"), read_rows(tmp_path / "dask")
    assert by_key(pool) == by_key(on_dask)
    assert {row["key"] for row in pool} == {task.key for task in tasks}
    assert all(row["status"] != "failed" for row in pool), [row["error"] for row in pool]
    assert all(math.isfinite(row["duration_s"]) for row in pool)


def _start(command: list[str], cwd: Path, log: Path) -> subprocess.Popen[bytes]:
    with open(log, "wb") as output:
        return subprocess.Popen(
            command, cwd=cwd, stdout=output, stderr=subprocess.STDOUT, start_new_session=True
        )


def _address(scheduler_file: Path) -> str | None:
    """The address in a scheduler's file, None until it is written whole."""
    try:
        return json.loads(scheduler_file.read_text())["address"]
    except (FileNotFoundError, json.JSONDecodeError, KeyError):
        return None


def _bounded(call: Callable[[], Any], seconds: float) -> Any:
    """``call()`` in a thread of its own (a daemon: a hung one cannot hold the tests up);
    TimeoutError after ``seconds``."""
    future: Future[Any] = Future()

    def run() -> None:
        try:
            future.set_result(call())
        except BaseException as error:  # noqa: BLE001 - handed to the test
            future.set_exception(error)

    threading.Thread(target=run, daemon=True).start()
    return future.result(timeout=seconds)


@pytest.fixture
def separate_cluster(tmp_path: Path) -> Iterator[tuple[str, int]]:
    """A Dask scheduler and a worker (with its nanny), each started as ``dask`` on the
    command line on loopback, the worker in an empty directory; yields the scheduler's
    address and the worker's session id. Both are killed at the end (and end by themselves
    when idle or orphaned)."""
    distributed = pytest.importorskip("distributed")
    dask = [sys.executable, "-m", "dask"]
    scheduler_file, empty = tmp_path / "scheduler.json", tmp_path / "empty"
    empty.mkdir()
    processes = []
    try:
        scheduler = _start(
            [*dask, "scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard"]
            + ["--scheduler-file", str(scheduler_file), "--idle-timeout", "300s"],
            tmp_path,
            tmp_path / "scheduler.log",
        )
        processes.append(scheduler)
        deadline = time.monotonic() + 60
        while (address := _address(scheduler_file)) is None:
            log = (tmp_path / "scheduler.log").read_text()[-2000:]
            assert scheduler.poll() is None, f"the scheduler ended: {log}"
            assert time.monotonic() < deadline, "no scheduler within 60 s"
            time.sleep(0.1)
        worker = _start(
            [*dask, "worker", address, "--host", "127.0.0.1", "--nthreads", "1"]
            + ["--no-dashboard", "--local-directory", str(tmp_path / "dask-worker")]
            + ["--death-timeout", "30s"],  # orphans (the tests killed) end by themselves
            empty,
            tmp_path / "worker.log",
        )
        processes.append(worker)
        with distributed.Client(address, timeout=30, set_as_default=False) as client:
            client.wait_for_workers(1, timeout=60)
        yield address, worker.pid
    finally:
        for process in processes:
            if process.poll() is None:
                os.killpg(process.pid, signal.SIGKILL)
            process.wait(10)


def test_a_dask_worker_without_the_problem_files_runs_the_tasks(
    tmp_path: Path, separate_cluster: tuple[str, int]
) -> None:
    """The tasks carry their files: the worker, in an empty directory, never sees them
    (the problem's directory is renamed before the tasks run), and its rows are those of
    this process."""
    address, worker_session = separate_cluster
    copy = tmp_path / "problems"
    copy.mkdir()
    shutil.copy(ROOT / "problems" / "craniotomy_bone_flap.toml", copy)
    shutil.copytree(ROOT / "problems" / "robots", copy / "robots")
    spec_file = tmp_path / "tiny.toml"
    spec_file.write_text(
        'name = "tiny"\nproblem = "problems/craniotomy_bone_flap.toml"\nplanners = ["cubic"]\n'
        '[grid]\n"limits.max_tool_speed_mm_s" = [2.0, 3.0]\n"robot.payload.mass_kg" = [0.0, 0.5]\n'
    )
    tasks = load_sweep_spec(spec_file).tasks()
    assert len(tasks) == 4
    here = run_sweep(tasks, tmp_path / "here", progress=False)
    assert here.failed == 0
    copy.rename(tmp_path / "gone")

    there = tmp_path / "there"
    summary = _bounded(lambda: run_sweep(tasks, there, scheduler=address, progress=False), 120)
    rows = read_rows(there)
    assert (summary.done, summary.failed) == (4, 0), [row.get("error") for row in rows]
    assert by_key(rows) == by_key(read_rows(tmp_path / "here"))
    pids = {int(row["worker"].rsplit(":", 1)[1]) for row in rows}
    assert os.getpid() not in pids
    if PROC:
        assert pids <= set(living_processes(worker_session))


def test_a_second_run_resumes_and_leaves_other_rows_alone(tmp_path: Path) -> None:
    other = {"key": "someone-else0000", "planner": "cubic", "status": "ok"}
    tmp_path.joinpath("results.jsonl").write_text(json.dumps(other) + "\n")
    tasks = grid_tasks(6, sleep=0.0)
    first = run_sweep(tasks[:4], tmp_path, progress=False, task_function=square)
    again = run_sweep(tasks, tmp_path, progress=False, task_function=square)
    assert (first.skipped, first.done) == (0, 4)
    assert (again.total, again.skipped, again.done, again.failed) == (6, 4, 2, 0)
    rows = read_rows(tmp_path)
    assert rows[0] == other
    assert sorted(by_key(rows[1:])) == sorted(task.key for task in tasks)
    assert run_sweep(tasks, tmp_path, progress=False, task_function=square).skipped == 6
    assert len(read_rows(tmp_path)) == 7


def test_resume_runs_machine_failures_again_and_retry_failed_every_failure(
    tmp_path: Path,
) -> None:
    tasks = grid_tasks(5, sleep=0.0)
    first = run_sweep(tasks, tmp_path, progress=False, task_function=fails_by_kind)
    assert (first.done, first.failed) == (2, 3)
    failures = {row["parameters"]["x"]: row.get("failure") for row in read_rows(tmp_path)}
    assert failures == {0: None, 1: "machine", 2: "result", 3: "result", 4: None}

    again = run_sweep(tasks, tmp_path, progress=False, task_function=square)
    assert (again.skipped, again.retried, again.done, again.failed) == (4, 1, 1, 0)
    rows = read_rows(tmp_path)
    assert len(rows) == 6 and rows[-1]["key"] == tasks[1].key and rows[-1]["status"] != "failed"

    retry = run_sweep(tasks, tmp_path, progress=False, task_function=square, retry_failed=True)
    assert (retry.skipped, retry.retried, retry.done, retry.failed) == (3, 2, 2, 0)
    assert {row["key"] for row in read_rows(tmp_path)[6:]} == {tasks[2].key, tasks[3].key}
    assert run_sweep(tasks, tmp_path, progress=False, retry_failed=True).skipped == 5

    frame = load_sweep(tmp_path)  # 8 rows in the file, the newest of each key wins
    assert len(frame) == 5 and frame["key"].is_unique
    assert (frame["status"] != "failed").all() and (frame["failure"] == "").all()
    write_sweep_report(tmp_path, keys=[task.key for task in tasks])
    summary = (tmp_path / "summary.md").read_text()
    assert "- tasks: 5 (4 ok, 1 with violations, 0 failed)" in summary
    assert "stale" not in summary


def test_failures_of_the_machine_are_told_from_results() -> None:
    distributed = pytest.importorskip("distributed")
    from distributed.comm.core import CommClosedError

    machine = [
        TimeoutError("30 s"),
        ConnectionResetError("peer"),
        MemoryError(),
        BrokenProcessPool("died"),
        distributed.scheduler.KilledWorker("task", "worker", 1),
        CommClosedError("lost"),
    ]
    results = [PlanningError("infeasible"), InputError("x = 3"), ZeroDivisionError("bug")]
    assert [failure_kind(error) for error in machine] == ["machine"] * len(machine)
    assert [failure_kind(error) for error in results] == ["result"] * len(results)


def test_a_torn_last_line_is_cut_before_appending(tmp_path: Path) -> None:
    tasks = grid_tasks(4, sleep=0.0)
    run_sweep(tasks[:2], tmp_path, progress=False, task_function=square)
    with open(tmp_path / "results.jsonl", "a") as results:
        results.write('{"key": "' + tasks[2].key + '", "sweep": "stand-in", "stat')
    summary = run_sweep(tasks, tmp_path, progress=False, task_function=square)
    assert (summary.skipped, summary.done) == (2, 2)
    assert sorted(by_key(read_rows(tmp_path))) == sorted(task.key for task in tasks)


def living_processes(session: int) -> list[int]:
    """The processes of a session that are not zombies (Linux's /proc; none without)."""
    found = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except (OSError, IndexError):
            continue
        if int(fields[3]) == session and fields[0] != "Z":
            found.append(int(stat.parent.name))
    return found


@pytest.mark.slow
def test_kill_9_then_run_again_gives_every_task_once(tmp_path: Path) -> None:
    count = 16
    command = [sys.executable, "-c", "import sweep_helpers; sweep_helpers.main()"]
    command += [str(tmp_path), str(count), "2"]
    environment = {**os.environ, "PYTHONPATH": str(Path(sweep_helpers.__file__).parent)}
    results = tmp_path / "results.jsonl"
    process = subprocess.Popen(command, env=environment, start_new_session=True)
    try:
        deadline = time.monotonic() + 30
        while not (results.exists() and results.read_text().count("\n") >= 3):
            assert process.poll() is None, "the runner ended before it was killed"
            assert time.monotonic() < deadline, "no rows within 30 s"
            time.sleep(0.02)
        if PROC:
            assert len(living_processes(process.pid)) >= 3  # runner, fork server, workers
        process.send_signal(signal.SIGKILL)
        assert process.wait(10) == -signal.SIGKILL
        deadline = time.monotonic() + 10
        while living_processes(process.pid):  # the workers end with the runner
            assert time.monotonic() < deadline, "orphaned workers outlive the runner"
            time.sleep(0.05)
    finally:
        if living_processes(process.pid):
            os.killpg(process.pid, signal.SIGKILL)
    written = len(read_rows(tmp_path))
    assert 3 <= written < count
    subprocess.run(command, env=environment, check=True, timeout=60)
    assert sorted(by_key(read_rows(tmp_path))) == sorted(t.key for t in grid_tasks(count))


def test_pool_workers_share_the_cpus_among_their_threads(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    for name in THREAD_VARIABLES:
        monkeypatch.delenv(name, raising=False)
    tasks = grid_tasks(4, sleep=0.0)
    run_sweep(tasks, tmp_path, workers=2, progress=False, task_function=thread_settings)
    share = threads_per_worker(2)
    assert [
        (row["OMP_NUM_THREADS"], row["OPENBLAS_NUM_THREADS"], row["blas_threads"])
        for row in read_rows(tmp_path)
    ] == [(str(share), str(share), [share])] * 4
    assert threads_per_worker(10**6) == 1


@pytest.mark.parametrize("workers", [1, 2])
def test_a_task_that_raises_is_a_failed_row(tmp_path: Path, workers: int) -> None:
    tasks = grid_tasks(5, sleep=0.0)
    summary = run_sweep(
        tasks, tmp_path, workers=workers, progress=False, task_function=fails_on_three
    )
    assert (summary.done, summary.failed) == (4, 1)
    rows = by_key(read_rows(tmp_path))
    failed = rows[tasks[3].key]
    assert failed["status"] == "failed" and failed["parameters"] == {"x": 3, "sleep": 0.0}
    assert failed["error"] == "ZeroDivisionError: x = 3 is not allowed"
    assert failed["failure"] == "result"  # a bug: the same again on resume
    assert "fails_on_three" in failed["traceback"]
    assert all(row["status"] != "failed" for key, row in rows.items() if key != tasks[3].key)


def test_a_task_function_that_returns_no_row_gives_failed_rows(tmp_path: Path) -> None:
    tasks = grid_tasks(2, sleep=0.0)
    summary = run_sweep(tasks, tmp_path, progress=False, task_function=returns_text)
    assert summary.failed == 2
    assert (
        read_rows(tmp_path)[0]["error"] == "TypeError: the task function returned a str, not a row"
    )
    summary = run_sweep(tasks, tmp_path / "set", progress=False, task_function=returns_a_set)
    assert summary.failed == 2
    row = read_rows(tmp_path / "set")[0]
    assert row["error"] == "the row is not JSON (Object of type set is not JSON serializable)"
    assert row["failure"] == "result"
    assert set(row) == {
        "key",
        "sweep",
        "planner",
        "parameters",
        "status",
        "error",
        "failure",
    } | TIMING - {
        "wall_time_s",
        "solve_time_s",
    }


def test_a_worker_killed_on_the_pool_fails_its_task_only(tmp_path: Path) -> None:
    tasks = grid_tasks(8, sleep=0.1)
    summary = run_sweep(tasks, tmp_path, workers=2, progress=False, task_function=kills_on_three)
    assert (summary.done, summary.failed) == (7, 1)
    rows = by_key(read_rows(tmp_path))
    assert sorted(rows) == sorted(task.key for task in tasks)
    killed = rows[tasks[3].key]
    assert killed["status"] == "failed"
    assert killed["error"].startswith("BrokenProcessPool: ")
    assert killed["error"].endswith("(the worker died running this task alone)")
    assert killed["failure"] == "machine"


def test_a_worker_killed_on_dask_is_a_failed_row(tmp_path: Path, cluster: Any) -> None:
    tasks = grid_tasks(4, sleep=0.0)[3:]
    summary = run_sweep(
        tasks,
        tmp_path,
        scheduler=cluster.scheduler_address,
        progress=False,
        task_function=kills_on_three,
    )
    assert summary.failed == 1
    [row] = read_rows(tmp_path)
    assert row["status"] == "failed" and row["error"].startswith("KilledWorker: ")
    assert row["failure"] == "machine"


@pytest.mark.slow
def test_a_local_dask_cluster_on_request(tmp_path: Path) -> None:
    pytest.importorskip("distributed")
    summary = run_sweep(
        grid_tasks(3, sleep=0.0),
        tmp_path,
        scheduler="local",
        workers=2,
        progress=False,
        task_function=square,
    )
    assert (summary.done, summary.failed) == (3, 0)
    assert len({row["worker"] for row in read_rows(tmp_path)}) >= 1


def test_the_progress_bar_counts_on_stderr(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    run_sweep(grid_tasks(3, sleep=0.0), tmp_path, task_function=fails_on_three)
    run_sweep(grid_tasks(5, sleep=0.0), tmp_path, task_function=fails_on_three)
    captured = capsys.readouterr()
    assert captured.out == ""
    assert "5/5" in captured.err and "done=1, failed=1, remaining=0" in captured.err


@pytest.mark.parametrize(
    ("options", "named"),
    [
        ({"workers": 0}, "--workers 0"),
        ({"workers": 1.5}, "--workers 1.5"),
        ({"workers": True}, "--workers True"),
        ({"scheduler": "tcp://somewhere"}, "--scheduler 'tcp://somewhere'"),
        ({"scheduler": "http://host:8786"}, "--scheduler 'http://host:8786'"),
        ({"scheduler": "tcp://host:99999"}, "--scheduler 'tcp://host:99999'"),
        ({"scheduler": "cluster"}, "--scheduler 'cluster'"),
    ],
)
def test_bad_options_are_one_line_errors(
    tmp_path: Path, options: dict[str, Any], named: str
) -> None:
    with pytest.raises(InputError) as error:
        run_sweep(grid_tasks(1), tmp_path, progress=False, task_function=square, **options)
    assert str(error.value).startswith(named) and "\n" not in str(error.value)
    assert not tmp_path.joinpath("results.jsonl").exists()


def test_an_unreachable_scheduler_is_an_input_error(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    with socket.socket() as unused:
        unused.bind(("127.0.0.1", 0))
        address = f"tcp://127.0.0.1:{unused.getsockname()[1]}"
    monkeypatch.setattr(dask_cluster, "CONNECT_TIMEOUT_S", 0.5)
    with pytest.raises(InputError, match=f"^--scheduler {address}: cannot connect") as error:
        run_sweep(grid_tasks(1), tmp_path, scheduler=address, progress=False, task_function=square)
    assert "\n" not in str(error.value)


def test_two_tasks_with_one_key_are_refused(tmp_path: Path) -> None:
    tasks = grid_tasks(2)
    with pytest.raises(InputError, match=f"^tasks: key {tasks[0].key} appears twice"):
        run_sweep([*tasks, tasks[0]], tmp_path, progress=False, task_function=square)


def test_a_sweep_already_writing_the_directory_is_refused(tmp_path: Path) -> None:
    with open(tmp_path / "results.jsonl", "a") as held:
        fcntl.flock(held, fcntl.LOCK_EX)
        with pytest.raises(InputError, match="being written by another sweep"):
            run_sweep(grid_tasks(1), tmp_path, progress=False, task_function=square)


def test_a_task_function_that_cannot_be_pickled_is_refused_for_the_pool(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="^task function .* cannot be sent to worker processes"):
        run_sweep(grid_tasks(1), tmp_path, workers=2, progress=False, task_function=lambda t: {})


def test_nothing_to_do_starts_nothing(tmp_path: Path) -> None:
    summary = run_sweep([], tmp_path, workers=2, progress=False, task_function=square)
    assert summary == SweepSummary(0, 0, 0, 0, 0, summary.seconds)
    assert read_rows(tmp_path) == []
