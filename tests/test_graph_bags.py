"""Graph tests: real replayer and recorder processes over DDS on localhost.

C3D -> bag -> replayer -> recorder -> bag, and the recorded messages equal the originals (counts, order and values
per topic); the recorder survives SIGKILL up to its last flush; bad bags make the replayer exit with a clear error.
"""

from __future__ import annotations

import dataclasses
import re
import shutil
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
import rclpy
from conftest import GRAPHS, real_file
from diagnostic_msgs.msg import DiagnosticStatus
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosgraph_msgs.msg import Clock
from std_srvs.srv import SetBool

from sit2stand.io.bag import BagError, BagReader, BagWriter
from sit2stand.io.c3d import read_c3d, write_trial_bag
from sit2stand.io.recover import recover_bag
from sit2stand_msgs.msg import MocapFrame

pytestmark = pytest.mark.graph


def same(a, b, path="msg") -> None:
    """Assert two deserialized messages are equal field by field (NaN equals NaN)."""
    if dataclasses.is_dataclass(a):
        assert type(a).__name__ == type(b).__name__, path
        for f in dataclasses.fields(a):
            same(getattr(a, f.name), getattr(b, f.name), f"{path}.{f.name}")
    elif isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b), err_msg=path)
    elif isinstance(a, (list, tuple)):
        assert len(a) == len(b), path
        for i, (x, y) in enumerate(zip(a, b)):
            same(x, y, f"{path}[{i}]")
    elif isinstance(a, float):
        assert (np.isnan(a) and np.isnan(b)) or a == b, f"{path}: {a} != {b}"
    else:
        assert a == b, f"{path}: {a!r} != {b!r}"


def assert_bags_equal(original, recorded, topics=None):
    with BagReader(original) as a, BagReader(recorded) as b:
        names = topics or sorted(a.topics())
        assert sorted(b.topics()) == sorted(names), "recorded topics differ"
        for topic in names:
            xs, ys = a.read(topic), b.read(topic)
            assert len(xs) == len(ys), f"{topic}: {len(ys)} recorded of {len(xs)}"
            for i, ((_, x), (_, y)) in enumerate(zip(xs, ys)):
                same(x, y, f"{topic}[{i}]")


def launch(ros_env, tmp_path, *overrides, timeout=120):
    cmd = [sys.executable, "-m", "sit2stand.cli", "launch", str(GRAPHS / "roundtrip.yaml"), *overrides]
    result = subprocess.run(cmd, env=ros_env, capture_output=True, text=True, timeout=timeout, cwd=tmp_path)
    return result.returncode, result.stdout + result.stderr


def test_c3d_to_bag_to_replayer_to_recorder_round_trip(sts_bag, ros_env, tmp_path):
    out = tmp_path / "copy"
    code, log = launch(ros_env, tmp_path, f"bag:={sts_bag}", f"out:={out}", "rate:=1.0")
    assert code == 0, log
    assert "[replayer] " in log and "[recorder] " in log
    assert_bags_equal(sts_bag, out)


def test_two_plates_at_five_times_real_time(ros_env, tmp_path):
    bag = tmp_path / "walk"
    write_trial_bag(read_c3d(real_file("walk_amti_eb015pi.c3d")), bag)
    out = tmp_path / "copy"
    t0 = time.monotonic()
    code, log = launch(ros_env, tmp_path, f"bag:={bag}", f"out:={out}", "rate:=5")
    assert code == 0, log
    assert_bags_equal(bag, out)
    played_s = float(re.search(r"done: \d+ messages published in ([\d.]+) s", log).group(1))
    assert 1.4 < played_s < 3.5, "the 9 s bag at 5x: ~1.8 s"
    with BagReader(out) as rec, BagReader(bag) as orig:
        # one time base: logged at the replayer's /clock, the copy spans the original's 9 s, not the 1.8 s it took;
        # within 0.3 s at either end: at 5x (2,250 messages a second) a recorder behind on its queue logs at the
        # /clock it has taken so far, as rosbag2's does (in full runs on a slow host: 8.92 and 8.84 s for 9.0, the
        # first message at 0.08 s)
        assert orig.duration_s == pytest.approx(9.0, abs=0.05)
        assert rec.duration_s == pytest.approx(orig.duration_s, abs=0.3)
        assert abs(rec.start_ns - orig.start_ns) <= 300_000_000, "within the bag's first frames"
    assert time.monotonic() - t0 < 60


