"""Two emulated Dynamixel PRO L54-50-S500-R actuators on a pseudo-terminal.

The emulator opens a pseudo-terminal, answers Protocol 2.0 on it as two actuators would
(default ids 1 and 2, joints θ1 and θ2) and drives the simulated robot
(:class:`spm_opt.execution.plant.DynamixelPlant`) in real time: before each instruction,
and whenever the line is idle, the plant is advanced to the time elapsed since serving
began (on a machine too slow for that, it drops time rather than delay replies; see
:data:`MAX_LAG_S`). A client opens ``Emulator.device`` as it would a USB-serial adapter;
the baud rate is accepted and ignored.

Instructions: ping (model 38152 and the firmware version), read, write, sync read (each
addressed actuator answers with its own status packet, in the order of the ids), sync
write (no reply) and reboot (clears the hardware error; torque off). Any other
instruction gets the instruction error (2); a packet with a bad CRC gets the CRC error (3)
if its id is one of ours; a read of addresses outside the table or a write to a read-only
or unlisted address, or to an EEPROM item (address < 562) while torque is on, gets the
access error (7); a write that covers part of an item gets the data length error (5); a
value outside its item's range (a goal position outside the position limits, a goal
velocity above the velocity limit, a goal torque above the torque limit) gets the data
range error (4); ranges the reference does not give are the item's type range, non-negative
for limits and gains. A write is applied whole or not at all. A sync write gets no reply,
so a value it carries that a write would refuse is silently dropped. While an actuator's
Hardware Error Status is non-zero, bit 7 (alert) is set in the error byte of its status
packets.

Simplifications: every instruction addressed to one id is answered whatever the Status
Return Level (891), without the Return Delay Time (9); broadcast ping is answered by
both actuators in id order, other broadcast instructions get no reply. The plant always
runs position control: Operating Mode, Homing Offset, Goal Velocity, Goal Torque and Goal
Acceleration are stored and read back but do not act. Torque Enable cannot be set while a
hardware error is pending (the write is accepted; the table keeps 0). A write of ID (7)
changes the id the actuator answers to.

The control table follows the original PRO firmware (``docs/dynamixel.md``);
Firmware Version (address 6, read-only) is added so that the table agrees with ping.

Faults (:class:`Faults`) are timed from the first goal-position write (a write or sync
write covering address 596) made while torque is on, so that a run is deterministic
relative to its own start. Their text form, ``kind:field=value,...``, is read by
:func:`parse_fault`.

A sync write gets no reply, so nothing on the bus can tell the host that one was lost:
the SDK's ``txPacket`` reports success once the port has taken the bytes. The write fault
(:class:`RefusedWrites`) therefore acts where a real failure shows: the emulator suspends
the pseudo-terminal's output (``tcflow(TCOOFF)``, as a stalled adapter or a deasserted
CTS line would), so the port takes no byte from the host and the host's writes, of goals
and of read instructions alike, time out at the port.

For tests, the emulator can record the plant's true state (:class:`StateTrace`) on the
machine's monotonic clock, which is the executor's clock too.

The package's modules: :mod:`.control_table` (the items and the bytes), :mod:`.faults` (the
faults, their text form and their state), :mod:`.server` (the pseudo-terminal, the
protocol and the plant) and :mod:`.process` (serving until a signal, and an emulator in a
child process). Its command line is ``spm-opt emulate``.
"""

from spm_opt.execution.emulator.control_table import FIRMWARE_VERSION, MODEL_NUMBER, ControlTable
from spm_opt.execution.emulator.faults import (
    CorruptReplies,
    DelayReplies,
    DropReplies,
    Faults,
    Overload,
    RefusedWrites,
    StuckEncoder,
    parse_fault,
    parse_faults,
)
from spm_opt.execution.emulator.process import SpawnedEmulator, serve, spawn_emulator
from spm_opt.execution.emulator.server import Emulator

__all__ = [
    "FIRMWARE_VERSION",
    "MODEL_NUMBER",
    "ControlTable",
    "CorruptReplies",
    "DelayReplies",
    "DropReplies",
    "Emulator",
    "Faults",
    "Overload",
    "RefusedWrites",
    "SpawnedEmulator",
    "StuckEncoder",
    "parse_fault",
    "parse_faults",
    "serve",
    "spawn_emulator",
]
