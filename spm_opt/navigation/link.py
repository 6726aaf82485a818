"""The navigation link during a run: the robot in 3D Slicer over OpenIGTLink.

Sent (device names are Slicer's node names; RAS, mm; see :mod:`spm_opt.navigation.scene`):

- ``ToolToRAS`` (TRANSFORM), the tool's pose from the measured joint angles, at
  :data:`POSE_RATE_HZ` while a run reads them; its timestamp is the log's time of the
  cycle that read them (s since the loop's start), so each frame names its log row;
- ``RobotToRAS`` (TRANSFORM), the registration's inverse, to place the robot's models;
- ``PlannedCut``, ``Contour`` and ``TubeEdges`` (POLYDATA), when a client connects;
  ``ExecutedCut`` (POLYDATA), the measured cut's trail, at :data:`INFO_RATE_HZ`;
- ``RunState`` (STATUS): the state (ready, approach, running, held, settling, stopping,
  at rest, stopped, fault) as its error name, on every change and when a client connects;
  ``RunInfo`` (STRING): the state with the feed, the following error and the progress
  along the contour, at :data:`INFO_RATE_HZ`.

Taken: ``RASToRobot`` (TRANSFORM), a new registration (image RAS to robot, mm: the
problem's ``image_to_robot``), which the link shows the robot through from then on; a
POINT list (any device name), the flap drawn in Slicer, kept for PLAN; ``CMD_<id>``
(STRING) commands, answered by ``ACK_<id>`` (STRING, the command echoed) at once and then
a STATUS ``CMD_<id>`` with the outcome (see :mod:`spm_opt.navigation.commands`).

Nothing received starts motion. STOP asks the executor for the safe stop, as SIGINT does;
HOLD and RESUME are the console's space key. The link reads the executor's status from a
thread of its own and never touches the control loop.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from spm_opt.execution.console import ContourProgress
from spm_opt.execution.cycle import INTERRUPTED
from spm_opt.execution.executor import Executor
from spm_opt.execution.results import ExecutionResult, RunStatus
from spm_opt.model.params import DEG, MM
from spm_opt.navigation import igtl, scene
from spm_opt.navigation.commands import Command, CommandReply, parse_command
from spm_opt.navigation.server import DEFAULT_PORT, NavigationServer
from spm_opt.problem.problem import Problem
from spm_opt.problem.trajectory import Trajectory

_LOG = logging.getLogger(__name__)

POSE_RATE_HZ = 50.0
"""How often the tool's pose is sent while the run reads the joints, Hz."""
INFO_RATE_HZ = 2.0
"""How often ``RunInfo`` and the executed cut's trail are sent, Hz."""
PLANNED_CUT_RATE_HZ = 20.0
"""The plan is drawn at its time grid at this rate (breakpoints included), Hz."""
MAX_TRAIL_POINTS = 4_000
"""The trail keeps every other point once it has this many (its model stays small: the
server computes each message's CRC on the GIL the control loop also needs)."""

STATUS_OK, STATUS_ERROR = 1, 2
"""OpenIGTLink STATUS codes: OK, and "unknown error" for a fault."""


@dataclass(frozen=True)
class ReceivedFlap:
    """A POINT list received from Slicer: the flap's points in RAS, mm."""

    device: str
    names: tuple[str, ...]
    points_ras_mm: np.ndarray


def run_state(status: RunStatus | None) -> str:
    """The state a run's status shows: ready (no cycle yet), approach (also the hold at
    the plan's start), running, held, settling or stopping."""
    if status is None:
        return "ready"
    if status.phase in ("approach", "ready"):
        return "approach"
    if status.phase == "plan":
        return "held" if status.held and status.feed == 0.0 else "running"
    if status.phase == "settle":
        return "settling"
    return "stopping"


def end_state(result: ExecutionResult) -> tuple[str, int]:
    """The state a finished run shows, with its STATUS code: at rest (the plan ran to its
    end and rest was proven), stopped (a stop was asked for and rest was proven) or
    fault."""
    if result.succeeded:
        return "at rest", STATUS_OK
    asked = result.reason.startswith(INTERRUPTED)
    if asked and result.stop is not None and result.stop.at_rest:
        return "stopped", STATUS_OK
    return "fault", STATUS_ERROR


