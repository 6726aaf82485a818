"""The identified robot as the text of a robot file, the estimates in its comments."""

from __future__ import annotations

from spm_opt.identify.estimate import Identification
from spm_opt.identify.loop import LoopEstimate
from spm_opt.model.params import robot_toml
from spm_opt.model.regressor import STANDARD_PARAMETERS


def robot_file_text(identification: Identification, loops: LoopEstimate, name: str) -> str:
    """The identified robot, its actuator loops from ``loops``, as the text of a robot file,
    the estimates in comments."""
    ident = identification
    lines = [
        f"# Identified by spm-opt identify from {ident.duration_s:.1f} s of log "
        f"({ident.samples} samples); condition number {ident.condition_number:.3g}; "
        f"residual standard deviations {ident.residual_std_nm[0]:.4f} and "
        f"{ident.residual_std_nm[1]:.4f} N m.",
        "# Base parameters (weighted least squares): estimate +- standard error [prior], the "
        f"errors with the residuals' correlation factor {ident.correlation_factor:.3g};",
        "# identified when two errors (a 95 % interval) are at most 10 % of the value.",
    ]
    for base_name, base_unit, prior, value, error, ok in ident.base_rows():
        status = "identified" if ok else "NOT identified"
        lines.append(
            f"#   {value: .5g} +- {error:.2g} {base_unit} [{prior:.5g}] {status}: {base_name}"
        )
    lines.append(_efficiency_comment(ident))
    drive = dict(zip(STANDARD_PARAMETERS, ident.standard, strict=True))
    lines.append(
        "# Not in the robot file: the drives' offsets "
        f"{drive['offset.theta1']:.4g} and {drive['offset.theta2']:.4g} N m."
    )
    lines += loops.comment_lines()
    return "\n".join(lines) + "\n" + robot_toml(loops.robot(ident.robot), name)


def _efficiency_comment(ident: Identification) -> str:
    """The robot file's comment on the gear efficiency."""
    return (
        f"# Gear efficiency: {ident.efficiency:.4g} +- {ident.efficiency_error:.2g} "
        f"[{ident.efficiency_prior:.4g}]. {efficiency_sentence(ident)}"
    )


def efficiency_sentence(ident: Identification) -> str:
    """What the logs say of the gear efficiency η, and the identified robot's."""
    loss = 1.0 - ident.efficiency
    if ident.efficiency_identified:
        return (
            "Identified (the loss 1 − η to 10 % at 95 %): the identified robot's η is "
            f"{ident.efficiency:.4g}."
        )
    if ident.efficiency_significant:
        return (
            f"Not identified to 10 % of the loss 1 − η at 95 %, but the loss is "
            f"{loss / ident.efficiency_error:.1f} standard errors: the identified robot's η is "
            f"{ident.efficiency:.4g}."
        )
    return (
        "The logs do not tell the gear train from a lossless one: the identified robot's η is "
        "1 (its losses show as friction). A motion where the load drives the motors back "
        "(braking, lowering against gravity) shows it."
    )
