"""The fitted human skeleton for ROS tools: its URDF (``/human/robot_description``) and its frames (``/tf``).

What ``robot_state_publisher`` would do for the skeleton of :mod:`sit2stand.human.skeleton`: every Pinocchio joint
is a URDF joint, every segment a link named after it (``pelvis``, ``torso``, ``thigh_l``...); the massless links
between the axes of a multi-axis joint (hip z -> x -> y) are named ``<joint>_link``. The free-flyer root is no URDF
joint: ``lab`` -> ``pelvis`` comes from the fitted pelvis pose, so RViz and Foxglove draw the subject where the
markers are. Each revolute joint j between links p and c gives

    X_pc(theta) = M_j * Rot(a_j, theta)

with M_j the joint's placement in its parent joint (a segment's frame is its joint's frame) and a_j its axis. These
are constants of the scaled skeleton, so a message costs a few vectorised quaternion products (~20 us for the 32
joints; measured with :func:`time.perf_counter` on a 2-core host), not a Pinocchio forward kinematics pass.

Segments are drawn as the skeleton's own capsules (:attr:`HumanModel.geometry`): a cylinder between the ends and a
sphere at each (URDF has no capsule). Units: metres, kilograms; rotations (x, y, z, w), ROS's order.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from ..errors import InputError
from ..io.topics import HUMAN_ROOT_FRAME, LAB_FRAME
from .skeleton import HumanModel

AXES = {"JointModelRX": (1.0, 0.0, 0.0), "JointModelRY": (0.0, 1.0, 0.0), "JointModelRZ": (0.0, 0.0, 1.0)}
SKIN_RGBA = "0.85 0.65 0.5 1"


def link_names(human: HumanModel) -> list[str]:
    """The URDF link (and /tf frame) of each Pinocchio joint id, index 0 (the universe) being ``lab``."""
    segment_of = {jid: name for name, jid in human.segment_joint.items()}
    names = [LAB_FRAME]
    for jid in range(1, human.model.njoints):
        names.append(segment_of.get(jid, f"{human.model.names[jid]}_link"))
    if names[1] != HUMAN_ROOT_FRAME:
        raise InputError(f"the skeleton's root segment is {names[1]!r}, not {HUMAN_ROOT_FRAME!r}")
    return names


def _fmt(values) -> str:
    return " ".join(f"{float(v):.6g}" for v in values)


def _capsule_visuals(g: dict) -> list[str]:
    """URDF visuals of a capsule from ``g['from']`` to ``g['to']`` of radius ``g['radius']`` [m]."""
    a, b, r = np.asarray(g["from"], float), np.asarray(g["to"], float), float(g["radius"])
    material = f'<material name="skin"><color rgba="{SKIN_RGBA}"/></material>'
    out = [f'<visual><origin xyz="{_fmt(p)}"/><geometry><sphere radius="{r:.6g}"/></geometry>{material}</visual>'
           for p in (a, b)]
    d = b - a
    length = float(np.linalg.norm(d))
    if length > 1e-9:
        z = d / length
        x = np.cross([0.0, 1.0, 0.0], z) if abs(z[1]) < 0.9 else np.cross([1.0, 0.0, 0.0], z)
        x /= np.linalg.norm(x)
        rpy = pin.rpy.matrixToRpy(np.column_stack([x, np.cross(z, x), z]))
        out.append(f'<visual><origin xyz="{_fmt((a + b) / 2)}" rpy="{_fmt(rpy)}"/><geometry><cylinder '
                   f'radius="{r:.6g}" length="{length:.6g}"/></geometry>{material}</visual>')
    return out


def _link(human: HumanModel, name: str, jid: int) -> str:
    """A URDF link: the segment's inertia (about its COM, in the joint frame) and capsule, if it has one."""
    body = []
    if name in human.geometry:
        inertia = human.model.inertias[jid]
        i = inertia.inertia
        body.append(f'<inertial><origin xyz="{_fmt(inertia.lever)}"/><mass value="{inertia.mass:.6g}"/>'
                    f'<inertia ixx="{i[0, 0]:.6g}" ixy="{i[0, 1]:.6g}" ixz="{i[0, 2]:.6g}" iyy="{i[1, 1]:.6g}" '
                    f'iyz="{i[1, 2]:.6g}" izz="{i[2, 2]:.6g}"/></inertial>')
        body += _capsule_visuals(human.geometry[name])
    return f'  <link name="{name}">{"".join(body)}</link>'


def human_urdf(human: HumanModel, name: str = "human") -> str:
    """The URDF of the scaled skeleton (links, revolute joints with limits, inertias, capsules); root ``pelvis``."""
    model, links = human.model, link_names(human)
    lines = ['<?xml version="1.0"?>', f'<robot name="{name}">']
    lines += [_link(human, links[jid], jid) for jid in range(1, model.njoints)]
    for jid in range(2, model.njoints):
        joint = model.joints[jid]
        placement = model.jointPlacements[jid]
        lo, hi = model.lowerPositionLimit[joint.idx_q], model.upperPositionLimit[joint.idx_q]
        rpy = pin.rpy.matrixToRpy(placement.rotation)
        lines.append(f'  <joint name="{model.names[jid]}" type="revolute"><parent link="{links[model.parents[jid]]}"/>'
                     f'<child link="{links[jid]}"/><origin xyz="{_fmt(placement.translation)}" rpy="{_fmt(rpy)}"/>'
                     f'<axis xyz="{_fmt(AXES[joint.shortname()])}"/>'
                     f'<limit lower="{lo:.6g}" upper="{hi:.6g}" effort="200" velocity="20"/></joint>')
    lines.append("</robot>")
    return "\n".join(lines)


def _quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise Hamilton products a * b of (N, 4) quaternions (x, y, z, w)."""
    ax, ay, az, aw = a.T
    bx, by, bz, bw = b.T
    return np.column_stack([aw * bx + ax * bw + ay * bz - az * by, aw * by - ax * bz + ay * bw + az * bx,
                            aw * bz + ax * by - ay * bx + az * bw, aw * bw - ax * bx - ay * by - az * bz])


class SkeletonFrames:
    """The skeleton's /tf transforms from a configuration q (Pinocchio's: pelvis x y z qx qy qz qw, then joints)."""

    def __init__(self, human: HumanModel) -> None:
        model, links = human.model, link_names(human)
        joints = range(2, model.njoints)
        self.pairs = [(LAB_FRAME, HUMAN_ROOT_FRAME)] + [(links[model.parents[j]], links[j]) for j in joints]
        self.nq = model.nq
        self._idx_q = np.array([model.joints[j].idx_q for j in joints])
        self._axis = np.array([AXES[model.joints[j].shortname()] for j in joints])
        self._offset_m = np.array([model.jointPlacements[j].translation for j in joints])
        self._placement = np.array([pin.Quaternion(model.jointPlacements[j].rotation).coeffs() for j in joints])

    def transforms(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Translations (N, 3) [m] and rotations (N, 4) (x, y, z, w) of :attr:`pairs` at ``q`` (nq,).

        Raises:
            InputError: a configuration of another size.
        """
        q = np.asarray(q, float)
        if q.shape != (self.nq,):
            raise InputError(f"a skeleton configuration has {self.nq} entries, not {q.shape}")
        half = 0.5 * q[self._idx_q]
        local = np.column_stack([self._axis * np.sin(half)[:, None], np.cos(half)])
        root = q[3:7] / np.linalg.norm(q[3:7])
        rotations = np.vstack([root, _quat_mul(self._placement, local)])
        translations = np.vstack([q[:3], self._offset_m])
        return translations, rotations
