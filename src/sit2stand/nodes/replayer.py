"""Replayer node: plays a bag's topics with their recorded timing, publishing /clock.

A bag's topics, raw CDR with their recorded QoS, at their recorded times (0.1-50x real time, or as fast as the
subscribers acknowledge), with /clock, pause and live rate changes, subscriber waits and lockstep with a graph's
slowest node; the play loop itself is :mod:`sit2stand.io.replay`, the clock and the lockstep
:mod:`sit2stand.io.playback`. Parameters, topics and services: ``docs/nodes.md`` (replayer).
"""

from __future__ import annotations

import os
import threading
import time
from pathlib import Path

from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from rclpy.node import Node
from rclpy.parameter import Parameter
from rcl_interfaces.msg import SetParametersResult
from sit2stand_msgs.msg import Subject as SubjectMsg
from std_srvs.srv import SetBool

from ..io.topics import MARKERS_TOPIC, SUBJECT_TOPIC, TOPIC_TYPES, ros_name
from ..io.bag import BagError, BagReader, bag_subject
from ..io.messages import cdr_header_stamp_ns
from ..io.playback import (ClockTicks, Lockstep, LockstepGate, PlaybackClock, check_rate, lockstep_lead_ns,
                           markers_rate_hz, parse_wait_for)
from ..io.replay import PlayLoop, ReplayIO, Waits
from .bag_publishers import BagPublishers, SharedDomain
from .runtime import NodeError, declare, message_class, node_main
from .qos import LATCHED_QOS, publish_depth

# Reliable writers heartbeat every 5 ms instead of Fast DDS's 3 s, so acknowledgements (and with them the unpaced
# mode's flow control) come quickly. Set before rclpy.init; a user's own profile file takes precedence.
os.environ.setdefault("FASTRTPS_DEFAULT_PROFILES_FILE", str(Path(__file__).with_name("replayer_fastdds.xml")))



