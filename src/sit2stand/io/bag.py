"""rosbag2-layout MCAP bags (a directory with ``metadata.yaml`` and one ``.mcap``), read and written with `rosbags`.

* :class:`BagWriter` writes our own and standard types; :meth:`BagWriter.flush` closes the current MCAP chunk and
  pushes it to disk, so that a writer killed with SIGKILL leaves every flushed message recoverable.
* :class:`BagReader` reads a bag and names the file and the problem when it cannot (missing, truncated, corrupt).
* :func:`recover_bag` rebuilds a bag from the complete chunks of a truncated ``.mcap`` (a killed recorder), and
  :func:`bag_info` summarises topics, types, counts, rates and duration.

Timestamps are integer nanoseconds (ROS time). Bags follow rosbag2's metadata version 9 (Jazzy).
"""

from __future__ import annotations

import io
import shutil
import struct
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime
from rosbags.rosbag2 import Reader, StoragePlugin, Writer
from rosbags.rosbag2.errors import ReaderError, WriterError
from rosbags.rosbag2.metadata import parse_qos
from rosbags.typesys import get_types_from_msg

from .typestore import UnknownMessageType, ensure_type, typestore

MCAP_MAGIC = b"\x89MCAP0\r\n"


class BagError(RuntimeError):
    """A bag that cannot be read or written; the message names the bag (and topic) and what is wrong."""


def reliable_qos(depth: int = 1000, transient_local: bool = False) -> Qos:
    """A rosbag2 ``offered_qos_profiles`` entry: reliable, keep-last ``depth``, volatile (or transient-local)."""
    never = QosTime(sec=0x7FFFFFFF, nsec=0xFFFFFFFF)
    return Qos(
        history=QosHistory.KEEP_LAST,
        depth=depth,
        reliability=QosReliability.RELIABLE,
        durability=QosDurability.TRANSIENT_LOCAL if transient_local else QosDurability.VOLATILE,
        deadline=never,
        lifespan=never,
        liveliness=QosLiveliness.AUTOMATIC,
        liveliness_lease_duration=never,
        avoid_ros_namespace_conventions=False,
    )


@dataclass
class TopicInfo:
    """What a bag holds on one topic. Times in ns."""

    name: str
    msgtype: str
    count: int = 0
    first_ns: int | None = None
    last_ns: int | None = None

    @property
    def rate_hz(self) -> float:
        """Mean message rate [Hz] over the topic's own span (0 when fewer than two messages)."""
        if self.count < 2 or self.first_ns is None or self.last_ns is None or self.last_ns <= self.first_ns:
            return 0.0
        return (self.count - 1) / ((self.last_ns - self.first_ns) * 1e-9)


@dataclass
class BagMessage:
    """One serialized message as stored: topic, type, receive/log time [ns], CDR bytes."""

    topic: str
    msgtype: str
    timestamp_ns: int
    data: bytes


