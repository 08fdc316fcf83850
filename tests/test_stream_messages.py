"""io/stream_messages.py: the bridge's MocapFrame and ForcePlateSample bytes equal rosbags' serialization of the same
messages, and read back in rclpy; the robot state's JointState and stamped geometry bytes equal rclpy's."""

import numpy as np
import pytest
from geometry_msgs.msg import Point, PointStamped, PoseStamped, WrenchStamped
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint
from sit2stand_msgs.msg import CenterOfMass, ForcePlateSample, MocapFrame

from sit2stand.io.messages import force_plate_sample, mocap_frame
from sit2stand.io.stream_messages import (CenterOfMassEncoder, JointStateEncoder, JointStateReader,
                                          JointTrajectoryEncoder, MocapFrameEncoder, MocapFrameReader,
                                          PlateSampleEncoder, StampedNumbersEncoder, pose_from_cdr)
from sit2stand.io.topics import LAB_FRAME, MOCAP_TYPE, PLATE_TYPE
from sit2stand.io.typestore import typestore


@pytest.mark.parametrize("names", [["LASI", "RASI", "T10", "LHEE"], ["a", "bc", "def", "ghij", "klmno"], [], ["X"]])
def test_a_mocap_frame_is_rosbags_own_bytes(names):
    rng = np.random.default_rng(len(names))
    n = len(names)
    pos, valid = rng.normal(size=(n, 3)), rng.random(n) > 0.3
    res = rng.random(n).astype(np.float32)
    enc = MocapFrameEncoder(names, LAB_FRAME)
    for residuals in (res, None):
        want = bytes(typestore().serialize_cdr(mocap_frame(1_700_000_123_456_789_012, names, pos, valid, residuals),
                                               MOCAP_TYPE))
        assert enc.encode(1_700_000_123_456_789_012, pos, valid, residuals) == want


@pytest.mark.parametrize("plate", ["chair", "feet", "plate3", "p"])
def test_plate_samples_are_rosbags_own_bytes_and_rclpy_reads_them(plate):
    rng = np.random.default_rng(7)
    k = 6
    t = 1_700_000_000_000_000_000 + np.arange(k) * 500_000
    f, m, c = rng.normal(size=(k, 3)), rng.normal(size=(k, 3)), rng.normal(size=(k, 3))
    ok, free = np.array([True, False, True, True, False, True]), rng.normal(size=k)
    got = PlateSampleEncoder(plate, LAB_FRAME).encode_many(t, f, m, c, ok, free)
    for i in range(k):
        want = force_plate_sample(int(t[i]), plate, f[i], m[i], c[i], bool(ok[i]), float(free[i]))
        assert got[i] == bytes(typestore().serialize_cdr(want, PLATE_TYPE))
    msg = deserialize_message(got[2], ForcePlateSample)
    assert msg.plate_name == plate and msg.header.frame_id == LAB_FRAME and msg.cop_valid
    assert msg.wrench.force.z == f[2, 2] and msg.free_moment_z == free[2]
    frame = deserialize_message(MocapFrameEncoder(["A", "B"], LAB_FRAME).encode(5, c[:2], ok[:2]), MocapFrame)
    assert list(frame.marker_names) == ["A", "B"] and frame.positions[0].y == c[0, 1]
    assert np.isnan(frame.positions[1].x) and list(frame.valid) == [True, False]


def _canonical(data: bytes, msg_type: str) -> bytes:
    """The bytes rosbags writes for the message ``data`` holds (padding zero, as the encoders write it)."""
    store = typestore()
    return bytes(store.serialize_cdr(store.deserialize_cdr(data, msg_type), msg_type))


@pytest.mark.parametrize("names", [["leg_left_1_joint", "leg_left_2_joint", "torso_1_joint"], ["a"], []])
def test_a_joint_state_is_the_message_rclpy_builds(names):
    rng = np.random.default_rng(3)
    n = len(names)
    q, v, tau = rng.normal(size=n), rng.normal(size=n), rng.normal(size=n)
    data = JointStateEncoder(names, "base_link").encode(1_700_000_123_456_789_012, q, v, tau)
    want = JointState(name=names, position=list(q), velocity=list(v), effort=list(tau))
    want.header.frame_id, want.header.stamp.sec, want.header.stamp.nanosec = "base_link", 1_700_000_123, 456_789_012
    assert deserialize_message(data, JointState) == want
    assert data == _canonical(data, "sensor_msgs/msg/JointState")
    only = deserialize_message(JointStateEncoder(names, "pelvis", ("position",)).encode(5, q), JointState)
    assert list(only.position) == list(q) and len(only.velocity) == 0 and len(only.effort) == 0


@pytest.mark.parametrize(("msg_type", "count", "fields"), [
    (PointStamped, 3, lambda m: [(m.point, "xyz")]),
    (WrenchStamped, 6, lambda m: [(m.wrench.force, "xyz"), (m.wrench.torque, "xyz")]),
    (PoseStamped, 7, lambda m: [(m.pose.position, "xyz"), (m.pose.orientation, "xyzw")])])
def test_stamped_geometry_is_the_message_rclpy_builds(msg_type, count, fields):
    numbers = np.arange(1, count + 1) * 0.5
    want = msg_type()
    want.header.frame_id, want.header.stamp.sec, want.header.stamp.nanosec = "sole_left", 12, 345
    values = iter(numbers)
    for part, axes in fields(want):
        for axis in axes:
            setattr(part, axis, float(next(values)))
    data = StampedNumbersEncoder("sole_left", count).encode(12_000_000_345, numbers)
    assert deserialize_message(data, msg_type) == want
    assert data == _canonical(data, f"geometry_msgs/msg/{msg_type.__name__}")


