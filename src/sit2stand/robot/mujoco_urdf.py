"""A robot profile's URDF as MuJoCo compiles it: sit2stand's reading of the file (REP-103,
:meth:`~sit2stand.robot.profile.RobotProfile.urdf_text`), its mesh URIs absolute paths of this machine with COLLADA
meshes converted (:mod:`~sit2stand.robot.meshes`), the link inertias MuJoCo refuses made ones it takes, and the compiler
options sit2stand needs."""

from __future__ import annotations

import re

import numpy as np

from .meshes import readable_mesh_files
from .packages import mesh_uris_to_files
from .profile import RobotProfile


MUJOCO_COMPILER = ('<mujoco><compiler strippath="false" fusestatic="false" discardvisual="false" '
                   'balanceinertia="false" autolimits="true"/></mujoco>')
"""Keep the sole and F/T frames (fusestatic would drop them) and meshes of the same file name in two folders."""


POINT_MASS_RADIUS_M = 0.01
"""A link whose URDF inertia has no positive moment gets that of a solid ball of this radius about its centre of
mass, 0.4 m r^2 on each axis (0.75 kg: 3e-5 kg m^2): a point mass moved by a joint, or moments written with rounding
errors (a negative one, products of inertia about zero moments), as iCub's hip and ankle links have. MuJoCo takes a
zero inertia on a link welded to its parent (TALOS's sensor frames), which is left as it is."""
_INERTIA = re.compile(r'<inertia\b[^>]*/>')
_INERTIA_VALUE = re.compile(r'\b(i[xyz]{2})\s*=\s*"([^"]*)"')


def _balanced(tensor: np.ndarray) -> np.ndarray | None:
    """``tensor`` [kg m^2] with its two smaller principal moments raised by half their shortfall each, and 0.1 % of
    the largest (the file's six digits must keep it), where the three break the triangle inequality (A + B >= C: no
    body has them; MuJoCo refuses them), about the same axes; None where they keep it. Romeo's shoulder and elbow
    yaw links break it by up to 8 times their smaller moments."""
    moments, axes = np.linalg.eigh(tensor)
    shortfall = moments[2] - moments[0] - moments[1]
    if shortfall <= 0.0:
        return None
    moments[:2] += shortfall / 2 + 1e-3 * moments[2]
    return axes @ np.diag(moments) @ axes.T


def _tensor_xml(m: np.ndarray) -> str:
    return (f'<inertia ixx="{m[0, 0]:.6g}" ixy="{m[0, 1]:.6g}" ixz="{m[0, 2]:.6g}" iyy="{m[1, 1]:.6g}" '
            f'iyz="{m[1, 2]:.6g}" izz="{m[2, 2]:.6g}"/>')


def inertias_mujoco_takes(urdf: str) -> str:
    """The URDF with each link inertia that MuJoCo would refuse made one it takes: a small ball's where it has no
    positive moment (:data:`POINT_MASS_RADIUS_M`), balanced where its moments break the triangle inequality
    (:func:`_balanced`); every other one unchanged, character for character. Only the simulated robot's: the
    controller's model reads the file's values."""
    moved = set(re.findall(r'<joint\b[^>]*type="(?!fixed)[^"]*"[^>]*>.*?<child\s+link="([^"]+)"', urdf, flags=re.S))

    def fixed(link: re.Match) -> str:
        block = link.group(0)
        tensor, mass = _INERTIA.search(block), re.search(r'<mass\s+value="([^"]+)"', block)
        if tensor is None or mass is None:
            return block
        v = {k: float(x) for k, x in _INERTIA_VALUE.findall(tensor.group(0))}
        m = np.array([[v.get("ixx", 0), v.get("ixy", 0), v.get("ixz", 0)],
                      [v.get("ixy", 0), v.get("iyy", 0), v.get("iyz", 0)],
                      [v.get("ixz", 0), v.get("iyz", 0), v.get("izz", 0)]])
        least = np.linalg.eigvalsh(m).min()
        products = bool(m[0, 1] or m[0, 2] or m[1, 2])
        if least > 1e-12:
            balanced = _balanced(m)
            return block if balanced is None else block.replace(tensor.group(0), _tensor_xml(balanced))
        if least == 0.0 and not products and link.group(1) not in moved:
            return block
        i = max(0.4 * float(mass.group(1)) * POINT_MASS_RADIUS_M ** 2, 1e-9)
        return block.replace(tensor.group(0), _tensor_xml(np.eye(3) * i))
    return re.sub(r'<link\s+name="([^"]+)"\s*>.*?</link>', fixed, urdf, flags=re.S)


_MUJOCO_BLOCK = re.compile(r"<mujoco\b[^>]*/>|<mujoco\b[^>]*>.*?</mujoco>", flags=re.S)


def urdf_for_mujoco(profile: RobotProfile) -> str:
    """The profile's URDF as sit2stand reads it (:meth:`RobotProfile.urdf_text`) with absolute mesh paths (COLLADA
    ones converted: :mod:`~sit2stand.robot.meshes`) and the MuJoCo compiler options it needs, in place of any
    ``<mujoco>`` block of the file's own (unitree_ros's H1 carries one for its conversion to MJCF: a ``meshdir``
    the absolute paths make moot, and MuJoCo refuses two)."""
    text = readable_mesh_files(mesh_uris_to_files(profile.urdf_text(), profile.urdf))
    text = inertias_mujoco_takes(_MUJOCO_BLOCK.sub("", text))
    return re.sub(r"(<robot\b[^>]*>)", r"\1" + MUJOCO_COMPILER, text, count=1)
