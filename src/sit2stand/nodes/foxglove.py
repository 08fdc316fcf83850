"""Foxglove node: chosen topics of a running graph served to Foxglove over WebSocket (:mod:`sit2stand.io.live_view`).

Open Foxglove, "Open connection", Foxglove WebSocket ``ws://localhost:8765``, and import the shipped layout
(``sit2stand/data/layouts/standup.json``: the robot and the human in 3D, the paper's Fig. 6 plots).

Parameters:
    port (int, 8765)             WebSocket port (0: any free one, printed).
    host (str, 127.0.0.1)        address to listen on (0.0.0.0: every interface).
    topics (str[], [])           serve these topics ...
    regex (str, DEFAULT_REGEX)   ... and every topic whose name matches (the stand-up graph's topics, /tf and the
                                 descriptions).
    use_sim_time (bool)          standard: log times from /clock (a replay's bag time).

The robot's meshes: ``/robot_description`` goes out with ``package://`` mesh URIs (:func:`_with_package_uris`), and
the server answers a client's fetch of one with the mesh file (the protocol's assets capability), so Foxglove's web
app draws the robot too.

Topics are those of the node's namespace, served under their bag names (``/robot2/tf`` as ``/tf`` for a node in
``/robot2``: one view per robot). Each is subscribed raw with its publishers' QoS (as the recorder does), so the
bytes go to the client undecoded; transient-local topics are resent to clients that subscribe later.
"""

from __future__ import annotations

import re

from rclpy.node import Node
from rclpy.qos import DurabilityPolicy
from rclpy.serialization import deserialize_message, serialize_message
from std_msgs.msg import String

from ..io.live_view import LiveView
from ..io.topics import HUMAN_DESCRIPTION_TOPIC, ROBOT_DESCRIPTION_TOPIC, bag_name
from ..robot.packages import package_asset, package_uris
from .runtime import IdleDrain, NodeError, declare, message_class, node_main, steady_timer
from .qos import qos_matching_publishers

DEFAULT_REGEX = r"^/(mocap|force_plate|human|robot|viz)/|^/tf(_static)?$|^/robot_description$"


DESCRIPTION_TOPICS = frozenset({ROBOT_DESCRIPTION_TOPIC, HUMAN_DESCRIPTION_TOPIC})


def _with_package_uris(data: bytes) -> bytes:
    """A description (std_msgs/String, CDR) whose ``file://`` mesh URIs are served as ``package://`` ones: a client
    fetches those through the connection (a browser cannot open a ``file://`` URI of this machine)."""
    msg = deserialize_message(bytes(data), String)
    served = package_uris(msg.data)
    return data if served == msg.data else serialize_message(String(data=served))


class FoxgloveNode(Node):
    """Serves topics to Foxglove (see the module docstring)."""

    executor_kind = "events"  # callbacks only: the fast executor is safe here

    def __init__(self) -> None:
        super().__init__("foxglove")
        port = declare(self, "port", 8765, "WebSocket port (0: any free one)")
        host = declare(self, "host", "127.0.0.1", "address to listen on")
        self.topics = set(declare(self, "topics", [], "topics to serve"))
        regex = declare(self, "regex", DEFAULT_REGEX, "serve topics matching this regular expression")
        try:
            self.regex = re.compile(regex) if regex else None
        except re.error as err:
            raise NodeError(f"parameter regex is not a regular expression: {err}") from None
        try:
            self.view = LiveView(host, port, asset_handler=package_asset)
        except RuntimeError as err:        # the SDK's error for a port in use
            raise NodeError(f"cannot serve on {host}:{port}: {err}") from None
        self.subs: dict[str, object] = {}
        self.sent = 0
        self.drain = IdleDrain(lambda: self.sent)
        steady_timer(self, 0.5, self._discover)
        steady_timer(self, 0.1, self.view.relatch)
        self.get_logger().info(f"Foxglove WebSocket server on ws://{host}:{self.view.port}")
        self._discover()

    def _discover(self) -> None:
        for resolved, types in self.get_topic_names_and_types():
            topic = bag_name(self.get_namespace(), resolved)       # None: another namespace's
            if topic is None or topic in self.subs or not (topic in self.topics or
                                                           (self.regex and self.regex.search(topic))):
                continue
            if not self.get_publishers_info_by_topic(resolved):
                continue            # only subscribers so far: wait for a publisher to learn its QoS
            try:
                cls = message_class(types[0])
            except NodeError as err:
                self.get_logger().warning(f"not serving {topic}: {err}")
                self.subs[topic] = None
                continue
            qos = qos_matching_publishers(self, resolved, keep_all=False, depth=100)
            self.view.add_topic(topic, types[0], latched=qos.durability == DurabilityPolicy.TRANSIENT_LOCAL)
            self.subs[topic] = self.create_subscription(cls, resolved, lambda data, t=topic: self._on_message(t, data),
                                                        qos, raw=True)
            self.get_logger().info(f"serving {topic} ({types[0]})")

    def _on_message(self, topic: str, data: bytes) -> None:
        if topic in DESCRIPTION_TOPICS:
            data = _with_package_uris(data)
        self.view.log(topic, data, self.get_clock().now().nanoseconds)
        self.sent += 1

    def close(self) -> None:
        self.view.close()
        print(f"[foxglove] served {self.sent} messages on {sum(s is not None for s in self.subs.values())} topics",
              flush=True)


main = node_main(FoxgloveNode)

if __name__ == "__main__":
    raise SystemExit(main())