@pytest.mark.parametrize("names", [["leg_left_1_joint", "leg_left_2_joint", "torso_1_joint"], ["a"], []])
def test_a_joint_command_is_the_trajectory_rclpy_builds(names):
    rng = np.random.default_rng(4)
    q, v, a = (rng.normal(size=len(names)) for _ in range(3))
    data = JointTrajectoryEncoder(names, "base_link").encode(1_700_000_123_456_789_012, q, v, a)
    want = JointTrajectory(joint_names=names, points=[JointTrajectoryPoint(
        positions=list(q), velocities=list(v), accelerations=list(a))])
    want.header.frame_id, want.header.stamp.sec, want.header.stamp.nanosec = "base_link", 1_700_000_123, 456_789_012
    assert deserialize_message(data, JointTrajectory) == want
    assert data == _canonical(data, "trajectory_msgs/msg/JointTrajectory")


def test_joint_states_and_poses_are_read_from_their_bytes():
    """The retargeter's reading of the robot's state: stamp and positions as rclpy's message has them, whichever
    frame id and joint names (read again when they change)."""
    reader = JointStateReader()
    for names, frame in [(["a", "bb", "ccc"], "base_link"), (["a", "bb", "ccc"], "base_link"), (["x"], "w"),
                         ([], "pelvis"), (["a", "bb", "ccc"], "base_link")]:
        q = np.arange(len(names)) + 0.25
        data = JointStateEncoder(names, frame).encode(3_000_000_007, q, -q, 2 * q)
        t_ns, got = reader.read(data)
        assert t_ns == 3_000_000_007 and reader.names == names and got.tolist() == q.tolist()
    ref = serialize_message(JointState(name=["j1", "j2"], position=[0.5, -1.0]))
    assert reader.read(ref)[1].tolist() == [0.5, -1.0] and reader.names == ["j1", "j2"]
    for frame in ["", "world", "odom_frame"]:
        pose = PoseStamped()
        pose.header.frame_id, pose.header.stamp.sec, pose.header.stamp.nanosec = frame, 7, 8
        pose.pose.position.x, pose.pose.orientation.z, pose.pose.orientation.w = 1.5, 0.6, 0.8
        t_ns, numbers = pose_from_cdr(serialize_message(pose))
        assert t_ns == 7_000_000_008 and numbers.tolist() == [1.5, 0, 0, 0, 0, 0.6, 0.8]


def test_mocap_frames_are_read_from_their_bytes_as_rclpy_builds_them():
    """The estimator's and the retargeter's reading of a marker frame: stamp, names, positions (NaN where invalid)
    and validity as rclpy's message has them, whichever frame id, name lengths (each shifts the alignment) and count
    (names read again when they change); a frame cut short, or whose arrays disagree with its names, is refused."""
    rng = np.random.default_rng(3)
    reader = MocapFrameReader()
    for names, frame in [(["LASI", "RASI", "T10"], "lab"), (["LASI", "RASI", "T10"], "lab"), (["a", "bcdefgh"], ""),
                         ([], "lab_frame"), (["x", "yy", "zzz", "wwww", "v"], "l"), (["LASI", "RASI", "T10"], "lab")]:
        msg = MocapFrame(marker_names=names, valid=[bool(v) for v in rng.random(len(names)) > 0.3],
                         residuals_m=[0.001] * len(names))
        msg.header.frame_id, msg.header.stamp.sec, msg.header.stamp.nanosec = frame, 1_700_000_123, 456_789_012
        msg.positions = [Point(x=x, y=y, z=z) for x, y, z in rng.normal(size=(len(names), 3))]
        t_ns, got_names, pos, valid = reader.read(serialize_message(msg))
        assert t_ns == 1_700_000_123_456_789_012 and got_names == names and valid.tolist() == list(msg.valid)
        want = np.array([[p.x, p.y, p.z] for p in msg.positions]).reshape(-1, 3)
        want[~valid] = np.nan
        np.testing.assert_array_equal(pos, want)
    msg.valid = msg.valid[:-1]
    with pytest.raises(ValueError, match="3 marker names, 3 positions and 2 validity flags"):
        reader.read(serialize_message(msg))
    with pytest.raises(ValueError, match="cut short"):
        MocapFrameReader().read(serialize_message(msg)[:30])


@pytest.mark.parametrize(("source", "frame"), [("robot_plan", "world"), ("skeleton_fit", "lab"), ("", "")])
def test_a_com_estimate_is_the_message_rclpy_builds(source, frame):
    enc = CenterOfMassEncoder(source, frame)
    for valid, rms, cop_error, n in [(True, 0.004, 0.012, 39), (False, float("nan"), float("nan"), 0)]:
        data = enc.encode(1_700_000_123_456_789_012, [1, 2, 3], [4, 5, 6], [7, 8, 9], valid, rms, cop_error, n)
        got = deserialize_message(data, CenterOfMass)
        assert (got.header.frame_id, got.header.stamp.sec, got.header.stamp.nanosec) == (frame, 1_700_000_123,
                                                                                        456_789_012)
        assert [got.position.x, got.velocity.y, got.acceleration.z] == [1, 5, 9]
        assert (got.source, got.valid, got.n_markers) == (source, valid, n)
        assert np.array_equal([got.marker_rms_m, got.cop_error_m], [rms, cop_error], equal_nan=True)
        assert data == _canonical(data, "sit2stand_msgs/msg/CenterOfMass")
