"""Marker calibration and COM mapping between the human demonstrator and the robot (Mistry et al. 2010, Sec. IV).

* :func:`calibrate_markers`: overlay one seated human frame onto the robot's seated posture (pelvis on pelvis,
  scaled by the ratio of thigh lengths) and fix each marker to the nearest robot link "bone" (the segment from a link's
  joint to its child's joint), keeping its offset in that link's frame. Saved to / loaded from YAML.
* :func:`map_com`: a human COM (lab frame) expressed relative to the human's left foot, scaled by the two bodies'
  leg lengths, placed relative to the robot's left sole: the robot's COM target.

Units SI; lab and world frames REP-103 (x forward, y left, z up).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin
import yaml
from ..errors import InputError

PELVIS_MARKERS = ("LASI", "RASI", "LPSI", "RPSI")


@dataclass
class MarkerMap:
    """Where each human marker sits on the robot: link (Pinocchio joint name) and offset [m] in that joint's frame."""

    links: dict[str, str]
    offsets: dict[str, np.ndarray]
    scale: float

    def save(self, path: str | Path) -> None:
        doc = {"scale": float(self.scale),
               "markers": {m: {"link": self.links[m], "offset_m": [float(v) for v in self.offsets[m]]}
                           for m in sorted(self.links)}}
        Path(path).write_text(yaml.safe_dump(doc, sort_keys=False))

    @staticmethod
    def load(path: str | Path) -> MarkerMap:
        doc = yaml.safe_load(Path(path).read_text())
        markers = doc["markers"]
        return MarkerMap({m: v["link"] for m, v in markers.items()},
                         {m: np.asarray(v["offset_m"], float) for m, v in markers.items()}, float(doc["scale"]))

    def add_frames(self, model: pin.Model) -> dict[str, int]:
        """Add an operational frame per marker to ``model``; returns marker -> frame id."""
        out = {}
        for name, joint in self.links.items():
            jid = model.getJointId(joint)
            out[name] = model.addFrame(pin.Frame(f"marker_{name}", jid, pin.SE3(np.eye(3), self.offsets[name]),
                                                 pin.FrameType.OP_FRAME))
        return out


def _bones(model: pin.Model, data: pin.Data) -> list[tuple[int, np.ndarray, np.ndarray]]:
    """(joint id, start, end) world segments standing for each link: from its joint to each child joint, and from
    its joint through its COM to twice the COM offset (the link's extent; the only bone of a leaf such as the head
    or the foot)."""
    children: dict[int, list[int]] = {}
    for j in range(2, model.njoints):
        children.setdefault(model.parents[j], []).append(j)
    bones = []
    for j in range(1, model.njoints):
        a = data.oMi[j].translation
        for c in children.get(j, []):
            bones.append((j, a, data.oMi[c].translation))
        bones.append((j, a, data.oMi[j].act(2.0 * model.inertias[j].lever)))
    return bones


def _depth(model: pin.Model, j: int) -> int:
    d = 0
    while j > 0:
        j = model.parents[j]
        d += 1
    return d


def _point_segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    ab = b - a
    t = 0.0 if ab @ ab < 1e-12 else float(np.clip((p - a) @ ab / (ab @ ab), 0.0, 1.0))
    return float(np.linalg.norm(p - (a + t * ab)))


def marker_group(name: str) -> str:
    """Body part of a Plug-in-Gait marker name: head, trunk, pelvis, thigh, shank, foot or arm."""
    n = name[1:] if name[:1] in "LR" and len(name) > 3 else name
    if n in ("FHD", "BHD"):
        return "head"
    if name in ("C7", "T10", "CLAV", "STRN", "RBAK"):
        return "trunk"
    if n in ("ASI", "PSI"):
        return "pelvis"
    if n in ("THI", "KNE"):
        return "thigh"
    if n in ("TIB", "ANK"):
        return "shank"
    if n in ("HEE", "TOE"):
        return "foot"
    return "arm"


