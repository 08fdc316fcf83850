"""rosbag2-layout MCAP bags (a directory with ``metadata.yaml`` and one ``.mcap``), read and written with `rosbags`.

* :class:`BagWriter` writes our own and standard types in log-time order, in chunks that do not overlap in time and
  carry their CRC; :meth:`BagWriter.flush` closes the current MCAP chunk and pushes it to disk, so that a writer
  killed with SIGKILL leaves every flushed message recoverable.
* :class:`BagReader` reads a bag and names the file (and the chunk) and the problem when it cannot (missing,
  truncated, corrupt).
* :func:`~sit2stand.io.recover.recover_bag` rebuilds a bag from the readable chunks of a truncated or damaged
  ``.mcap`` (a killed recorder, a bad disk block), and :func:`bag_info` summarises topics, types, counts, rates and
  duration.

Timestamps are integer nanoseconds (ROS time). Bags follow rosbag2's metadata version 9 (Jazzy).
"""

from __future__ import annotations

import contextlib
import heapq
import struct
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Self

from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime
from rosbags.rosbag2 import Reader, StoragePlugin
from rosbags.rosbag2.enums import CompressionFormat, CompressionMode
from rosbags.rosbag2.errors import ReaderError
from rosbags.typesys import get_types_from_msg

from ..errors import Sit2StandError
from .mcap_chunks import find_bad_chunks
from .mcap_writer import RosbagsWriter
from .topics import ESTIMATE_TOPICS
from .typestore import UnknownMessageType, ensure_type, typestore

MCAP_MAGIC = b"\x89MCAP0\r\n"


class BagError(Sit2StandError, RuntimeError):
    """A bag that cannot be read or written; the message names the bag (and topic) and what is wrong."""


