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

    def hold_at(self, ceiling_ns: int | None) -> bool:
        """Keep bag time from passing ``ceiling_ns`` (None: no limit): while it would, the wall origin slides, so
        that time stands at the ceiling and goes on from there, without a jump, once the ceiling rises. Never
        before the last played message (time shown on /clock does not go back). True when held. No effect while
        paused or unpaced."""
        if ceiling_ns is None or self.rate == 0.0 or self._paused_at is not None:
            return False
        over_ns = self.bag_now_ns() - max(int(ceiling_ns), self._last_bag_ns)
        if over_ns <= 0:
            return False
        self._wall_origin += over_ns * 1e-9 / self.rate
        return True

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


ENDED_SILENCE_S = 0.2
"""Wall time [s] after which a followed stream that ended with the bag stops holding the clock (see Lockstep)."""
FIRST_MESSAGE_TIMEOUT_S = 60.0
"""Longest wait [s, wall] for a followed topic's first message (a node that never starts publishing)."""


def lockstep_lead_ns(lead_s: float, frame_rate_hz: float) -> int:
    """How far /clock may lead the followed topics [ns]: ``lead_s``, or, where the bag's marker frames are further
    apart, one frame of them and 1 %: the next frame must come due (a 60 Hz bag under a 10 ms lead waited out the
    stall timeout at every frame). ``frame_rate_hz`` 0: no marker frames."""
    period_s = 1.0 / frame_rate_hz if frame_rate_hz > 0 else 0.0
    return int(round(1e9 * (lead_s if period_s <= 1.001 * lead_s else 1.01 * period_s)))


class Lockstep:
    """The replay's clock held to what the graph has done (the simulator-owns-the-clock rule of Gazebo's lockstep):
    /clock may lead the newest header stamp of each followed topic (the simulated robot's states, the retargeter's
    commands, the estimator's output) by at most ``lead_ns``, so a node that falls behind on a loaded machine slows
    the whole graph's time instead of falling behind it.

    Before a followed topic's first message, while a node offers it (``announced``), the replay may run ``first_ns``
    past the bag's start and then waits (a node that needs the first frames to start, e.g. the estimator's
    calibration, gets them, and the rest waits for it), at most :data:`FIRST_MESSAGE_TIMEOUT_S`. A topic stops
    holding the clock when it has held it for ``timeout_s`` of wall time without a newer message (a dead or stalled
    node; silence while another topic holds the clock is no stall; it holds again from its next message), or, once
    the clock has passed the bag's end, when its stamps stay within the bag for :data:`ENDED_SILENCE_S` (a stream
    derived from the bag's own, which ends with it; the robot's go on).
    """

    def __init__(self, topics: list[str], lead_ns: int, timeout_s: float, bag_span_ns: tuple[int, int],
                 first_ns: int) -> None:
        self.lead_ns = int(lead_ns)
        self.timeout_s = float(timeout_s)
        self.bag_start_ns, self.bag_end_ns = (int(t) for t in bag_span_ns)
        self.first_ns = int(first_ns)
        self._newest: dict[str, tuple[int, float]] = {t: (-1, 0.0) for t in topics}   # stamp [ns], wall [s]
        self._awaited_since: dict[str, float] = {}       # waiting for the first message since [s, wall]
        self._holding_since: dict[str, float] = {}       # holding the clock, with no newer message, since [s, wall]
        self.released: set[str] = set()                   # silent past the timeout (until their next message)

    @property
    def topics(self) -> list[str]:
        return list(self._newest)

    def note(self, topic: str, stamp_ns: int, wall_s: float) -> None:
        """A message of a followed topic with header stamp ``stamp_ns`` arrived at ``wall_s``."""
        if stamp_ns >= self._newest[topic][0]:
            self._newest[topic] = (int(stamp_ns), wall_s)
        self.released.discard(topic)
        self._holding_since.pop(topic, None)

    def holding(self, clock_ns: int, wall_s: float, announced: frozenset[str] = frozenset()) -> dict[str, int]:
        """The followed topics that bound the clock now, with the bag time [ns] each allows; ``announced``: the
        followed topics that some node offers (has a publisher for)."""
        out = {}
        for topic, (stamp_ns, seen_s) in self._newest.items():
            if stamp_ns < 0:
                if topic in announced and self._awaiting(topic, wall_s):
                    out[topic] = self.bag_start_ns + self.first_ns
                continue
            if topic in self.released:
                continue
            if clock_ns > self.bag_end_ns and stamp_ns <= self.bag_end_ns and wall_s - seen_s > ENDED_SILENCE_S:
                continue
            ceiling = stamp_ns + self.lead_ns
            if clock_ns >= ceiling and wall_s - self._holding_since.setdefault(topic, wall_s) > self.timeout_s:
                self.released.add(topic)
                continue
            if clock_ns < ceiling:
                self._holding_since.pop(topic, None)
            out[topic] = ceiling
        return out

    def _awaiting(self, topic: str, wall_s: float) -> bool:
        if self.first_ns < 0:
            return False
        since = self._awaited_since.setdefault(topic, wall_s)
        if wall_s - since > FIRST_MESSAGE_TIMEOUT_S:
            self.released.add(topic)
            return False
        return True

    def caught_up(self, wall_s: float) -> bool:
        """Every followed topic that has published has reached the bag's end (within ``lead_ns``), or is let go
        (released, or silent for ``timeout_s``): a replay that ends its graph waits for this, so that the last
        frames it played are processed."""
        for topic, (stamp_ns, seen_s) in self._newest.items():
            if stamp_ns < 0 or topic in self.released or wall_s - seen_s > self.timeout_s:
                continue
            if stamp_ns < self.bag_end_ns - self.lead_ns:
                return False
        return True

    def ceiling_ns(self, clock_ns: int, wall_s: float, announced: frozenset[str] = frozenset()) -> int | None:
        """The latest bag time /clock may show now (None: unbounded)."""
        bounds = self.holding(clock_ns, wall_s, announced)
        return min(bounds.values()) if bounds else None


