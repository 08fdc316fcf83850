"""What the driver node publishes of the simulated robot (:mod:`sit2stand.nodes.driver`): each state sample (joint
states, the feet's ground reactions, the COP, the base pose, and /clock when the driver owns the time) laid out as
bytes (:mod:`sit2stand.io.stream_messages`), /tf every few samples, and /tf_static and /robot_description once."""

from __future__ import annotations

import time

import numpy as np
from builtin_interfaces.msg import Time as BuiltinTime
from geometry_msgs.msg import PointStamped, PoseStamped, TransformStamped, WrenchStamped
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from tf2_msgs.msg import TFMessage

from ..io.stream_messages import JointStateEncoder, StampedNumbersEncoder
from ..io.tf_message import TfEncoder
from ..io.topics import (CLOCK_TOPIC, ROBOT_BASE_POSE_TOPIC, ROBOT_COP_TOPIC, ROBOT_DESCRIPTION_TOPIC,
                         ROBOT_JOINT_STATES_TOPIC, TF_STATIC_TOPIC, TF_TOPIC, WORLD_FRAME, ft_topic, ros_name,
                         sole_world_aligned_frame)
from ..robot.description import DescriptionError, FrameTree, robot_description
from ..robot.driver_timing import SIM_EPOCH_S
from ..robot.model import SIDES
from ..robot.plant import Sensors
from ..robot.profile import RobotProfile
from ..vectors import pose_xyzw_from_wxyz
from .runtime import NodeError
from .qos import LATCHED_QOS, TF_QOS, publish_depth, robot_state_qos


class RobotOutputs:
    """The driver's state publishers on ``node`` for a robot of joints ``names`` and ``profile``, sampled at
    ``state_rate_hz``; /tf at ``tf_rate_hz`` (0: none) with the URDF's meshes as ``meshes`` URIs; /clock with
    ``publish_clock``."""

    def __init__(self, node: Node, names: list[str], profile: RobotProfile, state_rate_hz: float, tf_rate_hz: float,
                 meshes: str, publish_clock: bool) -> None:
        # deep enough that a recorder held up loses none
        depth, state_qos = publish_depth(state_rate_hz), robot_state_qos(state_rate_hz)
        self.pubs = {"joints": node.create_publisher(JointState, ros_name(ROBOT_JOINT_STATES_TOPIC), state_qos),
                     **{s: node.create_publisher(WrenchStamped, ros_name(ft_topic(s)), depth) for s in SIDES},
                     "cop": node.create_publisher(PointStamped, ros_name(ROBOT_COP_TOPIC), depth),
                     "base": node.create_publisher(PoseStamped, ros_name(ROBOT_BASE_POSE_TOPIC), state_qos),
                     "tf": node.create_publisher(TFMessage, ros_name(TF_TOPIC), TF_QOS),
                     # kept: a latched message lives as long as its publisher
                     "tf_static": node.create_publisher(TFMessage, ros_name(TF_STATIC_TOPIC), LATCHED_QOS),
                     "description": node.create_publisher(String, ros_name(ROBOT_DESCRIPTION_TOPIC), LATCHED_QOS)}
        self.clock_pub = node.create_publisher(Clock, ros_name(CLOCK_TOPIC), QoSProfile(
            depth=10, reliability=ReliabilityPolicy.BEST_EFFORT)) if publish_clock else None
        self.encoders = {
            "joints": JointStateEncoder(names, profile.root_link),
            **{side: StampedNumbersEncoder(sole_world_aligned_frame(side), StampedNumbersEncoder.WRENCH)
               for side in SIDES},
            "cop": StampedNumbersEncoder(WORLD_FRAME, StampedNumbersEncoder.POINT),
            "base": StampedNumbersEncoder(WORLD_FRAME, StampedNumbersEncoder.POSE)}
        try:
            self.urdf = robot_description(profile, meshes)
            self.frames = FrameTree(names, self.urdf, profile)
        except DescriptionError as err:
            raise NodeError(str(err)) from None
        self.tf_every = max(1, int(round(state_rate_hz / tf_rate_hz))) if tf_rate_hz > 0 else 0
        self.tf_encoder = TfEncoder(self.frames.pairs)
        self.tf_cost_s: list[float] = []          # per /tf message: forward kinematics + encoding + publish
        self.samples = 0
        self.state_rate_hz = state_rate_hz

    def state(self, s: Sensors, t_ns: int, sim_t_s: float) -> None:
        """One state sample stamped ``t_ns``; /clock at the simulated time ``sim_t_s`` when the driver owns it."""
        if self.clock_pub is not None:
            c = Clock()
            c.clock.sec, c.clock.nanosec = divmod(int(round((SIM_EPOCH_S + sim_t_s) * 1e9)), 1_000_000_000)
            self.clock_pub.publish(c)
        enc, pubs = self.encoders, self.pubs
        pubs["joints"].publish(enc["joints"].encode(t_ns, s.q, s.qd, s.tau))
        for side in SIDES:
            pubs[side].publish(enc[side].encode(t_ns, s.wrench_world[side][:6]))
        pubs["cop"].publish(enc["cop"].encode(t_ns, s.cop_m if s.cop_valid else np.full(3, np.nan)))
        # the base pose: x y z, then the quaternion w x y z (MuJoCo's order); the message's is x y z w
        pubs["base"].publish(enc["base"].encode(t_ns, pose_xyzw_from_wxyz(s.base_pose)))
        self.samples += 1
        if self.tf_every and (self.samples - 1) % self.tf_every == 0:     # from the first sample on
            self._tf(s, t_ns)

    def _tf(self, s: Sensors, t_ns: int) -> None:
        """world -> the root link and every moving joint of this state sample (raw CDR: see io/tf_message.py)."""
        t0 = time.perf_counter()
        translations, rotations = self.frames.transforms(s.base_pose, s.q)
        self.pubs["tf"].publish(self.tf_encoder.encode(t_ns, translations, rotations))
        if len(self.tf_cost_s) < 1_000_000:
            self.tf_cost_s.append(time.perf_counter() - t0)

    def latched(self, stamp: BuiltinTime) -> None:
        """/tf_static and /robot_description, stamped ``stamp``."""
        static = TFMessage()
        for tr in self.frames.static_transforms():
            m = TransformStamped(child_frame_id=tr.child)
            m.header.stamp, m.header.frame_id = stamp, tr.parent
            m.transform.translation.x, m.transform.translation.y, m.transform.translation.z = tr.translation_m
            r = m.transform.rotation
            r.x, r.y, r.z, r.w = tr.rotation_xyzw
            static.transforms.append(m)
        self.pubs["tf_static"].publish(static)
        self.pubs["description"].publish(String(data=self.urdf))

    def tf_cost_text(self) -> str:
        if not self.tf_cost_s:
            return "no /tf published"
        us = np.percentile(self.tf_cost_s, [50, 99]) * 1e6
        return (f"/tf at {self.state_rate_hz / self.tf_every:g} Hz: {len(self.tf_cost_s)} messages of "
                f"{len(self.frames.pairs)} transforms, {us[0]:.0f} us median, {us[1]:.0f} us p99 per message")
