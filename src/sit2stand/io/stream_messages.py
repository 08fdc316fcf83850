"""Stream messages as serialized bytes where their names do not change: the bridge's MocapFrame and ForcePlateSample,
the robot's state (JointState and the stamped geometry messages) and the human skeleton's joint angles.

The mocap bridge publishes a 200 Hz marker frame and, per frame, ten samples of each 2 kHz plate. Built as rosbags
objects and serialized by rosbags, that cost ~1.3 ms of a frame's 5 ms on the 2-core host (profiled: the plates'
20 messages most of it), all on the bridge's receiving thread. The marker names, plate name and frame id are fixed
for a connection, so each encoder lays out their CDR bytes once and a message only writes its numbers into a copy
(as :mod:`sit2stand.io.tf_message` does for ``/tf``). The driver publishes five state messages 500 times a second:
built as rclpy objects and serialized by rclpy they took ~40 % of its process, as much as the simulation (py-spy,
live graph). Subscribers, recorders and tools see ordinary messages;
``tests/test_stream_messages.py`` checks the bytes against rosbags' serialization.

Layout (XCDR1 little endian, as Fast DDS writes it; offsets from the end of the 4-byte encapsulation header, each
primitive aligned to its size, padding zero): header (int32 sec, uint32 nanosec, frame_id string: uint32 length
including the NUL, characters, NUL), then the message's own fields in order.
"""

from __future__ import annotations

import struct

import numpy as np

from .tf_message import CdrLayout


def _header(frame_id: str) -> CdrLayout:
    """A layout opening with a std_msgs/Header: the stamp (written per message) and ``frame_id``."""
    lay = CdrLayout()
    lay.buf.extend(b"\x00" * 8)
    lay.string(frame_id)
    return lay


def _named(frame_id: str, names: list[str]) -> CdrLayout:
    """A layout opening with a std_msgs/Header and a string sequence: the marker or joint ``names``."""
    lay = _header(frame_id)
    lay.uint32(len(names))
    for name in names:
        lay.string(name)
    return lay


def _float64_slot(lay: CdrLayout, count: int) -> int:
    """Lay out a float64 sequence of ``count`` zeros; where its numbers start."""
    lay.uint32(count)
    if count:
        lay.align(8)
    at = len(lay.buf)
    lay.buf.extend(b"\x00" * (8 * count))
    return at


def _with_arrays(template: bytes, t_ns: int, slots: list[int], arrays, n: int) -> bytes:
    """``template`` stamped ``t_ns`` with each (n,) array of ``arrays`` written at its slot."""
    buf = bytearray(template)
    buf[4:12] = _stamp(t_ns)
    for at, values in zip(slots, arrays, strict=True):
        buf[at:at + 8 * n] = np.asarray(values, "<f8").reshape(n).tobytes()
    return bytes(buf)


