"""A run as a 3D scene over time: what ``sit2stand view`` draws, read from bags into arrays (no viewer here).

A *run* is a bag or a folder of bags: a stand-up graph's run (its ``standup`` bag), a ``retarget --simulate``
output (its ``retarget`` and ``robot`` bags) or an imported or synthesised demonstration. A folder's
``summary.json`` may name the demonstration it came from (``bag``); that bag adds the markers and plates a run
lacks, and the plates' corners (:data:`~sit2stand.forceplate.PLATE_CORNERS_KEY`). A topic found in several bags
is read from the first.

Bodies are posed by forward kinematics of their URDF (Pinocchio) from the states the bags carry: the robot from
``/robot/joint_states`` and ``/robot/base_pose`` (the profile whose joints they name, its URDF's visual meshes), the
human skeleton from ``/human/robot_description``, ``/human/joint_states`` and ``/human/pelvis_pose``. Everything is
in the lab frame (REP-103; ``world`` coincides with ``lab``), times are the bag's own [s].
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pinocchio as pin

from ..errors import InputError
from ..human.skeleton import SAGITTAL_FLEXION
from ..io.bag import BagReader
from ..forceplate import plate_corners_from
from ..io.messages import stamp_ns
from ..io.topics import (CHAIR_PLATE_TOPIC, FEET_PLATE_TOPIC, HUMAN_COM_TOPIC, HUMAN_DESCRIPTION_TOPIC,
                         HUMAN_JOINTS_TOPIC, HUMAN_MEASURED_COP_TOPIC, HUMAN_PELVIS_POSE_TOPIC, MARKERS_TOPIC,
                         ROBOT_BASE_POSE_TOPIC, ROBOT_COP_TOPIC, ROBOT_JOINT_STATES_TOPIC, ROBOT_PLANNED_COM_TOPIC,
                         ROBOT_PLANNED_ZMP_TOPIC)
from ..retarget.export import StateSeries, read_states, resample, robot_of
from ..retarget.compare import flexion_deg, matched_times
from ..robot.meshes import readable_mesh
from ..robot.model import SIDES, PlantConfig, sole_corners_local
from ..robot.plant import Plant
from ..robot.packages import mesh_uris_to_files, package_share
from ..robot.profile import RobotProfile

VIEW_RATE_HZ = 50.0
"""Bodies are posed at this rate [Hz] (a 500 Hz driver's states would cost ten times the time for no visible
difference)."""

POINT_TOPICS = {"human COM": HUMAN_COM_TOPIC, "human measured COP": HUMAN_MEASURED_COP_TOPIC,
                "robot planned COM": ROBOT_PLANNED_COM_TOPIC, "robot planned ZMP": ROBOT_PLANNED_ZMP_TOPIC,
                "robot COP": ROBOT_COP_TOPIC}
"""Points drawn over time: label -> topic (``CenterOfMass`` or ``PointStamped``, lab/world frame)."""

PLATE_TOPICS = {"chair": CHAIR_PLATE_TOPIC, "feet": FEET_PLATE_TOPIC}


@dataclass
class PointSeries:
    """A point over time: stamps [s], positions (N, 3) [m, lab]; NaN rows where undefined."""

    t_s: np.ndarray
    xyz: np.ndarray


@dataclass
class Visual:
    """A mesh of a body: its file, scale, colour (RGBA 0-1) and, per pose, its placement in the lab."""

    name: str
    mesh: Path
    scale: np.ndarray               # (3,)
    rgba: np.ndarray                # (4,)
    translation: np.ndarray         # (N, 3) [m]
    rotation: np.ndarray            # (N, 3, 3)


@dataclass
class RobotMotion:
    """The robot: its profile, pose times [s], visuals, measured COM (N, 3) [m], soles' corners (N, 2, 4, 3) [m],
    and its knee, hip and trunk flexion [deg] (N,) (mean of both sides where a side has one)."""

    profile: RobotProfile
    t_s: np.ndarray
    visuals: list[Visual]
    com: np.ndarray
    soles: np.ndarray
    angles_deg: dict[str, np.ndarray]


@dataclass
class HumanMotion:
    """The human skeleton: pose times [s], bones as segment end points (N, B, 2, 3) [m] and joint flexion [deg]."""

    t_s: np.ndarray
    bones: np.ndarray
    angles_deg: dict[str, np.ndarray]


@dataclass
class Plate:
    """A force plate: stamps [s], COP (N, 3) [m] (NaN unloaded), force on the body (N, 3) [N], corners (4, 3) [m]
    when the bag says where the plate is."""

    name: str
    t_s: np.ndarray
    cop: np.ndarray
    force: np.ndarray
    corners: np.ndarray | None


@dataclass
class Chair:
    """The robot's chair: a box, its centre and half sizes [m] (the plant's: the profile's chair rule)."""

    centre: np.ndarray
    half_size: np.ndarray


