"""Reading a skull mesh from imaging: any format trimesh reads, in mm, in RAS or LPS.

3D Slicer writes models in LPS unless told otherwise and may state the frame at the head of
the file (``SPACE=RAS`` or ``SPACE=LPS``: a binary STL's 80-byte header, an ASCII STL's
``solid`` line, a comment line of OBJ, PLY or OFF); a stated frame must be the one the
problem names. What trimesh can repair is repaired (merged vertices, degenerate and duplicate
triangles, winding, holes of three or four edges, outward normals); holes larger than that
are kept (a CT skull is open at its foramina), but edges shared by more than two triangles
are refused: the ray casts could not tell the skull's inside from its outside there.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from spm_opt.base.errors import InputError, require
from spm_opt.skull.frames import check_frame, frame_matrix

if TYPE_CHECKING:
    import trimesh

MAX_MESH_BYTES = 500 * 2**20
"""Largest mesh file read, bytes (500 MB)."""
MAX_FACES = 5_000_000
"""Most triangles a mesh may have."""
HEADER_BYTES = 4096
"""How much of a file's start is searched for a stated frame, bytes."""
STL_HEADER_BYTES = 80
"""The length of a binary STL's free-text header, bytes."""
_SPACE = re.compile(rb"SPACE\s*=\s*(RAS|LPS)\b", re.IGNORECASE)
_HEADER_LINES = (b"#", b"comment", b"solid")
"""How the lines that may state a frame start: OBJ/OFF comments, PLY comments, ASCII STL."""


def load_mesh(path: Path, frame: str, field: str) -> trimesh.Trimesh:
    """The mesh in the file at ``path``, repaired.

    Parameters
    ----------
    path : Path
        A mesh file trimesh reads (STL, PLY, OBJ, OFF, ...), in mm.
    frame : str
        The image frame the file is in, "RAS" or "LPS"; a frame stated in the file's header
        must agree.
    field : str
        The problem file's key that names the file, to start error messages.

    Returns
    -------
    trimesh.Trimesh
        The mesh, mm, in ``frame``: vertices merged, degenerate and duplicate triangles
        removed, winding made consistent, small holes filled, normals outward.

    Raises
    ------
    InputError
        One line starting ``{field} = '{path}':`` for a missing, oversized, unreadable or
        empty file, too many triangles, a header stating another frame, or non-manifold
        edges.
    """
    trimesh = require("trimesh", "a skull mesh")
    frame = check_frame(frame, "frame")
    path = Path(path)
    where = f"{field} = '{path}'"
    if not path.is_file():
        raise InputError(f"{where}: no such file")
    size = path.stat().st_size
    if size > MAX_MESH_BYTES:
        raise InputError(f"{where}: {size / 2**20:.0f} MB; expected a file of at most 500 MB")
    stated = _stated_frame(path)
    if stated is not None and stated != frame:
        raise InputError(
            f"{where}: the file's header says SPACE={stated} but frame = '{frame}'; "
            "give the frame the file was written in"
        )
    try:
        mesh = trimesh.load(path, force="mesh", process=False)
    except Exception as error:  # trimesh raises many kinds for files it cannot parse
        reason = (str(error).strip().splitlines() or [type(error).__name__])[0][:120]
        raise InputError(
            f"{where}: not a mesh trimesh can read (STL, PLY, OBJ, OFF, ...): {reason}"
        ) from None
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise InputError(
            f"{where}: no triangles read from the file; expected a triangle mesh (STL, PLY, "
            "OBJ, OFF, ...)"
        )
    if len(mesh.faces) > MAX_FACES:
        raise InputError(
            f"{where}: {len(mesh.faces):,} triangles; expected at most {MAX_FACES:,} "
            "(decimate the model)"
        )
    if not np.all(np.isfinite(mesh.vertices)):
        raise InputError(f"{where}: vertices that are not finite numbers (NaN or infinity)")
    _repair(mesh, where)
    return mesh


def to_robot(mesh: trimesh.Trimesh, frame: str, image_to_robot_mm: np.ndarray) -> trimesh.Trimesh:
    """A copy of ``mesh`` in the robot's frame, m.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        A mesh in mm, in the image frame ``frame``.
    frame : str
        "RAS" or "LPS"; LPS is turned to RAS first (x and y negated).
    image_to_robot_mm : ndarray (4, 4)
        The homogeneous transform from the image's RAS coordinates (mm) to the robot's frame
        (mm).

    Returns
    -------
    trimesh.Trimesh
        The moved copy, in metres.
    """
    moved = mesh.copy()
    millimetre = np.diag([1e-3, 1e-3, 1e-3, 1.0])
    moved.apply_transform(
        millimetre @ np.asarray(image_to_robot_mm, dtype=float) @ frame_matrix(frame)
    )
    return moved


def _stated_frame(path: Path) -> str | None:
    """The frame ("RAS" or "LPS") the start of the file states as ``SPACE=...``, or None."""
    with path.open("rb") as stream:
        head = stream.read(HEADER_BYTES)
    lines = [line for line in head.splitlines() if line.lstrip().lower().startswith(_HEADER_LINES)]
    for text in (head[:STL_HEADER_BYTES], *lines):
        stated = _SPACE.search(text)
        if stated:
            return stated.group(1).decode().upper()
    return None


def _repair(mesh: trimesh.Trimesh, where: str) -> None:
    """Repair ``mesh`` in place as far as trimesh can, or raise a one-line InputError."""
    repair = require("trimesh", "a skull mesh").repair
    mesh.merge_vertices()
    mesh.update_faces(mesh.nondegenerate_faces())
    mesh.update_faces(mesh.unique_faces())
    mesh.remove_unreferenced_vertices()
    if len(mesh.faces) == 0:
        raise InputError(f"{where}: every triangle is degenerate (no area)")
    shared = np.bincount(mesh.edges_unique_inverse)
    over = int(np.count_nonzero(shared > 2))
    if over:
        raise InputError(
            f"{where}: {over} non-manifold edges (shared by more than two triangles; at most "
            f"{int(shared.max())}); expected one surface, each edge in at most two triangles"
        )
    repair.fix_winding(mesh)
    repair.fill_holes(mesh)
    repair.fix_inversion(mesh)
    if not mesh.is_watertight and mesh.is_winding_consistent and mesh.volume < 0.0:
        mesh.invert()  # an open skull: small holes barely change the signed volume
