"""sit2stand.io.playback: bag time -> wall time with rate, pause and rate changes, on a fake clock."""

import pytest

from sit2stand.io.playback import PlaybackClock, check_rate


class FakeTime:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def test_due_times_scale_with_rate():
    now = FakeTime()
    clock = PlaybackClock(bag_start_ns=5_000_000_000, rate=2.0, now=now)
    assert clock.due_in_s(5_000_000_000) == pytest.approx(0.0)
    assert clock.due_in_s(7_000_000_000) == pytest.approx(1.0)   # 2 s of bag at 2x
    now.t += 0.25
    assert clock.bag_now_ns() == 5_500_000_000


def test_pause_freezes_bag_time_and_resume_shifts_deadlines():
    now = FakeTime()
    clock = PlaybackClock(0, rate=1.0, now=now)
    now.t += 1.0
    clock.pause()
    assert clock.due_in_s(2_000_000_000) == float("inf")
    now.t += 5.0
    assert clock.bag_now_ns() == 1_000_000_000
    clock.resume()
    assert clock.due_in_s(2_000_000_000) == pytest.approx(1.0)


def test_rate_change_keeps_bag_time_continuous():
    now = FakeTime()
    clock = PlaybackClock(0, rate=1.0, now=now)
    now.t += 2.0
    clock.set_rate(10.0)
    assert clock.bag_now_ns() == 2_000_000_000
    assert clock.due_in_s(3_000_000_000) == pytest.approx(0.1)


def test_unpaced_mode_is_always_due():
    clock = PlaybackClock(0, rate=0.0, now=FakeTime())
    assert clock.due_in_s(10**12) == 0.0
    clock.played(42)
    assert clock.bag_now_ns() == 42


@pytest.mark.parametrize("rate", [0.05, 51.0, -1.0])
def test_rate_bounds(rate):
    with pytest.raises(ValueError, match="outside 0.1..50"):
        check_rate(rate)
