"""The live view: a real WebSocket client (the `websockets` package) does Foxglove's handshake (subprotocol
foxglove.sdk.v1), reads the advertised channels, subscribes and receives messages; from io/live_view.py directly,
then from the foxglove node serving a replayed run. The shipped layout is what standup_layout() makes."""

import json
import re
import struct
import time
from pathlib import Path

import numpy as np
import pytest
from websockets.sync.client import connect

from sit2stand.data import folder
from sit2stand.io.live_view import SUBPROTOCOL, LiveView, standup_layout
from sit2stand.io.typestore import typestore
from sit2stand.robot.packages import package_asset

ROOT = Path(__file__).resolve().parents[1]
MESSAGE_DATA = 0x01          # Foxglove WebSocket protocol: binary opcode of a message


class Client:
    """A Foxglove WebSocket client: handshake, channels by topic, subscriptions, message frames."""

    def __init__(self, port: int) -> None:
        # no keepalive pings: a flood of plate samples would queue their pongs behind it
        self._connection = connect(f"ws://127.0.0.1:{port}", subprotocols=[SUBPROTOCOL], open_timeout=10,
                                   ping_interval=None, max_queue=None, max_size=None)   # meshes: MBs
        self.ws = self._connection.__enter__()
        self.channels: dict[str, dict] = {}
        self.server_info = json.loads(self.ws.recv(timeout=10))

    def wait_for_channels(self, topics: set[str], timeout_s: float = 20.0) -> None:
        """Read advertise operations until every one of ``topics`` has a channel."""
        while not topics <= set(self.channels):
            op = json.loads(self.ws.recv(timeout=timeout_s))
            if op["op"] == "advertise":
                self.channels.update({c["topic"]: c for c in op["channels"]})

    def subscribe(self, topics: list[str]) -> dict[int, str]:
        subs = {i: t for i, t in enumerate(topics, start=1)}
        self.ws.send(json.dumps({"op": "subscribe", "subscriptions": [
            {"id": i, "channelId": self.channels[t]["id"]} for i, t in subs.items()]}))
        return subs

    def messages(self, subs: dict[int, str], count: int, timeout_s: float = 20.0, each: bool = False):
        """``count`` (topic, log time [ns], payload) of the subscriptions ``subs`` (``each``: ``count`` of every
        subscription; a fast topic would otherwise fill the count alone); other frames skipped."""
        out = []
        deadline = time.monotonic() + timeout_s
        while (min((sum(t == topic for t, _, _ in out) for topic in subs.values()), default=0) < count if each
               else len(out) < count):
            if time.monotonic() > deadline:
                raise TimeoutError(f"{len(out)} messages in {timeout_s} s: {sorted({t for t, _, _ in out})}")
            frame = self.ws.recv(timeout=timeout_s)
            if isinstance(frame, bytes) and frame[0] == MESSAGE_DATA:
                sub_id, log_ns = struct.unpack_from("<IQ", frame, 1)
                out.append((subs[sub_id], log_ns, frame[13:]))
        return out

    def close(self) -> None:
        self._connection.__exit__(None, None, None)


def _subject(height_m: float) -> bytes:
    store = typestore()
    Subject, Header, Time = (store.types[t] for t in ("sit2stand_msgs/msg/Subject", "std_msgs/msg/Header",
                                                      "builtin_interfaces/msg/Time"))
    msg = Subject(header=Header(stamp=Time(sec=3, nanosec=0), frame_id=""), height_m=height_m, mass_kg=61.0,
                  sex="female", age_years=float("nan"))
    return bytes(store.serialize_cdr(msg, "sit2stand_msgs/msg/Subject"))


