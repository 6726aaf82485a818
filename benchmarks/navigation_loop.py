"""The control loop with the navigation link on: period error without the link, with the
link and no client, with clients attached (one that reads everything, as 3D Slicer does;
one that never reads; one that floods the server), and what a reading client gets: the
tool pose's rate and its latency from the cycle that read the joints to its arrival.

Each client is a process of its own, as 3D Slicer would be. Each condition runs the same
plan (12 mm along the skull problem's contour, about 4 s of toppra) on the simulated robot
on the wall clock at 100 Hz, ``--repeats`` times, interleaved. The reference is the run
without the link, measured in the same run. Prints a table and writes
benchmarks/results/navigation_loop.json.

    python benchmarks/navigation_loop.py [--repeats 10]
"""

from __future__ import annotations

import argparse
import multiprocessing
import socket
import struct
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from timing import ROOT, write_results

import spm_opt as so
from spm_opt.execution import ExecutionSettings, Executor, SimulatedRobot
from spm_opt.execution.log import read_log
from spm_opt.navigation.link import NavigationLink

PROBLEM = ROOT / "problems" / "skull_flap.toml"
CONDITIONS = (
    "no link (reference)",
    "link, no client",
    "one client reading",
    "four clients reading",
    "a client that never reads",
    "a client flooding POINT bodies",
)


def _exactly(sock: socket.socket, size: int) -> bytes | None:
    data = b""
    while len(data) < size:
        try:
            chunk = sock.recv(size - len(data))
        except OSError:
            return None
        if not chunk:
            return None
        data += chunk
    return data


def read_client(port: int, poses: multiprocessing.Queue) -> None:
    """A client process that reads every message until the server closes; puts the arrival
    time (perf_counter: CLOCK_MONOTONIC, the simulated robot's clock) and log time of each
    ToolToRAS on ``poses``."""
    arrivals = []
    with socket.create_connection(("127.0.0.1", port)) as sock:
        while (header := _exactly(sock, 58)) is not None:
            kind, device = header[2:14].rstrip(b"\0"), header[14:34].rstrip(b"\0")
            seconds, fraction, size = struct.unpack(">IIQ", header[34:50])
            if _exactly(sock, size) is None:
                break
            if kind == b"TRANSFORM" and device == b"ToolToRAS":
                arrivals.append((time.perf_counter(), seconds + fraction / 2**32))
    poses.put(arrivals)


def idle_client(port: int, poses: multiprocessing.Queue) -> None:
    """A client process that connects and never reads."""
    with socket.create_connection(("127.0.0.1", port)):
        time.sleep(3600)


def flood_client(port: int, poses: multiprocessing.Queue) -> None:
    """A client process that sends POINT bodies at the server's bound, each with a wrong
    CRC, as fast as TCP takes them."""
    body = b"\0" * (136 * 722)
    frame = struct.pack(">H12s20sIIQQ", 1, b"POINT", b"Flap", 0, 0, len(body), 1) + body
    with socket.create_connection(("127.0.0.1", port)) as sock:
        while True:
            sock.sendall(frame)


CLIENTS = {
    "link, no client": [],
    "one client reading": [read_client],
    "four clients reading": [read_client] * 4,
    "a client that never reads": [idle_client],
    "a client flooding POINT bodies": [flood_client],
}


