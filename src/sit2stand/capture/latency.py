"""Capture -> arrival latencies of a live stream, from the capture stand-in's clock origin and a probe's record.

``serve-c3d`` prints the CLOCK_REALTIME time of its capture timestamp 0 ("capture clock origin N ns"); frame k was
captured at origin + k / rate. The latency probe (:mod:`sit2stand.nodes.latency_probe`) writes, per topic, each
message's header stamp and the time DDS received it (CLOCK_REALTIME). The bridge stamps every frame with its capture
time mapped once to the ROS clock, so a frame's index follows from its stamp's distance to the first marker frame's.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np

from ..io.topics import MARKERS_TOPIC

ORIGIN_LINE = re.compile(r"capture clock origin (\d+) ns")
PROBE_READY = "probe ready"
"""What the latency probe (:mod:`sit2stand.nodes.latency_probe`) prints once it is subscribed."""


def capture_origin_ns(server_output: str) -> int:
    """The CLOCK_REALTIME time [ns] of capture timestamp 0 that serve-c3d printed.

    Raises:
        ValueError: the output has no such line.
    """
    found = ORIGIN_LINE.search(server_output)
    if found is None:
        raise ValueError("serve-c3d's output has no 'capture clock origin' line")
    return int(found.group(1))


def latencies_ms(probe_json: Path, topic: str, origin_ns: int, rate_hz: float,
                 first_topic: str = MARKERS_TOPIC) -> np.ndarray:
    """Arrival time minus capture time [ms] of each message of ``topic`` in a probe's record: the frame index from
    the stamp's distance to the first ``first_topic`` message's, the capture time from serve-c3d's origin."""
    record = json.loads(Path(probe_json).read_text())
    if not record.get(first_topic):
        raise ValueError(f"no {first_topic} message reached the probe")
    rows = np.array(record[topic], np.int64).reshape(-1, 2)
    stamps, arrived = rows[:, 0], rows[:, 1]
    k = np.round((stamps - record[first_topic][0][0]) * rate_hz * 1e-9).astype(np.int64)
    return (arrived - (origin_ns + np.round(k * 1e9 / rate_hz).astype(np.int64))) * 1e-6


def p50_p99(values_ms: np.ndarray) -> str:
    """``p50 X ms p99 Y ms (n=N)`` of latencies [ms]."""
    return f"p50 {np.percentile(values_ms, 50):.2f} ms p99 {np.percentile(values_ms, 99):.2f} ms (n={len(values_ms)})"
