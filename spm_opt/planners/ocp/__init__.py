"""Optimal-control planners: minimum time, energy or jerk through the landmarks, on the cut,
within the actuators' limits (CasADi + IPOPT).

Two transcriptions. ``ocp-min-time`` works in path coordinates
(:mod:`~spm_opt.planners.ocp.path_planner`): the contour's arc length is the independent
variable, the cut's speed along it and a lateral offset within the tube are the states, and
there are no free durations, so IPOPT converges in ~25 iterations (56 in the time domain on
the paper's flap) to a cut that passes the landmarks without stopping. The others transcribe
the motion on a grid of phases whose durations are variables
(:mod:`~spm_opt.planners.ocp.transcription`): their objectives are integrals over time and
their timing may be fixed. Every limit the time-domain planners keep is declared once
(:mod:`~spm_opt.planners.ocp.constraints`); the NLP is built once per shape
(:mod:`~spm_opt.planners.ocp.nlp`) and solved by IPOPT (:mod:`~spm_opt.planners.ocp.ipopt`)
until the evaluator finds the plan clean (:mod:`~spm_opt.planners.ocp.refinement`,
:class:`~spm_opt.planners.ocp.planner.OcpPlanner`). This module registers the four
planners.

Objectives: total time (``ocp-min-time``); ∫ τᵀτ dt (``ocp-min-energy``; with a linear
current map this is proportional to the copper losses ∫ I²R dt); ∫ jerkᵀjerk dt
(``ocp-min-jerk``); or a weighted mix (``ocp-mix``). Minimum time and the mix leave the
durations free; minimum energy keeps the problem's total duration as a maximum
("bounded": gravity holding dominates this robot's torques, so a shorter cut can cost less
effort); minimum jerk keeps the total ("total"; "segments" keeps every segment's).

Starts: ``ocp-min-time`` in path coordinates starts at 80 % of the speed limits along the
contour. In the time domain (``transcription = "time"``) it starts from toppra's
time-optimal parameterisation of the contour
(:func:`~spm_opt.planners.toppra.time_optimal_guess`, ~10 ms), and from the
contour-following guess if IPOPT fails from there (on the paper's flap the near-optimal
start found 37.87 s, the contour-following one 38.09 s). The others start from the
minimum-time plan re-timed to their durations (:mod:`~spm_opt.planners.ocp.guess`).
"""

from spm_opt.planners.ocp.planner import OcpPlanner
from spm_opt.planners.ocp.settings import MIN_TIME_JERK_WEIGHT, OcpSettings
from spm_opt.planners.registry import register
from spm_opt.planners.toppra import time_optimal_guess

MIN_TIME = register(
    OcpPlanner(
        "ocp-min-time",
        # in path coordinates: 25 iterations and 37.98 s on the paper's flap, against the
        # time-domain transcription's 56 iterations (from toppra's start) and 37.92 s
        OcpSettings(
            timing="free",
            time_weight=1.0,
            jerk_weight=MIN_TIME_JERK_WEIGHT,
            transcription="path",
            nodes_per_phase=4,
        ),
        start=time_optimal_guess,
    )
)
MIN_ENERGY = register(
    # min-time's margin, so that its plan (the start) is feasible here; the grid of
    # min-jerk: with min-time's (10 middle intervals, one check) the re-solves after a
    # tightened tube failed on the five-landmark and the large flaps (1000 iterations);
    # up to 1000 iterations a solve: on small flaps with tight tubes the effort falls
    # slowly, in short steps (IPOPT's steps cut to 5-50 % for a hundred iterations), and 3
    # of a sample of 18 varied flaps took 383-542 iterations in their two solves
    OcpPlanner(
        "ocp-min-energy",
        OcpSettings(
            energy_weight=1.0,
            jerk_weight=1e-4,
            timing="bounded",
            nodes_per_phase=16,
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
        OcpSettings(jerk_weight=1.0, nodes_per_phase=16, checks_per_interval=3, margin=0.02),
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
            checks_per_interval=3,
            margin=0.02,
        ),
        start=MIN_TIME.plan,
    )
)
