"""The Qualisys Track Manager (QTM) real-time protocol, version 1.x, little-endian port: encoder and decoder.

As documented by Qualisys ("QTM RT protocol", Real-Time-Protocol-Documentation, version 1.25). Every packet is an
8-byte header (uint32 size including the header, uint32 type) and a body:

* 0 Error, 1 Command, 2 XML: a NUL-terminated ASCII string (the server's welcome, without a full stop, is
  ``QTM RT Interface connected``; qtm-rt matches it exactly);
* 3 Data: int64 timestamp [us from the start of the measurement], uint32 frame number, uint32 component count,
  then components, each with its own 8-byte header (size, type);
* 4 No More Data (header only), 6 Event (one byte: the event number).

Components written here:

* Component3d (1) / Component3dRes (9): uint32 marker count, uint16 2D drop rate, uint16 2D out-of-sync rate
  [per mille], then per *label* (the order of the XML ``The_3D`` labels) float32 x y z [mm] (+ float32 residual
  [mm]); a marker missing from the frame has all bits set (a negative quiet NaN);
* Component3dNoLabels (2): as 3D with an int32 id after each position;
* ComponentForce (4): int32 plate count, per plate int32 plate id (from 1), int32 force count, int32 force number
  (index of the first sample at the plate's own rate), then per sample float32 force x y z [N], moment x y z
  [N m], application point x y z [mm];
* ComponentForceSingle (15): per plate int32 id and one sample.

The force data are given in the capture system's global axes, the moment about the plate's surface centre (the
centre of its four ``Location`` corners): QTM's force output in world coordinates.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field
from enum import IntEnum
from xml.etree import ElementTree

import numpy as np

from ..errors import InputError

PROTOCOL_VERSION = "1.25"
"""The protocol version our server speaks (qtm-rt 3.1 asks for it); 1.8 to 1.25 are accepted."""
OLDEST_VERSION = (1, 8)
WELCOME = "QTM RT Interface connected"
HEADER = struct.Struct("<II")
DATA_HEADER = struct.Struct("<qII")
FORCE_SAMPLE = struct.Struct("<9f")
MISSING = struct.unpack("<f", b"\xff\xff\xff\xff")[0]     # all bits set: QTM's missing-marker NaN


class PacketType(IntEnum):
    """QTM RT packet types."""

    ERROR = 0
    COMMAND = 1
    XML = 2
    DATA = 3
    NO_MORE_DATA = 4
    EVENT = 6


class Component(IntEnum):
    """QTM RT data component types (the ones a marker-and-plate stream uses)."""

    THREE_D = 1
    THREE_D_NO_LABELS = 2
    FORCE = 4
    THREE_D_RES = 9
    FORCE_SINGLE = 15


class Event(IntEnum):
    """QTM RT event numbers used here."""

    RT_FROM_FILE_STARTED = 8
    RT_FROM_FILE_STOPPED = 9
    QTM_SHUTTING_DOWN = 12


COMPONENT_NAMES = {"3d": Component.THREE_D, "3dres": Component.THREE_D_RES,
                   "3dnolabels": Component.THREE_D_NO_LABELS, "force": Component.FORCE,
                   "forcesingle": Component.FORCE_SINGLE}


class ProtocolError(InputError):
    """A packet or command that does not follow the QTM RT protocol; the message names what was wrong."""


# --- packets ------------------------------------------------------------------------------------------------------
def packet(kind: PacketType, body: bytes = b"") -> bytes:
    """One packet: the 8-byte header and ``body``."""
    return HEADER.pack(HEADER.size + len(body), int(kind)) + body


def string_packet(kind: PacketType, text: str) -> bytes:
    """An error, command or XML packet: ``text`` NUL-terminated, as the server sends them."""
    return packet(kind, text.encode() + b"\0")


def event_packet(event: Event) -> bytes:
    """An event packet (one byte)."""
    return packet(PacketType.EVENT, bytes([int(event)]))


def split_packets(buffer: bytes) -> tuple[list[tuple[PacketType, bytes]], bytes]:
    """The whole packets at the start of a TCP stream buffer, as (type, body), and the rest (an incomplete one)."""
    out = []
    while len(buffer) >= HEADER.size:
        size, kind = HEADER.unpack_from(buffer)
        if size < HEADER.size:
            raise ProtocolError(f"packet size {size} is smaller than its 8-byte header")
        if len(buffer) < size:
            break
        try:
            out.append((PacketType(kind), buffer[HEADER.size:size]))
        except ValueError:
            raise ProtocolError(f"unknown packet type {kind}") from None
        buffer = buffer[size:]
    return out, buffer


def text_of(body: bytes) -> str:
    """The string of an error, command or XML packet body (the NUL terminator is optional from clients)."""
    return body.rstrip(b"\0").decode(errors="replace")


# --- data packets -------------------------------------------------------------------------------------------------
@dataclass
class PlateChunk:
    """One plate's force samples in one data packet: id (from 1), the first sample's number at the plate's rate,
    and (K, 9) float samples: force [N], moment about the surface centre [N m], application point [mm]."""

    plate_id: int
    first_sample: int
    samples: np.ndarray


@dataclass
class DataFrame:
    """One data packet's content: timestamp [us], frame number, labelled markers (M, 3) [mm] with NaN where
    missing, their residuals (M,) [mm], and the plates' samples."""

    timestamp_us: int
    frame_number: int
    markers_mm: np.ndarray
    residuals_mm: np.ndarray | None = None
    plates: list[PlateChunk] = field(default_factory=list)


