"""Which frames calibrate a subject: found in the trial, given by the user, or a static trial recorded beforehand.

A calibration (segment lengths and marker placements, :mod:`sit2stand.human.calibration`; the robot's marker map,
:mod:`sit2stand.retarget.calibration`) needs frames that see the subject's markers and in which the subject is still:
a quiet stretch, as a lab's static trial is. :func:`quiet_frames` finds one in any trial:

1. a frame counts if it sees at least ``min_markers`` markers (finite and valid);
2. of the windows of ``n`` consecutive counting frames, those whose mean marker count is within
   :data:`MARKER_SLACK` of the best window's are candidates (one marker fewer for a much stiller window is a good
   trade; two is not);
3. of these, the one whose markers move least: the mean over its frames of the median marker speed [m/s] (over
   :data:`SPEED_LAG_S`); windows about as still (:data:`STILL_TIE`) go to the earliest.

Restricted to the frames before ``stop`` (e.g. the seated frames before a rise), the same rule finds the quietest
seated stretch. :func:`frames_at` is the user's choice (``--calibration-frame N``: the ``n`` counting frames from N),
:func:`sit2stand.human.offline.read_static` reads a static trial (``--static FILE``: a bag, a C3D or a TRC file).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from .calibration import CALIBRATION_MIN_MARKERS

MARKER_SLACK = 1.0
"""A window may see this many markers fewer (mean over its frames) than the best one and still be chosen if stiller."""
STILL_TIE, STILL_TIE_MPS = 1.25, 0.005
"""Windows within 25 % + 5 mm/s of the stillest are as still (marker noise alone reads ~20 mm/s): the earliest wins,
a seated start as the stream's own calibration takes it."""
SPEED_LAG_S = 0.1
"""Marker speeds are taken over this lag [s]: over one frame, 1 mm of noise at 100 Hz reads as 0.1 m/s."""


@dataclass(frozen=True)
class FrameChoice:
    """Frames chosen for a calibration and why, in words for a log line."""

    frames: np.ndarray            # (n,) frame indices of the trial
    reason: str

    @property
    def first(self) -> int:
        return int(self.frames[0])


def seen(positions: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """(N, M) True where a marker is valid and finite."""
    return np.asarray(valid, bool) & np.all(np.isfinite(positions), axis=-1)


def marker_speed(t_s: np.ndarray, positions: np.ndarray, valid: np.ndarray, lag_s: float = SPEED_LAG_S) -> np.ndarray:
    """(N,) median speed [m/s] of the markers seen in a frame and ``lag_s`` before it (the first frames: the first
    such speed); over a lag, not one frame, so that measurement noise does not hide a still subject."""
    t = np.asarray(t_s, float)
    n = len(t)
    lag = int(np.clip(round(lag_s / float(np.median(np.diff(t)))) if n > 1 else 1, 1, max(1, n - 1)))
    if n <= lag:
        return np.zeros(n)
    ok = seen(positions, valid)
    both = ok[lag:] & ok[:-lag]
    step = np.linalg.norm(np.nan_to_num(positions[lag:] - positions[:-lag]), axis=-1)
    speed = np.array([np.median(s[b]) if b.any() else np.inf for s, b in zip(step, both)]) / (t[lag:] - t[:-lag])
    return np.concatenate([np.full(lag, speed[0]), speed])


def quiet_frames(t_s: np.ndarray, positions: np.ndarray, valid: np.ndarray, n: int, *, stop: int | None = None,
                 min_markers: int = CALIBRATION_MIN_MARKERS) -> FrameChoice:
    """The quietest stretch of ``n`` frames that sees the most markers, among the frames before ``stop`` (see the
    module docstring). Fewer counting frames than ``n``: all of them.

    Raises:
        InputError: no frame (before ``stop``) sees ``min_markers`` markers.
    """
    stop = len(t_s) if stop is None else max(1, min(stop, len(t_s)))
    count = seen(positions, valid)[:stop].sum(axis=1)
    good = np.flatnonzero(count >= min_markers)
    if not len(good):
        raise InputError(f"no frame{f' before frame {stop}' if stop < len(t_s) else ''} sees {min_markers} markers "
                         f"(the most in one frame: {int(count.max(initial=0))})")
    speed = marker_speed(t_s, positions, valid)[:stop][good]
    n = max(1, min(n, len(good)))
    kernel = np.ones(n) / n
    mean_count = np.convolve(count[good], kernel, "valid")
    mean_speed = np.convolve(np.where(np.isfinite(speed), speed, 1e3), kernel, "valid")
    candidates = np.flatnonzero(mean_count >= mean_count.max() - MARKER_SLACK)
    still = mean_speed[candidates] <= STILL_TIE * mean_speed[candidates].min() + STILL_TIE_MPS
    best = int(candidates[np.flatnonzero(still)[0]])
    frames = good[best:best + n]
    return FrameChoice(frames, f"frames {frames[0]}-{frames[-1]} found: {mean_count[best]:.1f} markers seen, the "
                               f"markers moving {1e3 * mean_speed[best]:.0f} mm/s (median)")


def frames_at(first: int, positions: np.ndarray, valid: np.ndarray, n: int,
              min_markers: int = CALIBRATION_MIN_MARKERS) -> FrameChoice:
    """The ``n`` frames from ``first`` on that see ``min_markers`` markers (``--calibration-frame``).

    Raises:
        InputError: ``first`` is not a frame of the trial, or it does not see enough markers.
    """
    total = len(positions)
    if not 0 <= first < total:
        raise InputError(f"--calibration-frame {first}: the trial has frames 0-{total - 1}")
    count = seen(positions, valid).sum(axis=1)
    if count[first] < min_markers:
        raise InputError(f"--calibration-frame {first}: it sees {int(count[first])} markers, a calibration needs "
                         f"{min_markers}")
    frames = first + np.flatnonzero(count[first:] >= min_markers)[:n]
    return FrameChoice(frames, f"frames {frames[0]}-{frames[-1]} given (--calibration-frame {first})")
