"""Streaming IK retargeter node: human markers and COM in, robot joint commands out (Mistry et al. 2010, Sec. IV).

Subscribes ``/mocap/markers`` (sit2stand_msgs/MocapFrame), ``/human/com`` (sit2stand_msgs/CenterOfMass, from the
human COM estimator), ``/force_plate/chair`` (seat-off, if there is a chair plate), and, with ``wait_for_robot``,
``/robot/joint_states`` and ``/robot/base_pose`` (the robot's measured seated posture, which the calibration
overlays the first human frame on; then, with ``com_feedback``, the measured COM). Per marker frame it runs
:class:`sit2stand.retarget.stream.Retargeter` and :class:`sit2stand.retarget.stream.PlanPlayer`, corrects the command
for the measured COM (:class:`sit2stand.retarget.stabiliser.ComStabiliser`, from the plan's seat-off) and publishes:

* ``/robot/joint_command`` (trajectory_msgs/JointTrajectory, one point: positions, velocities, accelerations;
  stamped now: the driver applies it at once), one per marker frame, and on at the mocap rate after the markers stop
  until the (retimed) plan ends;
* ``/robot/planned_com`` (sit2stand_msgs/CenterOfMass, source ``robot_plan``) and ``/robot/planned_zmp``
  (geometry_msgs/PointStamped) of each command (as planned: the COM feedback's target);
* ``/robot/com_feedback`` (geometry_msgs/Vector3Stamped): the COM shift the feedback put into each command [m];
* ``/robot/retarget/ik`` (sensor_msgs/JointState, the raw IK pose per frame, base as root_* entries) and
  ``~/status`` (diagnostic_msgs/DiagnosticStatus: infeasible frames, time scale, latency p50/p99).

The human COM of a frame is the estimator's estimate for that stamp, or its latest one if it is at most ``com_wait_s``
older (moved on by its velocity); otherwise the frame waits for it. Parameters: ``plant``, ``controller_params``
(identified YAML; empty: CAD), ``margin_m`` (0.06), ``lookahead_s`` (0.8), ``smooth_frames`` (21), ``time_scale``
(0: adaptive retiming; else fixed), ``rate_hz`` (100), ``wait_for_robot`` (true), ``marker_map`` (YAML to write the
calibration to; empty: none), ``hold_s`` (3: the node exits this long after its plan ends; 0: never),
``input_timeout_s`` (20: marker frames waiting this long for a human COM end the node with an error),
``com_feedback`` (true), ``com_feedback_kp``, ``_ki``, ``_kd`` (the stabiliser's gains; defaults those of
:class:`~sit2stand.retarget.stabiliser.StabiliserConfig`).
"""

from __future__ import annotations

import time
from collections import deque

import numpy as np
from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from geometry_msgs.msg import PointStamped, PoseStamped, Vector3Stamped
from rclpy.node import Node
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import JointState
from sit2stand_msgs.msg import CenterOfMass, ForcePlateSample, MocapFrame
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from ..io.messages import MARKERS_TOPIC, plate_sample_from_cdr, plate_topic, stamp_ns
from ..retarget.stabiliser import ComStabiliser, StabiliserConfig
from ..retarget.stream import PlanPlayer, RetargetConfig, Retargeter, robot_model, robot_setup
from .driver import DEFAULT_PLANT
from .runtime import (PUBLISH_DEPTH, IdleDrain, NodeError, declare, node_main, qos_matching_publishers,
                      scheduling_text)


