"""The control loop with the navigation link on: period error without the link, with the
link and no client, with clients attached (one that reads everything, as 3D Slicer does;
one that never reads; one that floods the server), and what a reading client gets: the
tool pose's rate and its latency from the cycle that read the joints to its arrival.

Each condition runs the same plan (a 12 mm flap on the skull problem, about 4 s of
toppra) on the simulated robot on the wall clock at 100 Hz, ``--repeats`` times,
interleaved. The reference is the run without the link, measured in the same run. Prints a
table and writes benchmarks/results/navigation_loop.json.

    python benchmarks/navigation_loop.py [--repeats 5]
"""

from __future__ import annotations

import argparse
import socket
import struct
import sys
import tempfile
import threading
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


class Reader:
    """Reads every message; keeps the arrival time (perf_counter, the simulated robot's
    clock) and log time of each ToolToRAS."""

    def __init__(self, port: int, read: bool = True) -> None:
        self.sock = socket.create_connection(("127.0.0.1", port))
        self.poses: list[tuple[float, float]] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._read if read else self._idle, daemon=True)
        self._thread.start()

    def _exactly(self, size: int) -> bytes | None:
        data = b""
        while len(data) < size and not self._stop.is_set():
            try:
                chunk = self.sock.recv(size - len(data))
            except OSError:
                return None
            if not chunk:
                return None
            data += chunk
        return data if len(data) == size else None

    def _read(self) -> None:
        while (header := self._exactly(58)) is not None:
            kind = header[2:14].rstrip(b"\0")
            device = header[14:34].rstrip(b"\0")
            seconds, fraction, size = struct.unpack(">IIQ", header[34:50])
            if self._exactly(size) is None:
                return
            if kind == b"TRANSFORM" and device == b"ToolToRAS":
                self.poses.append((time.perf_counter(), seconds + fraction / 2**32))

    def _idle(self) -> None:
        self._stop.wait()

    def close(self) -> None:
        self._stop.set()
        self.sock.close()
        self._thread.join(timeout=2.0)


def flood(port: int, until: threading.Event) -> None:
    """Send POINT bodies at the server's bound, each with a wrong CRC, as fast as TCP takes."""
    body = b"\0" * (136 * 722)
    frame = struct.pack(">H12s20sIIQQ", 1, b"POINT", b"Flap", 0, 0, len(body), 1) + body
    with socket.create_connection(("127.0.0.1", port)) as sock:
        sock.settimeout(0.1)
        while not until.is_set():
            try:
                sock.send(frame)
            except TimeoutError:
                continue
            except OSError:
                return


def run_once(problem, plan, condition: str, log: Path) -> dict:
    backend = SimulatedRobot(problem.robot, start_rad=plan.position(plan.start_time), realtime=True)
    executor = Executor(problem, backend, ExecutionSettings())
    if condition == CONDITIONS[0]:
        result = executor.run(plan, log)
        return {"statistics": result.statistics, "poses": []}
    done = threading.Event()
    with NavigationLink(problem, plan, executor, port=0) as link:
        port = link.server.port
        readers = []
        if condition in ("one client reading", "four clients reading"):
            readers = [Reader(port) for _ in range(4 if condition.startswith("four") else 1)]
        elif condition == "a client that never reads":
            readers = [Reader(port, read=False)]
        flooder = None
        if condition == "a client flooding POINT bodies":
            flooder = threading.Thread(target=flood, args=(port, done), daemon=True)
            flooder.start()
        time.sleep(0.3)  # the clients connected and got the models
        result = executor.run(plan, log)
        done.set()
        poses = [p for r in readers for p in r.poses] if condition.endswith("reading") else []
        for reader in readers:
            reader.close()
        if flooder is not None:
            flooder.join(timeout=2.0)
    origin = read_log(log)[1]["clock_origin_s"]  # the log's time 0 on the loop's clock
    latencies = [arrived - (origin + stamp) for arrived, stamp in poses]
    stamps = sorted({stamp for _, stamp in poses})
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
