"""A robot's URDF as sit2stand reads it: its base frame REP-103 (x forward, y left, z up) and its sagittal joints
turning about +y (hip flexion negative, knee flexion positive, ankle dorsiflexion negative), as TALOS's and G1's
files are already.

Other files differ: iCub's base frame has x backward and y right, and its knees flex with negative angles. Such a
file is brought to the conventions once, in its text, without changing the robot:

* **the base's heading**: the root link's frame is turned about its z axis until the left foot lies on its +y side
  (the turn is rounded to a quarter turn when within 2 degrees of one); the root link's inertial, visual and
  collision origins and its child joints' origins are turned with it, so every link stays where it was;
* **the sagittal joints' sense**: a hip pitch, knee, ankle pitch or trunk pitch joint whose axis then points along
  -y has its axis reversed and its limits swapped and negated: the same motion, with its angle negated.

Angles a profile gives (``seated_posture``, ``posture_ranges.ankle``) stay in the URDF's own sense and are converted
on loading; ``/robot/joint_states``, ``/robot/joint_command`` and ``/robot_description`` carry the converted robot
(``sit2stand robot check`` lists what was changed). A base whose z does not point up, or a sagittal joint whose axis
is not along y, is refused with the profile's field named.
"""

from __future__ import annotations

import math
import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from ..errors import Sit2StandError

AXIS_TOLERANCE = 0.9
"""A sagittal joint's axis must have at least this component along y (either sense) in the neutral pose."""
QUARTER_TURN_SNAP_RAD = math.radians(2.0)
"""A base turn this close to a quarter turn is that quarter turn: files are drawn at right angles, their feet may be
placed a little apart."""


@dataclass(frozen=True)
class Conventions:
    """How a URDF was brought to sit2stand's conventions: the turn of its root frame about z [rad] and the joints
    whose sense was reversed."""

    base_yaw_rad: float = 0.0
    flipped: tuple[str, ...] = ()

    @property
    def changed(self) -> bool:
        return bool(self.base_yaw_rad or self.flipped)

    def angle(self, joint: str, value: float) -> float:
        """A joint angle [rad] of the URDF's sense in sit2stand's."""
        return -value if joint in self.flipped else value

    def interval(self, joint: str, lo: float, hi: float) -> tuple[float, float]:
        """A joint interval [rad] of the URDF's sense in sit2stand's."""
        return (-hi, -lo) if joint in self.flipped else (lo, hi)

    def lines(self) -> list[str]:
        """What was changed, for ``robot check``."""
        if not self.changed:
            return []
        out = []
        if self.base_yaw_rad:
            out.append(f"base frame turned {math.degrees(self.base_yaw_rad):+.0f} deg about z (x forward, y left)")
        if self.flipped:
            out.append(f"sense reversed (angles negated): {', '.join(self.flipped)}")
        return out


class ConventionError(Sit2StandError, ValueError):
    """A URDF that cannot be brought to the conventions; ``field`` names the profile field concerned."""

    def __init__(self, field: str, what: str) -> None:
        super().__init__(what)
        self.field = field


def floating_base_removed(urdf: str) -> str:
    """The URDF without a ``world`` link and the floating joint that hangs the robot from it (G1's file has them;
    sit2stand adds its own free joint, and the root link is the profile's)."""
    floating = re.search(r'<joint\b[^>]*type="floating"[^>]*>.*?</joint>', urdf, flags=re.S)
    if floating is None:
        return urdf
    parent = re.search(r'<parent\s+link="([^"]+)"', floating.group(0))
    urdf = urdf.replace(floating.group(0), "")
    if parent is not None:
        urdf = re.sub(rf'<link\s+name="{re.escape(parent.group(1))}"\s*(/>|>\s*</link>)', "", urdf)
    return urdf


def brought_to_conventions(urdf: str, feet: dict[str, str], sagittal: dict[str, str]) -> tuple[str, Conventions]:
    """``urdf`` (no floating base) in sit2stand's conventions, and what was changed; the text itself when nothing
    is. ``feet``: side -> foot link; ``sagittal``: joint -> the profile field that names it."""
    model = pin.buildModelFromXML(urdf)
    yaw = _base_yaw(model, feet)
    text = urdf
    if yaw:                          # the turned file is parsed again; one already in the conventions is not
        text = _turned(urdf, yaw)
        model = pin.buildModelFromXML(text)
    flipped = _reversed_joints(model, sagittal)
    if flipped:
        text = _reversed(text, flipped)
    return text, Conventions(yaw, tuple(flipped))