class BagWriter:
    """Write a rosbag2 MCAP bag. Use as a context manager; the bag is complete after :meth:`close`.

    Example::

        with BagWriter("bags/demo") as bag:
            bag.add_topic("/mocap/markers", "sit2stand_msgs/msg/MocapFrame")
            bag.write("/mocap/markers", t_ns, msg)          # a rosbags message object
    """

    def __init__(self, path: str | Path, *, custom_data: dict[str, str] | None = None, compress: bool = True) -> None:
        self.path = Path(path)
        if self.path.exists():
            raise BagError(f"{self.path}: exists already; bags are never overwritten (remove it or pick another)")
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.store = typestore()
        self._writer = Writer(self.path, version=9, storage_plugin=StoragePlugin.MCAP)
        if compress:
            from rosbags.rosbag2.enums import CompressionFormat, CompressionMode

            self._writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
        for key, value in (custom_data or {}).items():
            self._writer.set_custom_data(key, str(value))
        self._writer.open()
        self._connections: dict[str, Any] = {}
        self.counts: dict[str, int] = {}
        self._closed = False

    def add_topic(self, topic: str, msgtype: str, qos: Iterable[Qos] | None = None) -> None:
        """Declare ``topic`` with type ``pkg/msg/Type`` (registered from share/ if the store lacks it)."""
        if topic in self._connections:
            if self._connections[topic].msgtype != msgtype:
                raise BagError(f"{self.path}: topic {topic} declared as {self._connections[topic].msgtype}, "
                               f"now as {msgtype}")
            return
        try:
            ensure_type(self.store, msgtype)
        except UnknownMessageType as err:
            raise BagError(f"{self.path}: topic {topic}: {err}") from None
        qos_list = list(qos) if qos is not None else [reliable_qos()]
        self._connections[topic] = self._writer.add_connection(
            topic, msgtype, typestore=self.store, offered_qos_profiles=qos_list)
        self.counts[topic] = 0

    def has_topic(self, topic: str) -> bool:
        return topic in self._connections

    def write(self, topic: str, timestamp_ns: int, msg: Any) -> None:
        """Serialize a rosbags message object and write it (the topic must have been added)."""
        conn = self._connection(topic)
        self._writer.write(conn, int(timestamp_ns), self.store.serialize_cdr(msg, conn.msgtype))
        self.counts[topic] += 1

    def write_raw(self, topic: str, timestamp_ns: int, data: bytes | memoryview) -> None:
        """Write already-serialized CDR bytes (e.g. from a raw ROS subscription)."""
        self._writer.write(self._connection(topic), int(timestamp_ns), data)
        self.counts[topic] += 1

    def _connection(self, topic: str):
        try:
            return self._connections[topic]
        except KeyError:
            raise BagError(f"{self.path}: topic {topic} was not added before writing") from None

    def flush(self) -> None:
        """Close the pending MCAP chunk and push it to the disk: everything written so far survives a SIGKILL
        (:func:`recover_bag` reads it back). Costs one chunk record; call it about once a second, not per message."""
        storage = self._writer.storage
        if storage is None:
            return
        if storage.chunk.bio.tell():  # rosbags' McapWriter: pending chunk buffer
            storage.close_chunk()
        storage.bio.flush()

    def close(self) -> None:
        """Finish the MCAP summary and write ``metadata.yaml``. Idempotent."""
        if not self._closed:
            self._closed = True
            self._writer.close()

    def __enter__(self) -> BagWriter:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _check_bag_dir(path: Path) -> None:
    if not path.exists():
        raise BagError(f"{path}: no such bag (expected a directory with metadata.yaml and a .mcap file)")
    if path.is_file():
        raise BagError(f"{path}: is a file; a rosbag2 bag is a directory holding metadata.yaml and a .mcap file")
    if not (path / "metadata.yaml").exists():
        mcaps = sorted(path.glob("*.mcap"))
        hint = (f"; it holds {mcaps[0].name}: if a recorder was killed, rebuild it with "
                f"`sit2stand bag recover {path}`") if mcaps else ""
        raise BagError(f"{path}: metadata.yaml is missing{hint}")