@dataclass
class Scene:
    """Everything ``sit2stand view`` draws; any part may be missing from a run."""

    source: Path
    bags: list[Path]
    start_s: float
    robot: RobotMotion | None = None
    human: HumanMotion | None = None
    chair: Chair | None = None
    human_chair: Chair | None = None
    points: dict[str, PointSeries] = field(default_factory=dict)
    plates: list[Plate] = field(default_factory=list)
    markers: tuple[np.ndarray, np.ndarray] | None = None    # stamps (N,) [s], positions (N, M, 3) [m], NaN missing


def run_bags(path: Path) -> list[Path]:
    """The bags of a run (see the module docstring), the one with the most to show first.

    Raises:
        InputError: ``path`` is neither a bag nor a folder holding one.
    """
    path = Path(path)
    if (path / "metadata.yaml").exists():
        return [path]
    if (path / "standup" / "metadata.yaml").exists():
        bags = [path / "standup"]
    else:
        bags = sorted(p.parent for p in path.glob("*/metadata.yaml"))
    summary = path / "summary.json"
    if summary.exists():
        demo = Path(json.loads(summary.read_text()).get("bag") or "")
        if demo.name and (demo / "metadata.yaml").exists() and demo.resolve() not in {b.resolve() for b in bags}:
            bags.append(demo)
    if not bags:
        raise InputError(f"{path}: not a bag, and no bag in it (a run folder holds a standup/ bag, or the retarget/ "
                         f"and robot/ bags of `retarget --simulate`)")
    return bags


def _xyz(msg) -> list[float]:
    p = msg.position if hasattr(msg, "position") else msg.point
    return [p.x, p.y, p.z]


class _Bags:
    """Topics of several bags, each read from the first bag that has it (the bags open once: opening one parses its
    metadata, ~0.3 s)."""

    def __init__(self, bags: list[Path]) -> None:
        self.readers = [BagReader(bag) for bag in bags]
        self.where: dict[str, BagReader] = {}
        self.custom: dict[str, str] = {}
        for r in self.readers:
            for topic in r.topics():
                self.where.setdefault(topic, r)
            self.custom = {**r.custom_data, **self.custom}

    def path(self, topic: str) -> Path | None:
        return self.where[topic].path if topic in self.where else None

    def read(self, topic: str) -> list:
        """The messages of ``topic`` (empty when no bag has it)."""
        return [m for _, m in self.where[topic].read(topic)] if topic in self.where else []

    def close(self) -> None:
        for r in self.readers:
            r.close()


def load_scene(path: str | Path, robot: str | None = None) -> Scene:
    """The scene of a run (a bag or a run folder); ``robot``: the profile to pose the robot with, when the states'
    joints are not a packaged robot's.

    Raises:
        InputError: nothing to show (no bag, or a bag without any topic drawn here).
        BagError: a bag that cannot be read.
    """
    bags = run_bags(Path(path))
    src = _Bags(bags)
    try:
        return _scene(Path(path), bags, src, robot)
    finally:
        src.close()


def _scene(path: Path, bags: list[Path], src: _Bags, robot: str | None) -> Scene:
    scene = Scene(path, bags, 0.0)
    robot_bag = src.path(ROBOT_JOINT_STATES_TOPIC)
    if robot_bag is not None and ROBOT_BASE_POSE_TOPIC in src.where:
        scene.robot, scene.chair = _robot_motion(read_states(robot_bag), robot)
    desc = src.read(HUMAN_DESCRIPTION_TOPIC)
    if desc and HUMAN_JOINTS_TOPIC in src.where and HUMAN_PELVIS_POSE_TOPIC in src.where:
        scene.human = _human_motion(desc[0].data, src.read(HUMAN_JOINTS_TOPIC), src.read(HUMAN_PELVIS_POSE_TOPIC))
    for label, topic in POINT_TOPICS.items():
        msgs = src.read(topic)
        if msgs:
            scene.points[label] = PointSeries(_stamps(msgs), np.array([_xyz(m) for m in msgs], float))
    corners = plate_corners_from(src.custom)
    for name, topic in PLATE_TOPICS.items():
        msgs = src.read(topic)
        if msgs:
            scene.plates.append(_plate(name, msgs, corners.get(name)))
    scene.human_chair = _human_chair(src, corners.get("chair"))
    frames = src.read(MARKERS_TOPIC)
    if frames:
        scene.markers = (_stamps(frames), np.array([_marker_positions(f) for f in frames]))
    starts = [s.t_s[0] for s in scene.points.values()] + [p.t_s[0] for p in scene.plates]
    starts += [b.t_s[0] for b in (scene.robot, scene.human) if b is not None]
    if not starts:
        raise InputError(f"{path}: nothing to show: no robot states, human skeleton, markers, plates, COM or COP in "
                         f"{', '.join(map(str, bags))}")
    scene.start_s = float(min(starts))
    return scene