class NavigationLink:
    """The OpenIGTLink server of a run (see the module's docstring).

    Parameters
    ----------
    problem : Problem
        The run's problem: its contour, its tube and its registration.
    trajectory : Trajectory, optional
        The plan, drawn as ``PlannedCut``.
    executor : Executor, optional
        The run whose status is streamed and which STOP, HOLD and RESUME steer.
    host, port : str, int
        Where to listen (127.0.0.1: this machine only; port 0: any free one).
    plan : callable, optional
        Serves PLAN: called on a worker thread with (received flap, planner name, command
        id, the registration RAS mm to robot mm); returns the new problem and its plan,
        whose models are sent back (``PlannedCut``, ``Contour``, ``TubeEdges``). None:
        PLAN is refused.
    """

    def __init__(
        self,
        problem: Problem,
        trajectory: Trajectory | None = None,
        executor: Executor | None = None,
        host: str = "127.0.0.1",
        port: int = DEFAULT_PORT,
        plan: Callable[[ReceivedFlap, str, str, np.ndarray], tuple[Problem, Trajectory]]
        | None = None,
    ) -> None:
        self.problem, self.trajectory, self.executor = problem, trajectory, executor
        self._plan = plan
        self._lock = threading.Lock()
        self._image_to_robot = scene.image_to_robot(problem)
        self._progress = (
            None
            if trajectory is None or trajectory.metadata.get("ignores_contour")
            else ContourProgress(problem, trajectory)
        )
        self.flap: ReceivedFlap | None = None
        self._model_frames: list[bytes] | None = None  # made by _models, once
        self._trail: list[np.ndarray] = []
        self._state, self._state_code, self._state_message = "ready", STATUS_OK, ""
        self._finished = False
        self._planning: threading.Thread | None = None
        self._closing = threading.Event()
        self.server = NavigationServer(self._received, self._connected, host, port)
        self._publisher = threading.Thread(target=self._publish, name="igtl-publish", daemon=True)
        self.poses_sent = 0

    # ------------------------------------------------------------------ the owner's side
    def start(self) -> None:
        """Make the models, listen and start streaming (raises CommunicationError if the
        port is taken)."""
        self._models()
        self.server.start()
        self._publisher.start()

    def close(self) -> None:
        """Send the last state, stop streaming and close every client."""
        self._closing.set()
        if self._publisher.is_alive():
            self._publisher.join(timeout=5.0)
        self._send_state()
        if self._planning is not None:
            self._planning.join(timeout=60.0)
        self.server.close()

    def __enter__(self) -> NavigationLink:
        self.start()
        return self

    def __exit__(self, *_exc: object) -> None:
        self.close()

    def finished(self, result: ExecutionResult) -> None:
        """Show how the run ended (at rest, stopped or fault, with its reason)."""
        state, code = end_state(result)
        with self._lock:
            self._finished = True
        self._set_state(state, code, result.reason)

    @property
    def image_to_robot(self) -> np.ndarray:
        """The registration the link shows the robot through (4, 4), RAS mm to robot mm."""
        with self._lock:
            return self._image_to_robot.copy()

    # ------------------------------------------------------------------ what is sent
    def _frame(
        self, kind: str, device: str, body: bytes, timestamp_s: float | None = None
    ) -> bytes:
        return igtl.pack(kind, device, body, time.time() if timestamp_s is None else timestamp_s)

    def _models(self) -> list[bytes]:
        """The models and the registration, as a new client gets them: made once for each
        registration and plan (a plan's cut is tens of kB, whose CRC a connection during a
        run should not wait for), the trail as it stands."""
        with self._lock:
            frames = self._model_frames
        if frames is None:
            frames = self._make_models()
            with self._lock:
                self._model_frames = frames
        trail = self._trail_frame(scene.robot_to_ras(self.image_to_robot))
        return frames if trail is None else [*frames, trail]

    def _make_models(self) -> list[bytes]:
        to_ras = scene.robot_to_ras(self.image_to_robot)
        frames = [self._frame("TRANSFORM", "RobotToRAS", igtl.transform_body(to_ras))]
        contour = scene.contour_points(self.problem, to_ras)
        frames.append(self._polyline("Contour", contour, closed=self.problem.closed))
        edges = scene.tube_edges(self.problem, to_ras)
        if edges is not None:
            frames.append(self._polylines("TubeEdges", list(edges), closed=self.problem.closed))
        if self.trajectory is not None:
            frames.append(self._planned_cut(self.problem, self.trajectory, to_ras))
        return frames

    def _planned_cut(self, problem: Problem, trajectory: Trajectory, to_ras: np.ndarray) -> bytes:
        t = trajectory.time_grid(PLANNED_CUT_RATE_HZ)
        return self._polyline(
            "PlannedCut", scene.cut_points(problem, trajectory.position(t), to_ras)
        )

    def _polyline(self, device: str, points_mm: np.ndarray, closed: bool = False) -> bytes:
        return self._polylines(device, [points_mm], closed)

    def _polylines(self, device: str, lines_mm: list[np.ndarray], closed: bool) -> bytes:
        points, lines, start = [], [], 0
        for line in lines_mm:
            indices = list(range(start, start + len(line)))
            lines.append([*indices, start] if closed else indices)
            points.append(line)
            start += len(line)
        return self._frame("POLYDATA", device, igtl.polydata_body(np.vstack(points), lines))

    def _trail_frame(self, to_ras: np.ndarray) -> bytes | None:
        with self._lock:
            if len(self._trail) < 2:
                return None
            trail = np.array(self._trail)
        return self._polyline("ExecutedCut", scene.in_ras(trail, to_ras))

    def _set_state(self, state: str, code: int, message: str) -> None:
        with self._lock:
            changed = (state, code, message) != (self._state, self._state_code, self._state_message)
            self._state, self._state_code, self._state_message = state, code, message
        if changed:
            _LOG.info("navigation: run state %s%s", state, f" ({message})" if message else "")
            self._send_state()

    def _send_state(self, client: int | None = None) -> None:
        with self._lock:
            state, code, message = self._state, self._state_code, self._state_message
        body = igtl.status_body(code, 0, state, message or state)
        self.server.send(self._frame("STATUS", "RunState", body), client=client)
        self._send_info(client)

    def _send_info(self, client: int | None = None) -> None:
        line = self._info_line()
        self.server.send(self._frame("STRING", "RunInfo", igtl.string_body(line)), client=client)

    def _info_line(self) -> str:
        """The state, feed, following error and progress along the contour, in one line."""
        with self._lock:
            state, message = self._state, self._state_message
        status = None if self.executor is None else self.executor.status
        parts = [state]
        if status is not None:
            parts.append(f"feed {status.feed:.0%}")
            if status.following_error_rad is not None:
                parts.append(f"following error {status.following_error_rad / DEG:.3f} deg")
            if self._progress is not None:
                done = self._progress.at(status.plan_time_s)
                length = self._progress.length_m
                parts.append(f"{done / MM:.1f} of {length / MM:.1f} mm ({done / length:.0%})")
        if message and message != state:
            parts.append(message)
        return "; ".join(parts)

    def _publish(self) -> None:
        """Stream the pose at :data:`POSE_RATE_HZ`, the state on change, the information
        and the trail at :data:`INFO_RATE_HZ`, until closed. Each round starts right after
        a control cycle (:meth:`Executor.next_status`), so its work falls in the loop's
        idle time rather than across a cycle."""
        period, info_period = 1.0 / POSE_RATE_HZ, 1.0 / INFO_RATE_HZ
        sent_at: float | None = None  # the log time of the last pose sent
        info_due = time.monotonic()
        try:
            while not self._closing.is_set():
                if self.executor is None:
                    self._closing.wait(period)
                    status = None
                else:
                    after = None if sent_at is None else sent_at + 0.75 * period
                    status = self.executor.next_status(after, period)
                if status is not None and (sent_at is None or status.time_s > sent_at):
                    if sent_at is None or status.time_s >= sent_at + 0.75 * period:
                        sent_at = status.time_s
                        self._send_pose(status)
                with self._lock:
                    finished = self._finished
                if not finished:
                    self._set_state(run_state(status), STATUS_OK, "")
                if time.monotonic() >= info_due:
                    info_due += info_period
                    self._send_info()
                    trail = self._trail_frame(scene.robot_to_ras(self.image_to_robot))
                    if trail is not None:
                        self.server.send(trail, droppable=True)
        except Exception:  # the link must never take the run down
            _LOG.exception("navigation: streaming stopped by an error; the run goes on")

    def _send_pose(self, status: RunStatus) -> None:
        if status.measured_rad is None:
            return
        in_robot = scene.tool_to_robot(self.problem, np.array([status.measured_rad]))[0]
        pose = scene.robot_to_ras(self.image_to_robot) @ in_robot
        frame = self._frame("TRANSFORM", "ToolToRAS", igtl.transform_body(pose), status.time_s)
        self.server.send(frame, droppable=True)
        self.poses_sent += 1
        if status.phase in ("plan", "settle", "stop", "hold"):
            with self._lock:
                self._trail.append(in_robot[:3, 3] * MM)  # the tool tip: the cut point
                if len(self._trail) > MAX_TRAIL_POINTS:
                    self._trail = self._trail[::2]

    # ------------------------------------------------------------------ what is received
    def _connected(self, client: int) -> None:
        for frame in self._models():
            self.server.send(frame, client=client)
        self._send_state(client)

    def _received(self, client: int, message: igtl.Message) -> None:
        kind, device = message.header.kind, message.header.device
        content = igtl.content(message)
        if kind == "TRANSFORM" and device == "RASToRobot":
            self._take_registration(igtl.read_transform(content))
        elif kind == "POINT":
            names, points = igtl.read_points(content)
            self.flap = ReceivedFlap(device, tuple(names), points)
            _LOG.info("navigation: flap of %d points received as %r", len(points), device)
        elif kind == "STRING" and device.startswith("CMD_"):
            self._command(client, device[len("CMD_") :], igtl.read_string(content))
        else:
            _LOG.info("navigation: %s %r from client %d ignored", kind, device, client)

    def _take_registration(self, matrix: np.ndarray) -> None:
        rotation = matrix[:3, :3]
        if (
            not np.allclose(rotation.T @ rotation, np.eye(3), atol=1e-4)
            or np.linalg.det(rotation) < 0
        ):
            _LOG.warning("navigation: RASToRobot dropped: its rotation is not a rotation")
            return
        with self._lock:
            self._image_to_robot = matrix
            self._model_frames = None
        _LOG.info("navigation: registration RASToRobot received; the robot is shown through it")
        for frame in self._models():
            self.server.send(frame)

    def _command(self, client: int, command_id: str, text: str) -> None:
        ack = self._frame("STRING", f"ACK_{command_id}", igtl.string_body(text))
        self.server.send(ack, client=client)
        reply = self._act(client, command_id, parse_command(text))
        body = igtl.status_body(reply.code, 0, reply.name, reply.message)
        self.server.send(self._frame("STATUS", f"CMD_{command_id}", body), client=client)
        _LOG.info(
            "navigation: CMD_%s %r from client %d: %s", command_id, text, client, reply.message
        )

    def _act(self, client: int, command_id: str, command: Command | CommandReply) -> CommandReply:
        if isinstance(command, CommandReply):
            return command
        if command.verb == "PLAN":
            return self._start_plan(client, command_id, command.argument)
        executor = self.executor
        if executor is None:
            return CommandReply.not_ready(command.verb, "no run to steer")
        if command.verb == "STOP":
            executor.stop(f"STOP from the navigation link (client {client}, CMD_{command_id})")
            return CommandReply.ok(command.verb, "safe stop requested")
        if command.verb == "HOLD":
            executor.hold()
            return CommandReply.ok(command.verb, "feed hold")
        executor.resume()
        return CommandReply.ok(command.verb, "resumed")

    def _start_plan(self, client: int, command_id: str, planner: str) -> CommandReply:
        """PLAN on a worker thread; the reply says it started; the models and a second
        STATUS ``CMD_<id>`` (its message beginning "planned" or "failed") follow when it
        ends."""
        if self._plan is None:
            return CommandReply.busy(
                "PLAN", "a run is on: plan with spm-opt navigate, not during a run"
            )
        if self.flap is None:
            return CommandReply.not_ready("PLAN", "no flap received: send a POINT list first")
        if self._planning is not None and self._planning.is_alive():
            return CommandReply.busy("PLAN", "a plan is being made")
        flap, plan = self.flap, self._plan

        def work() -> None:
            try:
                problem, trajectory = plan(flap, planner, command_id, self.image_to_robot)
                with self._lock:
                    self.problem, self.trajectory = problem, trajectory
                    self._model_frames = None
                for frame in self._models():
                    self.server.send(frame)
                reply = CommandReply.ok("PLAN", f"planned by {planner}: {problem.source}")
            except Exception as error:  # any planner's failure is the client's answer
                reply = CommandReply.failed("PLAN", f"failed: {type(error).__name__}: {error}")
            body = igtl.status_body(reply.code, 0, reply.name, reply.message)
            self.server.send(self._frame("STATUS", f"CMD_{command_id}", body), client=client)
            _LOG.info("navigation: CMD_%s PLAN: %s", command_id, reply.message)

        self._planning = threading.Thread(target=work, name="igtl-plan", daemon=True)
        self._planning.start()
        return CommandReply.ok("PLAN", f"planning {len(flap.names)} points with {planner}")
