"""nodes/markers.py: the plan's markers say what the plan holds, in world, and each message replaces the last; the
bytes the nodes publish are rclpy's serialization of the same message."""

import numpy as np
from builtin_interfaces.msg import Time
from rclpy.serialization import deserialize_message, serialize_message
from visualization_msgs.msg import Marker, MarkerArray

from sit2stand.io.marker_message import marker_array_cdr
from sit2stand.nodes.markers import (COM_DROP_ID, COM_ID, HUMAN_COM_DROP_ID, HUMAN_COM_ID, HUMAN_NAMESPACE,
                                    MEASURED_COP_ID, MOCAP_ID, MODEL_COP_ID, NAMESPACE, SUPPORT_ID, ZMP_ID,
                                    human_marker_shapes, human_markers, plan_marker_shapes, plan_markers,
                                    to_message)

SQUARE = np.array([[-0.1, -0.15], [0.12, -0.15], [0.12, 0.15], [-0.1, 0.15]])


def test_com_zmp_and_support_polygon_markers_in_world():
    msg = plan_markers(Time(sec=7, nanosec=9), np.array([0.01, 0.02, 0.8]), np.array([0.03, -0.01, 0.0]), SQUARE)
    by_id = {m.id: m for m in msg.markers}
    assert sorted(by_id) == [COM_ID, COM_DROP_ID, ZMP_ID, SUPPORT_ID]
    for m in msg.markers:
        assert (m.ns, m.header.frame_id, m.header.stamp.sec, m.header.stamp.nanosec) == (NAMESPACE, "world", 7, 9)
        assert m.action == Marker.ADD and m.lifetime.sec == 0 and m.color.a > 0 and m.pose.orientation.w == 1.0
    com = by_id[COM_ID]
    assert com.type == Marker.SPHERE and [com.pose.position.x, com.pose.position.y, com.pose.position.z] == \
        [0.01, 0.02, 0.8]
    drop = by_id[COM_DROP_ID]
    assert [(p.x, p.y, p.z) for p in drop.points] == [(0.01, 0.02, 0.8), (0.01, 0.02, 0.0)]
    zmp = by_id[ZMP_ID]
    assert zmp.type == Marker.CYLINDER and (zmp.pose.position.x, zmp.pose.position.y) == (0.03, -0.01)
    support = by_id[SUPPORT_ID]
    pts = np.array([[p.x, p.y, p.z] for p in support.points])
    assert support.type == Marker.LINE_STRIP and len(pts) == 5, "closed: the first corner repeated"
    np.testing.assert_array_equal(pts[:4, :2], SQUARE)
    np.testing.assert_array_equal(pts[4], pts[0])
    assert np.all(pts[:, 2] == 0.001)


def test_the_human_markers_are_in_lab_with_their_own_stamps():
    """Mocap markers (NaN rows left out), the COM with its drop, and the COPs at the delayed frame's stamp."""
    pts = np.array([[0.1, 0.2, 0.9], [np.nan, np.nan, np.nan], [0.3, -0.1, 0.05]])
    msg = human_markers(Time(sec=5), pts, np.array([0.05, 0.0, 0.95]), Time(sec=4, nanosec=850_000_000),
                        np.array([0.07, 0.01, 0.0]), np.array([0.06, 0.02, 0.0]))
    by_id = {m.id: m for m in msg.markers}
    assert sorted(by_id) == [MOCAP_ID, HUMAN_COM_ID, HUMAN_COM_DROP_ID, MEASURED_COP_ID, MODEL_COP_ID]
    assert {(m.ns, m.header.frame_id) for m in msg.markers} == {(HUMAN_NAMESPACE, "lab")}
    assert [(p.x, p.y, p.z) for p in by_id[MOCAP_ID].points] == [(0.1, 0.2, 0.9), (0.3, -0.1, 0.05)]
    assert by_id[MOCAP_ID].type == Marker.SPHERE_LIST and by_id[MOCAP_ID].header.stamp.sec == 5
    com = by_id[HUMAN_COM_ID].pose.position
    assert (com.x, com.y, com.z) == (0.05, 0.0, 0.95)
    for ident, cop in ((MEASURED_COP_ID, (0.07, 0.01)), (MODEL_COP_ID, (0.06, 0.02))):
        m = by_id[ident]
        assert (m.pose.position.x, m.pose.position.y) == cop and m.type == Marker.CYLINDER
        assert (m.header.stamp.sec, m.header.stamp.nanosec) == (4, 850_000_000)


def test_the_human_markers_leave_out_what_is_not_there_yet():
    msg = human_markers(Time(sec=1), np.zeros((0, 3)), None)
    assert [m.id for m in msg.markers] == [MOCAP_ID] and not msg.markers[0].points


def test_the_published_bytes_are_what_rclpy_serializes():
    """The nodes publish the markers as bytes: rclpy reads them back as it reads its own serialization of the same
    message (whose padding bytes it leaves unset, so the bytes themselves are not compared), whatever the number of
    points and the alignment the strings leave."""
    rng = np.random.default_rng(3)
    cases = [human_marker_shapes(Time(sec=5, nanosec=7), rng.normal(size=(n, 3)), com, Time(sec=4), cop, cop)
             for n, com, cop in ((35, np.array([0.05, 0.0, 0.95]), np.array([0.07, 0.01, 0.0])), (0, None, None),
                                 (3, np.array([np.nan, 0.0, 1.0]), np.array([0.1, 0.2, 0.0])))]
    cases.append(plan_marker_shapes(Time(sec=7, nanosec=9), np.array([0.01, 0.02, 0.8]),
                                    np.array([0.03, -0.01, 0.0]), SQUARE, frame_id="w"))
    for shapes in cases:
        ours, theirs = marker_array_cdr(shapes), serialize_message(to_message(shapes))
        assert deserialize_message(ours, MarkerArray) == deserialize_message(theirs, MarkerArray)
        assert len(ours) == len(theirs)
    assert deserialize_message(marker_array_cdr(cases[0]), MarkerArray).markers[0].points[34].z == \
        cases[0][0].points[34, 2]
