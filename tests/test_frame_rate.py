"""A stream's frame rate told from its stamps (io.frame_rate)."""

import numpy as np
import pytest

from sit2stand.errors import InputError
from sit2stand.io.frame_rate import PERIODS_NEEDED, FrameRateCheck


def verdicts(check: FrameRateCheck, stamps) -> list[str]:
    return [v for t in stamps if (v := check.add(float(t))) is not None]


def test_a_stream_at_the_configured_rate_passes_with_a_dropped_and_a_repeated_frame():
    stamps = list(np.arange(40) * 0.01)
    del stamps[3]                       # a dropped frame
    stamps.insert(6, stamps[5])         # a repeated one
    check = FrameRateCheck("/mocap/markers", 100.0)
    assert verdicts(check, stamps) == [] and abs(check.measured_hz - 100.0) < 1e-6


def test_a_stream_at_another_rate_is_named_once_with_what_to_set():
    check = FrameRateCheck("/mocap/markers", 100.0)
    said = verdicts(check, np.arange(50) * 0.005)
    assert len(said) == 1
    assert said[0].startswith("/mocap/markers: frames stamped every 5.00 ms (200.0 Hz), but rate_hz is 100 Hz")
    assert "rate_hz:=200" in said[0]
    assert verdicts(FrameRateCheck("/mocap/markers", 100.0), np.arange(PERIODS_NEEDED) * 0.005) == [], \
        "no verdict before enough periods"


def test_a_rate_within_the_tolerance_passes():
    assert verdicts(FrameRateCheck("/mocap/markers", 100.0), np.arange(30) / 98.0) == []
    assert verdicts(FrameRateCheck("/mocap/markers", 100.0), np.arange(30) / 90.0) != []


def test_a_rate_no_capture_has_is_refused_naming_the_parameter():
    for bad in (0.0, -100.0, 10.0, float("nan")):
        with pytest.raises(InputError, match="rate_hz .*at least 20 Hz"):
            FrameRateCheck("/mocap/markers", bad)