def run_once(problem, plan, condition: str, log: Path) -> dict:
    backend = SimulatedRobot(problem.robot, start_rad=plan.position(plan.start_time), realtime=True)
    executor = Executor(problem, backend, ExecutionSettings())
    if condition == CONDITIONS[0]:
        result = executor.run(plan, log)
        return {"statistics": result.statistics}
    poses: multiprocessing.Queue = multiprocessing.Queue()
    with NavigationLink(problem, plan, executor, port=0) as link:
        clients = [
            (target, multiprocessing.Process(target=target, args=(link.server.port, poses)))
            for target in CLIENTS[condition]
        ]
        for _, process in clients:
            process.start()
        deadline = time.monotonic() + 10.0
        while link.server.clients < len(clients) and time.monotonic() < deadline:
            time.sleep(0.01)
        time.sleep(0.3)  # the clients got the models
        result = executor.run(plan, log)
        for target, process in clients:
            if target is not read_client:
                process.kill()
    # the link closed: the readers' streams ended and each reports its arrivals
    readers = sum(target is read_client for target, _ in clients)
    arrivals = [pose for _ in range(readers) for pose in poses.get(timeout=30)]
    for _, process in clients:
        process.join(timeout=5)
    origin = read_log(log)[1]["clock_origin_s"]  # the log's time 0 on the loop's clock
    latencies = [arrived - (origin + stamp) for arrived, stamp in arrivals]
    stamps = sorted({stamp for _, stamp in arrivals})
    rate = (len(stamps) - 1) / (stamps[-1] - stamps[0]) if len(stamps) > 1 else float("nan")
    return {"statistics": result.statistics, "latencies": latencies, "rate_hz": rate}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5, help="runs of each condition")
    args = parser.parse_args()
    problem = so.load_problem(PROBLEM).along_contour([0.0, 6.0, 12.0], [2.0, 2.0], "short")
    plan = so.plan(problem, planner="toppra")
    runs: dict[str, list[dict]] = {c: [] for c in CONDITIONS}
    with tempfile.TemporaryDirectory() as scratch:
        for repeat in range(args.repeats):
            for condition in CONDITIONS:
                print(f"run {repeat + 1}/{args.repeats}: {condition} ...", file=sys.stderr)
                log = Path(scratch) / f"run_{repeat}_{CONDITIONS.index(condition)}.csv"
                runs[condition].append(run_once(problem, plan, condition, log))
    rows = []
    for condition, results in runs.items():
        p99 = [r["statistics"].period_error_p99_ms for r in results]
        worst = [r["statistics"].period_error_max_ms for r in results]
        latencies = np.concatenate([r.get("latencies", []) for r in results] + [[]])
        rates = [r["rate_hz"] for r in results if np.isfinite(r.get("rate_hz", np.nan))]
        rows.append(
            {
                "condition": condition,
                "runs": len(results),
                "period_error_p99_ms_median": float(np.median(p99)),
                "period_error_p99_ms_worst": float(np.max(p99)),
                "period_error_max_ms_worst": float(np.max(worst)),
                "overruns": int(sum(r["statistics"].overruns for r in results)),
                "pose_rate_hz_median": float(np.median(rates)) if rates else None,
                "latency_ms_p50": float(np.percentile(latencies, 50) * 1e3)
                if latencies.size
                else None,
                "latency_ms_p99": float(np.percentile(latencies, 99) * 1e3)
                if latencies.size
                else None,
            }
        )
    reference = rows[0]["period_error_p99_ms_median"]
    print(
        f"{'condition':34s} {'p99 ms':>7s} {'×ref':>6s} {'worst p99':>9s} {'max ms':>7s} "
        f"{'overruns':>8s} {'pose Hz':>8s} {'lat p50':>8s} {'lat p99':>8s}"
    )
    for r in rows:
        rate = "-" if r["pose_rate_hz_median"] is None else f"{r['pose_rate_hz_median']:.1f}"
        p50 = "-" if r["latency_ms_p50"] is None else f"{r['latency_ms_p50']:.2f}"
        p99 = "-" if r["latency_ms_p99"] is None else f"{r['latency_ms_p99']:.2f}"
        print(
            f"{r['condition']:34s} {r['period_error_p99_ms_median']:7.3f} "
            f"{r['period_error_p99_ms_median'] / reference:6.2f} "
            f"{r['period_error_p99_ms_worst']:9.3f} {r['period_error_max_ms_worst']:7.3f} "
            f"{r['overruns']:8d} {rate:>8s} {p50:>8s} {p99:>8s}"
        )
    print(
        "(p99: the median over the runs of each run's p99 period error; ×ref: against the "
        "run without the link, in the same run; latency: the cycle that read the joints to "
        "the pose's arrival at the client)"
    )
    write_results("navigation_loop", {"plan_s": plan.duration, "rate_hz": 100.0, "results": rows})
    return 0


if __name__ == "__main__":
    sys.exit(main())
