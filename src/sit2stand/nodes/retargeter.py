"""Streaming IK retargeter node: human markers and COM in, robot joint commands out (Mistry et al. 2010, Sec. IV).

A thin shell around :class:`sit2stand.retarget.pacing.LiveRetargeting` (stamp matching, pacing, latency) and the
retargeting stages it drives (per-frame IK, plan player, COM feedback). Subscribes ``/mocap/markers``,
``/human/com`` (from the human COM estimator), ``/force_plate/chair`` (seat-off, if there is a chair plate) and,
with ``wait_for_robot``, ``/robot/joint_states`` and ``/robot/base_pose`` (the robot's measured seated posture, which
the calibration overlays the first human frame on; then the measured COM: the COM feedback's, or without it how far
the robot trails the plan, which slows the plan). Publishes:

* ``/robot/joint_command`` (trajectory_msgs/JointTrajectory, one point: positions, velocities, accelerations;
  stamped now: the driver applies it at once), one per planned frame's period (the marker period, or
  ``plan_rate_hz``'s) until the (retimed) plan ends;
* ``/robot/planned_com`` (sit2stand_msgs/CenterOfMass, source ``robot_plan``) and ``/robot/planned_zmp``
  (geometry_msgs/PointStamped) of each command, as planned (the COM feedback's target);
* ``/robot/com_feedback`` (geometry_msgs/Vector3Stamped): the COM shift the feedback put into each command [m];
* ``/viz/markers`` (visualization_msgs/MarkerArray, every ``markers_every``-th command): the planned COM, its drop
  to the floor, the planned ZMP and the feet's support polygon, in world (:mod:`sit2stand.nodes.markers`);
* ``/robot/retarget/ik`` (sensor_msgs/JointState, the raw IK pose per frame, base as root_* entries) and
  ``~/status`` (diagnostic_msgs/DiagnosticStatus: infeasible frames, time scale, latency p50/p99).

Parameters: ``plant``, ``controller_params`` (identified YAML; empty: CAD), ``margin_m``, ``lookahead_s``,
``smooth_s``, ``max_joint_speed``, ``retiming`` (local | uniform), ``seat_off_dwell_s``, ``time_scale`` (0:
adaptive; else fixed), ``max_time_scale`` (the adaptive one's cap), ``rate_hz``, ``plan_rate_hz`` (the plan's
rate: every n-th frame of a faster capture; 0: every frame), ``com_wait_s``, ``wait_for_robot``,
``marker_map`` (YAML to write the calibration to), ``hold_s`` (hold the last pose this long after the plan ends,
in ROS time, then exit; 0: never),
``input_timeout_s`` (marker frames waiting this long for a human COM end the node with an error), ``controller``
(the robot's on-board controller, as the driver's: ``inverse_dynamics``, joint PD, or ``wbc``, whole-body torque
control, which tracks the plan's COM itself: no COM feedback then), ``com_feedback`` and its gains
``com_feedback_kp``, ``_ki``, ``_kd``, ``markers_every`` (5; 0: no markers), ``marker_set`` (as the
human_com node's: which markers are the pelvis, the left knee, ankle and heel, and each marker's body part;
:func:`sit2stand.retarget.calibration.marker_roles`).
"""

from __future__ import annotations

import sys
import time

import numpy as np
from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from geometry_msgs.msg import PointStamped, PoseStamped, Vector3Stamped
from rclpy.node import Node
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from sit2stand_msgs.msg import CenterOfMass, ForcePlateSample, MocapFrame
from trajectory_msgs.msg import JointTrajectory
from visualization_msgs.msg import MarkerArray

from ..human.marker_sets import load_marker_set, load_packaged_marker_sets
from ..io.messages import plate_sample_from_cdr, stamp_ns
from ..io.stream_messages import (CenterOfMassEncoder, JointStateEncoder, JointStateReader, JointTrajectoryEncoder,
                                  StampedNumbersEncoder, pose_from_cdr)
