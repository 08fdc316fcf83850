"""The storage under :class:`~sit2stand.io.bag.BagWriter`: rosbags' MCAP writer, with three differences that rosbags
0.11.9 has no option for (all else is rosbags' code):

* chunk CRCs (it stores 0: 256 random bytes put at 40 places of bags/natural as written that way made rosbags read
  fewer messages, without an error, 28 times);
* schema and channel records in the data section instead of inside the chunk that happens to be open (a corrupt or
  lost chunk no longer takes the channels of every later message with it);
* ``ros_distro: jazzy`` instead of ``rosbags`` in the metadata.

The summary's chunk index is held packed until the bag closes (a recorder runs for hours).
"""

from __future__ import annotations

import re
import struct
import zlib
from array import array
from io import BytesIO
from typing import ClassVar

from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.rosbag2.storage_mcap import McapWriter

ROS_DISTRO = "jazzy"
# A Chunk record: opcode (1 byte), record length (8), message start and end time (8 + 8), uncompressed size (8),
# then the uncompressed CRC-32 (4).
_CHUNK_CRC_OFFSET = 1 + 8 + 8 + 8 + 8


def _with_distro(metadata_yaml: str) -> str:
    """rosbag2 metadata text with the ``ros_distro`` rosbags writes (``rosbags``) replaced by :data:`ROS_DISTRO`."""
    return re.sub(r"^( *)ros_distro: rosbags$", rf"\1ros_distro: {ROS_DISTRO}", metadata_yaml, count=1,
                  flags=re.MULTILINE)


class _McapStorage(McapWriter):
    def add_msgtype(self, connection) -> None:
        self._outside_chunk(super().add_msgtype, connection)

    def add_connection(self, connection, offered_qos_profiles: str) -> None:
        self._outside_chunk(super().add_connection, connection, offered_qos_profiles)

    def _outside_chunk(self, add, *args) -> None:
        # rosbags writes the record to the pending chunk's buffer; point that buffer at the file for the call. The
        # file is always at a record boundary here: chunks reach it whole, in close_chunk().
        pending, self.chunk.bio = self.chunk.bio, self.bio
        try:
            add(*args)
        finally:
            self.chunk.bio = pending

    def close_chunk(self) -> None:
        crc = zlib.crc32(self.chunk.bio.getvalue())
        start = self.bio.tell()
        super().close_chunk()
        end = self.bio.tell()
        self.bio.seek(start + _CHUNK_CRC_OFFSET)
        self.bio.write(struct.pack("<I", crc))
        self.bio.seek(end)
        self._pack_chunk_index()

    def _pack_chunk_index(self) -> None:
        # The summary's chunk index stays in memory until close(); rosbags keeps one BytesIO per chunk (~0.3 kB in
        # Python objects), a recorder flushing twice a second gathered ~1 MB an hour. Packed, ~0.10 kB per chunk.
        if not hasattr(self, "_index_bytes"):
            self._index_bytes, self._index_ends = bytearray(), array("Q")
        self._index_bytes += self.chunks.pop().getbuffer()
        self._index_ends.append(len(self._index_bytes))

    def _unpack_chunk_index(self) -> None:
        begin = 0
        for end in getattr(self, "_index_ends", ()):
            record = BytesIO(self._index_bytes[begin:end])
            record.seek(0, 2)               # rosbags reads a record's length from its position
            self.chunks.append(record)
            begin = end

    def flush_chunk(self) -> None:
        """Close the pending chunk (if it holds anything) and push the file to the OS."""
        if self.chunk.bio.tell():
            self.close_chunk()
        self.bio.flush()

    def close(self, version: int, metadata: str) -> None:
        if self.chunk.bio.tell():       # the last chunk joins the packed index before rosbags writes the summary
            self.close_chunk()
        self._unpack_chunk_index()
        super().close(version, _with_distro(metadata))


class RosbagsWriter(Writer):
    STORAGE_PLUGINS: ClassVar = {**Writer.STORAGE_PLUGINS, StoragePlugin.MCAP: _McapStorage}

    def close(self) -> None:
        super().close()
        self.metapath.write_text(_with_distro(self.metapath.read_text()))
