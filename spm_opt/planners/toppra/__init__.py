"""Time-optimal motion along the planned contour (toppra), made jerk-limited; this package
registers the ``toppra`` planner.

Path. The contour has a corner at every landmark, so the cut stops there: each segment
between consecutive landmark visits is its own path, from rest to rest, and the segments are
chained. Along a segment the cut point's arc length s (mm, from the segment's first
landmark) parameterises the joint angles q(s): a cubic spline through the inverse kinematics
of ``path_samples`` points of the great-circle arc, exact at the landmarks
(:mod:`spm_opt.planners.path`). q varies on the scale of the skull's radius (~70 mm), so 100
samples keep it within 1e-8 mm of the arc.

Limits (:mod:`~spm_opt.planners.toppra.constraints`), as toppra's linear constraints in the
path acceleration and the squared path speed at ``gridpoints`` points per segment (spaced as
s ∝ ξ² at the ends, where the cut starts and stops), solved by toppra's LP
(:mod:`~spm_opt.planners.toppra.lp`): joint speed, tool speed, joint acceleration and
actuator torque from the one model.

Jerk (:mod:`~spm_opt.planners.toppra.smoothing`). toppra's path acceleration is constant
between gridpoints; its motion is resampled on a uniform time grid and averaged over the
fewest grid steps that keep the joint jerk within its limit.

Retries (:mod:`~spm_opt.planners.toppra.segment`). The smoothed motion is measured and
toppra runs again with the share of any exceeded limit cut by the excess.

Planner (:mod:`~spm_opt.planners.toppra.planner`) and settings
(:mod:`~spm_opt.planners.toppra.settings`, ``[planner.toppra]``). The minimum-time optimal
control's start (:mod:`~spm_opt.planners.toppra.guess`) is toppra's first run on a coarse
grid.
"""

from spm_opt.planners.registry import register
from spm_opt.planners.toppra.planner import ToppraPlanner

register(ToppraPlanner())