def test_as_fast_as_the_subscribers_take_it_loses_nothing(ros_env, tmp_path):
    bag = tmp_path / "cmj"
    write_trial_bag(read_c3d(real_file("cmj_vicon_kistler.c3d")), bag)  # 19 200 messages
    out = tmp_path / "copy"
    code, log = launch(ros_env, tmp_path, f"bag:={bag}", f"out:={out}", "rate:=0")
    assert code == 0, log
    assert_bags_equal(bag, out)


def test_recorder_killed_with_sigkill_loses_at_most_the_last_second(ros_env, tmp_path, run_node):
    bag = tmp_path / "walk"
    write_trial_bag(read_c3d(real_file("walk_amti_eb015pi.c3d")), bag)
    out = tmp_path / "killed"
    rec = run_node("sit2stand.nodes.recorder", "--ros-args", "-p", f"output:={out}", "-p", "regex:=^/(mocap|force)",
                   "-p", "discovery_period_s:=0.2")
    play = run_node("sit2stand.nodes.replayer", "--ros-args", "-p", f"bag:={bag}", "-p", "wait_for_subscribers:=1",
                    "-p", "wait_timeout_s:=60.0")
    assert play.wait_for_output("playing", 20)
    assert rec.wait_for_output("subscribed to /mocap/markers", 60), rec.output
    # killed once it has flushed more than 100 messages to disk, while the 9 s bag still plays (not after a time)
    deadline = time.monotonic() + 60
    while flushed_messages(out, tmp_path / "probe") <= 100 and play.proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.1)
    assert play.proc.poll() is None, f"the replay ended before the kill:\n{play.output}"
    kill_time_ns = time.time_ns()
    rec.proc.send_signal(signal.SIGKILL)
    rec.wait(10)
    play.stop(signal.SIGINT)
    assert not (out / "metadata.yaml").exists()
    report = recover_bag(out)
    assert report.messages > 100
    lost_s = (kill_time_ns - report.last_ns) * 1e-9   # recorder stamps are receive times (wall clock)
    assert 0.0 <= lost_s <= 1.0, f"lost the last {lost_s:.2f} s"
    # what was recovered is exactly the start of what was played, per topic
    with BagReader(bag) as a, BagReader(out) as b:
        for topic, n in report.topics.items():
            xs, ys = a.read(topic)[:n], b.read(topic)
            for i, ((_, x), (_, y)) in enumerate(zip(xs, ys)):
                same(x, y, f"{topic}[{i}]")


def test_recorder_closes_cleanly_on_sigterm_and_picks_up_late_topics(sts_bag, ros_env, tmp_path, run_node):
    out = tmp_path / "rec"
    rec = run_node("sit2stand.nodes.recorder", "--ros-args", "-p", f"output:={out}",
                   "-p", "topics:=['/mocap/markers']", "-p", "discovery_period_s:=0.2")
    assert rec.wait_for_output("recording to", 20)
    # the scenario, not a wait: nothing publishes yet, the topic appears later; nothing depends on how long (the
    # replayer plays once the recorder subscribes)
    time.sleep(0.5)
    play = run_node("sit2stand.nodes.replayer", "--ros-args", "-p", f"bag:={sts_bag}", "-p", "wait_for_subscribers:=1",
                    "-p", "wait_timeout_s:=60.0", "-p", "topics:=['/mocap/markers']")
    # the replayer ends once the recorder acknowledged every message: SIGTERM then finds them all delivered (the
    # recorder takes what DDS delivered before it closes)
    assert play.wait(90) == 0, play.output
    assert "did not acknowledge" not in play.output, play.output
    assert rec.stop(signal.SIGTERM) == 0, rec.output
    assert_bags_equal(sts_bag, out, topics=["/mocap/markers"])


