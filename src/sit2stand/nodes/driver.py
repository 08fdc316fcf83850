"""Robot driver node: the robot of a profile (``robot``: TALOS, G1, a file) simulated in MuJoCo under its on-board
controller, behaving like the real robot.

The on-board controller (parameter ``controller``): ``inverse_dynamics``, joint PD with a feed-forward (inverse
dynamics along a trajectory's accelerations, else the ``feedforward`` parameter's), or ``wbc``, whole-body torque
control (:mod:`sit2stand.robot.torque_control`: a QP at 500 Hz on the measured state, tracking each command's joint
positions, velocities and accelerations with the soles in contact; its QP time per control step is reported, p50/p99,
on the status and on exit). Either knows only the identified (or CAD) parameters, never the plant's hidden effects.
Before the first command the robot sits under joint PD.

Subscribes:
* ``/robot/joint_command`` (trajectory_msgs/JointTrajectory, what the retargeter sends): the first point's
  positions, velocities and accelerations; with accelerations the feed-forward is inverse dynamics along the plan
  (joints not named keep their last reference);
* ``/robot/joint_state_command`` (sensor_msgs/JointState): positions and optional velocities by joint name.

A command is applied when the simulation reaches its header stamp (at once when the stamp is 0, already past, or
too far ahead, with a warning): the time bases, the command queue and the fall policy are
:mod:`sit2stand.robot.driver_timing`'s.

Publishes: ``/robot/joint_states`` (position, velocity, measured torque as effort) at ``state_rate_hz`` (500) of
simulated time, ``/robot/ft/left`` and ``/robot/ft/right`` (geometry_msgs/WrenchStamped: ground reaction in world
axes about the sole point, frame ``sole_<side>_world_aligned``), ``/robot/cop`` (geometry_msgs/PointStamped),
``/robot/base_pose`` (geometry_msgs/PoseStamped, what a state estimator would give), ``/robot/status``
(diagnostic_msgs/DiagnosticStatus, 10 Hz), and ``/clock`` when ``publish_clock`` is true (then every stamp is
simulated time). Under ``use_sim_time`` (a replayer's /clock drives the graph) the simulation follows that clock
instead of the wall clock: it waits seated, publishing nothing, until the first /clock, publishes its state at
that time at once (a clock held there still sees a robot), then steps to each /clock time, and each state sample
is stamped with the /clock time it simulates. Every name is relative (``__ns`` moves them). For RViz, Foxglove
and tf2 (what robot_state_publisher does on a full ROS install; see
:mod:`sit2stand.robot.description`): ``/tf`` (tf2_msgs/TFMessage: ``world`` -> the root link and every moving joint's
link, from the measured joint state and base pose, at ``tf_rate_hz`` with that state sample's stamp), and, transient
local, once: ``/tf_static`` (fixed joints, the soles, ``lab`` -> ``world``) and ``/robot_description``
(std_msgs/String: the robot's URDF).

Parameters: ``plant`` (YAML, or a packaged plant's name; default ``default``), ``controller_params`` (identified
parameters YAML from ``sit2stand identify``; empty: CAD), ``controller`` (inverse_dynamics | wbc, above),
``feedforward`` (joint PD's, for commands without accelerations: gravity | inverse_dynamics | none),
``real_time_factor`` (1.0; 0 = as fast as it can), ``state_rate_hz``, ``publish_clock``, ``on_fall`` (limp | hold),
``settle_s`` (2: simulated seconds to come to rest on the chair before anything is published), ``tf_rate_hz`` (50;
at most the state rate, 0: no ``/tf``), ``robot_description_meshes`` (``file``: this machine's paths, the default,
see :data:`~sit2stand.robot.description.DESCRIPTION_MESHES`; ``package``: the URDF's ``package://`` URIs).
Service: ``~/reset`` (std_srvs/Trigger): back to sitting on the chair.
Safety: torques clamped to the URDF efforts by the joints; a fall (pelvis below ``fall_pelvis_height_m`` or the base
tilted past ``fall_tilt_rad``) is published on the status and the robot goes limp or holds its posture.
"""

