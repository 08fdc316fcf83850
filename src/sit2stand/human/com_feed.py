"""What the streaming human COM estimator's node (:mod:`sit2stand.nodes.human_com`) keeps between its callbacks, as
plain objects: the marker frames that wait for the subject, the plate samples between two marker frames, which
frames are shed to catch up, and the per-frame cost figures."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from .com_stream import StreamingComEstimator

SUBJECT_WAIT_FRAMES = 500        # marker frames held for /human/subject (5 s at 100 Hz; a bag latches it first)
PENDING_PLATE_SAMPLES = 4000      # per plate, between two marker frames (4 s at 1 kHz; the estimator keeps ~2 s)


class SubjectWait:
    """Marker frames that came before the subject (at most :data:`SUBJECT_WAIT_FRAMES`)."""

    def __init__(self) -> None:
        self.frames: list[Any] = []

    def hold(self, frame: Any) -> bool:
        """Keep ``frame``; False once too many wait (the subject is not coming)."""
        self.frames.append(frame)
        return len(self.frames) <= SUBJECT_WAIT_FRAMES

    def release(self, handle: Callable[[Any], None]) -> None:
        """The subject came: every held frame to ``handle``, in order."""
        held, self.frames = self.frames, []
        for frame in held:
            handle(frame)


class PlateInbox:
    """Plate samples (t [s], force (3,) [N], moment about the lab origin (3,) [N m], one tuple each) received since
    the last marker frame, per plate; a plate streaming without marker frames keeps its newest."""

    def __init__(self) -> None:
        self.pending: dict[str, list[tuple]] = {}

    def add(self, name: str, row: tuple) -> None:
        rows = self.pending.setdefault(name, [])
        rows.append(row)
        if len(rows) > PENDING_PLATE_SAMPLES:
            del rows[:-PENDING_PLATE_SAMPLES // 2]

    def flush(self, estimator: StreamingComEstimator) -> None:
        """Every plate's pending samples to ``estimator``, one array per plate."""
        for name, rows in self.pending.items():
            if rows:
                a = np.array(rows)
                estimator.add_plate_samples(name, a[:, 0], a[:, 1:4], a[:, 4:7])
                rows.clear()


def shed(behind_s: float, clock_now_s: float, frame_t_s: float) -> bool:
    """Whether a frame stamped ``frame_t_s`` gets its COM only (no delayed COPs, scaling rows nor /tf): it reached
    the estimator more than ``behind_s`` behind the clock (0: never), and the stream must catch up."""
    return 0 < behind_s < clock_now_s - frame_t_s


class FrameCosts:
    """Per frame: wall and thread CPU time [s] of its processing; frames skipped (too few markers) and shed."""

    def __init__(self) -> None:
        self.wall_s: list[float] = []
        self.cpu_s: list[float] = []     # below the wall time: the thread waited
        self.skipped = 0
        self.shed = 0

    def figures(self, plate_gaps: dict[str, int]) -> dict[str, str]:
        """The node's ``~/stats`` and closing line, over the newest 2000 frames."""
        c = np.array(self.wall_s[-2000:]) * 1e3
        return {"frames": str(len(self.wall_s)), "skipped_frames": str(self.skipped), "shed_frames": str(self.shed),
                "cost_p50_ms": f"{np.percentile(c, 50):.3f}" if len(c) else "nan",
                "cost_p99_ms": f"{np.percentile(c, 99):.3f}" if len(c) else "nan",
                "cpu_p50_ms": f"{np.median(self.cpu_s[-2000:]) * 1e3:.3f}" if len(c) else "nan",
                "plate_dropouts": ", ".join(f"{k}: {v} frames" for k, v in plate_gaps.items()) or "none"}