def _component(kind: Component, body: bytes) -> bytes:
    return HEADER.pack(HEADER.size + len(body), int(kind)) + body


def _markers_body(frame: DataFrame, kind: Component) -> bytes:
    xyz = np.where(np.isfinite(frame.markers_mm), frame.markers_mm, MISSING).astype("<f4")
    head = struct.pack("<IHH", len(xyz), 0, 0)
    if kind == Component.THREE_D:
        return head + xyz.tobytes()
    if kind == Component.THREE_D_RES:
        res = frame.residuals_mm if frame.residuals_mm is not None else np.full(len(xyz), np.nan)
        return head + np.column_stack([xyz, res.astype("<f4")]).astype("<f4").tobytes()
    seen = np.all(np.isfinite(frame.markers_mm), axis=1)           # no labels: only the seen markers, with an id
    rows = np.zeros(int(seen.sum()), dtype=[("p", "<f4", 3), ("id", "<i4")])
    rows["p"], rows["id"] = xyz[seen], np.flatnonzero(seen) + 1
    return struct.pack("<IHH", len(rows), 0, 0) + rows.tobytes()


def _force_body(frame: DataFrame, single: bool) -> bytes:
    parts = [struct.pack("<i", len(frame.plates))]
    for chunk in frame.plates:
        samples = np.asarray(chunk.samples, "<f4").reshape(-1, 9)
        if single:
            last = samples[-1] if len(samples) else np.full(9, np.nan, "<f4")
            parts.append(struct.pack("<i", chunk.plate_id) + last.tobytes())
        else:
            parts.append(struct.pack("<iii", chunk.plate_id, len(samples), chunk.first_sample) + samples.tobytes())
    return b"".join(parts)


def data_packet(frame: DataFrame, components: list[Component]) -> bytes:
    """A data packet of ``frame`` holding ``components`` in that order."""
    body = []
    for kind in components:
        if kind in (Component.FORCE, Component.FORCE_SINGLE):
            body.append(_component(kind, _force_body(frame, kind == Component.FORCE_SINGLE)))
        else:
            body.append(_component(kind, _markers_body(frame, kind)))
    payload = DATA_HEADER.pack(int(frame.timestamp_us), int(frame.frame_number), len(body)) + b"".join(body)
    return packet(PacketType.DATA, payload)


