"""A tracker's recording in the formats labs export, and its pairing with a run's dwells."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from spm_opt.base.errors import InputError
from spm_opt.calibration.dwell import dwell_means
from spm_opt.calibration.ndi import record_frames, track_from_frames
from spm_opt.calibration.tracker_files import point_csv_text, read_tracker_file

RNG = np.random.default_rng(5)
TIMES = np.arange(50) / 60.0
POINTS = RNG.uniform(-0.3, 0.3, (50, 3))


def motive_text(units: str, scale: float, lost: set[int]) -> str:
    """A Motive export of one rigid body and one marker, written as its documentation
    describes the layout (positions in ``units``, ``scale`` per metre)."""
    quaternions = Rotation.random(50, random_state=1).as_quat()
    lines = [
        "Format Version,1.23,Take Name,calibration,Capture Frame Rate,60.000000,"
        f"Export Frame Rate,60.000000,Rotation Type,Quaternion,Length Units,{units},"
        "Coordinate Space,Global",
        "",
        ",,Rigid Body,Rigid Body,Rigid Body,Rigid Body,Rigid Body,Rigid Body,Rigid Body,"
        "Rigid Body,Marker,Marker,Marker",
        ",,tool,tool,tool,tool,tool,tool,tool,tool,stray,stray,stray",
        ",,1,1,1,1,1,1,1,1,2,2,2",
        ",,Rotation,Rotation,Rotation,Rotation,Position,Position,Position,Mean Marker Error,"
        "Position,Position,Position",
        "Frame,Time (Seconds),X,Y,Z,W,X,Y,Z,,X,Y,Z",
    ]
    for k, (t, p, q) in enumerate(zip(TIMES, POINTS * scale, quaternions, strict=True)):
        body = ",,,,,,," if k in lost else ",".join(f"{v:.6f}" for v in [*q, *p]) + ",0.0001"
        lines.append(f"{k},{t:.6f},{body},1,2,3")
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize(("units", "scale"), [("Millimeters", 1e3), ("Meters", 1.0)])
def test_a_motive_export_gives_its_rigid_bodys_path(tmp_path, units, scale):
    path = tmp_path / "take.csv"
    path.write_text(motive_text(units, scale, lost={3, 7}))
    track = read_tracker_file(path)
    keep = np.setdiff1d(np.arange(50), [3, 7])
    assert np.allclose(track.times_s, TIMES[keep], atol=1e-6)
    assert np.allclose(track.points_m, POINTS[keep], atol=2e-6 / scale * 1e3)
    assert len(track.occluded_lines) == 2
    stray = read_tracker_file(path, body="stray")
    assert np.allclose(stray.points_m, [1 / scale, 2 / scale, 3 / scale])


def test_motive_errors_name_the_field(tmp_path):
    path = tmp_path / "take.csv"
    path.write_text(motive_text("Inches", 1.0, set()))
    with pytest.raises(InputError, match="Length Units = 'Inches'; expected one of Meters"):
        read_tracker_file(path)
    path.write_text(motive_text("Meters", 1.0, set()))
    with pytest.raises(InputError, match=r"--body 'probe': not in .* tool, stray"):
        read_tracker_file(path, body="probe")


def test_a_pose_csv_gives_its_translation_and_refuses_a_pose_that_is_not_rigid(tmp_path):
    rotations = Rotation.random(50, random_state=2).as_matrix()
    header = "time_s," + ",".join(f"m{i}{j}" for i in range(4) for j in range(4))
    rows = []
    for t, r, p in zip(TIMES, rotations, POINTS * 1e3, strict=True):
        pose = np.eye(4)
        pose[:3, :3], pose[:3, 3] = r, p
        rows.append(f"{t:.6f}," + ",".join(f"{v:.9f}" for v in pose.ravel()))
    path = tmp_path / "poses.csv"
    path.write_text("\n".join([header, *rows, f"{TIMES[-1] + 1:.6f}" + "," * 16]) + "\n")
    track = read_tracker_file(path)
    assert np.allclose(track.points_m, POINTS, atol=1e-9) and len(track.occluded_lines) == 1
    rows[4] = rows[4].replace(rows[4].split(",")[1], "2.0", 1)
    path.write_text("\n".join([header, *rows]) + "\n")
    with pytest.raises(InputError, match="line 6: not a rigid pose"):
        read_tracker_file(path)


def test_the_point_csv_round_trips_and_an_unknown_format_is_named(tmp_path):
    points = POINTS.copy()
    points[9] = np.nan
    path = tmp_path / "points.csv"
    path.write_text(point_csv_text(TIMES, points))
    track = read_tracker_file(path)
    assert len(track.times_s) == 49 and np.allclose(
        track.points_m, np.delete(POINTS, 9, 0), atol=1e-7
    )
    path.write_text("frame;x;y;z\n1;2;3;4\n")
    with pytest.raises(InputError, match="line 1 is 'frame;x;y;z'; expected time_s,x_mm") as e:
        read_tracker_file(path)
    assert "\n" not in str(e.value)


def test_ndi_frames_give_the_tools_origin_and_the_dummy_tracker_sees_nothing(tmp_path):
    frames = []
    for k, (t, p) in enumerate(zip(TIMES, POINTS * 1e3, strict=True)):
        pose = np.eye(4)
        pose[:3, 3] = np.nan if k == 4 else p
        frames.append(([1], [t], [k], [pose], [0.1]))
    track = track_from_frames(frames)
    assert np.allclose(track.points_m, np.delete(POINTS, 4, 0)) and track.occluded_lines == (4,)
    pytest.importorskip("sksurgerynditracker")
    rom = tmp_path / "tool.rom"
    rom.write_bytes(b"")  # the dummy only checks that the file is there
    dummy = record_frames({"tracker type": "dummy", "romfiles": [str(rom)]}, 0.2, 50.0)
    assert dummy and all(np.isnan(frame[3][0][0, 3]) for frame in dummy)
    with pytest.raises(InputError, match="tool 0 was not seen in any of"):
        track_from_frames(dummy)


def run_recording(rng, poses, dwell_s, jitter_m, dropout):
    """A marker that moves between ``poses`` (n, 3), m, and dwells at each: the log's view
    (exact, 100 Hz) and the tracker's (jittered, 60 Hz, frames lost, its own clock)."""
    pieces, windows, t = [], [], 0.0
    for k, pose in enumerate(poses):
        if k:
            move = float(rng.uniform(0.5, 2.0))
            pieces.append((t, t + move, poses[k - 1], pose))
            t += move
        pieces.append((t, t + dwell_s[k], pose, pose))
        windows.append([t + 0.4 * dwell_s[k], t + dwell_s[k]])
        t += dwell_s[k]

    def path(times):
        out = np.empty((len(times), 3))
        for start, end, a, b in pieces:
            inside = (times >= start) & (times <= end)
            s = (times[inside] - start) / max(end - start, 1e-9)
            smooth = s * s * (3 - 2 * s)
            out[inside] = a + (b - a) * smooth[:, None]
        return out

    log_times = np.arange(0.0, t, 0.01)
    tracker_times = np.arange(0.0, t, 1 / 60)
    offset = float(rng.uniform(-100.0, 100.0))
    seen = path(tracker_times) + rng.normal(0.0, jitter_m / math.sqrt(3), (len(tracker_times), 3))
    kept = rng.random(len(tracker_times)) >= dropout
    from spm_opt.verify.motion_capture import MarkerTrack

    track = MarkerTrack(tracker_times[kept] + offset, seen[kept], ())
    return track, log_times, path(log_times), np.asarray(windows), offset


@given(
    st.integers(4, 12),
    st.floats(0.1e-3, 0.25e-3),
    st.floats(0.0, 0.1),
    st.integers(0, 2**32 - 1),
)
@settings(deadline=None, max_examples=15)
def test_the_dwells_pair_without_a_shared_clock(count, jitter_m, dropout, seed):
    rng = np.random.default_rng(seed)
    directions = rng.normal(size=(count, 3))
    poses = 0.07 * directions / np.linalg.norm(directions, axis=1, keepdims=True)
    dwell_s = rng.uniform(1.5, 3.0, count)
    track, log_times, log_path, windows, offset = run_recording(
        rng, poses, dwell_s, jitter_m, dropout
    )
    means = dwell_means(track, log_times, log_path, windows, "tracker")
    assert abs(means.lag_s - offset) <= 0.05
    sigma = jitter_m / math.sqrt(3) / np.sqrt(means.counts)[:, None]
    assert np.all(np.abs(means.means_m - poses) <= 5 * sigma + 1e-9)
