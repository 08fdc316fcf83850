"""Motion-capture bridge node: a capture system's real-time stream onto the replayer's topics.

A thin shell around :mod:`sit2stand.capture`: a client loop (:class:`~sit2stand.capture.clients.QtmStream` through
Qualisys' ``qtm-rt``, or :class:`~sit2stand.capture.clients.NatNetStream` through ``natnet``) hands each frame to
:class:`~sit2stand.capture.convert.FrameConverter`; the node publishes, exactly as the replayer plays a bag:

* ``/mocap/markers`` (sit2stand_msgs/MocapFrame, frame ``lab``, metres, invalid markers NaN), one per frame;
* ``/force_plate/<name>`` (sit2stand_msgs/ForcePlateSample, lab axes, moment about the lab origin), one per plate
  sample (QTM: every sample, at the plate's rate); ``chair`` and ``feet`` by ``chair_plate``/``feet_plate``;
* ``~/status`` (diagnostic_msgs/DiagnosticStatus, 1 Hz): connection, frames received and lost, reconnections.

Stamps are capture times, mapped once to the ROS clock (:class:`~sit2stand.capture.convert.ClockMap`). Messages are
laid out as CDR by :mod:`sit2stand.io.stream_messages` (names fixed per connection, only numbers written) and
published from the client's thread as soon as a frame is decoded, the markers first.

Parameters:
    protocol (str, qtm)          qtm | natnet
    host (str, 127.0.0.1), port (int, 0: 22223 for QTM's little-endian port, 1510 for NatNet)
    transport (str, tcp)         tcp | udp (QTM streams frames over UDP to ``udp_port``; 0: any free port)
    version (str, 1.25)          QTM RT protocol version asked for
    chair_plate, feet_plate (int, 0, 1)  0-based plate indices (the capture system's plate id - 1; -1: none)
    forward, up (str, +X, +Z)    the capture system's signed axes that are the lab's x (forward) and z (up)
    marker_set (str, "")         a packaged marker set's name or a YAML file: publish its markers in its order
    markers (str[], [])          or these markers, in this order (default: every label the server sends)
    cop_threshold_n (float, 20)  normal force below which the COP is invalid (import-c3d's default)
    reconnect_max_s (float, 2)   longest wait between connection attempts
"""

from __future__ import annotations

import sys
import threading
import time

from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from rclpy.node import Node
from sit2stand_msgs.msg import ForcePlateSample, MocapFrame

from ..capture.clients import NatNetStream, QtmStream
from ..capture.convert import (CaptureServer, ClockMap, DropCounter, FrameConverter, ReconnectPolicy, StreamLayout,
                               plate_names, plate_stamps)
from ..human.marker_sets import load_marker_set
from ..io.c3d import LabAxes
from ..io.stream_messages import MocapFrameEncoder
from ..io.topics import LAB_FRAME, MARKERS_TOPIC, plate_topic
from .runtime import NodeError, declare, node_main
from .qos import PLATE_PUBLISH_DEPTH, qos_from_bag


