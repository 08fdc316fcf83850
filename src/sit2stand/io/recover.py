"""Recovery of a bag whose writer died (SIGKILL, power loss) or whose file was damaged.

A truncated .mcap has no summary or footer and there is no ``metadata.yaml``. Every complete record up to the cut
is kept, the messages of every chunk that decompresses and checks out included; a corrupt chunk is skipped and
reported. Records are read with ``mcap``'s own stream reader; what it cannot do (resume after an unreadable record)
is done here and commented where it is.
"""

from __future__ import annotations

import shutil
import struct
from dataclasses import dataclass, field
from pathlib import Path

import yaml
from typing import IO

from mcap.exceptions import McapError
from mcap.opcode import Opcode
from mcap.reader import make_reader
from mcap.records import Channel, Chunk, DataEnd, Footer, McapRecord, Message, Schema
from rosbags.rosbag2.metadata import parse_qos

from .bag import MCAP_MAGIC, BagError, BagWriter, register_definition
from .mcap_chunks import BadChunk, chunk_records, records_at

# ---------------------------------------------------------------------------------------------------------------
# Recovery of a bag whose writer died (SIGKILL, power loss) or whose file was damaged: a truncated .mcap has no
# summary/footer and there is no metadata.yaml. Every complete record up to the cut is kept, the messages of every
# chunk that decompresses and checks out included; a corrupt chunk is skipped and reported.
# ---------------------------------------------------------------------------------------------------------------

@dataclass
class RecoveryReport:
    """What :func:`recover_bag` found and kept. Times in ns."""

    source: Path
    output: Path
    messages: int = 0
    topics: dict[str, int] = field(default_factory=dict)
    bytes_read: int = 0
    bytes_total: int = 0
    stopped_because: str = ""
    first_ns: int | None = None
    last_ns: int | None = None
    chunks: int = 0                                           # chunks read and kept
    bad_chunks: list[str] = field(default_factory=list)      # one line per chunk skipped as corrupt
    bad_records: list[str] = field(default_factory=list)     # one line per other record skipped as unparseable
    orphaned: int = 0                                         # messages whose channel/schema was never readable

    def __str__(self) -> str:
        span = (self.last_ns - self.first_ns) * 1e-9 if self.messages else 0.0
        tops = ", ".join(f"{k} ({v})" for k, v in sorted(self.topics.items()))
        text = (f"recovered {self.messages} messages spanning {span:.3f} s from {self.source} "
                f"({self.bytes_read}/{self.bytes_total} bytes usable; {self.stopped_because}; {self.chunks} chunks "
                f"read, {len(self.bad_chunks)} skipped as corrupt) into {self.output}: {tops}")
        if self.orphaned:
            text += f"\n  dropped {self.orphaned} messages whose channel definition was lost"
        return "\n".join([text] + [f"  skipped {note}" for note in self.bad_chunks + self.bad_records])


@dataclass
class _Scan:
    """What a damaged ``.mcap`` still holds."""

    schemas: dict[int, Schema] = field(default_factory=dict)
    channels: dict[int, Channel] = field(default_factory=dict)
    messages: list[tuple[int, int, bytes]] = field(default_factory=list)   # (channel id, log time [ns], CDR bytes)
    chunk_offsets: list[int] = field(default_factory=list)   # where the summary says chunks start [bytes]

    def take(self, rec: McapRecord) -> None:
        if isinstance(rec, Message):
            self.messages.append((rec.channel_id, rec.log_time, rec.data))
        elif isinstance(rec, Schema):
            self.schemas[rec.id] = rec
        elif isinstance(rec, Channel):
            self.channels[rec.id] = rec


def _scan_mcap(f: IO[bytes], report: RecoveryReport) -> _Scan:
    """Read every record after the magic until the end of the file or a cut, skipping unreadable ones.

    The summary after DataEnd is read too: it repeats the schemas and channels, which matters when the chunk that
    held them is corrupt (files written before our writer put them in the data section).
    """
    scan = _Scan(chunk_offsets=_indexed_chunk_offsets(f))
    offset: int | None = len(MCAP_MAGIC)
    report.bytes_read = len(MCAP_MAGIC)
    report.stopped_because = "file ends on a record boundary (no summary)"
    while offset is not None:
        offset = _scan_from(f, offset, scan, report)
    return scan


