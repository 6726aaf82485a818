"""The identified robot as the text of a robot file, the estimates in its comments."""

from __future__ import annotations

import numpy as np

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
        "# Base parameters, physically consistent: estimate +- standard error (of the "
        "unconstrained weighted least squares,",
        f"# with the residuals' correlation factor {ident.correlation_factor:.3g}) [prior]; "
        "identified when off its bound, not moved by the constraints",
        "# and two errors (a 95 % interval) at most 10 % of the value.",
    ]
    for (base_name, base_unit, prior, value, error, ok), why in zip(
        ident.base_rows(), ident.reasons(), strict=True
    ):
        status = "identified" if ok else "NOT identified"
        lines.append(
            f"#   {value: .5g} +- {error:.2g} {base_unit} [{prior:.5g}] {status} ({why}): "
            f"{base_name}"
        )
    lines.append(_efficiency_comment(ident))
    lines.append(
        "# Physical constraints holding back the estimates: "
        f"{'; '.join(ident.active) or 'none'}; this file's fit: "
        f"{'; '.join(ident.file_active) or 'none'}."
    )
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


def efficiency_reason(ident: Identification) -> str:
    """Why the gear efficiency η is identified or not, in a few words."""
    loss = 1.0 - ident.efficiency
    share = 2.0 * ident.efficiency_error / loss if loss > 0.0 else np.inf
    if ident.efficiency_identified:
        return f"2 s.e. within 10 % of the loss 1 − η ({100 * share:.2g} %)"
    if ident.efficiency_significant:
        return (
            f"the loss is {loss / ident.efficiency_error:.1f} s.e. (kept), but 2 s.e. are "
            f"{100 * share:.3g} % of it"
        )
    return "not told from a lossless gear train: η = 1 kept"


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
