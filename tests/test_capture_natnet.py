"""The NatNet encoder and ``serve-c3d --protocol natnet``, checked against OptiTrack's protocol as the ``natnet``
client package reads it: its own parsers, its own client (through the bridge's NatNetStream), and the bridge node."""

import functools
import socket
import struct
import threading
import time

import numpy as np
import pytest
from natnet import DataDescriptions, DataFrame, ServerInfo, Version
from natnet.packet_buffer import PacketBuffer

from conftest import ROOT, real_file
from sit2stand.capture import natnet_protocol as nn
from sit2stand.capture.clients import NatNetStream
from sit2stand.capture.convert import FrameConverter
from sit2stand.capture.qtm_protocol import DataFrame as CaptureFrame
from sit2stand.capture.recording import CaptureRecording
from sit2stand.capture.server import NatNetServer
from sit2stand.errors import InputError
from sit2stand.io.bag import BagReader
from sit2stand.io.c3d import LabAxes
from sit2stand.io.messages import mocap_arrays, stamp_ns

LOCAL = "127.0.0.1"
ELDERLY = ROOT / "bags" / "elderly"
MOTIVE_LAB = LabAxes("+X", "+Y")          # a z-up recording served y up: the lab frame back


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind((LOCAL, 0))
        return s.getsockname()[1]


def _read(data: bytes, parser, version=(4, 1)):
    """A message through natnet's own parser, as NatNetClient reads it (id, size, then the body)."""
    buf = PacketBuffer(data)
    kind, size = buf.read_uint16(), buf.read_uint16()
    assert size == len(data) - 4
    return kind, parser.read_from_buffer(buf, Version(*version)), buf


def _frame() -> nn.NatNetFrame:
    pos = np.array([[0.5, 1.25, -0.75], [0.0, 0.0, 0.0], [1.0, 2.0, 3.0]])
    marks = [nn.LabeledMarker(65537, (0.5, 1.25, -0.75), residual_mm=0.4), nn.LabeledMarker(65539, (1.0, 2.0, 3.0))]
    return nn.NatNetFrame(42, [("child", pos), ("chair", pos[:1])], marks, 0.41, timecode=0x01020304,
                          timecode_sub=2, stamps=(10**18, 10**18 + 5, 2**63 + 7), flags=1)


def test_server_info_reads_back_through_natnet_with_name_and_versions():
    kind, info, _ = _read(nn.server_info(), ServerInfo)
    assert kind == nn.Message.SERVERINFO
    assert info.application_name == "sit2stand serve-c3d"
    assert info.server_version == Version(3, 1, 0, 0) and info.nat_net_protocol_version == Version(4, 1, 0, 0)
    with pytest.raises(InputError, match="NatNet 2.9 is not encoded here"):
        nn.server_info(version=(2, 9))


@pytest.mark.parametrize("version", [(3, 0), (4, 0), (4, 1)])
def test_model_definitions_read_back_through_natnet_as_marker_sets(version):
    sets = [("child", ["LASI", "RASI", "C7"]), ("chair", ["SEAT"])]
    kind, desc, buf = _read(nn.model_definitions(sets, version), DataDescriptions, version)
    assert kind == nn.Message.MODELDEF and buf.pointer == len(buf.data), "every byte read"
    assert [(d.name, list(d.marker_names)) for d in desc.marker_sets] == sets
    assert not desc.rigid_bodies and not desc.skeletons and not desc.assets


@pytest.mark.parametrize("version", [(3, 0), (4, 0), (4, 1)])
def test_frames_read_back_through_natnet_with_every_field(version):
    frame = _frame()
    kind, got, buf = _read(nn.frame_of_data(frame, version), DataFrame, version)
    assert kind == nn.Message.FRAMEOFDATA and buf.pointer == len(buf.data), "every byte read"
    assert got.prefix.frame_number == 42
    assert [m.model_name for m in got.marker_sets] == ["child", "chair"]
    assert np.array_equal(np.array(got.marker_sets[0].marker_pos_list), frame.marker_sets[0][1].astype(np.float32))
    assert got.unlabeled_marker_pos == () and got.rigid_bodies == () and got.skeletons == ()
    assert got.assets == (() if version >= (4, 1) else None)
    a, b = got.labeled_markers
    assert (a.model_id, a.marker_id, b.marker_id) == (1, 1, 3) and a.pos == (0.5, 1.25, -0.75)
    assert a.point_cloud_solved and a.has_model and not a.occluded and a.residual == pytest.approx(0.4)
    assert a.size == pytest.approx(nn.MARKER_SIZE_M)
    s = got.suffix
    assert (s.timecode, s.timecode_sub, s.timestamp, s.is_recording) == (0x01020304, 2, 0.41, True)
    assert (s.stamp_camera_mid_exposure, s.stamp_data_received, s.stamp_transmit) == frame.stamps
    assert got.force_plates == () and got.devices == ()


