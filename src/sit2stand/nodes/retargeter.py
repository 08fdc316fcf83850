"""Streaming IK retargeter node: human markers and COM in, robot joint commands out (Mistry et al. 2010, Sec. IV).

A thin shell around :class:`sit2stand.retarget.pacing.LiveRetargeting` (stamp matching, pacing, latency) and the
retargeting stages it drives (per-frame IK, plan player, COM feedback): the human's markers, COM and chair plate in;
the robot's measured state (:mod:`sit2stand.retarget.robot_state`) in; joint commands, the planned COM and ZMP, the
COM feedback's shift, the plan's markers and the raw IK pose out (:mod:`sit2stand.nodes.retarget_outputs`).
Topics and parameters: ``docs/nodes.md`` (retargeter).
"""

from __future__ import annotations

import sys
import time

import numpy as np
from geometry_msgs.msg import PoseStamped
from rclpy.node import Node
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from sit2stand_msgs.msg import CenterOfMass, ForcePlateSample, MocapFrame

from .. import native
from ..human.marker_sets import load_marker_set, load_packaged_marker_sets
from ..io.messages import plate_sample_from_cdr, stamp_ns
from ..io.stream_messages import MocapFrameReader
from ..io.topics import (CHAIR_PLATE_TOPIC, HUMAN_COM_TOPIC, MARKERS_TOPIC, ROBOT_BASE_POSE_TOPIC,
                         ROBOT_JOINT_STATES_TOPIC, ros_name)
from ..retarget.pacing import (READY_LINE, LiveRetargeting, MarkerFrame, summary_line)
from ..retarget.player import (Command)
from ..retarget.robot import robot_model, robot_setup
from ..retarget.robot_state import RobotStateInbox
from ..retarget.warm_up import warm_up
from ..robot.plant import CONTROLLERS
from ..robot.profile import profile_of
from .retarget_outputs import RetargetOutputs
from .retargeter_config import live_config
from .runtime import IdleDrain, NodeError, declare, marker_rate_check, node_main, scheduling_text, steady_timer
from .qos import ROBOT_STATE_READER_QOS, qos_matching_publishers


