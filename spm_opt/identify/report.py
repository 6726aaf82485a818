"""The identification's report: its summary in Markdown and its torque-prediction figure."""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure

from spm_opt.base.markdown import markdown_table
from spm_opt.identify.estimate import Identification
from spm_opt.identify.robot_file import efficiency_sentence
from spm_opt.identify.samples import Samples
from spm_opt.identify.validate import filtered_prediction
from spm_opt.model.params import Robot


def report_markdown(
    identification: Identification,
    prior_rms: np.ndarray,
    identified_rms: np.ndarray,
    on: str,
    current_unit_nm: float,
) -> str:
    """The identification's summary: the base parameters, the log each would need, and the
    torque predictions; ``current_unit_nm``: one Present Current unit at the output."""
    ident = identification
    rows = [
        [
            name,
            f"{prior:.4g}",
            f"{value:.4g}",
            f"{error:.2g}",
            "yes" if ok else "no",
            f"{seconds:.3g}" if np.isfinite(seconds) else "never",
            unit_,
        ]
        for (name, unit_, prior, value, error, ok), seconds in zip(
            [*ident.base_rows(), ident.efficiency_row()],
            [*ident.seconds_for_identification(), ident.seconds_for_efficiency()],
            strict=True,
        )
    ]
    header = ["base parameter", "prior", "estimate", "std. error", "identified", "log for 10 %, s"]
    lines = [
        "# Identification",
        "",
        f"{ident.duration_s:.1f} s of log, {ident.samples} samples after filtering; condition "
        f"number {ident.condition_number:.3g}; residual standard deviations "
        f"{ident.residual_std_nm[0]:.4f} and {ident.residual_std_nm[1]:.4f} N·m, against one "
        f"current unit of {current_unit_nm:.4f} N·m at the output.",
        "",
        "A base parameter counts as identified when its 95 % interval, two standard errors, "
        "lies within 10 % of its value; the gear efficiency η when its two standard errors lie "
        "within 10 % of the loss 1 − η. The standard errors allow for the correlation of "
        f"neighbouring rows (their variances × {ident.correlation_factor:.3g}). The log for "
        "10 % extrapolates this motion's length by 1/√length; a parameter whose torques stay "
        "far below the residuals needs a livelier motion, not a longer one.",
        "",
        f"Gear efficiency: {efficiency_sentence(ident)}",
        "",
        f"Not identifiable from any motion: {', '.join(ident.unseen) or 'none'} (they leave "
        "no trace in the torques). Every other parameter of the robot file shows only in the "
        "combinations below; the prior settles how a combination splits.",
        "",
        *markdown_table([*header, "unit"], rows),
        "",
        f"Torque prediction on {on} (RMS of measured − predicted, filtered as for the fit):",
        "",
        *markdown_table(
            ["robot", "θ1 N·m", "θ2 N·m"],
            [
                ["prior (the problem's robot)", f"{prior_rms[0]:.4f}", f"{prior_rms[1]:.4f}"],
                ["identified", f"{identified_rms[0]:.4f}", f"{identified_rms[1]:.4f}"],
            ],
        ),
    ]
    return "\n".join(lines) + "\n"


def prediction_figure(prior: Robot, identified: Robot, samples: Samples) -> Figure:
    """Measured torques against the prior's and the identified robot's predictions (N·m),
    filtered as for the fit, per joint, over the time the kept samples span (s): the
    stretches where a joint turns slower than the samples' minimum speed are left out and
    the runs follow each other."""
    figure = Figure(figsize=(9, 5.5), layout="constrained")
    axes = figure.subplots(2, 1, sharex=True)
    measured = samples.parallel(samples.torque)
    t = np.arange(len(measured)) * samples.decimation / float(np.median(samples.rates_hz))
    predictions = {
        name: filtered_prediction(robot, samples)
        for name, robot in (("prior", prior), ("identified", identified))
    }
    for joint, axis in enumerate(axes):
        axis.plot(t, measured[:, joint], "k-", lw=1.0, label="measured")
        for (name, values), style in zip(predictions.items(), ("--", "-"), strict=True):
            rms = float(np.sqrt(np.mean((measured[:, joint] - values[:, joint]) ** 2)))
            axis.plot(t, values[:, joint], style, lw=1.0, label=f"{name} (RMS error {rms:.4f} N·m)")
        axis.set_ylabel(f"τ{joint + 1} (N·m)")
        axis.set_title(f"actuator {joint + 1}", fontsize=10)
        axis.grid(True, alpha=0.3)
        axis.legend(loc="center left", bbox_to_anchor=(1.01, 0.5), fontsize=8)
    axes[1].set_xlabel("time while both joints move (s)")
    figure.suptitle(
        "Torque prediction: measured against the prior and the identified robot\n"
        f"(low-passed at {samples.cutoff_hz:g} Hz as for the fit; stretches where a joint "
        f"turns slower than {samples.min_speed_rad_s:g} rad/s left out)",
        fontsize=11,
    )
    return figure