class BagReader:
    """Read a rosbag2 bag (MCAP or SQLite3 storage) written by us, rosbag2 or rosbags.

    Raises:
        BagError: the directory is missing, or its metadata/storage is truncated or corrupt (message names the file).
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        _check_bag_dir(self.path)
        self._reader = Reader(self.path)
        try:
            self._reader.open()
        except (ReaderError, OSError, AssertionError, ValueError, struct.error) as err:
            files = ", ".join(p.name for p in sorted(self.path.glob("*.mcap"))) or "its storage file"
            raise BagError(f"{self.path}: cannot open {files}: {err} (truncated or corrupt bag; a recording cut off "
                           f"by a crash can be rebuilt with `sit2stand bag recover {self.path}`)") from None
        self.store = typestore()
        self._register_bag_types()

    def _register_bag_types(self) -> None:
        """Types that only the bag defines (not in our store) are registered from the bag's own definitions."""
        for conn in self._reader.connections:
            if conn.msgtype in self.store.fielddefs:
                continue
            if conn.msgdef and conn.msgdef.data:
                try:
                    self.store.register(get_types_from_msg(conn.msgdef.data, conn.msgtype))
                    continue
                except Exception:  # noqa: BLE001 - fall through to the share/ lookup
                    pass
            try:
                ensure_type(self.store, conn.msgtype)
            except UnknownMessageType:
                pass  # readable as bytes; deserialize() will name it

    @property
    def start_ns(self) -> int:
        return self._reader.start_time

    @property
    def end_ns(self) -> int:
        return self._reader.end_time

    @property
    def duration_s(self) -> float:
        return max(0, self.end_ns - self.start_ns) * 1e-9 if self.message_count else 0.0

    @property
    def message_count(self) -> int:
        return self._reader.message_count

    @property
    def custom_data(self) -> dict[str, str]:
        return dict(getattr(self._reader.storage.metadata, "custom", None) or {})

    def topics(self) -> dict[str, TopicInfo]:
        """Topic name -> :class:`TopicInfo` with counts from the metadata (first/last times not filled)."""
        out: dict[str, TopicInfo] = {}
        for conn in self._reader.connections:
            info = out.setdefault(conn.topic, TopicInfo(conn.topic, conn.msgtype))
            info.count += conn.msgcount
        return out

    def qos(self, topic: str) -> list[Qos]:
        """The offered QoS profiles recorded for ``topic`` (empty when unknown)."""
        for conn in self._reader.connections:
            if conn.topic == topic:
                return list(getattr(conn.ext, "offered_qos_profiles", []) or [])
        return []

    def messages(self, topics: Iterable[str] | None = None, start_ns: int | None = None,
                 stop_ns: int | None = None) -> Iterator[BagMessage]:
        """Messages in timestamp order, optionally only ``topics`` and within [start_ns, stop_ns)."""
        wanted = None if topics is None else set(topics)
        conns = [c for c in self._reader.connections if wanted is None or c.topic in wanted]
        if wanted is not None:
            missing = wanted - {c.topic for c in conns}
            if missing:
                raise BagError(f"{self.path}: no topic {', '.join(sorted(missing))} "
                               f"(it has {', '.join(sorted(self.topics()))})")
        try:
            for conn, t_ns, raw in self._reader.messages(connections=conns, start=start_ns, stop=stop_ns):
                yield BagMessage(conn.topic, conn.msgtype, t_ns, bytes(raw))
        except (ReaderError, OSError, AssertionError, ValueError, struct.error, EOFError) as err:
            raise BagError(f"{self.path}: reading messages failed: {err} (truncated or corrupt storage)") from None

    def deserialize(self, msg: BagMessage) -> Any:
        """The rosbags message object of a :class:`BagMessage`."""
        if msg.msgtype not in self.store.fielddefs:
            raise BagError(f"{self.path}: topic {msg.topic}: unknown message type {msg.msgtype}")
        try:
            return self.store.deserialize_cdr(msg.data, msg.msgtype)
        except Exception as err:  # noqa: BLE001 - rosbags raises assorted errors on bad CDR
            raise BagError(f"{self.path}: topic {msg.topic} at t={msg.timestamp_ns} ns: cannot deserialize "
                           f"{msg.msgtype}: {err}") from None

    def read(self, topic: str) -> list[tuple[int, Any]]:
        """All messages of one topic as (timestamp_ns, message object)."""
        return [(m.timestamp_ns, self.deserialize(m)) for m in self.messages([topic])]

    def close(self) -> None:
        self._reader.close()

    def __enter__(self) -> BagReader:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def merge_bags(out: str | Path, inputs: list[str | Path]) -> dict[str, int]:
    """Write the messages of several bags into one, in time order (e.g. a demonstration and the human COM computed
    from it offline). A topic present in more than one input is taken from the first that has it; the custom data
    (metadata) are the first bag's. Returns the message count per topic."""
    import heapq

    readers = [BagReader(p) for p in inputs]
    try:
        owner: dict[str, int] = {}
        for i, r in enumerate(readers):
            for topic in r.topics():
                owner.setdefault(topic, i)
        with BagWriter(out, custom_data=readers[0].custom_data) as w:
            for topic, i in owner.items():
                w.add_topic(topic, readers[i].topics()[topic].msgtype, readers[i].qos(topic) or None)
            streams = [r.messages([t for t, o in owner.items() if o == i]) for i, r in enumerate(readers)
                       if any(o == i for o in owner.values())]
            for m in heapq.merge(*streams, key=lambda m: m.timestamp_ns):
                w.write_raw(m.topic, m.timestamp_ns, m.data)
            return dict(w.counts)
    finally:
        for r in readers:
            r.close()


