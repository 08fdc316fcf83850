"""The replayer's play loop, without ROS: a bag's messages out at their recorded times on a :class:`PlaybackClock`.

The node (:mod:`sit2stand.nodes.replayer`) runs :meth:`PlayLoop.run` on a thread of its own and gives it, through
:class:`ReplayIO`, what touches the ROS graph: publishing a message and /clock, counting a topic's subscribers,
waiting for acknowledgements, reporting progress. Everything else is here: waiting for the subscribers, holding
/clock at the bag's start, pacing (or, unpaced, flow control by acknowledgements every :data:`ACK_BATCH` messages),
looping, waiting for a lockstep graph to catch up, and /clock after the bag's end.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

from .bag import BagReader
from .playback import ClockTicks, PlaybackClock, played_fraction
from .topics import FORCE_PLATE_PREFIX, MARKERS_TOPIC

ACK_BATCH = 200          # unpaced mode: wait for acknowledgements every this many messages
CLOCK_SETTLE_S = 0.1     # /clock at the bag's start this long before the first message, at least
HOLD_PERIOD_S = 0.02     # /clock is repeated this often while it holds the bag's start (best effort)


@dataclass
class ReplayIO:
    """What the play loop does to the ROS graph (the node's publishers and queries)."""

    publish: Callable[[str, bytes], None]          # topic, raw CDR
    publish_clock: Callable[[int], None] | None     # bag time [ns]; None: no /clock
    subscribers: Callable[[str], int]               # a topic's subscribers (see the replayer's wait_for)
    wait_acked: Callable[[bool], None]              # until every subscriber acknowledged; True: /clock goes on
    report: Callable[[bool], None]                  # progress; True: now, whatever the period
    info: Callable[[str], None]
    warning: Callable[[str], None]


@dataclass
class Waits:
    """Before playing: subscribers to wait for (topic -> count; or, with none, ``per_topic`` on every played topic),
    for ``timeout_s`` at most, then ``delay_s`` more."""

    counts: dict[str, int]
    per_topic: int = 0
    timeout_s: float = 10.0
    delay_s: float = 0.0


class PlayLoop:
    """Plays ``topics`` of ``reader`` on ``clock``; ``bag_now_ns`` is the bag time to play now (the node's, held
    back by its lockstep topics), ``caught_up`` whether a lockstep graph has processed all (True without one)."""

    def __init__(self, reader: BagReader, topics: list[str], clock: PlaybackClock, ticks: ClockTicks, io: ReplayIO,
                 waits: Waits, loop: bool, bag_now_ns: Callable[[], int], caught_up: Callable[[], bool]) -> None:
        self.reader, self.topics, self.clock, self.ticks, self.io = reader, topics, clock, ticks, io
        self.waits, self.loop = waits, loop
        self.bag_now_ns, self.caught_up = bag_now_ns, caught_up
        self.stop, self.wake = threading.Event(), threading.Event()
        self.sent = 0
        self.loops_done = 0
        self.t_first: float | None = None

    def run(self, keep_clock_after: bool) -> None:
        """Wait, play (looping if asked), wait for the graph, and with ``keep_clock_after`` keep /clock going after
        the bag's end until stopped. A bag or graph error propagates to the caller."""
        self._wait_for_subscribers()
        self._hold_clock_at_start(max(self.waits.delay_s, CLOCK_SETTLE_S))
        while not self.stop.is_set():
            self._play_once()
            if self.stop.is_set():
                return
            self.loops_done += 1
            if not self.loop:
                break
        while not self.stop.is_set() and not self.caught_up():
            self.wake.wait(0.02)
            self.wake.clear()
        if keep_clock_after:     # on from the last message's time: a replay behind its schedule must not jump ahead
            self.clock.restart(self.reader.end_ns)
        self.io.wait_acked(keep_clock_after)
        self.io.report(True)
        elapsed = time.monotonic() - self.t_first if self.t_first is not None else 0.0
        self.io.info(f"done: {self.sent} messages published in {elapsed:.3f} s "
                     f"({self.sent / elapsed if elapsed > 0 else 0.0:.0f} msg/s)")
        if keep_clock_after:
            self._keep_clock()

    def progress(self, total: int, holder: str) -> dict[str, str]:
        """What ``~/progress`` shows (``total``: the messages of one pass; ``holder``: the lockstep topic holding
        /clock now, "" for none)."""
        r = self.reader
        bag_t = min(max(0, self.clock.bag_now_ns() - r.start_ns) * 1e-9, r.duration_s)
        return {"fraction": f"{played_fraction(self.sent, total, self.loops_done, self.loop):.4f}",
                "bag_time_s": f"{bag_t:.3f}", "duration_s": f"{r.duration_s:.3f}", "messages_sent": str(self.sent),
                "loops_done": str(self.loops_done), "rate": f"{self.clock.rate:g}", "lockstep_waits_for": holder}

    def _play_once(self) -> None:
        self.clock.restart(self.reader.start_ns)
        since_ack = 0
        for msg in self.reader.messages(self.topics):
            while not self.stop.is_set():
                self.bag_now_ns()
                wait = self.clock.due_in_s(msg.timestamp_ns)
                if wait <= 0:
                    break
                self.wake.wait(min(wait, 0.05))
                self.wake.clear()
                self.io.report(False)
            if self.stop.is_set():
                return
            if self.io.publish_clock is not None and self.ticks.due(msg.timestamp_ns):
                self.io.publish_clock(msg.timestamp_ns)
            self.io.publish(msg.topic, msg.data)
            if self.t_first is None:
                self.t_first = time.monotonic()
            self.clock.played(msg.timestamp_ns)
            self.sent += 1
            since_ack += 1
            if self.clock.rate == 0.0 and since_ack >= ACK_BATCH:
                self.io.wait_acked(False)
                since_ack = 0
            self.io.report(False)

    def _wait_for_subscribers(self) -> None:
        # a capture topic the bag does not hold (a trial without a chair plate) has nobody to wait for
        absent = [t for t in self.waits.counts if t.startswith((FORCE_PLATE_PREFIX, MARKERS_TOPIC))
                  and t not in self.topics]
        if absent:
            self.io.info(f"the bag has no {', '.join(absent)}: not waiting for its subscribers")
        wanted = {t: n for t, n in self.waits.counts.items() if t not in absent}
        if not wanted and self.waits.per_topic > 0:
            wanted = {t: self.waits.per_topic for t in self.topics}
        if not wanted:
            return
        deadline = time.monotonic() + self.waits.timeout_s
        while not self.stop.is_set():
            short = [t for t, n in wanted.items() if self.io.subscribers(t) < n]
            if not short:
                return
            if time.monotonic() > deadline:
                self.io.warning(f"playing without the awaited subscribers on {', '.join(short)} after "
                                f"{self.waits.timeout_s:g} s")
                return
            self._hold_clock_at_start(HOLD_PERIOD_S)

    def _hold_clock_at_start(self, duration_s: float) -> None:
        """The bag's start time on /clock for ``duration_s`` (every :data:`HOLD_PERIOD_S`; best effort: repeated)."""
        end = time.monotonic() + duration_s
        while not self.stop.is_set():
            if self.io.publish_clock is not None:
                self.io.publish_clock(self.reader.start_ns)
            left = end - time.monotonic()
            if left <= 0:
                return
            time.sleep(min(HOLD_PERIOD_S, left))

    def _keep_clock(self) -> None:
        """After the bag: /clock every tick of play time from the last message on, until stopped."""
        period_s = self.ticks.period_ns * 1e-9
        while not self.stop.wait(period_s / max(self.clock.rate, 1.0)):
            self.io.publish_clock(max(self.bag_now_ns(), self.reader.end_ns))
