"""The comparison's columns, each with its heading, axis label, unit and format written once.

Every table and figure that shows a column (the comparison, the sweeps) takes its words
from here:

    from spm_opt.report.columns import COLUMN, COLUMNS, HEADINGS
    heading, axis_label = HEADINGS["max_tool_speed_mm_s"]
    # "max tool mm/s", "max tool speed (mm/s)"
"""

from __future__ import annotations

import math
from typing import NamedTuple


class Column(NamedTuple):
    """How one column is shown.

    Attributes
    ----------
    heading : str
        Short table heading, unit included ("max dev. mm").
    label : str
        Axis label or figure title, unit in parentheses ("max contour deviation (mm)").
    unit : str
        The unit of its values ("" for a ratio, a count or text).
    format : str
        ``str.format`` pattern for one value in a table.
    """

    heading: str
    label: str
    unit: str
    format: str = "{}"

    def show(self, value: object) -> str:
        """``value`` as a table cell: formatted, or "—" for NaN or None (no value)."""
        if value is None or (isinstance(value, float) and math.isnan(value)):
            return "—"
        return self.format.format(value)


COLUMN: dict[str, Column] = {
    "planner": Column("planner", "planner", ""),
    "status": Column("status", "status", ""),
    "solve_time_s": Column("solve s", "solve time (s)", "s", "{:.3g}"),
    "wall_time_s": Column("wall s", "wall time (s)", "s", "{:.3g}"),
    "duration_s": Column("duration s", "duration (s)", "s", "{:.2f}"),
    "duration_over_lower_bound": Column("over bound", "duration / lower bound", "", "{:.4f}"),
    "peak_torque_1_nm": Column("peak τ1 N·m", "peak torque, joint 1 (N·m)", "N·m", "{:.3f}"),
    "peak_torque_2_nm": Column("peak τ2 N·m", "peak torque, joint 2 (N·m)", "N·m", "{:.3f}"),
    "rms_torque_1_nm": Column("RMS τ1 N·m", "RMS torque, joint 1 (N·m)", "N·m", "{:.4f}"),
    "rms_torque_2_nm": Column("RMS τ2 N·m", "RMS torque, joint 2 (N·m)", "N·m", "{:.4f}"),
    "energy_j": Column("energy J", "energy (J)", "J", "{:.4f}"),
    "effort_n2m2s": Column("∫τᵀτ N²m²s", "effort ∫τᵀτ dt (N²·m²·s)", "N²·m²·s", "{:.4f}"),
    "peak_joint_speed_over_limit": Column(
        "joint speed / limit", "peak joint speed / limit", "", "{:.3f}"
    ),
    "max_contour_deviation_mm": Column("max dev. mm", "max contour deviation (mm)", "mm", "{:.3g}"),
    "rms_contour_deviation_mm": Column("RMS dev. mm", "RMS contour deviation (mm)", "mm", "{:.3g}"),
    "max_tool_speed_mm_s": Column("max tool mm/s", "max tool speed (mm/s)", "mm/s", "{:.3f}"),
    "mean_tool_speed_mm_s": Column("mean tool mm/s", "mean tool speed (mm/s)", "mm/s", "{:.3f}"),
    "tool_speed_cv": Column("tool CV", "tool speed coefficient of variation", "", "{:.3f}"),
    "rms_jerk_1_rad_s3": Column(
        "RMS jerk 1 rad/s³", "RMS jerk, joint 1 (rad/s³)", "rad/s³", "{:.3g}"
    ),
    "rms_jerk_2_rad_s3": Column(
        "RMS jerk 2 rad/s³", "RMS jerk, joint 2 (rad/s³)", "rad/s³", "{:.3g}"
    ),
    "max_landmark_error_mm": Column(
        "landmark err. mm", "max distance from a landmark (mm)", "mm", "{:.3g}"
    ),
    "violations": Column("violations", "violations", ""),
    "error": Column("error", "error", ""),
}
"""Every column of the comparison table, in order, by name."""

COLUMNS: tuple[str, ...] = tuple(COLUMN)
"""The comparison table's columns, in order."""

DERIVED: dict[str, Column] = {
    "peak_torque_nm": Column("peak τ N·m", "peak torque, larger joint (N·m)", "N·m", "{:.3f}"),
    "rms_jerk_rad_s3": Column(
        "RMS jerk rad/s³", "RMS jerk, larger joint (rad/s³)", "rad/s³", "{:.3g}"
    ),
    "violation_count": Column("violations", "violations", "", "{:d}"),
}
"""Columns computed from the table's own: the larger joint's peak torque and RMS jerk, and
the number of violations."""

HEADINGS: dict[str, tuple[str, str]] = {
    name: (column.heading, column.label) for name, column in {**COLUMN, **DERIVED}.items()
}
"""Every column, the table's and the derived ones: name → (table heading, axis label)."""


def column(name: str) -> Column:
    """How the column ``name`` (one of :data:`COLUMNS` or :data:`DERIVED`) is shown."""
    return COLUMN[name] if name in COLUMN else DERIVED[name]