def topic_stats(path: str | Path) -> tuple[dict[str, TopicInfo], int, int]:
    """Per-topic counts and first/last times by reading every message's header; also bag start/end [ns]."""
    with BagReader(path) as bag:
        infos = {name: TopicInfo(name, t.msgtype) for name, t in bag.topics().items()}
        for msg in bag.messages():
            info = infos[msg.topic]
            info.count += 1
            if info.first_ns is None:
                info.first_ns = msg.timestamp_ns
            info.last_ns = msg.timestamp_ns
        return infos, bag.start_ns, bag.end_ns


def bag_info(path: str | Path) -> str:
    """A table of a bag's topics: type, count, rate [Hz], first/last time; plus duration and start."""
    path = Path(path)
    infos, start, end = topic_stats(path)
    total = sum(t.count for t in infos.values())
    lines = [
        f"bag:       {path}",
        f"storage:   {', '.join(p.name for p in sorted(path.glob('*.mcap'))) or '?'}"
        f" ({sum(p.stat().st_size for p in path.iterdir() if p.is_file()) / 1e6:.2f} MB)",
        f"duration:  {max(0, end - start) * 1e-9 if total else 0.0:.3f} s",
        f"start:     {start * 1e-9 if total else 0.0:.6f} s",
        f"messages:  {total}",
        "",
        f"{'topic':<34} {'type':<40} {'count':>8} {'rate [Hz]':>10} {'span [s]':>9}",
    ]
    for name in sorted(infos):
        t = infos[name]
        span = (t.last_ns - t.first_ns) * 1e-9 if t.count else 0.0
        lines.append(f"{name:<34} {t.msgtype:<40} {t.count:>8} {t.rate_hz:>10.2f} {span:>9.3f}")
    return "\n".join(lines)


# ---------------------------------------------------------------------------------------------------------------
# Recovery of a bag whose writer died (SIGKILL, power loss): the .mcap has no summary/footer and there is no
# metadata.yaml. Every complete record up to the cut is kept; records inside complete chunks included.
# ---------------------------------------------------------------------------------------------------------------

@dataclass
class RecoveryReport:
    """What :func:`recover_bag` found and kept."""

    source: Path
    output: Path
    messages: int = 0
    topics: dict[str, int] = field(default_factory=dict)
    bytes_read: int = 0
    bytes_total: int = 0
    stopped_because: str = ""
    first_ns: int | None = None
    last_ns: int | None = None

    def __str__(self) -> str:
        span = (self.last_ns - self.first_ns) * 1e-9 if self.messages else 0.0
        tops = ", ".join(f"{k} ({v})" for k, v in sorted(self.topics.items()))
        return (f"recovered {self.messages} messages spanning {span:.3f} s from {self.source} "
                f"({self.bytes_read}/{self.bytes_total} bytes usable; {self.stopped_because}) into {self.output}: "
                f"{tops}")