def decode_data(body: bytes) -> DataFrame:
    """A data packet's body (after the 8-byte header) to a :class:`DataFrame` (3D, 3D residual and force
    components; others are skipped)."""
    ts, number, count = DATA_HEADER.unpack_from(body)
    frame = DataFrame(ts, number, np.zeros((0, 3)))
    pos = DATA_HEADER.size
    for _ in range(count):
        size, kind = HEADER.unpack_from(body, pos)
        _decode_component(frame, kind, body[pos + HEADER.size:pos + size])
        pos += size
    return frame


def _decode_component(frame: DataFrame, kind: int, data: bytes) -> None:
    if kind in (Component.THREE_D, Component.THREE_D_RES):
        (n,) = struct.unpack_from("<I", data)
        width = 4 if kind == Component.THREE_D_RES else 3
        rows = np.frombuffer(data, "<f4", n * width, 8).reshape(n, width).astype(float)
        frame.markers_mm = rows[:, :3]
        frame.residuals_mm = rows[:, 3] if width == 4 else None
    elif kind in (Component.FORCE, Component.FORCE_SINGLE):
        (n,) = struct.unpack_from("<i", data)
        pos = 4
        for _ in range(n):
            if kind == Component.FORCE:
                plate_id, k, first = struct.unpack_from("<iii", data, pos)
                pos += 12
            else:
                (plate_id,), k, first = struct.unpack_from("<i", data, pos), 1, -1
                pos += 4
            samples = np.frombuffer(data, "<f4", 9 * k, pos).reshape(k, 9).astype(float)
            pos += FORCE_SAMPLE.size * k
            frame.plates.append(PlateChunk(plate_id, first, samples))


# --- commands -----------------------------------------------------------------------------------------------------
@dataclass
class StreamRequest:
    """A parsed ``StreamFrames`` command: every n-th frame, an optional UDP destination, the components."""

    divisor: int
    components: list[Component]
    udp_port: int | None = None
    udp_address: str | None = None
    frequency_hz: float | None = None


def parse_version(text: str) -> tuple[int, int]:
    """(major, minor) of a ``Version n.n`` argument; ProtocolError if it is not one."""
    try:
        major, minor = (int(v) for v in text.split("."))
    except ValueError:
        raise ProtocolError(f"{text!r} is not a protocol version n.n") from None
    return major, minor


def parse_stream_frames(args: list[str]) -> StreamRequest:
    """The arguments of ``StreamFrames`` (after the command word), case-insensitive; ProtocolError names a bad
    one. ``Frequency:n`` is kept as a rate and turned into a divisor by the server."""
    if not args:
        raise ProtocolError("StreamFrames needs Stop or a frame selection and components")
    req = StreamRequest(1, [])
    for arg in args:
        low = arg.lower()
        if low == "allframes":
            continue
        if low.startswith("frequencydivisor:"):
            req.divisor = max(1, int(low.split(":")[1]))
        elif low.startswith("frequency:"):
            req.frequency_hz = float(low.split(":")[1])
        elif low.startswith("udp:"):
            parts = arg.split(":")[1:]
            req.udp_port = int(parts[-1])
            req.udp_address = parts[0] if len(parts) == 2 else None
            if not 1023 <= req.udp_port <= 65535:
                raise ProtocolError(f"UDP port {req.udp_port} is outside 1023..65535")
        elif low in COMPONENT_NAMES:
            req.components.append(COMPONENT_NAMES[low])
        else:
            raise ProtocolError(f"component {arg!r} is not served here (only {', '.join(COMPONENT_NAMES)})")
    if not req.components:
        raise ProtocolError("StreamFrames names no component")
    return req


