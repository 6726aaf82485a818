"""An NDI tracker (Polaris, Vega, Aurora) through scikit-surgerynditracker, recorded as a
marker's track: what the calibration reads from any tracker.

``NDITracker.get_frame()`` gives (port handles, timestamps, frame numbers, tracking,
quality), one entry per tool: the host's clock when the frame was read, s; the tracker's
frame counter; a 4×4 pose, its translation in mm, NaN where the tool is not seen (with
``"use quaternions": True`` a row (1, 7), qw qx qy qz x y z). The marker is one tool's
origin (``port``, its index in the tracker's tools). A frame read again before the tracker
made a new one (the same frame number) is left out. scikit-surgery's "dummy" tracker type
runs without hardware: one tool per file of ``romfiles`` (any file; none without them),
port handle None, frame number 0, quality 0 and a pose whose rotation and translation are
NaN (it sees nothing); its ``start_tracking`` and ``stop_tracking`` raise (no device), so
its frames are polled without them.
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np

from spm_opt.base.errors import CommunicationError, InputError, require
from spm_opt.model.params import MM
from spm_opt.verify.motion_capture import MarkerTrack


def _translation_mm(number: int, port: int, pose: Any) -> np.ndarray:
    """A tool's translation (3,), mm, from its 4×4 pose or its quaternion row (1, 7)."""
    array = np.asarray(pose, dtype=float)
    if array.shape == (4, 4):
        return array[:3, 3]
    if array.size == 7:
        return array.reshape(7)[4:]
    raise InputError(
        f"NDI frame {number}, tool {port}: tracking of shape {array.shape}; expected a 4x4 "
        "pose or a quaternion row (1, 7)"
    )


def track_from_frames(frames: Iterable[Sequence[Any]], port: int = 0) -> MarkerTrack:
    """The track of tool ``port``'s origin over ``get_frame()`` tuples.

    Parameters
    ----------
    frames : iterable of tuples
        ``NDITracker.get_frame()``'s (port handles, timestamps, frame numbers, tracking,
        quality), in the order read.
    port : int
        The tool's index in each frame's lists.

    Returns
    -------
    MarkerTrack
        Times (k,), s, the host's timestamps; positions (k, 3), m; ``occluded_lines``: the
        indices (0-based) of the frames the tool was not seen in.

    Raises
    ------
    InputError
        A frame that is not a 5-tuple or has no tool ``port``, tracking of another shape,
        times that do not increase, or a tool never seen.
    """
    times: list[float] = []
    points: list[np.ndarray] = []
    lost: list[int] = []
    previous: float | None = None  # the frame number of the last frame kept
    for number, frame in enumerate(frames):
        if len(frame) != 5:
            raise InputError(
                f"NDI frame {number}: {len(frame)} items; expected 5 (port handles, "
                "timestamps, frame numbers, tracking, quality)"
            )
        _, stamps, counters, tracking, _ = frame
        if not 0 <= port < len(tracking):
            raise InputError(f"NDI frame {number}: no tool {port} (it has {len(tracking)})")
        point = _translation_mm(number, port, tracking[port])
        if not np.all(np.isfinite(point)):
            lost.append(number)
            continue
        if previous is not None and counters[port] == previous:
            continue  # the tracker's last frame, read again
        stamp = float(stamps[port])
        if times and stamp <= times[-1]:
            raise InputError(
                f"NDI frame {number}: timestamp {stamp:.6f} s; timestamps must increase "
                f"(the frame before has {times[-1]:.6f} s)"
            )
        previous = counters[port]
        times.append(stamp)
        points.append(point * MM)
    if not points:
        raise InputError(f"NDI tracker: tool {port} was not seen in any of {len(lost)} frames")
    return MarkerTrack(np.asarray(times), np.asarray(points), tuple(lost))


def record_frames(settings: dict[str, Any], seconds: float, rate_hz: float) -> list[tuple]:
    """Poll ``NDITracker(settings)`` (scikit-surgerynditracker's settings: "tracker type",
    "romfiles", "serial port", ...) every 1/``rate_hz`` s for ``seconds`` s; its frames, for
    :func:`track_from_frames`. Tracking is always stopped and the device closed, whatever
    happens.

    Raises
    ------
    InputError
        ``seconds`` or ``rate_hz`` not a number > 0, or settings the tracker refuses.
    CommunicationError
        No tracker where the settings say.
    MissingDependency
        scikit-surgerynditracker is not installed.
    """
    for name, value in (("seconds", seconds), ("rate_hz", rate_hz)):
        try:
            number = float(value)
        except (TypeError, ValueError):
            number = math.nan
        if not (math.isfinite(number) and number > 0.0):
            raise InputError(f"{name} = {value!r}: expected a number > 0")
    nditracker = require("sksurgerynditracker.nditracker", "an NDI tracker")
    try:
        tracker = nditracker.NDITracker(settings)
    except (KeyError, ValueError, FileNotFoundError) as error:
        reason = error.args[0] if error.args else error
        raise InputError(f"NDI tracker settings: {reason}") from None
    except OSError as error:
        raise CommunicationError(f"NDI tracker: {error}") from None
    tracking = False
    frames = []
    try:
        if settings.get("tracker type") != "dummy":
            tracker.start_tracking()
            tracking = True
        start = time.monotonic()
        for tick in range(max(1, round(float(seconds) * float(rate_hz)))):
            time.sleep(max(0.0, start + tick / float(rate_hz) - time.monotonic()))
            frames.append(tracker.get_frame())
    finally:
        try:
            if tracking:
                tracker.stop_tracking()
        finally:
            tracker.close()
    return frames
