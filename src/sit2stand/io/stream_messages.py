"""MocapFrame and ForcePlateSample as serialized bytes for a live stream whose names do not change.

The mocap bridge publishes a 200 Hz marker frame and, per frame, ten samples of each 2 kHz plate. Built as rosbags
objects and serialized by rosbags, that cost ~1.3 ms of a frame's 5 ms on the 2-core host (profiled: the plates'
20 messages most of it), all on the bridge's receiving thread. The marker names, plate name and frame id are fixed
for a connection, so each encoder lays out their CDR bytes once and a message only writes its numbers into a copy
(as :mod:`sit2stand.io.tf_message` does for ``/tf``). Subscribers, recorders and tools see ordinary messages;
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


def _stamp(t_ns: int) -> bytes:
    t_ns = int(t_ns)
    return struct.pack("<iI", t_ns // 1_000_000_000, t_ns % 1_000_000_000)


class MocapFrameEncoder:
    """Serialized sit2stand_msgs/MocapFrame of the markers ``names`` in frame ``frame_id``."""

    def __init__(self, names: list[str], frame_id: str) -> None:
        self.names = list(names)
        n = len(self.names)
        lay = _header(frame_id)
        lay.uint32(n)
        for name in self.names:
            lay.string(name)
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