def test_a_client_does_the_handshake_and_receives_cdr_as_logged():
    view = LiveView(port=0)
    try:
        view.add_topic("/human/subject", "sit2stand_msgs/msg/Subject", latched=True)
        client = Client(view.port)
        assert client.ws.subprotocol == SUBPROTOCOL and client.server_info["op"] == "serverInfo"
        client.wait_for_channels({"/human/subject"})
        channel = client.channels["/human/subject"]
        assert (channel["encoding"], channel["schemaEncoding"], channel["schemaName"]) == \
            ("cdr", "ros2msg", "sit2stand_msgs/msg/Subject")
        assert channel["schema"].startswith("std_msgs/Header header\nfloat64 height_m") and "MSG: std_msgs/Header" \
            in channel["schema"]
        subs = client.subscribe(["/human/subject"])
        deadline = time.monotonic() + 20.0       # the server notes the subscription on its own thread
        while not view.subscribed("/human/subject") and time.monotonic() < deadline:
            time.sleep(0.02)
        assert view.relatch() == 0          # nothing logged yet: nothing resent
        data = _subject(1.62)
        view.log("/human/subject", data, 7_000_000_000)
        [(topic, log_ns, payload)] = client.messages(subs, 1)
        assert (topic, log_ns, payload) == ("/human/subject", 7_000_000_000, data)
        msg = typestore().deserialize_cdr(payload, "sit2stand_msgs/msg/Subject")
        assert (msg.height_m, msg.mass_kg, msg.sex) == (1.62, 61.0, "female")
        client.close()
        late = Client(view.port)            # latched: a client that subscribes later gets the last message
        late.wait_for_channels({"/human/subject"})
        subs = late.subscribe(["/human/subject"])
        deadline = time.monotonic() + 20.0       # the server notes the subscription on its own thread
        while not view.relatch() and time.monotonic() < deadline:
            time.sleep(0.02)
        [(_, log_ns, payload)] = late.messages(subs, 1)
        assert (log_ns, payload) == (7_000_000_000, data)
        late.close()
    finally:
        view.close()


def _wait_until_served(fox, topics: list[str], timeout_s: float = 30.0) -> None:
    """Until the node has logged each topic as served: the SDK advertises a channel to clients a moment before its
    server accepts subscriptions to it ("attempted to subscribe to unknown channel"), and a subscription refused
    that way is never retried."""
    for topic in topics:
        assert fox.wait_for_output(f"serving {topic} (", timeout_s), fox.output


@pytest.mark.graph
def test_the_foxglove_node_serves_a_replayed_run(run_node):
    """The foxglove node (port 0) and a replayer of bags/natural: the client gets the run's markers as MocapFrames
    (their log times the replayer's /clock: bag time) and the plates."""
    fox = run_node("sit2stand.nodes.foxglove", "--ros-args", "-p", "port:=0", "-p", "use_sim_time:=true")
    assert fox.wait_for_output("WebSocket server on", 30), fox.output
    port = int(re.search(r"ws://127\.0\.0\.1:(\d+)", fox.output).group(1))
    client = Client(port)
    play = run_node("sit2stand.nodes.replayer", "--ros-args", "-p", f"bag:={ROOT / 'bags' / 'natural'}",
                    "-p", "topics:=['/mocap/markers', '/force_plate/feet']", "-p", "wait_for_subscribers:=1",
                    "-p", "loop:=true")     # still playing whenever the client's subscription takes effect
    try:
        client.wait_for_channels({"/mocap/markers", "/force_plate/feet"}, 30)
        _wait_until_served(fox, ["/mocap/markers", "/force_plate/feet"])
        subs = client.subscribe(["/mocap/markers", "/force_plate/feet"])
        got = client.messages(subs, 20, 30, each=True)
    except TimeoutError as err:
        raise AssertionError(f"{err}\n--- foxglove node:\n{fox.output}\n--- replayer:\n{play.output}") from None
    finally:
        client.close()
    topics = {t for t, _, _ in got}
    assert topics == {"/mocap/markers", "/force_plate/feet"}
    frames = [typestore().deserialize_cdr(p, "sit2stand_msgs/msg/MocapFrame") for t, _, p in got
              if t == "/mocap/markers"]
    assert frames and "LASI" in frames[0].marker_names and frames[0].header.frame_id == "lab"
    stamps = np.array([f.header.stamp.sec + f.header.stamp.nanosec * 1e-9 for f in frames])
    logs = np.array([log for t, log, _ in got if t == "/mocap/markers"]) * 1e-9
    assert np.all(np.abs(logs - stamps) < 0.5), "log times are the replay's /clock, the stamps' time base"
    assert play.stop() == 0 and fox.stop() == 0
    assert "[foxglove] served" in fox.output


