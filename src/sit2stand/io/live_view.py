"""A live view for Foxglove: ROS 2 topics served over WebSocket as they arrive (``foxglove_bridge`` is not on PyPI).

foxglove-sdk's server speaks Foxglove's WebSocket protocol (subprotocol ``foxglove.sdk.v1``): a client connects, gets
``serverInfo`` and an ``advertise`` of the channels, subscribes to some and then receives binary ``messageData``
frames (opcode 1, subscription id, log time [ns], payload). A channel here is one ROS topic: message encoding
``cdr`` with the serialized bytes exactly as they came over DDS, schema encoding ``ros2msg`` with the full message
definition (the type's text and each type it uses, as rosbag2's MCAP writer stores it), which is what Foxglove
decodes ROS 2 data with. So the 3D panel draws ``/tf``, ``/robot_description`` and ``MarkerArray`` topics, and the
plots read any field, with no conversion here.

A client fetches the robot's meshes through the connection (the protocol's ``fetchAsset``, the server's
``assets`` capability): the URIs of ``/robot_description`` are the ``package://`` ones a client asks for.

Latched topics (transient local: ``/tf_static``, the descriptions, the subject) have no counterpart in the protocol:
a client that subscribes later is sent the last message again (:meth:`LiveView.relatch`).
"""

from __future__ import annotations

import threading
from collections.abc import Callable

import foxglove
import foxglove.layouts as fl

from .topics import (HUMAN_COM_TOPIC, HUMAN_DESCRIPTION_TOPIC, HUMAN_MEASURED_COP_TOPIC, LAB_FRAME, ROBOT_COP_TOPIC,
                     ROBOT_DESCRIPTION_TOPIC, ROBOT_PLANNED_COM_TOPIC, ROBOT_PLANNED_ZMP_TOPIC)
from .typestore import typestore

ROS2_SCHEMA_ENCODING = "ros2msg"
CDR_ENCODING = "cdr"
SUBPROTOCOL = "foxglove.sdk.v1"


def ros2msg_schema(msgtype: str) -> foxglove.Schema:
    """The ``ros2msg`` schema of ``pkg/msg/Type``: its definition followed by those of the types it uses."""
    text, _ = typestore().generate_msgdef(msgtype, ros_version=2)
    return foxglove.Schema(name=msgtype, encoding=ROS2_SCHEMA_ENCODING, data=text.encode())


class _Subscriptions(foxglove.ServerListener):
    """Notes the latched topics a client subscribed to (called on the server's thread: only a note is taken)."""

    def __init__(self, view: LiveView) -> None:
        self.view = view

    def on_subscribe(self, client, channel) -> None:
        with self.view._lock:
            self.view._to_relatch.add(channel.topic)
            self.view._subscribed.add(channel.topic)