from ..io.topics import (CHAIR_PLATE_TOPIC, HUMAN_COM_TOPIC, MARKERS_TOPIC, ROBOT_BASE_POSE_TOPIC,
                         ROBOT_COM_FEEDBACK_TOPIC, ROBOT_JOINT_COMMAND_TOPIC, ROBOT_JOINT_STATES_TOPIC,
                         ROBOT_PLANNED_COM_TOPIC, ROBOT_PLANNED_ZMP_TOPIC, ROBOT_RETARGET_IK_TOPIC, VIZ_MARKERS_TOPIC,
                         WORLD_FRAME, ros_name)
from ..retarget.pacing import (READY_LINE, LiveConfig, LiveRetargeting, MarkerFrame, robot_state_current,
                               summary_line)
from ..retarget.player import (DEFAULT_MARGIN_M, DEFAULT_MAX_JOINT_SPEED, DEFAULT_MAX_TIME_SCALE, LOOKAHEAD_S,
                               SEAT_OFF_DWELL_S, SMOOTH_S, Command)
from ..retarget.stabiliser import StabiliserConfig
from ..retarget.robot import robot_model, robot_setup
from ..robot.plant import CONTROLLERS
from ..robot.profile import profile_of
from .markers import plan_markers
from .runtime import (PUBLISH_DEPTH, ROBOT_STATE_READER_QOS, IdleDrain, NodeError, declare, marker_rate_check,
                      node_main, qos_matching_publishers, scheduling_text, steady_timer)


def _live_config(node: Node) -> LiveConfig:
    """The node's parameters, declared."""
    gains = StabiliserConfig()
    scale = declare(node, "time_scale", 0.0, "0: adaptive retiming; else a fixed time scale")
    return LiveConfig(
        rate_hz=declare(node, "rate_hz", 100.0, "marker rate [Hz]"),
        plan_rate_hz=declare(node, "plan_rate_hz", 0.0, "the plan's rate [Hz]: every n-th frame, n the nearest "
                             "whole number to rate_hz / this (0: every frame)"),
        margin_m=declare(node, "margin_m", DEFAULT_MARGIN_M, "ZMP margin inside the feet [m]"),
        lookahead_s=declare(node, "lookahead_s", LOOKAHEAD_S, "look-ahead of the retiming [s]"),
        smooth_s=declare(node, "smooth_s", SMOOTH_S, "Savitzky-Golay window of the plan [s]"),
        max_joint_speed=declare(node, "max_joint_speed", DEFAULT_MAX_JOINT_SPEED,
                                "joint speed limit of the retimed plan [rad/s]"),
        retiming=declare(node, "retiming", "local", "local: slower only where a frame needs it; uniform: one factor"),
        seat_off_dwell_s=declare(node, "seat_off_dwell_s", SEAT_OFF_DWELL_S, "wait at the robot's seat-off [s]"),
        fixed_time_scale=scale if scale > 0 else None,
        max_time_scale=declare(node, "max_time_scale", DEFAULT_MAX_TIME_SCALE, "cap of the adaptive time scale"),
        com_wait_s=declare(node, "com_wait_s", 0.03, "use the latest human COM if at most this old [s]"),
        com_feedback=declare(node, "com_feedback", True, "correct the commands for the measured robot COM (under "
                             "joint PD)"),
        controller=declare(node, "controller", "inverse_dynamics", "the robot's on-board controller, as the driver's: "
                           "inverse_dynamics (joint PD) | wbc (whole-body torque control: no COM feedback)"),
        marker_set=declare(node, "marker_set", "", "marker set: a packaged set's name or a YAML file (empty: the "
                           "packaged set that covers most of the stream's marker names)"),
        stabiliser=StabiliserConfig(
            kp=declare(node, "com_feedback_kp", gains.kp, "COM feedback: proportional gain [m/m]"),
            ki=declare(node, "com_feedback_ki", gains.ki, "COM feedback: integral gain [1/s]"),
            kd=declare(node, "com_feedback_kd", gains.kd, "COM feedback: velocity gain [s]")))


