"""sit2stand.io.playback: bag time -> wall time with rate, pause and rate changes, on a fake clock."""

import pytest

from sit2stand.errors import InputError
from sit2stand.io.playback import (ENDED_SILENCE_S, FIRST_MESSAGE_TIMEOUT_S, ClockTicks, Lockstep, PlaybackClock,
                                   check_rate, lockstep_lead_ns, parse_wait_for, played_fraction)


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


MS = 1_000_000
SPAN = (0, 4000 * MS)


def test_held_time_stands_at_the_ceiling_and_goes_on_without_a_jump():
    now = FakeTime()
    clock = PlaybackClock(0, rate=1.0, now=now)
    now.t += 1.0
    assert clock.hold_at(400 * MS) and clock.bag_now_ns() == 400 * MS
    now.t += 2.0                                      # held two more seconds: time stays
    assert clock.hold_at(400 * MS) and clock.bag_now_ns() == 400 * MS
    assert not clock.hold_at(None) and not clock.hold_at(10_000 * MS)
    now.t += 0.1
    assert clock.bag_now_ns() == 500 * MS             # on from the ceiling, not from wall time
    clock.played(500 * MS)
    now.t += 0.1
    assert clock.hold_at(100 * MS) and clock.bag_now_ns() == 500 * MS, "never back before what was played"


def test_lockstep_follows_a_topic_from_its_first_message_and_releases_a_silent_one():
    step = Lockstep(["/robot/joint_states", "/human/com"], lead_ns=50 * MS, timeout_s=3.0, bag_span_ns=SPAN,
                    first_ns=-1)
    assert step.ceiling_ns(1000 * MS, wall_s=10.0) is None, "nothing heard yet: the replay is not held"
    step.note("/robot/joint_states", 900 * MS, wall_s=10.0)
    step.note("/human/com", 700 * MS, wall_s=10.0)
    assert step.ceiling_ns(1000 * MS, wall_s=10.5) == 750 * MS, "the slowest followed node binds"
    step.note("/human/com", 600 * MS, wall_s=10.6)            # an older stamp (reordered) changes nothing
    assert step.holding(1000 * MS, wall_s=10.6)["/human/com"] == 750 * MS
    assert step.ceiling_ns(1000 * MS, wall_s=13.7) is None, "both held the clock 3 s with nothing newer: released"
    assert step.released == {"/robot/joint_states", "/human/com"}
    step.note("/human/com", 800 * MS, wall_s=14.0)
    assert step.released == {"/robot/joint_states"} and step.ceiling_ns(1000 * MS, wall_s=14.0) == 850 * MS


def test_lockstep_does_not_release_a_topic_that_is_silent_because_another_holds_the_clock():
    step = Lockstep(["/robot/joint_states", "/human/com"], lead_ns=50 * MS, timeout_s=3.0, bag_span_ns=SPAN,
                    first_ns=-1)
    step.note("/robot/joint_states", 1000 * MS, wall_s=10.0)     # the robot is where the clock may go
    step.note("/human/com", 500 * MS, wall_s=10.0)               # the estimator holds the clock
    for wall in (10.0, 12.0):
        assert step.ceiling_ns(550 * MS, wall_s=wall) == 550 * MS
    assert step.ceiling_ns(550 * MS, wall_s=13.5) == 1050 * MS, "the estimator held it 3.5 s: released"
    assert step.released == {"/human/com"}, "the robot was silent as long, but did not hold the clock"
    assert step.ceiling_ns(1050 * MS, wall_s=15.0) == 1050 * MS, "now the robot holds it, from 15 s on"
    assert step.ceiling_ns(1050 * MS, wall_s=17.5) == 1050 * MS
    assert step.ceiling_ns(1050 * MS, wall_s=18.5) is None


def test_lockstep_waits_for_a_first_message_after_the_allowance_while_a_node_offers_the_topic():
    step = Lockstep(["/human/com"], lead_ns=50 * MS, timeout_s=3.0, bag_span_ns=SPAN, first_ns=1000 * MS)
    assert step.ceiling_ns(300 * MS, wall_s=1.0) is None, "nobody offers it: not waited for"
    offered = frozenset({"/human/com"})
    assert step.ceiling_ns(300 * MS, wall_s=1.0, announced=offered) == 1000 * MS, "the calibration's frames pass"
    assert step.ceiling_ns(1000 * MS, wall_s=30.0, announced=offered) == 1000 * MS, "a slow calibration is waited for"
    assert step.ceiling_ns(1000 * MS, wall_s=1.0 + FIRST_MESSAGE_TIMEOUT_S + 1, announced=offered) is None
    assert step.released == {"/human/com"}


def test_lockstep_lets_a_stream_that_ended_with_the_bag_go_and_keeps_the_robot():
    step = Lockstep(["/robot/joint_states", "/human/com"], lead_ns=50 * MS, timeout_s=3.0, bag_span_ns=SPAN,
                    first_ns=-1)
    step.note("/human/com", 3990 * MS, wall_s=20.0)         # the estimator's last frame
    step.note("/robot/joint_states", 4010 * MS, wall_s=20.0)
    assert step.ceiling_ns(4020 * MS, wall_s=20.0) == 4040 * MS, "just ended: still followed"
    later = 20.0 + ENDED_SILENCE_S + 0.05
    step.note("/robot/joint_states", 4200 * MS, wall_s=later)
    assert step.holding(4220 * MS, wall_s=later) == {"/robot/joint_states": 4250 * MS}


def test_a_replay_that_ends_its_graph_waits_until_the_followed_streams_reach_its_end():
    step = Lockstep(["/human/com"], lead_ns=50 * MS, timeout_s=3.0, bag_span_ns=SPAN, first_ns=-1)
    assert step.caught_up(wall_s=1.0), "nothing published: nothing to wait for"
    step.note("/human/com", 3800 * MS, wall_s=1.0)
    assert not step.caught_up(wall_s=1.5), "the estimator is 200 ms behind the bag's end"
    step.note("/human/com", 3990 * MS, wall_s=1.6)
    assert step.caught_up(wall_s=1.6)
    stalled = Lockstep(["/human/com"], lead_ns=50 * MS, timeout_s=3.0, bag_span_ns=SPAN, first_ns=-1)
    stalled.note("/human/com", 1000 * MS, wall_s=1.0)
    assert not stalled.caught_up(wall_s=3.9) and stalled.caught_up(wall_s=4.1), "a dead node is not waited for"


def test_the_lockstep_lead_is_at_least_one_marker_frame_of_the_bag():
    assert lockstep_lead_ns(0.01, 100.0) == 10_000_000       # the shipped bags: as set
    assert lockstep_lead_ns(0.01, 200.0) == 10_000_000
    assert lockstep_lead_ns(0.01, 60.0) == 16_833_333         # one 60 Hz frame and 1 %: the next frame comes due
    assert lockstep_lead_ns(0.01, 0.0) == 10_000_000          # no markers in the bag
