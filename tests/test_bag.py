"""sit2stand.io.bag: bags we write read back (rosbags and mcap-ros2), follow rosbag2's layout, and fail clearly."""

import itertools
import json
import math
import os
import signal
import sys
import tracemalloc
from pathlib import Path

import numpy as np
import pytest
import yaml
from mcap.reader import make_reader
from mcap.records import Chunk, Message
from mcap.stream_reader import StreamReader, breakup_chunk
from mcap_ros2.decoder import DecoderFactory
from rclpy.serialization import deserialize_message
from rosbags.rosbag2 import Reader, StoragePlugin, Writer
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from sit2stand.io import messages as M
from sit2stand.io.bag import BagError, BagReader, BagWriter, bag_info, merge_bags
from sit2stand.io.recover import recover_bag
from sit2stand.io.topics import MARKERS_TOPIC, MOCAP_TYPE, PLATE_TYPE, plate_topic
from sit2stand.io.typestore import typestore
from sit2stand_msgs.msg import ForcePlateSample


def write_demo_bag(path, n=50):
    """A bag with markers (one occluded) and force-plate samples with known values."""
    with BagWriter(path) as bag:
        bag.add_topic(MARKERS_TOPIC, MOCAP_TYPE)
        bag.add_topic(plate_topic("feet"), PLATE_TYPE)
        for i in range(n):
            t = 1_000_000_000 + i * 10_000_000
            pos = np.array([[0.1 * i, 0.2, 1.0], [9.0, 9.0, 9.0]])
            bag.write(MARKERS_TOPIC, t, M.mocap_frame(t, ["LASI", "RASI"], pos, np.array([True, i % 2 == 0])))
            bag.write(plate_topic("feet"), t, M.force_plate_sample(
                t, "feet", np.array([1.0, 2.0, 600.0 + i]), np.array([3.0, 4.0, 5.0]), np.array([0.1, 0.0, 0.0]),
                True, 0.5))
    return path


def test_round_trip_values_through_rosbags(tmp_path):
    bag = write_demo_bag(tmp_path / "b")
    with BagReader(bag) as r:
        topics = r.topics()
        assert topics[MARKERS_TOPIC].count == 50 and topics[plate_topic("feet")].count == 50
        frames = r.read(MARKERS_TOPIC)
        names, pos, valid = M.mocap_arrays(frames[3][1])
        assert names == ["LASI", "RASI"] and valid.tolist() == [True, False]
        assert pos[0] == pytest.approx([0.3, 0.2, 1.0])
        assert np.isnan(pos[1]).all(), "an occluded marker must be NaN, never a stale or zero position"
        plate = M.plate_series("feet", r.read(plate_topic("feet")))
        assert plate.force_n[:, 2] == pytest.approx(600.0 + np.arange(50))
        assert r.duration_s == pytest.approx(0.49)


