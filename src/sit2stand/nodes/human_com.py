"""Human COM estimator node: markers + force plates in, the human centre of mass out, per frame.

Subscribes ``/mocap/markers`` (sit2stand_msgs/MocapFrame) and every ``/force_plate/*`` topic
(sit2stand_msgs/ForcePlateSample, discovered as they appear). Publishes, per marker frame:

* ``/human/com`` (sit2stand_msgs/CenterOfMass): position now; velocity and acceleration from a causal fit;
  ``valid`` false (last estimate repeated) on frames with too few markers;
* ``/human/joint_states`` (sensor_msgs/JointState, frame ``pelvis``): the fitted skeleton's joint angles;
* ``/human/pelvis_pose`` (geometry_msgs/PoseStamped, lab): the skeleton's floating base;
* ``/human/model_cop`` and ``/human/measured_cop`` (geometry_msgs/PointStamped, lab), half a window (~150 ms)
  behind, stamped with the frame they belong to;
* ``/human/scaling`` (sit2stand_msgs/InertialParameters, transient local): the segment masses it chose, each
  time it re-solves them (every ``rescale_every_s`` of frames with plate data);
* for RViz and Foxglove, at ``viz_rate_hz`` (50) of marker time: ``/tf`` (lab -> pelvis -> every segment, see
  :mod:`sit2stand.human.description`) and ``/viz/human`` (visualization_msgs/MarkerArray: the frame's markers, the
  COM, both COPs; :func:`sit2stand.nodes.markers.human_markers`); ``/human/robot_description`` (std_msgs/String,
  transient local): the URDF of the skeleton, again when the calibration rescales it.

Every name is relative (:func:`sit2stand.io.topics.ros_name`): ``__ns`` moves them all. Stamps are the marker
frame's (bag time when replayed: run it with ``use_sim_time`` under the replayer's /clock).

Parameters: ``height_m``, ``mass_kg``, ``sex`` (the subject; with no stature or mass given, the subject comes from
``/human/subject``, latched, as a bag carries it, and marker frames wait for it), ``marker_set`` (a packaged set's
name or a YAML file, as ``sit2stand human-com --marker-set``; empty: the packaged set that covers most of the stream's
marker names), ``rate_hz`` (marker rate, 100), ``window_s`` (0.3
s), ``calibration_frames`` (50: length and marker calibration from the first frames, a pause of ~1 s, several
under load, that the stream then runs behind), ``calibration_file`` (a calibration made beforehand from a static
trial, ``sit2stand human-calibrate``: no pause), ``rescale_every_s`` (2.5 s),
``chair_on_plate`` (true: every frame with the whole weight on plates is used; false: only after seat-off),
``plates`` (names of the plates to expect, e.g. [chair, feet]: frames count only when all have data; default:
the plates that appear), ``viz_rate_hz`` (50; 0: no /tf nor markers), ``shed_behind_s`` (0: off; live, e.g.
0.03: a frame that reaches the estimator this far behind the ROS clock gets its COM, joint angles and pelvis pose
only, not the delayed window's COPs and scaling rows nor /tf, so that an estimator held up catches up in a few
frames instead of running behind for the rest of the stream; the frames so shed are counted),
``fifo_after_calibration`` (0: off; e.g. 40: once calibrated, the estimator moves itself to that SCHED_FIFO
priority where permitted: live, on a computer shared with the robot's loop).
The per-frame cost is logged on exit (p50/p99) and on ``~/stats`` (diagnostic_msgs/DiagnosticStatus) every 2 s.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from geometry_msgs.msg import PointStamped, PoseStamped
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from sit2stand_msgs.msg import CenterOfMass, ForcePlateSample, InertialParameters, MocapFrame
from sit2stand_msgs.msg import Subject as SubjectMsg
from std_msgs.msg import Header, String
from tf2_msgs.msg import TFMessage
from visualization_msgs.msg import MarkerArray

from ..human.calibration import StreamCalibration
from ..human.description import SkeletonFrames, human_urdf
from ..human.com import WINDOW_S
from ..human.com_stream import RESCALE_EVERY_S, StreamingComEstimator
from ..human.marker_ik import MarkerUnitsError, TooFewMarkers
from ..human.marker_sets import MarkerSetError, choose_marker_set
from ..human.skeleton import Subject
from ..io.messages import mocap_arrays, plate_sample_from_cdr, reorder_markers, stamp_ns
from ..io.stream_messages import JointStateEncoder, StampedNumbersEncoder
from ..io.tf_message import TfEncoder
from ..scheduling import Scheduling
from ..io.topics import (FORCE_PLATE_PREFIX, HUMAN_COM_TOPIC, HUMAN_DESCRIPTION_TOPIC, HUMAN_JOINTS_TOPIC,
                         HUMAN_MARKERS_TOPIC, HUMAN_MEASURED_COP_TOPIC, HUMAN_MODEL_COP_TOPIC, HUMAN_PELVIS_POSE_TOPIC,
                         HUMAN_ROOT_FRAME, HUMAN_SCALING_TOPIC, LAB_FRAME, MARKERS_TOPIC, SUBJECT_TOPIC, TF_TOPIC,
                         bag_name, ros_name)
from .markers import human_markers
from .runtime import (LATCHED_QOS, PUBLISH_DEPTH, TF_QOS, IdleDrain, NodeError, declare, marker_rate_check,
                      node_main, scheduling_text, steady_timer)

SUBJECT_WAIT_FRAMES = 500        # marker frames held for /human/subject (5 s at 100 Hz; a bag latches it first)
PENDING_PLATE_SAMPLES = 4000      # per plate, between two marker frames (4 s at 1 kHz; the estimator keeps ~2 s)


class HumanComNode(Node):
    """Streams the human COM (see the module docstring)."""

    executor_kind = "events"  # publishes only from its own callbacks: the fast executor is safe here
    # after a signal, keep taking/processing what already arrived while it keeps coming (stops after 0.3 s idle);
    # a backlog (e.g. after the human_com calibration pause) can take several seconds under load
    drain_timeout_s = 30.0

    def __init__(self) -> None:
        super().__init__("human_com")
        height, mass = declare(self, "height_m", 0.0, "stature [m] (0: from /human/subject)"), \
            declare(self, "mass_kg", 0.0, "body mass [kg] (0: from /human/subject)")
        self.sex = declare(self, "sex", "male", "male | female")
        self.marker_set = declare(self, "marker_set", "", "marker set: a packaged set's name or a YAML file (empty: "
                                  "the packaged set that covers most of the stream's marker names)")
        self.subject = Subject(height, mass, self.sex) if height > 0 and mass > 0 else None
        self._held: list[MocapFrame] = []       # marker frames that came before the subject
        if self.subject is None:
            self.create_subscription(SubjectMsg, ros_name(SUBJECT_TOPIC), self._on_subject, LATCHED_QOS)
        self.rate_hz = declare(self, "rate_hz", 100.0, "marker rate [Hz]")
        self.rate_check = marker_rate_check(self.rate_hz)
        self.window_s = declare(self, "window_s", WINDOW_S, "Savitzky-Golay window [s]")
        self.calibration_frames = declare(self, "calibration_frames", 50, "frames used to calibrate the model")
        self.rescale_every_s = declare(self, "rescale_every_s", RESCALE_EVERY_S, "re-solve the masses every this "
                                       "much time [s] of frames with plates")
        if not self.rescale_every_s > 0:
            raise NodeError(f"human_com: parameter rescale_every_s is {self.rescale_every_s!r}; give the time [s] "
                            "between two mass scalings (> 0)")
        self.chair_on_plate = declare(self, "chair_on_plate", True, "the chair stands on a force plate")
        self.expected_plates = declare(self, "plates", [], "plate names to expect (default: whatever appears)")
        self.fifo_after_calibration = declare(self, "fifo_after_calibration", 0, "once calibrated, run at this "
                                              "SCHED_FIFO priority (0: stay as started)")
        cal_file = declare(self, "calibration_file", "", "skeleton calibration YAML made beforehand (sit2stand "
                           "human-calibrate); empty: calibrate on the first frames")
        self.shed_behind_s = declare(self, "shed_behind_s", 0.0, "a frame this far behind the clock [s] gets its "
                                     "COM only: no COPs, scaling rows nor /tf (0: never)")
        self.shed = 0
        self.calibration = None
        if cal_file:
            try:
                self.calibration = StreamCalibration.load(cal_file)
                if self.subject is not None:
                    self.calibration.build(self.subject)      # the subject it was made for
            except ValueError as err:
                raise NodeError(f"calibration_file: {err}") from None
        deep = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=2000, reliability=ReliabilityPolicy.RELIABLE)
        self.create_subscription(MocapFrame, ros_name(MARKERS_TOPIC), self._on_markers, deep)
        # transient-local with a deep history: a subscriber that matches late (a recorder still discovering the
        # topic when the first frames come) still gets every estimate
        history = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=PUBLISH_DEPTH,
                             reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.com_pub = self.create_publisher(CenterOfMass, ros_name(HUMAN_COM_TOPIC), history)
        self.joint_pub = self.create_publisher(JointState, ros_name(HUMAN_JOINTS_TOPIC), history)
        self.pelvis_pub = self.create_publisher(PoseStamped, ros_name(HUMAN_PELVIS_POSE_TOPIC), history)
        self.model_cop_pub = self.create_publisher(PointStamped, ros_name(HUMAN_MODEL_COP_TOPIC), history)
        self.measured_cop_pub = self.create_publisher(PointStamped, ros_name(HUMAN_MEASURED_COP_TOPIC), history)
        self._joint_encoder: JointStateEncoder | None = None     # the skeleton's joints: made with the estimator
        self._lab_pose = StampedNumbersEncoder(LAB_FRAME, StampedNumbersEncoder.POSE)
        self._lab_point = StampedNumbersEncoder(LAB_FRAME, StampedNumbersEncoder.POINT)
        self._cop_numbers = np.zeros(3)        # a COP on the floor: z 0
        self.scaling_pub = self.create_publisher(InertialParameters, ros_name(HUMAN_SCALING_TOPIC), LATCHED_QOS)
        self._setup_viz(declare(self, "viz_rate_hz", 50.0, "/tf and /viz/human rate [Hz] of marker time (0: none)"))
        self.stats_pub = self.create_publisher(DiagnosticStatus, "~/stats", 10)
        self.plate_subs: dict[str, object] = {}
        self._pending_plates: dict[str, list[tuple]] = {}   # samples received since the last marker frame
        self.estimator: StreamingComEstimator | None = None
        self.costs: list[float] = []
        self.cpu_costs: list[float] = []     # the thread's CPU time per frame: below the wall time, it waited
        self.skipped = 0
        self.last_com: np.ndarray | None = None
        self.last_cop_error = float("nan")
        self.finished = False
        self.exit_code = 0
        self.drain = IdleDrain(lambda: len(self.costs))   # after a signal, finish the frames already received
        self.names: list[str] = []
        self._stream_checked = False
        if self.calibration is not None and self.subject is not None:
            # the skeleton now, for the calibration's markers (each frame is put in their order), not on the first
            # frame: ~0.1 s there held up the stream's first 25 frames on 2 cores
            self._start(list(self.calibration.marker_placements_m))
        steady_timer(self, 0.5, self._discover_plates)
        steady_timer(self, 2.0, self._report)
        self._discover_plates()
        who = f"a {height:g} m, {mass:g} kg {self.sex}" if self.subject else f"the subject of {SUBJECT_TOPIC}"
        self.get_logger().info(f"human COM estimator for {who}; waiting for {MARKERS_TOPIC}")

    def _setup_viz(self, rate_hz: float) -> None:
        """/tf and /viz/human every ``viz_every`` marker frames; the description when the skeleton is (re)built."""
        self.viz_every = max(1, int(round(self.rate_hz / rate_hz))) if rate_hz > 0 else 0
        self.tf_pub = self.create_publisher(TFMessage, ros_name(TF_TOPIC), TF_QOS)
        self.viz_pub = self.create_publisher(MarkerArray, ros_name(HUMAN_MARKERS_TOPIC), PUBLISH_DEPTH)
        self.description_pub = self.create_publisher(String, ros_name(HUMAN_DESCRIPTION_TOPIC), LATCHED_QOS)
        self._described = None           # the skeleton (HumanModel) the frames and description are of
        self._frames_seen = 0

    def _discover_plates(self) -> None:
        for resolved, types in self.get_topic_names_and_types():
            topic = bag_name(self.get_namespace(), resolved)     # None: another namespace's
            if topic is not None and topic.startswith(FORCE_PLATE_PREFIX) and topic not in self.plate_subs and \
                    "sit2stand_msgs/msg/ForcePlateSample" in types:
                name = topic[len(FORCE_PLATE_PREFIX):]
                qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=5000, reliability=ReliabilityPolicy.RELIABLE)
                self.plate_subs[topic] = self.create_subscription(   # raw: see _on_plate
                    ForcePlateSample, ros_name(topic), lambda data, n=name: self._on_plate(n, data), qos, raw=True)
                self.get_logger().info(f"using force plate {resolved}")

    def _on_plate(self, name: str, data: bytes) -> None:
        # ~1 kHz per plate: the stamp and wrench are read straight from the CDR bytes (~1 us, against ~30 us to build
        # the message) into a tuple; they go to the estimator in one array per plate at the next marker frame
        rows = self._pending_plates.setdefault(name, [])
        rows.append(plate_sample_from_cdr(data))
        if len(rows) > PENDING_PLATE_SAMPLES:          # plates streaming without marker frames: keep the newest
            del rows[:-PENDING_PLATE_SAMPLES // 2]

    def _flush_plates(self) -> None:
        for name, rows in self._pending_plates.items():
            if rows:
                a = np.array(rows)
                self.estimator.add_plate_samples(name, a[:, 0], a[:, 1:4], a[:, 4:7])
                rows.clear()

    def _on_subject(self, msg: SubjectMsg) -> None:
        if self.subject is not None:
            return
        try:
            self.subject = Subject(msg.height_m, msg.mass_kg, msg.sex or self.sex)
        except ValueError as err:
            self._fail(f"{SUBJECT_TOPIC}: {err}")
            return
        self.get_logger().info(f"subject from {SUBJECT_TOPIC}: {msg.height_m:g} m, {msg.mass_kg:g} kg "
                               f"{self.subject.sex}")
        held, self._held = self._held, []
        for frame in held:
            self._on_markers(frame)

    def _fail(self, text: str) -> None:
        self.get_logger().error(text)
        self.exit_code, self.finished = 2, True

    def _start(self, names: list[str]) -> bool:
        """The estimator for the stream's marker names and the subject (False: the node stops, saying why)."""
        try:
            markers = choose_marker_set(names, self.marker_set or None)
            self.subject = dataclasses.replace(self.subject, marker_set=markers)
            self.estimator = StreamingComEstimator(
                self.subject, names, rate_hz=self.rate_hz, window_s=self.window_s,
                calibration_frames=self.calibration_frames, rescale_every_s=self.rescale_every_s,
                chair_on_plate=self.chair_on_plate, calibration=self.calibration, defer_rescale=True)
        except (TooFewMarkers, MarkerSetError) as err:
            self._fail(f"{MARKERS_TOPIC}: {err}")
            return False
        except ValueError as err:         # a calibration_file made for another subject
            self._fail(f"calibration_file: {err}")
            return False
        for name in self.expected_plates:
            self.estimator.expect_plate(name)
        self.names = names
        # the skeleton's joints never change (a calibration rescales lengths only): their names laid out once
        self._joint_encoder = JointStateEncoder(self.estimator.human.joint_names(), HUMAN_ROOT_FRAME, ("position",))
        self.get_logger().info(f"marker set {markers.name}: {len(markers.covered(names))} of the stream's "
                               f"{len(names)} markers")
        return True

    def _check_stream(self, names: list[str]) -> None:
        """The first frame's marker names against the estimator's (made before the stream from a calibration)."""
        self._stream_checked = True
        missing = [n for n in self.names if n not in names]
        if missing:
            self.get_logger().warning(f"{MARKERS_TOPIC} lacks {len(missing)} of the calibration's markers "
                                      f"({', '.join(missing[:8])}{', ...' if len(missing) > 8 else ''}): treated "
                                      "as occluded")

    def _on_markers(self, msg: MocapFrame) -> None:
        if self.finished:
            return
        if self.subject is None:
            self._held.append(msg)
            if len(self._held) > SUBJECT_WAIT_FRAMES:
                self._fail(f"no {SUBJECT_TOPIC} after {SUBJECT_WAIT_FRAMES} marker frames and no height_m/mass_kg "
                           f"parameters: give them")
            return
        t0, c0 = time.perf_counter(), time.thread_time()
        if self.estimator is None and not self._start(list(msg.marker_names)):
            return
        if not self._stream_checked:
            self._check_stream(list(msg.marker_names))
        pos, valid = reorder_markers(*mocap_arrays(msg), self.names)
        t_s = stamp_ns(msg.header) * 1e-9
        if (wrong_rate := self.rate_check.add(t_s)) is not None:
            self._fail(wrong_rate)
            return
        self._flush_plates()
        for name in self.estimator.drop_silent_plates():
            self.get_logger().warning(f"no samples on {FORCE_PLATE_PREFIX}{name} while other plates stream: going on "
                                      f"without it{' (seat-off from the kinematics)' if name == 'chair' else ''}")
        try:
            out = self.estimator.update(t_s, pos, valid, defer_delayed=True)
        except MarkerUnitsError as err:
            self.get_logger().error(f"{MARKERS_TOPIC}: {err}")
            self.exit_code, self.finished = 2, True
            return
        if not out.valid:
            self.skipped += 1
        self._publish_com(msg.header, out)        # first: the retargeter waits for it
        shedding = 0 < self.shed_behind_s < self.get_clock().now().nanoseconds * 1e-9 - t_s
        if shedding:
            self.shed += 1                          # catching up: the COM only, as the stream needs it
        else:
            self.estimator.process_delayed(out)    # then the window half a window back (COPs, scaling rows)
        self._publish_rest(msg.header, out)
        if not shedding:
            self._publish_viz(msg.header, pos, out)
        self.costs.append(time.perf_counter() - t0)
        self.cpu_costs.append(time.thread_time() - c0)
        if self.fifo_after_calibration and self.estimator.calibrated:
            self._enter_real_time()
        if self.estimator.rescale_pending:     # after the frame is out: the re-solve does not delay its COM
            self.estimator.rescale_pending = False
            t0 = time.perf_counter()
            if self.estimator.rescale() is not None:
                self._publish_scaling(msg.header, time.perf_counter() - t0)

    def _enter_real_time(self) -> None:
        """Real time once the live calibration (a pause of 1-2 s that at real-time priority would starve the
        robot's loop on a small computer) is over: the estimator's frames then wait for no time-shared process."""
        wanted, self.fifo_after_calibration = Scheduling("fifo", self.fifo_after_calibration), 0
        if wanted.try_apply():
            self.get_logger().info(f"calibrated; now at {scheduling_text()}")
        else:
            self.get_logger().warning(f"calibrated; staying at {scheduling_text()}: {wanted} not permitted")

    def _publish_com(self, header, out) -> None:
        com_msg = CenterOfMass(header=_header(header.stamp, LAB_FRAME), source="skeleton_fit", valid=bool(out.valid),
                               marker_rms_m=float(out.marker_rms_m), n_markers=int(out.n_markers),
                               cop_error_m=float("nan"))
        com = out.com_m if np.all(np.isfinite(out.com_m)) else (self.last_com if self.last_com is not None else None)
        if com is not None:
            com_msg.position.x, com_msg.position.y, com_msg.position.z = map(float, com)
            if out.valid:
                self.last_com = com
                (com_msg.velocity.x, com_msg.velocity.y, com_msg.velocity.z) = map(float, out.com_vel)
                (com_msg.acceleration.x, com_msg.acceleration.y, com_msg.acceleration.z) = map(float, out.com_acc)
        com_msg.cop_error_m = self.last_cop_error      # of the latest delayed frame (~half a window back)
        self.com_pub.publish(com_msg)

    def _publish_rest(self, header, out) -> None:
        """Joint angles (of the chain below the pelvis), the pelvis pose in lab, both COPs of the delayed frame: laid
        out as bytes (:mod:`sit2stand.io.stream_messages`), not built as messages, at 100 Hz beside the fit."""
        if out.model_cop_m is not None and out.measured_cop_m is not None:
            self.last_cop_error = float(np.linalg.norm(out.model_cop_m[:2] - out.measured_cop_m[:2]))
        t_ns = stamp_ns(header)
        self.joint_pub.publish(self._joint_encoder.encode(t_ns, out.q[7:]))
        self.pelvis_pub.publish(self._lab_pose.encode(t_ns, out.q[:7]))     # Pinocchio's x y z, qx qy qz qw
        for pub, cop in ((self.model_cop_pub, out.model_cop_m), (self.measured_cop_pub, out.measured_cop_m)):
            if cop is not None and out.delayed_t_s is not None:
                self._cop_numbers[:2] = cop[:2]
                pub.publish(self._lab_point.encode(_ns_of(out.delayed_t_s), self._cop_numbers))

    def _publish_viz(self, header, markers_m: np.ndarray, out) -> None:
        """The skeleton's /tf and the human's markers every ``viz_every`` frames (~0.1 ms together)."""
        human = self.estimator.human
        if human is not self._described:          # built, or rebuilt by the calibration: new lengths
            self._described = human
            self.frames = SkeletonFrames(human)
            self.tf_encoder = TfEncoder(self.frames.pairs)
            self.description_pub.publish(String(data=human_urdf(human)))
        self._frames_seen += 1
        if not self.viz_every or (self._frames_seen - 1) % self.viz_every:
            return
        if np.all(np.isfinite(out.q)):
            self.tf_pub.publish(self.tf_encoder.encode(stamp_ns(header), *self.frames.transforms(out.q)))
        cop_stamp = _stamp_of(out.delayed_t_s) if out.delayed_t_s is not None else None
        self.viz_pub.publish(human_markers(header.stamp, markers_m, self.last_com, cop_stamp, out.measured_cop_m,
                                           out.model_cop_m))

    def _publish_scaling(self, header, solve_s: float | None = None) -> None:
        sc = self.estimator.scaling
        if sc is not None:
            names = [f"{g}.mass" for g in sc.masses] + ["torso.com_shift_x", "torso.com_shift_y"]
            values = list(sc.masses.values()) + [float(sc.torso_com_shift_m[0]), float(sc.torso_com_shift_m[1])]
            self.scaling_pub.publish(InertialParameters(header=_header(header.stamp, LAB_FRAME), model="human_scaling",
                                                        names=names,
                                                        values=[float(v) for v in values],
                                                        std_devs=[float("nan")] * len(values)))
            took = f" (solved in {solve_s * 1e3:.0f} ms)" if solve_s is not None else ""
            self.get_logger().info("scaling: " + ", ".join(f"{g} x{f:.2f}" for g, f in sc.factors().items()) + took)

    def _stats(self) -> dict[str, str]:
        c = np.array(self.costs[-2000:]) * 1e3
        gaps = self.estimator.plate_gaps if self.estimator else {}
        return {"frames": str(len(self.costs)), "skipped_frames": str(self.skipped), "shed_frames": str(self.shed),
                "cost_p50_ms": f"{np.percentile(c, 50):.3f}" if len(c) else "nan",
                "cost_p99_ms": f"{np.percentile(c, 99):.3f}" if len(c) else "nan",
                "cpu_p50_ms": f"{np.median(self.cpu_costs[-2000:]) * 1e3:.3f}" if len(c) else "nan",
                "plate_dropouts": ", ".join(f"{k}: {v} frames" for k, v in gaps.items()) or "none"}

    def _report(self) -> None:
        stats = self._stats()
        status = DiagnosticStatus(level=DiagnosticStatus.OK if stats["plate_dropouts"] == "none" else
                                  DiagnosticStatus.WARN, name=self.get_fully_qualified_name(),
                                  message=f"{stats['frames']} frames")
        status.values = [KeyValue(key=k, value=v) for k, v in stats.items()]
        self.stats_pub.publish(status)
        if stats["plate_dropouts"] != "none":
            self.get_logger().warning(f"force plate without samples for some frames: {stats['plate_dropouts']}")

    def close(self) -> None:
        if self.estimator is not None and self.estimator.rescale() is not None:   # a last solve with all rows
            header = Header(frame_id=LAB_FRAME)
            header.stamp = self.get_clock().now().to_msg()
            self._publish_scaling(header)
        stats = self._stats()
        print(f"[human_com] {stats['frames']} frames, {stats['skipped_frames']} skipped (too few markers), "
              f"{stats['shed_frames']} with the COM only (behind the clock), per-frame "
              f"cost p50 {stats['cost_p50_ms']} ms p99 {stats['cost_p99_ms']} ms (CPU p50 {stats['cpu_p50_ms']} ms); "
              f"plate dropouts: {stats['plate_dropouts']}", flush=True)


def _header(stamp, frame_id: str) -> Header:
    """A header of its own (never shared between messages)."""
    return Header(stamp=Time(sec=stamp.sec, nanosec=stamp.nanosec), frame_id=frame_id)


def _ns_of(t_s: float) -> int:
    """``t_s`` [s] in integer nanoseconds."""
    return int(round(t_s * 1e9))


def _stamp_of(t_s: float):
    """builtin_interfaces/Time of ``t_s`` [s]."""
    sec, nsec = divmod(_ns_of(t_s), 1_000_000_000)
    return Time(sec=sec, nanosec=nsec)


main = node_main(HumanComNode)

if __name__ == "__main__":
    raise SystemExit(main())
