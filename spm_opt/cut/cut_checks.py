"""What a skull from imaging must allow along the cut, checked when a problem is loaded:
every direction the cut uses meets the outer surface once, and the bone under it is thick
enough to cut."""

from __future__ import annotations

import numpy as np

from spm_opt.base.errors import InputError
from spm_opt.cut.contour import Contour
from spm_opt.model.params import MM
from spm_opt.skull.raycast import MeshSurface

SPACING = 0.5 * MM
"""Distance between the checked points along the contour, m."""


def check_cut(
    surface: MeshSurface,
    contour: Contour,
    visit_names: list[str],
    tube: float | None,
    min_thickness: float | None,
) -> None:
    """Raise a one-line InputError naming the stretch (the landmarks it runs between, and how
    far along) where a direction of the cut, or of its tube's edges (``tube``, m), misses
    the outer surface or meets it more than once, or where the bone along the tool's axis
    is thinner than ``min_thickness`` (m). Checked every :data:`SPACING` along each arc's
    great circle, before anything is built on the surface."""
    radius = float(np.min(np.linalg.norm(contour.landmarks, axis=1)))
    arcs, angles = [], []
    for arc, sweep in enumerate(contour.sweep):
        count = max(2, int(np.ceil(sweep * radius / SPACING)) + 1)
        arcs.append(np.full(count, arc))
        angles.append(np.linspace(0.0, sweep, count))
    arc, angle = np.concatenate(arcs), np.concatenate(angles)
    centre = (
        np.cos(angle)[:, None] * contour.start[arc]
        + np.sin(angle)[:, None] * (contour.inplane[arc])
    )
    offset = (tube or 0.0) / radius
    for side in (0.0, -1.0, 1.0):
        directions = centre + side * offset * contour.normal[arc]
        directions /= np.linalg.norm(directions, axis=1, keepdims=True)
        counts = surface.crossings(directions)
        bad = np.flatnonzero(counts != 1)
        if len(bad):
            k = int(bad[0])
            raise InputError(
                f"{stretch(visit_names, arc[k], angle[k] * radius)}: the tool's axis meets the "
                f"outer surface {int(counts[k])} times"
                + ("" if side == 0.0 else " at the tube's edge")
                + "; it must meet it once (a hole in the mesh, or the isocenter misplaced?)"
            )
    if min_thickness is None:
        return
    thickness = surface.thickness(centre)
    thin = np.flatnonzero(~(thickness >= min_thickness))
    if len(thin):
        k = int(thin[np.argmin(np.nan_to_num(thickness[thin], nan=-np.inf))])
        value = "no inner surface" if np.isnan(thickness[k]) else f"{thickness[k] / MM:.2f} mm"
        raise InputError(
            f"{stretch(visit_names, arc[k], angle[k] * radius)}: bone {value} thick along "
            f"the tool's axis, below min_bone_thickness_mm = {min_thickness / MM:g}"
        )


def stretch(visit_names: list[str], arc: int, along: float) -> str:
    """'the cut from A2 to A3, about 12.3 mm along it' (``along`` in m)."""
    return (
        f"the cut from {visit_names[arc]} to {visit_names[arc + 1]}, about "
        f"{along / MM:.1f} mm along it"
    )
