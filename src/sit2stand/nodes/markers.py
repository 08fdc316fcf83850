"""RViz / Foxglove markers (visualization_msgs/MarkerArray): the retargeter's plan (``/viz/markers``, world) and the
human side (``/viz/human``, lab).

The plan: four markers in the namespace ``plan``, each message replacing the previous one (same ids, no lifetime):

* ``COM_ID``: the planned centre of mass, a green sphere of ``COM_DIAMETER_M``;
* ``COM_DROP_ID``: a grey line from it down to the floor (where it stands over the feet);
* ``ZMP_ID``: the planned zero-moment point, a flat red disc on the floor;
* ``SUPPORT_ID``: the feet's support polygon (the convex hull of both sole plates where the plan keeps them), a
  closed blue line 1 mm above the floor: the ZMP must stay inside it, the plan keeps ``margin_m`` inside.

The human (namespace ``human``, :func:`human_markers`): the mocap markers the frame saw (``MOCAP_ID``, blue spheres
of ``MOCAP_DIAMETER_M``), the estimated COM (``HUMAN_COM_ID``, an orange sphere, and ``HUMAN_COM_DROP_ID``, its
drop to the floor), the plates' measured COP (``MEASURED_COP_ID``, a black disc) and the skeleton's model COP
(``MODEL_COP_ID``, a magenta disc). The COPs are half a window behind the markers; each marker carries its own stamp.

The nodes publish the shapes as bytes (:func:`~sit2stand.io.marker_message.marker_array_cdr`); :func:`to_message`
gives the same array as message objects.
"""

from __future__ import annotations

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Point
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker, MarkerArray

from ..io.marker_message import MarkerShape
from ..io.topics import LAB_FRAME, WORLD_FRAME

NAMESPACE = "plan"
COM_ID, COM_DROP_ID, ZMP_ID, SUPPORT_ID = range(4)
HUMAN_NAMESPACE = "human"
MOCAP_ID, HUMAN_COM_ID, HUMAN_COM_DROP_ID, MEASURED_COP_ID, MODEL_COP_ID = range(5)
COM_DIAMETER_M = 0.06
ZMP_DIAMETER_M = 0.04
COP_DIAMETER_M = 0.04
MOCAP_DIAMETER_M = 0.015
LINE_WIDTH_M = 0.008


def _stamp_ns(stamp: Time) -> int:
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def plan_marker_shapes(stamp: Time, com_m: np.ndarray, zmp_m: np.ndarray, support_xy: np.ndarray,
                       frame_id: str = WORLD_FRAME) -> list[MarkerShape]:
    """The plan's markers (see the module docstring): COM (3,) [m], ZMP (3,) [m] on the floor, support polygon
    (K, 2) [m] counter-clockwise, all in ``frame_id``."""
    t = _stamp_ns(stamp)
    c = tuple(float(v) for v in com_m)
    z = [float(v) for v in zmp_m]
    corners = np.column_stack([np.asarray(support_xy, float).reshape(-1, 2), np.full(len(support_xy), 0.001)])
    return [MarkerShape(t, frame_id, NAMESPACE, COM_ID, Marker.SPHERE, (0.1, 0.75, 0.2, 1.0), (COM_DIAMETER_M,) * 3,
                        c),
            MarkerShape(t, frame_id, NAMESPACE, COM_DROP_ID, Marker.LINE_LIST, (0.5, 0.5, 0.5, 0.8),
                        (LINE_WIDTH_M / 2, 0.0, 0.0), points=np.array([c, (c[0], c[1], 0.0)])),
            MarkerShape(t, frame_id, NAMESPACE, ZMP_ID, Marker.CYLINDER, (0.9, 0.15, 0.1, 1.0),
                        (ZMP_DIAMETER_M, ZMP_DIAMETER_M, 0.004), (z[0], z[1], z[2] + 0.002)),
            MarkerShape(t, frame_id, NAMESPACE, SUPPORT_ID, Marker.LINE_STRIP, (0.15, 0.35, 0.9, 1.0),
                        (LINE_WIDTH_M, 0.0, 0.0), points=np.vstack([corners, corners[:1]]))]


