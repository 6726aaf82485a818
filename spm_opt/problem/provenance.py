"""What a plan or an execution log was made for, checked before it is used.

A plan's metadata (its JSON sidecar) and an execution log's header both record, under
``problem``, the problem they were made for (:meth:`~spm_opt.problem.problem.Problem.record`). Its
fingerprint (the landmarks, the limits and the robot, not the file's bytes) must be that of
the problem they are about to be used under. One that records none (no sidecar, a header
written by hand or by an older spm-opt) or another's is refused, unless the caller lets it
through on purpose (``other_problem``: ``--other-problem`` on the command line), and is then
still judged by the given problem's limits.

A log's header also records the plan it ran (its metadata, with the SHA-256 of its CSV's
bytes, and its duration): :func:`check_run_of` refuses a log beside a plan it did not run.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

from spm_opt.base.errors import InputError

if TYPE_CHECKING:
    from spm_opt.problem.problem import Problem
    from spm_opt.problem.trajectory import Trajectory

PLAN_HINT = "plan it again for this problem, or allow it with --other-problem"
"""How a message refusing a plan ends."""


def log_hint(use: str) -> str:
    """How a message refusing a log ends, for a command that would ``use`` it ("judge")."""
    return f"{use} it under the problem it ran under, or allow it with --other-problem"


_WORDING = {
    "plan": (
        "the plan was made",
        "for",
        "the plan records no problem it was made for (a CSV without its sidecar, or one "
        "written by hand or by an older spm-opt)",
    ),
    "log": ("it ran", "under", "its header records no problem it ran under"),
}
"""Per kind of record: what was done, its preposition, and what a record without a problem
says."""


def check_made_for(
    problem: Problem,
    recorded: Mapping[str, Any],
    kind: str,
    other_problem: bool,
    refused: str,
    hint: str,
    error: type[InputError] = InputError,
) -> str:
    """Refuse a plan's metadata or a log's header that does not record ``problem``'s
    fingerprint, unless ``other_problem``.

    Parameters
    ----------
    problem : Problem
        The problem it is about to be used under.
    recorded : mapping
        A plan's metadata or a log's header (its ``problem`` entry is read).
    kind : str
        "plan" or "log": how the message words it.
    other_problem : bool
        Let it through all the same.
    refused : str
        What the one-line message starts with ("plan refused", "log run.csv refused").
    hint : str
        What the message ends with: what the user may do.
    error : type
        The :class:`~spm_opt.base.errors.InputError` raised.

    Returns
    -------
    str
        Why it was let through by ``other_problem``, for a warning; "" if it is
        ``problem``'s.
    """
    made, preposition, unrecorded = _WORDING[kind]
    entry = recorded.get("problem")
    fingerprint = entry.get("fingerprint") if isinstance(entry, dict) else None
    if fingerprint == problem.fingerprint:
        return ""
    if fingerprint is None:
        why = unrecorded
    else:
        name = entry.get("name") or "another problem"
        why = (
            f"{made} {preposition} {name} (fingerprint {str(fingerprint)[:12]}), not "
            f"{preposition} {problem.name} ({problem.fingerprint[:12]}): their landmarks, "
            "limits or robot differ"
        )
    if not other_problem:
        raise error(f"{refused}: {why}; {hint}")
    return why


def check_plan_made_for(
    problem: Problem,
    trajectory: Trajectory,
    other_problem: bool,
    refused: str = "plan refused",
    error: type[InputError] = InputError,
) -> str:
    """:func:`check_made_for` of a plan: refuse ``trajectory`` unless its metadata records
    ``problem`` or ``other_problem``; returns why it was let through ("" if it is
    ``problem``'s)."""
    return check_made_for(
        problem, trajectory.metadata, "plan", other_problem, refused, PLAN_HINT, error
    )


def check_run_of(trajectory: Trajectory, plan: str, header: Mapping[str, Any], log: str) -> None:
    """Refuse a log whose header records a run of another plan than ``trajectory``.

    The plan is told by the SHA-256 of its CSV's bytes where both its metadata and the
    header record it (every plan ``spm-opt plan`` writes, as ``spm-opt execute`` runs it),
    else by its duration (to 1 ns); a header that records neither is let through.

    Parameters
    ----------
    trajectory : Trajectory
        The plan.
    plan : str
        The plan's path, for the message.
    header : mapping
        The log's header.
    log : str
        The log's path, for the message.
    """
    ran = header.get("plan")
    ran = ran if isinstance(ran, dict) else {}
    planner = ran.get("planner")
    what = f"a {planner} plan" if isinstance(planner, str) and planner else "a plan"
    ran_hash, hash_ = _samples_hash(ran), _samples_hash(trajectory.metadata)
    ran_duration = header.get("plan_duration_s")
    if ran_hash is not None and hash_ is not None:
        if ran_hash == hash_:
            return
        differs = f"{what} whose CSV's SHA-256 is {ran_hash[:12]}, not {hash_[:12]}"
    elif isinstance(ran_duration, int | float) and not isinstance(ran_duration, bool):
        if math.isclose(ran_duration, trajectory.duration, rel_tol=0.0, abs_tol=1e-9):
            return
        differs = f"{what} of {ran_duration:.6g} s, not {trajectory.duration:.6g} s"
    else:
        return
    raise InputError(
        f"log {log} refused: it is a run of another plan than {plan} ({differs}); give the "
        "plan it ran"
    )


def _samples_hash(metadata: Mapping[str, Any]) -> str | None:
    """The SHA-256 of its CSV's bytes that a plan's metadata records, or None."""
    samples = metadata.get("samples")
    digest = samples.get("sha256") if isinstance(samples, dict) else None
    return digest if isinstance(digest, str) else None
