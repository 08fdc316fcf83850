"""serve-c3d + the mocap_bridge node + the recorder as real processes, against import-c3d's values."""

import socket

import numpy as np
import pytest

from conftest import real_file
from sit2stand.io.bag import BagReader
from sit2stand.io.messages import mocap_arrays, plate_series, stamp_ns

pytestmark = pytest.mark.graph
LOCAL = "127.0.0.1"


def free_port() -> int:
    with socket.socket() as s:
        s.bind((LOCAL, 0))
        return s.getsockname()[1]


def bridge_args(port: int, *extra: str) -> list[str]:
    return ["sit2stand.nodes.mocap_bridge", "--ros-args", "-p", f"host:={LOCAL}", "-p", f"port:={port}",
            "-p", "reconnect_max_s:=0.5", *extra]


def _stamps_s(msgs) -> np.ndarray:
    s = np.array([stamp_ns(m.header) for _, m in msgs], np.int64)
    return (s - s[0]) * 1e-9


def test_every_frame_of_a_real_c3d_reaches_the_bag_with_import_c3ds_values(tmp_path, run_node, sts_bag):
    """sts_child_vicon_01.c3d: 91 marker frames at 100 Hz, the feet plate (index 2) at 2 kHz."""
    path = real_file("sts_child_vicon_01.c3d")
    port, out = free_port(), tmp_path / "live"
    rec = run_node("sit2stand.cli", "record", "--out", str(out), "--regex", "^/(mocap|force_plate)/",
                   log_name="record")
    bridge = run_node(*bridge_args(port, "-p", "chair_plate:=-1", "-p", "feet_plate:=2", "-p", "forward:=-Y",
                                   "-p", "up:=+Z"))
    assert rec.wait_for_output("subscribed to /force_plate/feet", 30), rec.output
    assert rec.wait_for_output("subscribed to /mocap/markers", 10), rec.output
    server = run_node("sit2stand.cli", "serve-c3d", str(path), "--protocol", "qtm", "--port", str(port),
                      "--host", LOCAL, log_name="serve")
    assert server.wait(60) == 0, server.output
    assert bridge.wait_for_output("connected to QTM RT protocol 1.25 at 127.0.0.1", 5), bridge.output
    assert bridge.stop() == 0
    assert "[mocap_bridge] 91 frames, 0 lost, 1 connection(s) to qtm" in bridge.output, bridge.output
    assert rec.stop() == 0, rec.output
    with BagReader(out) as live, BagReader(sts_bag) as imported:
        for topic in ("/mocap/markers", "/force_plate/feet"):
            assert live.topics()[topic].count == imported.topics()[topic].count, topic
        lm, im = live.read("/mocap/markers"), imported.read("/mocap/markers")
        lf, im_f = plate_series("feet", live.read("/force_plate/feet")), plate_series("feet",
                                                                                      imported.read("/force_plate/feet"))
        assert np.allclose(_stamps_s(lm), _stamps_s(im), atol=1e-6), "capture times, 10 ms apart"
        assert np.allclose(_stamps_s(live.read("/force_plate/feet")), _stamps_s(imported.read("/force_plate/feet")),
                           atol=1e-6)
    for (_, a), (_, b) in zip(lm, im):
        names_a, pos_a, valid_a = mocap_arrays(a)
        names_b, pos_b, valid_b = mocap_arrays(b)
        assert names_a == names_b and np.array_equal(valid_a, valid_b)
        assert np.allclose(pos_a, pos_b, atol=1e-6, equal_nan=True), "float32 on the wire: 1e-7 m at 1.5 m"
    assert a.header.frame_id == "lab"
    assert np.allclose(lf.force_n, im_f.force_n, atol=1e-4, rtol=1e-6)
    assert np.allclose(lf.moment_origin_nm, im_f.moment_origin_nm, atol=1e-4, rtol=1e-6)
    assert np.array_equal(lf.cop_valid, im_f.cop_valid)
    assert np.allclose(lf.cop_m, im_f.cop_m, atol=1e-5, equal_nan=True)


def test_the_bridge_names_what_failed_and_survives_the_server_going_away_and_coming_back(tmp_path, run_node):
    real_file("sts_child_vicon_01.c3d")
    path, port = real_file("sts_child_vicon_01.c3d"), free_port()
    bridge = run_node(*bridge_args(port, "-p", "chair_plate:=-1", "-p", "feet_plate:=2"))
    assert bridge.wait_for_output(f"cannot connect to QTM RT protocol 1.25 at 127.0.0.1:{port}: [Errno 111]", 30), \
        bridge.stacks()
    first = run_node("sit2stand.cli", "serve-c3d", str(path), "--port", str(port), "--host", LOCAL, "--loop",
                     log_name="serve1")
    assert bridge.wait_for_output("connected to QTM", 20), bridge.output
    assert first.wait_for_output("capture clock origin", 10)
    first.stop()
    assert bridge.wait_for_output("the server closed the connection; reconnecting", 10), bridge.output
    second = run_node("sit2stand.cli", "serve-c3d", str(path), "--port", str(port), "--host", LOCAL,
                      log_name="serve2")
    assert second.wait(60) == 0, second.output
    assert bridge.stop() == 0
    assert "2 connection(s) to qtm" in bridge.output and " 0 lost" in bridge.output, bridge.output[-3000:]


def test_a_protocol_version_the_server_refuses_is_named(tmp_path, run_node):
    path, port = real_file("sts_child_vicon_01.c3d"), free_port()
    server = run_node("sit2stand.cli", "serve-c3d", str(path), "--port", str(port), "--host", LOCAL,
                      log_name="serve")
    bridge = run_node(*bridge_args(port, "-p", "version:=1.99"))
    assert bridge.wait_for_output("the server refused protocol version 1.99 (Version NOT supported)", 30), \
        bridge.output
    bridge.stop()
    server.kill()