def _read_u(buf: io.BytesIO, fmt: str, size: int) -> int:
    data = buf.read(size)
    if len(data) < size:
        raise EOFError
    return struct.unpack(fmt, data)[0]


def _read_str(buf: io.BytesIO) -> str:
    n = _read_u(buf, "<I", 4)
    data = buf.read(n)
    if len(data) < n:
        raise EOFError
    return data.decode()


def _read_bytes_u32(buf: io.BytesIO) -> bytes:
    n = _read_u(buf, "<I", 4)
    data = buf.read(n)
    if len(data) < n:
        raise EOFError
    return data


def _decompress(compression: str, data: bytes, size: int) -> bytes:
    if compression == "":
        return data
    if compression == "zstd":
        import zstandard

        return zstandard.ZstdDecompressor().decompress(data, max_output_size=size)
    if compression == "lz4":
        import lz4.frame

        return lz4.frame.decompress(data)
    raise ValueError(f"unknown chunk compression {compression!r}")


def _iter_records(data: bytes) -> Iterator[tuple[int, bytes, int]]:
    """(opcode, body, end offset) of each complete MCAP record in ``data`` (after the magic); stops at a cut."""
    pos = 0
    while pos + 9 <= len(data):
        op = data[pos]
        (length,) = struct.unpack_from("<Q", data, pos + 1)
        end = pos + 9 + length
        if end > len(data):
            return
        yield op, data[pos + 9:end], end
        pos = end