# --- XML parameters -----------------------------------------------------------------------------------------------
@dataclass
class PlateInfo:
    """A force plate as the ``Force`` XML parameters describe it: id (from 1), name, sample rate [Hz], corners
    (4, 3) [mm] in the capture system's axes."""

    plate_id: int
    name: str
    rate_hz: float
    corners_mm: np.ndarray


def _sub(parent: ElementTree.Element, tag: str, text: object = None) -> ElementTree.Element:
    node = ElementTree.SubElement(parent, tag)
    if text is not None:
        node.text = str(text)
    return node


def parameters_xml(labels: list[str] | None, plates: list[PlateInfo] | None, frequency_hz: float,
                   version: str = PROTOCOL_VERSION, axis_up: str = "+Z") -> str:
    """The ``QTM_Parameters_Ver_<version>`` document with General (frequency), The_3D (labels) and/or Force
    (plates) elements; None leaves an element out."""
    root = ElementTree.Element(f"QTM_Parameters_Ver_{version}")
    general = _sub(root, "General")
    _sub(general, "Frequency", f"{frequency_hz:g}")
    if labels is not None:
        the_3d = _sub(root, "The_3D")
        _sub(the_3d, "AxisUpwards", axis_up)
        _sub(the_3d, "Labels", len(labels))
        for name in labels:
            _sub(_sub(the_3d, "Label"), "Name", name)
    if plates is not None:
        force = _sub(root, "Force")
        _sub(force, "Unit_Length", "mm")
        _sub(force, "Unit_Force", "N")
        for p in plates:
            plate = _sub(force, "Plate")
            for tag, value in (("Plate_ID", p.plate_id), ("Force_Plate_Index", p.plate_id),
                               ("Analog_Device_ID", p.plate_id), ("Frequency", f"{p.rate_hz:g}"),
                               ("Type", "C3D"), ("Name", p.name)):
                _sub(plate, tag, value)
            location = _sub(plate, "Location")
            for k, corner in enumerate(p.corners_mm, 1):
                c = _sub(location, f"Corner{k}")
                for axis, v in zip("XYZ", corner):
                    _sub(c, axis, repr(float(v)))
    return ElementTree.tostring(root, encoding="unicode")


def parse_labels(xml: str | bytes) -> list[str]:
    """The 3D labels (marker names) of a parameters document, in stream order; ProtocolError if it has none."""
    root = _parse(xml)
    the_3d = root.find("The_3D")
    if the_3d is None:
        raise ProtocolError("the parameters have no The_3D element (ask for GetParameters 3D)")
    return [(label.findtext("Name") or "").strip() for label in the_3d.findall("Label")]


def parse_plates(xml: str | bytes) -> list[PlateInfo]:
    """The force plates of a parameters document (empty if it has no Force element). Corners are converted to mm
    from ``Unit_Length``."""
    force = _parse(xml).find("Force")
    if force is None:
        return []
    scale = {"mm": 1.0, "cm": 10.0, "m": 1000.0}.get((force.findtext("Unit_Length") or "mm").strip(), 1.0)
    plates = []
    for p in force.findall("Plate"):
        pid = p.findtext("Plate_ID") or p.findtext("Force_Plate_Index") or "0"
        corners = [[float(p.findtext(f"Location/Corner{k}/{a}") or "nan") for a in "XYZ"] for k in range(1, 5)]
        plates.append(PlateInfo(int(pid), (p.findtext("Name") or "").strip(), float(p.findtext("Frequency") or 0),
                                np.array(corners) * scale))
    return plates


def parse_frequency(xml: str | bytes) -> float:
    """The capture frequency [Hz] of a parameters document's General element (NaN without one)."""
    text = _parse(xml).findtext("General/Frequency")
    return float(text) if text else float("nan")


def _parse(xml: str | bytes) -> ElementTree.Element:
    try:
        return ElementTree.fromstring(xml.rstrip(b"\0") if isinstance(xml, bytes) else xml)
    except ElementTree.ParseError as err:
        raise ProtocolError(f"the parameters are not valid XML: {err}") from None
