"""An NDI tracker (Polaris, Vega, Aurora) through scikit-surgerynditracker, recorded as a
marker's track: what the calibration reads from any tracker.

``NDITracker.get_frame()`` gives (port handles, timestamps, frame numbers, tracking,
quality): per tool a 4×4 pose, its translation in mm, NaN where the tool is not seen. The
marker is one tool's origin (``port``, its index in the tracker's tools). scikit-surgery's
"dummy" tracker type runs without hardware (it sees nothing) and cannot start tracking, so
its frames are polled without ``start_tracking``.
"""

from __future__ import annotations

import time
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np

from spm_opt.base.errors import InputError, require
from spm_opt.verify.motion_capture import MarkerTrack

MM = 1e-3


def track_from_frames(frames: Iterable[Sequence[Any]], port: int = 0) -> MarkerTrack:
    """The track of tool ``port``'s origin over ``get_frame()`` tuples: times (k,), s, and
    positions (k, 3), m; frames where it is not seen are counted as lost."""
    times, points, lost = [], [], []
    for number, frame in enumerate(frames):
        _, stamps, _, tracking, _ = frame
        if port >= len(tracking):
            raise InputError(f"NDI frame {number}: no tool {port} (it has {len(tracking)})")
        pose = np.asarray(tracking[port], dtype=float)
        if pose.shape != (4, 4) or not np.all(np.isfinite(pose[:3, 3])):
            lost.append(number)
            continue
        times.append(float(stamps[port]))
        points.append(pose[:3, 3] * MM)
    if not points:
        raise InputError(f"NDI tracker: tool {port} was not seen in any of {len(lost)} frames")
    return MarkerTrack(np.asarray(times), np.asarray(points), tuple(lost))


def record_frames(settings: dict[str, Any], seconds: float, rate_hz: float) -> list[tuple]:
    """Poll an ``NDITracker(settings)`` at ``rate_hz`` for ``seconds``; tracking is always
    stopped and the device closed, whatever happens."""
    nditracker = require("sksurgerynditracker.nditracker", "an NDI tracker")
    tracker = nditracker.NDITracker(settings)
    live = settings.get("tracker type") != "dummy"
    frames = []
    try:
        if live:
            tracker.start_tracking()
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            frames.append(tracker.get_frame())
            time.sleep(1.0 / rate_hz)
    finally:
        if live:
            tracker.stop_tracking()
        tracker.close()
    return frames