def _scan_from(f: IO[bytes], offset: int, scan: _Scan, report: RecoveryReport) -> int | None:
    """Take the records from byte ``offset`` on; returns where to resume after an unreadable record (None: done).

    ``mcap``'s StreamReader stops for good at the first record it cannot parse, so a new one is started after it.
    """
    records = records_at(f, offset, report.bytes_total)
    while True:
        try:
            rec = next(records)
        except StopIteration:
            return None
        except (McapError, ValueError, struct.error) as err:
            return _skip_record(f, offset, err, scan, report)
        if isinstance(rec, Chunk):
            try:
                for inner in chunk_records(rec):
                    scan.take(inner)
                report.chunks += 1
            except BadChunk as err:
                report.bad_chunks.append(f"chunk at byte {offset}: {err}")
        elif isinstance(rec, (DataEnd, Footer)):
            report.stopped_because = "file was complete"
        else:
            scan.take(rec)
        offset = report.bytes_read = f.tell()


def _skip_record(f: IO[bytes], offset: int, err: Exception, scan: _Scan, report: RecoveryReport) -> int | None:
    """After ``err`` reading the record at ``offset``: where to resume, or None (a cut: nothing follows).

    A record whose length field is plausible is skipped (its body is what is corrupt). One whose length runs past
    the end of the file is a cut, unless the summary lists a chunk after it (a complete file with a corrupt length
    field): reading resumes at that chunk. Skipped records are listed in the report. mcap's reader has no such
    resumption: with 256 random bytes at byte 1000 of bags/natural (over a channel record and the length of the
    next one) it recovers 0 of the 8,976 messages; this recovers all of them.
    """
    f.seek(offset)
    head = f.read(9)
    end = offset + 9 + struct.unpack("<Q", head[1:])[0] if len(head) == 9 else report.bytes_total + 1
    try:
        kind = Opcode(head[0]).name.lower() if head else "?"
    except ValueError:
        kind = f"opcode {head[0]:#04x}"
    if end > report.bytes_total:
        later = [o for o in scan.chunk_offsets if o > offset]
        if not later:
            if report.stopped_because != "file was complete":
                report.stopped_because = _why_stopped(err, offset, report.bytes_total)
            return None
        end = later[0]
        note = f"{kind} record at byte {offset}: its length runs past the end of the file; resumed at the next chunk"
    else:
        note = f"{kind} record at byte {offset}: cannot parse: {type(err).__name__}: {err}"
    (report.bad_chunks if head[0] == Opcode.CHUNK else report.bad_records).append(note)
    return end


def _indexed_chunk_offsets(f: IO[bytes]) -> list[int]:
    """Byte offsets of the chunks the file's summary lists (empty when it has none or cannot be read)."""
    f.seek(0)  # mcap's reader takes the current position for the start of the file
    try:
        summary = make_reader(f).get_summary()
    except Exception:  # noqa: BLE001 - a truncated or damaged file: no index to resume from
        return []
    return sorted(c.chunk_start_offset for c in summary.chunk_indexes) if summary else []


def _why_stopped(err: Exception, offset: int, size: int) -> str:
    if offset == size:
        return "file ends on a record boundary (no summary)"
    return (f"file cut in the middle of the record at byte {offset} (or its length field is corrupt): "
            f"{type(err).__name__}")


def _add_recovered_topic(writer: BagWriter, channel: Channel, schemas: dict[int, Schema]) -> str | None:
    """Declare a channel found in the damaged file on ``writer``; None when its type cannot be rebuilt."""
    schema = schemas.get(channel.schema_id)
    if schema is None:
        return None
    if schema.name not in writer.store.fielddefs and not register_definition(
            writer.store, schema.data, schema.name):
        return None
    qos_text = channel.metadata.get("offered_qos_profiles", "")
    try:
        qos = parse_qos(qos_text) if qos_text else None
    except Exception:  # noqa: BLE001 - keep the topic with our default QoS
        qos = None
    try:
        writer.add_topic(channel.topic, schema.name, qos)
    except BagError:
        return None
    return channel.topic


def _surviving_custom_data(bag_dir: Path) -> dict[str, str]:
    """The ``custom_data`` of the bag's metadata.yaml, if it is there and readable (a killed recorder leaves none)."""
    try:
        doc = yaml.safe_load((bag_dir / "metadata.yaml").read_text()) or {}
        custom = doc["rosbag2_bagfile_information"].get("custom_data") or {}
        return {str(k): str(v) for k, v in custom.items()}
    except (OSError, KeyError, TypeError, AttributeError, yaml.YAMLError):
        return {}