from __future__ import annotations

import time

import numpy as np
from builtin_interfaces.msg import Time as BuiltinTime
from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from geometry_msgs.msg import PointStamped, PoseStamped, TransformStamped, WrenchStamped
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from std_srvs.srv import Trigger
from tf2_msgs.msg import TFMessage
from trajectory_msgs.msg import JointTrajectory

from ..io.messages import stamp_ns
from ..io.stream_messages import JointStateEncoder, StampedNumbersEncoder
from ..io.tf_message import TfEncoder
from ..io.topics import (CLOCK_TOPIC, FELL_EXIT_CODE, ROBOT_BASE_POSE_TOPIC, ROBOT_COP_TOPIC, ROBOT_DESCRIPTION_TOPIC,
                         ROBOT_JOINT_COMMAND_TOPIC, ROBOT_JOINT_STATES_TOPIC, ROBOT_JOINT_STATE_COMMAND_TOPIC,
                         ROBOT_STATUS_TOPIC, TF_STATIC_TOPIC, TF_TOPIC, WORLD_FRAME, ft_topic, ros_name,
                         sole_world_aligned_frame)
from ..robot.description import DESCRIPTION_MESHES, DescriptionError, FrameTree, robot_description
from ..robot.driver_timing import FALL_POLICIES, SIM_EPOCH_S, CommandQueue, SimulationClock, respond_to_fall
from ..robot.identify import IdentificationError, read_link_parameters
from ..robot.model import SIDES, PlantConfig, PlantConfigError
from ..robot.profile import ProfileError, RobotProfile
from ..robot.plant import CONTROLLERS, Plant
from ..vectors import xyzw_from_wxyz
from .runtime import (LATCHED_QOS, PUBLISH_DEPTH, TF_QOS, NodeError, declare, node_main, publish_depth,
                      robot_state_qos, steady_timer)

DEFAULT_PLANT = "default"