def recover_bag(path: str | Path, output: str | Path | None = None) -> RecoveryReport:
    """Rebuild a complete bag from a truncated rosbag2 ``.mcap`` (e.g. a recorder killed with SIGKILL).

    Args:
        path: the damaged bag directory (or the ``.mcap`` file itself).
        output: where to write the rebuilt bag; default: the same directory, rebuilt in place (the damaged file is
            kept beside it as ``<name>.mcap.damaged``).

    Returns:
        A :class:`RecoveryReport` (counts per topic, where and why reading stopped).

    Raises:
        BagError: no .mcap file, or not an MCAP file at all.
    """
    path = Path(path)
    mcap_file = path if path.is_file() else next(iter(sorted(path.glob("*.mcap"))), None)
    if mcap_file is None:
        raise BagError(f"{path}: no .mcap file to recover")
    bag_dir = mcap_file.parent
    raw = mcap_file.read_bytes()
    if not raw.startswith(MCAP_MAGIC):
        raise BagError(f"{mcap_file}: not an MCAP file (bad magic); nothing to recover")
    report = RecoveryReport(source=mcap_file, output=Path(output) if output else bag_dir, bytes_total=len(raw))

    schemas: dict[int, tuple[str, str]] = {}              # id -> (name, definition text)
    channels: dict[int, tuple[str, int, str]] = {}         # id -> (topic, schema id, qos yaml)
    messages: list[tuple[int, int, bytes]] = []            # (channel id, log time, data)
    usable = len(MCAP_MAGIC)
    report.stopped_because = "file cut in the middle of a record"

    def handle(op: int, body: bytes) -> None:
        buf = io.BytesIO(body)
        if op == 0x03:  # Schema
            sid = _read_u(buf, "<H", 2)
            name = _read_str(buf)
            _read_str(buf)  # encoding
            schemas[sid] = (name, _read_bytes_u32(buf).decode())
        elif op == 0x04:  # Channel
            cid = _read_u(buf, "<H", 2)
            sid = _read_u(buf, "<H", 2)
            topic = _read_str(buf)
            _read_str(buf)  # message encoding
            meta_len = _read_u(buf, "<I", 4)
            meta = io.BytesIO(buf.read(meta_len))
            qos = ""
            while meta.tell() < meta_len:
                key, value = _read_str(meta), _read_str(meta)
                if key == "offered_qos_profiles":
                    qos = value
            channels[cid] = (topic, sid, qos)
        elif op == 0x05:  # Message
            cid = _read_u(buf, "<H", 2)
            _read_u(buf, "<I", 4)  # sequence
            log_time = _read_u(buf, "<Q", 8)
            _read_u(buf, "<Q", 8)  # publish time
            messages.append((cid, log_time, buf.read()))

    body_data = raw[len(MCAP_MAGIC):]
    for op, body, end in _iter_records(body_data):
        if op == 0x06:  # Chunk: start, end, uncompressed size, crc, compression, records
            buf = io.BytesIO(body)
            _read_u(buf, "<Q", 8)
            _read_u(buf, "<Q", 8)
            size = _read_u(buf, "<Q", 8)
            _read_u(buf, "<I", 4)
            compression = _read_str(buf)
            n = _read_u(buf, "<Q", 8)
            try:
                inner = _decompress(compression, buf.read(n), size)
            except Exception as err:  # noqa: BLE001
                report.stopped_because = f"corrupt chunk at byte {usable}: {err}"
                break
            for iop, ibody, _ in _iter_records(inner):
                handle(iop, ibody)
        elif op in (0x02, 0x0F):  # Footer / DataEnd: the file was complete up to here
            usable = len(MCAP_MAGIC) + end
            report.stopped_because = "file was complete"
            break
        else:
            handle(op, body)
        usable = len(MCAP_MAGIC) + end
    else:
        if usable == len(raw):
            report.stopped_because = "file ends on a record boundary (no summary)"
    report.bytes_read = usable

    # Write the rebuilt bag next to the damaged one, then swap it in.
    out_dir = report.output
    tmp_dir = out_dir.with_name(out_dir.name + ".recovering")
    if tmp_dir.exists():
        shutil.rmtree(tmp_dir)
    writer = BagWriter(tmp_dir, custom_data={"recovered_from": str(mcap_file)})
    try:
        for cid, (topic, sid, qos_text) in sorted(channels.items()):
            if sid not in schemas:
                continue
            name, text = schemas[sid]
            if name not in writer.store.fielddefs:
                try:
                    writer.store.register(get_types_from_msg(text, name))
                except Exception:  # noqa: BLE001
                    continue
            try:
                qos = parse_qos(qos_text) if qos_text else None
            except Exception:  # noqa: BLE001
                qos = None
            writer.add_topic(topic, name, qos)
        for cid, t_ns, data in sorted(messages, key=lambda m: m[1]):
            if cid not in channels or not writer.has_topic(channels[cid][0]):
                continue
            topic = channels[cid][0]
            writer.write_raw(topic, t_ns, data)
            report.messages += 1
            report.topics[topic] = report.topics.get(topic, 0) + 1
            report.first_ns = t_ns if report.first_ns is None else min(report.first_ns, t_ns)
            report.last_ns = t_ns if report.last_ns is None else max(report.last_ns, t_ns)
    finally:
        writer.close()

    if out_dir == bag_dir:
        damaged = mcap_file.with_name(mcap_file.name + ".damaged")
        mcap_file.replace(damaged)
        (bag_dir / "metadata.yaml").unlink(missing_ok=True)
        new_mcap = next(tmp_dir.glob("*.mcap"))
        new_mcap.replace(bag_dir / f"{bag_dir.name}.mcap")
        meta = (tmp_dir / "metadata.yaml").read_text().replace(new_mcap.name, f"{bag_dir.name}.mcap")
        (bag_dir / "metadata.yaml").write_text(meta)
        shutil.rmtree(tmp_dir)
    else:
        if out_dir.exists():
            raise BagError(f"{out_dir}: exists already; not overwriting")
        tmp_dir.rename(out_dir)
        new_mcap = next(out_dir.glob("*.mcap"))
        target = out_dir / f"{out_dir.name}.mcap"
        if new_mcap != target:
            new_mcap.replace(target)
            meta = (out_dir / "metadata.yaml").read_text().replace(new_mcap.name, target.name)
            (out_dir / "metadata.yaml").write_text(meta)
    return report
