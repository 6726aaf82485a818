"""The identification's report: its summary in Markdown, one table of what the logs
determine, and its torque-prediction figure."""

from __future__ import annotations

import dataclasses

import numpy as np
from matplotlib.figure import Figure

from spm_opt.base.markdown import markdown_table
from spm_opt.identify.estimate import Identification
from spm_opt.identify.robot_file import efficiency_reason, efficiency_sentence
from spm_opt.identify.samples import Samples
from spm_opt.identify.validate import filtered_prediction, subset
from spm_opt.model.params import Robot
from spm_opt.model.regressor import STANDARD_PARAMETERS, standard_parameters, unit

Prediction = tuple[str, np.ndarray, np.ndarray]
"""Where the torques were predicted, and the RMS error per joint (2,), N·m, of the prior and
of the identified robot."""


def parameter_rows(identification: Identification, prior_robot: Robot) -> list[list[str]]:
    """The table's rows: each base parameter, the gear efficiency and each standard
    parameter no motion shows: parameter, estimate ± standard error, prior, identified,
    why, unit."""
    ident = identification
    rows = [
        [name, f"{value:.4g} ± {error:.2g}", f"{prior:.4g}", "yes" if ok else "no", why, unit_]
        for (name, unit_, prior, value, error, ok), why in zip(
            ident.base_rows(), ident.reasons(), strict=True
        )
    ]
    name, unit_, prior, value, error, ok = ident.efficiency_row()
    rows.append(
        [name, f"{value:.4g} ± {error:.2g}", f"{prior:.4g}", "yes" if ok else "no"]
        + [efficiency_reason(ident), unit_]
    )
    priors = dict(zip(STANDARD_PARAMETERS, standard_parameters(prior_robot), strict=True))
    written = dict(zip(STANDARD_PARAMETERS, ident.standard, strict=True))
    for name in ident.unseen:
        kept = bool(np.isclose(written[name], priors[name], rtol=1e-6, atol=1e-12))
        why = (
            "not seen by any motion: stays at its prior"
            if kept
            else "not seen by any motion: moved by the physical constraints"
        )
        value, prior = written[name] + 0.0, priors[name] + 0.0  # no "-0"
        rows.append([name, f"{value:.4g}", f"{prior:.4g}", "no", why, unit(name)])
    return rows


def report_markdown(
    identification: Identification,
    prior_robot: Robot,
    predictions: list[Prediction],
    current_unit_nm: float,
) -> str:
    """The identification's summary: one table of the parameters (estimate ± standard
    error, prior, identified and why), the physical constraints that bind, and the torque
    predictions on each of ``predictions``' stretches; ``current_unit_nm``: one Present
    Current unit at the output, N·m."""
    ident = identification
    header = ["parameter", "estimate ± std. error", "prior", "identified", "why", "unit"]
    lines = [
        "# Identification",
        "",
        f"{ident.duration_s:.1f} s of log fitted, {ident.samples} samples after filtering; "
        f"condition number {ident.condition_number:.3g}; residual standard deviations "
        f"{ident.residual_std_nm[0]:.4f} and {ident.residual_std_nm[1]:.4f} N·m, against one "
        f"current unit of {current_unit_nm:.4f} N·m at the output.",
        "",
        "Each base parameter (a combination of the robot file's parameters the torques "
        "determine) is estimated physically consistent: masses > 0, each body's inertia "
        "positive definite with the triangle inequalities, friction and rotor inertia ≥ 0 "
        "(the unconstrained weighted least squares' standard errors). One counts as "
        "identified when it is off its bound, not moved by more than one standard error by "
        "the constraints, and its 95 % interval, two standard errors, lies within 10 % of it; "
        "the gear efficiency η when its two standard errors lie within 10 % of the loss "
        "1 − η. The standard errors allow for the correlation of neighbouring rows (their "
        f"variances × {ident.correlation_factor:.3g}). The seconds of log a parameter needs "
        "extrapolate this motion's length by 1/√length; one whose torques stay far below the "
        "residuals needs a livelier motion, not a longer one.",
        "",
        f"Gear efficiency: {efficiency_sentence(ident)}",
        "",
        *markdown_table(header, parameter_rows(ident, prior_robot)),
        "",
        "Physical constraints that hold the estimates back: "
        f"{'; '.join(ident.active) or 'none'}. In the robot file's fit (the prior settles "
        f"what the logs leave open): {'; '.join(ident.file_active) or 'none'}.",
        "",
        "Torque prediction (RMS of measured − predicted, filtered as for the fit, N·m):",
        "",
        *markdown_table(
            ["samples", "prior θ1", "prior θ2", "identified θ1", "identified θ2"],
            [
                [label, *(f"{value:.4f}" for value in (*prior, *identified))]
                for label, prior, identified in predictions
            ],
        ),
    ]
    return "\n".join(lines) + "\n"


def prediction_figure(
    prior: Robot, identified: Robot, stretches: list[tuple[Samples, bool]]
) -> Figure:
    """Measured torques against the prior's and the identified robot's predictions (N·m),
    filtered as for the fit, per joint over time (s): ``stretches`` in the order logged, each
    with whether it was held out of the fit (shaded). Every sample is drawn, also where a
    joint turns slower than the fit's minimum speed."""
    figure = Figure(figsize=(11, 6), layout="constrained")
    axes = figure.subplots(2, 1, sharex=True)
    start, shaded = 0.0, []
    curves: dict[str, list[np.ndarray]] = {"t": [], "measured": [], "prior": [], "identified": []}
    for samples, held in stretches:
        every = dataclasses.replace(samples, min_speed_rad_s=0.0)
        for run, rate in zip(every.runs, every.rates_hz, strict=True):
            part = subset(every, [(run, rate)])
            measured = part.parallel(part.torque)
            t = start + np.arange(len(measured)) * part.decimation / rate
            curves["t"].append(np.append(t, np.nan))
            curves["measured"].append(np.vstack([measured, np.full(2, np.nan)]))
            for name, robot in (("prior", prior), ("identified", identified)):
                values = filtered_prediction(robot, part)
                curves[name].append(np.vstack([values, np.full(2, np.nan)]))
            if held:
                shaded.append((start, t[-1]))
            start = t[-1] + part.decimation / rate
    t = np.concatenate(curves["t"])
    for joint, axis in enumerate(axes):
        axis.plot(t, np.concatenate(curves["measured"])[:, joint], "k-", lw=1.2, label="measured")
        axis.plot(t, np.concatenate(curves["prior"])[:, joint], "C3--", lw=1.0, label="prior")
        axis.plot(
            t, np.concatenate(curves["identified"])[:, joint], "C0-", lw=1.0, label="identified"
        )
        for k, (low, high) in enumerate(shaded):
            label = "held out of the fit" if k == 0 else None
            axis.axvspan(low, high, color="0.85", zorder=0, label=label)
        axis.set_ylabel(f"τ{joint + 1} (N·m)")
        axis.set_title(f"actuator {joint + 1}", fontsize=10)
        axis.grid(True, alpha=0.3)
        axis.legend(loc="center left", bbox_to_anchor=(1.01, 0.5), fontsize=8)
    axes[1].set_xlabel("time (s)")
    figure.suptitle(
        "Torque prediction: measured against the prior and the identified robot\n"
        f"(low-passed at {stretches[0][0].cutoff_hz:g} Hz as for the fit; logs one after the "
        "other; the shaded stretches were not fitted)",
        fontsize=11,
    )
    return figure