def test_pause_resume_progress_and_clock(sts_bag, ros_env, tmp_path, run_node):

    # wait_for_subscribers: it plays (and reports progress) once this test's subscription to /mocap/markers matched
    play = run_node("sit2stand.nodes.replayer", "--ros-args", "-p", f"bag:={sts_bag}", "-p", "start_paused:=true",
                    "-p", "topics:=['/mocap/markers']", "-p", "at_end:=idle", "-p", "wait_for_subscribers:=1",
                    "-p", "wait_timeout_s:=60.0")
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        node = rclpy.create_node("tester", context=context)
        frames, clocks, progress = [], [], []
        node.create_subscription(MocapFrame, "/mocap/markers", frames.append, 1000)
        node.create_subscription(Clock, "/clock", clocks.append, rclpy.qos.QoSProfile(
            depth=100, reliability=rclpy.qos.ReliabilityPolicy.BEST_EFFORT))  # ROS's clock QoS
        node.create_subscription(DiagnosticStatus, "/replayer/progress", progress.append, 100)
        client = node.create_client(SetBool, "/replayer/pause")
        executor = rclpy.executors.SingleThreadedExecutor(context=context)
        executor.add_node(node)

        def spin_for(seconds):
            end = time.monotonic() + seconds
            while time.monotonic() < end:
                executor.spin_once(timeout_sec=0.05)

        def spin_until(condition, seconds):
            end = time.monotonic() + seconds
            while not condition() and time.monotonic() < end:
                executor.spin_once(timeout_sec=0.05)
            return condition()

        def final(status):
            values = {kv.key: kv.value for kv in status.values}
            return values["messages_sent"] == "91" and float(values["fraction"]) == pytest.approx(1.0)

        assert client.wait_for_service(timeout_sec=60), play.output
        # its progress (2 Hz, once it found this subscriber) says paused; then, for 1.5 s (a window to see that
        # nothing comes, not a wait: no frame may come however long it is), it publishes nothing
        assert spin_until(lambda: progress, 60), play.output
        assert progress[-1].message == "paused"
        spin_for(1.5)
        assert frames == [], "a paused replayer must not publish"
        assert progress[-1].message == "paused"
        future = client.call_async(SetBool.Request(data=False))
        executor.spin_until_future_complete(future, timeout_sec=10)
        assert future.result().success and future.result().message == "playing"
        # its last progress (once every subscriber acknowledged every frame) says all 91 sent: then every frame is
        # here, and no more come (at_end:=idle)
        assert spin_until(lambda: len(frames) >= 91 and final(progress[-1]), 30), (len(frames), progress[-1])
        assert len(frames) == 91
        values = {kv.key: kv.value for kv in progress[-1].values}
        assert float(values["fraction"]) == pytest.approx(1.0) and values["messages_sent"] == "91"
        stamps = [c.clock.sec + c.clock.nanosec * 1e-9 for c in clocks]
        assert stamps and 9.96 < stamps[0] and stamps[-1] < 10.9 and stamps == sorted(stamps)
        assert play.proc.poll() is None, "at_end:=idle keeps the node alive"
        node.destroy_node()
    finally:
        rclpy.shutdown(context=context)
    assert play.stop() == 0


def test_loop_plays_the_bag_again(sts_bag, ros_env, tmp_path, run_node):
    out = tmp_path / "rec"
    rec = run_node("sit2stand.nodes.recorder", "--ros-args", "-p", f"output:={out}", "-p", "topics:=['/mocap/markers']",
                   "-p", "discovery_period_s:=0.2")
    play = run_node("sit2stand.nodes.replayer", "--ros-args", "-p", f"bag:={sts_bag}", "-p", "loop:=true",
                    "-p", "rate:=10.0", "-p", "topics:=['/mocap/markers']", "-p", "wait_for_subscribers:=1",
                    "-p", "wait_timeout_s:=60.0")
    assert play.wait_for_output("playing", 20)
    # stopped once it has published the 91 frames three times over (its progress line), not after a time
    deadline = time.monotonic() + 60
    while max(sent_messages(play.output), default=0) < 3 * 91 and time.monotonic() < deadline:
        assert play.proc.poll() is None, play.output
        time.sleep(0.1)
    assert max(sent_messages(play.output), default=0) >= 3 * 91, play.output
    assert play.stop() == 0
    assert rec.stop() == 0
    with BagReader(out) as b:
        assert b.topics()["/mocap/markers"].count > 2 * 91


def sent_messages(output: str) -> list[int]:
    """The messages a replayer has published, by its progress lines (every 2 s while it plays)."""
    return [int(n) for n in re.findall(r"bag time [\d.]+/[\d.]+ s, (\d+) messages", output)]


def flushed_messages(bag_dir, scratch) -> int:
    """The messages a running recorder has written to disk so far: its open .mcap read as a killed one is (rebuilt
    into ``scratch``, the recorder's file only read); 0 before it holds a readable start."""
    shutil.rmtree(scratch, ignore_errors=True)
    try:
        return recover_bag(bag_dir, scratch).messages if any(bag_dir.glob("*.mcap")) else 0
    except BagError:
        return 0


def replayer_cli(ros_env, *params):
    """The replayer run alone through its console script, as a user would."""
    exe = [str(p) for p in (sys.prefix + "/bin/replayer",)]
    args = exe + ["--ros-args"] + [x for p in params for x in ("-p", p)]
    return subprocess.run(args, env=ros_env, capture_output=True, text=True, timeout=60)