class MocapBridge(Node):
    """Streams a capture system onto ``/mocap/markers`` and ``/force_plate/<name>`` (see the module docstring)."""

    def __init__(self) -> None:
        super().__init__("mocap_bridge")
        try:
            self.server = CaptureServer(declare(self, "protocol", "qtm", "qtm | natnet"),
                                        declare(self, "host", "127.0.0.1", "capture server address"),
                                        declare(self, "port", 0, "capture server port (0: the protocol's default)"),
                                        declare(self, "transport", "tcp", "tcp | udp (QTM)"),
                                        declare(self, "udp_port", 0, "local UDP port for QTM's frames (0: any)"),
                                        declare(self, "version", "1.25", "QTM RT protocol version"))
        except ValueError as err:
            raise NodeError(f"parameter {err}") from None
        self.chair = declare(self, "chair_plate", 0, "0-based index of the chair's plate (-1: none)")
        self.feet = declare(self, "feet_plate", 1, "0-based index of the feet's plate (-1: none)")
        forward = declare(self, "forward", "+X", "capture axis that is the lab's forward (x)")
        up = declare(self, "up", "+Z", "capture axis that is the lab's up (z)")
        self.marker_names = self._marker_set(declare(self, "marker_set", "", "marker set name or YAML file"),
                                             declare(self, "markers", [], "markers to publish, in order"))
        self.threshold_n = declare(self, "cop_threshold_n", 20.0, "COP valid above this normal force [N]")
        reconnect_max_s = declare(self, "reconnect_max_s", 2.0, "longest wait between connection attempts [s]")
        try:
            self.axes = LabAxes(forward.upper(), up.upper())
            self.axes.rotation()
        except ValueError as err:
            raise NodeError(f"parameters 'forward'/'up': {err}") from None
        self.qos, self.plate_qos = qos_from_bag(None), qos_from_bag(None, PLATE_PUBLISH_DEPTH)
        self.marker_pub = self.create_publisher(MocapFrame, MARKERS_TOPIC, self.qos)
        # the chair's and feet's topics exist from the start, as a replayer's do: a subscriber matched before the
        # first frame gets every sample (a reliable, volatile topic gives a late subscriber nothing it missed)
        self.plate_pubs = {name: self.create_publisher(ForcePlateSample, plate_topic(name), self.plate_qos)
                           for name, index in (("chair", self.chair), ("feet", self.feet)) if index >= 0}
        self.status_pub = self.create_publisher(DiagnosticStatus, "~/status", 10)
        self.clock, self.drops = ClockMap(), DropCounter()
        self.policy = ReconnectPolicy(max_s=reconnect_max_s)
        self.connected, self.state = False, "connecting"
        self.layout: StreamLayout | None = None       # the current connection's
        self._lock = threading.Lock()
        self._last_drop_log = 0.0
        self.stream = self._make_stream()
        self.create_timer(1.0, self._report)
        self.stream.start()

    def _marker_set(self, name: str, markers: list[str]) -> list[str] | None:
        if markers:
            return markers
        if not name:
            return None
        try:
            return load_marker_set(name).names
        except (ValueError, OSError) as err:
            raise NodeError(f"parameter 'marker_set': {err}") from None

    def _make_stream(self):
        sv = self.server
        if sv.protocol == "natnet":
            return NatNetStream(sv.host, sv.port, self._on_frame, self._on_status, policy=self.policy)
        return QtmStream(sv.host, sv.port, self._on_frame, self._on_status, transport=sv.transport,
                         udp_port=sv.udp_port, version=sv.version, policy=self.policy)

    # --- the client thread ---------------------------------------------------------------------------------------
    def _on_status(self, text: str, connected: bool) -> None:
        with self._lock:
            self.connected, self.state = connected, text
            # the next connection maps the capture clock again from its first frame: reset when the stream is lost,
            # not when a connection is announced (NatNet's first frames may be stamped by then, and a frame error
            # is reported as connected too)
            if not connected:
                self.clock.reset()
        if connected:
            self.get_logger().info(text)
        else:
            self.get_logger().error(text)

    def _layout_for(self, info) -> StreamLayout:
        if self.layout is None or info is not self.layout.info:    # a new connection: its labels and plates
            names = plate_names(info.plates, self.chair, self.feet)
            conv = FrameConverter(info.labels, info.plates, self.axes, names, self.marker_names, self.threshold_n)
            for name in names.values():
                if name not in self.plate_pubs:
                    self.plate_pubs[name] = self.create_publisher(ForcePlateSample, plate_topic(name), self.plate_qos)
            self.layout = StreamLayout(info, conv, MocapFrameEncoder(conv.marker_names, LAB_FRAME))
        return self.layout

    def _on_frame(self, frame, info) -> None:
        now_ns = self.get_clock().now().nanoseconds     # first: the clock map's offset must not hold our own work
        layout = self._layout_for(info)
        conv = layout.converter
        m = conv.markers(frame, self.clock.stamp(frame.timestamp_us * 1000, now_ns))
        self.marker_pub.publish(layout.markers.encode(m.t_ns, m.positions_m, m.valid, m.residuals_m))
        for chunk in frame.plates:
            plate = conv.plates.get(chunk.plate_id)
            if plate is None or not len(chunk.samples):
                continue
            t_ns = plate_stamps(chunk.first_sample, len(chunk.samples), plate.rate_hz, self.clock, now_ns)
            s = conv.plate(chunk.plate_id, chunk.samples, t_ns)
            pub = self.plate_pubs[s.name]
            for data in layout.plate(s.name).encode_many(t_ns, s.force_n, s.moment_origin_nm, s.cop_m, s.cop_valid,
                                            s.free_moment_nm):
                pub.publish(data)
        self._count(frame.frame_number)

    def _count(self, number: int) -> None:
        lost = self.drops.add(number)
        if lost and time.monotonic() - self._last_drop_log > 1.0:
            self._last_drop_log = time.monotonic()
            self.get_logger().warning(f"lost {lost} frame(s) before frame {number}; {self.drops.dropped} lost of "
                                      f"{self.drops.received + self.drops.dropped} so far")

    # --- the executor ---------------------------------------------------------------------------------------------
    def figures(self) -> dict[str, str]:
        d = self.drops
        return {"protocol": self.server.protocol, "server": self.server.address, "connected": str(self.connected),
                "frames": str(d.received), "frames_lost": str(d.dropped), "stream_restarts": str(d.restarts),
                "connections": str(getattr(self.stream, "connections", int(self.connected))), "state": self.state}

    def _report(self) -> None:
        level = DiagnosticStatus.OK if self.connected and not self.drops.dropped else DiagnosticStatus.WARN
        st = DiagnosticStatus(name=self.get_fully_qualified_name(),
                              hardware_id=f"{self.server.protocol}:{self.server.host}",
                              level=level, message=self.state)
        st.values = [KeyValue(key=k, value=v) for k, v in self.figures().items()]
        self.status_pub.publish(st)

    def close(self) -> None:
        self.stream.stop()
        f = self.figures()
        print(f"[mocap_bridge] {f['frames']} frames, {f['frames_lost']} lost, {f['connections']} connection(s) to "
              f"{f['protocol']} at {f['server']}", flush=True)


main = node_main(MocapBridge)

if __name__ == "__main__":
    sys.exit(main())
