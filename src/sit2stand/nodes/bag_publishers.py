"""The replayer's ROS side (:mod:`sit2stand.nodes.replayer`): a publisher per played topic with the bag's QoS,
``/clock``, and what the play loop (:class:`sit2stand.io.replay.PlayLoop`) asks of the ROS graph: subscriber
counts, acknowledgements, and that no other graph publishes the same topics."""

from __future__ import annotations

import os
import time
from collections.abc import Callable

from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock

from ..io.bag import BagReader
from ..io.topics import CLOCK_TOPIC, GRAPH_TOPIC, ros_name
from .runtime import NodeError, message_class
from .qos import publish_depth, publisher_names, qos_from_bag

ACK_TIMEOUT_S = 10.0
"""How long the subscribers have in all to acknowledge what was published (a dead one, e.g. a killed recorder,
never does)."""
CLOCK_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT, durability=DurabilityPolicy.VOLATILE)


class SharedDomain(NodeError):
    """Another node publishes one of the played topics on this ROS domain: two graphs would mix their data."""


class BagPublishers:
    """Publishers of ``topics`` of ``reader`` (default: all but another run's bookkeeping) on ``node``, and of
    /clock with ``publish_clock``; ``skip_unknown``: leave out a topic whose type has no Python class here (with a
    warning) instead of failing."""

    def __init__(self, node: Node, reader: BagReader, topics: list[str], skip_unknown: bool,
                 publish_clock: bool) -> None:
        self.node, self.reader = node, reader
        bag_topics = reader.topics()
        wanted = topics or sorted(set(bag_topics) - {GRAPH_TOPIC})
        missing = [t for t in wanted if t not in bag_topics]
        if missing:
            raise NodeError(f"{reader.path}: no topic {', '.join(missing)} (it has {', '.join(sorted(bag_topics))})")
        self.pubs = {}
        for topic in wanted:
            try:
                cls = message_class(bag_topics[topic].msgtype)
            except NodeError as err:
                if skip_unknown:
                    node.get_logger().warning(f"skipping {topic}: {err}")
                    continue
                raise NodeError(f"{reader.path}: topic {topic}: {err}") from None
            qos = qos_from_bag(reader.qos(topic), publish_depth(bag_topics[topic].rate_hz))
            self.pubs[topic] = node.create_publisher(cls, ros_name(topic), qos)
        if not self.pubs:
            raise NodeError(f"{reader.path}: nothing to play")
        self.total = sum(bag_topics[t].count for t in self.pubs)
        self.clock_pub = node.create_publisher(Clock, ros_name(CLOCK_TOPIC), CLOCK_QOS) if publish_clock else None

    def publish(self, topic: str, data: bytes) -> None:
        self.pubs[topic].publish(data)

    def publish_clock(self, bag_ns: int) -> None:
        clock = Clock()
        clock.clock.sec, clock.clock.nanosec = divmod(int(bag_ns), 1_000_000_000)
        self.clock_pub.publish(clock)

    def subscribers(self, topic: str) -> int:
        """Matched subscriptions of a played topic or /clock; the graph's subscriptions on any other topic."""
        if topic in self.pubs:
            return self.pubs[topic].get_subscription_count()
        if topic == CLOCK_TOPIC and self.clock_pub is not None:
            return self.clock_pub.get_subscription_count()
        return self.node.count_subscribers(ros_name(topic))

    def wait_acked(self, clock_ns: Callable[[], int] | None) -> None:
        """Wait until the subscribers acknowledged all, :data:`ACK_TIMEOUT_S` at most in all; with ``clock_ns``,
        /clock goes on meanwhile at that time (a graph's time frozen for 10 s made its simulated robot stand still,
        then fall). Waits in 2 ms slices: rclpy holds the GIL while it waits."""
        deadline = time.monotonic() + ACK_TIMEOUT_S
        for topic, pub in self.pubs.items():
            if pub.qos_profile.reliability != ReliabilityPolicy.RELIABLE or not pub.get_subscription_count():
                continue
            while not pub.wait_for_all_acked(Duration(seconds=0.002)):
                if time.monotonic() > deadline:
                    self.node.get_logger().warning(f"{topic}: subscribers did not acknowledge within "
                                                   f"{ACK_TIMEOUT_S} s")
                    break
                if clock_ns is not None:
                    self.publish_clock(clock_ns())

    def check_alone(self) -> None:
        """Raise :class:`SharedDomain` if another node publishes a topic played here (in this namespace: another
        graph in another namespace is no conflict)."""
        for topic in self.pubs:
            publishers = self.node.get_publishers_info_by_topic(ros_name(topic))  # ours among them
            if len(publishers) > 1:
                names = publisher_names(publishers)
                domain = os.environ.get("ROS_DOMAIN_ID", "0")
                raise SharedDomain(f"{self.node.resolve_topic_name(ros_name(topic))} has {len(publishers)} "
                                   f"publishers ({', '.join(names)}) on ROS domain {domain}: two graphs there would "
                                   f"mix their data; stopping (give each its own namespace, sit2stand launch "
                                   f"--namespace, or its own ROS_DOMAIN_ID)")
