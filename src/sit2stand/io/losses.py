"""What a recorder lost, counted two ways: DDS's message-lost status, and gaps in each topic's publication sequence.

DDS's status alone misses losses. A reliable keep-last writer that dropped samples a slow reader had not acknowledged
either announces them in a heartbeat (counted as lost) or answers the reader's request for them with a GAP, which
marks them irrelevant and is not counted. Which of the two comes first is a race: a recorder stopped while 2000
samples went past a depth-50 writer kept 68 of them and read 0 lost in one of ~10 runs. A reader's own keep-last
queue overflowing is not counted either.

The publication sequence numbers the rmw hands with each sample tell what never arrived between two samples of one
writer, whatever the cause. rclpy does not say which writer sent a sample, so gaps are counted only while a topic has
one matched publisher (asked at the gap) and its numbers have never gone back (a second writer, or a restarted one,
starts again at 1; from then on that topic has DDS's count only). Samples lost after the last one received show in
DDS's count only. Each count is a lower bound of what was lost; a topic's loss is the larger of the two.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable

SEQUENCE_UNKNOWN = 2**63
"""Numbers from here up are not sequence numbers (rmw's ``RMW_MESSAGE_INFO_SEQUENCE_NUMBER_UNSUPPORTED`` is the
largest uint64); an rmw that gives those, or none, leaves the topic to DDS's count."""


class SequenceGaps:
    """Samples of one topic's writer that never arrived: the gaps between consecutive publication sequence numbers
    (see the module docstring for when they are counted)."""

    def __init__(self) -> None:
        self.missed = 0
        self.counting = True       # False once the numbers are not one writer's (went back, or unknown)
        self._last: int | None = None

    def see(self, sequence_number: int | None, publishers: Callable[[], int]) -> None:
        """Note one received sample's publication sequence number; ``publishers()`` says how many writers the
        topic's subscription matches now (asked only at a gap)."""
        if not self.counting:
            return
        if sequence_number is None or sequence_number >= SEQUENCE_UNKNOWN or \
                (self._last is not None and sequence_number <= self._last):
            self.counting = False
            return
        if self._last is not None and sequence_number > self._last + 1 and publishers() == 1:
            self.missed += sequence_number - self._last - 1
        self._last = sequence_number


class TopicLosses:
    """Per topic, samples lost on the way to the recorder: the larger of DDS's count and the sequence gaps."""

    def __init__(self) -> None:
        self.gaps: dict[str, SequenceGaps] = {}
        self.dds: dict[str, int] = {}

    def see(self, topic: str, sequence_number: int | None, publishers: Callable[[], int]) -> None:
        gaps = self.gaps.get(topic)
        if gaps is None:
            gaps = self.gaps[topic] = SequenceGaps()
        gaps.see(sequence_number, publishers)

    def dds_lost(self, topic: str, count: int) -> None:
        """DDS's message-lost total for ``topic``'s subscription."""
        self.dds[topic] = self.dds.get(topic, 0) + int(count)

    def forget(self, topic: str) -> None:
        """A subscription dropped before it took anything (it is made anew): its counts are not the topic's."""
        self.gaps.pop(topic, None)
        self.dds.pop(topic, None)

    def lost(self) -> dict[str, int]:
        """Topic -> samples lost, only topics that lost any."""
        counts = {t: max(self.dds.get(t, 0), self.gaps[t].missed if t in self.gaps else 0)
                  for t in sorted({*self.gaps, *self.dds})}
        return {t: n for t, n in counts.items() if n > 0}


class WithMessageInfo:
    """A subscription callback that takes each message with its message info (a dict, ``publication_sequence_number``
    among its keys) under either rclpy executor: rclpy 7.1.6's EventsExecutor passes them as one (message, info)
    tuple, SingleThreadedExecutor as two arguments. The signature says two, which is how rclpy decides to take the
    info."""

    __signature__ = inspect.Signature([inspect.Parameter("message", inspect.Parameter.POSITIONAL_ONLY),
                                       inspect.Parameter("info", inspect.Parameter.POSITIONAL_ONLY)])

    def __init__(self, callback: Callable[[object, dict], None]) -> None:
        self.callback = callback

    def __call__(self, *args) -> None:
        message, info = args if len(args) == 2 else args[0]
        self.callback(message, info)
