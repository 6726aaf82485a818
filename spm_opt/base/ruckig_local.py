"""The one call into ruckig, for the planners and the executor alike: one segment at a
time, computed on this machine.

Ruckig's community edition sends a problem with intermediate waypoints to a remote
service. :func:`calculate_locally` refuses an input that carries any, and builds its
generator without waypoint capacity; motions through waypoints are chained from single
segments by the caller (the ruckig planner, the executor's approach, stop and feed changes).
"""

from __future__ import annotations

import ruckig

from spm_opt.base.errors import PlanningError

_RESULT_WORDS = {
    ruckig.Result.Error: "failed (unspecified error)",
    ruckig.Result.ErrorInvalidInput: "refused the input as invalid",
    ruckig.Result.ErrorPositionalLimits: "found the motion leaves the position limits",
    ruckig.Result.ErrorExecutionTimeCalculation: "found no time-optimal profile",
    ruckig.Result.ErrorSynchronizationCalculation: "could not synchronise the joints",
}


def calculate_locally(inp: ruckig.InputParameter, segment: str) -> ruckig.Trajectory:
    """The one call into ruckig: one segment, without intermediate waypoints, on this machine.

    Raises
    ------
    PlanningError
        If ``inp`` carries intermediate positions (ruckig would send them to its remote
        service), or ruckig fails; the message names ``segment`` and ruckig's result.
    """
    if len(inp.intermediate_positions) > 0:
        raise PlanningError(
            f"ruckig: {segment}: refusing {len(inp.intermediate_positions)} intermediate "
            "positions (ruckig would plan them on a remote service); chain single segments"
        )
    generator = ruckig.Ruckig(inp.degrees_of_freedom)
    trajectory = ruckig.Trajectory(inp.degrees_of_freedom)
    try:
        result = generator.calculate(inp, trajectory)
    except ruckig.RuckigError as error:
        reason = next((line for line in str(error).splitlines() if line.strip()), "no message")
        raise PlanningError(f"ruckig: {segment}: {reason.strip()}") from None
    except ValueError as error:  # a result code its Python binding does not know
        raise PlanningError(f"ruckig: {segment}: ruckig failed ({error})") from None
    if result not in (ruckig.Result.Working, ruckig.Result.Finished):
        words = _RESULT_WORDS.get(result, f"returned {result}")
        raise PlanningError(f"ruckig: {segment}: ruckig {words} ({result.name})")
    return trajectory