def test_the_shipped_layout_is_the_stand_up_layout():
    shipped = json.loads((folder("layouts") / "standup.json").read_text())
    assert shipped == json.loads(standup_layout())
    text = json.dumps(shipped)
    for needed in ('"/robot_description"', '"/human/robot_description"', "ThreeDee", "/human/com.position.z",
                   "/robot/planned_com.position.z"):
        assert needed in text


FETCH_ASSET_RESPONSE = 0x04  # Foxglove WebSocket protocol: binary opcode of a fetched asset


def _fetch_asset(client: Client, uri: str, request_id: int = 7, timeout_s: float = 20.0) -> tuple[int, bytes]:
    """A fetchAsset request, answered as (status: 0 found, 1 error, the asset's bytes or the error text)."""
    client.ws.send(json.dumps({"op": "fetchAsset", "uri": uri, "requestId": request_id}))
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        frame = client.ws.recv(timeout=timeout_s)
        if isinstance(frame, bytes) and frame[0] == FETCH_ASSET_RESPONSE:
            rid, status, n = struct.unpack_from("<IBI", frame, 1)
            if rid == request_id:
                return status, frame[10 + n:] if status == 0 else frame[10:10 + n]
    raise TimeoutError(f"no answer to fetchAsset {uri}")


@pytest.mark.graph
def test_a_client_gets_the_robots_tf_description_markers_and_meshes_from_the_node(run_node):
    """The driver (TALOS seated), a replayer of bags/natural's markers and the foxglove node: a real client receives
    /tf, /robot_description (its meshes as package:// URIs, which a browser asks the server for) and the markers,
    then fetches a mesh through the connection and gets the file's bytes."""
    fox = run_node("sit2stand.nodes.foxglove", "--ros-args", "-p", "port:=0")
    assert fox.wait_for_output("WebSocket server on", 30), fox.output
    port = int(re.search(r"ws://127\.0\.0\.1:(\d+)", fox.output).group(1))
    client = Client(port)
    driver = run_node("sit2stand.nodes.driver")
    play = run_node("sit2stand.nodes.replayer", "--ros-args", "-p", f"bag:={ROOT / 'bags' / 'natural'}",
                    "-p", "topics:=['/mocap/markers']", "-p", "loop:=true")
    wanted = ["/tf", "/robot_description", "/mocap/markers"]
    try:
        assert "assets" in client.server_info["capabilities"]
        client.wait_for_channels(set(wanted), 60)
        _wait_until_served(fox, wanted)
        got = client.messages(client.subscribe(wanted), 1, 60, each=True)
        [desc] = [typestore().deserialize_cdr(p, "std_msgs/msg/String").data for t, _, p in got
                  if t == "/robot_description"][:1]
        uris = re.findall(r'<mesh filename="([^"]+)"', desc)
        assert uris and all(u.startswith("package://example-robot-data/") for u in uris), uris[:3]
        status, mesh = _fetch_asset(client, uris[0])
        assert status == 0 and mesh == package_asset(uris[0]) and len(mesh) > 84
        status, error = _fetch_asset(client, "file:///etc/passwd", request_id=8)
        assert status == 1, "only the packages' meshes are served"
    except TimeoutError as err:
        raise AssertionError(f"{err}\n--- foxglove node:\n{fox.output}\n--- driver:\n{driver.output}") from None
    finally:
        client.close()
    tf = [typestore().deserialize_cdr(p, "tf2_msgs/msg/TFMessage") for t, _, p in got if t == "/tf"]
    assert {tr.child_frame_id for tr in tf[0].transforms} >= {"base_link", "leg_left_4_link"}
    assert any(t == "/mocap/markers" for t, _, _ in got)
    assert play.stop() == 0 and driver.stop() == 0 and fox.stop() == 0