def _frame_with_every_list() -> bytes:
    """A 4.1 frame whose lists after the marker sets are not empty: an unlabelled marker, a rigid body (id, position,
    rotation, error, flags), the frame's labelled markers."""
    sized = functools.partial(nn._sized, (4, 1, 0, 0))
    pos = np.array([[0.5, 1.25, -0.75], [1.0, 2.0, 3.0]], "<f4")
    sets = b"child\0" + struct.pack("<I", 2) + pos.tobytes() + b"chair\0" + struct.pack("<I", 1) + pos[1].tobytes()
    lists = [sized(1, struct.pack("<3f", 9.0, 8.0, 7.0)),
             sized(1, struct.pack("<I3f4ffH", 3, 1, 2, 3, 0, 0, 0, 1, 0.001, 1)), sized(0, b""), sized(0, b""),
             sized(1, struct.pack("<I3ffHf", 65537, 0.5, 1.25, -0.75, 0.014, 6, 0.4)), sized(0, b""), sized(0, b"")]
    body = struct.pack("<I", 7) + sized(2, sets) + b"".join(lists) + struct.pack("<IId3QH", 1, 2, 12.345, 0, 0, 0, 0)
    return nn.message(nn.Message.FRAMEOFDATA, body)


@pytest.mark.parametrize("packet", [nn.frame_of_data(_frame()), _frame_with_every_list()])
def test_the_quick_reader_gives_natnets_markers_and_timestamp_stepping_over_the_other_lists(packet):
    _, full, _ = _read(packet, DataFrame)
    quick = nn.read_marker_frame(packet[4:], (4, 1, 0, 0))
    assert quick.frame_number == full.prefix.frame_number and quick.timestamp_s == full.suffix.timestamp
    assert list(quick.marker_sets) == [m.model_name for m in full.marker_sets]
    for m in full.marker_sets:
        assert np.array_equal(quick.marker_sets[m.model_name], np.array(m.marker_pos_list, float))


def test_the_quick_reader_leaves_older_protocols_and_broken_frames_to_natnet():
    for version in ((3, 0, 0, 0), (4, 0, 0, 0)):
        assert nn.read_marker_frame(nn.frame_of_data(_frame(), version)[4:], version) is None
    body = nn.frame_of_data(_frame())[4:]
    assert nn.read_marker_frame(body, (4, 1)).frame_number == 42, "a version natnet truncated to (4, 1)"
    assert nn.read_marker_frame(body[:-30], (4, 1, 0, 0)) is None, "cut short"
    wrong_size = body[:8] + struct.pack("<I", 3) + body[12:]
    assert nn.read_marker_frame(wrong_size, (4, 1, 0, 0)) is None, "a marker set list whose size is not its sets'"


def test_requests_and_limits():
    assert nn.request(nn.Message.CONNECT) == b"\x00\x00\x05\x00Ping\x00", "what natnet sends"
    assert nn.parse_request(nn.request(nn.Message.REQUEST, "FrameRate")) == (nn.Message.REQUEST, "FrameRate")
    assert nn.parse_request(b"\x0a\x00\x01\x00\x00") == (nn.Message.KEEPALIVE, "")
    with pytest.raises(InputError, match="shorter than its header"):
        nn.parse_request(b"\x00")
    with pytest.raises(InputError, match="at most 65535"):
        nn.message(nn.Message.MODELDEF, bytes(70000))


