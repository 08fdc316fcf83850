"""The robot's measured state as the live retargeter receives it.

The newest serialized ``/robot/joint_states`` and ``/robot/base_pose`` are kept as bytes (the robot publishes at
500 Hz, into the retargeter's real-time process) and read only when the calibration or a command needs them: the
measured seated posture the calibration overlays the first human frame on, and the measured configuration the COM
feedback and the plan's pacing use, if it is current (:func:`~sit2stand.retarget.pacing.robot_state_current`).
"""

from __future__ import annotations

import numpy as np

from ..io.stream_messages import JointStateReader, pose_from_cdr
from .pacing import robot_state_current


class RobotStateInbox:
    """The robot's newest joint state and base pose (serialized), with when each arrived (wall clock [s])."""

    def __init__(self, sim_time: bool) -> None:
        self.sim_time = sim_time
        self.joint_states: bytes | None = None
        self.base_pose: bytes | None = None
        self._received = (0.0, 0.0)
        self._reader = JointStateReader()
        # the message's names and the model's joints (as lists: compared by identity), each model joint's index
        self._order: tuple[list[str], list[str], np.ndarray] | None = None

    def add_joint_states(self, data: bytes, wall_s: float) -> None:
        self.joint_states, self._received = data, (wall_s, self._received[1])

    def add_base_pose(self, data: bytes, wall_s: float) -> None:
        self.base_pose, self._received = data, (self._received[0], wall_s)

    @property
    def complete(self) -> bool:
        """Both have come."""
        return self.joint_states is not None and self.base_pose is not None

    def start(self) -> tuple[np.ndarray, list[str]]:
        """The measured configuration (base x y z, quaternion x y z w, then the joints in the message's order) and
        the message's joint names: the seated posture the calibration starts from."""
        _, positions = self._reader.read(self.joint_states)
        return self._configuration(positions), list(self._reader.names)

    def current(self, joint_names: list[str], ros_now_ns: int, wall_s: float) -> tuple[np.ndarray, float] | None:
        """The measured configuration in ``joint_names``' order and its stamp [s]; None if none has come, if it
        lacks one of the joints, or if it is not current (received or stamped too long ago)."""
        if not self.complete:
            return None
        stamp, positions = self._reader.read(self.joint_states)
        if not robot_state_current(wall_s - min(self._received), (ros_now_ns - stamp) * 1e-9, self.sim_time):
            return None
        names = self._reader.names
        if self._order is None or self._order[0] is not names or self._order[1] is not joint_names:
            if not set(joint_names) <= set(names):
                return None
            self._order = (names, joint_names, np.array([names.index(n) for n in joint_names]))
        return self._configuration(positions[self._order[2]]), stamp * 1e-9

    def _configuration(self, positions: np.ndarray) -> np.ndarray:
        return np.concatenate([pose_from_cdr(self.base_pose)[1], positions])
