"""An observer for latency measurements (tests and benchmarks), not part of a graph: records, per message of the
given topics, its header stamp and when DDS received it (the sample's ``received_timestamp``, CLOCK_REALTIME: the
clock serve-c3d prints its capture origin on; not when this process's executor got round to the callback), and
writes them as JSON (``{topic: [[stamp_ns, received_ns], ...]}``) at SIGINT or SIGTERM.

    python -m sit2stand.nodes.latency_probe OUT.json /mocap/markers /human/com /robot/retarget/ik

It prints ``PROBE_READY`` once every topic has a publisher it has discovered (at most ``DISCOVERY_WAIT_S``): a
stream of 0.9 s (the real child trial) started right after the subscriptions were made was over before the probe's
DDS had matched the bridge, and no marker reached it. :mod:`sit2stand.capture.latency` turns the record into
latencies.
"""

from __future__ import annotations

import json
import signal
import sys
import time

import rclpy
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from sit2stand_msgs.msg import CenterOfMass, MocapFrame

from ..capture.latency import PROBE_READY
from ..io.messages import cdr_header_stamp_ns
from ..io.topics import HUMAN_COM_TOPIC, MARKERS_TOPIC, ROBOT_RETARGET_IK_TOPIC

TYPES = {MARKERS_TOPIC: MocapFrame, HUMAN_COM_TOPIC: CenterOfMass, ROBOT_RETARGET_IK_TOPIC: JointState}
DISCOVERY_WAIT_S = 20.0
"""How long the probe waits for its topics' publishers before it says it is ready anyway [s]."""
POLL_S = 0.01
"""How often the probe takes the samples waiting [s] (each reader keeps 1000)."""


def _take(subs: dict, seen: dict[str, list[tuple[int, int]]]) -> None:
    """Every sample waiting on each subscription: (header stamp, DDS receive time) [ns] appended to its topic's list
    (``take_message`` is how rclpy's executors take them)."""
    for topic, sub in subs.items():
        with sub.handle:
            while (taken := sub.handle.take_message(sub.msg_type, True)) is not None:
                data, info = taken
                seen[topic].append((cdr_header_stamp_ns(data), info["received_timestamp"]))


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    if len(args) < 2 or any(t not in TYPES for t in args[1:]):
        print(f"usage: latency_probe OUT.json TOPIC... (topics: {', '.join(TYPES)})", file=sys.stderr)
        return 2
    out, topics = args[0], args[1:]
    rclpy.init()
    node = rclpy.create_node("latency_probe")
    seen: dict[str, list[tuple[int, int]]] = {t: [] for t in topics}

    # no executor: every 10 ms each subscription's samples are taken raw and only their stamps read. The probe runs
    # above the graph it measures; with rclpy's messages and executor it took 15-30 % of a core from it at 200 Hz.
    # The time recorded is the sample's DDS receive time, which a late take does not change.
    qos = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
    subs = {t: node.create_subscription(TYPES[t], t, lambda _: None, qos, raw=True) for t in topics}
    stop = []
    signal.signal(signal.SIGINT, lambda *_: stop.append(1))
    signal.signal(signal.SIGTERM, lambda *_: stop.append(1))
    deadline = time.monotonic() + DISCOVERY_WAIT_S
    while not stop and time.monotonic() < deadline and not all(node.count_publishers(t) for t in topics):
        time.sleep(0.05)
    print(PROBE_READY, flush=True)
    while not stop:
        time.sleep(POLL_S)
        _take(subs, seen)
    _take(subs, seen)
    with open(out, "w") as f:
        json.dump(seen, f)
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
