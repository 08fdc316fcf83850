"""OptiTrack NatNet, the server's side: the packets ``serve-c3d --protocol natnet`` sends, as ``natnet`` reads them;
and the bridge's quick reader of a frame's markers (:func:`read_marker_frame`).

Written as the inverse of the parsers of the PyPI package ``natnet`` (0.3.0; the bridge's client library):
``ServerInfo``, ``DataDescriptions`` and ``DataFrame`` ``.read_from_buffer``. Every message is a 4-byte header
(uint16 message id, uint16 body size in bytes) and a body, little-endian; strings are NUL-terminated UTF-8.

* NAT_SERVERINFO (1), the reply to NAT_CONNECT (0): the application name in a 256-byte NUL-padded field, the
  application's version and the NatNet protocol version (4 bytes each). After them, as Motive's server description
  does, the high-resolution clock's frequency (uint64; 1e9 here: the frame stamps are CLOCK_REALTIME ns), the data
  port (uint16), a multicast flag (uint8) and the multicast group (4 bytes); ``natnet`` reads the first three only.
* NAT_MODELDEF (5), the reply to NAT_REQUEST_MODELDEF (4): the data descriptions; here marker sets only (type 0:
  name, uint32 count, the marker names), each preceded from protocol 4.1 on by its size in bytes.
* NAT_FRAMEOFDATA (7): uint32 frame number; then the lists marker sets (name, uint32 count, float32 x y z [m] per
  marker, in the description's order), legacy unlabelled markers, rigid bodies, skeletons, assets (4.1),
  labelled markers (uint32 id = model id << 16 | marker id, float32 x y z [m], float32 size [m], uint16 flags,
  float32 residual [mm]), force plates, devices: each a uint32 count, and from 4.1 on a uint32 size in bytes;
  then the suffix: uint32 timecode, uint32 timecode subframe, float64 timestamp [s], three uint64 stamps
  (camera mid-exposure, data received, transmitted; clock ticks) and uint16 flags.

:data:`PROTOCOL_VERSION` is 4.1 (Motive 3.1's), the newest the ``natnet`` package parses in full; 3.0 to 4.1 can be
encoded. Motive 3.1 ends a 4.1 frame's suffix with a precision timestamp (two uint32) that ``natnet`` 0.3.0 does not
read: it is not sent, so the flags land where ``natnet`` reads them.

A member of a marker set that is not seen in a frame is sent at (0, 0, 0) in the marker set (the bridge, like
``import-c3d``, reads exactly zero as missing) and is left out of the labelled markers.

Axes: Motive streams metres in its own right-handed axes, by default y up (:data:`Y_UP`). :func:`capture_frame`
rotates a recording's z-up axes to y up by -90 degrees about x: served (x, y, z) = recorded (x, z, -y). A bridge
then takes the lab frame back with ``up:=+Y`` and ``forward`` = the served axis of the recording's forward (a
z-up recording's +X stays +X; its -Y becomes +Z).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field
from enum import IntEnum

import numpy as np

from ..errors import InputError
from .qtm_protocol import DataFrame

PROTOCOL_VERSION = (4, 1, 0, 0)
OLDEST_VERSION = (3, 0, 0, 0)
SERVER_VERSION = (3, 1, 0, 0)           # the Motive release that speaks NatNet 4.1
APP_NAME = "sit2stand serve-c3d"
HEADER = struct.Struct("<HH")
MARKER_SIZE_M = 0.014                   # the labelled markers' diameter [m]
STAMP_HZ = 1_000_000_000                # the frame stamps' clock: ns
MAX_BODY = 0xFFFF                       # the header's uint16 size
SIZED_FROM = (4, 1, 0, 0)               # the protocol whose lists carry their size in bytes
LISTS_AFTER_MARKER_SETS = 7             # 4.1: unlabelled, rigid bodies, skeletons, assets, labelled, plates, devices
_COUNT_SIZE = struct.Struct("<II")

Z_UP = np.eye(3)
Y_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
"""Served = Y_UP @ recorded: a z-up recording in Motive's default y-up axes (a proper rotation, -90 deg about x)."""


class Message(IntEnum):
    """NatNet message ids."""

    CONNECT = 0
    SERVERINFO = 1
    REQUEST = 2
    RESPONSE = 3
    REQUEST_MODELDEF = 4
    MODELDEF = 5
    REQUEST_FRAMEOFDATA = 6
    FRAMEOFDATA = 7
    MESSAGESTRING = 8
    DISCONNECT = 9
    KEEPALIVE = 10
    UNRECOGNIZED_REQUEST = 100