def test_a_recorded_frame_is_served_in_metres_y_up_and_the_bridge_axes_give_the_lab_back():
    mm = np.array([[100.0, 200.0, 1000.0], [np.nan] * 3, [-5.0, 7.0, 0.5]])
    cf = CaptureFrame(30000, 4, mm, np.array([0.3, np.nan, 0.1]))
    f = nn.capture_frame(cf, ["A", "B", "C"], "trial", nn.Y_UP)
    name, pos = f.marker_sets[0]
    assert name == "trial" and np.allclose(pos[0], [0.1, 1.0, -0.2]), "served (x, y, z) = recorded (x, z, -y)"
    assert np.array_equal(pos[1], [0, 0, 0]), "an unseen member of the marker set is at the origin"
    assert [m.id_num & 0xFFFF for m in f.labeled_markers] == [1, 3] and f.timestamp_s == 0.03
    assert np.isclose(np.linalg.det(nn.Y_UP), 1.0)
    back = FrameConverter(["A", "B", "C"], [], MOTIVE_LAB, {}).markers(CaptureFrame(0, 4, pos * 1e3), 0)
    assert np.allclose(back.positions_m, mm * 1e-3, equal_nan=True) and list(back.valid) == [True, False, True]
    with pytest.raises(InputError, match="3 markers for 2 names"):
        nn.capture_frame(cf, ["A", "B"], "trial")


def test_the_stream_names_markers_per_set_skips_motives_all_set_and_drops_frames_before_names():
    got = []
    stream = NatNetStream(LOCAL, 1510, lambda f, i: got.append((f, i)), lambda *a: None)
    _, frame, _ = _read(nn.frame_of_data(_frame()), DataFrame)
    stream._on_frame(frame)
    assert got == [], "no names yet"
    both = nn.model_definitions([("all", ["x"] * 4), ("chair", ["SEAT"]), ("child", ["A", "B", "C"])])
    stream._on_descriptions(_read(both, DataDescriptions)[1])
    stream._on_frame(frame)
    (f, info), = got
    assert info.labels == ["chair:SEAT", "child:A", "child:B", "child:C"]
    assert f.frame_number == 42 and f.timestamp_us == 410000
    assert np.allclose(f.markers_mm, [[500, 1250, -750], [500, 1250, -750], [0, 0, 0], [1000, 2000, 3000]])
    stream._on_markers(nn.read_marker_frame(nn.frame_of_data(_frame())[4:], nn.PROTOCOL_VERSION))
    assert got[1][0].frame_number == 42 and got[1][0].timestamp_us == 410000
    assert np.array_equal(got[1][0].markers_mm, f.markers_mm), "the quick reader's frame is natnet's"


def _collect(port: int, **kw):
    frames, status, done = [], [], threading.Event()

    def on_status(text, ok):
        status.append(text)
        if "no frame for" in text:
            done.set()
    stream = NatNetStream(LOCAL, port, lambda f, i: frames.append((f, i)), on_status, **kw)
    return stream, frames, status, done


def test_the_real_natnet_client_gets_every_frame_of_a_bag_with_its_names_and_positions(run_node):
    """bags/elderly: 531 frames at 100 Hz, served at 2x by the serve-c3d command, read by NatNetStream."""
    port = free_udp_port()
    server = run_node("sit2stand.cli", "serve-c3d", str(ELDERLY), "--protocol", "natnet", "--port", str(port),
                      "--host", LOCAL, "--rate", "2", log_name="serve")
    assert server.wait_for_output("NatNet 4.1 (unicast, markers only, metres, Y up) on UDP", 20), server.output
    stream, frames, status, done = _collect(port, silence_s=0.5)
    stream.start()
    try:
        assert server.wait(30) == 0, server.output
        assert done.wait(5), status
    finally:
        stream.stop()
    assert status[0].startswith(f"connected to NatNet (unicast) at 127.0.0.1:{port}: sit2stand serve-c3d 3.1.0.0, "
                                "NatNet 4.1; 35 markers in 1 marker set(s)"), status
    assert f"NatNet (unicast) at 127.0.0.1:{port}: no frame for 0.5 s; reconnecting" in status
    with BagReader(ELDERLY) as bag:
        want = [mocap_arrays(m) for _, m in bag.read("/mocap/markers")]
    assert [f.frame_number for f, _ in frames] == list(range(1, len(want) + 1)), "every frame, in order"
    assert np.allclose([f.timestamp_us for f, _ in frames], np.arange(len(want)) * 5000, atol=1), "200 Hz"
    conv = FrameConverter(frames[0][1].labels, [], MOTIVE_LAB, {})
    for (f, _), (names, pos, valid) in zip(frames, want):
        m = conv.markers(f, 0)
        assert m.names == names and np.array_equal(m.valid, valid)
        assert np.allclose(m.positions_m, pos, atol=1e-6, equal_nan=True), "float32 on the wire"