def _write_recovered(scan: _Scan, out_dir: Path, source: Path, report: RecoveryReport) -> None:
    """Write the scanned messages as a complete bag at ``out_dir`` (sorted by log time, by BagWriter), with the
    damaged bag's own ``custom_data`` (the subject's stature and mass...) where its metadata.yaml survived."""
    custom = {**_surviving_custom_data(source.parent), "recovered_from": str(source)}
    with BagWriter(out_dir, custom_data=custom) as writer:
        topics = {cid: _add_recovered_topic(writer, ch, scan.schemas) for cid, ch in sorted(scan.channels.items())}
        for cid, t_ns, data in sorted(scan.messages, key=lambda m: m[1]):
            topic = topics.get(cid)
            if topic is None:
                report.orphaned += 1
                continue
            writer.write_raw(topic, t_ns, data)
            report.messages += 1
            report.topics[topic] = report.topics.get(topic, 0) + 1
            report.first_ns = t_ns if report.first_ns is None else min(report.first_ns, t_ns)
            report.last_ns = t_ns if report.last_ns is None else max(report.last_ns, t_ns)


def _install_recovered(tmp_dir: Path, out_dir: Path, mcap_file: Path) -> None:
    """Move the rebuilt bag from ``tmp_dir`` to ``out_dir``; in place, the damaged file stays as ``.damaged``."""
    bag_dir = mcap_file.parent
    if out_dir == bag_dir:
        mcap_file.replace(mcap_file.with_name(mcap_file.name + ".damaged"))
        (bag_dir / "metadata.yaml").unlink(missing_ok=True)
        new_mcap = next(tmp_dir.glob("*.mcap"))
        new_mcap.replace(bag_dir / f"{bag_dir.name}.mcap")
        meta = (tmp_dir / "metadata.yaml").read_text().replace(new_mcap.name, f"{bag_dir.name}.mcap")
        (bag_dir / "metadata.yaml").write_text(meta)
        shutil.rmtree(tmp_dir)
        return
    if out_dir.exists():
        raise BagError(f"{out_dir}: exists already; not overwriting")
    tmp_dir.rename(out_dir)
    new_mcap = next(out_dir.glob("*.mcap"))
    target = out_dir / f"{out_dir.name}.mcap"
    if new_mcap != target:
        new_mcap.replace(target)
        meta = (out_dir / "metadata.yaml").read_text().replace(new_mcap.name, target.name)
        (out_dir / "metadata.yaml").write_text(meta)


def recover_bag(path: str | Path, output: str | Path | None = None) -> RecoveryReport:
    """Rebuild a complete bag from a truncated or damaged rosbag2 ``.mcap`` (e.g. a recorder killed with SIGKILL).

    Records are read with ``mcap``'s StreamReader up to the cut; chunks that fail to decompress, fail their CRC or
    hold impossible log times are skipped and listed in the report, the others kept.

    Args:
        path: the damaged bag directory (or the ``.mcap`` file itself).
        output: where to write the rebuilt bag; default: the same directory, rebuilt in place (the damaged file is
            kept beside it as ``<name>.mcap.damaged``).

    Returns:
        A :class:`RecoveryReport` (counts per topic, chunks kept and skipped, where and why reading stopped).

    Raises:
        BagError: no .mcap file, or not an MCAP file at all.
    """
    path = Path(path)
    mcap_file = path if path.is_file() else next(iter(sorted(path.glob("*.mcap"))), None)
    if mcap_file is None:
        raise BagError(f"{path}: no .mcap file to recover")
    out_dir = Path(output) if output else mcap_file.parent
    report = RecoveryReport(source=mcap_file, output=out_dir, bytes_total=mcap_file.stat().st_size)
    with mcap_file.open("rb") as f:
        if f.read(len(MCAP_MAGIC)) != MCAP_MAGIC:
            raise BagError(f"{mcap_file}: not an MCAP file (bad magic); nothing to recover")
        scan = _scan_mcap(f, report)
    tmp_dir = out_dir.with_name(out_dir.name + ".recovering")
    if tmp_dir.exists():
        shutil.rmtree(tmp_dir)
    _write_recovered(scan, tmp_dir, mcap_file, report)
    _install_recovered(tmp_dir, out_dir, mcap_file)
    return report
