"""Robot driver node: the robot of a profile (``robot``: TALOS, G1, a file) simulated in MuJoCo under its on-board
controller, behaving like the real robot.

The on-board controller: joint PD with a feed-forward, or whole-body torque control
(:mod:`sit2stand.robot.torque_control`, a QP at 500 Hz); either knows only the identified (or CAD) parameters, never
the plant's hidden effects. Before the first command the robot sits under joint PD. A command is applied when the
simulation reaches its header stamp: the time bases, the command queue and the fall policy are
:mod:`sit2stand.robot.driver_timing`'s; what it publishes of the robot, :mod:`sit2stand.nodes.robot_outputs`. Under
``use_sim_time`` the simulation follows the graph's /clock; otherwise wall time scaled by ``real_time_factor``, or
its own /clock. Topics, parameters and the reset service: ``docs/nodes.md`` (driver).
"""

from __future__ import annotations

import time

import numpy as np
from builtin_interfaces.msg import Time as BuiltinTime
from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger
from trajectory_msgs.msg import JointTrajectory

from ..io.messages import stamp_ns
from ..io.topics import (FELL_EXIT_CODE, ROBOT_JOINT_COMMAND_TOPIC, ROBOT_JOINT_STATE_COMMAND_TOPIC,
                         ROBOT_STATUS_TOPIC, ros_name)
from ..robot.description import DESCRIPTION_MESHES
from ..robot.driver_timing import FALL_POLICIES, CommandQueue, SimulationClock, respond_to_fall
from ..robot.identify import IdentificationError, read_link_parameters
from ..robot.model import PlantConfig, PlantConfigError
from ..robot.profile import ProfileError
from ..robot.plant import CONTROLLERS, Plant
from .robot_outputs import RobotOutputs
from .runtime import NodeError, declare, node_main, steady_timer
from .qos import PUBLISH_DEPTH

DEFAULT_PLANT = "default"


class Driver(Node):
    """Simulates the robot (see the module docstring)."""

    executor_kind = "events"

    def __init__(self) -> None:
        super().__init__("driver")
        plant_file = declare(self, "plant", "", "plant YAML or packaged plant name") or DEFAULT_PLANT
        robot = declare(self, "robot", "", "robot profile: packaged (`sit2stand robot list`) or a file (empty: the "
                                           "plant's)")
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
        self.index = {n: i for i, n in enumerate(self.plant.joint_names)}
        self.out = RobotOutputs(self, self.plant.joint_names, cfg.profile, 1.0 / self.state_period,
                                declare(self, "tf_rate_hz", 50.0, "/tf rate [Hz] (at most the state rate; 0: none)"),
                                declare(self, "robot_description_meshes", DESCRIPTION_MESHES,
                                        "package | file: mesh URIs of the URDF"), self.publish_clock)
        self.status_pub = self.create_publisher(DiagnosticStatus, ros_name(ROBOT_STATUS_TOPIC), PUBLISH_DEPTH)
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

    def _publish_latched(self) -> None:
        """/tf_static and /robot_description, stamped now (under use_sim_time: once the clock runs)."""
        self.out.latched(self._now_stamp())

    # -- commands ---------------------------------------------------------------------------------------------
    def _apply(self, names, positions, velocities=None, accelerations=None, ff=None) -> None:
        q, qd, qdd = self.plant.q_ref.copy(), self.plant.ref.qd.copy(), self.plant.ref.qdd.copy()
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
        """The ROS time [ns] of the simulated state now; unpaced on wall time, the system clock's time (what the ROS
        clock reads without ``use_sim_time``, at a tenth of its call's cost: this stamps 500 states a second)."""
        ns = self._sim_ros_ns()
        if ns is not None:
            return ns
        return self.get_clock().now().nanoseconds if self.sim_time else time.time_ns()

    def _now_stamp(self):
        sec, nsec = divmod(self._now_ns(), 1_000_000_000)
        return BuiltinTime(sec=sec, nanosec=nsec)

    def _publish_state(self) -> None:
        """One state sample, every message with its stamp."""
        self.out.state(self.plant.sensors(), self._now_ns(), self.plant.t_s)

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
              f"{'FALLEN: ' + self.plant.status_text if self.plant.fallen else 'upright'}; {self.out.tf_cost_text()}"
              f"{self._qp_text()}", flush=True)

    def _qp_figures(self) -> dict[str, str]:
        """The whole-body controller's QP figures (its latest steps) and its estimate of the true COM's offset from
        its model's, as status text, when it has run."""
        f = self.plant.wbc.qp_figures() if self.plant.wbc is not None else {}
        if not f:
            return {}
        offset = self.plant.wbc.com_offset.offset_m
        return {"qp_steps": str(f["qp_steps"]), "qp_p50_ms": f"{f['qp_ms_p50']:.2f}",
                "qp_p99_ms": f"{f['qp_ms_p99']:.2f}", "qp_cpu_p99_ms": f"{f['qp_cpu_ms_p99']:.2f}",
                "com_offset_x_m": f"{offset[0]:.4f}", "com_offset_y_m": f"{offset[1]:.4f}"}

    def _qp_text(self) -> str:
        f = self._qp_figures()
        return (f"; whole-body QP p50 {f['qp_p50_ms']} ms p99 {f['qp_p99_ms']} ms (CPU p99 {f['qp_cpu_p99_ms']} ms; "
                f"{f['qp_steps']} steps)") if f else ""


main = node_main(Driver)

if __name__ == "__main__":
    raise SystemExit(main())