class RetargeterNode(Node):
    """Streams joint commands (see the module docstring)."""

    executor_kind = "events"
    drain_timeout_s = 30.0

    def __init__(self) -> None:
        super().__init__("retargeter")
        self.plant_file = declare(self, "plant", "", "plant YAML (seated posture, chair)") or "default"
        self.robot = declare(self, "robot", "", "robot profile: a packaged name (talos, g1) or a file (empty: the "
                                                "plant's)") or None
        self.params_file = declare(self, "controller_params", "", "identified parameters YAML (empty: CAD)")
        self.wait_for_robot = declare(self, "wait_for_robot", True, "start from the robot's measured posture")
        self.map_out = declare(self, "marker_map", "", "write the marker calibration YAML here")
        self.hold_s = declare(self, "hold_s", 3.0, "after the plan ends, hold its last pose this long [s] of ROS "
                                                   "time, then exit (0: never)")
        self.input_timeout_s = declare(self, "input_timeout_s", 20.0, "marker frames may wait this long for a COM")
        cfg = _live_config(self)
        self.rate_check = marker_rate_check(cfg.rate_hz)
        try:
            self.live = LiveRetargeting(cfg, self._publish, self._measured_q,
                                        lambda: self.get_clock().now().nanoseconds * 1e-9)
        except ValueError as err:
            raise NodeError(f"retargeter: {err}") from None
        if self.live.cfg.controller not in CONTROLLERS:
            raise NodeError(f"retargeter: controller {self.live.cfg.controller!r} is not one of "
                            f"{', '.join(CONTROLLERS)}")
        try:        # the robot model now (~0.6 s idle, more under load), not when the first frames are queued
            self.robot_model = robot_model(self.plant_file, self.params_file or None, robot=self.robot)
        except (ValueError, OSError) as err:
            raise NodeError(f"retargeter: plant {self.plant_file}, controller_params "
                            f"{self.params_file or '(CAD)'}: {err}") from None
        # the marker sets now too: read at the first frame, they held it and the 10 after it up by ~0.1 s
        try:
            load_packaged_marker_sets()
            if cfg.marker_set:
                load_marker_set(cfg.marker_set)
        except ValueError as err:
            raise NodeError(f"retargeter: marker_set: {err}") from None
        self._com_found = self._ready = False
        self._subscribe()
        self.cmd_pub = self.create_publisher(JointTrajectory, ros_name(ROBOT_JOINT_COMMAND_TOPIC), PUBLISH_DEPTH)
        self.com_pub = self.create_publisher(CenterOfMass, ros_name(ROBOT_PLANNED_COM_TOPIC), PUBLISH_DEPTH)
        self.zmp_pub = self.create_publisher(PointStamped, ros_name(ROBOT_PLANNED_ZMP_TOPIC), PUBLISH_DEPTH)
        self.feedback_pub = self.create_publisher(Vector3Stamped, ros_name(ROBOT_COM_FEEDBACK_TOPIC), PUBLISH_DEPTH)
        self.ik_pub = self.create_publisher(JointState, ros_name(ROBOT_RETARGET_IK_TOPIC), PUBLISH_DEPTH)
        self.viz_pub = self.create_publisher(MarkerArray, ros_name(VIZ_MARKERS_TOPIC), PUBLISH_DEPTH)
        self.markers_every = declare(self, "markers_every", 5, "/viz/markers every this many commands (0: none)")
        self.support_xy: np.ndarray | None = None   # the plan's support polygon, once calibrated
        self._commands = 0
        self.status_pub = self.create_publisher(DiagnosticStatus, "~/status", 10)
        self.robot_js: bytes | None = None        # the latest robot state, serialized, and when each came
        self.robot_base: bytes | None = None
        self.robot_rx = (0.0, 0.0)
        self.sim_time = bool(self.get_parameter("use_sim_time").value)
        self._js_order: tuple[list[str], np.ndarray] | None = None
        self._js_reader = JointStateReader()
        # the commands' messages laid out once, when the joints are known (the per-command path: 100 Hz, real time)
        self._encoders: dict[str, object] = {
            "com": CenterOfMassEncoder("robot_plan", WORLD_FRAME),
            "zmp": StampedNumbersEncoder(WORLD_FRAME, StampedNumbersEncoder.POINT),
            "feedback": StampedNumbersEncoder(WORLD_FRAME, 3)}
        self._t_init = time.monotonic()
        self._first_wait: float | None = None     # when a frame first waited (for a COM or the robot's state)
        self._robot_wait: float | None = None
        self._done_at: float | None = None
        self.finished, self.exit_code = False, 0
        self.drain = IdleDrain(lambda: self.live.processed)
        self.scheduling = scheduling_text()
        steady_timer(self, 0.25 / self.live.cfg.rate_hz, self._tick)
        steady_timer(self, 2.0, self._report)
        self.get_logger().info(f"retargeter: plant {self.plant_file}, COM parameters "
                               f"{self.params_file or 'CAD'}; waiting for {MARKERS_TOPIC} and {HUMAN_COM_TOPIC}")

    def _subscribe(self) -> None:
        deep = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=2000, reliability=ReliabilityPolicy.RELIABLE)
        self.create_subscription(MocapFrame, ros_name(MARKERS_TOPIC), self._on_markers, deep)
        # /human/com is subscribed with its publishers' durability once they appear (transient local from the
        # estimator: a late match still gets every estimate; volatile from a replayed bag)
        self._com_discovery = steady_timer(self, 0.1, self._discover_com)
        self.create_subscription(ForcePlateSample, ros_name(CHAIR_PLATE_TOPIC), self._on_chair,
                                 QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=5000,
                                            reliability=ReliabilityPolicy.RELIABLE), raw=True)
        # kept as bytes (400 Hz, in the real-time thread); read when a command needs them
        self.create_subscription(JointState, ros_name(ROBOT_JOINT_STATES_TOPIC), self._on_joint_states,
                                 ROBOT_STATE_READER_QOS, raw=True)
        self.create_subscription(PoseStamped, ros_name(ROBOT_BASE_POSE_TOPIC), self._on_base_pose,
                                 ROBOT_STATE_READER_QOS, raw=True)

    # -- inputs ------------------------------------------------------------------------------------------------
    def _on_joint_states(self, data: bytes) -> None:
        self.robot_js, self.robot_rx = data, (time.monotonic(), self.robot_rx[1])
        if not self._ready:
            self._note_ready()

    def _on_base_pose(self, data: bytes) -> None:
        self.robot_base, self.robot_rx = data, (self.robot_rx[0], time.monotonic())
        if not self._ready:
            self._note_ready()

    def _note_ready(self) -> None:
        """Say once (READY_LINE) that what the first frame needs is here: the human COM's publisher and, with
        ``wait_for_robot``, the robot's state. A frame before it waits, and its latency counts the wait."""
        robot = not self.wait_for_robot or (self.robot_js is not None and self.robot_base is not None)
        if robot and self._com_found and not self._ready:
            self._ready = True
            self.get_logger().info(f"{READY_LINE} ({time.monotonic() - self._t_init:.2f} s after start)")
            self._process()     # frames that came before the robot's state: a short trial may send no more

    def _on_chair(self, data: bytes) -> None:
        # 1 kHz, in the real-time process: read the stamp and Fz from the CDR bytes instead of building messages
        t_s, _, _, fz, _, _, _ = plate_sample_from_cdr(data)
        self.live.chair.add(t_s, fz)

    def _discover_com(self) -> None:
        if self.get_publishers_info_by_topic(ros_name(HUMAN_COM_TOPIC)):
            qos = qos_matching_publishers(self, ros_name(HUMAN_COM_TOPIC), keep_all=False, depth=2000)
            self.create_subscription(CenterOfMass, ros_name(HUMAN_COM_TOPIC), self._on_com, qos)
            self.get_logger().info(f"{HUMAN_COM_TOPIC} publisher found after {time.monotonic() - self._t_init:.2f} "
                                   f"s; subscribed ({qos.durability.name.lower()})")
            self._com_discovery.cancel()
            self._com_found = True
            self._note_ready()

    def _on_com(self, msg: CenterOfMass) -> None:
        if not self.live.coms.samples and not self.live.coms.invalid:
            self.get_logger().info(f"first {HUMAN_COM_TOPIC} after {time.monotonic() - self._t_init:.2f} s")
        p, v = msg.position, msg.velocity
        self.live.coms.add(stamp_ns(msg.header) * 1e-9, np.array([p.x, p.y, p.z]), np.array([v.x, v.y, v.z]),
                           msg.valid)
        self._process()

    def _on_markers(self, msg: MocapFrame) -> None:
        pos = np.array([[p.x, p.y, p.z] for p in msg.positions], float).reshape(-1, 3)
        t_s = stamp_ns(msg.header) * 1e-9
        if (wrong_rate := self.rate_check.add(t_s)) is not None:
            raise NodeError(wrong_rate)
        self.live.add_frame(MarkerFrame(t_s, list(msg.marker_names), pos, np.asarray(msg.valid, bool),
                                        time.perf_counter(), msg.header))
        self._process()

    # -- processing --------------------------------------------------------------------------------------------
    def _process(self) -> None:
        while (ready := self.live.next_ready()) is not None:
            frame, com = ready
            if self.live.retargeter is None and not self._start(frame, com):
                return
            q = self.live.step(frame, com)
            # after the command: it is for the record, not on the path
            self.ik_pub.publish(self._encoders["ik"].encode(stamp_ns(frame.header), q))

    def _start(self, frame: MarkerFrame, com: np.ndarray) -> bool:
        """Calibrate on the first ready frame, over the robot's measured posture (False: wait for it)."""
        q_start, joint_names, began = None, None, time.perf_counter()
        if self.wait_for_robot:
            if self.robot_js is None or self.robot_base is None:
                self._robot_wait = self._robot_wait or time.monotonic()
                return False
            _, positions = self._js_reader.read(self.robot_js)
            q_start, joint_names = self._robot_q(positions), list(self._js_reader.names)
        waited = f"; the first frames waited {time.monotonic() - self._robot_wait:.2f} s for the robot's state " \
                 "(they count in the latency)" if self._robot_wait else ""
        try:
            robot = robot_setup(q_start=q_start, start_joint_names=joint_names, prebuilt=self.robot_model)
            marker_map = self.live.start(robot, frame, com)
        except (ValueError, OSError) as err:
            raise NodeError(f"retargeter calibration: {err}") from None
        self.joint_names = robot.joint_names
        self.support_xy = robot.support_xy
        self._encoders["command"] = JointTrajectoryEncoder(self.joint_names, profile_of(robot.model).root_link)
        self._encoders["ik"] = JointStateEncoder([f"root_{c}" for c in ("x", "y", "z", "qx", "qy", "qz", "qw")]
                                                 + self.joint_names, WORLD_FRAME, ("position",))
        if self.map_out:
            marker_map.save(self.map_out)
        lead = f"; the recording starts after the human's seat-off: a lead-in of {self.live.lead_in_frames} " \
               "frames from the robot's seat" if self.live.lead_in_frames else ""
        self.get_logger().info(f"calibrated on the first frame in {(time.perf_counter() - began) * 1e3:.0f} ms: "
                               f"{len(marker_map.links)} markers fixed to the robot; "
                               f"leg-length scale {self.live.retargeter.scale:.3f}{waited}{lead}")
        return True

    def _robot_q(self, positions: np.ndarray) -> np.ndarray:
        """The measured configuration: base pose (x y z, quaternion x y z w), then the joint ``positions`` in the
        joint state's order."""
        return np.concatenate([pose_from_cdr(self.robot_base)[1], positions])

    def _measured_q(self) -> tuple[np.ndarray, float] | None:
        """The robot's measured configuration in the model's order and its stamp [s]; None if received longer than
        ROBOT_STATE_MAX_AGE_S ago (on a wall clock) or stamped longer than ROBOT_STATE_MAX_DELAY_S ago
        (:func:`~sit2stand.retarget.pacing.robot_state_current`)."""
        if self.robot_js is None or self.robot_base is None:
            return None
        stamp, positions = self._js_reader.read(self.robot_js)
        stamped_ago_s = (self.get_clock().now().nanoseconds - stamp) * 1e-9
        if not robot_state_current(time.monotonic() - min(self.robot_rx), stamped_ago_s, self.sim_time):
            return None
        names = self._js_reader.names
        if self._js_order is None or self._js_order[0] is not names:
            if not set(self.joint_names) <= set(names):
                return None
            self._js_order = (names, np.array([names.index(n) for n in self.joint_names]))
        return self._robot_q(positions[self._js_order[1]]), stamp * 1e-9

    def _tick(self) -> None:
        """Input time-out, the pacing timer, and the end of the plan."""
        now = time.monotonic()
        frames = self.live.frames
        if frames and now - max(self.live.last_frame_s, self._first_wait or now) > self.input_timeout_s:
            missing = f"{ROBOT_JOINT_STATES_TOPIC} and {ROBOT_BASE_POSE_TOPIC}" if self.live.retargeter is None \
                and self.live.coms.samples and self.wait_for_robot else HUMAN_COM_TOPIC
            self.get_logger().error(f"{len(frames)} marker frames waited {self.input_timeout_s:g} s for "
                                    f"{missing}; stopping")
            self.exit_code, self.finished = 2, True
            return
        if frames and self._first_wait is None:
            self._first_wait = now
        if self.live.tick():
            robot_now = self.get_clock().now().nanoseconds * 1e-9     # the hold is the robot's time standing
            self._done_at = self._done_at or robot_now
            self.finished = self.hold_s > 0 and robot_now - self._done_at > self.hold_s

    # -- outputs -----------------------------------------------------------------------------------------------
    def _publish(self, cmd: Command, offset_m: np.ndarray | None) -> float:
        """The joint command first (its send time is returned: the latency ends there), then the planned COM and
        ZMP and the feedback's shift."""
        now = self.get_clock().now()        # a command is for now: the driver applies it at once
        t_ns, stamp = now.nanoseconds, now.to_msg()
        self.cmd_pub.publish(self._encoders["command"].encode(t_ns, cmd.q[7:], cmd.v[6:], cmd.a[6:]))
        sent = time.perf_counter()
        self.com_pub.publish(self._encoders["com"].encode(t_ns, cmd.com))
        self.zmp_pub.publish(self._encoders["zmp"].encode(t_ns, cmd.zmp))
        if offset_m is not None:
            self.feedback_pub.publish(self._encoders["feedback"].encode(t_ns, [offset_m[0], offset_m[1], 0.0]))
        self._commands += 1
        if self.markers_every > 0 and self.support_xy is not None and (self._commands - 1) % self.markers_every == 0:
            self.viz_pub.publish(plan_markers(stamp, cmd.com, cmd.zmp, self.support_xy))   # ~0.15 ms
        return sent

    def _report(self) -> None:
        st = DiagnosticStatus(name=self.get_fully_qualified_name(), hardware_id="retargeter",
                              level=DiagnosticStatus.OK if not self.live.infeasible else DiagnosticStatus.WARN,
                              message=f"{self.live.processed} frames")
        figures = {**self.live.figures(), "scheduling": self.scheduling}
        st.values = [KeyValue(key=k, value=v) for k, v in figures.items()]
        self.status_pub.publish(st)

    def close(self) -> None:
        print(f"[retargeter] {summary_line({**self.live.figures(), 'scheduling': self.scheduling})}", flush=True)


main = node_main(RetargeterNode)

if __name__ == "__main__":
    sys.exit(main())