def test_replayer_rejects_a_truncated_bag(sts_bag, ros_env, tmp_path):

    bad = tmp_path / "cut"
    shutil.copytree(sts_bag, bad)
    mcap = next(bad.glob("*.mcap"))
    mcap.write_bytes(mcap.read_bytes()[:5000])
    result = replayer_cli(ros_env, f"bag:={bad}")
    assert result.returncode == 2, result.stdout + result.stderr
    assert str(bad) in result.stderr and "truncated or corrupt" in result.stderr


def test_replayer_rejects_a_bag_with_an_unknown_type(ros_env, tmp_path):

    store = get_typestore(Stores.ROS2_JAZZY)
    store.register(get_types_from_msg("float64 pressure_pa", "lab_msgs/msg/Barometer"))
    with Writer(tmp_path / "foreign", version=9, storage_plugin=StoragePlugin.MCAP) as w:
        conn = w.add_connection("/baro", "lab_msgs/msg/Barometer", typestore=store)
        w.write(conn, 5, store.serialize_cdr(store.types["lab_msgs/msg/Barometer"](pressure_pa=1.0),
                                             "lab_msgs/msg/Barometer"))
    result = replayer_cli(ros_env, f"bag:={tmp_path / 'foreign'}")
    assert result.returncode == 2
    assert "/baro" in result.stderr and "lab_msgs/msg/Barometer" in result.stderr


def test_replayer_names_a_missing_bag_and_a_bad_rate(ros_env, tmp_path, sts_bag):
    result = replayer_cli(ros_env, f"bag:={tmp_path / 'nowhere'}")
    assert result.returncode == 2 and "no such bag" in result.stderr
    result = replayer_cli(ros_env, f"bag:={sts_bag}", "rate:=80.0")
    assert result.returncode == 2 and "outside 0.1..50" in result.stderr


def test_recorder_refuses_to_overwrite(ros_env, tmp_path, sts_bag):
    result = subprocess.run([sys.prefix + "/bin/recorder", "--ros-args", "-p", f"output:={sts_bag}"],
                            env=ros_env, capture_output=True, text=True, timeout=60)
    assert result.returncode == 2 and "exists already" in result.stderr
    assert BagWriter  # the same rule as the library's writer


def test_wait_for_counts_a_topic_the_bag_does_not_hold(sts_bag, ros_env, tmp_path, run_node):
    """wait_for may name a downstream topic (the stand-up graph waits for /human/com's subscribers): the replayer
    plays once the graph has them, and, without them, after wait_timeout_s with a warning naming the topic."""
    alone = replayer_cli(ros_env, f"bag:={sts_bag}", "rate:=20.0", "wait_for:=['/robot/joint_command:1']",
                         "wait_timeout_s:=1.0")
    assert alone.returncode == 0, alone.stderr
    assert "playing without the awaited subscribers on /robot/joint_command" in alone.stdout + alone.stderr
    driver = run_node("sit2stand.nodes.driver")          # subscribes /robot/joint_command when it starts
    assert driver.wait_for_output("seated on a", 60)
    waited = replayer_cli(ros_env, f"bag:={sts_bag}", "rate:=20.0", "wait_for:=['/robot/joint_command:1']",
                          "wait_timeout_s:=30.0")
    assert waited.returncode == 0, waited.stderr
    assert "playing without" not in waited.stdout + waited.stderr
    driver.stop()


def test_two_replayers_on_one_domain_stop_instead_of_mixing(sts_bag, ros_env, run_node):
    """Two graphs on one ROS domain would mix their streams: the later replayer stops with exit 2 naming the other and
    the domain (the other may find itself alone again by then and go on)."""
    replayers = [run_node("sit2stand.nodes.replayer", "--ros-args", "-p", f"bag:={sts_bag}", "-p", "loop:=true")
                 for _ in range(2)]
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline and all(r.proc.poll() is None for r in replayers):
        time.sleep(0.1)
    stopped = [r for r in replayers if r.proc.poll() is not None]
    assert stopped and stopped[0].proc.returncode == 2, "".join(r.output for r in replayers)
    # the later node stops on the other's announcement (GraphGuard), or on seeing its topics published twice; which
    # comes first, and whether DDS has named the other publisher by then, is discovery's timing, not the behaviour
    out = stopped[0].output
    domain = ros_env["ROS_DOMAIN_ID"]
    guard = re.search(rf"another graph's /replayer \(run pid\d+, pid \d+\) is running on ROS_DOMAIN_ID {domain}\b", out)
    collision = re.search(rf"/\S+ has 2 publishers \([^)]*\) on ROS domain {domain}:", out)
    assert guard or collision, out
    assert "_UNKNOWN_" not in out, out
