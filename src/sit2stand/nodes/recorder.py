"""Recorder node: records topics into a rosbag2 MCAP bag with raw (undeserialized) subscriptions.

Parameters: ``docs/nodes.md`` (recorder). Topics are written with their names relative to the recorder's namespace
(:func:`sit2stand.io.topics.bag_name`), so a bag replays into any namespace.

Every wanted topic of :data:`~sit2stand.io.topics.TOPIC_TYPES` is subscribed to at start-up, reliable (and transient
local for the latched ones), so a topic whose publisher appears mid-run is recorded from its first message; a
publisher whose QoS that subscription cannot match (best effort, or volatile on a latched topic) makes the recorder
subscribe anew. Other topics are found by polling the graph. Subscriptions take the QoS of the topic's publishers
(reliable only if all are, as rosbag2 does), and that QoS is stored in the bag. SIGINT or SIGTERM closes the bag
cleanly (summary and metadata.yaml written).

Losses are counted, never silent: each subscription keeps up to 100,000 samples not yet taken (recorder_fastdds.xml);
a sample that never reached the recorder (DDS's message-lost status, or a gap in its writer's publication sequence
numbers: :mod:`sit2stand.io.losses`) is counted per topic at close, logged, stored in the bag's ``custom_data`` as
``lost_messages``, and makes the node exit 1. The status is read at close only: the pinned rmw_fastrtps (8.4.3) can
deadlock taking that event while DDS reports a new loss (ros2/rmw_fastrtps#890). A latched state topic (depth 1)
keeps only its newest sample by design: a replaced sample is stored as ``superseded_latched_messages``, not an error.
"""

from __future__ import annotations

import os
import re
import time
from pathlib import Path

from rclpy.event_handler import QoSSubscriptionEventType
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node
from rclpy.qos import QoSProfile

from ..io.topics import (CLOCK_TOPIC, ESTIMATE_TOPICS, GRAPH_TOPIC, LATCHED_TOPICS, RUN_ID_ENV, TOPIC_TYPES, bag_name,
                         ros_name)
from ..io.bag import BagError, BagWriter
from ..io.losses import TopicLosses, WithMessageInfo
from .runtime import IdleDrain, NodeError, declare, message_class, node_main, steady_timer
from .qos import known_topic_qos, matches_publishers, qos_matching_publishers, qos_to_bag

# the deep reader queues (read when rclpy creates its DDS participant; a profile the user names wins)
os.environ.setdefault("FASTRTPS_DEFAULT_PROFILES_FILE", str(Path(__file__).with_name("recorder_fastdds.xml")))

DEFAULT_EXCLUDE = r"^/rosout$|^/parameter_events$"


