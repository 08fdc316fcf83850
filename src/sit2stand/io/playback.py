"""Playback timing for bag replay: which wall-clock instant each bag timestamp is due at, with rate and pause.

Pure (no ROS): the replayer node drives a :class:`PlaybackClock` and sleeps until :meth:`PlaybackClock.due_in_s`
says a message is due. Time arguments are ``time.monotonic()`` seconds unless named ``*_ns`` (bag time).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from ..errors import InputError

MIN_RATE = 0.1
MAX_RATE = 50.0


def check_rate(rate: float) -> float:
    """A replay rate: 0 (as fast as the subscribers take it) or 0.1x..50x real time."""
    rate = float(rate)
    if rate != 0.0 and not MIN_RATE <= rate <= MAX_RATE:
        raise InputError(f"rate {rate:g} is outside {MIN_RATE:g}..{MAX_RATE:g} (or 0 for as fast as possible)")
    return rate


class PlaybackClock:
    """Maps bag time [ns] to wall time [s] for a replay at ``rate`` x real time, with pause/resume.

    ``rate == 0`` means unpaced: every message is due at once (:meth:`due_in_s` returns 0).
    """

    def __init__(self, bag_start_ns: int, rate: float = 1.0, now: Callable[[], float] = time.monotonic) -> None:
        self.rate = check_rate(rate)
        self._now = now
        self._bag_origin_ns = int(bag_start_ns)
        self._wall_origin = now()
        self._paused_at: float | None = None
        self._last_bag_ns = int(bag_start_ns)

    @property
    def paused(self) -> bool:
        return self._paused_at is not None

    def restart(self, bag_start_ns: int) -> None:
        """Start again from ``bag_start_ns`` now (used when looping)."""
        self._bag_origin_ns = int(bag_start_ns)
        self._wall_origin = self._now()
        self._last_bag_ns = int(bag_start_ns)
        if self._paused_at is not None:
            self._paused_at = self._wall_origin

    def pause(self) -> None:
        if self._paused_at is None:
            self._paused_at = self._now()

    def resume(self) -> None:
        if self._paused_at is not None:
            self._wall_origin += self._now() - self._paused_at
            self._paused_at = None

    def set_rate(self, rate: float) -> None:
        """Change the rate without a jump in bag time."""
        rate = check_rate(rate)
        now_bag = self.bag_now_ns()
        self.rate = rate
        self._bag_origin_ns = now_bag
        self._wall_origin = self._paused_at if self._paused_at is not None else self._now()

    def bag_now_ns(self) -> int:
        """The bag time being played now (for /clock); frozen while paused; last played time when unpaced."""
        if self.rate == 0.0:
            return self._last_bag_ns
        wall = self._paused_at if self._paused_at is not None else self._now()
        return self._bag_origin_ns + int((wall - self._wall_origin) * self.rate * 1e9)

    def due_in_s(self, bag_t_ns: int) -> float:
        """Seconds until the message stamped ``bag_t_ns`` is due (<= 0: due now; inf while paused)."""
        if self._paused_at is not None:
            return float("inf")
        if self.rate == 0.0:
            return 0.0
        due = self._wall_origin + (bag_t_ns - self._bag_origin_ns) * 1e-9 / self.rate
        return due - self._now()

    def played(self, bag_t_ns: int) -> None:
        """Note that the message at ``bag_t_ns`` has been published."""
        self._last_bag_ns = int(bag_t_ns)


def parse_wait_for(entries: list[str]) -> dict[str, int]:
    """``TOPIC:COUNT`` entries (the replayer's ``wait_for``) as {topic: subscribers to wait for}.

    Raises:
        InputError: an entry that is not an absolute topic, a colon and a count.
    """
    wanted = {}
    for entry in entries:
        topic, _, count = entry.rpartition(":")
        if not topic.startswith("/") or not count.isdigit():
            raise InputError(f"parameter wait_for: {entry!r} is not TOPIC:COUNT")
        wanted[topic] = int(count)
    return wanted


class ClockTicks:
    """When to publish ``/clock`` while playing: every ``period_ns`` of bag time, and again after a loop restarts."""

    def __init__(self, period_ns: int) -> None:
        self.period_ns = period_ns
        self.last_ns: int | None = None

    def due(self, bag_t_ns: int) -> bool:
        """True (and noted) if a clock message is due at the message stamped ``bag_t_ns``."""
        if self.last_ns is not None and self.last_ns <= bag_t_ns < self.last_ns + self.period_ns:
            return False
        self.last_ns = bag_t_ns
        return True


def played_fraction(sent: int, total: int, loops_done: int, loop: bool) -> float:
    """Share of the bag played in the current pass (0..1), from the messages sent so far."""
    done = sent - loops_done * total if loop else sent
    return min(1.0, max(0.0, done / max(1, total)))
