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
"""

from __future__ import annotations

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Point
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker, MarkerArray

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


def _marker(stamp: Time, frame_id: str, ident: int, kind: int, rgba: tuple[float, float, float, float],
            scale: tuple[float, float, float], ns: str = NAMESPACE) -> Marker:
    m = Marker(ns=ns, id=ident, type=kind, action=Marker.ADD, color=ColorRGBA(r=rgba[0], g=rgba[1],
                                                                              b=rgba[2], a=rgba[3]))
    m.header.stamp, m.header.frame_id = stamp, frame_id
    m.pose.orientation.w = 1.0
    m.scale.x, m.scale.y, m.scale.z = scale
    return m


def plan_markers(stamp: Time, com_m: np.ndarray, zmp_m: np.ndarray, support_xy: np.ndarray,
                 frame_id: str = WORLD_FRAME) -> MarkerArray:
    """The plan's markers (see the module docstring): COM (3,) [m], ZMP (3,) [m] on the floor, support polygon
    (K, 2) [m] counter-clockwise, all in ``frame_id``."""
    c = [float(v) for v in com_m]
    z = [float(v) for v in zmp_m]
    com = _marker(stamp, frame_id, COM_ID, Marker.SPHERE, (0.1, 0.75, 0.2, 1.0), (COM_DIAMETER_M,) * 3)
    com.pose.position.x, com.pose.position.y, com.pose.position.z = c
    drop = _marker(stamp, frame_id, COM_DROP_ID, Marker.LINE_LIST, (0.5, 0.5, 0.5, 0.8), (LINE_WIDTH_M / 2, 0, 0))
    drop.points = [Point(x=c[0], y=c[1], z=c[2]), Point(x=c[0], y=c[1], z=0.0)]
    zmp = _marker(stamp, frame_id, ZMP_ID, Marker.CYLINDER, (0.9, 0.15, 0.1, 1.0),
                  (ZMP_DIAMETER_M, ZMP_DIAMETER_M, 0.004))
    zmp.pose.position.x, zmp.pose.position.y, zmp.pose.position.z = z[0], z[1], z[2] + 0.002
    support = _marker(stamp, frame_id, SUPPORT_ID, Marker.LINE_STRIP, (0.15, 0.35, 0.9, 1.0), (LINE_WIDTH_M, 0, 0))
    corners = [Point(x=float(x), y=float(y), z=0.001) for x, y in np.asarray(support_xy, float)]
    support.points = corners + corners[:1]
    return MarkerArray(markers=[com, drop, zmp, support])


def _floor_disc(stamp: Time, ident: int, rgba: tuple[float, float, float, float], xy) -> Marker:
    """A flat disc of ``COP_DIAMETER_M`` on the lab floor at ``xy`` [m]."""
    m = _marker(stamp, LAB_FRAME, ident, Marker.CYLINDER, rgba, (COP_DIAMETER_M, COP_DIAMETER_M, 0.004),
                HUMAN_NAMESPACE)
    m.pose.position.x, m.pose.position.y, m.pose.position.z = float(xy[0]), float(xy[1]), 0.002
    return m


def human_markers(stamp: Time, markers_m: np.ndarray, com_m: np.ndarray | None,
                  cop_stamp: Time | None = None, measured_cop_m: np.ndarray | None = None,
                  model_cop_m: np.ndarray | None = None) -> MarkerArray:
    """The human side's markers (see the module docstring), all in lab [m]: the frame's markers (N, 3) (rows with
    NaN left out), the COM (3,) or None, and the COPs (x, y on the floor) of the delayed frame ``cop_stamp``."""
    pts = np.asarray(markers_m, float).reshape(-1, 3)
    mocap = _marker(stamp, LAB_FRAME, MOCAP_ID, Marker.SPHERE_LIST, (0.1, 0.4, 1.0, 1.0), (MOCAP_DIAMETER_M,) * 3,
                    HUMAN_NAMESPACE)
    mocap.points = [Point(x=float(x), y=float(y), z=float(z)) for x, y, z in pts[np.all(np.isfinite(pts), axis=1)]]
    out = [mocap]
    if com_m is not None and np.all(np.isfinite(com_m)):
        c = [float(v) for v in com_m]
        com = _marker(stamp, LAB_FRAME, HUMAN_COM_ID, Marker.SPHERE, (1.0, 0.55, 0.0, 1.0), (COM_DIAMETER_M,) * 3,
                      HUMAN_NAMESPACE)
        com.pose.position.x, com.pose.position.y, com.pose.position.z = c
        drop = _marker(stamp, LAB_FRAME, HUMAN_COM_DROP_ID, Marker.LINE_LIST, (0.5, 0.5, 0.5, 0.8),
                       (LINE_WIDTH_M / 2, 0, 0), HUMAN_NAMESPACE)
        drop.points = [Point(x=c[0], y=c[1], z=c[2]), Point(x=c[0], y=c[1], z=0.0)]
        out += [com, drop]
    if cop_stamp is not None:
        for ident, rgba, cop in ((MEASURED_COP_ID, (0.05, 0.05, 0.05, 1.0), measured_cop_m),
                                 (MODEL_COP_ID, (0.9, 0.1, 0.8, 1.0), model_cop_m)):
            if cop is not None and np.all(np.isfinite(cop[:2])):
                out.append(_floor_disc(cop_stamp, ident, rgba, cop))
    return MarkerArray(markers=out)
