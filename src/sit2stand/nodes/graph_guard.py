"""One graph per name on a ROS domain (:class:`GraphGuard`): every node started by ``node_main``
(:mod:`sit2stand.nodes.runtime`) announces its run and stops if another run's node of its name came first."""

from __future__ import annotations

import json
import os
import time

from rclpy.node import Node
from std_msgs.msg import String

from ..io.topics import GRAPH_TOPIC, RUN_ID_ENV
from .qos import LATCHED_ALL_QOS


class GraphGuard:
    """One graph per name: a node announces its run (the launcher's ``SIT2STAND_RUN_ID``, else its own process) on
    ``GRAPH_TOPIC`` (latched) and listens there. Another run's node with this node's fully qualified name means a
    second graph on the domain: the one that started later stops with an error naming the other (the earlier one
    logs a warning and goes on), before two graphs mix their data. Nodes in other namespaces never clash."""

    def __init__(self, node: Node) -> None:
        self.node, self.name = node, node.get_fully_qualified_name()
        self.run = os.environ.get(RUN_ID_ENV) or f"pid{os.getpid()}"
        self.started_ns = time.time_ns()
        self.conflict: str | None = None
        self._warned: set[str] = set()
        pub = node.create_publisher(String, GRAPH_TOPIC, LATCHED_ALL_QOS)
        pub.publish(String(data=json.dumps({"run": self.run, "node": self.name, "started_ns": self.started_ns,
                                            "pid": os.getpid()})))
        node.create_subscription(String, GRAPH_TOPIC, self._on_announce, LATCHED_ALL_QOS)

    def _on_announce(self, msg) -> None:
        try:
            other = json.loads(msg.data)
        except ValueError:
            return
        if other.get("node") != self.name or other.get("run") == self.run:
            return
        earlier = (other.get("started_ns", 0), other.get("pid", 0)) < (self.started_ns, os.getpid())
        domain = os.environ.get("ROS_DOMAIN_ID", "0")
        if earlier:
            self.conflict = (f"another graph's {self.name} (run {other.get('run')}, pid {other.get('pid')}) is "
                             f"running on ROS_DOMAIN_ID {domain}: this one (run {self.run}) stops before the two mix "
                             "their data; run it on another ROS_DOMAIN_ID, or in a namespace (sit2stand launch "
                             "--namespace NAME)")
        elif other.get("run") not in self._warned:
            self._warned.add(other.get("run"))
            self.node.get_logger().warning(f"a second {self.name} (run {other.get('run')}) appeared on ROS_DOMAIN_ID "
                                           f"{domain}; it was told to stop")
