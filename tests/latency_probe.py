"""A test helper process: records, per message of the given topics, its header stamp and its arrival time (when DDS
received it: the sample's ``received_timestamp``, CLOCK_REALTIME, the clock serve-c3d prints its capture origin on;
not when this process's executor got round to the callback), then writes them as JSON at SIGINT.

    python tests/latency_probe.py OUT.json /mocap/markers /human/com /robot/retarget/ik
"""

import json
import signal
import sys

import rclpy
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from sit2stand_msgs.msg import CenterOfMass, MocapFrame

TYPES = {"/mocap/markers": MocapFrame, "/human/com": CenterOfMass, "/robot/retarget/ik": JointState}


def main() -> int:
    out, topics = sys.argv[1], sys.argv[2:]
    rclpy.init()
    node = rclpy.create_node("latency_probe")
    seen: dict[str, list[tuple[int, int]]] = {t: [] for t in topics}

    def on(topic):
        def cb(msg, info):
            seen[topic].append((msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec,
                                info["received_timestamp"]))
        return cb

    for t in topics:
        node.create_subscription(TYPES[t], t, on(t), QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE))
    stop = []
    signal.signal(signal.SIGINT, lambda *_: stop.append(1))
    signal.signal(signal.SIGTERM, lambda *_: stop.append(1))
    print("probe ready", flush=True)
    while not stop:
        rclpy.spin_once(node, timeout_sec=0.05)
    with open(out, "w") as f:
        json.dump(seen, f)
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