class MarkerFlag(IntEnum):
    """Bits of a labelled marker's flags."""

    OCCLUDED = 0x01
    POINT_CLOUD_SOLVED = 0x02
    MODEL_SOLVED = 0x04
    HAS_MODEL = 0x08
    UNLABELED = 0x10
    ACTIVE = 0x20


@dataclass
class LabeledMarker:
    """A labelled marker of a frame: id (model id << 16 | marker id), position [m], size [m], flags, residual."""

    id_num: int
    pos_m: tuple[float, float, float]
    size_m: float = MARKER_SIZE_M
    flags: int = MarkerFlag.POINT_CLOUD_SOLVED | MarkerFlag.HAS_MODEL
    residual_mm: float = 0.0


@dataclass
class NatNetFrame:
    """One NAT_FRAMEOFDATA: frame number, marker sets (name, (M, 3) positions [m]), labelled markers, timecode,
    timestamp [s], the three stamps [clock ticks] and the suffix flags."""

    frame_number: int
    marker_sets: list[tuple[str, np.ndarray]]
    labeled_markers: list[LabeledMarker] = field(default_factory=list)
    timestamp_s: float = 0.0
    timecode: int = 0
    timecode_sub: int = 0
    stamps: tuple[int, int, int] = (0, 0, 0)
    flags: int = 0


def _check_version(version: tuple[int, ...]) -> tuple[int, int, int, int]:
    v = tuple(version) + (0,) * (4 - len(version))
    if not OLDEST_VERSION <= v <= PROTOCOL_VERSION:
        raise InputError(f"NatNet {'.'.join(map(str, v[:2]))} is not encoded here (3.0 to 4.1 are)")
    return v


def _cstr(text: str) -> bytes:
    data = text.encode("utf-8")
    if b"\0" in data:
        raise InputError(f"NatNet strings end at NUL: {text!r} has one")
    return data + b"\0"


def message(kind: Message, body: bytes = b"") -> bytes:
    """A message: the header (id, body size) and the body; a body over 65535 bytes cannot be sent."""
    if len(body) > MAX_BODY:
        raise InputError(f"NatNet message {kind.name} of {len(body)} bytes: the header holds at most {MAX_BODY}")
    return HEADER.pack(int(kind), len(body)) + body


def request(kind: Message, text: str = "") -> bytes:
    """A client's request as ``natnet`` sends it: the text (``Ping`` for NAT_CONNECT) and a NUL."""
    return message(kind, _cstr("Ping" if kind == Message.CONNECT else text))


def parse_request(data: bytes) -> tuple[int, str]:
    """A datagram from a client: (message id, its text up to the first NUL); InputError if it is too short."""
    if len(data) < HEADER.size:
        raise InputError(f"a NatNet datagram of {len(data)} bytes is shorter than its header")
    kind, size = HEADER.unpack_from(data)
    body = bytes(data[HEADER.size:HEADER.size + size])
    return kind, body.partition(b"\0")[0].decode("utf-8", "replace")


def server_info(app_name: str = APP_NAME, app_version: tuple[int, ...] = SERVER_VERSION,
                version: tuple[int, ...] = PROTOCOL_VERSION, data_port: int = 1511) -> bytes:
    """NAT_SERVERINFO (see the module docstring)."""
    name = app_name.encode("utf-8")[:255]
    body = name + b"\0" * (256 - len(name))
    body += struct.pack("<4B4B", *(tuple(app_version) + (0,) * 4)[:4], *_check_version(version))
    body += struct.pack("<QHB4B", STAMP_HZ, data_port, 0, 0, 0, 0, 0)
    return message(Message.SERVERINFO, body)


def _sized(version: tuple[int, ...], count: int, data: bytes) -> bytes:
    """A list: its count and, from 4.1 on, its size in bytes, then its elements."""
    head = struct.pack("<I", count)
    if version >= (4, 1, 0, 0):
        head += struct.pack("<I", len(data))
    return head + data


def model_definitions(marker_sets: list[tuple[str, list[str]]], version: tuple[int, ...] = PROTOCOL_VERSION) -> bytes:
    """NAT_MODELDEF describing marker sets (name, marker names)."""
    v = _check_version(version)
    body = struct.pack("<I", len(marker_sets))
    for name, markers in marker_sets:
        desc = _cstr(name) + struct.pack("<I", len(markers)) + b"".join(_cstr(m) for m in markers)
        body += struct.pack("<I", 0)           # data description type 0: a marker set
        if v >= (4, 1, 0, 0):
            body += struct.pack("<I", len(desc))
        body += desc
    return message(Message.MODELDEF, body)


