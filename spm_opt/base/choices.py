"""The names and bounds the command line's parser offers, in a module that imports nothing,
so that ``spm-opt --help`` starts without the library (numpy, SciPy, CasADi, pandas...).

The planners' names are those the registry holds once :mod:`spm_opt.planners` is imported
(``tests/test_cli_startup.py`` checks that they agree); the tracking modes and the
sweep's task bound are defined here, where their modules take them from.
"""

from __future__ import annotations

PLANNER_NAMES = (
    "cubic",
    "excitation",
    "ocp-min-energy",
    "ocp-min-jerk",
    "ocp-min-time",
    "ocp-mix",
    "ruckig",
    "toppra",
)
"""Every registered planner's name, sorted (:data:`spm_opt.planners.PLANNERS`)."""
CONTOUR_PLANNER_NAMES = tuple(name for name in PLANNER_NAMES if name != "excitation")
"""The planners that plan the problem's cut, sorted
(:func:`spm_opt.planners.contour_planners`): ``excitation`` plans a motion that identifies
the robot's parameters instead."""
TRACKING_MODES = ("lead", "none")
"""``lead``: goals lead the loop's lag; ``none``: the goal is the reference itself
(:mod:`spm_opt.execution.tracking`)."""
DEFAULT_MAX_TASKS = 100_000
"""Most tasks a sweep may have unless its caller allows more (``max_tasks``): the shipped
sweeps have 24 to 1,200; at seconds to minutes a task, 100,000 take days on a cluster."""
PREDICTION_ACTIONS = ("refuse", "warn")
"""What ``spm-opt execute`` does with a plan whose predicted cut leaves the tube, or whose
predicted run breaks a robot limit (:mod:`spm_opt.verify.predicted_cut`): refuse the run,
or say so and run it."""