class RetargeterNode(Node):
    """Streams joint commands (see the module docstring)."""

    executor_kind = "events"
    drain_timeout_s = 30.0

    def __init__(self) -> None:
        super().__init__("retargeter")
        self.plant_file = declare(self, "plant", "", "plant YAML (seated posture, chair)") or str(DEFAULT_PLANT)
        self.params_file = declare(self, "controller_params", "", "identified parameters YAML (empty: CAD)")
        self.margin = declare(self, "margin_m", 0.06, "ZMP margin inside the feet [m]")
        self.lookahead = declare(self, "lookahead_s", 0.8, "look-ahead of the retiming [s]")
        self.smooth = declare(self, "smooth_frames", 21, "Savitzky-Golay window of the plan [frames]")
        self.max_speed = declare(self, "max_joint_speed", 0.6, "joint speed limit of the retimed plan [rad/s]")
        scale = declare(self, "time_scale", 0.0, "0: adaptive retiming; else a fixed time scale")
        self.fixed_scale = scale if scale > 0 else None
        self.rate_hz = declare(self, "rate_hz", 100.0, "marker rate [Hz]")
        self.com_wait = declare(self, "com_wait_s", 0.03, "use the latest human COM if at most this old [s]")
        self.wait_for_robot = declare(self, "wait_for_robot", True, "start from the robot's measured posture")
        self.map_out = declare(self, "marker_map", "", "write the marker calibration YAML here")
        self.hold_s = declare(self, "hold_s", 3.0, "after the plan ends, exit after this long [s] (0: never)")
        self.input_timeout_s = declare(self, "input_timeout_s", 20.0, "marker frames may wait this long for a COM")
        gains = StabiliserConfig()
        self.com_feedback = declare(self, "com_feedback", True, "correct the commands for the measured robot COM")
        self.stabiliser_cfg = StabiliserConfig(
            kp=declare(self, "com_feedback_kp", gains.kp, "COM feedback: proportional gain [m/m]"),
            ki=declare(self, "com_feedback_ki", gains.ki, "COM feedback: integral gain [1/s]"),
            kd=declare(self, "com_feedback_kd", gains.kd, "COM feedback: velocity gain [s]"))
        self.stabiliser: ComStabiliser | None = None
        self._first_wait: float | None = None
        self._robot_wait: float | None = None      # when a frame first waited for the robot's state
        self._done_at: float | None = None
        self._next_due: float | None = None
        deep = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=2000, reliability=ReliabilityPolicy.RELIABLE)
        self.create_subscription(MocapFrame, MARKERS_TOPIC, self._on_markers, deep)
        # /human/com is subscribed with its publishers' durability once they appear (transient local from the
        # estimator: a late match still gets every estimate; volatile from a replayed bag); marker frames older than
        # the first COM received are skipped
        self.com_sub = None
        self._t_init = time.monotonic()
        self._com_discovery = self.create_timer(0.1, self._discover_com)
        self.create_subscription(ForcePlateSample, plate_topic("chair"), self._on_chair,
                                 QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=5000,
                                            reliability=ReliabilityPolicy.RELIABLE), raw=True)
        # the robot's measured posture: for the calibration, then for the COM feedback (else these go once the
        # calibration is done). Kept as bytes (400 Hz, in the real-time thread); read when a command needs them
        self.robot_subs = [self.create_subscription(JointState, "/robot/joint_states", self._on_joint_states, 10,
                                                    raw=True),
                           self.create_subscription(PoseStamped, "/robot/base_pose", self._on_base_pose, 10,
                                                    raw=True)]
        self.cmd_pub = self.create_publisher(JointTrajectory, "/robot/joint_command", PUBLISH_DEPTH)
        self.com_pub = self.create_publisher(CenterOfMass, "/robot/planned_com", PUBLISH_DEPTH)
        self.zmp_pub = self.create_publisher(PointStamped, "/robot/planned_zmp", PUBLISH_DEPTH)
        self.feedback_pub = self.create_publisher(Vector3Stamped, "/robot/com_feedback", PUBLISH_DEPTH)
        self.ik_pub = self.create_publisher(JointState, "/robot/retarget/ik", PUBLISH_DEPTH)
        self.status_pub = self.create_publisher(DiagnosticStatus, "~/status", 10)
        self.frames: deque = deque()          # (t_s, header, names, positions, valid, receipt time)
        self.coms: deque = deque(maxlen=400)  # (t_s, position, velocity)
        self.chair: deque = deque(maxlen=4000)
        self.robot_js: bytes | None = None        # the latest, serialized, and when it came (time.monotonic)
        self.robot_base: bytes | None = None
        self.robot_rx = (0.0, 0.0)
        self._js_order: tuple[list[str], np.ndarray] | None = None
        self.feedback_max_m = 0.0
        self.state_stale = 0                      # on-feet commands sent uncorrected: no recent robot state
        self.retargeter: Retargeter | None = None
        self.player: PlanPlayer | None = None
        self.latencies: list[float] = []          # marker received -> its command published
        self.own_latencies: list[float] = []      # marker and human COM both received -> command published
        self.in_step_latencies: list[float] = []  # marker -> command, frames whose COM came within in_step_s
        self.in_step_s = 0.02
        self.ik_costs: list[float] = []
        self.infeasible = 0
        self.skipped = 0                          # marker frames older than the first human COM received
        self.invalid_coms = 0
        self.processed = 0
        self.last_frame_wall = 0.0
        self.last_stamp = None
        self.finished = False
        self.exit_code = 0
        self.drain = IdleDrain(lambda: self.processed)
        self.scheduling = scheduling_text()
        try:        # the robot model now (~0.6 s idle, more under load), not when the first frames are queued
            self.robot_model = robot_model(self.plant_file, self.params_file or None)
        except (ValueError, OSError) as err:
            raise NodeError(f"retargeter: plant {self.plant_file}, controller_params "
                            f"{self.params_file or '(CAD)'}: {err}") from None
        self.create_timer(0.25 / self.rate_hz, self._tick)
        self.create_timer(2.0, self._report)
        self.get_logger().info(f"retargeter: plant {self.plant_file}, COM parameters "
                               f"{self.params_file or 'CAD'}; waiting for {MARKERS_TOPIC} and /human/com")

    # -- inputs ------------------------------------------------------------------------------------------------
    def _on_joint_states(self, data: bytes) -> None:
        self.robot_js = data
        self.robot_rx = (time.monotonic(), self.robot_rx[1])

    def _on_base_pose(self, data: bytes) -> None:
        self.robot_base = data
        self.robot_rx = (self.robot_rx[0], time.monotonic())

    def _on_chair(self, data: bytes) -> None:
        # 1 kHz, in the real-time process: read the stamp and Fz from the CDR bytes instead of building messages
        t_s, _, _, fz, _, _, _ = plate_sample_from_cdr(data)
        self.chair.append((t_s, fz))

    def _discover_com(self) -> None:
        if self.get_publishers_info_by_topic("/human/com"):
            qos = qos_matching_publishers(self, "/human/com", keep_all=False, depth=2000)
            self.com_sub = self.create_subscription(CenterOfMass, "/human/com", self._on_com, qos)
            self.get_logger().info(f"/human/com publisher found after {time.monotonic() - self._t_init:.2f} s; "
                                   f"subscribed ({qos.durability.name.lower()})")
            self._com_discovery.cancel()

    def _on_com(self, msg: CenterOfMass) -> None:
        if not self.coms and not self.invalid_coms:
            self.get_logger().info(f"first /human/com after {time.monotonic() - self._t_init:.2f} s")
        p, v = msg.position, msg.velocity
        pos, vel = np.array([p.x, p.y, p.z]), np.array([v.x, v.y, v.z])
        if not msg.valid or not np.all(np.isfinite(pos)):
            self.invalid_coms += 1         # an estimate the estimator itself rejects: frames interpolate across it
            return
        self.coms.append((stamp_ns(msg.header) * 1e-9, pos, np.where(np.isfinite(vel), vel, 0.0)))
        self._process()

    def _on_markers(self, msg: MocapFrame) -> None:
        pos = np.array([[p.x, p.y, p.z] for p in msg.positions], float).reshape(-1, 3)
        self.frames.append((stamp_ns(msg.header) * 1e-9, msg.header, list(msg.marker_names), pos,
                            np.asarray(msg.valid, bool), time.perf_counter()))
        self._process()

    def _com_for(self, t_s: float) -> np.ndarray | None:
        """The human COM at ``t_s``: its own estimate; between two estimates (the frame's own was invalid), the
        interpolation; after the latest one, that one moved on by its velocity if it is at most ``com_wait_s`` old;
        None: wait for it."""
        after = None
        for tc, p, v in reversed(self.coms):
            if abs(tc - t_s) < 1e-6:
                return p
            if tc > t_s:
                after = (tc, p)
                continue
            if after is not None:
                w = (t_s - tc) / (after[0] - tc)
                return (1.0 - w) * p + w * after[1]
            return p + v * (t_s - tc) if t_s - tc <= self.com_wait else None
        return None

    def _chair_force(self, t_s: float) -> float | None:
        if not self.chair:
            return None
        for tc, fz in reversed(self.chair):
            if tc <= t_s:
                return fz
        return self.chair[0][1]

    # -- processing --------------------------------------------------------------------------------------------
    def _start(self, names: list[str], pos: np.ndarray, valid: np.ndarray, com: np.ndarray) -> bool:
        q_start, joint_names = None, None
        if self.wait_for_robot:
            if self.robot_js is None or self.robot_base is None:
                self._robot_wait = self._robot_wait or time.monotonic()
                return False
            js = deserialize_message(self.robot_js, JointState)
            q_start, joint_names = self._robot_q(js), list(js.name)
        try:
            robot = robot_setup(q_start=q_start, start_joint_names=joint_names, prebuilt=self.robot_model)
            self.joint_names = robot.joint_names
            self.retargeter = Retargeter(robot, RetargetConfig())
            marker_map = self.retargeter.calibrate(names, pos, valid, com)
        except (ValueError, OSError) as err:
            raise NodeError(f"retargeter calibration: {err}") from None
        if self.map_out:
            marker_map.save(self.map_out)
        self.player = PlanPlayer(robot.model, 1.0 / self.rate_hz, robot.support_xy, margin_m=self.margin,
                                 lookahead_s=self.lookahead, smooth_frames=self.smooth, fixed_scale=self.fixed_scale,
                                 max_joint_speed=self.max_speed)
        self.names = names
        if self.com_feedback:
            self.stabiliser = ComStabiliser(robot.model, robot.sole_frames, robot.sole_targets, self.stabiliser_cfg)
        else:        # 400 callbacks/s no longer needed, in the same thread as the frames
            for sub in self.robot_subs:
                self.destroy_subscription(sub)
            self.robot_subs = []
        waited = f"; the first frames waited {time.monotonic() - self._robot_wait:.2f} s for the robot's state " \
                 "(they count in the latency)" if self._robot_wait else ""
        self.get_logger().info(f"calibrated on the first frame: {len(marker_map.links)} markers fixed to the robot; "
                               f"leg-length scale {self.retargeter.scale:.3f}{waited}")
        return True

    def _robot_q(self, js: JointState) -> np.ndarray:
        """The measured configuration: base pose (x y z, quaternion x y z w) and the joints in the JointState's
        order (``robot_setup`` maps them by name)."""
        b = deserialize_message(self.robot_base, PoseStamped).pose
        return np.concatenate([[b.position.x, b.position.y, b.position.z],
                               [b.orientation.x, b.orientation.y, b.orientation.z, b.orientation.w],
                               np.asarray(js.position, float)])

    def _measured_q(self, max_age_s: float = 0.1) -> np.ndarray | None:
        """The robot's measured configuration in the model's order, or None if its state is older than
        ``max_age_s`` (or lacks a joint)."""
        if self.robot_js is None or self.robot_base is None or \
                time.monotonic() - min(self.robot_rx) > max_age_s:
            return None
        js = deserialize_message(self.robot_js, JointState)
        if self._js_order is None or self._js_order[0] != list(js.name):
            if not set(self.joint_names) <= set(js.name):
                return None
            self._js_order = (list(js.name), np.array([list(js.name).index(n) for n in self.joint_names]) + 7)
        q = self._robot_q(js)
        return np.concatenate([q[:7], q[self._js_order[1]]])

    def _process(self) -> None:
        while self.frames:
            t_s, header, names, pos, valid, t_rx = self.frames[0]
            com = self._com_for(t_s)
            if com is None:
                if self.coms and self.coms[0][0] > t_s + 1e-6:     # the COM stream began after this frame
                    self.frames.popleft()
                    self.skipped += 1
                    continue
                return
            if self.retargeter is None and not self._start(names, pos, valid, com):
                return
            self.frames.popleft()
            t_ready = time.perf_counter()          # marker and COM both here: the retargeter's own latency starts
            if names != self.names:
                pm, vm = np.full((len(self.names), 3), np.nan), np.zeros(len(self.names), bool)
                for j, n in enumerate(names):
                    if n in self.names:
                        pm[self.names.index(n)], vm[self.names.index(n)] = pos[j], valid[j]
                pos, valid = pm, vm
            frame = self.retargeter.step(t_s, pos, valid, com, self._chair_force(t_s))
            self.ik_costs.append(frame.ik.seconds)
            self.infeasible += not frame.ik.feasible
            self.player.push(frame.q, not frame.seated)
            # one command per period of wall time, published as soon as a frame brings it (a burst of queued frames,
            # e.g. after the COM estimator's calibration pause, must not play the plan faster)
            now = time.monotonic()
            if self._next_due is None or now >= self._next_due - 0.5 / self.rate_hz:
                sent = self._pull_and_publish()
                if sent is not None:
                    self._next_due = max(self._next_due or now, now - 0.5 / self.rate_hz) + 1.0 / self.rate_hz
                    now_pc = sent
                    self.latencies.append(now_pc - t_rx)
                    self.own_latencies.append(now_pc - t_ready)
                    if t_ready - t_rx <= self.in_step_s:     # the COM stream kept up with the markers
                        self.in_step_latencies.append(now_pc - t_rx)
            self._publish_ik(header, frame.q)       # after the command: it is for the record, not on the path
            self.processed += 1
            self.last_frame_wall = time.monotonic()
            self.last_stamp = header.stamp

    def _pull_and_publish(self) -> float | None:
        """Publish the plan's next command, if it has one; returns when the joint command went out
        (``time.perf_counter``), or None."""
        cmd = self.player.pull()
        return None if cmd is None else self._publish(cmd)

    def _tick(self) -> None:
        """Keep the commands at the mocap rate when frames are late; after the markers stop, close the plan and play
        the rest of it. Marker frames that wait ``input_timeout_s`` for a human COM (or the robot's state) end the
        node with an error naming what is missing."""
        now = time.monotonic()
        if self.frames and now - max(self.last_frame_wall, self._first_wait or now) > self.input_timeout_s:
            missing = "/robot/joint_states and /robot/base_pose" if self.retargeter is None and self.coms and \
                self.wait_for_robot else "/human/com"
            self.get_logger().error(f"{len(self.frames)} marker frames waited {self.input_timeout_s:g} s for "
                                    f"{missing}; stopping")
            self.exit_code, self.finished = 2, True
            return
        if self.frames and self._first_wait is None:
            self._first_wait = now
        if self.player is None:
            return
        if self._next_due is not None and now > self._next_due + 0.5 / self.rate_hz and not self.player.done:
            if self._pull_and_publish() is not None:
                self._next_due += 1.0 / self.rate_hz
        if self.frames or now - self.last_frame_wall < 3.0 / self.rate_hz:
            return
        if not self.player.finished:
            self.player.close()
        if self.player.done:
            self._done_at = self._done_at or time.monotonic()
            if self.hold_s > 0 and time.monotonic() - self._done_at > self.hold_s:
                self.finished = True

    def _publish(self, cmd) -> float:
        """The joint command first (its send time is returned: the latency ends there), then the planned COM and
        ZMP."""
        q, offset = cmd.q, None
        if self.stabiliser is not None:
            q_measured = self._measured_q()
            self.state_stale += q_measured is None and cmd.on_feet
            fix = self.stabiliser.correct(cmd.q, cmd.com, q_measured, cmd.on_feet, 1.0 / self.rate_hz)
            q, offset = fix.q, fix.offset_m
        stamp = self.get_clock().now().to_msg()         # a command is for now: the driver applies it at once
        msg = JointTrajectory()
        msg.header.stamp = stamp
        msg.header.frame_id = "base_link"
        msg.joint_names = self.joint_names
        point = JointTrajectoryPoint()
        point.positions = q[7:].tolist()
        point.velocities = cmd.v[6:].tolist()
        point.accelerations = cmd.a[6:].tolist()
        msg.points = [point]
        self.cmd_pub.publish(msg)
        sent = time.perf_counter()
        com = CenterOfMass(source="robot_plan", valid=True, n_markers=0, marker_rms_m=float("nan"),
                           cop_error_m=float("nan"))
        com.header.stamp, com.header.frame_id = stamp, "world"
        com.position.x, com.position.y, com.position.z = map(float, cmd.com)
        self.com_pub.publish(com)
        z = PointStamped()
        z.header.stamp, z.header.frame_id = stamp, "world"
        z.point.x, z.point.y, z.point.z = map(float, cmd.zmp)
        self.zmp_pub.publish(z)
        if offset is not None:
            f = Vector3Stamped()
            f.header.stamp, f.header.frame_id = stamp, "world"
            f.vector.x, f.vector.y = float(offset[0]), float(offset[1])
            self.feedback_pub.publish(f)
            self.feedback_max_m = max(self.feedback_max_m, float(np.abs(offset).max()))
        return sent

    def _publish_ik(self, header, q: np.ndarray) -> None:
        js = JointState(name=["root_x", "root_y", "root_z", "root_qx", "root_qy", "root_qz", "root_qw"]
                        + self.joint_names, position=q.tolist())
        js.header.stamp, js.header.frame_id = header.stamp, "world"
        self.ik_pub.publish(js)

    def _stats(self) -> dict[str, str]:
        lat = np.array(self.latencies) * 1e3
        own = np.array(self.own_latencies) * 1e3
        step = np.array(self.in_step_latencies) * 1e3
        ik = np.array(self.ik_costs) * 1e3
        pct = lambda a, p: f"{np.percentile(a, p):.2f}" if len(a) else "nan"  # noqa: E731
        return {"frames": str(self.processed), "infeasible_frames": str(self.infeasible),
                "skipped_frames": str(self.skipped),
                "time_scale": f"{self.player.s:.2f}" if self.player else "nan",
                "ik_p50_ms": pct(ik, 50), "ik_p99_ms": pct(ik, 99),
                "latency_p50_ms": pct(lat, 50), "latency_p99_ms": pct(lat, 99),
                "own_latency_p50_ms": pct(own, 50), "own_latency_p99_ms": pct(own, 99),
                "in_step_frames": str(len(step)), "in_step_latency_p50_ms": pct(step, 50),
                "in_step_latency_p99_ms": pct(step, 99), "scheduling": self.scheduling,
                "com_feedback": "off" if not self.com_feedback else
                f"largest shift {self.feedback_max_m * 100:.1f} cm; {self.state_stale} on-feet commands without a "
                "recent robot state"}

    def _report(self) -> None:
        st = DiagnosticStatus(name=self.get_fully_qualified_name(), hardware_id="retargeter",
                              level=DiagnosticStatus.OK if not self.infeasible else DiagnosticStatus.WARN,
                              message=f"{self.processed} frames")
        st.values = [KeyValue(key=k, value=v) for k, v in self._stats().items()]
        self.status_pub.publish(st)

    def close(self) -> None:
        s = self._stats()
        print(f"[retargeter] {s['frames']} frames, {s['infeasible_frames']} infeasible, {s['skipped_frames']} without a "
              f"human COM; time scale {s['time_scale']}; "
              f"IK p50 {s['ik_p50_ms']} ms p99 {s['ik_p99_ms']} ms; marker->command latency p50 "
              f"{s['latency_p50_ms']} ms p99 {s['latency_p99_ms']} ms (waiting for the human COM included); "
              f"COM->command p50 {s['own_latency_p50_ms']} ms p99 {s['own_latency_p99_ms']} ms; marker->command with the "
              f"COM stream in step ({s['in_step_frames']} frames) p50 {s['in_step_latency_p50_ms']} ms p99 "
              f"{s['in_step_latency_p99_ms']} ms; scheduling {s['scheduling']}; COM feedback {s['com_feedback']}",
              flush=True)


main = node_main(RetargeterNode)

if __name__ == "__main__":
    raise SystemExit(main())