HUMAN_SEAT_DEPTH_M = (0.35, 0.10)
"""Without the chair plate's corners, the human's seat reaches this far behind and ahead of the seated pelvis [m]."""


def _human_chair(src: _Bags, plate_corners: np.ndarray | None) -> Chair | None:
    """The human's seat: its height from the demonstration's metadata (``seat_height_m``), over the chair plate (or
    around the first pelvis position); None when the height is not recorded."""
    try:
        top = float(src.custom["seat_height_m"])
    except (KeyError, ValueError):
        return None
    if plate_corners is not None:
        lo, hi = plate_corners[:, :2].min(axis=0), plate_corners[:, :2].max(axis=0)
    else:
        pelvis = src.read(HUMAN_PELVIS_POSE_TOPIC)
        if not pelvis:
            return None
        x = pelvis[0].pose.position.x
        lo, hi = np.array([x - HUMAN_SEAT_DEPTH_M[0], -0.25]), np.array([x + HUMAN_SEAT_DEPTH_M[1], 0.25])
    half = np.array([*(hi - lo) / 2, top / 2])
    return Chair(np.array([*(hi + lo) / 2, top / 2]), half)


def rise_time_s(scene: Scene) -> float:
    """Bag time [s] half-way through the rise: when the robot's COM (else the human's) is first half-way up from its
    lowest to its highest."""
    if scene.robot is not None:
        t, z = scene.robot.t_s, scene.robot.com[:, 2]
    elif "human COM" in scene.points:
        t, z = scene.points["human COM"].t_s, scene.points["human COM"].xyz[:, 2]
    else:
        return scene.start_s
    ok = np.isfinite(z)
    t, z = t[ok], z[ok]
    low = int(np.argmin(z[: int(np.argmax(z)) + 1]))
    above = np.nonzero(z[low:] >= (z[low] + z.max()) / 2)[0]
    return float(t[low + above[0]]) if len(above) else float(t[0])


def human_frames(scene: Scene, robot_t_s: np.ndarray, robot_com_z_m: np.ndarray,
                 at_robot_t_s: np.ndarray) -> np.ndarray | None:
    """The human skeleton's bones (len(at), B, 2, 3) [m] at the instants matched to the robot's ``at_robot_t_s``
    (:func:`~sit2stand.retarget.compare.matched_times`: the same share of each body's rise; the robot's times and
    COM heights on its own clock); None without a skeleton and COM in the scene."""
    if scene.human is None or "human COM" not in scene.points:
        return None
    com = scene.points["human COM"]
    t_h = matched_times((robot_t_s, robot_com_z_m), (com.t_s, com.xyz[:, 2]), at_robot_t_s)
    k = np.clip(np.searchsorted(scene.human.t_s, t_h), 0, len(scene.human.t_s) - 1)
    return scene.human.bones[k]


def _stamps(msgs: list) -> np.ndarray:
    return np.array([stamp_ns(m.header) for m in msgs], float) * 1e-9


def _marker_positions(frame) -> np.ndarray:
    """(M, 3) marker positions [m] of a ``MocapFrame``, NaN where a marker is not seen."""
    p = np.array([[m.x, m.y, m.z] for m in frame.positions], float).reshape(-1, 3)
    p[~np.asarray(frame.valid, bool)] = np.nan
    return p


def _plate(name: str, msgs: list, corners: np.ndarray | None) -> Plate:
    cop = np.array([[m.cop.x, m.cop.y, m.cop.z] if m.cop_valid else [np.nan] * 3 for m in msgs], float)
    force = np.array([[m.wrench.force.x, m.wrench.force.y, m.wrench.force.z] for m in msgs], float)
    return Plate(name, _stamps(msgs), cop, force, corners)


