"""The emulator: two actuators on a pseudo-terminal, answering Protocol 2.0 and driving the
simulated robot in real time (the package's docstring says what it answers and how)."""

from __future__ import annotations

import contextlib
import os
import select
import threading
import time
import tty
from collections import deque
from collections.abc import Callable, Sequence

import numpy as np

from spm_opt.base.errors import InputError
from spm_opt.base.input_limits import excerpt
from spm_opt.execution.emulator.control_table import (
    FIRMWARE_ITEM,
    FIRMWARE_VERSION,
    GOAL_POSITION,
    HARDWARE_ERROR_STATUS,
    ID_ITEM,
    LIVE_LAYOUT,
    MODEL_NUMBER,
    MOVING,
    POSITION_P_GAIN,
    TORQUE_ENABLE,
    TORQUE_LIMIT,
    VELOCITY_I_GAIN,
    VELOCITY_LIMIT,
    VELOCITY_P_GAIN,
    ControlTable,
    Item,
)
from spm_opt.execution.emulator.faults import Faults, LineStall, Overload, reply_window
from spm_opt.execution.plant import OVERLOAD_BIT, DynamixelPlant, PlantSettings, StateTrace
from spm_opt.execution.protocol import (
    ALERT,
    BROADCAST_ID,
    MAX_ID,
    ErrorCode,
    Instruction,
    Packet,
    PacketReader,
    build_status,
    layout_consistent,
)
from spm_opt.model.params import Robot

INTERBYTE_TIMEOUT_S = 0.1
"""A partly received packet is dropped after this long without a byte, s."""

MAX_LAG_S = 0.01
"""Most plant time, s, made up before a reply; beyond it the plant drops time (see
:attr:`Emulator.lost_time_s`)."""


def _valid_ids(ids: tuple[int, ...]) -> bool:
    return len(ids) == 2 and len(set(ids)) == 2 and all(0 <= int(i) <= MAX_ID for i in ids)


class _Actuator:
    def __init__(self, joint: int, device_id: int, firmware: int) -> None:
        self.joint = joint
        self.id = device_id
        self.table = ControlTable()
        self.table.set(ID_ITEM, device_id)
        self.table.set(FIRMWARE_ITEM, firmware)
        self.firmware = firmware


