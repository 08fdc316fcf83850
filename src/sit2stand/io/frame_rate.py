"""A stream's frame rate, told from its stamps, checked against the rate a node was set up for.

The human COM estimator's filters and the retargeter's per-frame limits (joint speed, the trunk's lift-off, the
plan's time step) take their time step from the node's ``rate_hz`` parameter. A capture at another rate would
silently run them at the wrong speed: a 200 Hz stream under ``rate_hz`` 100 is retargeted at twice the joint-speed
limit. The stamps tell within the first frames (0.09 s at 100 Hz): in a recording that starts seated, before the
human moves; in one that starts mid-rise, a few commands of the retargeter's lead-in from the seat may have gone.
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError

RATE_TOLERANCE = 0.05
"""The stamps' rate may differ from the configured one by this share (clock jitter, a capture's own rounding)."""
MIN_RATE_HZ = 20.0
"""The slowest capture the nodes take [Hz] (a sit-to-stand's ~1 s motion aliases below)."""
PERIODS_NEEDED = 8
"""Frame periods seen before the verdict (the median of them: a dropped or repeated frame does not decide it)."""


class FrameRateCheck:
    """Checks the stamps [s] of the frames on ``topic`` against ``rate_hz`` [Hz] (see the module docstring)."""

    def __init__(self, topic: str, rate_hz: float, parameter: str = "rate_hz") -> None:
        if not (np.isfinite(rate_hz) and rate_hz >= MIN_RATE_HZ):
            raise InputError(f"{parameter} {rate_hz!r}: a capture rate of at least {MIN_RATE_HZ:g} Hz")
        self.topic, self.rate_hz, self.parameter = topic, float(rate_hz), parameter
        self._stamps: list[float] = []
        self.measured_hz: float | None = None       # once told

    def add(self, stamp_s: float) -> str | None:
        """Note one frame's stamp; returns what is wrong, once, when the stamps' rate is not ``rate_hz``."""
        if self.measured_hz is not None:
            return None
        if not self._stamps or stamp_s > self._stamps[-1]:
            self._stamps.append(float(stamp_s))
        if len(self._stamps) <= PERIODS_NEEDED:
            return None
        period = float(np.median(np.diff(self._stamps)))
        self.measured_hz = 1.0 / period
        self._stamps = []
        if abs(self.measured_hz - self.rate_hz) <= RATE_TOLERANCE * self.rate_hz:
            return None
        return (f"{self.topic}: frames stamped every {period * 1e3:.2f} ms ({self.measured_hz:.1f} Hz), but "
                f"{self.parameter} is {self.rate_hz:g} Hz: set -p {self.parameter}:={self.measured_hz:.0f} "
                f"(sit2stand launch: rate_hz:={self.measured_hz:.0f})")