def test_bag_reads_back_with_mcap_ros2(tmp_path):

    bag = write_demo_bag(tmp_path / "b")
    with open(bag / "b.mcap", "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        got = [(channel.topic, msg) for _s, channel, _m, msg in reader.iter_decoded_messages()]
    assert len(got) == 100
    markers = [msg for topic, msg in got if topic == MARKERS_TOPIC]
    assert list(markers[4].marker_names) == ["LASI", "RASI"]
    assert markers[4].positions[0].x == pytest.approx(0.4)
    plate = [msg for topic, msg in got if topic == plate_topic("feet")]
    assert plate[7].wrench.force.z == pytest.approx(607.0) and plate[7].plate_name == "feet"


def test_metadata_follows_rosbag2_version_9(tmp_path):
    bag = write_demo_bag(tmp_path / "b")
    meta = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["version"] == 9 and meta["storage_identifier"] == "mcap"
    assert meta["relative_file_paths"] == ["b.mcap"] and meta["message_count"] == 100
    topics = {t["topic_metadata"]["name"]: t for t in meta["topics_with_message_count"]}
    assert topics[MARKERS_TOPIC]["message_count"] == 50
    tm = topics[MARKERS_TOPIC]["topic_metadata"]
    assert tm["type"] == MOCAP_TYPE and tm["serialization_format"] == "cdr"
    # the type hash must be the one rosidl generates for our interface (what ros2 bag checks)
    assert tm["type_description_hash"] == typestore().hash_rihs01(MOCAP_TYPE)
    assert tm["offered_qos_profiles"][0]["reliability"] == "reliable"
    assert meta["duration"]["nanoseconds"] == 490_000_000


def test_rosidl_and_rosbags_agree_on_our_type_hashes():

    share = Path(sys.prefix) / "share" / "sit2stand_msgs" / "msg"
    if not share.is_dir():
        pytest.skip("sit2stand_msgs is not installed in this environment")
    for name in ("MocapFrame", "ForcePlateSample", "CenterOfMass", "InertialParameters"):
        desc = json.loads((share / f"{name}.json").read_text())
        rosidl = next(h["hash_string"] for h in desc["type_hashes"] if h["type_name"].endswith(f"/{name}"))
        assert rosidl == typestore().hash_rihs01(f"sit2stand_msgs/msg/{name}"), name


def test_bag_info_lists_counts_and_rates(tmp_path):
    text = bag_info(write_demo_bag(tmp_path / "b"))
    line = next(x for x in text.splitlines() if x.startswith(MARKERS_TOPIC))
    assert "50" in line.split() and "100.00" in line.split()


def test_never_overwrites_a_bag(tmp_path):
    bag = write_demo_bag(tmp_path / "b")
    with pytest.raises(BagError, match="exists already"):
        BagWriter(bag)


@pytest.mark.parametrize("damage", ["truncate", "garbage", "no_metadata", "missing"])
def test_damaged_bags_fail_with_the_file_named(tmp_path, damage):
    bag = write_demo_bag(tmp_path / "b")
    mcap = bag / "b.mcap"
    if damage == "truncate":
        mcap.write_bytes(mcap.read_bytes()[: mcap.stat().st_size // 2])
        expect = "truncated or corrupt"
    elif damage == "garbage":
        mcap.write_bytes(b"not an mcap file at all" * 10)
        expect = "b.mcap"
    elif damage == "no_metadata":
        (bag / "metadata.yaml").unlink()
        expect = "sit2stand bag recover"
    else:
        bag = tmp_path / "nope"
        expect = "no such bag"
    with pytest.raises(BagError, match=expect) as err, BagReader(bag) as r:
        list(r.messages())
    assert str(bag) in str(err.value)


def test_recover_keeps_every_flushed_message_after_sigkill(tmp_path):
    """A writer killed with SIGKILL: everything written before its last flush() is recovered."""
    path = tmp_path / "killed"
    float64 = typestore().types["std_msgs/msg/Float64"]
    pid = os.fork()
    if pid == 0:  # child: write 1000 messages, flush after each 100, write 50 more unflushed, die
        try:
            bag = BagWriter(path)
            bag.add_topic("/x", "std_msgs/msg/Float64")
            for i in range(1050):
                bag.write("/x", 1_000 + i, float64(data=float(i)))
                if i % 100 == 99:
                    bag.flush()
        finally:
            os.kill(os.getpid(), signal.SIGKILL)
    os.waitpid(pid, 0)
    with pytest.raises(BagError, match="recover"):
        BagReader(path)
    report = recover_bag(path)
    assert report.topics == {"/x": 1000}
    with BagReader(path) as r:
        values = [m.data for _, m in r.read("/x")]
    assert values == [float(i) for i in range(1000)]
    assert (path / "killed.mcap.damaged").exists()


def test_recover_a_cut_in_the_middle_of_a_chunk(tmp_path):
    bag = write_demo_bag(tmp_path / "b", n=10)
    (bag / "metadata.yaml").unlink()
    data = (bag / "b.mcap").read_bytes()
    (bag / "b.mcap").write_bytes(data[: len(data) - 300])  # cut inside the summary/last record
    out = tmp_path / "rebuilt"
    report = recover_bag(bag, out)
    assert report.messages > 0
    with BagReader(out) as r:
        assert r.message_count == report.messages
        assert not math.isnan(r.duration_s)


def test_unknown_type_in_a_foreign_bag_reads_as_bytes_and_deserializes_from_its_own_definition(tmp_path):

    store = get_typestore(Stores.ROS2_JAZZY)
    store.register(get_types_from_msg("float64 pressure_pa\nstring site", "lab_msgs/msg/Barometer"))
    baro = store.types["lab_msgs/msg/Barometer"]
    with Writer(tmp_path / "foreign", version=9, storage_plugin=StoragePlugin.MCAP) as w:
        conn = w.add_connection("/baro", "lab_msgs/msg/Barometer", typestore=store)
        w.write(conn, 5, store.serialize_cdr(baro(pressure_pa=101325.0, site="lab"), "lab_msgs/msg/Barometer"))
    with BagReader(tmp_path / "foreign") as r:
        (_, msg), = r.read("/baro")
        assert msg.pressure_pa == 101325.0 and msg.site == "lab"


def test_merge_puts_two_bags_in_time_order_and_keeps_the_first_bags_metadata(tmp_path):

    a, b = tmp_path / "a", tmp_path / "b"
    store = typestore().types
    for path, topic, times, meta in ((a, "/x", [1, 3, 5], {"who": "a"}), (b, "/y", [2, 4], {"who": "b"})):
        with BagWriter(path, custom_data=meta) as w:
            w.add_topic(topic, "std_msgs/msg/String")
            for t in times:
                w.write(topic, t, store["std_msgs/msg/String"](data=f"{topic}{t}"))
    counts = merge_bags(tmp_path / "m", [a, b, a])
    assert counts == {"/x": 3, "/y": 2}
    with BagReader(tmp_path / "m") as m:
        assert [msg.timestamp_ns for msg in m.messages()] == [1, 2, 3, 4, 5]
        assert m.custom_data["who"] == "a"


@pytest.mark.parametrize("frame_id, plate", [("lab", "chair"), ("", "feet"), ("abc", "p"), ("lab_frame", "plate12")])
@pytest.mark.parametrize("little_endian", [True, False])
def test_plate_sample_read_from_cdr_bytes(frame_id, plate, little_endian):
    """The nodes read 1 kHz plate samples straight from the serialized bytes: same stamp and wrench as the message
    (string lengths change the alignment of the wrench)."""
    t_ns = 1_795_326_767_123_456_789
    msg = M.force_plate_sample(t_ns, plate, np.array([1.5, -2.0, 700.25]), np.array([3.0, 4.0, -5.0]),
                               np.array([0.1, 0.2, 0.0]), True, 0.5)
    msg.header.frame_id = frame_id
    data = typestore().serialize_cdr(msg, PLATE_TYPE, little_endian=little_endian)
    t_s, *wrench = M.plate_sample_from_cdr(data)
    assert t_s == M.stamp_ns(msg.header) * 1e-9
    assert wrench == [1.5, -2.0, 700.25, 3.0, 4.0, -5.0]
    # and as rclpy itself would build it from the same bytes

    if little_endian:
        ros = deserialize_message(bytes(data), ForcePlateSample)
        assert (ros.wrench.force.z, ros.wrench.torque.x, ros.header.stamp.nanosec) == (700.25, 3.0, 123_456_789)


# --- log-time order, chunk CRCs, corrupt chunks and recovery ------------------------------------------------------

def float_bag(path, n=300, flush_every=100):
    """/x: Float64 ``i`` at t = 1 s + i ms, flushed every ``flush_every`` messages (one chunk each).

    Returns the path of the .mcap file."""
    float64 = typestore().types["std_msgs/msg/Float64"]
    with BagWriter(path) as bag:
        bag.add_topic("/x", "std_msgs/msg/Float64")
        for i in range(n):
            bag.write("/x", 1_000_000_000 + i * 1_000_000, float64(data=float(i)))
            if i % flush_every == flush_every - 1:
                bag.flush()
    return path / f"{path.name}.mcap"


def chunk_indexes(mcap_file):
    """The chunk indexes of an .mcap's summary, in file order."""

    with open(mcap_file, "rb") as f:
        return sorted(make_reader(f).get_summary().chunk_indexes, key=lambda c: c.chunk_start_offset)


def order_problems(mcap_file):
    """What the MCAP CLI's ``doctor`` counts here, in file order: messages whose log time is below the latest one
    before them, pairs of consecutive chunks that overlap in time, chunks without a CRC (a wrong CRC raises)."""

    late = crcless = 0
    latest = -1
    with open(mcap_file, "rb") as f:
        for rec in StreamReader(f, emit_chunks=True).records:
            if isinstance(rec, Chunk):
                crcless += rec.uncompressed_crc == 0
            for m in breakup_chunk(rec, validate_crc=True) if isinstance(rec, Chunk) else [rec]:
                if isinstance(m, Message):
                    late += m.log_time < latest
                    latest = max(latest, m.log_time)
    idx = chunk_indexes(mcap_file)
    overlapping = sum(b.message_start_time < a.message_end_time for a, b in itertools.pairwise(idx))
    return {"late": late, "overlapping_chunks": overlapping, "chunks_without_crc": crcless}


def damage(mcap_file, chunk_numbers, n_bytes=64):
    """Invert ``n_bytes`` in the middle of each listed chunk (0-based) of an .mcap, in place."""
    data = bytearray(mcap_file.read_bytes())
    for k in chunk_numbers:
        idx = chunk_indexes(mcap_file)[k]
        mid = idx.chunk_start_offset + idx.chunk_length // 2
        data[mid:mid + n_bytes] = bytes(b ^ 0xFF for b in data[mid:mid + n_bytes])
    mcap_file.write_bytes(bytes(data))


def test_an_offline_writer_gets_a_file_in_log_time_order_with_non_overlapping_chunks(tmp_path):
    """Written topic after topic (as the importer and the synthesiser do), the file still comes out in log-time
    order, in several chunks that do not overlap, each with its CRC."""
    string = typestore().types["std_msgs/msg/String"]
    with BagWriter(tmp_path / "b") as bag:
        for topic in ("/a", "/b"):
            bag.add_topic(topic, "std_msgs/msg/String")
            for i in range(600):
                bag.write(topic, 1_000 + 7 * i, string(data=f"{topic} {i} " + "x" * 2000))
    assert bag.late_messages == 0
    mcap_file = tmp_path / "b" / "b.mcap"
    assert len(chunk_indexes(mcap_file)) >= 2
    assert order_problems(mcap_file) == {"late": 0, "overlapping_chunks": 0, "chunks_without_crc": 0}
    with BagReader(tmp_path / "b") as r:
        assert [m.timestamp_ns for m in r.messages(["/b"])] == [1_000 + 7 * i for i in range(600)]


def test_a_message_older_than_the_last_flush_is_kept_and_counted(tmp_path):
    float64 = typestore().types["std_msgs/msg/Float64"]
    with BagWriter(tmp_path / "b") as bag:
        bag.add_topic("/x", "std_msgs/msg/Float64")
        for t in (12, 10, 11):
            bag.write("/x", t, float64(data=float(t)))
        bag.flush()
        bag.write("/x", 5, float64(data=5.0))   # arrives after a flush already wrote newer ones
        bag.write("/x", 13, float64(data=13.0))
    assert bag.late_messages == 1
    with BagReader(tmp_path / "b") as r:
        assert [t for t, _ in r.read("/x")] == [5, 10, 11, 12, 13]


@pytest.mark.parametrize("name", ["natural", "elderly"])
def test_shipped_bags_are_in_log_time_order_and_match_their_metadata(name):

    bag = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "bags", name)
    mcap_file = os.path.join(bag, f"{name}.mcap")
    assert order_problems(mcap_file) == {"late": 0, "overlapping_chunks": 0, "chunks_without_crc": 0}
    with open(os.path.join(bag, "metadata.yaml")) as f:
        meta = yaml.safe_load(f)["rosbag2_bagfile_information"]
    assert meta["ros_distro"] == "jazzy"
    with BagReader(bag) as r:
        assert sum(1 for _ in r.messages()) == r.message_count == meta["message_count"]
        assert {t: i.count for t, i in r.topics().items()} == {
            t["topic_metadata"]["name"]: t["message_count"] for t in meta["topics_with_message_count"]}
    with Reader(bag) as r:
        assert sum(1 for _ in r.messages()) == meta["message_count"]


def test_metadata_and_the_mcap_name_jazzy_as_the_ros_distro(tmp_path):

    bag = write_demo_bag(tmp_path / "b")
    assert yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]["ros_distro"] == "jazzy"
    with open(bag / "b.mcap", "rb") as f:
        (record,) = make_reader(f).iter_metadata()
    assert yaml.safe_load(record.metadata["serialized_metadata"])["ros_distro"] == "jazzy"


def test_recover_a_file_cut_in_the_middle_of_its_third_chunk(tmp_path):
    mcap_file = float_bag(tmp_path / "b")
    third = chunk_indexes(mcap_file)[2]
    mcap_file.write_bytes(mcap_file.read_bytes()[: third.chunk_start_offset + third.chunk_length // 2])
    (tmp_path / "b" / "metadata.yaml").unlink()
    report = recover_bag(tmp_path / "b", tmp_path / "out")
    assert (report.messages, report.chunks, report.bad_chunks) == (200, 2, [])
    assert "cut in the middle" in report.stopped_because
    with BagReader(tmp_path / "out") as r:
        assert [m.data for _, m in r.read("/x")] == [float(i) for i in range(200)]


@pytest.mark.parametrize("killed", [False, True], ids=["complete", "killed_writer"])
@pytest.mark.parametrize("corrupt", [(0,), (0, 2)], ids=["first_chunk", "first_and_last"])
def test_recover_skips_corrupt_chunks_and_keeps_the_others(tmp_path, corrupt, killed):
    """Damaged bytes inside a chunk (the first one holds the start of the recording): that chunk is skipped and
    counted, every other chunk recovered, with or without the summary at the end of the file (a killed writer)."""
    mcap_file = float_bag(tmp_path / "b")
    last = chunk_indexes(mcap_file)[-1]
    damage(mcap_file, corrupt)
    if killed:  # the file ends after the last chunk and its message index: no summary, no metadata.yaml
        end = last.chunk_start_offset + last.chunk_length + last.message_index_length
        mcap_file.write_bytes(mcap_file.read_bytes()[:end])
        (tmp_path / "b" / "metadata.yaml").unlink()
    report = recover_bag(tmp_path / "b", tmp_path / "out")
    kept = [k for k in range(3) if k not in corrupt]
    assert len(report.bad_chunks) == len(corrupt) and report.chunks == len(kept)
    assert all("CRC mismatch" in note or "decompress" in note for note in report.bad_chunks)
    with BagReader(tmp_path / "out") as r:
        assert [m.data for _, m in r.read("/x")] == [float(i) for k in kept for i in range(100 * k, 100 * k + 100)]


def test_reading_a_corrupt_chunk_fails_naming_the_file_and_the_chunk(tmp_path):
    mcap_file = float_bag(tmp_path / "b")
    damage(mcap_file, [1])
    for read in (lambda: bag_info(tmp_path / "b"), lambda: BagReader(tmp_path / "b").read("/x")):
        with pytest.raises(BagError, match=r"b\.mcap: chunk 2 of 3 at byte \d+ \(log time 1\.100-1\.199 s\)"):
            read()


def test_reading_fewer_messages_than_the_metadata_counts_fails(tmp_path):
    """A damaged chunk without a CRC (bags from other writers) can decode to fewer messages: that must not pass."""
    float_bag(tmp_path / "b")
    meta = tmp_path / "b" / "metadata.yaml"
    meta.write_text(meta.read_text().replace("message_count: 300", "message_count: 301"))
    with pytest.raises(BagError, match="read 300 messages where its metadata counts 301"):
        list(BagReader(tmp_path / "b").messages())


def test_recovery_keeps_the_damaged_bags_subject_data(tmp_path):
    """A complete bag with one corrupt chunk: the rebuilt bag keeps its metadata's custom_data (stature, mass)."""
    damaged = tmp_path / "natural"
    damaged.mkdir()
    root = Path(__file__).resolve().parents[1] / "bags" / "natural"
    (damaged / "metadata.yaml").write_text((root / "metadata.yaml").read_text())
    data = bytearray((root / "natural.mcap").read_bytes())
    data[300_000:300_256] = bytes(256)
    (damaged / "natural.mcap").write_bytes(bytes(data))
    report = recover_bag(damaged, tmp_path / "rebuilt")
    assert report.bad_chunks, "the corrupt chunk is named"
    with BagReader(tmp_path / "rebuilt") as bag:
        assert bag.custom_data["height_m"] == "1.75" and "recovered_from" in bag.custom_data


def test_a_long_recording_holds_its_chunk_index_packed_and_writes_every_chunk_in_the_summary(tmp_path):
    """A recorder flushes a chunk every 0.5 s, and the summary's chunk index stays in memory until the bag closes
    (issue 16's soak: the recorder grew with it). Packed, 2,000 chunks of two topics cost under 0.15 kB each, and the
    summary still lists every chunk, each pointing at its chunk (rosbags' own index: 0.22 kB)."""
    string = typestore().types["std_msgs/msg/String"]
    with BagWriter(tmp_path / "b") as bag:
        for topic in ("/a", "/b"):
            bag.add_topic(topic, "std_msgs/msg/String")
            bag.write(topic, 500, string(data="first"))        # rosbags builds its serializer on first use
        bag.flush()
        tracemalloc.start()
        before = tracemalloc.get_traced_memory()[0]
        for i in range(2000):
            bag.write("/a", 1_000 + 10 * i, string(data=f"a{i}"))
            bag.write("/b", 1_005 + 10 * i, string(data=f"b{i}"))
            bag.flush()
        held = tracemalloc.get_traced_memory()[0] - before
        tracemalloc.stop()
    assert held / 2000 < 150, f"{held / 2000:.0f} bytes per chunk"
    indexes = chunk_indexes(tmp_path / "b" / "b.mcap")
    assert len(indexes) == 2001
    assert [ix.message_start_time for ix in indexes] == [500] + [1_000 + 10 * i for i in range(2000)]
    with BagReader(tmp_path / "b") as r:
        assert r.message_count == 4002
        assert [m.timestamp_ns for m in r.messages(["/b"])][-3:] == [1_005 + 10 * i for i in (1997, 1998, 1999)]