def _base_yaw(model: pin.Model, feet: dict[str, str]) -> float:
    """The turn about z [rad] that puts the left foot on the base's +y side (``model``: fixed base); checks that z
    points up."""
    data = model.createData()
    pin.framesForwardKinematics(model, data, pin.neutral(model))
    left, right = (data.oMf[model.getFrameId(feet[s])].translation for s in ("left", "right"))
    if max(left[2], right[2]) >= 0.0:
        raise ConventionError("root_link", f"the feet are not below the base in the neutral pose (z {left[2]:.3f}, "
                                           f"{right[2]:.3f} m): the base frame's z must point up")
    across = left - right
    yaw = math.pi / 2 - math.atan2(across[1], across[0])
    yaw = math.atan2(math.sin(yaw), math.cos(yaw))
    quarter = round(yaw / (math.pi / 2)) * (math.pi / 2)
    if abs(yaw - quarter) < QUARTER_TURN_SNAP_RAD:
        yaw = quarter
    return 0.0 if abs(yaw) < 1e-12 else yaw


def _reversed_joints(model: pin.Model, sagittal: dict[str, str]) -> list[str]:
    """The sagittal joints whose axis points along -y in the neutral pose; refuses one not along y."""
    data = model.createData()
    pin.computeJointJacobians(model, data, pin.neutral(model))
    out = []
    for joint, field in sagittal.items():
        axis = data.J[3:, model.joints[model.getJointId(joint)].idx_v]
        if abs(axis[1]) < AXIS_TOLERANCE:
            raise ConventionError(field, f"{joint!r} turns about ({axis[0]:.2f}, {axis[1]:.2f}, {axis[2]:.2f}) in "
                                         f"the base frame, not about its y axis (a sagittal joint)")
        if axis[1] < 0:
            out.append(joint)
    return out


def _turned(urdf: str, yaw: float) -> str:
    """The URDF with its root link's frame turned by ``yaw`` about z (its contents and child joints turned back)."""
    root = ET.fromstring(urdf)
    children = {j.find("child").get("link") for j in root.iter("joint") if j.find("child") is not None}
    base = next(link for link in root.iter("link") if link.get("name") not in children)
    turn = pin.SE3(pin.utils.rpyToMatrix(0.0, 0.0, yaw), np.zeros(3))
    for element in [*base, *(j for j in root.iter("joint") if j.find("parent") is not None
                              and j.find("parent").get("link") == base.get("name"))]:
        if element.tag in ("inertial", "visual", "collision", "joint"):
            _set_origin(element, turn * _origin(element))
    return ET.tostring(root, encoding="unicode")


def _reversed(urdf: str, joints: list[str]) -> str:
    """The URDF with ``joints``' axes reversed and their limits negated and swapped."""
    root = ET.fromstring(urdf)
    for j in root.iter("joint"):
        if j.get("name") not in joints:
            continue
        axis = j.find("axis")
        xyz = [float(v) for v in (axis.get("xyz", "1 0 0") if axis is not None else "1 0 0").split()]
        if axis is None:
            axis = ET.SubElement(j, "axis")
        axis.set("xyz", " ".join(f"{-v:.17g}" for v in xyz))
        limit = j.find("limit")
        if limit is not None and limit.get("lower") is not None and limit.get("upper") is not None:
            lo, hi = float(limit.get("lower")), float(limit.get("upper"))
            limit.set("lower", f"{-hi:.17g}")
            limit.set("upper", f"{-lo:.17g}")
    return ET.tostring(root, encoding="unicode")


def _origin(element: ET.Element) -> pin.SE3:
    o = element.find("origin")
    xyz = [float(v) for v in o.get("xyz", "0 0 0").split()] if o is not None else [0.0] * 3
    rpy = [float(v) for v in o.get("rpy", "0 0 0").split()] if o is not None else [0.0] * 3
    return pin.SE3(pin.utils.rpyToMatrix(*rpy), np.array(xyz))


def _set_origin(element: ET.Element, placement: pin.SE3) -> None:
    o = element.find("origin")
    if o is None:
        o = ET.Element("origin")
        element.insert(0, o)
    o.set("xyz", " ".join(f"{v:.17g}" for v in placement.translation))
    o.set("rpy", " ".join(f"{v:.17g}" for v in pin.utils.matrixToRpy(placement.rotation)))
