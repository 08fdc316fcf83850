"""The QoS of sit2stand's topics: history depths deep enough that a reader held up by a loaded machine loses
nothing, latched state, the robot's state, and conversions to and from a bag's recorded QoS."""

from __future__ import annotations

import math

from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime


def qos_to_bag(profile: QoSProfile):
    """rosbags Qos (for bag metadata) of an rclpy QoSProfile."""

    def t(d) -> QosTime:
        ns = d.nanoseconds
        if ns <= 0 or ns >= 0x7FFFFFFF * 10**9:
            return QosTime(sec=0x7FFFFFFF, nsec=0xFFFFFFFF)
        return QosTime(sec=ns // 10**9, nsec=ns % 10**9)

    return Qos(
        history=QosHistory(int(profile.history)),
        depth=int(profile.depth),
        reliability=QosReliability(int(profile.reliability)),
        durability=QosDurability(int(profile.durability)),
        deadline=t(profile.deadline),
        lifespan=t(profile.lifespan),
        liveliness=QosLiveliness(int(profile.liveliness)),
        liveliness_lease_duration=t(profile.liveliness_lease_duration),
        avoid_ros_namespace_conventions=bool(profile.avoid_ros_namespace_conventions),
    )


# History depth of the publishers whose topics are recorded: a publisher that catches up after a stall (the
# retargeter after waiting for the human COM, the simulated robot after a late tick) sends a burst, and a reliable
# writer drops its oldest samples the recorder has not yet acknowledged beyond this depth (seen at 50 and 100:
# 7-13 samples missing from a bag)
PUBLISH_DEPTH = 1000
READER_STALL_S = 5.0
"""A recorded topic's publisher keeps at least this long of its samples [s] for a reader held up by a loaded
machine: a live stand-up on 2 cores lost 133 force-plate samples (1 kHz, depth 1000) and 7 /tf messages (50 Hz,
depth 100, as tf2_ros's) to a recorder held up for 1-2 s."""


def publish_depth(rate_hz: float) -> int:
    """History depth of a recorded topic's publisher at ``rate_hz``: ``READER_STALL_S`` of samples, at least
    ``PUBLISH_DEPTH``."""
    return max(PUBLISH_DEPTH, math.ceil(rate_hz * READER_STALL_S))


PLATE_PUBLISH_DEPTH = publish_depth(1000.0)


def robot_state_qos(rate_hz: float) -> QoSProfile:
    """The robot's joint states and base pose as the driver publishes them: reliable, ``publish_depth`` deep, and
    transient local, so that a node matched late still gets the latest state. In a graph held in lockstep the robot's
    clock waits for the retargeter's first command, and the retargeter for a state to calibrate on: with two
    stand-up graphs on 2 cores it matched the driver seconds after its first states, and in 2 of 4 runs never got
    one (the driver's clock held, nothing newer came)."""
    return QoSProfile(depth=publish_depth(rate_hz), reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL)


ROBOT_STATE_READER_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE,
                                    durability=DurabilityPolicy.TRANSIENT_LOCAL)
"""A reader of :func:`robot_state_qos` topics that wants the latest state on matching."""
TF_QOS = QoSProfile(depth=publish_depth(50.0), reliability=ReliabilityPolicy.RELIABLE)     # /tf at 50 Hz
# /tf_static, descriptions, the subject, parameters: the latest message reaches subscribers that come later
LATCHED_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
# a latched topic that many nodes publish once each: a late subscriber gets every node's message
LATCHED_ALL_QOS = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)


def qos_from_bag(profiles, depth: int = PUBLISH_DEPTH) -> QoSProfile:
    """An rclpy QoSProfile to replay a topic with the reliability/durability it was recorded with."""
    reliable, transient = True, False
    if profiles:
        reliable = all(int(getattr(p.reliability, "value", p.reliability)) != 2 for p in profiles)  # 2: best effort
        transient = all(int(getattr(p.durability, "value", p.durability)) == 1 for p in profiles)
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST, depth=depth,
        reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if transient else DurabilityPolicy.VOLATILE)


UNNAMED_BY_DDS = "_NODE_NAME_UNKNOWN_"   # rmw's name for a publisher whose node discovery has not named yet


def publisher_names(infos) -> list[str]:
    """The publishers of a topic as a person reads them: ``/ns/node`` where DDS has named the node, "another
    publisher" (counted) where discovery has not yet brought its name (rmw's ``_NODE_NAME_UNKNOWN_``)."""
    named = sorted({f"{i.node_namespace.rstrip('/')}/{i.node_name}" for i in infos if i.node_name != UNNAMED_BY_DDS})
    unnamed = sum(1 for i in infos if i.node_name == UNNAMED_BY_DDS)
    if unnamed:
        named.append("another publisher" if unnamed == 1 else f"{unnamed} other publishers")
    return named


def qos_matching_publishers(node: Node, topic: str, keep_all: bool = True, depth: int = 1000) -> QoSProfile:
    """A subscription QoS that connects to every current publisher of ``topic`` (as rosbag2 record does):
    reliable only if all publishers are reliable, transient-local only if all are.

    ``keep_all`` (a recorder's choice): a reliable reader never drops a sample it has acknowledged; when the
    application falls behind it stops acknowledging, which is what lets a flow-controlled publisher slow down."""
    infos = node.get_publishers_info_by_topic(topic)
    reliable = bool(infos) and all(i.qos_profile.reliability == ReliabilityPolicy.RELIABLE for i in infos)
    transient = bool(infos) and all(i.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL for i in infos)
    return QoSProfile(
        history=HistoryPolicy.KEEP_ALL if keep_all else HistoryPolicy.KEEP_LAST, depth=depth,
        reliability=ReliabilityPolicy.RELIABLE if reliable or not infos else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if transient else DurabilityPolicy.VOLATILE)


def known_topic_qos(latched: bool) -> QoSProfile:
    """The subscription QoS of a topic of :data:`~sit2stand.io.topics.TOPIC_TYPES` before its publishers are seen:
    what every sit2stand publisher offers (reliable; transient local when latched or an estimate: a volatile reader
    matched late lost the first 0.3 s of /human/com in 2 of 5 replays), keep-all as a recorder should."""
    return QoSProfile(history=HistoryPolicy.KEEP_ALL, depth=1000, reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE)


def matches_publishers(qos: QoSProfile, infos) -> bool:
    """Whether a subscription of ``qos`` connects to every publisher in ``infos`` (DDS request/offer rules)."""
    for info in infos:
        if qos.reliability == ReliabilityPolicy.RELIABLE and info.qos_profile.reliability != ReliabilityPolicy.RELIABLE:
            return False
        if qos.durability == DurabilityPolicy.TRANSIENT_LOCAL and \
                info.qos_profile.durability != DurabilityPolicy.TRANSIENT_LOCAL:
            return False
    return True
