"""io/tf_message.py: the TFMessage bytes laid out once per frame list read back, in rclpy and in rosbags, as the
message they stand for."""

import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message
from tf2_msgs.msg import TFMessage

from sit2stand.errors import InputError
from sit2stand.io.tf_message import TfEncoder
from sit2stand.io.topics import TF_TYPE
from sit2stand.io.typestore import typestore

# frame names of every length mod 4 (string padding) and one empty name
PAIRS = [("world", "base_link"), ("base_link", "torso_1_link"), ("a", "bc"), ("abc", "abcd"), ("", "x" * 9)]


def _random(n, seed=0):
    rng = np.random.default_rng(seed)
    q = rng.normal(size=(n, 4))
    return rng.normal(size=(n, 3)), q / np.linalg.norm(q, axis=1, keepdims=True)


@pytest.mark.parametrize("stamp_ns", [0, 1, 1_796_154_669_592_003_033, 100 * 10**9 + 999_999_999])
def test_rclpy_reads_back_every_frame_number_and_stamp(stamp_ns):
    t, q = _random(len(PAIRS))
    msg = deserialize_message(TfEncoder(PAIRS).encode(stamp_ns, t, q), TFMessage)
    assert [(m.header.frame_id, m.child_frame_id) for m in msg.transforms] == PAIRS
    for m, tk, qk in zip(msg.transforms, t, q):
        assert (m.header.stamp.sec, m.header.stamp.nanosec) == divmod(stamp_ns, 10**9)
        tr, r = m.transform.translation, m.transform.rotation
        assert [tr.x, tr.y, tr.z, r.x, r.y, r.z, r.w] == [*tk, *qk]       # float64 carried bit for bit


def test_the_bytes_are_rclpys_own_serialization_up_to_padding():
    """Same length as rclpy's serialization of the same message, and rosbags (what the recorder's bags are read
    with) reads the same numbers."""
    t, q = _random(len(PAIRS), seed=1)
    ours = TfEncoder(PAIRS).encode(123_456_789_012, t, q)
    msg = deserialize_message(ours, TFMessage)
    assert len(serialize_message(msg)) == len(ours)
    back = typestore().deserialize_cdr(ours, TF_TYPE)
    got = np.array([[m.transform.translation.x, m.transform.translation.y, m.transform.translation.z,
                     m.transform.rotation.x, m.transform.rotation.y, m.transform.rotation.z, m.transform.rotation.w]
                    for m in back.transforms])
    np.testing.assert_array_equal(got, np.hstack([t, q]))
    assert [(m.header.frame_id, m.child_frame_id) for m in back.transforms] == PAIRS


def test_each_message_is_independent_of_the_previous():
    enc = TfEncoder(PAIRS[:2])
    t1, q1 = _random(2, seed=2)
    first = enc.encode(5, t1, q1)
    enc.encode(6, *_random(2, seed=3))
    again = deserialize_message(first, TFMessage)
    assert again.transforms[1].transform.translation.z == t1[1, 2] and again.transforms[0].header.stamp.nanosec == 5


def test_arrays_of_the_wrong_shape_are_named():
    with pytest.raises(InputError, match=r"TF of 5 transforms: translations \(4, 3\) and rotations \(5, 4\)"):
        TfEncoder(PAIRS).encode(0, np.zeros((4, 3)), np.zeros((5, 4)))
