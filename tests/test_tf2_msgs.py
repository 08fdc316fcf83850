"""msgs/tf2_msgs: our build of ROS 2 Jazzy's tf2_msgs is the same type as the distribution's (RIHS01 hashes), and
sit2stand's bag type store reads and writes it."""

import json
import sys
from pathlib import Path

import numpy as np
import pytest
import rclpy
from rclpy.node import Node
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from tf2_msgs.msg import TFMessage

from sit2stand.io.bag import BagReader, BagWriter
from sit2stand.io.topics import TF_TOPIC, TF_TYPE
from sit2stand.io.typestore import typestore

ROOT = Path(__file__).resolve().parents[1]
SOURCE = ROOT / "msgs" / "tf2_msgs" / "msg"
JAZZY = get_typestore(Stores.ROS2_JAZZY)


@pytest.mark.parametrize("name", ["TFMessage", "TF2Error"])
def test_the_message_definitions_are_jazzys(name):
    """Field for field (and constant for constant) what rosbags' Jazzy store holds for tf2_msgs."""
    ours = get_types_from_msg((SOURCE / f"{name}.msg").read_text(), f"tf2_msgs/msg/{name}")
    assert ours[f"tf2_msgs/msg/{name}"] == JAZZY.fielddefs[f"tf2_msgs/msg/{name}"]


@pytest.mark.parametrize("name", ["TFMessage", "TF2Error"])
def test_the_built_type_hash_is_jazzys(name):
    """The RIHS01 hash rosidl generated for our build (share/tf2_msgs/msg/*.json) equals Jazzy's."""
    desc = json.loads((Path(sys.prefix) / "share" / "tf2_msgs" / "msg" / f"{name}.json").read_text())
    built = {h["type_name"]: h["hash_string"] for h in desc["type_hashes"]}
    assert built[f"tf2_msgs/msg/{name}"] == JAZZY.hash_rihs01(f"tf2_msgs/msg/{name}")


def test_rclpy_announces_our_tfmessage_with_jazzys_type_hash(monkeypatch):
    """What a publisher of our TFMessage tells the graph (and RViz, Foxglove or rosbag2 check) is Jazzy's hash."""
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        node = Node("tf_hash_probe", context=context)
        node.create_publisher(TFMessage, "/tf_hash_probe", 1)
        info = node.get_publishers_info_by_topic("/tf_hash_probe")[0]
        assert info.topic_type == TF_TYPE
        assert str(info.topic_type_hash) == JAZZY.hash_rihs01(TF_TYPE) == \
            "RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087"
        node.destroy_node()
    finally:
        rclpy.shutdown(context=context)


def test_sit2stands_bags_write_and_read_tfmessage(tmp_path):
    """The shared type store knows TFMessage; a bag of it reads back the same numbers and frame names."""
    store = typestore()
    assert TF_TYPE in store.fielddefs
    t = store.types
    msg = t[TF_TYPE](transforms=[t["geometry_msgs/msg/TransformStamped"](
        header=t["std_msgs/msg/Header"](stamp=t["builtin_interfaces/msg/Time"](sec=100, nanosec=5),
                                        frame_id="world"),
        child_frame_id="base_link",
        transform=t["geometry_msgs/msg/Transform"](
            translation=t["geometry_msgs/msg/Vector3"](x=0.1, y=-0.2, z=0.7),
            rotation=t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.6, z=0.0, w=0.8)))])
    with BagWriter(tmp_path / "tf") as bag:
        bag.add_topic(TF_TOPIC, TF_TYPE)
        bag.write(TF_TOPIC, 100_000_000_005, msg)
    with BagReader(tmp_path / "tf") as bag:
        assert bag.topics()[TF_TOPIC].msgtype == TF_TYPE
        [(_, back)] = bag.read(TF_TOPIC)
    tr = back.transforms[0]
    assert (tr.header.frame_id, tr.child_frame_id, tr.header.stamp.sec, tr.header.stamp.nanosec) == \
        ("world", "base_link", 100, 5)
    np.testing.assert_array_equal([tr.transform.translation.x, tr.transform.translation.y,
                                   tr.transform.translation.z, tr.transform.rotation.y], [0.1, -0.2, 0.7, 0.6])
