"""Violations collected as a motion is checked: the worst sample beyond each limit, by more
than its rule allows (:data:`spm_opt.judge.limits.RULES`)."""

from __future__ import annotations

import numpy as np

from spm_opt.judge.limits import RULES
from spm_opt.judge.report import Violation

TUBE_RULES = frozenset(("contour deviation", "landmark visit", "coverage", "backtracking"))
"""The rules whose limit is the cut's tube (:func:`spm_opt.judge.limits.path_tolerance`)."""


class Checks:
    """Collects violations (``found``): the worst sample beyond a limit and its rule's
    allowance, on the grid ``t`` (N,), s. ``reserve_mm``: what a plan's tube keeps of the
    contour tolerance for execution, mm, told by the tube's rules' violations."""

    def __init__(self, t: np.ndarray, reserve_mm: float = 0.0) -> None:
        self.t = t
        self.reserve_mm = reserve_mm
        self.found: list[Violation] = []

    def upper(
        self,
        rule: str,
        label: str,
        values: np.ndarray,
        limit: float | np.ndarray | None,
        times: np.ndarray | None = None,
    ) -> None:
        """Record the worst of ``values`` (at ``times``, default the grid) above ``limit``
        (one for all, or one per value: the worst is then the largest ratio) by more than
        the rule allows; ``None``: not limited."""
        if limit is None or len(values) == 0:
            return
        if np.ndim(limit) == 0:
            worst = int(np.argmax(values))
        else:
            worst = int(np.argmax(values / limit))
            limit = limit[worst]
        if values[worst] > RULES[rule].allowed(limit):
            times = self.t if times is None else times
            self._add(rule, label, values[worst], limit, times[worst])

    def lower(self, rule: str, label: str, values: np.ndarray, limit: float) -> None:
        """Record the worst of ``values`` below ``limit`` by more than the rule allows."""
        worst = int(np.argmin(values))
        if values[worst] < RULES[rule].allowed(limit, upper=False):
            self._add(rule, label, values[worst], limit, self.t[worst])

    def _add(self, rule: str, label: str, worst: float, limit: float, time: float) -> None:
        reserve = self.reserve_mm if rule in TUBE_RULES else 0.0
        self.found.append(
            Violation(
                label, float(worst), float(limit), RULES[rule].unit, float(time), rule, reserve
            )
        )
