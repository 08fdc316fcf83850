"""The QTM RT protocol codec and the serve-c3d server, checked against Qualisys' own client library (qtm-rt)."""

import asyncio
import socket
import struct
import threading

import numpy as np
import pytest
import qtm_rt
from qtm_rt.packet import QRTComponentType, QRTPacket

from sit2stand.capture.clients import frame_from_qtm_packet
from sit2stand.capture.qtm_protocol import (MISSING, Component, DataFrame, PacketType, PlateChunk, PlateInfo,
                                            ProtocolError, data_packet, decode_data, packet, parameters_xml,
                                            parse_frequency, parse_labels, parse_plates, parse_stream_frames,
                                            split_packets, string_packet)
from sit2stand.capture.recording import CaptureRecording, RecordedPlate
from sit2stand.capture.server import QtmServer


def _frame() -> DataFrame:
    markers = np.array([[1.5, -2.25, 1000.0], [np.nan, np.nan, np.nan], [3.0, 4.0, 5.0]])
    samples = np.arange(18, dtype=float).reshape(2, 9)
    return DataFrame(123456, 42, markers, np.array([0.5, np.nan, 0.25]), [PlateChunk(3, 840, samples)])


def test_a_packet_is_its_size_and_type_then_the_body_and_strings_end_with_nul():
    data = string_packet(PacketType.COMMAND, "Version set to 1.25")
    assert struct.unpack("<II", data[:8]) == (8 + 20, 1) and data.endswith(b"\0")
    assert packet(PacketType.NO_MORE_DATA) == struct.pack("<II", 8, 4)


def test_packets_are_split_from_a_tcp_stream_in_any_chunking():
    stream = string_packet(PacketType.XML, "<a/>") + packet(PacketType.NO_MORE_DATA) + data_packet(_frame(),
                                                                                                    [Component.FORCE])
    got, rest = [], b""
    for k in range(0, len(stream), 7):
        out, rest = split_packets(rest + stream[k:k + 7])
        got += out
    assert [kind for kind, _ in got] == [PacketType.XML, PacketType.NO_MORE_DATA, PacketType.DATA] and rest == b""
    with pytest.raises(ProtocolError, match="smaller than its 8-byte header"):
        split_packets(struct.pack("<II", 4, 1))
    with pytest.raises(ProtocolError, match="unknown packet type 77"):
        split_packets(struct.pack("<II", 8, 77))


def test_data_packets_read_back_through_qtm_rt_with_labels_residuals_and_every_force_sample():
    frame = _frame()
    data = data_packet(frame, [Component.THREE_D_RES, Component.FORCE, Component.THREE_D_NO_LABELS])
    p = QRTPacket(data[8:])
    assert (p.timestamp, p.framenumber) == (123456, 42)
    info, markers = p.get_3d_markers_residual()
    assert info.marker_count == 3 and markers[0].x == 1.5 and markers[2].residual == 0.25
    assert struct.pack("<f", markers[1].x) == b"\xff\xff\xff\xff", "a missing marker has all bits set"
    _, plates = p.get_force()
    plate, samples = plates[0]
    assert (plate.id, plate.force_count, plate.force_number) == (3, 2, 840) and samples[1].z_a == 17.0
    _, unlabelled = p.get_3d_markers_no_label()
    assert [m.id for m in unlabelled] == [1, 3], "no labels: only the seen markers, with an id"
    single = QRTPacket(data_packet(frame, [Component.FORCE_SINGLE, Component.THREE_D])[8:])
    assert single.get_force_single()[1][0][1].x == 9.0 and QRTComponentType.Component3d in single.components
    back = decode_data(data[8:])
    assert np.array_equal(back.markers_mm, frame.markers_mm, equal_nan=True)
    assert np.array_equal(back.plates[0].samples, frame.plates[0].samples) and back.plates[0].first_sample == 840
    assert np.isnan(MISSING)


def test_the_bridge_reads_a_packet_as_qtm_rt_does():
    frame = _frame()
    p = QRTPacket(data_packet(frame, [Component.THREE_D_RES, Component.FORCE, Component.THREE_D_NO_LABELS])[8:])
    got = frame_from_qtm_packet(p)
    assert (got.timestamp_us, got.frame_number) == (p.timestamp, p.framenumber)
    rows = np.array([tuple(m) for m in p.get_3d_markers_residual()[1]], float)
    assert np.array_equal(got.markers_mm, rows[:, :3], equal_nan=True)
    assert np.array_equal(got.residuals_mm, rows[:, 3], equal_nan=True)
    ((plate, samples),) = p.get_force()[1]
    (chunk,) = got.plates
    assert (chunk.plate_id, chunk.first_sample) == (plate.id, plate.force_number)
    assert np.array_equal(chunk.samples, np.array([tuple(s) for s in samples], float))