def frame_of_data(frame: NatNetFrame, version: tuple[int, ...] = PROTOCOL_VERSION) -> bytes:
    """NAT_FRAMEOFDATA (see the module docstring)."""
    v = _check_version(version)
    body = struct.pack("<I", frame.frame_number)
    sets = b""
    for name, pos in frame.marker_sets:
        p = np.asarray(pos, "<f4").reshape(-1, 3)
        sets += _cstr(name) + struct.pack("<I", len(p)) + p.tobytes()
    body += _sized(v, len(frame.marker_sets), sets)
    empty = _sized(v, 0, b"")
    body += empty * (3 if v < (4, 1, 0, 0) else 4)       # unlabelled, rigid bodies, skeletons (, assets from 4.1)
    labelled = b"".join(struct.pack("<I3ffHf", m.id_num, *m.pos_m, m.size_m, m.flags, m.residual_mm)
                        for m in frame.labeled_markers)
    body += _sized(v, len(frame.labeled_markers), labelled)
    body += empty * 2                                     # force plates, devices
    body += struct.pack("<IId3QH", frame.timecode, frame.timecode_sub, frame.timestamp_s, *frame.stamps, frame.flags)
    return message(Message.FRAMEOFDATA, body)


@dataclass(frozen=True)
class MarkerFrame:
    """What the bridge takes from a NAT_FRAMEOFDATA: its frame number, each marker set's positions (M, 3) [m] by the
    set's name, and the frame's timestamp [s]."""

    frame_number: int
    marker_sets: dict[str, np.ndarray]
    timestamp_s: float


def read_marker_frame(body: bytes, version: tuple[int, ...]) -> MarkerFrame | None:
    """The marker sets and timestamp of a NAT_FRAMEOFDATA ``body`` (after its 4-byte header), in ``version``'s layout.
    From 4.1 on every list carries its size in bytes: only the marker sets are read and the other lists are stepped
    over (~10 us, against ~270 us for ``natnet``'s parse of every list into Python objects, on the capture -> joint
    command path). None before 4.1, or where the sizes do not fit the body: the caller then parses it in full."""
    if (tuple(version) + (0, 0, 0))[:4] < SIZED_FROM:       # natnet truncates a version it switched to: (4, 1)
        return None
    data = bytes(body)
    try:
        (frame_number,), (count, size) = struct.unpack_from("<I", data), _COUNT_SIZE.unpack_from(data, 4)
        at, end, sets = 12, 12 + size, {}
        for _ in range(count):
            nul = data.index(b"\0", at, end)
            (n,) = struct.unpack_from("<I", data, nul + 1)
            pos = np.frombuffer(data, "<f4", 3 * n, nul + 5).reshape(n, 3)
            sets[data[at:nul].decode()] = pos.astype(float)
            at = nul + 5 + 12 * n
        if at != end:
            return None
        for _ in range(LISTS_AFTER_MARKER_SETS):
            at += _COUNT_SIZE.size + _COUNT_SIZE.unpack_from(data, at)[1]
        (timestamp_s,) = struct.unpack_from("<d", data, at + 8)        # after the timecode and its subframe
    except (struct.error, ValueError, UnicodeDecodeError):
        return None
    return MarkerFrame(frame_number, sets, timestamp_s)


def capture_frame(frame: DataFrame, names: list[str], set_name: str, axes: np.ndarray = Y_UP, model_id: int = 1,
                  stamps: tuple[int, int, int] = (0, 0, 0)) -> NatNetFrame:
    """A recording's frame (markers [mm] in its axes, NaN where missing) as Motive streams it: one marker set of
    ``names`` in metres rotated by ``axes`` (missing markers at 0, 0, 0), the seen markers again as labelled
    markers (id ``model_id << 16 | index + 1``, residual [mm]), timestamp [s] from the frame's [us]."""
    mm = np.asarray(frame.markers_mm, float).reshape(-1, 3)
    if len(mm) != len(names):
        raise InputError(f"frame {frame.frame_number}: {len(mm)} markers for {len(names)} names")
    pos = (mm * 1e-3) @ np.asarray(axes, float).T
    seen = np.all(np.isfinite(pos), axis=1)
    pos[~seen] = 0.0
    res = frame.residuals_mm if frame.residuals_mm is not None else np.zeros(len(mm))
    labelled = [LabeledMarker((model_id << 16) | (i + 1), tuple(float(c) for c in pos[i]),
                              residual_mm=float(res[i]) if np.isfinite(res[i]) else 0.0)
                for i in np.flatnonzero(seen)]
    return NatNetFrame(frame.frame_number, [(set_name, pos)], labelled, frame.timestamp_us * 1e-6, stamps=stamps)
