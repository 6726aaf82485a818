"""Optimal-control planners: minimum time, energy or jerk through the landmarks, on the cut,
within the actuators' limits (CasADi + FATROP or IPOPT).

Two transcriptions. Where the problem has a contour tube, every planner works in path
coordinates (:mod:`~spm_opt.planners.ocp.path_planner`): the contour's arc length is the
independent variable, the cut's speed along it and a lateral offset within the tube are the
states, and there are no free durations, so the solver converges in 24-33 iterations (56 to
111 in the time domain on the paper's flap) to a cut that passes the landmarks without
stopping; the objectives over time are integrals over the arc length with dt = du / √β.
The NLP is assembled stage by stage (:mod:`~spm_opt.planners.ocp.path_assembly`); FATROP,
which exploits that structure, solves it where the timing is free (minimum time, the mix),
IPOPT where a row holds the time (:mod:`~spm_opt.planners.ocp.path_solver`).
Without a tube (the hardware run, which cuts nothing) they transcribe the motion on a grid
of phases whose durations are variables (:mod:`~spm_opt.planners.ocp.transcription`), the
cut free in joint space; ``transcription`` in ``[planner.NAME]`` chooses either. Every limit
the time-domain planners keep is declared once (:mod:`~spm_opt.planners.ocp.constraints`);
the NLP is built once per shape (:mod:`~spm_opt.planners.ocp.nlp`) and solved by IPOPT
(:mod:`~spm_opt.planners.ocp.ipopt`) until the evaluator finds the plan clean
(:mod:`~spm_opt.planners.ocp.refinement`,
:class:`~spm_opt.planners.ocp.planner.OcpPlanner`). This module registers the four
planners.

Objectives: total time (``ocp-min-time``); ∫ τᵀτ dt (``ocp-min-energy``; with a linear
current map this is proportional to the copper losses ∫ I²R dt); ∫ jerkᵀjerk dt
(``ocp-min-jerk``); or a weighted mix (``ocp-mix``). Minimum time and the mix leave the
durations free; minimum energy keeps the problem's total duration as a maximum
("bounded": gravity holding dominates this robot's torques, so a shorter cut can cost less
effort); minimum jerk keeps the total ("total"; "segments" keeps every segment's).

Starts, in path coordinates: 80 % of the speed limits along the contour, re-timed to the
problem's durations where the timing keeps them (starting minimum energy from the
minimum-time plan's solution instead saved 1-5 iterations, less than that plan costs). In
the time domain
``ocp-min-time`` starts from toppra's time-optimal parameterisation of the contour
(:func:`~spm_opt.planners.toppra.guess.time_optimal_guess`, ~10 ms), and from the
contour-following guess if IPOPT fails from there; the others start from the minimum-time
plan re-timed to their durations (:mod:`~spm_opt.planners.ocp.guess`).
"""

from spm_opt.planners.ocp.planner import OcpPlanner
from spm_opt.planners.ocp.settings import MIN_TIME_JERK_WEIGHT, OcpSettings
from spm_opt.planners.registry import register
from spm_opt.planners.toppra.guess import time_optimal_guess

MIN_TIME = register(
    OcpPlanner(
        "ocp-min-time",
        # in path coordinates: 33 iterations (FATROP) and 37.976 s on the paper's flap with
        # the default 0.5 % margin, against the time-domain transcription's 56 iterations
        # (from toppra's start) and 37.92 s. A 0.2 % margin: 1.009 of the lower bound
        # (0.5 %: 1.012), and the paper's, five-landmark, large, skull and hardware flaps
        # still clean without a re-solve (0.1 % too)
        OcpSettings(
            timing="free",
            time_weight=1.0,
            jerk_weight=MIN_TIME_JERK_WEIGHT,
            nodes_per_phase=4,
            margin=0.002,
        ),
        start=time_optimal_guess,
    )
)
MIN_ENERGY = register(
    # min-time's margin, so that its plan (the start) is feasible here; in path
    # coordinates 8 middle intervals: with 4 and 16 its ∫τᵀτ on the skull flap came out
    # above min-time's (0.61663 and 0.61656 against 0.61648), with 8 0.61618. In the time
    # domain 16 (with 8 and 12 the hardware run's cut ran back 0.008 and 0.003 mm; with 10
    # and one check the re-solves after a tightened tube failed on the five-landmark and
    # the large flaps), and up to 1000 iterations a solve: on small flaps with tight tubes
    # the effort falls slowly
    OcpPlanner(
        "ocp-min-energy",
        OcpSettings(
            margin=MIN_TIME.defaults.margin,
            energy_weight=1.0,
            jerk_weight=1e-4,
            timing="bounded",
            nodes_per_phase=16,
            path_intervals=8,
            checks_per_interval=3,
            max_iterations=1000,
        ),
        start=MIN_TIME.plan,
    )
)
MIN_JERK = register(
    # the smoothest cut bulges wide between points: shorter intervals, more checks, and
    # a wider reserve (one check and 0.5 %: ∫jerk² 0.123 against 0.265 rad²/s⁵ on the
    # paper's flap, but 0.23 mm off the contour on the large flap after three re-solves)
    OcpPlanner(
        "ocp-min-jerk",
        OcpSettings(
            jerk_weight=1.0,
            nodes_per_phase=24,
            corner_nodes=16,
            checks_per_interval=3,
            margin=0.02,
        ),
        start=MIN_TIME.plan,
    )
)
MIX = register(
    OcpPlanner(
        "ocp-mix",
        # by default a quick and smooth cut; set the weights in [planner.ocp-mix]
        OcpSettings(
            timing="free",
            time_weight=1.0,
            jerk_weight=1.0,
            nodes_per_phase=16,
            corner_nodes=16,
            checks_per_interval=3,
            margin=0.02,
        ),
        start=MIN_TIME.plan,
    )
)