class Emulator:
    """Two actuators on a pseudo-terminal, driving a :class:`DynamixelPlant`.

    Parameters
    ----------
    robot : Robot
    ids : pair of int
        Ids of the actuators of θ1 and θ2 (0–252, distinct).
    start_rad : array_like, shape (2,), rad
        Joint angles at start.
    faults : Faults
    plant_settings : PlantSettings, optional
    firmware : int
        Firmware version reported by ping and at address 6.
    trace : StateTrace, optional
        Receives the plant's true state each time the plant is advanced, on the
        machine's monotonic clock (``time.monotonic``, s).

    The pseudo-terminal is opened on construction (``device`` is its path) and closed by
    :meth:`close`. As a context manager it serves in a background daemon thread;
    :meth:`serve_forever` serves in the calling thread.

    Attributes
    ----------
    device : str
        Path of the pseudo-terminal's slave side.
    plant : DynamixelPlant
    lost_time_s : float, s
        Plant time dropped because the machine could not keep up (0 on a machine that
        can): the plant then runs behind the wall clock by this much.
    """

    def __init__(
        self,
        robot: Robot,
        ids: Sequence[int] = (1, 2),
        start_rad: np.ndarray | Sequence[float] | None = None,
        faults: Faults | None = None,
        plant_settings: PlantSettings | None = None,
        firmware: int = FIRMWARE_VERSION,
        trace: StateTrace | None = None,
    ) -> None:
        ids = tuple(ids)
        if not _valid_ids(ids):
            raise InputError(f"ids: expected two distinct ids 0-{MAX_ID}, got {excerpt(ids)}")
        self.faults = faults or Faults()
        unknown = self.faults.ids() - set(ids)
        if unknown:
            raise InputError(f"fault: id {min(unknown)} is not an emulated id (allowed: {ids})")
        start = np.zeros(2) if start_rad is None else np.asarray(start_rad, dtype=float)
        self.plant = DynamixelPlant(robot, settings=plant_settings, start_rad=start)
        self._units = robot.actuator
        self._actuators = [_Actuator(j, device_id, firmware) for j, device_id in enumerate(ids)]
        self._joint_of_id = {device_id: j for j, device_id in enumerate(ids)}
        for actuator in self._actuators:
            self._load_from_plant(actuator)
        self._fault_origin: float | None = None
        self._drop = reply_window(self.faults.drop)
        self._crc = reply_window(self.faults.crc)
        self._delay = reply_window(self.faults.delay)
        self._events = [*self.faults.overload, *self.faults.stuck]
        self.trace = trace
        self._start: float | None = None
        self._now = 0.0
        self.lost_time_s = 0.0
        self._reader = PacketReader()
        self._outbox: deque[tuple[float, bytes]] = deque()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._closed = False
        self._master, self._slave = os.openpty()
        tty.setraw(self._slave)
        os.set_blocking(self._master, False)
        self.device: str = os.ttyname(self._slave)
        self._stall = (
            None if self.faults.write is None else LineStall(self.faults.write, self._slave)
        )

    @property
    def line_suspended(self) -> bool:
        """Whether the write fault holds the line's output suspended now."""
        return self._stall is not None and self._stall.suspended

    # ------------------------------------------------------------------ lifecycle
    def __enter__(self) -> Emulator:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def start(self) -> None:
        """Serve in a background daemon thread (no-op if it is running)."""
        if self._thread is not None:
            return
        self._stop.clear()
        self._thread = threading.Thread(target=self.serve_forever, name="emulator", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        """Stop the background thread (if any) and wait for it."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
            self._thread = None

    def close(self) -> None:
        """Stop serving and close the pseudo-terminal."""
        self.stop()
        if not self._closed:
            self._closed = True
            os.close(self._master)
            os.close(self._slave)

    def serve_forever(self, stop_event: threading.Event | None = None) -> None:
        """Answer packets until ``stop_event`` (default: the one :meth:`stop` sets) is set.

        Waits on the pseudo-terminal at most until the plant's next step is due, so the
        plant keeps up with real time between packets.
        """
        stop = stop_event or self._stop
        if self._start is None:
            self._start = time.monotonic()
        master, reader, plant = self._master, self._reader, self.plant
        step = plant.settings.step_s
        last_byte = time.monotonic()
        while not stop.is_set():
            now = time.monotonic()
            timeout = self._start + plant.time_s + step - now
            if self._outbox:
                timeout = min(timeout, self._outbox[0][0] - now)
            ready, _, _ = select.select([master], [], [], min(max(timeout, 0.0), 0.05))
            if ready:
                try:
                    data = os.read(master, 65536)
                except (BlockingIOError, InterruptedError):
                    data = b""
                if data:
                    last_byte = time.monotonic()
                    for packet in reader.feed(data):
                        self._handle(packet)
            else:
                now = time.monotonic()
                self._advance(now)
                if reader.pending and now - last_byte > INTERBYTE_TIMEOUT_S:
                    reader.reset()
            if self._outbox:
                self._flush(time.monotonic())

    # ----------------------------------------------------------------- the plant
    def _load_from_plant(self, actuator: _Actuator) -> None:
        plant, units, table, j = self.plant, self._units, actuator.table, actuator.joint
        table.set(TORQUE_LIMIT, int(units.current_units(plant.current_limit_a[j])))
        table.set(VELOCITY_LIMIT, int(units.velocity_units(plant.velocity_limit_rad_s[j])))
        table.set(POSITION_P_GAIN, int(plant.position_p_gain[j]))
        table.set(VELOCITY_P_GAIN, int(plant.velocity_p_gain[j]))
        table.set(VELOCITY_I_GAIN, int(plant.velocity_i_gain[j]))
        table.set(GOAL_POSITION, int(units.pulses(plant.goal_position_rad[j])))
        table.set(TORQUE_ENABLE, int(plant.torque_enabled[j]))

    def _refresh(self) -> None:
        """Copy the plant's measured state into both tables (before a read)."""
        plant = self.plant
        position = plant.present_position_pulses().tolist()
        velocity = plant.present_velocity_units().tolist()
        current = plant.present_current_units().tolist()
        moving = plant.moving().tolist()
        error = plant.hardware_error.tolist()
        torque = plant.torque_enabled.tolist()
        for actuator in self._actuators:
            data, j = actuator.table.data, actuator.joint
            LIVE_LAYOUT.pack_into(
                data, MOVING.address, moving[j], position[j], velocity[j], current[j]
            )
            data[HARDWARE_ERROR_STATUS.address] = error[j]
            data[TORQUE_ENABLE.address] = torque[j]

    def _advance(self, now: float) -> None:
        """Bring the plant to ``now`` and fire the faults that are due.

        A plant more than :data:`MAX_LAG_S` behind (the machine could not keep up) drops
        the excess instead of catching up, so that replies stay prompt.
        """
        self._now = now
        lag = now - self._start - self.plant.time_s
        if lag > MAX_LAG_S:
            self._start += lag - MAX_LAG_S
            self.lost_time_s += lag - MAX_LAG_S
        self.plant.advance_to(now - self._start)
        if self.trace is not None:
            self.trace.record(now, self.plant)
        if self._stall is not None and self._fault_origin is not None:
            self._stall.update(now - self._fault_origin)
        if self._events and self._fault_origin is not None:
            t = now - self._fault_origin
            for event in [e for e in self._events if t >= e.at]:
                j = self._joint_of_id[event.id]
                if isinstance(event, Overload):
                    self.plant.trigger_hardware_error(j, OVERLOAD_BIT)
                else:
                    self.plant.encoder_stuck[j] = True
                self._events.remove(event)

    def _apply(self, actuator: _Actuator, item: Item, value: int) -> None:
        """Store a checked value and pass it on to the plant."""
        plant, units, j = self.plant, self._units, actuator.joint
        table = actuator.table
        table.set(item, value)
        if item is GOAL_POSITION:
            plant.goal_position_rad[j] = float(units.angle(value))
            if self._fault_origin is None and plant.torque_enabled.any():
                self._fault_origin = self._now
        elif item is TORQUE_ENABLE:
            plant.enable_torque(j, bool(value))
            table.set(TORQUE_ENABLE, int(plant.torque_enabled[j]))
            table.set(GOAL_POSITION, int(units.pulses(plant.goal_position_rad[j])))
        elif item is VELOCITY_LIMIT:
            plant.velocity_limit_rad_s[j] = float(units.rate(value))
        elif item is TORQUE_LIMIT:
            plant.current_limit_a[j] = float(units.current(value))
        elif item is POSITION_P_GAIN:
            plant.position_p_gain[j] = value
        elif item is VELOCITY_P_GAIN:
            plant.velocity_p_gain[j] = value
        elif item is VELOCITY_I_GAIN:
            plant.velocity_i_gain[j] = value
        elif item is ID_ITEM:
            actuator.id = value

    def _write(self, actuator: _Actuator, address: int, data: bytes) -> ErrorCode:
        torque_on = bool(self.plant.torque_enabled[actuator.joint])
        code, values = actuator.table.check_write(address, data, torque_on)
        for item, value in values:
            self._apply(actuator, item, value)
        return code

    # ------------------------------------------------------------------- packets
    def _by_id(self, device_id: int) -> _Actuator | None:
        return next((a for a in self._actuators if a.id == device_id), None)

    def _addressed(self, device_id: int) -> list[_Actuator]:
        if device_id == BROADCAST_ID:
            return self._actuators
        actuator = self._by_id(device_id)
        return [] if actuator is None else [actuator]

    def _handle(self, packet: Packet) -> None:
        self._advance(time.monotonic())
        broadcast = packet.id == BROADCAST_ID
        targets = self._addressed(packet.id)
        if not targets:
            return
        if not packet.crc_ok:
            if not broadcast:
                self._reply(targets[0], ErrorCode.CRC)
            return
        handler = self._HANDLERS.get(packet.instruction)
        if handler is None:
            if not broadcast:
                self._reply(targets[0], ErrorCode.INSTRUCTION)
            return
        if not layout_consistent(packet.instruction, packet.params):
            if not broadcast:
                self._reply(targets[0], ErrorCode.DATA_LENGTH)
            return
        handler(self, packet, targets, broadcast)

    def _ping(self, packet: Packet, targets: list[_Actuator], broadcast: bool) -> None:
        for actuator in targets:
            data = MODEL_NUMBER.to_bytes(2, "little") + bytes((actuator.firmware,))
            self._reply(actuator, ErrorCode.NONE, data)

    def _read(self, packet: Packet, targets: list[_Actuator], broadcast: bool) -> None:
        if broadcast:
            return
        params = packet.params
        self._refresh()
        code, data = targets[0].table.read(params[0] | params[1] << 8, params[2] | params[3] << 8)
        self._reply(targets[0], code, data)

    def _write_instruction(self, packet: Packet, targets: list[_Actuator], broadcast: bool) -> None:
        table = targets[0].table
        # the reading that covers whole items: an unstuffed sender's data may hold FF FF FD FD
        params = next(
            (
                p
                for p in packet.readings
                if len(p) >= 3 and not table.items_covered(p[0] | p[1] << 8, len(p) - 2)[0]
            ),
            packet.params,
        )
        address = params[0] | params[1] << 8
        codes = [self._write(actuator, address, params[2:]) for actuator in targets]
        if not broadcast:
            self._reply(targets[0], codes[0])

    def _sync_read(self, packet: Packet, targets: list[_Actuator], broadcast: bool) -> None:
        params = packet.params
        address, length = params[0] | params[1] << 8, params[2] | params[3] << 8
        self._refresh()
        for actuator in filter(None, map(self._by_id, params[4:])):
            code, data = actuator.table.read(address, length)
            self._reply(actuator, code, data)

    def _sync_write(self, packet: Packet, targets: list[_Actuator], broadcast: bool) -> None:
        params = packet.params
        address, length = params[0] | params[1] << 8, params[2] | params[3] << 8
        for offset in range(4, len(params), length + 1):
            actuator = self._by_id(params[offset])
            if actuator is not None:
                self._write(actuator, address, params[offset + 1 : offset + 1 + length])

    def _reboot(self, packet: Packet, targets: list[_Actuator], broadcast: bool) -> None:
        for actuator in targets:
            self.plant.reboot(actuator.joint)
            actuator.table.set(TORQUE_ENABLE, 0)
            actuator.table.set(HARDWARE_ERROR_STATUS, 0)
        if not broadcast:
            self._reply(targets[0], ErrorCode.NONE)

    _HANDLERS: dict[int, Callable[[Emulator, Packet, list[_Actuator], bool], None]] = {
        Instruction.PING: _ping,
        Instruction.READ: _read,
        Instruction.WRITE: _write_instruction,
        Instruction.SYNC_READ: _sync_read,
        Instruction.SYNC_WRITE: _sync_write,
        Instruction.REBOOT: _reboot,
    }

    # -------------------------------------------------------------------- replies
    def _reply(self, actuator: _Actuator, code: ErrorCode, data: bytes = b"") -> None:
        error = int(code) | (ALERT if self.plant.hardware_error[actuator.joint] else 0)
        packet = build_status(actuator.id, error, data)
        send_at = self._now
        if self._fault_origin is not None:
            t = self._now - self._fault_origin
            if self._drop is not None and self._drop.take(t):
                return
            if self._crc is not None and self._crc.take(t):
                packet = packet[:-2] + bytes((packet[-2] ^ 0xFF, packet[-1] ^ 0xFF))
            elif self._delay is not None and self._delay.take(t):
                send_at += self.faults.delay.seconds
        if self._outbox or send_at > self._now:
            self._outbox.append(
                (max(send_at, self._outbox[-1][0] if self._outbox else 0.0), packet)
            )
        else:
            self._send(packet)

    def _flush(self, now: float) -> None:
        while self._outbox and self._outbox[0][0] <= now:
            self._send(self._outbox.popleft()[1])

    def _send(self, packet: bytes) -> None:
        """Write to the line; what the client does not take in time is lost."""
        with contextlib.suppress(BlockingIOError):
            os.write(self._master, packet)
