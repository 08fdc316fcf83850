"""A robot's description and frame tree for ROS tools: ``/robot_description``, ``/tf`` and ``/tf_static``.

What ``robot_state_publisher`` does on a full ROS install (it is not on PyPI): the URDF's link tree, where each
moving joint gives a transform parent link -> child link from the measured joint position and each fixed joint a
static one; the floating base adds ``world`` -> the profile's root link from the base pose. Each transform is the
placement of the child link's frame in the parent link's, from Pinocchio's model of the URDF itself
(``pin.buildModelFromXML``; the URDF link names are Pinocchio's body frames), so a tool that loads the URDF sees the
robot where the transforms put it. For a revolute joint j between links p and c that placement is

    X_pc(theta) = A_j * Rot(a_j, theta),     A_j = F_p^-1 * M_j

with M_j the joint's placement in its parent joint, F_p the parent link's placement in its joint (a link fixed to
another has one; a URDF child link's frame is its joint's) and a_j the joint's axis. These are constants taken from
the model once, so each message costs a few vectorised quaternion products: ~30 us for 32 joints (TALOS), against
~200 us for Pinocchio's forward kinematics and 32 relative placements in a Python loop (measured on a 2-core host).
The soles' world positions come from Pinocchio's forward kinematics.

sit2stand adds its own frames:

* ``lab`` -> ``world`` (static, identity): the capture volume's frame and the simulation's coincide here;
* ``sole_<side>`` under the profile's foot link (static, the sole's depth below it, no rotation): the controller
  model's sole frames (on TALOS they coincide with the URDF's own sole links);
* ``sole_<side>_world_aligned`` under ``world`` (moving): the sole point with world axes, the frame of the feet's
  ground reactions ``/robot/ft/<side>`` (force in world axes, torque about the sole point).

Units: metres; rotations as unit quaternions (x, y, z, w), ROS's order. Base poses come in MuJoCo's order
(x y z, qw qx qy qz), as :class:`sit2stand.robot.plant.Sensors` gives them.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from ..errors import Sit2StandError
from ..io.topics import LAB_FRAME, WORLD_FRAME, sole_world_aligned_frame
from ..vectors import xyzw_from_wxyz
from .packages import mesh_uris_to_files
from .profile import SIDES, RobotProfile, load_profile


class DescriptionError(Sit2StandError, ValueError):
    """A URDF the frame tree cannot use; the message names the joint or link."""


@dataclass(frozen=True)
class Transform:
    """The placement of frame ``child`` in frame ``parent``: translation [m] and rotation (x, y, z, w)."""

    parent: str
    child: str
    translation_m: tuple[float, float, float]
    rotation_xyzw: tuple[float, float, float, float]


DESCRIPTION_MESHES = "file"
"""The mesh URIs the driver publishes on ``/robot_description`` (and so every stand-up bag keeps): ``file://`` paths
of the meshes the simulated robot is built from. Rerun, Foxglove's desktop app and RViz open a bag's robot with
them and no ROS environment (``package://`` needs ``ROS_PACKAGE_PATH``, which a PyPI install does not set); the
``foxglove`` node serves them to a live client as ``package://`` URIs through the protocol's asset fetching."""


def robot_description(robot: str | RobotProfile = "talos", meshes: str = "package") -> str:
    """The URDF of a robot profile's robot as sit2stand reads it (``RobotProfile.urdf_text``: the file's, less a
    floating joint from a ``world`` link, which the frame tree replaces, and brought to REP-103 where it is not, as
    the joint states it goes with are).

    Args:
        robot: a robot profile (a packaged name, a file, or the profile).
        meshes: ``package`` keeps the file's mesh URIs (``package://example-robot-data/...``: RViz and Foxglove
            resolve them where example-robot-data is a ROS package, ``ros-jazzy-example-robot-data``, or the PyPI
            wheel's ``cmeel.prefix/share`` on ``AMENT_PREFIX_PATH``/``ROS_PACKAGE_PATH``); ``file`` makes them
            ``file://`` paths of this machine's installed copy.
    """
    if meshes not in ("package", "file"):
        raise DescriptionError(f"meshes {meshes!r}: use 'package' or 'file'")
    profile = load_profile(robot)
    text = profile.urdf_text()
    if meshes == "package":
        return text
    local = mesh_uris_to_files(text, profile.urdf)
    return local.replace('filename="/', 'filename="file:///')


def urdf_joints(urdf: str) -> list[tuple[str, str, str, str]]:
    """(name, type, parent link, child link) of every joint of a URDF, in file order."""
    try:
        root = ET.fromstring(urdf)
    except ET.ParseError as err:
        raise DescriptionError(f"robot description is not XML: {err}") from None
    out = []
    for j in root.findall("joint"):
        parent, child = j.find("parent"), j.find("child")
        if parent is None or child is None:
            raise DescriptionError(f"URDF joint {j.get('name')!r} has no parent or child link")
        out.append((j.get("name", ""), j.get("type", ""), parent.get("link", ""), child.get("link", "")))
    return out


def quaternions_xyzw(R: np.ndarray) -> np.ndarray:
    """Unit quaternions (x, y, z, w), w >= 0, of rotation matrices R (N, 3, 3) (Shepperd's method, vectorised)."""
    R = np.asarray(R, float).reshape(-1, 3, 3)
    tr = R[:, 0, 0] + R[:, 1, 1] + R[:, 2, 2]
    diag = np.stack([R[:, 0, 0], R[:, 1, 1], R[:, 2, 2], tr], axis=1)
    k = np.argmax(diag, axis=1)                         # the largest of 4 x^2, 4 y^2, 4 z^2, 4 w^2 (each - 1 + tr)
    q = np.empty((len(R), 4))
    for i in range(4):
        m = k == i
        if not m.any():
            continue
        r = R[m]
        if i == 3:
            s = 2.0 * np.sqrt(1.0 + tr[m])
            q[m] = np.stack([(r[:, 2, 1] - r[:, 1, 2]) / s, (r[:, 0, 2] - r[:, 2, 0]) / s,
                             (r[:, 1, 0] - r[:, 0, 1]) / s, 0.25 * s], axis=1)
            continue
        a, b, c = i, (i + 1) % 3, (i + 2) % 3
        s = 2.0 * np.sqrt(np.maximum(1.0 + r[:, a, a] - r[:, b, b] - r[:, c, c], 1e-300))
        qi = np.empty((m.sum(), 4))
        qi[:, a] = 0.25 * s
        qi[:, b] = (r[:, b, a] + r[:, a, b]) / s
        qi[:, c] = (r[:, c, a] + r[:, a, c]) / s
        qi[:, 3] = (r[:, c, b] - r[:, b, c]) / s
        q[m] = qi
    q *= np.where(q[:, 3:4] < 0, -1.0, 1.0)
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def quaternion_products(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton products a * b of quaternions (N, 4) (x, y, z, w), row by row."""
    ax, ay, az, aw = a.T
    bx, by, bz, bw = b.T
    return np.stack([aw * bx + ax * bw + ay * bz - az * by, aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw, aw * bw - ax * bx - ay * by - az * bz], axis=1)


class FrameTree:
    """The robot's frames as ROS transforms, from a base pose and joint positions (see the module docstring).

    Args:
        joint_names: the joints whose positions :meth:`transforms` gets, in that order (the plant's); URDF joints
            not named stay at zero.
        urdf: the URDF text (default: :func:`robot_description` of ``robot``).
        robot: the robot profile (root link, foot links, soles).

    Raises:
        DescriptionError: a joint name the URDF lacks, a moving joint that is not revolute (prismatic, continuous,
            floating and planar joints are not handled), or a URDF whose root is not the profile's root link.
    """

    def __init__(self, joint_names: Sequence[str], urdf: str | None = None,
                 robot: str | RobotProfile = "talos") -> None:
        profile = load_profile(robot)
        urdf = urdf if urdf is not None else robot_description(profile)
        joints = urdf_joints(urdf)
        try:
            self.model = pin.buildModelFromXML(urdf, pin.JointModelFreeFlyer())
        except (RuntimeError, ValueError) as err:
            raise DescriptionError(f"Pinocchio cannot read the robot description: {err}") from None
        self.root = profile.root_link
        if self.model.frames[self.model.getFrameId(self.root, pin.BODY)].name != self.root:
            raise DescriptionError(f"the URDF has no link {self.root!r} (its root must be {self.root})")
        unknown = [n for n in joint_names if not self.model.existJointName(n)]
        if unknown:
            raise DescriptionError(f"joints {', '.join(unknown)} are not in the URDF")
        self.q_index = np.array([self.model.joints[self.model.getJointId(n)].idx_q for n in joint_names], int)
        self._q = pin.neutral(self.model)
        moving = [(p, c) for _, kind, p, c in joints if kind != "fixed"]
        self._fixed = [(p, c) for _, kind, p, c in joints if kind == "fixed"]
        self._joint_constants([(self._body(p), self._body(c)) for p, c in moving])
        self._foot = {side: profile.foot_links[side] for side in SIDES}
        self._sole_below_m = profile.sole.below_foot_m
        self._soles = [self._sole_frame(side) for side in SIDES]
        self.data = self.model.createData()
        self.pairs: list[tuple[str, str]] = [(WORLD_FRAME, self.root), *moving,
                                             *((WORLD_FRAME, sole_world_aligned_frame(s)) for s in SIDES)]
        """(parent, child) of each transform :meth:`transforms` gives, in its order."""

    def _joint_constants(self, moving: list[tuple[int, int]]) -> None:
        """A_j (as a translation and a quaternion), the axis and the configuration index of each moving joint."""
        m = self.model
        A, axes, idx = [], [], []
        for fp, fc in moving:
            j = m.frames[fc].parentJoint
            jm = m.joints[j]
            jd = jm.createData()
            jm.calc(jd, pin.neutral(m))
            S = np.array(jd.S).ravel()
            if jm.nq != 1 or jm.nv != 1 or np.linalg.norm(S[:3]) > 0 or m.parents[j] != m.frames[fp].parentJoint \
                    or not m.frames[fc].placement.isIdentity():
                raise DescriptionError(f"joint {m.names[j]!r} ({jm.shortname()}) between {m.frames[fp].name} and "
                                       f"{m.frames[fc].name}: only revolute joints are handled")
            A.append(m.frames[fp].placement.inverse() * m.jointPlacements[j])
            axes.append(S[3:] / np.linalg.norm(S[3:]))
            idx.append(jm.idx_q)
        self._A_t = np.array([X.translation for X in A]).reshape(-1, 3)
        self._A_q = quaternions_xyzw(np.array([X.rotation for X in A]))
        self._axis = np.array(axes).reshape(-1, 3)
        self._joint_q = np.array(idx, int)

    def _sole_frame(self, side: str) -> int:
        """A frame at the sole point under ``side``'s foot link."""
        foot = self.model.frames[self._body(self._foot[side])]
        below = foot.placement * pin.SE3(np.eye(3), np.array([0.0, 0.0, -self._sole_below_m]))
        return self.model.addFrame(pin.Frame(f"sole_{side}", foot.parentJoint, below, pin.FrameType.OP_FRAME))

    def _body(self, link: str) -> int:
        fid = self.model.getFrameId(link, pin.BODY)
        if fid >= len(self.model.frames):
            raise DescriptionError(f"link {link!r} is not a body of the URDF's model")
        return fid

    def configuration(self, base_pose: np.ndarray, q: np.ndarray) -> np.ndarray:
        """Pinocchio's configuration of a base pose (x y z, qw qx qy qz) and joint positions [rad]."""
        x = self._q.copy()
        b = np.asarray(base_pose, float)
        x[:3] = b[:3]
        x[3:7] = xyzw_from_wxyz(b[3:7])
        x[self.q_index] = q
        return x

    def transforms(self, base_pose: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Translations (N, 3) [m] and rotations (N, 4) (x, y, z, w) of :attr:`pairs`: the base pose, each moving
        joint's child link in its parent link (forward kinematics), and the soles' world-aligned frames."""
        x = self.configuration(base_pose, q)
        n = len(self._joint_q)
        t = np.empty((n + 3, 3))
        r = np.zeros((n + 3, 4))
        t[0] = x[:3]
        r[0] = x[3:7] / np.linalg.norm(x[3:7])
        half = 0.5 * x[self._joint_q]
        turn = np.hstack([self._axis * np.sin(half)[:, None], np.cos(half)[:, None]])
        t[1:n + 1] = self._A_t                        # a revolute joint turns about its own origin
        r[1:n + 1] = quaternion_products(self._A_q, turn)
        pin.forwardKinematics(self.model, self.data, x)
        for k, fid in enumerate(self._soles, start=n + 1):
            t[k] = pin.updateFramePlacement(self.model, self.data, fid).translation
        r[n + 1:, 3] = 1.0
        return t, r

    def static_transforms(self) -> list[Transform]:
        """``lab`` -> ``world``, every fixed joint of the URDF, and ``sole_<side>`` under the foot link."""
        pin.framesForwardKinematics(self.model, self.data, pin.neutral(self.model))
        oMf = self.data.oMf
        out = [Transform(LAB_FRAME, WORLD_FRAME, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0))]
        for p, c in self._fixed:
            X = oMf[self._body(p)].actInv(oMf[self._body(c)])
            out.append(Transform(p, c, tuple(map(float, X.translation)),
                                 tuple(map(float, quaternions_xyzw(X.rotation)[0]))))
        for side in SIDES:
            out.append(Transform(self._foot[side], f"sole_{side}", (0.0, 0.0, -self._sole_below_m),
                                 (0.0, 0.0, 0.0, 1.0)))
        return out

    def links(self) -> list[str]:
        """Every frame the transforms name (URDF links and sit2stand's frames)."""
        names = [n for pair in self.pairs for n in pair] + [n for t in self.static_transforms()
                                                             for n in (t.parent, t.child)]
        return list(dict.fromkeys(names))
