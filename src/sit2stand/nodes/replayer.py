"""Replayer node: plays a bag's topics with their recorded timing, publishing /clock.

Parameters:
    bag (str, required)          rosbag2 directory to play.
    rate (float, 1.0)            0.1..50 x real time; 0 = as fast as the subscribers take it (reliable topics are
                                 flow-controlled by waiting for every subscriber's acknowledgement). Settable live.
    topics (str[], all)          only these topics.
    loop (bool, false)           start again at the end.
    at_end ("exit" | "idle")     what to do when done: leave (exit code 0) or keep the node alive.
    start_paused (bool, false)   wait for ~/pause(false) before playing.
    publish_clock (bool, true)   publish rosgraph_msgs/Clock on /clock at clock_rate_hz of bag time.
    clock_rate_hz (float, 100)
    clock_after_end (bool, false)  with at_end "idle": after the last message /clock goes on at the play rate, so a
                                 graph run under use_sim_time (the stand-up: the robot still stands after the
                                 human's recording ends) keeps its time base.
    wait_for_subscribers (int, 0)  before playing, wait until every topic has this many subscribers ...
    wait_for (str[], [])         ... or, instead, until each listed "TOPIC:COUNT" has COUNT subscribers (a topic
                                 the bag does not hold counts the graph's subscriptions: a downstream input;
                                 "/clock:N" counts the nodes under use_sim_time that have our clock) ...
    wait_timeout_s (float, 10)   ... or this long (then play anyway, with a warning).
    delay_s (float, 0)           extra wait before the first message.
    lockstep (str[], [])         topics (each with a std_msgs/Header first) whose newest stamp /clock may lead by at
                                 most lockstep_lead_s: the graph's time then waits for a node that falls behind (the
                                 simulated robot, the estimator) instead of running away from it; see
                                 :class:`sit2stand.io.playback.Lockstep` for when a topic is followed.
    lockstep_lead_s (float, 0.01) one mocap frame (at least the bag's own marker period, +1 %, where that is longer:
                                 :func:`sit2stand.io.playback.lockstep_lead_ns`): the recorded stamps then agree with
                                 their log times within a frame
                                 (the stand-up graph, elderly: robot states p99 10 ms, against 65 ms at 0.05, for a
                                 graph ~30 % slower on 2 cores).
    lockstep_timeout_s (float, 10) wall seconds a followed topic may hold the clock without a newer message (a node
                                 stalled longer, e.g. dead, is then not waited for; on 2 cores the estimator's mass
                                 re-solve stalls it for 3-4 s).
    lockstep_first_s (float, -1)  bag seconds played before a followed topic's first message is waited for, while
                                 some node offers it (e.g. what the estimator needs to calibrate); < 0: not waited for.
    While it waits, /clock holds the bag's start time, so that a node under use_sim_time has the bag's time before the
    first message reaches it (a recorder then logs nothing before the bag's start).
    skip_unknown_types (bool, false)  skip topics whose type has no Python class here, instead of failing.

Services: ~/pause (std_srvs/SetBool: true pauses, false resumes).
Topics out: every bag topic (raw CDR, recorded QoS), /clock, ~/progress (diagnostic_msgs/DiagnosticStatus, 2 Hz:
fraction, bag time, messages, rate, the lockstep topic holding /clock now);
/human/subject (latched) from the bag's metadata (``height_m``, ``body_mass_kg``, ``sex``) when the bag holds no
such topic, so that an estimator that takes the subject from the stream finds it for every bag.
Every topic is played relative to the node's namespace: a bag's ``/mocap/markers`` is ``/robot2/mocap/markers``
under ``__ns:=/robot2`` (:func:`sit2stand.io.topics.ros_name`), /clock included, and the check for another publisher
of a played topic looks there.
"""

from __future__ import annotations

import os
import threading
import time
from pathlib import Path

