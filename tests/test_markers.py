"""nodes/markers.py: the plan's markers say what the plan holds, in world, and each message replaces the last."""

import numpy as np
from builtin_interfaces.msg import Time
from visualization_msgs.msg import Marker

from sit2stand.nodes.markers import COM_DROP_ID, COM_ID, NAMESPACE, SUPPORT_ID, ZMP_ID, plan_markers

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
