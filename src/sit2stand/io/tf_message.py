"""tf2_msgs/TFMessage as serialized bytes, for a fixed list of (parent, child) frames: only numbers change.

A ``/tf`` message of a 32-joint robot (TALOS) holds 35 transforms. Building it as rclpy message objects costs ~300 us
and rclpy's serialization another ~140 us (measured on a 2-core host): 20 % of a core at 500 Hz, all in the driver's
control loop. The frames never change, so the CDR bytes are laid out once (:class:`TfEncoder`) and each message only
writes its stamps and seven float64 per transform into a copy of that template (~10 us); rclpy publishes bytes as they
are (``Publisher.publish(bytes)``) and subscribers, recorders and tools see an ordinary TFMessage.

Layout (XCDR1 little endian, as Fast DDS writes it): a 4-byte encapsulation header (``00 01 00 00``), then the
sequence length (uint32) and per geometry_msgs/TransformStamped: stamp (int32 sec, uint32 nanosec), frame_id and
child_frame_id (uint32 length including the NUL, the characters, NUL; 4-byte aligned), translation x y z and rotation
x y z w (float64, 8-byte aligned from the end of the encapsulation header). Padding bytes are zero.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence

import numpy as np

from ..errors import InputError

ENCAPSULATION_CDR_LE = b"\x00\x01\x00\x00"


class CdrLayout:
    """A growing XCDR1 little-endian buffer (after the encapsulation header): primitives aligned to their size from
    the end of the header, padding zero; the encoders record where their numbers go while laying it out."""

    def __init__(self) -> None:
        self.buf = bytearray(ENCAPSULATION_CDR_LE)

    def align(self, n: int) -> None:
        self.buf.extend(b"\x00" * (-(len(self.buf) - 4) % n))

    def uint32(self, value: int) -> None:
        self.align(4)
        self.buf.extend(struct.pack("<I", value))

    def string(self, s: str) -> None:
        """uint32 length including the NUL, the characters, NUL."""
        raw = s.encode()
        self.uint32(len(raw) + 1)
        self.buf.extend(raw + b"\x00")


class TfEncoder:
    """Serialized TFMessages of the transforms ``pairs`` ((parent, child) frame ids), in that order."""

    def __init__(self, pairs: Sequence[tuple[str, str]]) -> None:
        self.pairs = list(pairs)
        lay = CdrLayout()
        lay.uint32(len(self.pairs))
        stamps, values = [], []
        for parent, child in self.pairs:
            lay.align(4)
            stamps.append((len(lay.buf) - 4) // 4)
            lay.buf.extend(b"\x00" * 8)
            lay.string(parent)
            lay.string(child)
            lay.align(8)
            values.append((len(lay.buf) - 4) // 8)
            lay.buf.extend(struct.pack("<7d", 0, 0, 0, 0, 0, 0, 1))
        self._template = np.frombuffer(bytes(lay.buf), np.uint8)
        self._sec = np.array(stamps, int)             # uint32 index (from the end of the header) of each stamp
        self._val = np.array(values, int)[:, None] + np.arange(7)   # float64 indices of each transform's numbers
        self._pose = np.zeros((len(self.pairs), 7))

    def encode(self, stamp_ns: int, translations_m: np.ndarray, rotations_xyzw: np.ndarray) -> bytes:
        """The TFMessage, every transform stamped ``stamp_ns``: translations (N, 3) [m], rotations (N, 4) x y z w.

        Raises:
            InputError: arrays whose shapes do not match the frames.
        """
        n = len(self.pairs)
        if np.shape(translations_m) != (n, 3) or np.shape(rotations_xyzw) != (n, 4):
            raise InputError(f"TF of {n} transforms: translations {np.shape(translations_m)} and rotations "
                             f"{np.shape(rotations_xyzw)}, expected ({n}, 3) and ({n}, 4)")
        out = self._template.copy()
        body = out[4:]
        self._pose[:, :3] = translations_m
        self._pose[:, 3:] = rotations_xyzw
        body.view("<f8")[self._val] = self._pose
        sec, nsec = divmod(int(stamp_ns), 1_000_000_000)
        words = body.view("<u4")
        words[self._sec] = np.uint32(sec)
        words[self._sec + 1] = np.uint32(nsec)
        return out.tobytes()
