"""A robot profile's URDF as MuJoCo compiles it: sit2stand's reading of the file (REP-103,
:meth:`~sit2stand.robot.profile.RobotProfile.urdf_text`), its mesh URIs absolute paths of this machine with COLLADA
meshes converted (:mod:`~sit2stand.robot.meshes`), the link inertias MuJoCo refuses replaced, and the compiler
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
"""A link whose URDF inertia MuJoCo refuses gets that of a solid ball of this radius about its centre of mass, 0.4 m
r^2 on each axis (0.75 kg: 3e-5 kg m^2): a point mass moved by a joint, or moments written with rounding errors (a
negative one, products of inertia about zero moments), as iCub's hip and ankle links have. MuJoCo takes a zero
inertia on a link welded to its parent (TALOS's sensor frames), which is left as it is."""
_INERTIA = re.compile(r'<inertia\b[^>]*/>')
_INERTIA_VALUE = re.compile(r'\b(i[xyz]{2})\s*=\s*"([^"]*)"')


def point_masses_given_inertia(urdf: str) -> str:
    """The URDF with each link inertia that MuJoCo would refuse (see :data:`POINT_MASS_RADIUS_M`) given a small
    ball's; every other one unchanged, character for character."""
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
        if least > 1e-12 or (least == 0.0 and not products and link.group(1) not in moved):
            return block
        i = max(0.4 * float(mass.group(1)) * POINT_MASS_RADIUS_M ** 2, 1e-9)
        return block.replace(tensor.group(0), f'<inertia ixx="{i:.6g}" ixy="0" ixz="0" iyy="{i:.6g}" iyz="0" '
                                              f'izz="{i:.6g}"/>')
    return re.sub(r'<link\s+name="([^"]+)"\s*>.*?</link>', fixed, urdf, flags=re.S)


_MUJOCO_BLOCK = re.compile(r"<mujoco\b[^>]*/>|<mujoco\b[^>]*>.*?</mujoco>", flags=re.S)


def urdf_for_mujoco(profile: RobotProfile) -> str:
    """The profile's URDF as sit2stand reads it (:meth:`RobotProfile.urdf_text`) with absolute mesh paths (COLLADA
    ones converted: :mod:`~sit2stand.robot.meshes`) and the MuJoCo compiler options it needs, in place of any
    ``<mujoco>`` block of the file's own (unitree_ros's H1 carries one for its conversion to MJCF: a ``meshdir``
    the absolute paths make moot, and MuJoCo refuses two)."""
    text = readable_mesh_files(mesh_uris_to_files(profile.urdf_text(), profile.urdf))
    text = point_masses_given_inertia(_MUJOCO_BLOCK.sub("", text))
    return re.sub(r"(<robot\b[^>]*>)", r"\1" + MUJOCO_COMPILER, text, count=1)