class Recorder(Node):
    """Records topics into a bag (see the module docstring)."""

    executor_kind = "events"  # callbacks only, no publishing threads: the fast executor is safe here
    # after a signal, keep taking/processing what already arrived while it keeps coming (stops after 0.3 s idle);
    # a backlog (e.g. after the human_com calibration pause) can take several seconds under load
    drain_timeout_s = 30.0

    def __init__(self) -> None:
        super().__init__("recorder")
        out = declare(self, "output", "", "bag directory to create") or \
            f"bags/generated/rec_{time.strftime('%Y%m%d_%H%M%S')}"
        self.topics = set(declare(self, "topics", [], "topics to record (also when they appear later)"))
        regex = declare(self, "regex", "", "record topics matching this regular expression")
        exclude = declare(self, "exclude", DEFAULT_EXCLUDE, "never record topics matching this")
        self.include_clock = declare(self, "include_clock", False, "also record /clock")
        discovery_period = declare(self, "discovery_period_s", 0.5, "topic discovery period [s]")
        flush_period = declare(self, "flush_period_s", 0.5, "chunk flush period [s]: most a SIGKILL loses")
        try:
            self.regex = re.compile(regex) if regex else None
            self.exclude = re.compile(exclude) if exclude else None
        except re.error as err:
            raise NodeError(f"parameter regex/exclude is not a regular expression: {err}") from None
        self.record_all = not self.topics and self.regex is None
        try:
            self.writer = BagWriter(Path(out), custom_data={"recorded_by": "sit2stand recorder",
                                                            "run_id": os.environ.get(RUN_ID_ENV, "")})
        except BagError as err:
            raise NodeError(str(err)) from None
        self.output = Path(out)
        self.sim_time = bool(self.get_parameter("use_sim_time").value)
        self._early: list[tuple[str, bytes]] = []     # received before the first /clock (use_sim_time)
        self.subs = {}
        self.unconfirmed: dict[str, tuple[str, QoSProfile]] = {}   # subscribed before a publisher was seen
        self.lost: dict[str, int] = {}
        self.losses = TopicLosses()
        self.lost_status: dict[str, object] = {}     # topic -> its subscription's message-lost status (DDS)
        self.superseded: dict[str, int] = {}      # latched states replaced before the recorder took them
        self.skipped: set[str] = set()
        self.finished = False
        self.exit_code = 0
        self._closed = False
        steady_timer(self, discovery_period, self._discover)
        steady_timer(self, flush_period, self.writer.flush)
        steady_timer(self, 5.0, self._log_counts)
        # after SIGINT/SIGTERM, take what DDS already delivered (a publisher that just finished expects it on disk)
        self.drain = IdleDrain(lambda: sum(self.writer.counts.values()))
        what = ["all topics"] if self.record_all else ([", ".join(sorted(self.topics))] if self.topics else []) + \
            ([f"topics matching /{regex}/"] if regex else [])
        self.get_logger().info(f"recording to {self.output} ({' and '.join(what)})")
        self._subscribe_known()
        self._discover()

    def _wanted(self, topic: str) -> bool:
        if topic == CLOCK_TOPIC and not self.include_clock or topic == GRAPH_TOPIC:   # the graphs' own bookkeeping
            return False
        if self.exclude is not None and self.exclude.search(topic) and topic not in self.topics:
            return False
        return self.record_all or topic in self.topics or bool(self.regex and self.regex.search(topic))

    def _subscribe_known(self) -> None:
        """Subscribe now to every wanted topic whose type is known, before its publisher exists."""
        for topic, msgtype in TOPIC_TYPES.items():
            if self._wanted(topic):
                qos = known_topic_qos(topic in LATCHED_TOPICS or topic in ESTIMATE_TOPICS)
                self._subscribe(topic, ros_name(topic), message_class(msgtype), qos)
                self.unconfirmed[topic] = (msgtype, qos)

    def _discover(self) -> None:
        for resolved, types in self.get_topic_names_and_types():
            topic = bag_name(self.get_namespace(), resolved)       # None: another namespace's
            if topic is None or topic in self.skipped or not self._wanted(topic):
                continue
            if topic in self.subs and topic not in self.unconfirmed:
                continue
            infos = self.get_publishers_info_by_topic(resolved)
            if not infos:
                continue  # only subscribers so far: wait for a publisher to learn its QoS
            msgtype = types[0]
            if len(types) > 1:
                self.get_logger().warning(f"{topic} has several types {types}; recording {msgtype}")
            if topic in self.unconfirmed and not self._resubscribe(topic, resolved, msgtype, infos):
                continue
            self._record(topic, resolved, msgtype)

    def _resubscribe(self, topic: str, resolved: str, msgtype: str, infos) -> bool:
        """A subscription made before its publishers were seen: True when it cannot serve them (then dropped, to
        subscribe anew), False when it does (the topic is then declared in the bag with the publishers' QoS)."""
        known_type, qos = self.unconfirmed.pop(topic)
        if known_type == msgtype and matches_publishers(qos, infos):
            self._add_to_bag(topic, msgtype, qos_matching_publishers(self, resolved))
            self.get_logger().info(f"subscribed to {topic} ({msgtype}, reliable; since start-up)")
            return False
        self.get_logger().info(f"subscribing to {topic} anew: its publishers offer {msgtype}, "
                               f"{'best effort' if qos.reliability == 1 else 'reliable'} or volatile")
        self.lost_status.pop(topic, None)      # it matched no publisher: it took nothing, it lost nothing
        self.losses.forget(topic)
        self.destroy_subscription(self.subs.pop(topic))
        return True

    def _record(self, topic: str, resolved: str, msgtype: str) -> None:
        """Subscribe to a discovered topic with its publishers' QoS and declare it in the bag."""
        try:
            cls = message_class(msgtype)
            qos = qos_matching_publishers(self, resolved)
            self._add_to_bag(topic, msgtype, qos)
        except (NodeError, BagError) as err:
            self.get_logger().warning(f"not recording {topic}: {err}")
            self.skipped.add(topic)
            return
        self._subscribe(topic, resolved, cls, qos)
        self.get_logger().info(f"subscribed to {topic} ({msgtype}, "
                               f"{'reliable' if qos.reliability == 1 else 'best effort'})")

    def _subscribe(self, topic: str, name: str, cls, qos: QoSProfile) -> None:
        sub = self.create_subscription(cls, name, WithMessageInfo(lambda data, info, t=topic: self._on_message(
            t, data, info)), qos, raw=True)
        self.subs[topic] = sub
        with sub.handle:        # read at close only (see the module docstring), never put in the executor's wait set
            self.lost_status[topic] = _rclpy.EventHandle(sub.handle,
                                                         QoSSubscriptionEventType.RCL_SUBSCRIPTION_MESSAGE_LOST)

    def _take_lost(self) -> None:
        """Each subscription's losses since it was made, into ``lost`` / ``superseded``."""
        for topic, event in self.lost_status.items():
            with event:
                info = event.take_event()
            if info is not None and info.total_count:
                self.losses.dds_lost(topic, info.total_count)
        self.lost_status.clear()
        for topic, count in self.losses.lost().items():
            self._on_lost(topic, count)

    def _add_to_bag(self, topic: str, msgtype: str, qos: QoSProfile) -> None:
        self.writer.add_topic(topic, msgtype, [qos_to_bag(qos)])

    def _on_lost(self, topic: str, count: int) -> None:
        if topic in LATCHED_TOPICS:     # a state kept at depth 1: a newer one replaced it, by design; noted only
            self.superseded[topic] = self.superseded.get(topic, 0) + count
            return
        self.lost[topic] = self.lost.get(topic, 0) + count
        self.exit_code = 1

    def _on_message(self, topic: str, data: bytes, info: dict) -> None:
        sub = self.subs.get(topic)        # None: a sample of a subscription just made anew (no gap counted)
        publishers = int if sub is None else sub.get_publisher_count
        self.losses.see(topic, info.get("publication_sequence_number"), publishers)
        if not self.writer.has_topic(topic):      # a known topic's first message, before its publisher was polled
            msgtype, qos = self.unconfirmed[topic]
            self._add_to_bag(topic, msgtype, qos)
        now_ns = self.get_clock().now().nanoseconds
        if self.sim_time and now_ns == 0:        # no /clock yet: a log time of 0 would be no time of the bag's
            self._early.append((topic, data))
            return
        for early_topic, early in self._early:
            self.writer.write_raw(early_topic, now_ns, early)
        self._early.clear()
        self.writer.write_raw(topic, now_ns, data)

    def _lost_text(self) -> str:
        return ", ".join(f"{t}: {n}" for t, n in sorted(self.lost.items()))

    def _log_counts(self) -> None:
        counts = ", ".join(f"{t}: {n}" for t, n in sorted(self.writer.counts.items()))
        self.get_logger().info(f"recorded {sum(self.writer.counts.values())} messages ({counts})")

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        self._take_lost()
        for sub in self.subs.values():
            self.destroy_subscription(sub)
        if self._early:        # use_sim_time and never a /clock: kept, at log time 0, rather than lost
            print(f"[recorder] no /clock came: {len(self._early)} messages logged at time 0", flush=True)
            for topic, data in self._early:
                self.writer.write_raw(topic, 0, data)
        if self.lost:
            self.writer.set_custom_data("lost_messages", self._lost_text())
        if self.superseded:
            self.writer.set_custom_data("superseded_latched_messages",
                                        ", ".join(f"{t}: {n}" for t, n in sorted(self.superseded.items())))
        self.writer.close()
        total = sum(self.writer.counts.values())
        print(f"[recorder] closed {self.output}: {total} messages on {len(self.writer.counts)} topics", flush=True)
        if self.lost:
            print(f"[recorder] error: lost {sum(self.lost.values())} messages ({self._lost_text()}): their publishers "
                  f"dropped them before the recorder took them (it fell behind by more than their queue depth)",
                  flush=True)


main = node_main(Recorder)

if __name__ == "__main__":
    raise SystemExit(main())