class Driver(Node):
    """Simulates the robot (see the module docstring)."""

    executor_kind = "events"

    def __init__(self) -> None:
        super().__init__("driver")
        plant_file = declare(self, "plant", "", "plant YAML or packaged plant name") or DEFAULT_PLANT
        robot = declare(self, "robot", "", "robot profile: a packaged name (talos, g1) or a file (empty: the plant's)")
        params_file = declare(self, "controller_params", "", "identified parameters YAML (empty: CAD)")
        self.controller = declare(self, "controller", "inverse_dynamics",
                                  "on-board controller: inverse_dynamics (joint PD + feed-forward) | wbc (whole-body "
                                  "torque control)")
        self.ff_mode = declare(self, "feedforward", "gravity", "joint PD's feed-forward without accelerations: "
                               "gravity | inverse_dynamics | none")
        self.rtf = declare(self, "real_time_factor", 1.0, "1 = real time, 0 = as fast as possible")
        self.state_period = 1.0 / declare(self, "state_rate_hz", 500.0, "joint state rate [Hz] of simulated time")
        self.publish_clock = declare(self, "publish_clock", False, "publish /clock (simulated time)")
        self.on_fall = declare(self, "on_fall", "limp", "limp | hold")
        if self.ff_mode not in ("gravity", "inverse_dynamics", "none") or self.on_fall not in FALL_POLICIES or \
                self.controller not in CONTROLLERS:
            raise NodeError(f"controller {self.controller!r}, feedforward {self.ff_mode!r} or on_fall "
                            f"{self.on_fall!r} not recognised (controller: {' | '.join(CONTROLLERS)})")
        try:
            cfg = PlantConfig.load(plant_file, robot or None)
            ctrl = read_link_parameters(params_file) if params_file else None
            self.plant = Plant(cfg, controller_params=ctrl)
        except (PlantConfigError, ProfileError, IdentificationError, OSError) as err:
            raise NodeError(str(err)) from None
        self.plant.feedforward = self.ff_mode
        self.settle_s = declare(self, "settle_s", 2.0, "simulated seconds to come to rest on the chair at start")
        self.plant.settle(self.settle_s)
        self.names = self.plant.joint_names
        self.index = {n: i for i, n in enumerate(self.names)}
        fast = QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT)
        rate_hz = 1.0 / self.state_period
        depth, state_qos = publish_depth(rate_hz), robot_state_qos(rate_hz)   # a recorder held up loses none
        self.js_pub = self.create_publisher(JointState, ros_name(ROBOT_JOINT_STATES_TOPIC), state_qos)
        self.ft_pubs = {s: self.create_publisher(WrenchStamped, ros_name(ft_topic(s)), depth) for s in SIDES}
        self.cop_pub = self.create_publisher(PointStamped, ros_name(ROBOT_COP_TOPIC), depth)
        self.base_pub = self.create_publisher(PoseStamped, ros_name(ROBOT_BASE_POSE_TOPIC), state_qos)
        self.state_encoders = {
            "joints": JointStateEncoder(self.names, cfg.profile.root_link),
            **{side: StampedNumbersEncoder(sole_world_aligned_frame(side), StampedNumbersEncoder.WRENCH)
               for side in SIDES},
            "cop": StampedNumbersEncoder(WORLD_FRAME, StampedNumbersEncoder.POINT),
            "base": StampedNumbersEncoder(WORLD_FRAME, StampedNumbersEncoder.POSE)}
        self.status_pub = self.create_publisher(DiagnosticStatus, ros_name(ROBOT_STATUS_TOPIC), PUBLISH_DEPTH)
        self.clock_pub = self.create_publisher(Clock, ros_name(CLOCK_TOPIC), fast) if self.publish_clock else None
        self._setup_frames(cfg.profile)
        self.create_subscription(JointTrajectory, ros_name(ROBOT_JOINT_COMMAND_TOPIC), self._on_trajectory, 10)
        self.create_subscription(JointState, ros_name(ROBOT_JOINT_STATE_COMMAND_TOPIC), self._on_command, 10)
        self.create_service(Trigger, "~/reset", self._on_reset)
        self.sim_time = bool(self.get_parameter("use_sim_time").value)
        self.clock = SimulationClock(self.sim_time, self.publish_clock, self.rtf)
        self.clock.start(self.plant.t_s, time.monotonic(), self.get_clock().now().nanoseconds)
        self.commands = CommandQueue()
        self.steps_done = 0
        self._status_count, self._status_qp = 0, {}
        self._fall_reported = False
        self.exit_code = 0
        if not self.sim_time:
            self._publish_latched()
        # steady ticks either way: under use_sim_time a ROS-time timer would not run before the first /clock
        steady_timer(self, 0.005, self._tick)
        steady_timer(self, 0.1, self._publish_status)
        self.get_logger().info(f"{cfg.profile.title or cfg.profile.name} seated on a {self.plant.seat_height_m:.3f} m "
                               f"chair; plant {cfg.name}; "
                               f"controller model {'identified' if params_file else 'CAD'}; "
                               f"{'as fast as possible' if self.rtf <= 0 else f'{self.rtf:g}x real time'}")

    def _setup_frames(self, robot: RobotProfile) -> None:
        """/tf every ``tf_every`` state samples; /tf_static and /robot_description once (transient local)."""
        tf_rate = declare(self, "tf_rate_hz", 50.0, "/tf rate [Hz] (at most the state rate; 0: none)")
        meshes = declare(self, "robot_description_meshes", DESCRIPTION_MESHES, "package | file: mesh URIs of the URDF")
        try:
            urdf = robot_description(robot, meshes)
            self.frames = FrameTree(self.names, urdf, robot)
        except DescriptionError as err:
            raise NodeError(str(err)) from None
        self.tf_every = max(1, int(round(1.0 / (tf_rate * self.state_period)))) if tf_rate > 0 else 0
        self.tf_encoder = TfEncoder(self.frames.pairs)
        self.tf_pub = self.create_publisher(TFMessage, ros_name(TF_TOPIC), TF_QOS)
        self.tf_cost_s: list[float] = []          # per /tf message: forward kinematics + encoding + publish
        self._samples = 0
        self.urdf = urdf
        # kept: a latched message lives as long as its publisher
        self.tf_static_pub = self.create_publisher(TFMessage, ros_name(TF_STATIC_TOPIC), LATCHED_QOS)
        self.description_pub = self.create_publisher(String, ros_name(ROBOT_DESCRIPTION_TOPIC), LATCHED_QOS)

    def _publish_latched(self) -> None:
        """/tf_static and /robot_description, stamped now (under use_sim_time: once the clock runs)."""
        stamp = self._now_stamp()
        static = TFMessage()
        for tr in self.frames.static_transforms():
            m = TransformStamped(child_frame_id=tr.child)
            m.header.stamp, m.header.frame_id = stamp, tr.parent
            m.transform.translation.x, m.transform.translation.y, m.transform.translation.z = tr.translation_m
            r = m.transform.rotation
            r.x, r.y, r.z, r.w = tr.rotation_xyzw
            static.transforms.append(m)
        self.tf_static_pub.publish(static)
        self.description_pub.publish(String(data=self.urdf))

    # -- commands ---------------------------------------------------------------------------------------------
    def _apply(self, names, positions, velocities=None, accelerations=None, ff=None) -> None:
        q, qd, qdd = self.plant.q_ref.copy(), self.plant.qd_ref.copy(), self.plant.qdd_ref.copy()
        for k, name in enumerate(names):
            j = self.index.get(name)
            if j is None:
                self.get_logger().warning(f"command for unknown joint {name!r} ignored", throttle_duration_sec=5.0)
                continue
            q[j] = positions[k]
            qd[j] = velocities[k] if velocities is not None and len(velocities) > k else 0.0
            qdd[j] = accelerations[k] if accelerations is not None and len(accelerations) > k else 0.0
        if not np.all(np.isfinite(q)) or not np.all(np.isfinite(qd)) or not np.all(np.isfinite(qdd)):
            self.get_logger().error("command with NaN or inf rejected", throttle_duration_sec=2.0)
            return
        self.plant.command(q, qd, qdd, feedforward=ff)

    def _on_command(self, msg: JointState) -> None:
        if len(msg.position) != len(msg.name):
            self.get_logger().error(f"/robot/joint_state_command: {len(msg.name)} names but {len(msg.position)} "
                                    "positions")
            return
        self._schedule(stamp_ns(msg.header), (msg.name, list(msg.position), list(msg.velocity) or None, None,
                                              self._torque_control()))

    def _on_trajectory(self, msg: JointTrajectory) -> None:
        if not msg.points:
            return
        p = msg.points[0]
        self._schedule(stamp_ns(msg.header), (msg.joint_names, list(p.positions), list(p.velocities) or None,
                                              list(p.accelerations) or None,
                                              self._torque_control() or
                                              ("inverse_dynamics" if len(p.accelerations) else None)))

    def _torque_control(self) -> str | None:
        """The plant's control mode for a command under whole-body torque control (None: joint PD)."""
        return "wbc" if self.controller == "wbc" else None

    def _schedule(self, stamp: int, command: tuple) -> None:
        """Apply ``command`` (the arguments of :meth:`_apply`) when the simulation reaches ``stamp`` [ns]."""
        sim_ns = self._sim_ros_ns()
        # the graph's clock now: the simulated time where the driver publishes it, else this node's clock
        now_ns = None if sim_ns is None else sim_ns if self.publish_clock else self.get_clock().now().nanoseconds
        if not self.commands.add(stamp, command, now_ns):
            self.get_logger().warning(f"a command stamped {(stamp - now_ns) * 1e-9:.2f} s ahead of the graph's clock "
                                      "(clocks not synchronised, or not on the simulated time?): applied at once",
                                      throttle_duration_sec=5.0)
        self._apply_due()

    def _apply_due(self) -> None:
        """Apply the pending commands whose stamps the simulation has reached (in the order they came)."""
        for command in self.commands.due(self._sim_ros_ns()):
            self._apply(*command)

    def _on_reset(self, _req: Trigger.Request, res: Trigger.Response) -> Trigger.Response:
        self.plant.reset()
        self.plant.feedforward = self.ff_mode
        self.plant.settle(self.settle_s)
        self.commands.clear()
        self.clock.start(self.plant.t_s, time.monotonic(), self.get_clock().now().nanoseconds)
        self._fall_reported = False
        self.exit_code = 0
        res.success, res.message = True, "reset: seated on the chair"
        return res

    # -- simulation ----------------------------------------------------------------------------------------------
    def _tick(self) -> None:
        plant = self.plant
        clock_ns = self.get_clock().now().nanoseconds if self.sim_time else None
        if clock_ns and self.clock.follow(clock_ns, plant.t_s):
            self._publish_latched()
            # the seated state at once, at the clock's time: a clock held for the first command (the replayer's
            # lockstep) would otherwise hold this driver's first state too, and the retargeter waits for it
            self._publish_state()
        target = self.clock.target_s(plant.t_s, clock_ns, time.monotonic())
        if target is None:                   # no /clock yet: wait seated
            return
        chunk = max(1, int(round(self.state_period / plant.cfg.timestep_s)))
        # behind (a held-up tick): the target is a slice ahead, so that the commands sent meanwhile are taken in
        # between and applied at their stamps; the next tick comes at once
        while plant.t_s + 0.5 * plant.cfg.timestep_s < target:
            self._apply_due()
            plant.step(chunk)
            self.steps_done += chunk
            self._publish_state()
            if plant.fallen and not self._fall_reported:
                self._fall_reported = True
                self.exit_code = FELL_EXIT_CODE        # the graph's job failed: the launcher says so
                self.get_logger().error(f"robot {plant.status_text} at {plant.t_s:.2f} s of simulated time; "
                                        f"going {self.on_fall}")
                respond_to_fall(plant, self.on_fall)

    def _sim_ros_ns(self) -> int | None:
        """The ROS time [ns] of the simulated state now (:meth:`SimulationClock.ros_ns`)."""
        return self.clock.ros_ns(self.plant.t_s)

    def _now_ns(self) -> int:
        ns = self._sim_ros_ns()
        return self.get_clock().now().nanoseconds if ns is None else ns

    def _now_stamp(self):
        sec, nsec = divmod(self._now_ns(), 1_000_000_000)
        return BuiltinTime(sec=sec, nanosec=nsec)

    def _publish_state(self) -> None:
        """One state sample, every message with its stamp; laid out as bytes (:mod:`sit2stand.io.stream_messages`)."""
        s = self.plant.sensors()
        self._sample_ns = t_ns = self._now_ns()
        if self.clock_pub is not None:
            c = Clock()
            c.clock.sec, c.clock.nanosec = divmod(int(round((SIM_EPOCH_S + self.plant.t_s) * 1e9)), 1_000_000_000)
            self.clock_pub.publish(c)
        enc = self.state_encoders
        self.js_pub.publish(enc["joints"].encode(t_ns, s.q, s.qd, s.tau))
        for side in SIDES:
            self.ft_pubs[side].publish(enc[side].encode(t_ns, s.wrench_world[side][:6]))
        self.cop_pub.publish(enc["cop"].encode(t_ns, s.cop_m if s.cop_valid else np.full(3, np.nan)))
        b = s.base_pose            # x y z, then the quaternion w x y z (MuJoCo's order); the message's is x y z w
        self.base_pub.publish(enc["base"].encode(t_ns, [*b[:3], *xyzw_from_wxyz(b[3:7])]))
        self._samples += 1
        if self.tf_every and (self._samples - 1) % self.tf_every == 0:     # from the first sample on
            self._publish_tf(s)

    def _publish_tf(self, s) -> None:
        """world -> the root link and every moving joint of this state sample (raw CDR: see io/tf_message.py)."""
        t0 = time.perf_counter()
        translations, rotations = self.frames.transforms(s.base_pose, s.q)
        self.tf_pub.publish(self.tf_encoder.encode(self._sample_ns, translations, rotations))
        if len(self.tf_cost_s) < 1_000_000:
            self.tf_cost_s.append(time.perf_counter() - t0)

    def _tf_cost_text(self) -> str:
        if not self.tf_cost_s:
            return "no /tf published"
        us = np.percentile(self.tf_cost_s, [50, 99]) * 1e6
        return (f"/tf at {1.0 / (self.tf_every * self.state_period):g} Hz: {len(self.tf_cost_s)} messages of "
                f"{len(self.frames.pairs)} transforms, {us[0]:.0f} us median, {us[1]:.0f} us p99 per message")

    def _publish_status(self) -> None:
        plant = self.plant
        self._status_count += 1
        if self._status_count % 10 == 1:     # percentiles of up to 60,000 QP times: once a second, not at 10 Hz
            self._status_qp = self._qp_figures()
        status = DiagnosticStatus(name=self.get_fully_qualified_name(),
        hardware_id=f"{self.plant.cfg.profile.name}_sim",
                                  level=DiagnosticStatus.ERROR if plant.fallen else DiagnosticStatus.OK,
                                  message=plant.status_text if plant.fallen else ("limp" if plant.limp else "ok"))
        status.values = [KeyValue(key=k, value=v) for k, v in (
            ("sim_time_s", f"{plant.t_s:.3f}"),
            ("real_time_factor", f"{self.clock.real_time_factor(plant.t_s, time.monotonic()):.2f}"),
            ("pelvis_height_m", f"{plant.data.qpos[2]:.3f}"), ("feedforward", plant.feedforward),
            ("controller", self.controller), *self._status_qp.items())]
        self.status_pub.publish(status)

    def close(self) -> None:
        now = time.monotonic()
        print(f"[driver] simulated {self.plant.t_s - self.clock.sim0_s:.2f} s in {now - self.clock.wall0_s:.2f} s "
              f"(real-time factor {self.clock.real_time_factor(self.plant.t_s, now):.2f}); "
              f"{'FALLEN: ' + self.plant.status_text if self.plant.fallen else 'upright'}; {self._tf_cost_text()}"
              f"{self._qp_text()}", flush=True)

    def _qp_figures(self) -> dict[str, str]:
        """The whole-body controller's QP figures (its latest steps) as status text, when it has run."""
        f = self.plant.wbc.qp_figures() if self.plant.wbc is not None else {}
        return {"qp_steps": str(f["qp_steps"]), "qp_p50_ms": f"{f['qp_ms_p50']:.2f}",
                "qp_p99_ms": f"{f['qp_ms_p99']:.2f}", "qp_cpu_p99_ms": f"{f['qp_cpu_ms_p99']:.2f}"} if f else {}

    def _qp_text(self) -> str:
        f = self._qp_figures()
        return (f"; whole-body QP p50 {f['qp_p50_ms']} ms p99 {f['qp_p99_ms']} ms (CPU p99 {f['qp_cpu_p99_ms']} ms; "
                f"{f['qp_steps']} steps)") if f else ""


main = node_main(Driver)

if __name__ == "__main__":
    raise SystemExit(main())
