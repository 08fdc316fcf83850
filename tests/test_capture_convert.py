"""The capture -> lab conversion, the clock map, lost-frame counting and the reconnect policy (no ROS)."""

import numpy as np
import pytest

from conftest import real_file
from sit2stand.capture.convert import (CaptureServer, ClockMap, DropCounter, FrameConverter, ReconnectPolicy,
                                      StreamLayout, plate_names, plate_stamps)
from sit2stand.capture.qtm_protocol import Component, DataFrame, PlateInfo, data_packet, decode_data
from sit2stand.capture.recording import load_recording
from sit2stand.io.c3d import LabAxes, read_c3d

CORNERS = np.array([[0, 0, 0], [500.0, 0, 0], [500, 400, 0], [0, 400, 0]])


def test_markers_become_metres_in_the_lab_axes_and_invalid_ones_nan():
    conv = FrameConverter(["A", "B", "C", "D"], [], LabAxes("-Y", "+Z"), {})
    mm = np.array([[100.0, 200.0, 300.0], [np.nan] * 3, [0.0, 0.0, 0.0], [1.0, 2.0, 3.0]])
    m = conv.markers(DataFrame(0, 1, mm, np.array([0.4, np.nan, 0.0, -1.0])), 7)
    assert m.t_ns == 7 and m.names == ["A", "B", "C", "D"]
    assert np.allclose(m.positions_m[0], [-0.2, 0.1, 0.3]), "forward -Y: lab x = -file y, lab y = file x"
    assert m.valid.tolist() == [True, False, False, False], "NaN, exactly zero, negative residual: invalid"
    assert np.isnan(m.positions_m[1:]).all() and m.residuals_m[0] == pytest.approx(0.4e-3)


def test_a_marker_set_orders_the_markers_and_marks_the_missing_ones_invalid():
    conv = FrameConverter(["A", "B"], [], LabAxes(), {}, marker_set=["B", "Z", "A"])
    m = conv.markers(DataFrame(0, 1, np.array([[1.0, 1, 1], [2.0, 2, 2]])), 0)
    assert m.names == ["B", "Z", "A"] and m.valid.tolist() == [True, False, True]
    assert m.positions_m[0, 0] == pytest.approx(2e-3)


def test_plates_are_named_by_their_0_based_index_as_import_c3d_names_them():
    plates = [PlateInfo(i, f"Force-plate {i}", 1000.0, CORNERS) for i in (1, 2, 3)]
    assert plate_names(plates, chair_index=2, feet_index=0) == {1: "feet", 2: "plate1", 3: "chair"}


def test_a_stream_of_a_real_c3d_converts_to_the_values_import_c3d_gives():
    """Frame by frame through the wire format (float32), the same markers and plate wrenches as import-c3d."""
    path = real_file("sts_child_vicon_01.c3d")
    trial = read_c3d(path, feet_plate=2)
    rec = load_recording(path)
    conv = FrameConverter(rec.labels, [p.info for p in rec.plates], trial.axes,
                          plate_names([p.info for p in rec.plates], -1, 2))
    clock, pos, force, moment, cop = ClockMap(), [], [], [], []
    for k in range(rec.n_frames):
        frame = decode_data(data_packet(rec.frame(k), [Component.THREE_D_RES, Component.FORCE])[8:])
        pos.append(conv.markers(frame, clock.stamp(frame.timestamp_us * 1000, 0)).positions_m)
        chunk = frame.plates[0]
        s = conv.plate(chunk.plate_id, chunk.samples, plate_stamps(chunk.first_sample, len(chunk.samples),
                                                                   2000.0, clock, 0))
        force.append(s.force_n), moment.append(s.moment_origin_nm), cop.append(s.cop_m)
        assert s.name == "feet"
    feet = trial.plates[0]
    assert conv.labels == trial.markers.names
    assert np.allclose(np.array(pos), trial.markers.positions_m, atol=1e-6, equal_nan=True)
    assert np.allclose(np.vstack(force), feet.force_n, atol=1e-4, rtol=1e-6)
    assert np.allclose(np.vstack(moment), feet.moment_origin_nm, atol=1e-4, rtol=1e-6)
    assert np.allclose(np.vstack(cop), feet.cop_m, atol=1e-5, equal_nan=True)


def test_the_capture_clock_is_mapped_once_and_again_when_it_goes_back():
    clock = ClockMap()
    assert clock.stamp(1_000, now_ns=50_000) == 50_000
    assert clock.stamp(11_000, now_ns=99_999_999) == 60_000, "spacing of the capture clock, not of arrival"
    assert clock.stamp(0, now_ns=70_000) == 70_000, "a new measurement (clock back): mapped again"
    clock.reset()
    assert clock.stamp(5, now_ns=10) == 10
    assert plate_stamps(20, 2, 2000.0, clock, 0).tolist() == [10_000_005, 10_500_005]


def test_lost_frames_are_counted_from_gaps_in_the_frame_numbers():
    drops = DropCounter()
    assert [drops.add(n) for n in (1, 2, 5, 6, 9)] == [0, 0, 2, 0, 2]
    assert (drops.received, drops.dropped, drops.gaps) == (5, 4, [(2, 5), (6, 9)])
    drops.add(1)
    assert drops.restarts == 1 and drops.dropped == 4, "a restarted measurement is not a loss"


def test_reconnect_waits_double_up_to_the_cap_and_start_again_after_a_success():
    policy = ReconnectPolicy(first_s=0.2, max_s=1.0)
    assert [policy.next_delay_s() for _ in range(5)] == [0.2, 0.4, 0.8, 1.0, 1.0]
    policy.succeeded()
    assert policy.next_delay_s() == 0.2


def test_a_capture_server_takes_its_protocols_port_and_refuses_unknown_settings():
    assert CaptureServer("qtm", "10.0.0.2", 0).address == "10.0.0.2:22223"
    assert CaptureServer("natnet", "h", 0).port == 1510 and CaptureServer("natnet", "h", 3000).port == 3000
    with pytest.raises(ValueError, match="protocol must be 'qtm' or 'natnet', not 'vicon'"):
        CaptureServer("vicon", "h", 0)
    with pytest.raises(ValueError, match="transport"):
        CaptureServer("qtm", "h", 0, transport="serial")


def test_a_connections_layout_makes_each_plates_message_layout_once():
    conv = FrameConverter(["a"], [], LabAxes("+X", "+Z"), {}, None)
    layout = StreamLayout(object(), conv, None)
    assert layout.plate("feet") is layout.plate("feet") and layout.plate("chair") is not layout.plate("feet")
