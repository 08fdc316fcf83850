"""What the human COM estimator node publishes (:mod:`sit2stand.nodes.human_com`): the COM first (the retargeter waits
for it), then the skeleton's joint angles, the pelvis pose and the delayed frame's COPs laid out as bytes
(:mod:`sit2stand.io.stream_messages`), the mass scaling when it is re-solved, and for the viewers /tf, the markers and
the skeleton's URDF."""

from __future__ import annotations

import numpy as np
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from geometry_msgs.msg import PointStamped, PoseStamped
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from sit2stand_msgs.msg import CenterOfMass, InertialParameters
from std_msgs.msg import Header, String
from tf2_msgs.msg import TFMessage
from visualization_msgs.msg import MarkerArray

from ..human.com_stream import StreamOutput
from ..human.description import SkeletonFrames, human_urdf
from ..human.mass_scaling import MassScaling
from ..human.skeleton import HumanModel
from ..io.marker_message import marker_array_cdr
from ..io.stream_messages import CenterOfMassEncoder, JointStateEncoder, StampedNumbersEncoder
from ..io.tf_message import TfEncoder
from ..io.topics import (HUMAN_COM_TOPIC, HUMAN_DESCRIPTION_TOPIC, HUMAN_JOINTS_TOPIC, HUMAN_MARKERS_TOPIC,
                         HUMAN_MEASURED_COP_TOPIC, HUMAN_MODEL_COP_TOPIC, HUMAN_PELVIS_POSE_TOPIC, HUMAN_ROOT_FRAME,
                         HUMAN_SCALING_TOPIC, LAB_FRAME, TF_TOPIC, ros_name)
from .markers import human_marker_shapes
from .qos import LATCHED_QOS, PUBLISH_DEPTH, TF_QOS


def ns_of(t_s: float) -> int:
    """``t_s`` [s] in integer nanoseconds."""
    return int(round(t_s * 1e9))


def time_of_ns(t_ns: int) -> Time:
    """builtin_interfaces/Time of ``t_ns`` [ns]."""
    sec, nsec = divmod(int(t_ns), 1_000_000_000)
    return Time(sec=sec, nanosec=nsec)


def stamp_of(t_s: float) -> Time:
    """builtin_interfaces/Time of ``t_s`` [s]."""
    return time_of_ns(ns_of(t_s))


