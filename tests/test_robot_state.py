"""sit2stand.retarget.robot_state: the robot's measured state kept as bytes, read when the retargeter needs it."""

import numpy as np

from sit2stand.io.stream_messages import JointStateEncoder, StampedNumbersEncoder
from sit2stand.retarget.robot_state import RobotStateInbox

NAMES = ["knee", "hip", "ankle"]


def messages(t_ns: int, positions):
    joints = JointStateEncoder(NAMES, "base", ("position",)).encode(t_ns, positions)
    pose = StampedNumbersEncoder("world", StampedNumbersEncoder.POSE).encode(t_ns, [0.1, 0.0, 0.6, 0, 0, 0, 1])
    return joints, pose


def test_the_start_posture_and_the_current_configuration_in_the_models_order():
    inbox = RobotStateInbox(sim_time=False)
    assert not inbox.complete and inbox.current(NAMES, 0, 0.0) is None
    joints, pose = messages(1_000_000_000, [1.0, 2.0, 3.0])
    inbox.add_joint_states(joints, 10.0)
    assert not inbox.complete
    inbox.add_base_pose(pose, 10.0)
    q, names = inbox.start()
    assert names == NAMES and np.allclose(q, [0.1, 0.0, 0.6, 0, 0, 0, 1, 1.0, 2.0, 3.0])
    q, stamp = inbox.current(["hip", "ankle", "knee"], 1_001_000_000, 10.001)
    assert stamp == 1.0 and np.allclose(q[7:], [2.0, 3.0, 1.0])
    assert inbox.current(["hip", "elbow"], 1_001_000_000, 10.001) is None, "a joint the message lacks"


def test_a_state_stamped_or_received_too_long_ago_is_not_current_unless_on_simulated_time():
    joints, pose = messages(1_000_000_000, [1.0, 2.0, 3.0])
    for sim_time in (False, True):
        inbox = RobotStateInbox(sim_time)
        inbox.add_joint_states(joints, 10.0)
        inbox.add_base_pose(pose, 10.0)
        assert inbox.current(NAMES, 2_000_000_000, 10.0) is None, "stamped 1 s before the graph's clock"
        received_late = inbox.current(NAMES, 1_000_000_000, 60.0)
        assert (received_late is not None) == sim_time, "under /clock the wall time since it came says nothing"
