"""What the retargeter node publishes (:mod:`sit2stand.nodes.retargeter`), its messages laid out once (the
per-command path runs at the plan's rate, in real time): the joint command first, then the planned COM and ZMP, the
COM feedback's shift, the plan's markers for the viewers, the raw IK pose and the status."""

from __future__ import annotations

import time

import numpy as np
from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from geometry_msgs.msg import PointStamped, Vector3Stamped
from rclpy.node import Node
from sensor_msgs.msg import JointState
from sit2stand_msgs.msg import CenterOfMass
from trajectory_msgs.msg import JointTrajectory
from visualization_msgs.msg import MarkerArray

from ..io.marker_message import marker_array_cdr
from ..io.stream_messages import CenterOfMassEncoder, JointStateEncoder, JointTrajectoryEncoder, StampedNumbersEncoder
from ..io.topics import (ROBOT_COM_FEEDBACK_TOPIC, ROBOT_JOINT_COMMAND_TOPIC, ROBOT_PLANNED_COM_TOPIC,
                         ROBOT_PLANNED_ZMP_TOPIC, ROBOT_RETARGET_IK_TOPIC, VIZ_MARKERS_TOPIC, WORLD_FRAME, ros_name)
from ..retarget.player import Command
from .markers import plan_marker_shapes
from .qos import PUBLISH_DEPTH

ROOT_COORDINATES = [f"root_{c}" for c in ("x", "y", "z", "qx", "qy", "qz", "qw")]
"""The base's entries of the raw IK pose (``/robot/retarget/ik``), before the joints'."""


class RetargetOutputs:
    """The retargeter's publishers on ``node``; ``markers_every``: the plan's markers with every this many commands
    (0: none). The command and IK messages need the joints: :meth:`calibrated` gives them."""

    def __init__(self, node: Node, markers_every: int) -> None:
        self.node = node
        self.pubs = {name: node.create_publisher(cls, ros_name(topic), PUBLISH_DEPTH) for name, cls, topic in (
            ("command", JointTrajectory, ROBOT_JOINT_COMMAND_TOPIC), ("com", CenterOfMass, ROBOT_PLANNED_COM_TOPIC),
            ("zmp", PointStamped, ROBOT_PLANNED_ZMP_TOPIC), ("feedback", Vector3Stamped, ROBOT_COM_FEEDBACK_TOPIC),
            ("ik", JointState, ROBOT_RETARGET_IK_TOPIC), ("viz", MarkerArray, VIZ_MARKERS_TOPIC))}
        self.pubs["status"] = node.create_publisher(DiagnosticStatus, "~/status", 10)
        self.encoders: dict[str, object] = {
            "com": CenterOfMassEncoder("robot_plan", WORLD_FRAME),
            "zmp": StampedNumbersEncoder(WORLD_FRAME, StampedNumbersEncoder.POINT),
            "feedback": StampedNumbersEncoder(WORLD_FRAME, 3)}
        self.markers_every = markers_every
        self.commands = 0
        self.support_xy: np.ndarray | None = None   # the plan's support polygon, once calibrated

    def calibrated(self, joint_names: list[str], root_link: str, support_xy: np.ndarray) -> None:
        self.encoders["command"] = JointTrajectoryEncoder(joint_names, root_link)
        self.encoders["ik"] = JointStateEncoder(ROOT_COORDINATES + joint_names, WORLD_FRAME, ("position",))
        self.support_xy = support_xy

    def command(self, cmd: Command, offset_m: np.ndarray | None) -> float:
        """The joint command first, stamped now (the driver applies it at once), then the planned COM and ZMP and
        the feedback's shift; the command's send time [s, perf_counter]: the latency ends there."""
        now = self.node.get_clock().now()
        t_ns = now.nanoseconds
        self.pubs["command"].publish(self.encoders["command"].encode(t_ns, cmd.q[7:], cmd.v[6:], cmd.a[6:]))
        sent = time.perf_counter()
        self.pubs["com"].publish(self.encoders["com"].encode(t_ns, cmd.com))
        self.pubs["zmp"].publish(self.encoders["zmp"].encode(t_ns, cmd.zmp))
        if offset_m is not None:
            self.pubs["feedback"].publish(self.encoders["feedback"].encode(t_ns, [offset_m[0], offset_m[1], 0.0]))
        self.commands += 1
        if self.markers_every > 0 and self.support_xy is not None and (self.commands - 1) % self.markers_every == 0:
            self.pubs["viz"].publish(marker_array_cdr(plan_marker_shapes(now.to_msg(), cmd.com, cmd.zmp,
                                                                         self.support_xy)))
        return sent

    def ik_pose(self, t_ns: int, q: np.ndarray) -> None:
        self.pubs["ik"].publish(self.encoders["ik"].encode(t_ns, q))

    def status(self, figures: dict[str, str], processed: int, infeasible: int) -> None:
        st = DiagnosticStatus(name=self.node.get_fully_qualified_name(), hardware_id="retargeter",
                              level=DiagnosticStatus.OK if not infeasible else DiagnosticStatus.WARN,
                              message=f"{processed} frames")
        st.values = [KeyValue(key=k, value=v) for k, v in figures.items()]
        self.pubs["status"].publish(st)