def talos_links(model: pin.Model, marker: str) -> tuple[str, ...]:
    """The TALOS links (Pinocchio joint names) a Plug-in-Gait marker may be fixed to: those of its body part and
    side. Nearest-link matching alone puts a seated human's hip markers on the robot's hanging arms."""
    side = "left" if marker.startswith("L") else "right" if marker.startswith("R") else None
    group = marker_group(marker)
    names = list(model.names[1:])
    if group == "pelvis":
        return (names[0],)
    if group == "head":
        return tuple(n for n in names if n.startswith("head_"))
    if group == "trunk":
        return ("torso_1_joint", "torso_2_joint")
    if group == "arm":
        return tuple(n for n in names if n.startswith((f"arm_{side}", f"gripper_{side}")))
    return {"thigh": (f"leg_{side}_3_joint", f"leg_{side}_4_joint"), "shank": (f"leg_{side}_4_joint",),
            "foot": (f"leg_{side}_6_joint",)}[group]


def calibrate_markers(model: pin.Model, q_robot: np.ndarray, names: list[str], positions_m: np.ndarray,
                      valid: np.ndarray, human_thigh_m: float, robot_thigh_m: float,
                      allowed_links=talos_links) -> MarkerMap:
    """Fix each valid human marker of one seated frame to the nearest robot link (see the module docstring)
    among ``allowed_links(model, marker)`` (None: any link).

    Raises:
        ValueError: fewer than 3 of the pelvis markers (LASI RASI LPSI RPSI) are valid in the frame.
    """
    data = model.createData()
    pin.forwardKinematics(model, data, q_robot)
    pel = [i for i, n in enumerate(names) if n in PELVIS_MARKERS and valid[i]]
    if len(pel) < 3:
        raise InputError(f"calibration frame: {len(pel)} of {', '.join(PELVIS_MARKERS)} valid; need 3")
    scale = robot_thigh_m / human_thigh_m
    human_pelvis = positions_m[pel].mean(axis=0)
    robot_pelvis = data.oMi[1].translation
    bones = _bones(model, data)
    links, offsets = {}, {}
    for i, name in enumerate(names):
        if not valid[i] or not np.all(np.isfinite(positions_m[i])):
            continue
        p = robot_pelvis + scale * (positions_m[i] - human_pelvis)
        side = "left" if name.startswith("L") else "right" if name.startswith("R") else None
        candidates = [b for b in bones if side is None or ("left" not in model.names[b[0]] and "right" not in
                                                          model.names[b[0]]) or side in model.names[b[0]]]
        if allowed_links is not None:
            allowed = set(allowed_links(model, name))
            candidates = [b for b in candidates if model.names[b[0]] in allowed] or candidates
        # nearest bone; within 5 mm, the more distal link (a heel marker belongs to the foot, not the shank's end)
        j = min(candidates, key=lambda b: (round(_point_segment_distance(p, b[1], b[2]) / 0.005),
                                           -_depth(model, b[0])))[0]
        links[name] = model.names[j]
        offsets[name] = data.oMi[j].actInv(p)
    return MarkerMap(links, offsets, scale)


def map_com(human_com_m: np.ndarray, human_left_foot_m: np.ndarray, human_leg_m: float,
            robot_left_sole_m: np.ndarray, robot_leg_m: float, robot_midline_y_m: float | None = 0.0) -> np.ndarray:
    """Robot COM target(s) [m]: the human COM relative to the human's left foot, scaled by the leg-length ratio,
    placed relative to the robot's left sole. With ``robot_midline_y_m`` set, the target's y is that value (the
    midline between the robot's feet): the robot's COM follows its own stance, not the human's stance width.
    Works on (3,) or (N, 3)."""
    rel = (np.asarray(human_com_m, float) - np.asarray(human_left_foot_m, float)) * (robot_leg_m / human_leg_m)
    target = np.asarray(robot_left_sole_m, float) + rel
    if robot_midline_y_m is not None:
        target[..., 1] = robot_midline_y_m
    return target
