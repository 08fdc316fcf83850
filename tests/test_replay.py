"""sit2stand.io.replay: the replayer's play loop without ROS, on a shipped bag and a fake ROS side."""

import threading
from pathlib import Path

from sit2stand.io.bag import BagReader
from sit2stand.io.playback import ClockTicks, PlaybackClock
from sit2stand.io.replay import ACK_BATCH, PlayLoop, ReplayIO, Waits

BAG = Path(__file__).resolve().parents[1] / "bags" / "natural"


class FakeRos:
    """What the node would do, recorded."""

    def __init__(self, subscribers_after: int = 0) -> None:
        self.messages, self.clock, self.acks, self.logs = [], [], 0, []
        self.asked = 0
        self.subscribers_after = subscribers_after

    def io(self) -> ReplayIO:
        return ReplayIO(lambda topic, data: self.messages.append((topic, len(data))), self.clock.append,
                        self._subscribers, self._acked, lambda force: None, self.logs.append, self.logs.append)

    def _subscribers(self, topic: str) -> int:
        self.asked += 1
        return 1 if self.asked > self.subscribers_after else 0

    def _acked(self, keep_clock: bool) -> None:
        self.acks += 1


def play(reader, rate=0.0, loop=False, waits=None, ros=None):
    ros = ros or FakeRos()
    clock = PlaybackClock(reader.start_ns, rate)
    topics = sorted(reader.topics())
    player = PlayLoop(reader, topics, clock, ClockTicks(10_000_000), ros.io(), waits or Waits({}), loop,
                      clock.bag_now_ns, lambda: True)
    return player, ros, topics


def test_unpaced_it_plays_every_message_in_time_order_with_acknowledgements_and_clock_ticks():
    with BagReader(BAG) as reader:
        player, ros, topics = play(reader)
        player.run(keep_clock_after=False)
        total = sum(reader.topics()[t].count for t in topics)
        assert player.sent == total == len(ros.messages) and player.loops_done == 1
        assert ros.acks == total // ACK_BATCH + 1, "every ACK_BATCH messages, and once at the end"
        assert ros.clock[0] == reader.start_ns, "/clock holds the bag's start before the first message"
        ticks = [t for t in ros.clock if t > reader.start_ns]
        assert ticks == sorted(ticks) and len(ticks) >= 0.9 * reader.duration_s / 0.01
        assert any("done:" in line for line in ros.logs)
        assert player.progress(total, "")["fraction"] == "1.0000"


def test_it_waits_for_the_subscribers_it_was_told_to_and_a_stop_ends_a_loop():
    with BagReader(BAG) as reader:
        ros = FakeRos(subscribers_after=5)
        player, ros, topics = play(reader, loop=True, waits=Waits({}, per_topic=1, timeout_s=5.0), ros=ros)
        thread = threading.Thread(target=player.run, args=(False,))
        thread.start()
        while player.loops_done < 2:
            thread.join(0.01)
        player.stop.set()
        thread.join(5)
        assert not thread.is_alive() and ros.asked > 5 and player.loops_done >= 2
