"""Shared by the live-graph tests: capture -> arrival latencies from serve-c3d's clock origin and a probe's log."""

import json
import re
from pathlib import Path

import numpy as np


def capture_origin_ns(server_output: str) -> int:
    """The CLOCK_REALTIME time [ns] of capture timestamp 0 that serve-c3d printed."""
    return int(re.search(r"capture clock origin (\d+) ns", server_output).group(1))


def latencies_ms(probe_json: Path, topic: str, origin_ns: int, rate_hz: float) -> np.ndarray:
    """Arrival time minus capture time [ms] of each frame of ``topic``: the frame index comes from the stamp's
    spacing (capture times, mapped once), the capture time from serve-c3d's origin."""
    rows = np.array(json.loads(probe_json.read_text())[topic], np.int64).reshape(-1, 2)
    stamps, arrived = rows[:, 0], rows[:, 1]
    first = json.loads(probe_json.read_text())["/mocap/markers"][0][0]
    k = np.round((stamps - first) * rate_hz * 1e-9).astype(np.int64)
    return (arrived - (origin_ns + np.round(k * 1e9 / rate_hz).astype(np.int64))) * 1e-6


def p50_p99(values_ms: np.ndarray) -> str:
    """``p50 X ms p99 Y ms`` of latencies [ms]."""
    return f"p50 {np.percentile(values_ms, 50):.2f} ms p99 {np.percentile(values_ms, 99):.2f} ms (n={len(values_ms)})"