class LockstepGate:
    """A :class:`Lockstep` applied to a :class:`PlaybackClock`: which followed topic holds /clock now (``holder``),
    and what changed for a log (topics that hold it for the first time; topics let go for a stall). Which followed
    topics some node offers is asked of the graph through ``offered_by_graph`` at most every ``ask_every_s``."""

    def __init__(self, lockstep: Lockstep, offered_by_graph: Callable[[str], bool], ask_every_s: float = 0.2) -> None:
        self.lockstep = lockstep
        self.holder = ""
        self._ask, self._every = offered_by_graph, ask_every_s
        self._held_by: set[str] = set()
        self._released: set[str] = set()
        self._offered: tuple[float, frozenset[str]] = (0.0, frozenset())

    def offered(self, wall_s: float) -> frozenset[str]:
        if wall_s - self._offered[0] > self._every:
            self._offered = (wall_s, frozenset(t for t in self.lockstep.topics if self._ask(t)))
        return self._offered[1]

    def hold(self, clock: PlaybackClock, wall_s: float) -> tuple[list[str], list[str]]:
        """Hold ``clock`` where the followed topics allow now; (topics holding it for the first time, topics let
        go since the last call)."""
        bounds = self.lockstep.holding(clock.bag_now_ns(), wall_s, self.offered(wall_s))
        self.holder, first = "", []
        if clock.hold_at(min(bounds.values()) if bounds else None):
            self.holder = min(bounds, key=bounds.get)
            if self.holder not in self._held_by:
                self._held_by.add(self.holder)
                first.append(self.holder)
        released = sorted(self.lockstep.released - self._released)
        self._released = set(self.lockstep.released)
        return first, released


def markers_rate_hz(counts: dict[str, int], span_ns: int, topic: str) -> float:
    """A topic's rate [Hz]: its message count over the bag's span (a bag's index does not time each topic)."""
    n = counts.get(topic, 0)
    return (n - 1) / (span_ns * 1e-9) if n > 1 and span_ns > 0 else 0.0


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