def _robot_motion(states: StateSeries, robot: str | None) -> tuple[RobotMotion, Chair]:
    """The robot posed at :data:`VIEW_RATE_HZ` from its sensed states, and its chair."""
    profile = robot_of(states.joint_names, robot)
    t, s = resample(states, VIEW_RATE_HZ)
    # the joint states' sense (robot.conventions), its meshes by absolute path (a file's relative ones too)
    urdf = mesh_uris_to_files(profile.urdf_text(), profile.urdf)
    model = pin.buildModelFromXML(urdf, pin.JointModelFreeFlyer())
    visuals = pin.buildGeomFromUrdfString(model, urdf, pin.GeometryType.VISUAL, package_dirs=_package_dirs())
    data, gdata = model.createData(), visuals.createData()
    idx = {model.names[j]: model.joints[j].idx_q for j in range(2, model.njoints)}
    cols = [idx[n] for n in s.joint_names if n in idx]
    keep = [i for i, n in enumerate(s.joint_names) if n in idx]
    n = len(t)
    place = np.zeros((visuals.ngeoms, n, 4, 4))
    com, soles = np.zeros((n, 3)), np.zeros((n, len(SIDES), 4, 3))
    foot = [model.getFrameId(profile.foot_links[side]) for side in SIDES]
    sole_local = sole_corners_local(profile) + [0.0, 0.0, -profile.sole.below_foot_m]
    for k in range(n):
        q = pin.neutral(model)
        q[:3], q[3:7] = s.root_pos[k], s.root_quat_xyzw[k]
        q[cols] = s.q[k, keep]
        pin.forwardKinematics(model, data, q)
        pin.updateFramePlacements(model, data)
        pin.updateGeometryPlacements(model, data, visuals, gdata)
        place[:, k] = [g.homogeneous for g in gdata.oMg]
        com[k] = pin.centerOfMass(model, data, q, False)
        soles[k] = [[data.oMf[f].act(c) for c in sole_local] for f in foot]
    meshes = [Visual(g.name, readable_mesh(Path(g.meshPath)), np.asarray(g.meshScale, float),
                     np.asarray(g.meshColor, float), place[i, :, :3, 3], place[i, :, :3, :3])
              for i, g in enumerate(visuals.geometryObjects) if g.meshPath and Path(g.meshPath).is_file()]
    angles = flexion_deg(s.joint_names, s.q, profile.sagittal_flexion())
    return RobotMotion(profile, t, meshes, com, soles, angles), _chair(robot or profile.name, profile)


def _package_dirs() -> list[str]:
    share = package_share("example-robot-data")
    return [str(share.parent)] if share is not None else []


def _chair(robot: str, profile: RobotProfile) -> Chair:
    """The chair the robot's default plant puts it on: its seat where the seated posture rests."""
    plant = Plant(PlantConfig(robot=robot), with_chair=False)
    half = np.array([profile.chair["depth_m"] / 2, profile.chair["width_m"] / 2, plant.seat_height_m / 2])
    return Chair(np.array([plant.chair_front_x - half[0], 0.0, half[2]]), half)


def _human_motion(urdf: str, joint_msgs: list, pelvis_msgs: list) -> HumanMotion:
    """The human skeleton's bones: from each joint's parent joint to it, over the fitted frames."""
    model = pin.buildModelFromXML(urdf, pin.JointModelFreeFlyer())
    data = model.createData()
    t = _stamps(joint_msgs)
    tp = _stamps(pelvis_msgs)
    names = list(joint_msgs[0].name)
    idx = {model.names[j]: model.joints[j].idx_q for j in range(2, model.njoints)}
    q_all = np.array([m.position for m in joint_msgs], float)
    at = np.clip(np.searchsorted(tp, t - 1e-6), 0, len(tp) - 1)
    bones = []
    for k in range(len(joint_msgs)):
        pose = pelvis_msgs[at[k]].pose
        q = pin.neutral(model)
        q[:7] = [pose.position.x, pose.position.y, pose.position.z, pose.orientation.x, pose.orientation.y,
                 pose.orientation.z, pose.orientation.w]
        for j, name in enumerate(names):
            if name in idx:
                q[idx[name]] = q_all[k, j]
        pin.forwardKinematics(model, data, q)
        bones.append([[data.oMi[model.parents[j]].translation.copy(), data.oMi[j].translation.copy()]
                      for j in range(2, model.njoints)
                      if np.linalg.norm(model.jointPlacements[j].translation) > 1e-6])
    angles = flexion_deg(names, q_all, SAGITTAL_FLEXION)
    return HumanMotion(t, np.array(bones, float), angles)