class Replayer(Node):
    """Plays a bag onto topics (see the module docstring)."""

    def __init__(self) -> None:
        super().__init__("replayer")
        self.bag_path = declare(self, "bag", None, "rosbag2 directory to play")
        rate = declare(self, "rate", 1.0, "0.1..50 x real time; 0 = as fast as the subscribers take it")
        topics = declare(self, "topics", [], "topics to play (default: all)")
        self.loop = declare(self, "loop", False, "start again at the end")
        self.at_end = declare(self, "at_end", "exit", "exit | idle")
        publish_clock = declare(self, "publish_clock", True, "publish /clock")
        ticks = ClockTicks(int(1e9 / max(1e-3, declare(self, "clock_rate_hz", 100.0, "/clock rate [Hz]"))))
        per_topic = declare(self, "wait_for_subscribers", 0, "subscribers per topic to wait for")
        wait_for = declare(self, "wait_for", [], "TOPIC:COUNT entries: wait for these instead of every topic")
        wait_timeout_s = declare(self, "wait_timeout_s", 10.0, "longest wait for subscribers [s]")
        delay_s = declare(self, "delay_s", 0.0, "wait before the first message [s]")
        start_paused = declare(self, "start_paused", False, "wait for ~/pause false before playing")
        skip_unknown = declare(self, "skip_unknown_types", False, "skip topics without a Python message class")
        if not self.bag_path:
            raise NodeError("parameter 'bag' is required (a rosbag2 directory)")
        if self.at_end not in ("exit", "idle"):
            raise NodeError(f"parameter 'at_end' must be 'exit' or 'idle', not {self.at_end!r}")
        try:
            rate = check_rate(rate)
            waits = Waits(parse_wait_for(wait_for), per_topic, wait_timeout_s, delay_s)
            self.reader = BagReader(self.bag_path)
        except (ValueError, BagError) as err:
            raise NodeError(str(err)) from None

        self.out = BagPublishers(self, self.reader, topics, skip_unknown, publish_clock)
        self._latch_subject()
        self.clock_after_end = declare(self, "clock_after_end", False, "keep /clock going after the bag's end")
        self.progress_pub = self.create_publisher(DiagnosticStatus, "~/progress", 10)
        self.create_service(SetBool, "~/pause", self._on_pause)
        self.add_on_set_parameters_callback(self._on_parameters)

        self.clock = PlaybackClock(self.reader.start_ns, rate)
        io = ReplayIO(self.out.publish, self.out.publish_clock if self.out.clock_pub is not None else None,
                      self.out.subscribers, self._wait_acked, self._report, self.get_logger().info,
                      self.get_logger().warning)
        self.player = PlayLoop(self.reader, list(self.out.pubs), self.clock, ticks, io, waits, self.loop,
                               self._bag_now_ns, lambda: self.gate is None or self.gate.lockstep.caught_up(
                                   time.monotonic()))
        self.gate = self._follow(declare(self, "lockstep", [], "topics whose newest stamp /clock may lead"),
                                     declare(self, "lockstep_lead_s", 0.01, "how far /clock may lead them [s]"),
                                     declare(self, "lockstep_timeout_s", 10.0, "stall that releases a topic [s]"),
                                     declare(self, "lockstep_first_s", -1.0, "bag time before first messages [s]"))
        if start_paused:
            self.clock.pause()
        self.finished = False
        self.exit_code = 0
        self._last_progress = 0.0
        self._last_log = time.monotonic()
        self.get_logger().info(
            f"playing {self.bag_path}: {len(self.out.pubs)} topics, {self.out.total} messages, "
            f"{self.reader.duration_s:.2f} s at {'max' if rate == 0 else f'{rate:g}x'}"
            f"{' (paused)' if start_paused else ''}")
        self._thread = threading.Thread(target=self._play, name="playback", daemon=True)
        self._thread.start()

    def _follow(self, topics: list[str], lead_s: float, timeout_s: float, first_s: float) -> LockstepGate | None:
        """Subscribe to the lockstep topics (raw: only their header stamps are read)."""
        if not topics:
            return None
        unknown = [t for t in topics if t not in TOPIC_TYPES]
        if unknown:
            raise NodeError(f"parameter lockstep: no known type for {', '.join(unknown)} (one of "
                            f"{', '.join(sorted(TOPIC_TYPES))})")
        r = self.reader
        rate_hz = markers_rate_hz({t: i.count for t, i in r.topics().items()}, r.end_ns - r.start_ns, MARKERS_TOPIC)
        lead_ns = lockstep_lead_ns(lead_s, rate_hz)
        lockstep = Lockstep(topics, lead_ns, timeout_s, (r.start_ns, r.end_ns), int(first_s * 1e9) if first_s >= 0
                            else -1)
        for topic in topics:
            self.create_subscription(message_class(TOPIC_TYPES[topic]), ros_name(topic),
                                     lambda data, t=topic: self._on_followed(t, data), publish_depth(500.0), raw=True)
        self.get_logger().info(f"lockstep: /clock leads {', '.join(topics)} by at most {lead_ns * 1e-6:g} ms")
        return LockstepGate(lockstep, lambda t: bool(self.count_publishers(ros_name(t))))

    def _on_followed(self, topic: str, data: bytes) -> None:
        self.gate.lockstep.note(topic, cdr_header_stamp_ns(data), time.monotonic())
        self.player.wake.set()

    def _bag_now_ns(self) -> int:
        """The bag time to play and show on /clock now, held back by the lockstep topics."""
        if self.gate is not None:
            first, released = self.gate.hold(self.clock, time.monotonic())
            for topic in first:          # logged once per topic; ~/progress says which holds it now
                self.get_logger().info(f"lockstep: /clock waits for {topic}")
            for topic in released:
                self.get_logger().warning(f"lockstep: nothing on {topic} for a while: /clock goes on without it")
        return self.clock.bag_now_ns()

    # --- controls --------------------------------------------------------------------------------------------
    def _on_pause(self, request: SetBool.Request, response: SetBool.Response) -> SetBool.Response:
        if request.data:
            self.clock.pause()
        else:
            self.clock.resume()
        self.player.wake.set()
        response.success = True
        response.message = "paused" if self.clock.paused else "playing"
        self.get_logger().info(response.message)
        return response

    def _on_parameters(self, params: list[Parameter]) -> SetParametersResult:
        for param in params:
            if param.name == "rate":
                try:
                    self.clock.set_rate(param.value)
                except ValueError as err:
                    return SetParametersResult(successful=False, reason=str(err))
                self.player.wake.set()
        return SetParametersResult(successful=True)

    def _latch_subject(self) -> None:
        """/human/subject from the bag's metadata, latched, unless the bag plays the topic itself."""
        try:
            named = None if SUBJECT_TOPIC in self.out.pubs else bag_subject(self.reader.custom_data)
        except ValueError:
            self.get_logger().warning(f"{self.bag_path}: metadata height_m/body_mass_kg are not numbers: no subject")
            return
        if named is not None:
            msg = SubjectMsg(height_m=named.height_m, mass_kg=named.mass_kg, sex=named.sex, age_years=float("nan"))
            msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(int(self.reader.start_ns), 1_000_000_000)
            self.subject_pub = self.create_publisher(SubjectMsg, ros_name(SUBJECT_TOPIC), LATCHED_QOS)
            self.subject_pub.publish(msg)

    # --- playback thread: sit2stand.io.replay.PlayLoop, with self.out as its ROS side ---------------------------
    def _wait_acked(self, keep_clock: bool) -> None:
        self.out.wait_acked((lambda: max(self._bag_now_ns(), self.reader.end_ns)) if keep_clock else None)

    def _play(self) -> None:
        try:
            self.player.run(self.clock_after_end and self.at_end == "idle" and self.out.clock_pub is not None)
        except BagError as err:
            self.get_logger().error(str(err))
            self.exit_code = 1
        except SharedDomain as err:
            self.get_logger().error(str(err))
            self.exit_code = 2
        except Exception as err:  # noqa: BLE001 - a dying playback thread must not leave the node hanging
            if not self.player.stop.is_set():
                self.get_logger().error(f"playback failed: {err!r}")
                self.exit_code = 1
        finally:
            if self.at_end == "exit" or self.exit_code:
                self.finished = True

    def _report(self, force: bool = False) -> None:
        now = time.monotonic()
        if not force and now - self._last_progress < 0.5:
            return
        self._last_progress = now
        if not force:
            self.out.check_alone()
        figures = self.player.progress(self.out.total, self.gate.holder if self.gate is not None else "")
        status = DiagnosticStatus(level=DiagnosticStatus.OK, name=self.get_fully_qualified_name(),
                                  message="paused" if self.clock.paused else "playing", hardware_id=self.bag_path)
        status.values = [KeyValue(key=k, value=v) for k, v in figures.items()]
        self.progress_pub.publish(status)
        if force or now - self._last_log >= 2.0:
            self._last_log = now
            self.get_logger().info(f"{100 * float(figures['fraction']):5.1f}%  bag time {figures['bag_time_s']}/"
                                   f"{figures['duration_s']} s, {self.player.sent} messages"
                                   f"{' (paused)' if self.clock.paused else ''}")

    def close(self) -> None:
        self.player.stop.set()
        self.player.wake.set()
        self._thread.join(timeout=2.0)
        self.reader.close()


main = node_main(Replayer)

if __name__ == "__main__":
    raise SystemExit(main())
