"""Human COM estimator node: markers + force plates in, the human centre of mass out, per frame.

Markers and every ``/force_plate/*`` in; per marker frame the COM out first (the retargeter waits for it), then the
skeleton's joint angles and pelvis pose, the delayed frame's COPs, the mass scaling when re-solved, and /tf and
markers for the viewers (:mod:`sit2stand.nodes.human_outputs`). The estimator is
:class:`sit2stand.human.com_stream.StreamingComEstimator`; what the node keeps between callbacks (frames waiting for
the subject, plate samples, shedding, costs) is :mod:`sit2stand.human.com_feed`. Stamps are the marker frame's.
Topics and parameters: ``docs/nodes.md`` (human_com).
"""

from __future__ import annotations

import dataclasses
import time

from rclpy.node import Node
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from sit2stand_msgs.msg import ForcePlateSample, MocapFrame
from sit2stand_msgs.msg import Subject as SubjectMsg

from .. import native
from ..human.calibration import StreamCalibration
from ..human.com import WINDOW_S
from ..human.com_feed import SUBJECT_WAIT_FRAMES, FrameCosts, PlateInbox, SubjectWait, shed
from ..human.com_stream import RESCALE_EVERY_S, StreamingComEstimator
from ..human.marker_ik import MarkerUnitsError, TooFewMarkers
from ..human.marker_sets import MarkerSetError, choose_marker_set
from ..human.skeleton import Subject
from ..io.messages import plate_sample_from_cdr, reorder_markers
from ..io.stream_messages import MocapFrameReader
from ..scheduling import Scheduling
from ..io.topics import FORCE_PLATE_PREFIX, MARKERS_TOPIC, SUBJECT_TOPIC, bag_name, ros_name
from .human_outputs import HumanOutputs
from .runtime import IdleDrain, NodeError, declare, marker_rate_check, node_main, scheduling_text, steady_timer
from .qos import LATCHED_QOS