def refuse_existing_bag(path: Path) -> None:
    """Raise :class:`BagError` if ``path`` exists: bags are never overwritten (a tool that writes other files beside
    its bag calls this first, so that a refused run leaves a finished one's files as they were)."""
    if path.exists():
        raise BagError(f"{path}: exists already; bags are never overwritten (remove it or pick another)")


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

    Messages are held in memory and written sorted by log time at each :meth:`flush` and at :meth:`close`, so a
    writer that never flushes (an importer, the synthesiser, :func:`merge_bags`) produces a file in log-time order
    with non-overlapping chunks whatever order it wrote in. A live recorder that flushes every 0.5 s gets the same
    as long as no message arrives with a log time older than one already flushed; such a late message is written
    as is in the next chunk (which then overlaps the previous one in time; readers that merge by log time, rosbags,
    ``mcap`` and ``ros2 bag``, still return it in order) and counted in :attr:`late_messages`. Above
    :attr:`MAX_PENDING_BYTES` of buffered data the buffer is written out without closing the chunk, which bounds
    memory but gives a writer that writes topic after topic late messages too.

    Example::

        with BagWriter("bags/demo") as bag:
            bag.add_topic(MARKERS_TOPIC, "sit2stand_msgs/msg/MocapFrame")
            bag.write(MARKERS_TOPIC, t_ns, msg)          # a rosbags message object
    """

    #: Serialized bytes held before they are written out without a flush() [bytes].
    MAX_PENDING_BYTES = 256 << 20

    def __init__(self, path: str | Path, *, custom_data: dict[str, str] | None = None, compress: bool = True) -> None:
        self.path = Path(path)
        refuse_existing_bag(self.path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.store = typestore()
        self._writer = RosbagsWriter(self.path, version=9, storage_plugin=StoragePlugin.MCAP)
        if compress:
            self._writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
        for key, value in (custom_data or {}).items():
            self._writer.set_custom_data(key, str(value))
        self._writer.open()
        self._connections: dict[str, Any] = {}
        self.counts: dict[str, int] = {}
        self._pending: list[tuple[int, Any, bytes]] = []   # (log time [ns], connection, CDR bytes)
        self._pending_bytes = 0
        self._written_until: int | None = None             # newest log time handed to the storage [ns]
        #: Messages written after a newer one had already gone to disk (see the class docstring).
        self.late_messages = 0
        self._closed = False

    def add_topic(self, topic: str, msgtype: str, qos: Iterable[Qos] | None = None) -> None:
        """Declare ``topic`` with type ``pkg/msg/Type`` (registered from share/ if the store lacks it); ``qos``
        default: reliable, transient local for the estimator's stream (:data:`~sit2stand.io.topics.ESTIMATE_TOPICS`,
        as the estimator publishes it), else volatile."""
        if topic in self._connections:
            if self._connections[topic].msgtype != msgtype:
                raise BagError(f"{self.path}: topic {topic} declared as {self._connections[topic].msgtype}, "
                               f"now as {msgtype}")
            return
        try:
            ensure_type(self.store, msgtype)
        except UnknownMessageType as err:
            raise BagError(f"{self.path}: topic {topic}: {err}") from None
        qos_list = list(qos) if qos is not None else [reliable_qos(transient_local=topic in ESTIMATE_TOPICS)]
        self._connections[topic] = self._writer.add_connection(
            topic, msgtype, typestore=self.store, offered_qos_profiles=qos_list)
        self.counts[topic] = 0

    def has_topic(self, topic: str) -> bool:
        return topic in self._connections

    def set_custom_data(self, key: str, value: str) -> None:
        """Set a ``custom_data`` entry of ``metadata.yaml`` (written at :meth:`close`)."""
        self._writer.set_custom_data(key, str(value))

    def write(self, topic: str, timestamp_ns: int, msg: Any) -> None:
        """Serialize a rosbags message object and queue it (the topic must have been added)."""
        conn = self._connection(topic)
        self._queue(conn, int(timestamp_ns), self.store.serialize_cdr(msg, conn.msgtype))
        self.counts[topic] += 1

    def write_raw(self, topic: str, timestamp_ns: int, data: bytes | memoryview) -> None:
        """Queue already-serialized CDR bytes (e.g. from a raw ROS subscription; copied, the caller may reuse them)."""
        self._queue(self._connection(topic), int(timestamp_ns), bytes(data))
        self.counts[topic] += 1

    def _connection(self, topic: str):
        try:
            return self._connections[topic]
        except KeyError:
            raise BagError(f"{self.path}: topic {topic} was not added before writing") from None

    def _queue(self, conn: Any, timestamp_ns: int, data: bytes) -> None:
        self._pending.append((timestamp_ns, conn, data))
        self._pending_bytes += len(data)
        if self._pending_bytes > self.MAX_PENDING_BYTES:
            self._write_pending()

    def _write_pending(self) -> None:
        """Hand the queued messages to the storage, oldest first (equal times keep the order they were written in)."""
        pending, self._pending, self._pending_bytes = self._pending, [], 0
        if not pending:
            return
        pending.sort(key=lambda m: m[0])
        before = self._written_until
        if before is not None:
            self.late_messages += sum(1 for t, _, _ in pending if t < before)
        for t_ns, conn, data in pending:
            self._writer.write(conn, t_ns, data)
        self._written_until = pending[-1][0] if before is None else max(before, pending[-1][0])

    def flush(self) -> None:
        """Write the queued messages sorted, close the pending MCAP chunk and push it to the disk: everything
        written so far survives a SIGKILL (:func:`~sit2stand.io.recover.recover_bag` reads it back). Costs one chunk
        record; call it about once a second, not per message."""
        if self._closed or self._writer.storage is None:
            return
        self._write_pending()
        self._writer.storage.flush_chunk()

    def close(self) -> None:
        """Write the queued messages, finish the MCAP summary and write ``metadata.yaml``. Idempotent."""
        if not self._closed:
            self._closed = True
            self._write_pending()
            self._writer.close()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def register_definition(store: Any, definition: str | bytes, msgtype: str) -> bool:
    """Register ``msgtype`` in ``store`` from its ``.msg`` text (UTF-8 bytes or str); False when it cannot be
    parsed (an IDL or a damaged definition)."""
    try:
        text = definition.decode() if isinstance(definition, bytes) else definition
        store.register(get_types_from_msg(text, msgtype))
    except Exception:  # noqa: BLE001 - rosbags' parser raises assorted errors on text it cannot read
        return False
    return True


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


@dataclass(frozen=True)
class BagSubject:
    """The subject a demonstration bag's ``custom_data`` names (``height_m``, ``body_mass_kg``, ``sex``)."""

    height_m: float
    mass_kg: float
    sex: str


