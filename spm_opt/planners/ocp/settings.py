"""The optimal-control planners' settings: the transcription's and IPOPT's, read from the
problem's ``[planner.NAME]`` table over each planner's defaults."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from spm_opt.base.errors import InputError
from spm_opt.planners.ocp.transcription import Grid
from spm_opt.planners.registry import planner_options, settings_from_options
from spm_opt.problem.problem import Problem


@dataclass(frozen=True)
class OcpSettings:
    """The transcription and solver settings, read from the problem's ``[planner.NAME]``.

    Attributes
    ----------
    nodes_per_phase : int
        Intervals along the middle of each segment.
    path_intervals : int
        In path coordinates, the intervals between a segment's end zones (0: as many as
        ``nodes_per_phase``).
    corner_nodes : int
        Intervals in each of the two short phases at a segment's ends.
    checks_per_interval : int
        Check points inside each interval where the path limits are imposed besides the
        nodes, evenly spaced at first (1: the midpoint) and moved where a solution exceeds
        a limit between them.
    margin : float
        Fraction of each limit kept in reserve for the motion between constraint points.
    timing : str
        "free" (every duration a variable: minimum time), "bounded" (the total duration at
        most the problem's), "total" (the problem's total duration kept, its split between
        segments free) or "segments" (each segment's duration as the problem gives it).
    max_iterations : int
    tolerance : float
        The solver's convergence tolerance (IPOPT's or FATROP's).
    acceptable_iterations : int
        IPOPT's ``acceptable_iter``: after this many iterations in a row at its looser
        "acceptable" level it stops early; such a stop is never a plan, but the start of a
        strict re-solve (with 0: never stop early).
    time_weight, energy_weight, jerk_weight : float
        Weights of the total time (s), ∫τᵀτ dt and ∫jerk² dt, each divided by its value at
        the initial guess so that the weights compare like with like.
    print_level : int
        The solver's verbosity (0 silent; IPOPT's 5: every iteration).
    transcription : str
        "path" (the contour's arc length as the independent variable and a lateral offset
        within the tube), "time" (phases of free durations: the cut free in joint space), or
        "auto": "path" where the problem has a contour tube, else "time" (a run without
        cutting: in path coordinates the cut could leave the contour by at most 1 mm). With
        "path", ``corner_nodes`` counts the intervals of the zone at each end of a segment
        and ``path_intervals`` those between; ``checks_per_interval`` and
        ``acceptable_iterations`` do not apply.
    solver : str
        In path coordinates: "fatrop" (FATROP, which exploits the stage-wise structure; it
        needs timing "free", since a fixed timing's time row spans every stage), "ipopt", or
        "auto": FATROP where the timing is free and the solve starts afresh, else IPOPT
        (which continues from a solution's multipliers; FATROP takes none). The time domain
        always uses IPOPT.
    """

    nodes_per_phase: int = 10
    path_intervals: int = 0
    corner_nodes: int = 8
    checks_per_interval: int = 1
    margin: float = 0.005
    timing: str = "total"
    max_iterations: int = 300
    tolerance: float = 1e-7
    acceptable_iterations: int = 15
    time_weight: float = 0.0
    energy_weight: float = 0.0
    jerk_weight: float = 0.0
    print_level: int = 0
    transcription: str = "auto"
    solver: str = "auto"

    _RANGES = {
        "nodes_per_phase": (1, 200),
        "path_intervals": (0, 200),
        "corner_nodes": (1, 50),
        "checks_per_interval": (1, 9),
        "margin": (0.0, 0.5),
        "max_iterations": (1, 100_000),
        "acceptable_iterations": (0, 100_000),
        "tolerance": (1e-12, 1e-2),
        "time_weight": (0.0, 1e6),
        "energy_weight": (0.0, 1e6),
        "jerk_weight": (0.0, 1e6),
        "print_level": (0, 12),
    }

    @classmethod
    def from_problem(cls, problem: Problem, name: str, defaults: OcpSettings) -> OcpSettings:
        """Settings from the problem's ``[planner.NAME]`` table over ``defaults``; one-line
        errors."""
        options = planner_options(problem, name, OPTION_KEYS)
        choices = {"timing": TIMINGS, "transcription": TRANSCRIPTIONS, "solver": SOLVERS}
        settings = settings_from_options(name, defaults, options, cls._RANGES, choices)
        if settings.solver == "fatrop" and settings.timing != "free":
            raise InputError(
                f"planner.{name}.solver = 'fatrop': needs timing = 'free' (this planner's "
                f"is {settings.timing!r}); use 'ipopt' or 'auto'"
            )
        return settings

    @property
    def fatrop(self) -> bool:
        """Whether path coordinates solve with FATROP (else IPOPT)."""
        return self.solver == "fatrop" or (self.solver == "auto" and self.timing == "free")

    @property
    def path_grid(self) -> tuple[int, int]:
        """In path coordinates: the intervals of each end zone and of the middle."""
        return self.corner_nodes, self.path_intervals or self.nodes_per_phase

    def grid(self, segments: int) -> Grid:
        """The time grid of ``segments`` segments: corner, middle and corner phases of
        ``corner_nodes``, ``nodes_per_phase`` and ``corner_nodes`` intervals."""
        corner = self.corner_nodes
        return Grid(segments, (corner, self.nodes_per_phase, corner))


TIMINGS = ("free", "bounded", "total", "segments")
"""The choices of :attr:`OcpSettings.timing`."""
TRANSCRIPTIONS = ("auto", "path", "time")
"""The choices of :attr:`OcpSettings.transcription`."""
SOLVERS = ("auto", "ipopt", "fatrop")
"""The choices of :attr:`OcpSettings.solver`."""
MIN_TIME_JERK_WEIGHT = 1e-6
"""The jerk's weight in minimum time: a tie-breaker between equally fast motions."""
OPTION_KEYS = tuple(f.name for f in dataclasses.fields(OcpSettings))
"""The keys a ``[planner.NAME]`` table of an optimal-control planner may hold."""
