"""visualization_msgs/MarkerArray as serialized bytes, from plain marker shapes.

The human estimator publishes its markers at 50 Hz and the retargeter its plan at 100 Hz. Built as rclpy objects (a
Point object per mocap marker) and serialized by rclpy, the human's five markers cost ~160 us per message (~0.3 ms
in the live graph, a quarter of the estimator's frame). A :class:`MarkerShape` holds what our markers vary (stamp,
frame, namespace, id, type, colour, scale, position, points); :func:`marker_array_cdr` writes the CDR bytes of the
whole array in one pass (~25 us), and ``Publisher.publish(bytes)`` sends them as they are: subscribers, recorders
and viewers see an ordinary MarkerArray. ``tests/test_markers.py`` checks the bytes against rclpy's serialization.

Layout (XCDR1 little endian, as Fast DDS writes it; see :mod:`sit2stand.io.tf_message`): per Marker, in field order:
header (int32 sec, uint32 nanosec, frame_id), ns, id, type, action (int32), pose (seven float64: position,
orientation x y z w), scale (three float64), color (four float32), lifetime (int32, uint32), frame_locked (bool),
points (uint32 count, then three float64 each), and the fields we leave empty (colors, texture_resource, texture,
uv_coordinates, text, mesh_resource, mesh_file, mesh_use_embedded_materials), which after the points always start
4-byte aligned and so are one constant run of bytes.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

import numpy as np

from .tf_message import CdrLayout

ADD = 0
"""visualization_msgs/Marker ``action`` ADD."""


@dataclass
class MarkerShape:
    """One visualization_msgs/Marker as our viewers' markers use it: identity orientation, no lifetime."""

    stamp_ns: int
    frame_id: str
    ns: str
    ident: int
    kind: int                                     # Marker.SPHERE, SPHERE_LIST, LINE_LIST, LINE_STRIP, CYLINDER
    rgba: tuple[float, float, float, float]
    scale: tuple[float, float, float]             # [m]
    position: tuple[float, float, float] = (0.0, 0.0, 0.0)    # pose.position [m]
    points: np.ndarray | None = None              # (K, 3) [m]


def _empty_tail() -> bytes:
    """The bytes of the empty fields after ``points``, from a 4-byte aligned offset."""
    lay = CdrLayout()
    lay.uint32(0)                        # colors
    lay.string("")                       # texture_resource
    lay.uint32(0)                        # texture: header stamp (sec, nanosec)
    lay.uint32(0)
    lay.string("")                       # texture: header frame_id
    lay.string("")                       # texture: format
    lay.uint32(0)                        # texture: data
    lay.uint32(0)                        # uv_coordinates
    lay.string("")                       # text
    lay.string("")                       # mesh_resource
    lay.string("")                       # mesh_file: filename
    lay.uint32(0)                        # mesh_file: data
    lay.buf.extend(b"\x00")              # mesh_use_embedded_materials
    return bytes(lay.buf[4:])


_TAIL = _empty_tail()


def marker_array_cdr(markers: list[MarkerShape]) -> bytes:
    """The serialized MarkerArray of ``markers``, in order."""
    lay = CdrLayout()
    lay.uint32(len(markers))
    for m in markers:
        sec, nsec = divmod(int(m.stamp_ns), 1_000_000_000)
        lay.align(4)
        lay.buf.extend(struct.pack("<iI", sec, nsec))
        lay.string(m.frame_id)
        lay.string(m.ns)
        lay.align(4)
        lay.buf.extend(struct.pack("<iii", m.ident, m.kind, ADD))
        lay.align(8)
        lay.buf.extend(struct.pack("<10d", *m.position, 0.0, 0.0, 0.0, 1.0, *m.scale))
        lay.buf.extend(struct.pack("<4fiI?", *m.rgba, 0, 0, False))
        points = np.zeros((0, 3)) if m.points is None else m.points
        lay.uint32(len(points))
        if len(points):
            lay.align(8)
            lay.buf.extend(np.ascontiguousarray(points, "<f8").tobytes())
        lay.buf.extend(_TAIL)
    return bytes(lay.buf)
