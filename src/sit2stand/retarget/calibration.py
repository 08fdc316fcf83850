"""Marker calibration and COM mapping between the human demonstrator and the robot (Mistry et al. 2010, Sec. IV).

* :func:`calibrate_markers`: overlay one seated human frame onto the robot's seated posture (pelvis on pelvis,
  scaled by the ratio of thigh lengths) and fix each marker to the nearest robot link "bone" (the segment from a link's
  joint to its child's joint), keeping its offset in that link's frame. Saved to / loaded from YAML.
* :func:`marker_roles`: what the calibration and the IK need of a marker set (:mod:`sit2stand.human.marker_sets`):
  each marker's body part and side, the pelvis markers, the left knee, ankle and heel markers; from the set's data,
  so that any set (Plug-in-Gait, Gait2392, a user's YAML) is retargeted alike.
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
from ..human.calibration_frames import FrameChoice, quiet_frames, seen
from ..human.marker_sets import MarkerSet, MarkerSpec, load_marker_set
from ..robot.profile import profile_of

PELVIS_MARKERS = ("LASI", "RASI", "LPSI", "RPSI")
SEGMENT_GROUPS = {"pelvis": "pelvis", "torso": "trunk", "head": "head", "upper_arm": "arm", "forearm": "arm",
                  "hand": "arm", "thigh": "thigh", "shank": "shank", "foot": "foot", "toes": "foot"}
"""The retargeter's body part of each skeleton segment (its marker weights and the robot links a marker may go to)."""
SHOULDER_Y_MM = 120.0
"""A torso marker this far [mm, at 1.75 m] to the side is on the shoulder: an arm marker for the robot, whose
shoulder is a link of the arm (Plug-in-Gait's LSHO at 175 mm, Gait2392's acromia at 166; RBAK at 80 stays trunk)."""
MAP_WINDOW = 10
"""Seated frames [frames] over which the marker map's frame must be quiet."""
SIDE_Y_MM = 20.0
"""A marker of a segment without a side (pelvis, torso, head) this far [mm] to one side is on that side."""


@dataclass(frozen=True)
class MarkerRoles:
    """What the retargeter needs of a marker set: per marker, its body part (head, trunk, pelvis, thigh, shank,
    foot, arm) and side (left, right or None); the pelvis markers; the left knee, ankle and heel markers (their
    mean where several are seen)."""

    groups: dict[str, str]
    sides: dict[str, str | None]
    pelvis: tuple[str, ...]
    knee: tuple[str, ...]
    ankle: tuple[str, ...]
    heel: tuple[str, ...]
    name: str = ""

    def group(self, marker: str) -> str:
        """The marker's body part ("" for a marker the set lacks: it gets no weight)."""
        return self.groups.get(marker, "")


def _role(spec: MarkerSpec) -> tuple[str, str | None]:
    base, _, suffix = spec.segment.rpartition("_") if spec.segment.endswith(("_l", "_r")) else (spec.segment, "", "")
    group = SEGMENT_GROUPS[base]
    y = spec.mm[1]
    if group == "trunk" and abs(y) >= SHOULDER_Y_MM:
        group = "arm"
    side = {"l": "left", "r": "right"}.get(suffix) or (("left" if y > 0 else "right") if abs(y) >= SIDE_Y_MM else None)
    return group, side


def marker_roles(marker_set: MarkerSet | str | None = None) -> MarkerRoles:
    """The roles of a marker set's markers (see :class:`MarkerRoles`). The knee and ankle markers are the left thigh's
    and shank's at the segment's end (``of_length`` z = -1), the heel the left foot's rearmost; from the set's data,
    so that the Plug-in-Gait rules (LKNE, LANK, LHEE) follow for any set."""
    ms = load_marker_set(marker_set)
    roles = {m.name: _role(m) for m in ms.markers}

    def at_end(segment: str) -> tuple[str, ...]:
        return tuple(m.name for m in ms.markers if m.segment == segment and m.of_length[2] == -1)

    feet = [m for m in ms.markers if m.segment == "foot_l"]
    heel = (min(feet, key=lambda m: (m.of_length[0], m.mm[0])).name,) if feet else ()
    return MarkerRoles({n: g for n, (g, _) in roles.items()}, {n: s for n, (_, s) in roles.items()},
                       ms.pelvis.markers, at_end("thigh_l"), at_end("shank_l"), heel, ms.name)


def pelvis_centre(roles: MarkerRoles, names: list[str], positions_m: np.ndarray, valid: np.ndarray,
                  rule: MarkerSet | None = None) -> tuple[np.ndarray, list[int]]:
    """The mean of the pelvis markers seen in a frame, and their indices; InputError when they do not define the
    pelvis (3 of them, or as the set's pelvis rule says)."""
    pel = [i for i, n in enumerate(names) if n in roles.pelvis and valid[i] and np.all(np.isfinite(positions_m[i]))]
    seen = [names[i] for i in pel]
    ok = rule.pelvis.defined_by(seen) if rule is not None else len(pel) >= 3
    if not ok:
        raise InputError(f"calibration frame: {len(pel)} of {', '.join(roles.pelvis)} valid; need 3"
                         + (f" ({rule.pelvis.describe()})" if rule is not None else ""))
    return positions_m[pel].mean(axis=0), pel


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