def _stamp(t_ns: int) -> bytes:
    t_ns = int(t_ns)
    return struct.pack("<iI", t_ns // 1_000_000_000, t_ns % 1_000_000_000)


class MocapFrameEncoder:
    """Serialized sit2stand_msgs/MocapFrame of the markers ``names`` in frame ``frame_id``."""

    def __init__(self, names: list[str], frame_id: str) -> None:
        self.names = list(names)
        n = len(self.names)
        lay = _named(frame_id, self.names)
        lay.uint32(n)
        lay.align(8)
        self._positions = len(lay.buf)
        lay.buf.extend(b"\x00" * (24 * n))
        lay.uint32(n)
        self._valid = len(lay.buf)
        lay.buf.extend(b"\x00" * n)
        lay.uint32(n)
        self._residuals = len(lay.buf)
        lay.buf.extend(b"\x00" * (4 * n))
        self._template = bytes(lay.buf)

    def encode(self, t_ns: int, positions_m: np.ndarray, valid: np.ndarray, residuals_m: np.ndarray | None = None
               ) -> bytes:
        """The frame stamped ``t_ns``: positions (M, 3) [m] (NaN where ``valid`` is false, whatever they hold),
        valid (M,), residuals (M,) [m] (NaN: none)."""
        n = len(self.names)
        ok = np.asarray(valid, bool)
        pos = np.where(ok[:, None], np.asarray(positions_m, float), np.nan)
        res = np.full(n, np.nan, np.float32) if residuals_m is None else np.asarray(residuals_m, np.float32)
        buf = bytearray(self._template)
        buf[4:12] = _stamp(t_ns)
        buf[self._positions:self._positions + 24 * n] = pos.astype("<f8").tobytes()
        buf[self._valid:self._valid + n] = ok.astype(np.uint8).tobytes()
        buf[self._residuals:self._residuals + 4 * n] = res.astype("<f4").tobytes()
        return bytes(buf)


class PlateSampleEncoder:
    """Serialized sit2stand_msgs/ForcePlateSample of the plate ``plate_name`` in frame ``frame_id``."""

    def __init__(self, plate_name: str, frame_id: str) -> None:
        lay = _header(frame_id)
        lay.string(plate_name)
        lay.align(8)
        self._numbers = len(lay.buf)              # wrench (force, torque) and cop: nine float64
        lay.buf.extend(b"\x00" * 72)
        self._valid = len(lay.buf)
        lay.buf.extend(b"\x00")
        lay.align(8)
        self._free_moment = len(lay.buf)
        lay.buf.extend(b"\x00" * 8)
        self._template = bytes(lay.buf)

    def encode_many(self, t_ns: np.ndarray, force_n: np.ndarray, moment_origin_nm: np.ndarray, cop_m: np.ndarray,
                    cop_valid: np.ndarray, free_moment_nm: np.ndarray) -> list[bytes]:
        """One message per sample: stamps (K,) [ns], force (K, 3) [N], moment about the lab origin (K, 3) [N m],
        COP (K, 3) [m] and free moment (K,) [N m], both NaN where ``cop_valid`` (K,) is false."""
        ok = np.asarray(cop_valid, bool)
        numbers = np.hstack([force_n, moment_origin_nm, np.where(ok[:, None], cop_m, np.nan)]).astype("<f8")
        free = np.where(ok, free_moment_nm, np.nan).astype("<f8")
        out = []
        a, v, f = self._numbers, self._valid, self._free_moment
        for k in range(len(ok)):
            buf = bytearray(self._template)
            buf[4:12] = _stamp(t_ns[k])
            buf[a:a + 72] = numbers[k].tobytes()
            buf[v] = int(ok[k])
            buf[f:f + 8] = free[k].tobytes()
            out.append(bytes(buf))
        return out


class JointStateEncoder:
    """Serialized sensor_msgs/JointState of the joints ``names`` in frame ``frame_id``: position, velocity and effort
    each of len(names) (or all empty, as a message that carries none)."""

    def __init__(self, names: list[str], frame_id: str, fields: tuple[str, ...] = ("position", "velocity", "effort")
                 ) -> None:
        self.names = list(names)
        self.fields = fields
        n = len(self.names)
        lay = _named(frame_id, self.names)
        self._arrays = []
        for field in ("position", "velocity", "effort"):
            at = _float64_slot(lay, n if field in fields else 0)
            if field in fields:
                self._arrays.append(at)
        self._template = bytes(lay.buf)

    def encode(self, t_ns: int, *arrays: np.ndarray) -> bytes:
        """The state stamped ``t_ns``: one (N,) array per field of ``fields``, in that order [rad, rad/s, N m]."""
        return _with_arrays(self._template, t_ns, self._arrays, arrays, len(self.names))


class StampedNumbersEncoder:
    """Serialized stamped geometry messages whose body is ``count`` float64 in order after the header: PointStamped
    (3: x y z), WrenchStamped (6: force, torque), PoseStamped (7: position, orientation x y z w)."""

    POINT, WRENCH, POSE = 3, 6, 7

    def __init__(self, frame_id: str, count: int) -> None:
        lay = _header(frame_id)
        lay.align(8)
        self._numbers, self.count = len(lay.buf), count
        lay.buf.extend(b"\x00" * (8 * count))
        self._template = bytes(lay.buf)

    def encode(self, t_ns: int, numbers: np.ndarray) -> bytes:
        """The message stamped ``t_ns`` holding ``numbers`` (count,)."""
        buf = bytearray(self._template)
        buf[4:12] = _stamp(t_ns)
        buf[self._numbers:] = np.asarray(numbers, "<f8").reshape(self.count).tobytes()
        return bytes(buf)


class JointTrajectoryEncoder:
    """Serialized trajectory_msgs/JointTrajectory of one point for the joints ``names`` (a joint command): positions,
    velocities and accelerations, no effort, ``time_from_start`` zero. The retargeter sends one per command (100 Hz,
    in its real-time thread)."""

    def __init__(self, names: list[str], frame_id: str) -> None:
        self.names = list(names)
        n = len(self.names)
        lay = _named(frame_id, self.names)
        lay.uint32(1)                                   # one point
        self._arrays = [_float64_slot(lay, n) for _ in ("positions", "velocities", "accelerations")]
        lay.uint32(0)                                   # effort
        lay.buf.extend(b"\x00" * 8)                     # time_from_start: int32 sec, uint32 nanosec (aligned)
        self._template = bytes(lay.buf)

    def encode(self, t_ns: int, positions: np.ndarray, velocities: np.ndarray, accelerations: np.ndarray) -> bytes:
        """The command stamped ``t_ns`` [rad, rad/s, rad/s^2], each (N,)."""
        return _with_arrays(self._template, t_ns, self._arrays, (positions, velocities, accelerations),
                            len(self.names))


def stamp_and_frame_end(data: bytes) -> tuple[int, int]:
    """The header's stamp [ns] of serialized ``data`` and the offset just after its frame_id (where the message's own
    fields begin, before their alignment)."""
    sec, nsec, length = struct.unpack_from("<iII", data, 4)
    return sec * 1_000_000_000 + nsec, 16 + length


def pose_from_cdr(data: bytes) -> tuple[int, np.ndarray]:
    """Stamp [ns] and the 7 numbers (position x y z, orientation x y z w) of a serialized PoseStamped."""
    t_ns, end = stamp_and_frame_end(data)
    end += -(end - 4) % 8
    return t_ns, np.frombuffer(data, "<f8", 7, end).copy()


def _string_sequence(data: bytes, at: int) -> tuple[list[str], int]:
    """The string[] whose length field is at offset ``at`` (4-aligned) of serialized ``data``, and the offset just
    after it."""
    (n,) = struct.unpack_from("<I", data, at)
    at, names = at + 4, []
    for _ in range(n):
        at += -(at - 4) % 4
        (length,) = struct.unpack_from("<I", data, at)
        names.append(data[at + 4:at + 3 + length].decode())
        at += 4 + length
    return names, at


class JointStateReader:
    """Positions out of serialized sensor_msgs/JointState messages without building them. A message's joint names
    are read once and compared as bytes afterwards: a publisher's names rarely change."""

    def __init__(self) -> None:
        self._names_bytes = b""
        self.names: list[str] = []
        self._positions_at = 0

    def read(self, data: bytes) -> tuple[int, np.ndarray]:
        """Stamp [ns] and positions (N,) [rad] in the message's own joint order (``names``)."""
        t_ns, end = stamp_and_frame_end(data)
        n_at = end + (-(end - 4) % 4)
        if data[n_at:self._positions_at] != self._names_bytes or not self._names_bytes:
            self._layout(data, n_at)
        n = len(self.names)
        return t_ns, np.frombuffer(data, "<f8", n, self._positions_at).copy()

    def _layout(self, data: bytes, n_at: int) -> None:
        names, at = _string_sequence(data, n_at)
        n = len(names)
        at += -(at - 4) % 4
        (count,) = struct.unpack_from("<I", data, at)
        if count != n:
            raise ValueError(f"JointState with {n} names and {count} positions")
        at += 4
        if n:
            at += -(at - 4) % 8
        self.names, self._positions_at = names, at
        self._names_bytes = data[n_at:at]


class MocapFrameReader:
    """Arrays out of serialized sit2stand_msgs/MocapFrame messages without building them (~5 us a frame against
    ~95 us for the rclpy message and its arrays, at the head of the live graph's path). The marker names are read
    once and compared as bytes afterwards: a capture's labels rarely change."""

    def __init__(self) -> None:
        self._names_bytes = b""
        self.names: list[str] = []
        self._names_end = 0

    def read(self, data: bytes) -> tuple[int, list[str], np.ndarray, np.ndarray]:
        """Stamp [ns], marker names, positions (M, 3) [m] (NaN where invalid) and validity (M,) of a frame.

        Raises:
            ValueError: the frame is cut short, or its arrays do not have one entry per marker name.
        """
        try:
            return self._read(data)
        except struct.error as err:
            raise ValueError(f"MocapFrame cut short ({len(data)} bytes): {err}") from None

    def _read(self, data: bytes) -> tuple[int, list[str], np.ndarray, np.ndarray]:
        t_ns, end = stamp_and_frame_end(data)
        n_at = end + (-(end - 4) % 4)
        if data[n_at:self._names_end] != self._names_bytes or not self._names_bytes:
            self.names, self._names_end = _string_sequence(data, n_at)
            self._names_bytes = data[n_at:self._names_end]
        n = len(self.names)
        at = self._names_end + (-(self._names_end - 4) % 4)
        (count,) = struct.unpack_from("<I", data, at)
        at += 4
        if count:
            at += -(at - 4) % 8
        pos = np.frombuffer(data, "<f8", 3 * count, at).reshape(count, 3).copy()
        at += 24 * count
        at += -(at - 4) % 4
        (n_valid,) = struct.unpack_from("<I", data, at)
        valid = np.frombuffer(data, np.uint8, n_valid, at + 4).astype(bool)
        if count != n or n_valid != n:
            raise ValueError(f"MocapFrame with {n} marker names, {count} positions and {n_valid} validity flags")
        pos[~valid] = np.nan
        return t_ns, self.names, pos, valid


class CenterOfMassEncoder:
    """Serialized sit2stand_msgs/CenterOfMass from one ``source`` in frame ``frame_id`` (the estimator's per marker
    frame, the retargeter's planned COM per command)."""

    def __init__(self, source: str, frame_id: str) -> None:
        lay = _header(frame_id)
        lay.align(8)
        self._vectors = len(lay.buf)
        lay.buf.extend(b"\x00" * (8 * 9))               # position, velocity, acceleration
        lay.string(source)
        self._valid = len(lay.buf)
        lay.buf.extend(b"\x00")
        lay.align(8)
        self._quality = len(lay.buf)
        lay.buf.extend(b"\x00" * 20)                    # marker_rms_m, cop_error_m (float64), n_markers (uint32)
        self._template = bytes(lay.buf)

    def encode(self, t_ns: int, position_m: np.ndarray, velocity_mps: np.ndarray = (0.0, 0.0, 0.0),
               acceleration_mps2: np.ndarray = (0.0, 0.0, 0.0), valid: bool = True,
               marker_rms_m: float = float("nan"), cop_error_m: float = float("nan"), n_markers: int = 0) -> bytes:
        """The estimate stamped ``t_ns`` (see the message's fields)."""
        buf = bytearray(self._template)
        buf[4:12] = _stamp(t_ns)
        buf[self._vectors:self._vectors + 72] = np.concatenate(
            [np.asarray(v, "<f8").reshape(3) for v in (position_m, velocity_mps, acceleration_mps2)]).tobytes()
        buf[self._valid] = 1 if valid else 0
        buf[self._quality:] = struct.pack("<ddI", marker_rms_m, cop_error_m, n_markers)
        return bytes(buf)