class LiveView:
    """A Foxglove WebSocket server on ``host``:``port`` (0: any free port, see :attr:`port`) for ROS topics;
    ``asset_handler``: the bytes of a URI a client fetches (a URDF's meshes), or None."""

    def __init__(self, host: str = "127.0.0.1", port: int = 8765, name: str = "sit2stand",
                 asset_handler: Callable[[str], bytes | None] | None = None) -> None:
        self._lock = threading.Lock()
        self._to_relatch: set[str] = set()
        self._subscribed: set[str] = set()                    # topics some client has subscribed to
        self._channels: dict[str, foxglove.Channel] = {}
        self._latched: dict[str, tuple[bytes, int]] = {}      # topic -> (last message, its log time [ns])
        self.context = foxglove.Context()
        self.server = foxglove.start_server(name=name, host=host, port=port, context=self.context,
                                            server_listener=_Subscriptions(self), asset_handler=asset_handler)

    @property
    def port(self) -> int:
        return self.server.port

    @property
    def topics(self) -> list[str]:
        return sorted(self._channels)

    def add_topic(self, topic: str, msgtype: str, latched: bool = False) -> None:
        """Advertise ``topic`` of ``msgtype`` (``pkg/msg/Type``); ``latched``: resend its last message to late
        subscribers."""
        self._channels[topic] = foxglove.Channel(topic, schema=ros2msg_schema(msgtype), message_encoding=CDR_ENCODING,
                                                 context=self.context)
        if latched:
            self._latched.setdefault(topic, (b"", 0))

    def log(self, topic: str, data: bytes, log_time_ns: int) -> None:
        """Send ``data`` (serialized CDR) on ``topic`` to its subscribers, logged at ``log_time_ns``."""
        self._channels[topic].log(bytes(data), log_time=int(log_time_ns))
        if topic in self._latched:
            self._latched[topic] = (bytes(data), int(log_time_ns))

    def subscribed(self, topic: str) -> bool:
        """Whether a client has subscribed to ``topic`` (messages logged before that reach no one)."""
        with self._lock:
            return topic in self._subscribed

    def relatch(self) -> int:
        """Resend the last message of each latched topic a client subscribed to since the last call; how many."""
        with self._lock:
            topics, self._to_relatch = self._to_relatch, set()
        sent = 0
        for topic in topics:
            data, t_ns = self._latched.get(topic, (b"", 0))
            if data:
                self._channels[topic].log(data, log_time=t_ns)
                sent += 1
        return sent

    def close(self) -> None:
        self.server.stop()


def _plot(title: str, series: list[tuple[str, str]], ylabel: str) -> fl.PlotPanel:
    """A time plot of ``(label, FoxQL path)`` series, ordered by header stamp (the demonstration's time)."""
    return fl.PlotPanel(title=title, config=fl.PlotConfig(
        paths=[fl.PlotSeries(value=path, label=label, timestamp_method="headerStamp") for label, path in series],
        y_axis_label=ylabel))


def standup_layout() -> str:
    """Foxglove layout JSON of a stand-up (``sit2stand/data/layouts/standup.json`` is this): the robot (URDF from
    /robot_description) and the human (/human/robot_description), both under /tf, with the plan's and the human's
    markers in 3D, fixed in ``lab``; beside it the paper's Fig. 6: the robot's planned COM against the human's (x
    and z), and the robot's COP against the planned ZMP."""
    urdf = {name: fl.BaseRendererUrdfLayerSettings(label=name, source_type="topic", topic=topic)
            for name, topic in (("robot", ROBOT_DESCRIPTION_TOPIC), ("human", HUMAN_DESCRIPTION_TOPIC))}
    three_d = fl.ThreeDeePanel(title="robot and human", config=fl.ThreeDeeConfig(
        follow_tf=LAB_FRAME, fixed_frame=LAB_FRAME, layers={"grid": fl.BaseRendererGridLayerSettings(), **urdf}))
    plots = [
        _plot("COM x (Fig. 6)", [("human", f"{HUMAN_COM_TOPIC}.position.x"),
                                 ("robot (plan)", f"{ROBOT_PLANNED_COM_TOPIC}.position.x")], "x [m]"),
        _plot("COM z (Fig. 6)", [("human", f"{HUMAN_COM_TOPIC}.position.z"),
                                 ("robot (plan)", f"{ROBOT_PLANNED_COM_TOPIC}.position.z")], "z [m]"),
        _plot("COP x", [("robot COP", f"{ROBOT_COP_TOPIC}.point.x"),
                        ("planned ZMP", f"{ROBOT_PLANNED_ZMP_TOPIC}.point.x"),
                        ("human COP", f"{HUMAN_MEASURED_COP_TOPIC}.point.x")], "x [m]"),
    ]
    column = fl.SplitContainer(direction="column", items=[fl.SplitItem(content=p) for p in plots])
    layout = fl.Layout(content=fl.SplitContainer(direction="row", items=[
        fl.SplitItem(proportion=3, content=three_d), fl.SplitItem(proportion=2, content=column)]))
    return layout.to_json()