def _bones(model: pin.Model, data: pin.Data) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The world segments standing for each link: from its joint to each child joint, and from its joint through its
    COM to twice the COM offset (the link's extent; the only bone of a leaf such as the head or the foot). Returns
    each bone's joint id (B,), start and end (B, 3) [m], in the model's joint order."""
    children: dict[int, list[int]] = {}
    for j in range(2, model.njoints):
        children.setdefault(model.parents[j], []).append(j)
    joint, start, end = [], [], []
    for j in range(1, model.njoints):
        a = data.oMi[j].translation
        ends = [data.oMi[c].translation for c in children.get(j, [])]
        for b in ends + [data.oMi[j].act(2.0 * model.inertias[j].lever)]:
            joint.append(j)
            start.append(a)
            end.append(b)
    return np.array(joint, int), np.array(start), np.array(end)


def _joint_depths(model: pin.Model) -> np.ndarray:
    """Each joint's number of joints from the universe (njoints,)."""
    depth = np.zeros(model.njoints, int)
    for j in range(1, model.njoints):
        depth[j] = depth[model.parents[j]] + 1
    return depth


def left_leg_points(roles: MarkerRoles, names: list[str], positions_m: np.ndarray, valid: np.ndarray,
                    rule: MarkerSet | None = None) -> tuple[np.ndarray, list[int], np.ndarray, np.ndarray, np.ndarray]:
    """The pelvis centre and its markers' indices, and the left knee, ankle and heel [m] of one frame (each the mean
    of its markers seen); InputError naming what is missing."""
    seen = {n: i for i, n in enumerate(names) if valid[i] and np.all(np.isfinite(positions_m[i]))}
    points, missing = [], []
    for markers in (roles.knee, roles.ankle, roles.heel):
        here = [seen[m] for m in markers if m in seen]
        if here:
            points.append(positions_m[here].mean(axis=0))
        else:
            missing.append(" or ".join(markers) or f"(marker set {roles.name} has none)")
    if missing:
        raise InputError(f"calibration frame: marker(s) {', '.join(missing)} missing")
    pelvis, pel = pelvis_centre(roles, names, positions_m, valid, rule)
    return pelvis, pel, *points


def map_frame(t_s: np.ndarray, positions_m: np.ndarray, valid: np.ndarray, seated_frames: int,
              given: int | None = None, n: int = MAP_WINDOW) -> FrameChoice:
    """The frame the marker map is made on: it overlays the human on the robot's seated posture, so a seated one.

    ``seated_frames``: how many frames the trial starts seated (0: it starts after the rise began; frame 0, the
    nearest to seated, then, and a lead-in joins the robot's seat to it). Automatically, the frame that sees the
    most markers in the quietest stretch of ``n`` seated frames
    (:func:`sit2stand.human.calibration_frames.quiet_frames`); ``given``: that frame, if it is seated.

    Raises:
        InputError: ``given`` is not a frame of the trial, or not a seated one.
    """
    if given is not None:
        if not 0 <= given < len(t_s):
            raise InputError(f"--calibration-frame {given}: the trial has frames 0-{len(t_s) - 1}")
        if seated_frames and given >= seated_frames:
            raise InputError(f"--calibration-frame {given}: the human is no longer seated there (the rise starts at "
                             f"frame {seated_frames}); the marker map overlays a seated frame on the robot's seat")
        return FrameChoice(np.array([given]), f"frame {given} given (--calibration-frame)")
    if not seated_frames:
        return FrameChoice(np.array([0]), "frame 0: the trial starts after the rise began (the nearest to seated)")
    window = quiet_frames(t_s, positions_m, valid, min(n, seated_frames), stop=seated_frames, min_markers=1)
    count = seen(positions_m[window.frames], valid[window.frames]).sum(axis=1)
    k = int(window.frames[np.argmax(count)])
    return FrameChoice(np.array([k]), f"frame {k}, seated: the most markers in the quietest seated stretch "
                                      f"({window.reason})")


def _point_segment_distances(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distances [m] from points ``p`` (K, 3) to the segments from ``a`` to ``b`` (N, 3): (K, N)."""
    ab = b - a
    length2 = np.einsum("ij,ij->i", ab, ab)
    point = length2 < 1e-12
    t = np.clip(np.einsum("kij,ij->ki", p[:, None, :] - a, ab) / np.where(point, 1.0, length2), 0.0, 1.0)
    t[:, point] = 0.0
    return np.linalg.norm(p[:, None, :] - (a + t[..., None] * ab), axis=2)


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


def robot_links(model: pin.Model, marker: str, roles: MarkerRoles | None = None) -> tuple[str, ...] | None:
    """The robot links (Pinocchio joint names) a marker may be fixed to: those its robot profile gives for the
    marker's body part and side (``marker_links``; ``roles``: of its marker set; None: Plug-in-Gait's names); None
    where the profile gives that body part no joints at all (a robot without arms: IHMC Alexander's legs). Nearest-link
    matching alone puts a seated human's hip markers on the robot's hanging arms, and an armless robot's wrists on its
    thighs."""
    if roles is None:
        side = "left" if marker.startswith("L") else "right" if marker.startswith("R") else None
        group = marker_group(marker)
    else:
        side, group = roles.sides.get(marker), roles.group(marker) or "arm"
    profile, joints = profile_of(model), tuple(model.names[1:])
    if not profile.marker_links.get(group):
        return None
    key = (id(profile), group, side, joints)
    if key not in _MARKER_JOINTS:          # the entry keeps its profile alive: no other profile takes its id
        _MARKER_JOINTS[key] = (profile, profile.marker_joints(group, side, list(joints)))
    return _MARKER_JOINTS[key][1]


_MARKER_JOINTS: dict[tuple, tuple] = {}
"""robot_links' answers (with their profile) per profile, marker group and side, and model joints: its globs cost
~50 us a marker."""


def posed_like(model: pin.Model, q_seated: np.ndarray, flexion_deg: dict[str, float]) -> np.ndarray:
    """The robot's seated configuration with its sagittal joints at a human's flexions [deg] (labels of
    :data:`~sit2stand.human.skeleton.SAGITTAL_FLEXION`, both legs alike, within the joints' limits), its base
    pitched to keep the soles flat and moved to keep the left ankle where it was: the robot on its feet in the
    human's posture."""
    q = q_seated.copy()
    profile = profile_of(model)
    data = model.createData()
    pin.forwardKinematics(model, data, q_seated)
    ankle = model.getJointId(profile.leg("left", "ankle_pitch"))
    before = data.oMi[ankle].translation.copy()
    leg_turn = 0.0
    for label, (joints, sign) in profile.sagittal_flexion().items():
        if not np.isfinite(flexion_deg.get(label, np.nan)):
            continue
        for name in joints:
            i = model.joints[model.getJointId(name)].idx_q
            angle = float(np.clip(sign * np.radians(flexion_deg[label]), model.lowerPositionLimit[i],
                                  model.upperPositionLimit[i]))
            if label != "trunk" and name == joints[0]:
                leg_turn += angle - q[i]
            q[i] = angle
    turn = pin.AngleAxis(-leg_turn, np.array([0.0, 1.0, 0.0])).matrix()
    q[3:7] = pin.Quaternion(turn @ pin.Quaternion(q[6], *q[3:6]).matrix()).coeffs()
    pin.forwardKinematics(model, data, q)
    q[:3] -= data.oMi[ankle].translation - before
    return q


def calibrate_markers(model: pin.Model, q_robot: np.ndarray, names: list[str], positions_m: np.ndarray,
                      valid: np.ndarray, human_thigh_m: float, robot_thigh_m: float,
                      allowed_links=robot_links, roles: MarkerRoles | None = None) -> MarkerMap:
    """Fix each valid human marker of one seated frame to the nearest robot link (see the module docstring)
    among ``allowed_links(model, marker, roles)`` (``allowed_links`` None: any link; its answer None: the robot has no
    such body part, and the marker stays off the robot). ``roles``: the marker set's (None: Plug-in-Gait).

    Raises:
        ValueError: the pelvis markers seen in the frame do not define the pelvis (3 of LASI RASI LPSI RPSI).
    """
    data = model.createData()
    pin.forwardKinematics(model, data, q_robot)
    roles = roles or marker_roles()
    human_pelvis, _ = pelvis_centre(roles, names, positions_m, valid)
    scale = robot_thigh_m / human_thigh_m
    joint, start, end = _bones(model, data)
    link = np.array(list(model.names))[joint]
    sided = {side: np.char.find(link, side) >= 0 for side in ("left", "right")}
    shown = [i for i, name in enumerate(names) if valid[i] and np.all(np.isfinite(positions_m[i]))]
    sites = data.oMi[1].translation + scale * (positions_m[shown] - human_pelvis)     # pelvis on pelvis [m]
    # nearest bone; within 5 mm, the more distal link (a heel marker belongs to the foot, not the shank's end);
    # the first in the model's order among equals
    rank = np.round(_point_segment_distances(sites, start, end) / 0.005) * model.njoints - _joint_depths(model)[joint]
    links, offsets, allowed_of = {}, {}, {}
    for k, i in enumerate(shown):
        name = names[i]
        side = roles.sides.get(name)
        candidates = np.ones(len(joint), bool) if side is None else ~(sided["left"] | sided["right"]) | sided[side]
        if allowed_links is not None:
            allowed = allowed_links(model, name, roles)
            if allowed is None:
                continue
            allowed = tuple(allowed)
            if allowed not in allowed_of:
                allowed_of[allowed] = np.isin(link, list(allowed))
            both = candidates & allowed_of[allowed]
            candidates = both if both.any() else candidates
        j = int(joint[np.argmin(np.where(candidates, rank[k], np.inf))])
        links[name] = model.names[j]
        offsets[name] = data.oMi[j].actInv(sites[k])
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
