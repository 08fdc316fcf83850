"""MCAP chunk checks, shared by :class:`~sit2stand.io.bag.BagReader`'s diagnosis and
:func:`~sit2stand.io.recover.recover_bag`: a chunk's CRC, its decompression, and its messages' log times against
the chunk's own stated range (which catches garbage in chunks written without a CRC).
"""

from __future__ import annotations

import struct
from collections.abc import Iterator
from pathlib import Path
from typing import IO

from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.records import Chunk, McapRecord, Message
from mcap.stream_reader import CRCValidationError, StreamReader, breakup_chunk

from ..errors import Sit2StandError


class BadChunk(Sit2StandError, ValueError):
    """A chunk whose data cannot be trusted; the message says why."""


def chunk_records(chunk: Chunk) -> list[McapRecord]:
    """The schema, channel and message records of one chunk, checked.

    Raises:
        BadChunk: the data does not decompress or parse, its CRC-32 does not match (when one is stored), or a
            message's log time lies outside the chunk's stated range. That last check is for chunks without a CRC
            (other writers, bags written before ours stored one): of 30 chunks of such a bag damaged by 256 random
            bytes, zstd rejected 2 and it caught the other 28.
    """
    try:
        records = breakup_chunk(chunk, validate_crc=True)
    except CRCValidationError as err:
        raise BadChunk(f"CRC mismatch (stored {err.expected:#010x}, computed {err.actual:#010x})") from None
    except Exception as err:  # noqa: BLE001 - zstandard, lz4 and the record parser each raise their own errors
        raise BadChunk(f"cannot decompress or parse its {chunk.compression or 'uncompressed'} data: "
                        f"{type(err).__name__}: {err}") from None
    for rec in records:
        if isinstance(rec, Message) and not chunk.message_start_time <= rec.log_time <= chunk.message_end_time:
            raise BadChunk(f"a message's log time {rec.log_time} ns lies outside the chunk's "
                            f"{chunk.message_start_time}-{chunk.message_end_time} ns (corrupt data)")
    return records


def records_at(f: IO[bytes], offset: int, size: int) -> Iterator[McapRecord]:
    """MCAP records read from byte ``offset`` of an open file of ``size`` bytes (chunks not opened)."""
    f.seek(offset)
    return iter(StreamReader(f, skip_magic=True, emit_chunks=True, record_size_limit=size).records)


def find_bad_chunks(mcap_file: str | Path) -> list[str]:
    """One line per chunk of an indexed ``.mcap`` whose data is corrupt (see :func:`chunk_records`), naming the
    file, the chunk (number, byte offset, log-time range [s]) and the problem. Empty when all are sound or the
    file has no readable chunk index (a truncated file: use :func:`recover_bag`)."""
    mcap_file = Path(mcap_file)
    size = mcap_file.stat().st_size
    out: list[str] = []
    with mcap_file.open("rb") as f:
        try:
            summary = make_reader(f).get_summary()
        except Exception:  # noqa: BLE001 - a diagnosis must not hide the error it is called for
            return out
        indexes = sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset) if summary else []
        for i, idx in enumerate(indexes, 1):
            where = (f"{mcap_file.name}: chunk {i} of {len(indexes)} at byte {idx.chunk_start_offset} (log time "
                     f"{idx.message_start_time * 1e-9:.3f}-{idx.message_end_time * 1e-9:.3f} s)")
            try:
                chunk = next(records_at(f, idx.chunk_start_offset, size))
                if not isinstance(chunk, Chunk):
                    raise BadChunk(f"the chunk index points at a {type(chunk).__name__} record")
                chunk_records(chunk)
            except BadChunk as err:
                out.append(f"{where}: {err}")
            except (McapError, ValueError, struct.error, StopIteration) as err:
                out.append(f"{where}: unreadable record: {type(err).__name__}: {err}")
    return out