def test_parameters_carry_labels_plate_corners_and_the_frequency():
    corners = np.array([[0, 0, 0], [600.0, 0, 0], [600, 400, 0], [0, 400, 0.5]])
    xml = parameters_xml(["LASI", "RASI"], [PlateInfo(2, "seat", 1000.0, corners)], 100.0)
    assert xml.startswith("<QTM_Parameters_Ver_1.25>")
    assert parse_labels(xml.encode() + b"\0") == ["LASI", "RASI"]
    (plate,) = parse_plates(xml)
    assert plate.plate_id == 2 and plate.name == "seat" and plate.rate_hz == 1000.0
    assert np.array_equal(plate.corners_mm, corners) and parse_frequency(xml) == 100.0
    with pytest.raises(ProtocolError, match="no The_3D element"):
        parse_labels(parameters_xml(None, [], 100.0))


def test_stream_frames_arguments_are_parsed_case_insensitively_and_bad_ones_named():
    req = parse_stream_frames(["FrequencyDivisor:2", "UDP:10.0.0.5:4545", "3DRes", "Force"])
    assert req.divisor == 2 and req.udp_address == "10.0.0.5" and req.udp_port == 4545
    assert req.components == [Component.THREE_D_RES, Component.FORCE]
    with pytest.raises(ProtocolError, match="component '6D' is not served here"):
        parse_stream_frames(["AllFrames", "6D"])
    with pytest.raises(ProtocolError, match="UDP port 80 is outside 1023..65535"):
        parse_stream_frames(["AllFrames", "UDP:80", "3D"])


def _recording(n: int = 30) -> CaptureRecording:
    t = np.arange(n)[:, None, None]
    markers = np.concatenate([np.full((n, 1, 3), 100.0) + t, np.full((n, 1, 3), 200.0) - t], axis=1)
    corners = np.array([[0, 0, 0], [500.0, 0, 0], [500, 500, 0], [0, 500, 0]])
    samples = np.tile(np.arange(9, dtype=float), (n * 10, 1))
    samples[:, 0] = np.arange(n * 10)
    return CaptureRecording(["A", "B"], 200.0, markers, np.zeros((n, 2)),
                            [RecordedPlate(PlateInfo(1, "p", 2000.0, corners), samples)], "synthetic")


async def until(condition, timeout_s: float = 10.0) -> bool:
    """Let the event loop run until ``condition()`` holds; False if it does not within ``timeout_s``."""
    deadline = asyncio.get_running_loop().time() + timeout_s
    while not condition() and asyncio.get_running_loop().time() < deadline:
        await asyncio.sleep(0.01)
    return condition()


@pytest.fixture
def server():
    srv = QtmServer(_recording(), "127.0.0.1", 0, log=lambda *a, **k: None)
    thread = threading.Thread(target=srv.serve, daemon=True)
    thread.start()
    yield srv
    srv.stop()
    thread.join(5)


def test_qtm_rt_gets_every_frame_over_tcp_then_no_more_data_and_the_stop_event(server):
    async def run():
        events = []
        conn = await qtm_rt.connect("127.0.0.1", server.port, version="1.25", on_event=events.append)
        assert conn is not None
        assert await conn.qtm_version() == b"QTM Version is 2024.2 (sit2stand serve-c3d)"
        xml = await conn.get_parameters(["3d", "force"])
        assert parse_labels(xml) == ["A", "B"] and parse_plates(xml)[0].rate_hz == 2000.0
        got = []
        assert await conn.stream_frames(components=["3dres", "force"], on_packet=got.append) == b"Ok"
        # the server sends the stop event after the last frame, on the same connection: waited for, not timed
        assert await until(lambda: qtm_rt.QRTEvent.EventRTfromFileStopped in events), (len(got), events)
        return got, events

    got, events = asyncio.run(run())
    assert [p.framenumber for p in got] == list(range(1, 31))
    assert [p.timestamp for p in got[:3]] == [0, 5000, 10000], "microseconds from the first frame at 200 Hz"
    forces = [s.x for p in got for s in p.get_force()[1][0][1]]
    assert forces == list(range(300)), "every plate sample, once, in order"
    assert events and events[-1] == qtm_rt.QRTEvent.EventRTfromFileStopped


def test_a_version_the_server_does_not_speak_and_an_unknown_command_are_refused(server):
    async def run():
        assert await qtm_rt.connect("127.0.0.1", server.port, version="2.0") is None
        conn = await qtm_rt.connect("127.0.0.1", server.port, version="1.25")
        with pytest.raises(qtm_rt.QRTCommandException, match="Parse Error"):
            await conn._protocol.send_command("frobnicate")

    asyncio.run(run())


def test_frames_go_over_udp_to_the_port_the_client_names(server):
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    sock.settimeout(2.0)

    async def run():
        events = []
        conn = await qtm_rt.connect("127.0.0.1", server.port, on_event=events.append)
        await conn._protocol.send_command(f"streamframes allframes udp:{sock.getsockname()[1]} 3d force",
                                          callback=False)
        # the stop event (over TCP) follows the last frame's datagram: waited for, not timed
        assert await until(lambda: qtm_rt.QRTEvent.EventRTfromFileStopped in events), events

    asyncio.run(run())
    numbers = []
    sock.settimeout(0.2)     # every datagram is in the socket's buffer by now (loopback): this only reads them out
    try:
        while True:
            numbers.append(QRTPacket(sock.recv(65536)[8:]).framenumber)
    except TimeoutError:
        pass
    assert numbers == list(range(1, 31))