class RetargeterNode(Node):
    """Streams joint commands (see the module docstring)."""

    executor_kind = "events"
    drain_timeout_s = 30.0

    def __init__(self) -> None:
        super().__init__("retargeter")
        plant_file = declare(self, "plant", "", "plant YAML (seated posture, chair)") or "default"
        robot = declare(self, "robot", "", "robot profile: a packaged name (`sit2stand robot list`) or a file "
                                           "(empty: the plant's)") or None
        params_file = declare(self, "controller_params", "", "identified parameters YAML (empty: CAD)")
        self.wait_for_robot = declare(self, "wait_for_robot", True, "start from the robot's measured posture")
        self.map_out = declare(self, "marker_map", "", "write the marker calibration YAML here")
        self.hold_s = declare(self, "hold_s", 3.0, "after the plan ends, hold its last pose this long [s] of ROS "
                                                   "time, then exit (0: never)")
        self.input_timeout_s = declare(self, "input_timeout_s", 20.0, "marker frames may wait this long for a COM")
        cfg = live_config(self)
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
            self.robot_model = robot_model(plant_file, params_file or None, robot=robot)
        except (ValueError, OSError) as err:
            raise NodeError(f"retargeter: plant {plant_file}, controller_params "
                            f"{params_file or '(CAD)'}: {err}") from None
        native.kernels()     # the IK's compiled kernels now too (built on a machine's first run: ~1.8 s)
        # the marker sets now too: read at the first frame, they held it and the 10 after it up by ~0.1 s
        try:
            load_packaged_marker_sets()
            if cfg.marker_set:
                load_marker_set(cfg.marker_set)
        except ValueError as err:
            raise NodeError(f"retargeter: marker_set: {err}") from None
        self._warm_up(cfg)
        self._com_found = self._ready = False
        self.robot_state = RobotStateInbox(bool(self.get_parameter("use_sim_time").value))
        self._subscribe()
        self.out = RetargetOutputs(self, declare(self, "markers_every", 5, "/viz/markers every this many commands "
                                                                           "(0: none)"))
        self.joint_names: list[str] = []
        self._t_init = time.monotonic()
        # when a frame first waited (for a COM, then for the robot's state), and when the plan ended
        self._waits: dict[str, float | None] = {"frame": None, "robot": None, "done": None}
        self.finished, self.exit_code = False, 0
        self.drain = IdleDrain(lambda: self.live.progress.processed)
        self.scheduling = scheduling_text()
        steady_timer(self, 0.25 / self.live.cfg.rate_hz, self._tick)
        steady_timer(self, 2.0, self._report)
        self.get_logger().info(f"retargeter: plant {plant_file}, COM parameters "
                               f"{params_file or 'CAD'}; waiting for {MARKERS_TOPIC} and {HUMAN_COM_TOPIC}")

    def _warm_up(self, cfg) -> None:
        """A dry run of the first frame's work (:mod:`sit2stand.retarget.warm_up`), before anything is subscribed."""
        try:
            dry = warm_up(cfg, self.robot_model)
        except ValueError as err:       # the synthetic human only: the capture's own frames may still fit
            self.get_logger().warning(f"retargeter: no dry run of the first frame ({err}); the first frames will "
                                      "wait for its first calls")
            return
        self.get_logger().info(f"dry run of the first frame's calibration and {dry.frames} steps on a synthetic "
                               f"human: {dry.seconds * 1e3:.0f} ms")

    def _subscribe(self) -> None:
        deep = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=2000, reliability=ReliabilityPolicy.RELIABLE)
        self.marker_reader = MocapFrameReader()     # raw: the arrays straight from the CDR bytes
        self.create_subscription(MocapFrame, ros_name(MARKERS_TOPIC), self._on_markers, deep, raw=True)
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
        self.robot_state.add_joint_states(data, time.monotonic())
        if not self._ready:
            self._note_ready()

    def _on_base_pose(self, data: bytes) -> None:
        self.robot_state.add_base_pose(data, time.monotonic())
        if not self._ready:
            self._note_ready()

    def _note_ready(self) -> None:
        """Say once (READY_LINE) that what the first frame needs is here: the human COM's publisher and, with
        ``wait_for_robot``, the robot's state. A frame before it waits, and its latency counts the wait."""
        robot = not self.wait_for_robot or self.robot_state.complete
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

    def _on_markers(self, data: bytes) -> None:
        received = time.perf_counter()
        try:
            t_ns, names, pos, valid = self.marker_reader.read(data)
        except ValueError as err:
            raise NodeError(f"{MARKERS_TOPIC}: a frame that cannot be read ({err})") from None
        if (wrong_rate := self.rate_check.add(t_ns * 1e-9)) is not None:
            raise NodeError(wrong_rate)
        self.live.add_frame(MarkerFrame(t_ns * 1e-9, names, pos, valid, received, t_ns))
        self._process()

    # -- processing --------------------------------------------------------------------------------------------
    def _process(self) -> None:
        while (ready := self.live.next_ready()) is not None:
            frame, com = ready
            if self.live.retargeter is None and not self._start(frame, com):
                return
            # the IK pose after the command: for the record, not on the path
            self.live.step(frame, com, lambda q, stamp_ns=frame.stamp_ns: self.out.ik_pose(stamp_ns, q))

    def _start(self, frame: MarkerFrame, com: np.ndarray) -> bool:
        """Calibrate on the first ready frame, over the robot's measured posture (False: wait for it)."""
        q_start, joint_names, began = None, None, time.perf_counter()
        if self.wait_for_robot:
            if not self.robot_state.complete:
                self._waits["robot"] = self._waits["robot"] or time.monotonic()
                return False
            q_start, joint_names = self.robot_state.start()
        waited = f"; the first frames waited {time.monotonic() - self._waits['robot']:.2f} s for the robot's " \
                 "state (they count in the latency)" if self._waits["robot"] else ""
        try:
            robot = robot_setup(q_start=q_start, start_joint_names=joint_names, prebuilt=self.robot_model)
            marker_map = self.live.start(robot, frame, com)
        except (ValueError, OSError) as err:
            raise NodeError(f"retargeter calibration: {err}") from None
        self.joint_names = robot.joint_names
        self.out.calibrated(robot.joint_names, profile_of(robot.model).root_link, robot.support_xy)
        if self.map_out:
            marker_map.save(self.map_out)
        lead = f"; the recording starts after the human's seat-off: a lead-in of {self.live.progress.lead_in_frames} " \
               "frames from the robot's seat" if self.live.progress.lead_in_frames else ""
        self.get_logger().info(f"calibrated on the first frame in {(time.perf_counter() - began) * 1e3:.0f} ms: "
                               f"{len(marker_map.links)} markers fixed to the robot; "
                               f"leg-length scale {self.live.retargeter.com_map.scale:.3f}{waited}{lead}")
        return True

    def _measured_q(self) -> tuple[np.ndarray, float] | None:
        """The robot's current measured configuration in the model's order and its stamp [s], or None."""
        return self.robot_state.current(self.joint_names, self.get_clock().now().nanoseconds, time.monotonic())

    def _tick(self) -> None:
        """Input time-out, the pacing timer, and the end of the plan."""
        now = time.monotonic()
        frames = self.live.frames
        if frames and now - max(self.live.progress.last_frame_s, self._waits["frame"] or now) > self.input_timeout_s:
            missing = f"{ROBOT_JOINT_STATES_TOPIC} and {ROBOT_BASE_POSE_TOPIC}" if self.live.retargeter is None \
                and self.live.coms.samples and self.wait_for_robot else HUMAN_COM_TOPIC
            self.get_logger().error(f"{len(frames)} marker frames waited {self.input_timeout_s:g} s for "
                                    f"{missing}; stopping")
            self.exit_code, self.finished = 2, True
            return
        if frames and self._waits["frame"] is None:
            self._waits["frame"] = now
        if self.live.tick():
            robot_now = self.get_clock().now().nanoseconds * 1e-9     # the hold is the robot's time standing
            self._waits["done"] = self._waits["done"] or robot_now
            self.finished = self.hold_s > 0 and robot_now - self._waits["done"] > self.hold_s

    # -- outputs -----------------------------------------------------------------------------------------------
    def _publish(self, cmd: Command, offset_m: np.ndarray | None) -> float:
        return self.out.command(cmd, offset_m)

    def _report(self) -> None:
        self.out.status({**self.live.figures(), "scheduling": self.scheduling}, self.live.progress.processed,
                        self.live.progress.infeasible)

    def close(self) -> None:
        print(f"[retargeter] {summary_line({**self.live.figures(), 'scheduling': self.scheduling})}", flush=True)


main = node_main(RetargeterNode)

if __name__ == "__main__":
    sys.exit(main())