def test_a_stream_pointed_at_no_server_names_protocol_host_and_port():
    port = free_udp_port()
    stream, frames, status, _ = _collect(port, timeout_s=0.3)
    stream.start()
    deadline = time.monotonic() + 5
    while not status and time.monotonic() < deadline:
        time.sleep(0.05)
    stream.stop()
    assert status[0] == (f"cannot connect to NatNet (unicast) at 127.0.0.1:{port}: no server info in reply to "
                         f"NAT_CONNECT within 0.3 s (is Motive streaming, unicast, with command port {port}?)")
    assert not frames


def test_the_server_answers_frame_rate_and_unknown_requests_and_forgets_a_client_that_disconnects():
    n = 20
    rec = CaptureRecording(["A"], 50.0, np.ones((n, 1, 3)), np.zeros((n, 1)), [], "x.c3d")
    srv = NatNetServer(rec, LOCAL, 0, speed=2.0, log=lambda *a, **k: None)
    thread = threading.Thread(target=srv.serve, kwargs={"exit_at_end": False}, daemon=True)
    thread.start()
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as c:
        c.settimeout(2)
        for req, want in ((nn.request(nn.Message.REQUEST, "FrameRate"), nn.message(nn.Message.RESPONSE,
                                                                                      b"\x00\x00\xc8\x42")),
                          (nn.request(nn.Message.REQUEST, "TimelinePlay"), b"\x64\x00\x00\x00")):
            c.sendto(req, (LOCAL, srv.port))
            assert c.recv(100) == want, "100 Hz as float32; then NAT_UNRECOGNIZED_REQUEST"
        c.sendto(nn.request(nn.Message.CONNECT), (LOCAL, srv.port))
        assert c.recv(1000)[:2] == b"\x01\x00"
        assert len(srv.clients) == 1
        c.sendto(nn.request(nn.Message.DISCONNECT), (LOCAL, srv.port))
        deadline = time.monotonic() + 10        # the server's thread takes the datagram: waited for, not timed
        while srv.clients and time.monotonic() < deadline:
            time.sleep(0.01)
        assert not srv.clients
    srv.stop()
    thread.join(5)


@pytest.mark.graph
def test_the_bridge_over_natnet_records_every_frame_of_a_real_c3d_with_import_c3ds_values(tmp_path, run_node,
                                                                                           sts_bag):
    """sts_child_vicon_01.c3d served y up (its lab forward -Y is served +Z): the bridge's /mocap/markers, recorded,
    equal import-c3d's frame for frame."""
    path, port, out = real_file("sts_child_vicon_01.c3d"), free_udp_port(), tmp_path / "live"
    rec = run_node("sit2stand.cli", "record", "--out", str(out), "--regex", "^/mocap/", log_name="record")
    bridge = run_node("sit2stand.nodes.mocap_bridge", "--ros-args", "-p", "protocol:=natnet", "-p", f"host:={LOCAL}",
                      "-p", f"port:={port}", "-p", "chair_plate:=-1", "-p", "feet_plate:=-1", "-p", "forward:=+Z",
                      "-p", "up:=+Y")
    assert rec.wait_for_output("subscribed to /mocap/markers", 30), rec.output
    server = run_node("sit2stand.cli", "serve-c3d", str(path), "--protocol", "natnet", "--port", str(port),
                      "--host", LOCAL, log_name="serve")
    assert server.wait(30) == 0, server.output
    assert bridge.wait_for_output(f"connected to NatNet (unicast) at 127.0.0.1:{port}", 5), bridge.output
    assert bridge.stop() == 0
    assert "[mocap_bridge] 91 frames, 0 lost, 1 connection(s) to natnet" in bridge.output, bridge.output
    assert rec.stop() == 0, rec.output
    with BagReader(out) as live, BagReader(sts_bag) as imported:
        lm, im = live.read("/mocap/markers"), imported.read("/mocap/markers")
    assert len(lm) == len(im) == 91
    t_live = np.array([stamp_ns(m.header) for _, m in lm], np.int64)
    t_imp = np.array([stamp_ns(m.header) for _, m in im], np.int64)
    assert np.allclose((t_live - t_live[0]) * 1e-9, (t_imp - t_imp[0]) * 1e-9, atol=1e-6), "capture times"
    for (_, a), (_, b) in zip(lm, im):
        names_a, pos_a, valid_a = mocap_arrays(a)
        names_b, pos_b, valid_b = mocap_arrays(b)
        assert names_a == names_b and np.array_equal(valid_a, valid_b)
        assert np.allclose(pos_a, pos_b, atol=1e-6, equal_nan=True), "float32 on the wire"
    assert a.header.frame_id == "lab"