def human_marker_shapes(stamp: Time, markers_m: np.ndarray, com_m: np.ndarray | None,
                        cop_stamp: Time | None = None, measured_cop_m: np.ndarray | None = None,
                        model_cop_m: np.ndarray | None = None) -> list[MarkerShape]:
    """The human side's markers (see the module docstring), all in lab [m]: the frame's markers (N, 3) (rows with
    NaN left out), the COM (3,) or None, and the COPs (x, y on the floor) of the delayed frame ``cop_stamp``."""
    t = _stamp_ns(stamp)
    pts = np.asarray(markers_m, float).reshape(-1, 3)
    out = [MarkerShape(t, LAB_FRAME, HUMAN_NAMESPACE, MOCAP_ID, Marker.SPHERE_LIST, (0.1, 0.4, 1.0, 1.0),
                       (MOCAP_DIAMETER_M,) * 3, points=pts[np.isfinite(pts).all(axis=1)])]
    if com_m is not None and np.isfinite(com_m).all():
        c = tuple(float(v) for v in com_m)
        out += [MarkerShape(t, LAB_FRAME, HUMAN_NAMESPACE, HUMAN_COM_ID, Marker.SPHERE, (1.0, 0.55, 0.0, 1.0),
                            (COM_DIAMETER_M,) * 3, c),
                MarkerShape(t, LAB_FRAME, HUMAN_NAMESPACE, HUMAN_COM_DROP_ID, Marker.LINE_LIST, (0.5, 0.5, 0.5, 0.8),
                            (LINE_WIDTH_M / 2, 0.0, 0.0), points=np.array([c, (c[0], c[1], 0.0)]))]
    if cop_stamp is not None:
        for ident, rgba, cop in ((MEASURED_COP_ID, (0.05, 0.05, 0.05, 1.0), measured_cop_m),
                                 (MODEL_COP_ID, (0.9, 0.1, 0.8, 1.0), model_cop_m)):
            if cop is not None and np.isfinite(cop[:2]).all():     # a flat disc on the lab floor
                out.append(MarkerShape(_stamp_ns(cop_stamp), LAB_FRAME, HUMAN_NAMESPACE, ident, Marker.CYLINDER,
                                       rgba, (COP_DIAMETER_M, COP_DIAMETER_M, 0.004),
                                       (float(cop[0]), float(cop[1]), 0.002)))
    return out


def to_message(shapes: list[MarkerShape]) -> MarkerArray:
    """The shapes as rclpy message objects (what :func:`marker_array_cdr` serializes them to, byte for byte)."""
    out = []
    for sh in shapes:
        m = Marker(ns=sh.ns, id=sh.ident, type=sh.kind, action=Marker.ADD,
                   color=ColorRGBA(r=sh.rgba[0], g=sh.rgba[1], b=sh.rgba[2], a=sh.rgba[3]))
        m.header.stamp = Time(sec=sh.stamp_ns // 1_000_000_000, nanosec=sh.stamp_ns % 1_000_000_000)
        m.header.frame_id = sh.frame_id
        m.pose.orientation.w = 1.0
        m.pose.position.x, m.pose.position.y, m.pose.position.z = map(float, sh.position)
        m.scale.x, m.scale.y, m.scale.z = map(float, sh.scale)
        if sh.points is not None:
            m.points = [Point(x=float(x), y=float(y), z=float(z)) for x, y, z in sh.points]
        out.append(m)
    return MarkerArray(markers=out)


def plan_markers(stamp: Time, com_m: np.ndarray, zmp_m: np.ndarray, support_xy: np.ndarray,
                 frame_id: str = WORLD_FRAME) -> MarkerArray:
    """:func:`plan_marker_shapes` as a message."""
    return to_message(plan_marker_shapes(stamp, com_m, zmp_m, support_xy, frame_id))


def human_markers(stamp: Time, markers_m: np.ndarray, com_m: np.ndarray | None, cop_stamp: Time | None = None,
                  measured_cop_m: np.ndarray | None = None, model_cop_m: np.ndarray | None = None) -> MarkerArray:
    """:func:`human_marker_shapes` as a message."""
    return to_message(human_marker_shapes(stamp, markers_m, com_m, cop_stamp, measured_cop_m, model_cop_m))
