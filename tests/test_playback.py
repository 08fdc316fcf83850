"""sit2stand.io.playback: bag time -> wall time with rate, pause and rate changes, on a fake clock."""

import pytest

from sit2stand.errors import InputError
from sit2stand.io.playback import ClockTicks, PlaybackClock, check_rate, parse_wait_for, played_fraction


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


def test_wait_for_entries_are_parsed_and_a_bad_one_is_named():
    assert parse_wait_for(["/human/com:1", "/mocap/markers:2"]) == {"/human/com": 1, "/mocap/markers": 2}
    with pytest.raises(InputError, match="'human/com:1' is not TOPIC:COUNT"):
        parse_wait_for(["human/com:1"])


def test_clock_ticks_every_period_of_bag_time_and_after_a_loop_restarts():
    ticks = ClockTicks(period_ns=10_000_000)
    due = [t for t in range(0, 50_000_000, 2_500_000) if ticks.due(t)]
    assert due == [0, 10_000_000, 20_000_000, 30_000_000, 40_000_000]
    assert ticks.due(0), "a loop back to the bag's start publishes the clock at once"


def test_played_fraction_counts_the_current_pass():
    assert played_fraction(50, 200, 0, loop=False) == 0.25
    assert played_fraction(250, 200, 1, loop=True) == 0.25
    assert played_fraction(300, 200, 0, loop=False) == 1.0
