"""sit2stand.io.messages: reading a header stamp off serialized bytes, as the replayer's lockstep does."""

import numpy as np

from sit2stand.io.messages import cdr_header_stamp_ns
from sit2stand.io.typestore import typestore


def _joint_state(sec: int, nanosec: int):
    store = typestore()
    t = store.types
    header = t["std_msgs/msg/Header"](stamp=t["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec),
                                      frame_id="base_link")
    msg = t["sensor_msgs/msg/JointState"](header=header, name=["a"], position=np.zeros(1), velocity=np.zeros(1),
                                          effort=np.zeros(1))
    return store, msg


def test_the_stamp_is_read_off_little_and_big_endian_cdr():
    store, msg = _joint_state(1_796_190_549, 701_695_807)
    little = store.serialize_cdr(msg, "sensor_msgs/msg/JointState")
    big = store.serialize_cdr(msg, "sensor_msgs/msg/JointState", little_endian=False)
    assert cdr_header_stamp_ns(little) == cdr_header_stamp_ns(big) == 1_796_190_549_701_695_807