class HumanComNode(Node):
    """Streams the human COM (see the module docstring)."""

    executor_kind = "events"  # publishes only from its own callbacks: the fast executor is safe here
    drain_timeout_s = 30.0    # after a signal, what already arrived is processed: a backlog can take seconds

    def __init__(self) -> None:
        super().__init__("human_com")
        height, mass = declare(self, "height_m", 0.0, "stature [m] (0: from /human/subject)"), \
            declare(self, "mass_kg", 0.0, "body mass [kg] (0: from /human/subject)")
        self.sex = declare(self, "sex", "male", "male | female")
        self.marker_set = declare(self, "marker_set", "", "marker set: a packaged set's name or a YAML file (empty: "
                                  "the packaged set that covers most of the stream's marker names)")
        self.subject = Subject(height, mass, self.sex) if height > 0 and mass > 0 else None
        self.waiting = SubjectWait()
        if self.subject is None:
            self.create_subscription(SubjectMsg, ros_name(SUBJECT_TOPIC), self._on_subject, LATCHED_QOS)
        rate_hz = declare(self, "rate_hz", 100.0, "marker rate [Hz]")
        self.rate_check = marker_rate_check(rate_hz)
        # the estimator's settings, for when the stream's marker names are known
        self.settings = {"rate_hz": rate_hz, "window_s": declare(self, "window_s", WINDOW_S, "Savitzky-Golay window"),
                         "calibration_frames": declare(self, "calibration_frames", 50, "frames used to calibrate"),
                         "rescale_every_s": declare(self, "rescale_every_s", RESCALE_EVERY_S, "re-solve the masses "
                                                    "every this much time [s] of frames with plates"),
                         "chair_on_plate": declare(self, "chair_on_plate", True, "the chair stands on a force plate")}
        if not self.settings["rescale_every_s"] > 0:
            raise NodeError(f"human_com: parameter rescale_every_s is {self.settings['rescale_every_s']!r}; give the "
                            "time [s] between two mass scalings (> 0)")
        self.expected_plates = declare(self, "plates", [], "plate names to expect (default: whatever appears)")
        self.fifo_after_calibration = declare(self, "fifo_after_calibration", 0, "once calibrated, run at this "
                                              "SCHED_FIFO priority (0: stay as started)")
        cal_file = declare(self, "calibration_file", "", "skeleton calibration YAML made beforehand (sit2stand "
                           "human-calibrate); empty: calibrate on the first frames")
        self.shed_behind_s = declare(self, "shed_behind_s", 0.0, "a frame this far behind the clock [s] gets its "
                                     "COM only: no COPs, scaling rows nor /tf (0: never)")
        native.kernels()     # the skeleton fit's compiled kernels now (built on a machine's first run: ~1.8 s)
        self.calibration = None
        if cal_file:
            try:
                self.calibration = StreamCalibration.load(cal_file)
                if self.subject is not None:
                    self.calibration.build(self.subject)      # the subject it was made for
            except ValueError as err:
                raise NodeError(f"calibration_file: {err}") from None
        deep = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=2000, reliability=ReliabilityPolicy.RELIABLE)
        self.marker_reader = MocapFrameReader()        # raw: read straight from the CDR bytes (see _on_markers)
        self.create_subscription(MocapFrame, ros_name(MARKERS_TOPIC), self._on_markers, deep, raw=True)
        viz_hz = declare(self, "viz_rate_hz", 50.0, "/tf and /viz/human rate [Hz] of marker time (0: none)")
        self.out = HumanOutputs(self, max(1, int(round(rate_hz / viz_hz))) if viz_hz > 0 else 0)
        self.plate_subs: dict[str, object] = {}
        self.plates = PlateInbox()
        self.estimator: StreamingComEstimator | None = None
        self.costs = FrameCosts()
        self.rescaling, self.rescale_s = None, 0.0     # a mass re-solve under way (a piece per frame), its time [s]
        self.finished = False
        self.exit_code = 0
        self.drain = IdleDrain(lambda: len(self.costs.wall_s))   # after a signal, finish the frames received
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
        # the message); they go to the estimator in one array per plate at the next marker frame
        self.plates.add(name, plate_sample_from_cdr(data))

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
        self.waiting.release(self._on_markers)

    def _fail(self, text: str) -> None:
        self.get_logger().error(text)
        self.exit_code, self.finished = 2, True

    def _start(self, names: list[str]) -> bool:
        """The estimator for the stream's marker names and the subject (False: the node stops, saying why)."""
        try:
            markers = choose_marker_set(names, self.marker_set or None)
            self.subject = dataclasses.replace(self.subject, marker_set=markers)
            self.estimator = StreamingComEstimator(
                self.subject, names, **self.settings, calibration=self.calibration, defer_rescale=True)
        except (TooFewMarkers, MarkerSetError) as err:
            self._fail(f"{MARKERS_TOPIC}: {err}")
            return False
        except ValueError as err:         # a calibration_file made for another subject
            self._fail(f"calibration_file: {err}")
            return False
        for name in self.expected_plates:
            self.estimator.expect_plate(name)
        self.names = names
        self.out.joints(self.estimator.human.joint_names())
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

    def _on_markers(self, data: bytes) -> None:
        # the frame's arrays straight from its CDR bytes: ~5 us against ~95 us for the rclpy message and its arrays,
        # at the head of the capture -> joint command path
        if self.finished:
            return
        if self.subject is None:
            if not self.waiting.hold(data):
                self._fail(f"no {SUBJECT_TOPIC} after {SUBJECT_WAIT_FRAMES} marker frames and no height_m/mass_kg "
                           f"parameters: give them")
            return
        t0, c0 = time.perf_counter(), time.thread_time()
        try:
            t_ns, names, pos, valid = self.marker_reader.read(data)
        except ValueError as err:
            self._fail(f"{MARKERS_TOPIC}: a frame that cannot be read ({err})")
            return
        if self.estimator is None and not self._start(list(names)):
            return
        if not self._stream_checked:
            self._check_stream(names)
        pos, valid = reorder_markers(names, pos, valid, self.names)
        t_s = t_ns * 1e-9
        if (wrong_rate := self.rate_check.add(t_s)) is not None:
            self._fail(wrong_rate)
            return
        try:
            out = self.estimator.update(t_s, pos, valid, defer_delayed=True)
        except MarkerUnitsError as err:
            self.get_logger().error(f"{MARKERS_TOPIC}: {err}")
            self.exit_code, self.finished = 2, True
            return
        self.costs.skipped += not out.valid
        self.out.com(t_ns, out)        # first: the retargeter waits for it; the fit and the COM use no plate
        self.plates.flush(self.estimator)
        for name in self.estimator.drop_silent_plates():
            self.get_logger().warning(f"no samples on {FORCE_PLATE_PREFIX}{name} while other plates stream: going on "
                                      f"without it{' (seat-off from the kinematics)' if name == 'chair' else ''}")
        shedding = shed(self.shed_behind_s, self.get_clock().now().nanoseconds * 1e-9, t_s)
        if shedding:
            self.costs.shed += 1                    # catching up: the COM only, as the stream needs it
        else:
            self.estimator.process_delayed(out)    # then the window half a window back (COPs, scaling rows)
        self.out.rest(t_ns, out)
        if not shedding:
            self.out.viz(t_ns, self.estimator.human, pos, out)
        self.costs.wall_s.append(time.perf_counter() - t0)
        self.costs.cpu_s.append(time.thread_time() - c0)
        if self.fifo_after_calibration and self.estimator.calibrated:
            self._enter_real_time()
        if self.estimator.rows.pending:     # after the frame is out: the re-solve does not delay its COM
            self.estimator.rows.pending = False
            self.rescaling, self.rescale_s = self.estimator.rescale_in_steps(), 0.0
        if self.rescaling is not None:
            self._rescale_piece(t_ns)

    def _rescale_piece(self, t_ns: int) -> None:
        """One piece of a due mass re-solve, a piece after each frame: whole, it held up the next frames."""
        t0 = time.perf_counter()
        piece = next(self.rescaling, False)
        self.rescale_s += time.perf_counter() - t0
        if piece is not None:       # the scaling (published), or False: too few rows
            self.rescaling = None
            if piece is not False:
                self._publish_scaling(t_ns, self.rescale_s)

    def _enter_real_time(self) -> None:
        """Real time once the live calibration (a pause of 1-2 s that at real-time priority would starve the
        robot's loop on a small computer) is over: the estimator's frames then wait for no time-shared process."""
        wanted, self.fifo_after_calibration = Scheduling("fifo", self.fifo_after_calibration), 0
        if wanted.try_apply_to_process():
            self.get_logger().info(f"calibrated; now at {scheduling_text()}")
        else:
            self.get_logger().warning(f"calibrated; staying at {scheduling_text()}: {wanted} not permitted")

    def _publish_scaling(self, t_ns: int, solve_s: float | None = None) -> None:
        sc = self.estimator.scaling
        if sc is not None:
            self.out.scaling(t_ns, sc)
            took = f" (solved in {solve_s * 1e3:.0f} ms)" if solve_s is not None else ""
            self.get_logger().info("scaling: " + ", ".join(f"{g} x{f:.2f}" for g, f in sc.factors().items()) + took)

    def _stats(self) -> dict[str, str]:
        return self.costs.figures(self.estimator.plate_gaps if self.estimator else {})

    def _report(self) -> None:
        stats = self._stats()
        self.out.stats(stats)
        if stats["plate_dropouts"] != "none":
            self.get_logger().warning(f"force plate without samples for some frames: {stats['plate_dropouts']}")

    def close(self) -> None:
        if self.estimator is not None and self.estimator.rescale() is not None:   # a last solve with all rows
            self._publish_scaling(self.get_clock().now().nanoseconds)
        stats = self._stats()
        print(f"[human_com] {stats['frames']} frames, {stats['skipped_frames']} skipped (too few markers), "
              f"{stats['shed_frames']} with the COM only (behind the clock), per-frame "
              f"cost p50 {stats['cost_p50_ms']} ms p99 {stats['cost_p99_ms']} ms (CPU p50 {stats['cpu_p50_ms']} ms); "
              f"plate dropouts: {stats['plate_dropouts']}", flush=True)


main = node_main(HumanComNode)

if __name__ == "__main__":
    raise SystemExit(main())
