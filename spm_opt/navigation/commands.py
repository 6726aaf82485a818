"""The commands a navigation client sends, as STRING ``CMD_<id>`` (the BRP robot protocol's
style), and the STATUS each is answered with.

``STOP`` (the safe stop, at any time), ``HOLD`` and ``RESUME`` (the feed hold), and
``PLAN [planner]`` (plan the received flap; default :data:`DEFAULT_PLANNER`). Upper or lower
case, words separated by spaces. Anything that asks for motion (START, RUN, MOVE,
EXECUTE...) is refused: nothing received over the network starts motion.
"""

from __future__ import annotations

from dataclasses import dataclass

from spm_opt.planners import PLANNERS

DEFAULT_PLANNER = "toppra"
VERBS = ("STOP", "HOLD", "RESUME", "PLAN")
MOTION_VERBS = ("START", "RUN", "MOVE", "EXECUTE", "GO", "MOVE_TO_TARGET", "MANUAL")
MAX_COMMAND_CHARS = 200

# OpenIGTLink STATUS codes (the protocol's status.md)
OK, UNKNOWN_ERROR, ACCESS_DENIED, BUSY, UNKNOWN_INSTRUCTION, NOT_READY = 1, 2, 5, 6, 12, 13


@dataclass(frozen=True)
class Command:
    """A command understood: its verb and its argument (a planner name for PLAN)."""

    verb: str
    argument: str = ""


@dataclass(frozen=True)
class CommandReply:
    """The STATUS a command is answered with: code, error name (the verb) and message."""

    code: int
    name: str
    message: str

    @classmethod
    def ok(cls, verb: str, message: str) -> CommandReply:
        return cls(OK, verb, message)

    @classmethod
    def busy(cls, verb: str, message: str) -> CommandReply:
        return cls(BUSY, verb, message)

    @classmethod
    def not_ready(cls, verb: str, message: str) -> CommandReply:
        return cls(NOT_READY, verb, message)

    @classmethod
    def failed(cls, verb: str, message: str) -> CommandReply:
        return cls(UNKNOWN_ERROR, verb, message[: MAX_COMMAND_CHARS * 4])


def parse_command(text: str) -> Command | CommandReply:
    """The command in a ``CMD_<id>`` string, or the reply that refuses it."""
    words = text.strip().split()
    if not words or len(text) > MAX_COMMAND_CHARS:
        return CommandReply(
            UNKNOWN_INSTRUCTION,
            "COMMAND",
            f"expected one of {', '.join(VERBS)} (at most {MAX_COMMAND_CHARS} characters)",
        )
    verb, arguments = words[0].upper(), words[1:]
    if verb in MOTION_VERBS:
        return CommandReply(
            ACCESS_DENIED,
            verb,
            "nothing received over the network starts motion: start the run at the robot's "
            "console (spm-opt execute)",
        )
    if verb not in VERBS:
        return CommandReply(
            UNKNOWN_INSTRUCTION, verb[:20], f"unknown command; expected one of {', '.join(VERBS)}"
        )
    if verb == "PLAN":
        planner = arguments[0] if arguments else DEFAULT_PLANNER
        if planner not in PLANNERS or len(arguments) > 1:
            return CommandReply(
                UNKNOWN_INSTRUCTION, verb, f"PLAN [planner]: planner one of {', '.join(PLANNERS)}"
            )
        return Command(verb, planner)
    if arguments:
        return CommandReply(UNKNOWN_INSTRUCTION, verb, f"{verb} takes no argument")
    return Command(verb)