class HumanOutputs:
    """The estimator's publishers on ``node``; /tf and the markers every ``viz_every`` frames (0: none)."""

    def __init__(self, node: Node, viz_every: int) -> None:
        # transient-local with a deep history: a subscriber that matches late (a recorder still discovering the
        # topic when the first frames come) still gets every estimate
        history = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=PUBLISH_DEPTH,
                             reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.pubs = {name: node.create_publisher(cls, ros_name(topic), qos) for name, cls, topic, qos in (
            ("com", CenterOfMass, HUMAN_COM_TOPIC, history), ("joints", JointState, HUMAN_JOINTS_TOPIC, history),
            ("pelvis", PoseStamped, HUMAN_PELVIS_POSE_TOPIC, history),
            ("model_cop", PointStamped, HUMAN_MODEL_COP_TOPIC, history),
            ("measured_cop", PointStamped, HUMAN_MEASURED_COP_TOPIC, history),
            ("scaling", InertialParameters, HUMAN_SCALING_TOPIC, LATCHED_QOS),
            ("tf", TFMessage, TF_TOPIC, TF_QOS), ("viz", MarkerArray, HUMAN_MARKERS_TOPIC, PUBLISH_DEPTH),
            ("description", String, HUMAN_DESCRIPTION_TOPIC, LATCHED_QOS))}
        self.stats_pub = node.create_publisher(DiagnosticStatus, "~/stats", 10)
        self.node = node
        self.joint_encoder: JointStateEncoder | None = None     # the skeleton's joints: made with the estimator
        self.lab_pose = StampedNumbersEncoder(LAB_FRAME, StampedNumbersEncoder.POSE)
        self.lab_point = StampedNumbersEncoder(LAB_FRAME, StampedNumbersEncoder.POINT)
        self.com_encoder = CenterOfMassEncoder("skeleton_fit", LAB_FRAME)
        self.viz_every = viz_every
        self.described: HumanModel | None = None     # the skeleton the frames and description are of
        self.frames: SkeletonFrames | None = None
        self.tf_encoder: TfEncoder | None = None
        self.frames_seen = 0
        self.last_com: np.ndarray | None = None
        self.last_cop_error = float("nan")

    def joints(self, names: list[str]) -> None:
        """The skeleton's joints, laid out once (a calibration rescales lengths only)."""
        self.joint_encoder = JointStateEncoder(names, HUMAN_ROOT_FRAME, ("position",))

    def com(self, t_ns: int, out: StreamOutput) -> None:
        """The COM of the frame (the last valid one while the fit fails), with its quality and the latest delayed
        frame's COP error (~half a window back), as bytes: ~10 us against ~100 us as an rclpy message."""
        com = out.com_m if np.all(np.isfinite(out.com_m)) else self.last_com
        velocity = acceleration = (0.0, 0.0, 0.0)
        if com is not None and out.valid:
            self.last_com, velocity, acceleration = com, out.com_vel, out.com_acc
        self.pubs["com"].publish(self.com_encoder.encode(
            t_ns, (0.0, 0.0, 0.0) if com is None else com, velocity, acceleration, bool(out.valid),
            float(out.marker_rms_m), self.last_cop_error, int(out.n_markers)))

    def rest(self, t_ns: int, out: StreamOutput) -> None:
        """Joint angles (of the chain below the pelvis), the pelvis pose in lab, both COPs of the delayed frame."""
        if out.model_cop_m is not None and out.measured_cop_m is not None:
            self.last_cop_error = float(np.linalg.norm(out.model_cop_m[:2] - out.measured_cop_m[:2]))
        self.pubs["joints"].publish(self.joint_encoder.encode(t_ns, out.q[7:]))
        self.pubs["pelvis"].publish(self.lab_pose.encode(t_ns, out.q[:7]))     # Pinocchio's x y z, qx qy qz qw
        for name, cop in (("model_cop", out.model_cop_m), ("measured_cop", out.measured_cop_m)):
            if cop is not None and out.delayed_t_s is not None:       # on the floor: z 0
                self.pubs[name].publish(self.lab_point.encode(ns_of(out.delayed_t_s), [cop[0], cop[1], 0.0]))

    def viz(self, t_ns: int, human: HumanModel, markers_m: np.ndarray, out: StreamOutput) -> None:
        """The skeleton's /tf and the human's markers every ``viz_every`` frames (~50 us together); the skeleton's
        URDF whenever it is built or rebuilt (new lengths)."""
        if human is not self.described:
            self.described = human
            self.frames = SkeletonFrames(human)
            self.tf_encoder = TfEncoder(self.frames.pairs)
            self.pubs["description"].publish(String(data=human_urdf(human)))
        self.frames_seen += 1
        if not self.viz_every or (self.frames_seen - 1) % self.viz_every:
            return
        if np.all(np.isfinite(out.q)):
            self.pubs["tf"].publish(self.tf_encoder.encode(t_ns, *self.frames.transforms(out.q)))
        cop_stamp = stamp_of(out.delayed_t_s) if out.delayed_t_s is not None else None
        shapes = human_marker_shapes(time_of_ns(t_ns), markers_m, self.last_com, cop_stamp, out.measured_cop_m,
                                     out.model_cop_m)
        self.pubs["viz"].publish(marker_array_cdr(shapes))

    def scaling(self, t_ns: int, sc: MassScaling) -> None:
        names = [f"{g}.mass" for g in sc.masses] + ["torso.com_shift_x", "torso.com_shift_y"]
        values = list(sc.masses.values()) + [float(sc.torso_com_shift_m[0]), float(sc.torso_com_shift_m[1])]
        header = Header(stamp=time_of_ns(t_ns), frame_id=LAB_FRAME)
        self.pubs["scaling"].publish(InertialParameters(header=header, model="human_scaling", names=names,
                                                        values=[float(v) for v in values],
                                                        std_devs=[float("nan")] * len(values)))

    def stats(self, figures: dict[str, str]) -> None:
        status = DiagnosticStatus(level=DiagnosticStatus.OK if figures["plate_dropouts"] == "none" else
                                  DiagnosticStatus.WARN, name=self.node.get_fully_qualified_name(),
                                  message=f"{figures['frames']} frames")
        status.values = [KeyValue(key=k, value=v) for k, v in figures.items()]
        self.stats_pub.publish(status)
