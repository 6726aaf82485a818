"""A tracker's recording in the formats labs export, and its pairing with a run's dwells."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from spm_opt.base.errors import InputError
from spm_opt.calibration.dwell import MIN_SAMPLES, dwell_means, jitter_m
from spm_opt.calibration.ndi import record_frames, track_from_frames
from spm_opt.calibration.tracker_files import POSE_COLUMNS, point_csv_text, read_tracker_file
from spm_opt.verify.motion_capture import MarkerTrack

RNG = np.random.default_rng(5)
TIMES = np.arange(50) / 120.0
POINTS = RNG.uniform(-0.3, 0.3, (50, 3))
MEASURED = np.array([0.01, 0.02, 0.03])  # the measured marker, from the rigid body's origin
EXPECTED = np.array([0.011, 0.019, 0.031])  # the rigid body's expected marker, likewise


def one_line(error: pytest.ExceptionInfo) -> str:
    message = str(error.value)
    assert "\n" not in message
    return message


# --- OptiTrack Motive ------------------------------------------------------------------


def motive_text(
    units: str = "Millimeters",
    scale: float = 1e3,
    lost: frozenset[int] = frozenset(),
    version: str = "1.23",
    labels: bool = True,
    second_body: bool = False,
) -> str:
    """A Motive export laid out as real ones are (format 1.23: the pathviewr package's
    example exports; 1.25 adds a Parent row): rigid body ``tool`` (rotation, position,
    mean marker error), its expected marker ``tool:Marker1`` (a Rigid Body Marker, with
    marker quality) and the measured marker of the same name; positions in ``units``,
    ``scale`` per metre; the frames in ``lost`` empty for the tool and its markers."""
    header = (
        f"Format Version,{version},Take Name,calibration 2026-01-12,Take Notes,,"
        "Capture Frame Rate,120.000000,Export Frame Rate,120.000000,"
        "Capture Start Time,2026-01-12 10.02.03.456 AM,Total Frames in Take,50,"
        f"Total Exported Frames,50,Rotation Type,Quaternion,Length Units,{units},"
        "Coordinate Space,Global"
    )
    blocks = [  # (type, name, ID, kinds, axes)
        ("Rigid Body", "tool", "1", ["Rotation"] * 4 + ["Position"] * 3 + ["Mean Marker Error"]),
        ("Rigid Body Marker", "tool:Marker1", "2", ["Position"] * 3 + ["Marker Quality"]),
        ("Marker", "tool:Marker1", "3", ["Position"] * 3),
    ]
    if second_body:
        blocks.append(blocks[0][:1] + ("probe", "4") + blocks[0][3:])
    axes = {
        "Rotation": ["X", "Y", "Z", "W"],
        "Position": ["X", "Y", "Z"],
        "Mean Marker Error": [""],
        "Marker Quality": [""],
    }
    types, names, ids, kinds, heading = [], [], [], [], []
    for kind, name, ident, columns in blocks:
        types += [kind] * len(columns)
        names += [name] * len(columns)
        ids += [f'"{ident}A7D2C0F3E11EA69D7AB6B1FACE49B"'] * len(columns)
        kinds += columns
        heading += [a for c in dict.fromkeys(columns) for a in axes[c]]
    label = ["Type", "Name", "ID"] if labels else ["", "", ""]
    lines = [
        header,
        "",
        ",".join(["", label[0], *types]),
        ",".join(["", label[1], *names]),
        ",".join(["", label[2], *ids]),
    ]
    if version == "1.25":
        lines.append(",".join(["", "Parent", *[""] * len(types)]))
    lines += [",".join(["", "", *kinds]), ",".join(["Frame", "Time (Seconds)", *heading])]
    quaternions = Rotation.random(50, random_state=1).as_quat()
    for k, (t, p, q) in enumerate(zip(TIMES, POINTS, quaternions, strict=True)):
        tool = [f"{v:.6f}" for v in [*q, *p * scale, 0.0001]]
        expected = [f"{v:.6f}" for v in [*(p + EXPECTED) * scale, 0.98]]
        measured = [f"{v:.6f}" for v in (p + MEASURED) * scale]
        cells = [""] * (len(tool) + len(expected)) if k in lost else tool + expected
        cells += measured + (tool if second_body else [])
        lines.append(",".join([str(k), f"{t:.6f}", *cells]))
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize(
    ("units", "scale", "version", "labels"),
    [
        ("Millimeters", 1e3, "1.23", True),
        ("Meters", 1.0, "1.23", True),
        ("Centimeters", 1e2, "1.25", True),
        ("Millimeters", 1e3, "1.21", False),
    ],
)
def test_a_motive_export_gives_its_rigid_bodys_path(tmp_path, units, scale, version, labels):
    path = tmp_path / "take.csv"
    path.write_text(motive_text(units, scale, frozenset({3, 7}), version, labels))
    track = read_tracker_file(path)
    keep = np.setdiff1d(np.arange(50), [3, 7])
    assert np.allclose(track.times_s, TIMES[keep], atol=1e-6)
    assert np.allclose(track.points_m, POINTS[keep], atol=1e-6 / scale)
    first_data_line = 9 if version == "1.25" else 8
    assert track.occluded_lines == (first_data_line + 3, first_data_line + 7)
    marker = read_tracker_file(path, body="tool:Marker1")  # the measured one, never lost
    assert np.allclose(marker.points_m, POINTS + MEASURED, atol=1e-6 / scale)
    assert marker.n_occluded == 0


@pytest.mark.parametrize(
    ("edit", "body", "message"),
    [
        (
            lambda t: t.replace("Millimeters", "Inches"),
            None,
            "line 1 has Length Units = 'Inches'; expected one of Meters, Centimeters, Millimeters",
        ),
        (lambda t: t.replace(",Length Units,Millimeters", ""), None, "line 1 has no Length Units"),
        (
            lambda t: t,
            "probe",
            r"--body 'probe': not in .* \(its bodies and markers: tool, "
            "tool:Marker1\\)",
        ),
        (
            lambda t: t.replace("\nFrame,Time (Seconds)", "\nFrame,Seconds"),
            None,
            "no header row 'Frame,Time",
        ),
        (
            lambda t: t.replace("\n5,0.041667,", "\n5,0.041667x,"),
            None,
            r"line 13, column Time \(Seconds\) = '0.041667x': expected a number",
        ),
        (
            lambda t: t.replace("\n5,0.041667,", "\n5,0.01,"),
            None,
            "line 13: time 0.01 s; times must increase strictly",
        ),
    ],
)
def test_motive_errors_name_the_field(tmp_path, edit, body, message):
    path = tmp_path / "take.csv"
    path.write_text(edit(motive_text()))
    with pytest.raises(InputError, match=message) as error:
        read_tracker_file(path, body=body)
    one_line(error)


def test_a_motive_export_of_two_rigid_bodies_needs_a_body(tmp_path):
    path = tmp_path / "take.csv"
    path.write_text(motive_text(second_body=True))
    with pytest.raises(InputError, match=r"2 rigid bodies; name one with --body") as error:
        read_tracker_file(path)
    assert "tool, tool:Marker1, probe" in one_line(error)
    assert np.allclose(read_tracker_file(path, body="probe").points_m, POINTS, atol=1e-9)


# --- the pose CSV ----------------------------------------------------------------------


def pose_rows(rotations: np.ndarray) -> list[str]:
    rows = []
    for t, r, p in zip(TIMES, rotations, POINTS * 1e3, strict=True):
        pose = np.eye(4)
        pose[:3, :3], pose[:3, 3] = r, p
        rows.append(f"{t:.6f}," + ",".join(f"{v:.9f}" for v in pose.ravel()))
    return rows


def test_a_pose_csv_gives_its_translation(tmp_path):
    header = ",".join(POSE_COLUMNS)
    rows = pose_rows(Rotation.random(50, random_state=2).as_matrix())
    rows[10] = f"{TIMES[10]:.6f}" + "," * 16  # lost
    path = tmp_path / "poses.csv"
    path.write_text("\n".join([header, *rows]) + "\n")
    track = read_tracker_file(path)
    assert np.allclose(track.points_m, np.delete(POINTS, 10, 0), atol=1e-9)
    assert np.allclose(track.times_s, np.delete(TIMES, 10), atol=1e-6)
    assert track.occluded_lines == (12,)


def _scaled(row: str) -> str:  # m00 × 2: not a rotation
    cells = row.split(",")
    cells[1] = f"{2 * float(cells[1]):.9f}"
    return ",".join(cells)


def _reflected(row: str) -> str:  # the first column negated: a reflection
    cells = row.split(",")
    for i in (1, 5, 9):
        cells[i] = f"{-float(cells[i]):.9f}"
    return ",".join(cells)


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (
            _scaled,
            r"line 6, columns m00-m22: not a rotation \(\|RᵀR − I\| up to .*; at most "
            "0.001 allowed",
        ),
        (_reflected, "line 6, columns m00-m22: a reflection"),
        (
            lambda r: r.rsplit(",", 4)[0] + ",0,0,0,2",
            "line 6, columns m30-m33 = 0 0 0 2; expected 0 0 0 1",
        ),
        (lambda r: r + ",7", "line 6: 18 cells; expected 17"),
        (
            lambda r: r.replace(",", ",abc,", 1).rsplit(",", 1)[0],
            "line 6, column m00 = 'abc': expected a number",
        ),
        (
            lambda r: "0.0" + r[r.index(",") :],
            r"line 6: time 0 s; times must increase strictly "
            r"\(line 5 has",
        ),
    ],
)
def test_a_pose_csv_refuses_what_is_not_a_rigid_pose(tmp_path, edit, message):
    rows = pose_rows(Rotation.random(50, random_state=3).as_matrix())
    rows[4] = edit(rows[4])
    path = tmp_path / "poses.csv"
    path.write_text("\n".join([",".join(POSE_COLUMNS), *rows]) + "\n")
    with pytest.raises(InputError, match=message) as error:
        read_tracker_file(path)
    one_line(error)


# --- the point CSV, and files that are none of them ------------------------------------


def test_the_point_csv_round_trips(tmp_path):
    points = POINTS.copy()
    points[9] = np.nan
    path = tmp_path / "points.csv"
    path.write_text(point_csv_text(TIMES, points))
    track = read_tracker_file(path)
    assert np.allclose(track.times_s, np.delete(TIMES, 9), atol=1e-6)
    assert np.allclose(track.points_m, np.delete(POINTS, 9, 0), atol=1e-7)
    assert track.occluded_lines == (11,)


def test_an_unknown_or_missing_file_is_named(tmp_path):
    path = tmp_path / "points.csv"
    path.write_text("frame;x;y;z\n1;2;3;4\n")
    with pytest.raises(InputError, match="line 1 is 'frame;x;y;z'; expected time_s,x_mm") as e:
        read_tracker_file(path)
    assert "m00,...,m33" in one_line(e) and "Motive" in one_line(e)
    with pytest.raises(InputError, match="no such file") as e:
        read_tracker_file(tmp_path / "absent.csv")
    one_line(e)


# --- NDI -------------------------------------------------------------------------------


def ndi_frames(quaternions: bool = False) -> list[tuple]:
    """get_frame() tuples of one tool over POINTS (mm), frame 4 unseen, frame 6 read twice."""
    frames = []
    for k, (t, p) in enumerate(zip(TIMES, POINTS * 1e3, strict=True)):
        p = np.full(3, np.nan) if k == 4 else p
        if quaternions:
            pose = np.concatenate([[1.0, 0.0, 0.0, 0.0], p]).reshape(1, 7)
        else:
            pose = np.eye(4)
            pose[:3, 3] = p
        frames.append(([1], [t], [100 + k], [pose], [0.1]))
        if k == 6:
            frames.append(([1], [t + 0.001], [100 + k], [pose], [0.1]))
    return frames


@pytest.mark.parametrize("quaternions", [False, True])
def test_ndi_frames_give_the_tools_origin(quaternions):
    track = track_from_frames(ndi_frames(quaternions))
    assert np.allclose(track.points_m, np.delete(POINTS, 4, 0))
    assert np.allclose(track.times_s, np.delete(TIMES, 4))
    assert track.occluded_lines == (4,)


@pytest.mark.parametrize(
    ("edit", "port", "message"),
    [
        (lambda f: f, 1, "NDI frame 0: no tool 1 \\(it has 1\\)"),
        (lambda f: [(*f[0][:3], [np.eye(3)], f[0][4])], 0, "tracking of shape \\(3, 3\\)"),
        (lambda f: [f[1], f[0]], 0, "NDI frame 1: timestamp .*; timestamps must increase"),
        (lambda f: [f[0][:4]], 0, "NDI frame 0: 4 items; expected 5"),
    ],
)
def test_bad_ndi_frames_are_named(edit, port, message):
    with pytest.raises(InputError, match=message) as error:
        track_from_frames(edit(ndi_frames()), port=port)
    one_line(error)


def test_the_dummy_ndi_tracker_sees_nothing(tmp_path):
    pytest.importorskip("sksurgerynditracker")
    rom = tmp_path / "tool.rom"
    rom.write_bytes(b"")  # the dummy only checks that the file is there
    frames = record_frames({"tracker type": "dummy", "romfiles": [str(rom)]}, 0.1, 100.0)
    assert len(frames) == 10
    handles, stamps, numbers, tracking, quality = frames[0]
    assert handles == [None] and numbers == [0] and quality == [0.0]
    assert np.isnan(tracking[0][:3]).all() and np.array_equal(tracking[0][3], [0, 0, 0, 1])
    with pytest.raises(InputError, match="tool 0 was not seen in any of 10 frames") as error:
        track_from_frames(frames)
    one_line(error)
    with pytest.raises(InputError, match="NDI tracker settings: .*not found") as error:
        record_frames({"tracker type": "dummy", "romfiles": [str(tmp_path / "no.rom")]}, 1, 1)
    one_line(error)
    with pytest.raises(InputError, match="rate_hz = 0: expected a number > 0"):
        record_frames({"tracker type": "dummy"}, 1.0, 0)


def test_a_failed_recording_still_stops_and_closes_the_tracker(monkeypatch):
    module = pytest.importorskip("sksurgerynditracker.nditracker")
    calls = []

    class Broken:
        def __init__(self, settings):
            calls.append("open")

        def start_tracking(self):
            calls.append("start")

        def get_frame(self):
            raise OSError("the cable")

        def stop_tracking(self):
            calls.append("stop")

        def close(self):
            calls.append("close")

    monkeypatch.setattr(module, "NDITracker", Broken)
    with pytest.raises(OSError, match="the cable"):
        record_frames({"tracker type": "polaris"}, 1.0, 10.0)
    assert calls == ["open", "start", "stop", "close"]


# --- the dwells ------------------------------------------------------------------------


def run_recording(rng, poses, dwell_s, sigma_m, dropout, rate_hz):
    """A marker that moves between ``poses`` (n, 3), m, and dwells at each: the log's view
    (exact, 100 Hz) and the tracker's (Gaussian jitter of ``sigma_m`` per coordinate, at
    ``rate_hz``, frames lost with probability ``dropout``, its own clock)."""
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
    tracker_times = np.arange(0.0, t, 1 / rate_hz)
    offset = float(rng.uniform(-100.0, 100.0))
    seen = path(tracker_times) + rng.normal(0.0, sigma_m, (len(tracker_times), 3))
    kept = rng.random(len(tracker_times)) >= dropout
    track = MarkerTrack(tracker_times[kept] + offset, seen[kept], ())
    return track, log_times, path(log_times), np.asarray(windows), offset


def sphere_poses(rng, count):
    directions = rng.normal(size=(count, 3))
    return 0.07 * directions / np.linalg.norm(directions, axis=1, keepdims=True)


@given(
    st.integers(4, 12),
    st.floats(0.05e-3, 0.25e-3),
    st.floats(0.0, 0.2),
    st.sampled_from([60.0, 120.0]),
    st.integers(0, 2**32 - 1),
)
@settings(deadline=None, max_examples=12)
def test_the_dwells_pair_without_a_shared_clock(count, sigma_m, dropout, rate_hz, seed):
    rng = np.random.default_rng(seed)
    poses = sphere_poses(rng, count)
    dwell_s = rng.uniform(1.5, 3.0, count)
    track, log_times, log_path, windows, offset = run_recording(
        rng, poses, dwell_s, sigma_m, dropout, rate_hz
    )
    means = dwell_means(track, log_times, log_path, windows, "tracker")
    assert abs(means.lag_s - offset) <= 0.05
    assert len(means.means_m) == count and np.all(means.counts >= MIN_SAMPLES)
    error = np.abs(means.means_m - poses) / (sigma_m / np.sqrt(means.counts)[:, None])
    assert np.all(error <= 5.0)


def test_the_jitter_is_measured_through_moves_and_dropouts():
    rng = np.random.default_rng(11)
    track, *_ = run_recording(rng, sphere_poses(rng, 8), np.full(8, 2.0), 0.2e-3, 0.2, 60.0)
    assert jitter_m(track.times_s, track.points_m) == pytest.approx(0.2e-3, rel=0.15)


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ("hidden", r"tracker: pose 3: \d tracker samples in its dwell, at least 10 needed"),
        ("still", "tracker: the tracker's still and moving stretches do not line up"),
    ],
)
def test_a_recording_that_does_not_fit_the_run_gets_one_line(change, message):
    rng = np.random.default_rng(3)
    track, log_times, log_path, windows, _ = run_recording(
        rng, sphere_poses(rng, 6), np.full(6, 2.0), 0.1e-3, 0.0, 60.0
    )
    times, points = track
    if change == "hidden":  # the marker hidden through most of the third pose's dwell
        start, end = windows[2] + track.times_s[0] - log_times[0]
        keep = (times < start + 0.11) | (times > end - 0.11)
        track = MarkerTrack(times[keep], points[keep], ())
    else:  # the marker still throughout: not a recording of this run
        track = MarkerTrack(times, np.broadcast_to(points[0], points.shape).copy(), ())
    with pytest.raises(InputError, match=message) as error:
        dwell_means(track, log_times, log_path, windows, "tracker")
    one_line(error)


def test_a_dwell_keeps_its_samples_across_a_dropout():
    rng = np.random.default_rng(4)
    track, log_times, log_path, windows, _ = run_recording(
        rng, sphere_poses(rng, 6), np.full(6, 3.0), 0.1e-3, 0.0, 60.0
    )
    times, points = track
    middle = windows[3].mean() + times[0] - log_times[0]
    keep = np.abs(times - middle) > 0.15  # 0.3 s lost in the middle of a dwell
    means = dwell_means(
        MarkerTrack(times[keep], points[keep], ()), log_times, log_path, windows, "t"
    )
    full = dwell_means(track, log_times, log_path, windows, "t")
    assert full.counts[3] - means.counts[3] == pytest.approx(18, abs=2)
    assert np.allclose(means.means_m, full.means_m, atol=0.1e-3)
    assert math.isclose(means.lag_s, full.lag_s, abs_tol=0.03)