from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rcl_interfaces.msg import SetParametersResult
from rosgraph_msgs.msg import Clock
from sit2stand_msgs.msg import Subject as SubjectMsg
from std_srvs.srv import SetBool

from ..io.topics import (CLOCK_TOPIC, FORCE_PLATE_PREFIX, GRAPH_TOPIC, MARKERS_TOPIC, SUBJECT_TOPIC, TOPIC_TYPES,
                         ros_name)
from ..io.bag import BagError, BagReader
from ..io.messages import cdr_header_stamp_ns
from ..io.playback import (ClockTicks, Lockstep, PlaybackClock, check_rate, lockstep_lead_ns, parse_wait_for,
                           played_fraction)
from .runtime import (LATCHED_QOS, NodeError, declare, message_class, node_main, publish_depth, publisher_names,
                      qos_from_bag)

# Reliable writers heartbeat every 5 ms instead of Fast DDS's 3 s, so acknowledgements (and with them the unpaced
# mode's flow control) come quickly. Set before rclpy.init; a user's own profile file takes precedence.
os.environ.setdefault("FASTRTPS_DEFAULT_PROFILES_FILE", str(Path(__file__).with_name("replayer_fastdds.xml")))

ACK_BATCH = 200          # unpaced mode: wait for acknowledgements every this many messages
ACK_TIMEOUT_S = 10.0
CLOCK_SETTLE_S = 0.1    # /clock at the bag's start this long before the first message, at least


class SharedDomain(NodeError):
    """Another node publishes one of the played topics on this ROS domain: two graphs would mix their data."""


