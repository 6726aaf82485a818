"""A problem file on a generated skull (:mod:`spm_opt.skull.generate`): the meshes, the flap
as a 3D Slicer markups file, and the problem that plans it.

    python -m spm_opt.skull.example_problem --out PROBLEM.toml [--data DIR] [--seed 0]
        [--frame RAS|LPS] [--subdivisions 5] [--registration] [--robot PATH]

writes the problem file, and the meshes and the markups into DIR (default: the problem's
folder). ``--registration`` gives the image-to-robot transform as fiducials in both frames
(four points on the outer surface: front, left, right and top) instead of the matrix;
``--robot`` is the robot file as the problem names it (relative to the problem's folder).
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

import numpy as np

from spm_opt.base.files import write_atomically
from spm_opt.model.rigid import apply
from spm_opt.skull.frames import to_ras
from spm_opt.skull.generate import generate_skull, write_example

SEGMENT_DURATION_S = 10.0
LIMITS = {
    "max_joint_speed_rpm": 13.7,
    "max_joint_acceleration_rad_s2": 1.0,
    "max_joint_jerk_rad_s3": 10.0,
    "max_tool_speed_mm_s": 3.0,
    "contour_tolerance_mm": 0.1,
    "max_tool_incidence_deg": 30.0,
    "min_bone_thickness_mm": 3.0,
}
"""The paper's flap's limits, and the bone's: no cut into bone meeting the tool at more than
30°, nor over bone thinner than 3 mm."""
DEPTH_MARGIN_MM = 0.5


def write_example_problem(
    path: Path,
    data_dir: Path | None = None,
    seed: int = 0,
    frame: str = "RAS",
    subdivisions: int = 5,
    registration: bool = False,
    robot: str = "robots/prototype.toml",
) -> Path:
    """Write a generated skull and its flap into ``data_dir`` (default: the problem's folder)
    and the problem file at ``path``, which names ``robot`` as given. Returns ``path``."""
    path = Path(path)
    data_dir = path.parent if data_dir is None else Path(data_dir)
    data_dir.mkdir(parents=True, exist_ok=True)
    example = write_example(data_dir, seed, frame, subdivisions)
    matrix = np.asarray(example["image_to_robot_mm"])

    def relative(file: object) -> str:
        return Path(os.path.relpath(Path(str(file)), path.parent)).as_posix()

    if registration:
        ras = _fiducials(seed, subdivisions)
        transform = (
            "[skull.registration]  # fiducials in both frames: front, left, right and top\n"
            f"image_fiducials_mm = {_rows(to_ras(ras, frame))}  # in {frame}\n"
            f"robot_fiducials_mm = {_rows(apply(matrix, ras))}\n"
        )
    else:
        transform = f"image_to_robot = {_rows(matrix)}  # image RAS mm -> robot mm\n"
    limits = "".join(f"{key} = {value:g}\n" for key, value in LIMITS.items())
    text = (
        f"# A flap on a generated skull (python -m spm_opt.skull.example_problem, seed {seed}):\n"
        "# the outer and inner surfaces as STL, the flap as a 3D Slicer markups file.\n"
        'name = "skull_flap"\n'
        f'description = "A flap on a generated skull (seed {seed}), planned on its outer '
        'surface from a 3D Slicer markups file"\n'
        f'robot = "{robot}"\n'
        f"segment_durations_s = {[SEGMENT_DURATION_S] * 5}\n"
        f'landmarks_file = "{relative(example["markups"])}"\n\n'
        "[skull]\n"
        f'outer_mesh = "{relative(example["outer"])}"\n'
        f'inner_mesh = "{relative(example["inner"])}"\n'
        f'frame = "{frame}"\n'
        f"depth_margin_mm = {DEPTH_MARGIN_MM:g}  # the tool tip's depth: the inner surface + this\n"
        + transform
        + "\n[limits]\n"
        + limits
    )
    write_atomically({path: text})
    return path


def _fiducials(seed: int, subdivisions: int) -> np.ndarray:
    """Four points on the generated outer surface (RAS, mm): its front, left, right, top."""
    vertices = np.asarray(generate_skull(seed, subdivisions).outer.vertices)
    picks = [np.argmax(vertices[:, 1]), np.argmin(vertices[:, 0]), np.argmax(vertices[:, 0])]
    return vertices[picks + [np.argmax(vertices[:, 2])]]


def _rows(values: np.ndarray) -> str:
    """A matrix as a TOML array of rows, one a line: 12 decimals, no -0.0."""
    rows = (", ".join(f"{round(float(v), 12) + 0.0:.12g}" for v in row) for row in values)
    return "[\n" + "".join(f"    [{row}],\n" for row in rows) + "]"


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--data", type=Path, default=None)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--frame", default="RAS", choices=("RAS", "LPS"))
    parser.add_argument("--subdivisions", type=int, default=5)
    parser.add_argument("--registration", action="store_true")
    parser.add_argument("--robot", default="robots/prototype.toml")
    args = parser.parse_args(argv)
    path = write_example_problem(
        args.out,
        args.data,
        args.seed,
        args.frame,
        args.subdivisions,
        args.registration,
        args.robot,
    )
    print(f"written {path}")


if __name__ == "__main__":
    main()