def bag_subject(custom: dict[str, str]) -> BagSubject | None:
    """The subject in a bag's ``custom_data``; None when it names none.

    Raises:
        ValueError: ``height_m`` or ``body_mass_kg`` is not a number.
    """
    if not {"height_m", "body_mass_kg"} <= set(custom):
        return None
    return BagSubject(float(custom["height_m"]), float(custom["body_mass_kg"]), custom.get("sex", "male"))


class BagReader:
    """Read a rosbag2 bag (MCAP or SQLite3 storage) written by us, rosbag2 or rosbags.

    Raises:
        BagError: the directory is missing, or its metadata/storage is truncated or corrupt (message names the file,
            and the chunk when one is corrupt).
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
            if conn.msgdef and conn.msgdef.data and register_definition(self.store, conn.msgdef.data, conn.msgtype):
                continue
            with contextlib.suppress(UnknownMessageType):  # readable as bytes; deserialize() will name it
                ensure_type(self.store, conn.msgtype)

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
        """Messages in timestamp order, optionally only ``topics`` and within [start_ns, stop_ns).

        Raises:
            BagError: the storage is corrupt (naming the chunk), or, when reading whole topics, fewer or more
                messages were found than the bag's metadata counts (a damaged chunk without a CRC).
        """
        wanted = None if topics is None else set(topics)
        conns = [c for c in self._reader.connections if wanted is None or c.topic in wanted]
        if wanted is not None:
            missing = wanted - {c.topic for c in conns}
            if missing:
                raise BagError(f"{self.path}: no topic {', '.join(sorted(missing))} "
                               f"(it has {', '.join(sorted(self.topics()))})")
        expected = sum(c.msgcount for c in conns) if start_ns is None and stop_ns is None else None
        count = 0
        try:
            for conn, t_ns, raw in self._reader.messages(connections=conns, start=start_ns, stop=stop_ns):
                count += 1
                yield BagMessage(conn.topic, conn.msgtype, t_ns, bytes(raw))
        except Exception as err:  # noqa: BLE001 - rosbags and its decompressor raise assorted errors on bad data
            raise self._storage_error(str(err)) from None
        if expected is not None and count != expected:
            raise self._storage_error(f"read {count} messages where its metadata counts {expected}")

    def _storage_error(self, what: str) -> BagError:
        """The error for storage that failed while reading: names the first corrupt chunk when one is found."""
        bad = [note for mcap_file in sorted(self.path.glob("*.mcap")) for note in find_bad_chunks(mcap_file)]
        if bad:
            return BagError(f"{self.path}: {bad[0]} ({len(bad)} corrupt chunk(s); `sit2stand bag recover "
                            f"{self.path} --out <dir>` keeps the messages of the others)")
        return BagError(f"{self.path}: reading messages failed: {what} (truncated or corrupt storage)")

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

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def merge_bags(out: str | Path, inputs: list[str | Path]) -> dict[str, int]:
    """Write the messages of several bags into one, in time order (e.g. a demonstration and the human COM computed
    from it offline). A topic present in more than one input is taken from the first that has it; the custom data
    (metadata) are the first bag's. Returns the message count per topic."""

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
        (f"storage:   {', '.join(p.name for p in sorted(path.glob('*.mcap'))) or '?'}"
         f" ({sum(p.stat().st_size for p in path.iterdir() if p.is_file()) / 1e6:.2f} MB)"),
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
