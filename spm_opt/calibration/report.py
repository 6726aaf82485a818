"""The calibration's report: Markdown (the parameters ± their standard errors, the poses'
observability, the fit's residual and the held-out error beside its prediction) and a
figure of the residuals per pose and axis."""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator

from spm_opt.base.markdown import markdown_table
from spm_opt.calibration.run import Calibration, parameter_rows

MM = 1e-3


def report_markdown(calibration: Calibration, robot_name: str) -> str:
    """The report's Markdown for ``calibration`` of the robot ``robot_name``."""
    result, judged = calibration.result, calibration.held_out
    seen = result.observability
    rows = [
        [
            row["name"],
            f"{row['value']:.4f} ± {row['standard_error']:.4f}" if row["identified"] else "0",
            row["unit"],
            "yes" if row["identified"] else "no (not separable from the others)",
        ]
        for row in parameter_rows(calibration)
    ]
    predicted = float(np.sqrt(np.mean(judged.predicted_tre_m**2))) / MM
    lines = [
        f"# Calibration of {robot_name}",
        "",
        f"- Tracker: {calibration.tracker} (data SHA-256 {calibration.data_sha256[:16]}…).",
        f"- Poses fitted: {len(calibration.fitted.readings_rad)}; held out (never fitted): "
        f"{len(calibration.tested.readings_rad)}.",
        f"- Observability of the fitted poses: condition number {seen.condition_number:.1f}, "
        f"O1 {seen.o1 / MM:.3g} mm, O3 {seen.o3 / MM:.3g} mm, O4 {seen.o4 / MM:.3g} mm "
        "(scaled to the marker).",
        f"- Fit residual (FRE): {result.residual_rms_m / MM:.4f} mm RMS; per coordinate "
        f"σ̂ = {result.sigma_m / MM:.4f} mm.",
        f"- Held-out error (TRE, measured): {judged.rms_m / MM:.4f} mm RMS, at most "
        f"{np.max(judged.errors_m) / MM:.4f} mm. It includes the tracker's own error at "
        "those poses.",
        f"- Fitzpatrick's TRE for the rigid registration from σ̂: {predicted:.4f} mm RMS "
        "(a registration's TRE; the kinematic parameters add to it).",
        "",
        *markdown_table(["unknown", "value ± standard error", "unit", "identified"], rows),
        "",
    ]
    return "\n".join(lines)


def residual_figure(calibration: Calibration) -> Figure:
    """Residuals per pose and axis, mm: the fitted poses' and the held-out poses'."""
    result = calibration.result
    fitted = result.residuals_m / MM
    tested = (result.marker(calibration.tested.readings_rad) - calibration.tested.marker_m) / MM
    figure = Figure(figsize=(9, 4.5), layout="constrained")
    axes = figure.subplots(
        1, 2, sharey=True, width_ratios=[max(len(fitted), 1), max(len(tested), 4)]
    )
    for ax, values, title in (
        (axes[0], fitted, "fitted poses (FRE)"),
        (axes[1], tested, "held-out poses (TRE)"),
    ):
        poses = np.arange(1, len(values) + 1)
        for axis, (label, color) in enumerate(
            (("x", "tab:red"), ("y", "tab:green"), ("z", "tab:blue"))
        ):
            ax.plot(poses, values[:, axis], "o", color=color, label=label, markersize=4)
        ax.plot(poses, np.linalg.norm(values, axis=1), "k_", markersize=10, label="distance")
        ax.axhline(0.0, color="0.6", linewidth=0.8)
        ax.set_title(title)
        ax.set_xlabel("pose, in the run's order (count)")
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("tracker minus model (mm)")
    handles, labels = axes[0].get_legend_handles_labels()
    figure.legend(handles, labels, loc="outside lower center", ncols=4, fontsize=9)
    figure.suptitle(
        f"Calibration residuals: FRE {result.residual_rms_m / MM:.3f} mm RMS, "
        f"TRE {calibration.held_out.rms_m / MM:.3f} mm RMS"
    )
    return figure