class Replayer(Node):
    """Plays a bag onto topics (see the module docstring)."""

    def __init__(self) -> None:
        super().__init__("replayer")
        self.bag_path = declare(self, "bag", None, "rosbag2 directory to play")
        rate = declare(self, "rate", 1.0, "0.1..50 x real time; 0 = as fast as the subscribers take it")
        self.topics_param = declare(self, "topics", [], "topics to play (default: all)")
        self.loop = declare(self, "loop", False, "start again at the end")
        self.at_end = declare(self, "at_end", "exit", "exit | idle")
        self.publish_clock = declare(self, "publish_clock", True, "publish /clock")
        self.clock_ticks = ClockTicks(int(1e9 / max(1e-3, declare(self, "clock_rate_hz", 100.0, "/clock rate [Hz]"))))
        self.wait_for_subscribers = declare(self, "wait_for_subscribers", 0, "subscribers per topic to wait for")
        wait_for = declare(self, "wait_for", [], "TOPIC:COUNT entries: wait for these instead of every topic")
        self.wait_timeout_s = declare(self, "wait_timeout_s", 10.0, "longest wait for subscribers [s]")
        self.delay_s = declare(self, "delay_s", 0.0, "wait before the first message [s]")
        start_paused = declare(self, "start_paused", False, "wait for ~/pause false before playing")
        skip_unknown = declare(self, "skip_unknown_types", False, "skip topics without a Python message class")
        if not self.bag_path:
            raise NodeError("parameter 'bag' is required (a rosbag2 directory)")
        if self.at_end not in ("exit", "idle"):
            raise NodeError(f"parameter 'at_end' must be 'exit' or 'idle', not {self.at_end!r}")
        try:
            rate = check_rate(rate)
            self.wait_for = parse_wait_for(wait_for)
            self.reader = BagReader(self.bag_path)
        except (ValueError, BagError) as err:
            raise NodeError(str(err)) from None

        bag_topics = self.reader.topics()
        wanted = self.topics_param or sorted(set(bag_topics) - {GRAPH_TOPIC})    # another run's bookkeeping
        missing = [t for t in wanted if t not in bag_topics]
        if missing:
            raise NodeError(f"{self.bag_path}: no topic {', '.join(missing)} (it has {', '.join(sorted(bag_topics))})")
        self.pubs = {}
        for topic in wanted:
            msgtype = bag_topics[topic].msgtype
            try:
                cls = message_class(msgtype)
            except NodeError as err:
                if skip_unknown:
                    self.get_logger().warning(f"skipping {topic}: {err}")
                    continue
                raise NodeError(f"{self.bag_path}: topic {topic}: {err}") from None
            qos = qos_from_bag(self.reader.qos(topic), publish_depth(bag_topics[topic].rate_hz))
            self.pubs[topic] = self.create_publisher(cls, ros_name(topic), qos)
        if not self.pubs:
            raise NodeError(f"{self.bag_path}: nothing to play")
        self.total = sum(bag_topics[t].count for t in self.pubs)
        self._latch_subject()
        self.clock_after_end = declare(self, "clock_after_end", False, "keep /clock going after the bag's end")
        self.clock_pub = self.create_publisher(
            Clock, ros_name(CLOCK_TOPIC), QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT,
                                        durability=DurabilityPolicy.VOLATILE)) if self.publish_clock else None
        self.progress_pub = self.create_publisher(DiagnosticStatus, "~/progress", 10)
        self.create_service(SetBool, "~/pause", self._on_pause)
        self.add_on_set_parameters_callback(self._on_parameters)

        self.clock = PlaybackClock(self.reader.start_ns, rate)
        self._holder = ""                               # the lockstep topic holding /clock now ("": none)
        self.lockstep = self._follow(declare(self, "lockstep", [], "topics whose newest stamp /clock may lead"),
                                     declare(self, "lockstep_lead_s", 0.01, "how far /clock may lead them [s]"),
                                     declare(self, "lockstep_timeout_s", 10.0, "stall that releases a topic [s]"),
                                     declare(self, "lockstep_first_s", -1.0, "bag time before first messages [s]"))
        if start_paused:
            self.clock.pause()
        self.sent = 0
        self.loops_done = 0
        self.finished = False
        self.exit_code = 0
        self._stop = threading.Event()
        self._wake = threading.Event()
        self._last_progress = 0.0
        self._t_first: float | None = None
        self._last_log = time.monotonic()
        self.get_logger().info(
            f"playing {self.bag_path}: {len(self.pubs)} topics, {self.total} messages, "
            f"{self.reader.duration_s:.2f} s at {'max' if rate == 0 else f'{rate:g}x'}"
            f"{' (paused)' if start_paused else ''}")
        self._thread = threading.Thread(target=self._play, name="playback", daemon=True)
        self._thread.start()

    def _follow(self, topics: list[str], lead_s: float, timeout_s: float, first_s: float) -> Lockstep | None:
        """Subscribe to the lockstep topics (raw: only their header stamps are read)."""
        if not topics:
            return None
        unknown = [t for t in topics if t not in TOPIC_TYPES]
        if unknown:
            raise NodeError(f"parameter lockstep: no known type for {', '.join(unknown)} (one of "
                            f"{', '.join(sorted(TOPIC_TYPES))})")
        # the markers' rate: their count over the bag's span (the index does not time each topic)
        markers, span_ns = self.reader.topics().get(MARKERS_TOPIC), self.reader.end_ns - self.reader.start_ns
        rate_hz = (markers.count - 1) / (span_ns * 1e-9) if markers is not None and markers.count > 1 and span_ns > 0 \
            else 0.0
        lead_ns = lockstep_lead_ns(lead_s, rate_hz)
        lockstep = Lockstep(topics, lead_ns, timeout_s, (self.reader.start_ns, self.reader.end_ns),
                            int(first_s * 1e9) if first_s >= 0 else -1)
        self._held_by: set[str] = set()
        self._released: set[str] = set()
        self._announced: tuple[float, frozenset[str]] = (0.0, frozenset())
        for topic in topics:
            self.create_subscription(message_class(TOPIC_TYPES[topic]), ros_name(topic),
                                     lambda data, t=topic: self._on_followed(t, data), publish_depth(500.0), raw=True)
        self.get_logger().info(f"lockstep: /clock leads {', '.join(topics)} by at most {lead_ns * 1e-6:g} ms")
        return lockstep

    def _on_followed(self, topic: str, data: bytes) -> None:
        self.lockstep.note(topic, cdr_header_stamp_ns(data), time.monotonic())
        self._wake.set()

    def _bag_now_ns(self) -> int:
        """The bag time to play and show on /clock now, held back by the lockstep topics."""
        if self.lockstep is not None:
            now = time.monotonic()
            bounds = self.lockstep.holding(self.clock.bag_now_ns(), now, self._offered(now))
            self._holder = ""
            if self.clock.hold_at(min(bounds.values()) if bounds else None):
                self._note_holder(min(bounds, key=bounds.get))
            for topic in self.lockstep.released - self._released:
                self.get_logger().warning(f"lockstep: nothing on {topic} for a while: /clock goes on without it")
            self._released = set(self.lockstep.released)
        return self.clock.bag_now_ns()

    def _offered(self, now: float) -> frozenset[str]:
        """The lockstep topics some node publishes (asked of the ROS graph at most every 0.2 s)."""
        if now - self._announced[0] > 0.2:
            self._announced = (now, frozenset(t for t in self.lockstep.topics if self.count_publishers(ros_name(t))))
        return self._announced[1]

    def _note_holder(self, topic: str) -> None:
        self._holder = topic
        if topic not in self._held_by:       # logged once per topic; ~/progress says which holds it now
            self._held_by.add(topic)
            self.get_logger().info(f"lockstep: /clock waits for {topic}")

    # --- controls --------------------------------------------------------------------------------------------
    def _on_pause(self, request: SetBool.Request, response: SetBool.Response) -> SetBool.Response:
        if request.data:
            self.clock.pause()
        else:
            self.clock.resume()
        self._wake.set()
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
                self._wake.set()
        return SetParametersResult(successful=True)

    def _latch_subject(self) -> None:
        """/human/subject from the bag's metadata, latched, unless the bag plays the topic itself."""
        custom = self.reader.custom_data
        if SUBJECT_TOPIC in self.pubs or not {"height_m", "body_mass_kg"} <= set(custom):
            return
        try:
            height, mass = float(custom["height_m"]), float(custom["body_mass_kg"])
        except ValueError:
            self.get_logger().warning(f"{self.bag_path}: metadata height_m/body_mass_kg are not numbers: no subject")
            return
        msg = SubjectMsg(height_m=height, mass_kg=mass, sex=custom.get("sex", "male"), age_years=float("nan"))
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(int(self.reader.start_ns), 1_000_000_000)
        self.subject_pub = self.create_publisher(SubjectMsg, ros_name(SUBJECT_TOPIC), LATCHED_QOS)
        self.subject_pub.publish(msg)

    # --- playback thread ---------------------------------------------------------------------------------------
    def _wait_for_subscribers(self) -> None:
        # a capture topic the bag does not hold (a trial without a chair plate) has nobody to wait for
        absent = [t for t in self.wait_for if t.startswith((FORCE_PLATE_PREFIX, MARKERS_TOPIC)) and t not in self.pubs]
        if absent:
            self.get_logger().info(f"the bag has no {', '.join(absent)}: not waiting for its subscribers")
        wanted = {t: n for t, n in self.wait_for.items() if t not in absent}
        if not wanted and self.wait_for_subscribers > 0:
            wanted = {t: self.wait_for_subscribers for t in self.pubs}
        if not wanted:
            return
        deadline = time.monotonic() + self.wait_timeout_s
        while not self._stop.is_set():
            # a played topic: our publisher's matched subscriptions; any other (e.g. a downstream node's input,
            # /human/com in the stand-up graph): the subscriptions the graph has on it
            short = [t for t, n in wanted.items() if self._subscribers(t) < n]
            if not short:
                return
            if time.monotonic() > deadline:
                self.get_logger().warning(f"playing without the awaited subscribers on {', '.join(short)} after "
                                          f"{self.wait_timeout_s:g} s")
                return
            self._hold_clock_at_start(0.02)

    def _subscribers(self, topic: str) -> int:
        """Matched subscriptions of a played topic or /clock; the graph's subscriptions on any other topic."""
        if topic in self.pubs:
            return self.pubs[topic].get_subscription_count()
        if topic == CLOCK_TOPIC and self.clock_pub is not None:
            return self.clock_pub.get_subscription_count()
        return self.count_subscribers(ros_name(topic))

    def _hold_clock_at_start(self, duration_s: float) -> None:
        """Publish the bag's start time on /clock for ``duration_s`` (every 20 ms; best effort, so repeated)."""
        end = time.monotonic() + duration_s
        while not self._stop.is_set():
            if self.clock_pub is not None:
                self._publish_clock(self.reader.start_ns)
            left = end - time.monotonic()
            if left <= 0:
                return
            time.sleep(min(0.02, left))

    def _wait_acked(self, keep_clock: bool = False) -> None:
        """Wait until the subscribers acknowledged all, ACK_TIMEOUT_S at most in all (a dead subscriber, e.g. a
        killed recorder, never does); ``keep_clock``: /clock goes on meanwhile (a graph's time frozen for 10 s made
        its simulated robot stand still, then fall). Waits in 2 ms slices: rclpy holds the GIL while it waits."""
        deadline = time.monotonic() + ACK_TIMEOUT_S
        for topic, pub in self.pubs.items():
            if pub.qos_profile.reliability != ReliabilityPolicy.RELIABLE or not pub.get_subscription_count():
                continue
            while not pub.wait_for_all_acked(Duration(seconds=0.002)):
                if time.monotonic() > deadline:
                    self.get_logger().warning(f"{topic}: subscribers did not acknowledge within {ACK_TIMEOUT_S} s")
                    break
                if keep_clock:
                    self._publish_clock(max(self._bag_now_ns(), self.reader.end_ns))

    def _play(self) -> None:
        try:
            self._wait_for_subscribers()
            self._hold_clock_at_start(max(self.delay_s, CLOCK_SETTLE_S))
            while not self._stop.is_set():
                self.clock.restart(self.reader.start_ns)
                since_ack = 0
                for msg in self.reader.messages(list(self.pubs)):
                    while not self._stop.is_set():
                        self._bag_now_ns()
                        wait = self.clock.due_in_s(msg.timestamp_ns)
                        if wait <= 0:
                            break
                        self._wake.wait(min(wait, 0.05))
                        self._wake.clear()
                        self._report()
                    if self._stop.is_set():
                        return
                    if self.clock_pub is not None and self.clock_ticks.due(msg.timestamp_ns):
                        self._publish_clock(msg.timestamp_ns)
                    self.pubs[msg.topic].publish(msg.data)
                    if self._t_first is None:
                        self._t_first = time.monotonic()
                    self.clock.played(msg.timestamp_ns)
                    self.sent += 1
                    since_ack += 1
                    if self.clock.rate == 0.0 and since_ack >= ACK_BATCH:
                        self._wait_acked()
                        since_ack = 0
                    self._report()
                self.loops_done += 1
                if not self.loop:
                    break
            self._wait_caught_up()
            keep_clock = self.clock_after_end and self.at_end == "idle" and self.clock_pub is not None
            if keep_clock:      # on from the last message's time: a replay behind its schedule must not jump ahead
                self.clock.restart(self.reader.end_ns)
            self._wait_acked(keep_clock)
            self._report(force=True)
            elapsed = time.monotonic() - self._t_first if self._t_first is not None else 0.0
            self.get_logger().info(f"done: {self.sent} messages published in {elapsed:.3f} s "
                                   f"({self.sent / elapsed if elapsed > 0 else 0.0:.0f} msg/s)")
            if keep_clock:
                self._keep_clock()
        except BagError as err:
            self.get_logger().error(str(err))
            self.exit_code = 1
        except SharedDomain as err:
            self.get_logger().error(str(err))
            self.exit_code = 2
        except Exception as err:  # noqa: BLE001 - a dying playback thread must not leave the node hanging
            if not self._stop.is_set():
                self.get_logger().error(f"playback failed: {err!r}")
                self.exit_code = 1
        finally:
            if self.at_end == "exit" or self.exit_code:
                self.finished = True

    def _wait_caught_up(self) -> None:
        """In lockstep, after the last message: wait until the followed nodes have processed it (the graph may end
        with the replay)."""
        while self.lockstep is not None and not self._stop.is_set() and \
                not self.lockstep.caught_up(time.monotonic()):
            self._wake.wait(0.02)
            self._wake.clear()

    def _publish_clock(self, bag_ns: int) -> None:
        clock = Clock()
        clock.clock.sec, clock.clock.nanosec = divmod(int(bag_ns), 1_000_000_000)
        self.clock_pub.publish(clock)

    def _keep_clock(self) -> None:
        """After the bag: /clock at ``clock_rate_hz`` of play time from the last message on, until stopped."""
        period_s = self.clock_ticks.period_ns * 1e-9
        while not self._stop.wait(period_s / max(self.clock.rate, 1.0)):
            self._publish_clock(max(self._bag_now_ns(), self.reader.end_ns))

    def _check_alone(self) -> None:
        """Raise :class:`SharedDomain` if another node publishes a topic this replayer plays (in its namespace:
        another graph in another namespace is no conflict)."""
        for topic in self.pubs:
            publishers = self.get_publishers_info_by_topic(ros_name(topic))  # ours among them
            if len(publishers) > 1:
                names = publisher_names(publishers)
                domain = os.environ.get("ROS_DOMAIN_ID", "0")
                raise SharedDomain(f"{self.resolve_topic_name(ros_name(topic))} has {len(publishers)} publishers "
                                   f"({', '.join(names)}) on ROS domain {domain}: two graphs there would mix their "
                                   f"data; stopping (give each its own namespace, sit2stand launch --namespace, or "
                                   f"its own ROS_DOMAIN_ID)")

    def _report(self, force: bool = False) -> None:
        now = time.monotonic()
        if not force and now - self._last_progress < 0.5:
            return
        self._last_progress = now
        if not force:
            self._check_alone()
        bag_t = min(max(0, self.clock.bag_now_ns() - self.reader.start_ns) * 1e-9, self.reader.duration_s)
        frac = played_fraction(self.sent, self.total, self.loops_done, self.loop)
        status = DiagnosticStatus(level=DiagnosticStatus.OK, name=self.get_fully_qualified_name(),
                                  message="paused" if self.clock.paused else "playing", hardware_id=self.bag_path)
        status.values = [KeyValue(key=k, value=v) for k, v in (
            ("fraction", f"{frac:.4f}"), ("bag_time_s", f"{bag_t:.3f}"),
            ("duration_s", f"{self.reader.duration_s:.3f}"), ("messages_sent", str(self.sent)),
            ("loops_done", str(self.loops_done)), ("rate", f"{self.clock.rate:g}"),
            ("lockstep_waits_for", self._holder))]
        self.progress_pub.publish(status)
        if force or now - self._last_log >= 2.0:
            self._last_log = now
            self.get_logger().info(f"{100 * frac:5.1f}%  bag time {bag_t:.2f}/{self.reader.duration_s:.2f} s, "
                                   f"{self.sent} messages{' (paused)' if self.clock.paused else ''}")

    def close(self) -> None:
        self._stop.set()
        self._wake.set()
        self._thread.join(timeout=2.0)
        self.reader.close()


main = node_main(Replayer)

if __name__ == "__main__":
    raise SystemExit(main())
