"""A robot profile: everything sit2stand knows about one humanoid, from one YAML file.

A profile (``sit2stand/data/robots/<name>.yaml``, or a user's file) names the robot's URDF and says, in the paper's
terms, which of its joints and links play which part: per leg the hip yaw, roll and pitch, the knee, the ankle pitch
(and roll, where it has one) and the foot link; the trunk's pitch, yaw and roll joints, those it has; which joints are
the upper limbs; the sole
box the feet stand on; which links touch the floor and the seat; the seated posture; the fall threshold; the links
each marker group of the human may be fixed to; and the joint ranges of the identification's static postures. No
code outside the profile files names a joint or a link of a particular robot.

Names in a profile may hold ``{side}`` (each of ``left`` and ``right``, spelt as the robot spells them: ``sides``)
and joint or link globs (``arm_*``). The URDF is a path (absolute, or relative to the profile file) or
``package://PACKAGE/PATH`` of an installed package that ships robot descriptions (``example-robot-data``: its
``cmeel.prefix/share`` folder on ``sys.path``); its mesh URIs are resolved the same way.

:func:`load_profile` reads and checks a profile's fields; :func:`check_against_model` checks its names against the
robot's model (a joint or link the URDF lacks, a leg without a knee). :func:`profile_of` gives the profile of a
Pinocchio model built by :func:`sit2stand.robot.model.controller_model` (its ``name``).
"""

from __future__ import annotations

import dataclasses
import fnmatch
import os
import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from ..data import folder as data_folder
from ..errors import Sit2StandError
from .conventions import ConventionError, Conventions, brought_to_conventions, floating_base_removed
from .packages import resolve_uri

SIDES = ("left", "right")
"""sit2stand's side names (a profile's ``sides`` maps them to the robot's spelling)."""
LEG_ROLES = ("hip_yaw", "hip_roll", "hip_pitch", "knee", "ankle_pitch", "ankle_roll")
"""A leg's joints by role; the sagittal ones (hip pitch, knee, ankle pitch) turn about +y, flexing the hip with a
negative angle and the knee with a positive one (REP-103), as TALOS and G1 do."""
SAGITTAL_LEG_ROLES = ("hip_pitch", "knee", "ankle_pitch")
LATERAL_LEG_ROLES = ("hip_yaw", "hip_roll", "ankle_roll")
OPTIONAL_LEG_ROLES = ("ankle_roll",)
"""A leg may lack these (Unitree H1's ankle only pitches): the foot then hangs on the ankle pitch."""
TRUNK_ROLES = ("pitch", "yaw", "roll")
CHAIR_FIELDS = ("front_gap_m", "depth_m", "width_m")
MARKER_GROUPS = ("pelvis", "trunk", "head", "arm", "thigh", "shank", "foot")
PROFILE_SUFFIXES = (".yaml", ".yml")
DEFAULT_SEAT_POINT_X_M = -0.05
"""Where a seat supports the seated robot unless its profile says (``seat_point_x_m``): on the seat's surface, this
far along the base's x from its origin (5 cm behind the hip joints: the ischial tuberosities' place on a human; on
TALOS and G1 the lowest points of the pelvis and thighs). The whole-body controller and the plan take the seat's
force there; a robot that sits on its thighs alone, ahead of its hips (iCub), says so. A robot whose trunk only turns
is held at its hips' axis instead (:func:`sit2stand.robot.model.hips_axis_in_base`)."""


class ProfileError(Sit2StandError, ValueError):
    """A robot profile that cannot be used; the message names the file and the field."""


@dataclass(frozen=True)
class Sole:
    """The box a foot stands on, in the foot link's frame [m]: its half sizes (x, y, z), the x of its centre, and
    how far its bottom is below the foot link's origin."""

    half_size_m: tuple[float, float, float]
    centre_x_m: float
    below_foot_m: float


@dataclass(frozen=True)
class PostureRanges:
    """The static postures' ranges [rad] (``collect-postures``): hip flexion, knee flexion, trunk pitch (from 0 to
    each), the ankle pitch's search interval, and per upper-limb joint ``{side}``-template -> (low, high) for the
    left side (the right side's is its mirror, ``mirrored`` joints negated); a stance whose pelvis is lower than
    ``min_pelvis_height_m`` is too deep for the knees' torque."""

    hip: float
    knee: float
    trunk: float
    ankle: tuple[float, float]
    arms: dict[str, tuple[float, float]]
    mirrored: tuple[str, ...]
    min_pelvis_height_m: float


@dataclass
class RobotProfile:
    """One robot (see the module docstring). Joint and link names are the URDF's."""

    name: str
    source: str
    urdf: Path
    root_link: str
    legs: dict[str, dict[str, str]]            # side -> role -> joint
    foot_links: dict[str, str]                 # side -> link
    sole: Sole
    trunk: dict[str, str]                      # role -> joint (those the robot has)
    upper_limbs: tuple[str, ...]               # joint globs
    colliding_links: tuple[str, ...]           # link globs: with the floor and the seat
    seat_links: tuple[str, ...]                # link globs: what rests on the seat (its lowest point sets its height)
    seated_posture: dict[str, float]           # joint glob -> rad
    fall_pelvis_height_m: float
    seat_point_x_m: float                      # where the seat supports the robot, along the base's x [m]
    chair: dict[str, float]                    # front_gap_m (behind the heels), depth_m, width_m
    marker_links: dict[str, tuple[str, ...]]   # marker group -> joint globs ({side}: the marker's side)
    posture_ranges: PostureRanges
    title: str = ""
    sensors: str = ""                          # what the real robot measures (prose for reports)
    gap: dict = field(default_factory=dict)    # the model-gap suite's choices (links for hidden masses, joints)
    sides: dict[str, str] = field(default_factory=lambda: {s: s for s in SIDES})   # sit2stand's -> the robot's
    plants: dict[str, str] = field(default_factory=dict)   # generic plant name -> the packaged plant of this robot
    _joints: dict[str, tuple[str, str]] | None = field(default=None, repr=False)
    _efforts: dict[str, float] = field(default_factory=dict, repr=False)   # moving joint -> URDF effort [N m]
    conventions: Conventions = field(default_factory=Conventions)   # how its URDF was brought to REP-103
    _urdf_text: str | None = field(default=None, repr=False)

    def urdf_text(self) -> str:
        """The URDF as sit2stand reads it: no floating base, its base frame and sagittal joints brought to the
        conventions (:mod:`~sit2stand.robot.conventions`; the file's text where they hold already)."""
        if self._urdf_text is None:
            self._urdf_text = floating_base_removed(self.urdf.read_text())
        return self._urdf_text

    def in_own_sense(self, pattern_values: dict[str, float]) -> dict[str, float]:
        """Joint globs -> angles [rad] of the URDF's sense, as joint -> angle in sit2stand's (later globs win)."""
        moving = sorted(self.moving_joints())
        return {name: self.conventions.angle(name, float(value))
                for pattern, value in pattern_values.items() for name in fnmatch.filter(moving, pattern)}

    # -- names by role ----------------------------------------------------------------------------------------
    def leg(self, side: str, role: str) -> str:
        """The joint of ``role`` (:data:`LEG_ROLES`) in the ``side`` leg."""
        return self.legs[side][role]

    def leg_joints(self, roles: tuple[str, ...] = LEG_ROLES) -> list[str]:
        """Both legs' joints of ``roles`` (those the legs have: :data:`OPTIONAL_LEG_ROLES`), left leg first."""
        return [self.legs[s][r] for s in SIDES for r in roles if r in self.legs[s]]

    def foot_joint(self, side: str) -> str:
        """The joint that carries the foot link (the ankle's last: its roll, else its pitch): the F/T sensor and the
        sole hang on it."""
        return self.legs[side].get("ankle_roll") or self.legs[side]["ankle_pitch"]

    @property
    def redundant_sole_contacts(self) -> bool:
        """Whether the soles' 6D contacts constrain the robot redundantly: legs without an ankle roll (Unitree H1's).
        Wherever the hips' roll axes align (seated, standing straight) each sole's roll then fixes its hip's, and the
        two soles' sideways rows are one: their forces have a null space, their rows are dependent (G1 with fixed
        ankle rolls, seated: the soles' and seat's stacked Jacobian's smallest singular value 1.5e-5 of its largest;
        G1's 0.045)."""
        return any("ankle_roll" not in self.legs[side] for side in SIDES)

    @property
    def trunk_pitch(self) -> str | None:
        """The trunk's pitch joint; None for a robot whose trunk only turns (G1's 23-DoF waist: the hips lean it)."""
        return self.trunk.get("pitch")

    def sagittal_flexion(self) -> dict[str, tuple[tuple[str, ...], float]]:
        """The sagittal flexions as :data:`sit2stand.human.skeleton.SAGITTAL_FLEXION` names them for the human:
        label -> (joints, sign that makes flexion positive: the trunk forward, hip and knee flexion, ankle
        dorsiflexion). Sagittal joints turn about +y (see :data:`LEG_ROLES`)."""
        trunk = {"trunk": ((self.trunk_pitch,), 1.0)} if self.trunk_pitch else {}
        return {**trunk,
                "hip": (tuple(self.leg(s, "hip_pitch") for s in SIDES), -1.0),
                "knee": (tuple(self.leg(s, "knee") for s in SIDES), 1.0),
                "ankle": (tuple(self.leg(s, "ankle_pitch") for s in SIDES), -1.0)}

    def lateral_joints(self) -> list[str]:
        """Trunk yaw and roll, hip yaw and roll, ankle roll: the joints a sagittal rise holds near its seated
        posture."""
        trunk = [self.trunk[r] for r in ("yaw", "roll") if r in self.trunk]
        return trunk + self.leg_joints(LATERAL_LEG_ROLES)

    def is_upper_limb(self, joint: str) -> bool:
        """Whether ``joint`` is an arm, hand or head joint (``upper_limbs``)."""
        return any(fnmatch.fnmatchcase(joint, p) for p in self.upper_limbs)

    def marker_joints(self, group: str, side: str | None, joint_names: list[str]) -> tuple[str, ...]:
        """The joints (of ``joint_names``, a model's) whose links a marker of ``group`` on ``side`` may sit on."""
        out: list[str] = []
        for pattern in self.marker_links.get(group, ()):
            pattern = pattern.replace("{root}", joint_names[0])
            if "{side}" in pattern and side is None:
                continue
            pattern = self.side_name(pattern, side) if side else pattern
            out += [n for n in fnmatch.filter(joint_names, pattern) if n not in out]
        return tuple(out)

    def matches(self, globs: tuple[str, ...], name: str) -> bool:
        """Whether ``name`` matches any of ``globs``."""
        return any(fnmatch.fnmatchcase(name, g) for g in globs)

    def leg_chain(self, side: str) -> list[str]:
        """The ``side`` leg's joints from the pelvis down (the URDF's order: TALOS's hip yaw first, G1's hip pitch)."""
        joints = self.urdf_joints()
        parents = {child: parent for parent, child in joints.values()}
        depth = {}
        for name in self.legs[side].values():
            d, link = 0, joints[name][0]
            while link in parents:
                d, link = d + 1, parents[link]
            depth[name] = d
        return sorted(self.legs[side].values(), key=depth.__getitem__)

    def is_arm_link(self, link: str) -> bool:
        """Whether ``link`` is moved by a joint of the arms (the ``arm`` marker group's joints, either side)."""
        joint = next((j for j, (_, child) in self.urdf_joints().items() if child == link), "")
        arms = [self.side_name(g, s) for g in self.marker_links.get("arm", ()) for s in SIDES]
        return any(fnmatch.fnmatchcase(joint, g) for g in arms)

    def effort_nm(self, joint: str) -> float:
        """The URDF effort limit [N m] of ``joint`` (inf where it gives none)."""
        self.urdf_joints()
        return self._efforts.get(joint, float("inf"))

    def moving_joints(self) -> set[str]:
        """The URDF's moving (not fixed, not floating) joints."""
        self.urdf_joints()
        return set(self._efforts)

    def child_link(self, joint: str) -> str:
        """The URDF link ``joint`` moves."""
        return self.urdf_joints()[joint][1]

    def urdf_joints(self) -> dict[str, tuple[str, str]]:
        """Every URDF joint's (parent link, child link), by name (read once)."""
        if self._joints is None:
            root = ET.fromstring(self.urdf.read_text())
            self._joints = {j.get("name", ""): (j.find("parent").get("link", ""), j.find("child").get("link", ""))
                            for j in root.findall("joint") if j.find("parent") is not None
                            and j.find("child") is not None}
            self._efforts = {j.get("name", ""): float(j.find("limit").get("effort", "inf"))
                             if j.find("limit") is not None else float("inf")
                             for j in root.findall("joint") if j.get("type") not in ("fixed", "floating")}
        return self._joints

    def both_sides(self, name: str) -> str:
        """A glob for ``name`` (a left or right joint or link) on both sides: its side's spelling as ``*``."""
        for s in SIDES:
            if self.sides[s] in name:
                return name.replace(self.sides[s], "*", 1)
        return name

    def side_name(self, template: str, side: str) -> str:
        """``template`` with ``{side}`` spelt as the robot spells ``side``."""
        return template.replace("{side}", self.sides[side])


_LOADED: dict[str, RobotProfile] = {}


def packaged_folder() -> Path:
    """The folder of the packaged profiles."""
    return data_folder("robots")


def packaged_names() -> list[str]:
    return sorted(p.stem for p in packaged_folder().iterdir() if p.suffix in PROFILE_SUFFIXES)


def profile_path(name_or_path: str | os.PathLike) -> Path:
    """A packaged profile's file by name (``talos``, ``g1``), or an existing file."""
    text = os.fspath(name_or_path)
    packaged = packaged_folder() / f"{text}.yaml"
    if Path(text).name == text and packaged.is_file():
        return packaged
    if Path(text).is_file():
        return Path(text)
    raise ProfileError(f"{text!r}: no such robot profile file, nor a packaged profile's name "
                       f"(packaged: {', '.join(packaged_names())})")


def load_profile(name_or_path: str | os.PathLike | RobotProfile = "talos") -> RobotProfile:
    """Read a robot profile (a packaged name or a file); the same profile object for the same name.

    Raises:
        ProfileError: the file is missing or not YAML, or a field is missing or malformed (named with the file).
    """
    if isinstance(name_or_path, RobotProfile):
        return name_or_path
    key = os.fspath(name_or_path)
    if key in _LOADED:
        return _LOADED[key]
    path = profile_path(key)
    try:
        doc = yaml.safe_load(path.read_text())
    except yaml.YAMLError as err:
        raise ProfileError(f"{path}: not valid YAML: {err}") from None
    if not isinstance(doc, dict):
        raise ProfileError(f"{path}: a robot profile is a YAML mapping of fields")
    profile = _parse(doc, path)
    check_against_urdf(profile)
    _bring_to_conventions(profile)
    known = _LOADED.get(profile.name)
    if known is not None and Path(known.source).resolve() != path.resolve():
        raise ProfileError(f"{path}: a robot named {profile.name!r} is loaded already from {known.source}; "
                           f"give this profile another name")
    _LOADED[key] = _LOADED[profile.name] = profile
    return profile


def profile_of(model) -> RobotProfile:
    """The profile of a robot model built from one (a Pinocchio model's ``name`` is its profile's)."""
    name = getattr(model, "name", "")
    if name in _LOADED:
        return _LOADED[name]
    try:
        return load_profile(name)
    except ProfileError:
        raise ProfileError(f"model {name!r} was not built from a robot profile loaded here "
                           f"(sit2stand.robot.model.controller_model names its model after its profile)") from None


def _bring_to_conventions(profile: RobotProfile) -> None:
    """The profile's URDF text and its angles in sit2stand's conventions (:mod:`~sit2stand.robot.conventions`).

    Raises:
        ProfileError: naming the file and the field, where the URDF cannot be brought to them.
    """
    sagittal = {profile.leg(s, r): f"legs.{r}" for s in SIDES for r in SAGITTAL_LEG_ROLES}
    if profile.trunk_pitch:
        sagittal[profile.trunk_pitch] = "trunk.pitch"
    try:
        text, conventions = brought_to_conventions(profile.urdf_text(), profile.foot_links, sagittal)
    except ConventionError as err:
        raise ProfileError(f"{profile.source}: field {err.field!r}: {err} (URDF {profile.urdf.name})") from None
    if not conventions.changed:
        return
    profile.conventions, profile._urdf_text = conventions, text
    profile.seated_posture = profile.in_own_sense(profile.seated_posture)
    ankle = profile.leg("left", "ankle_pitch")
    profile.posture_ranges = dataclasses.replace(
        profile.posture_ranges, ankle=conventions.interval(ankle, *profile.posture_ranges.ankle))


def check_against_urdf(profile: RobotProfile) -> None:
    """Every name of the profile in its URDF: the legs' and trunk's joints (moving ones), the root and foot links;
    each glob matches something; the seated posture within the joints' limits.

    Raises:
        ProfileError: naming the file, the field and what is wrong.
    """
    root = ET.fromstring(profile.urdf.read_text())
    joints = {j.get("name"): j for j in root.findall("joint")}
    moving = [n for n, j in joints.items() if j.get("type") in ("revolute", "continuous", "prismatic")]
    links = {link.get("name") for link in root.findall("link")}
    fail = lambda field_name, what: ProfileError(  # noqa: E731
        f"{profile.source}: field {field_name!r}: {what} (URDF {profile.urdf.name})")
    roles = [(f"legs.{r}", j) for s in SIDES for r, j in profile.legs[s].items()] + \
        [(f"trunk.{r}", j) for r, j in profile.trunk.items()]
    for field_name, joint in roles:
        if joint not in moving:
            raise fail(field_name, f"{joint!r} is not a moving joint of the URDF")
    for side in SIDES:
        if profile.foot_links[side] not in links:
            raise fail("foot_link", f"{profile.foot_links[side]!r} is not a link of the URDF")
    if profile.root_link not in links:
        raise fail("root_link", f"{profile.root_link!r} is not a link of the URDF")
    for field_name, globs, names in (("upper_limbs", profile.upper_limbs, moving),
                                     ("colliding_links", profile.colliding_links, links),
                                     ("seat_links", profile.seat_links, links)):
        for g in globs:
            if not fnmatch.filter(names, g):
                raise fail(field_name, f"{g!r} matches nothing")
    for group, globs in profile.marker_links.items():
        for g in globs:
            if "{root}" not in g and not any(fnmatch.filter(moving, profile.side_name(g, s)) for s in SIDES):
                raise fail(f"marker_links.{group}", f"{g!r} matches no moving joint")
    for pattern, value in profile.seated_posture.items():
        matched = fnmatch.filter(moving, pattern)
        if not matched:
            raise fail("seated_posture", f"{pattern!r} matches no moving joint")
        for name in matched:
            limit = joints[name].find("limit")
            lo, hi = (float(limit.get("lower", "-inf")), float(limit.get("upper", "inf"))) if limit is not None \
                else (-np.inf, np.inf)
            if not lo <= value <= hi:
                raise fail("seated_posture", f"{name} at {value:g} rad is outside its limits [{lo:g}, {hi:g}]")


class _Fields:
    """Reads a profile's fields, each error naming the file and the field."""

    def __init__(self, doc: dict, path: Path) -> None:
        self.doc, self.path = doc, path

    def fail(self, name: str, what: str) -> ProfileError:
        return ProfileError(f"{self.path}: field {name!r}: {what}")

    def get(self, name: str, kind=None, default=...):
        node = self.doc
        for part in name.split("."):
            if not isinstance(node, dict) or part not in node:
                if default is not ...:
                    return default
                raise self.fail(name, "missing")
            node = node[part]
        if kind is not None and not isinstance(node, kind):
            raise self.fail(name, f"expected {getattr(kind, '__name__', kind)}, got {node!r}")
        return node

    def number(self, name: str, default=...) -> float:
        value = self.get(name, default=default)
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self.fail(name, f"expected a number, got {value!r}")
        return float(value)

    def numbers(self, name: str, n: int) -> tuple[float, ...]:
        value = self.get(name, list)
        if len(value) != n or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value):
            raise self.fail(name, f"expected {n} numbers, got {value!r}")
        return tuple(float(v) for v in value)

    def names(self, name: str, default=...) -> tuple[str, ...]:
        value = self.get(name, default=default)
        value = [value] if isinstance(value, str) else value
        if not isinstance(value, list) or not all(isinstance(v, str) and v for v in value):
            raise self.fail(name, f"expected a list of names, got {value!r}")
        return tuple(value)


def _foot_links(f: _Fields, per_side) -> dict[str, str]:
    """``foot_link``: a ``{side}`` template, or a link per side where the file spells its links' sides unlike its
    joints' (Romeo's ankle joints start with ``L``, its ankle links with ``l_``)."""
    value = f.get("foot_link")
    if isinstance(value, str) and value:
        return per_side(value)
    if not isinstance(value, dict) or set(value) != set(SIDES) or not all(isinstance(v, str) for v in value.values()):
        raise f.fail("foot_link", f"a link name with {{side}}, or one for each of {', '.join(SIDES)}; got {value!r}")
    return {s: value[s] for s in SIDES}


def _parse(doc: dict, path: Path) -> RobotProfile:
    f = _Fields(doc, path)
    unknown = set(doc) - set(_FIELDS)
    if unknown:
        raise ProfileError(f"{path}: unknown field(s) {', '.join(sorted(unknown))} (known: {', '.join(_FIELDS)})")
    side_names = {s: str(f.get(f"sides.{s}", default=s)) for s in SIDES}
    per_side = lambda text: {s: text.replace("{side}", side_names[s]) for s in SIDES}  # noqa: E731
    legs_doc = f.get("legs", dict)
    missing = [r for r in LEG_ROLES if r not in legs_doc and r not in OPTIONAL_LEG_ROLES]
    if missing:
        raise f.fail("legs", f"no {', '.join(missing)} (a leg names: {', '.join(LEG_ROLES)}; "
                             f"{', '.join(OPTIONAL_LEG_ROLES)} where it has one)")
    legs = {s: {r: per_side(str(f.get(f"legs.{r}", str)))[s] for r in LEG_ROLES if r in legs_doc} for s in SIDES}
    trunk = {r: str(v) for r, v in f.get("trunk", dict).items()}
    if set(trunk) - set(TRUNK_ROLES):
        raise f.fail("trunk", f"names the trunk's joints by role ({', '.join(TRUNK_ROLES)}), those it has")
    arms = {str(k): tuple(f.numbers(f"posture_ranges.arms.{k}", 2)) for k in f.get("posture_ranges.arms", dict)}
    ranges = PostureRanges(f.number("posture_ranges.hip"), f.number("posture_ranges.knee"),
                           f.number("posture_ranges.trunk"), f.numbers("posture_ranges.ankle", 2), arms,
                           f.names("posture_ranges.mirrored", default=()),
                           f.number("posture_ranges.min_pelvis_height_m"))
    markers = {g: f.names(f"marker_links.{g}") for g in f.get("marker_links", dict)}
    bad = set(markers) - set(MARKER_GROUPS)
    if bad or set(MARKER_GROUPS) - set(markers):
        raise f.fail("marker_links", f"one entry per marker group: {', '.join(MARKER_GROUPS)}")
    seated = f.get("seated_posture", dict)
    for k in seated:
        f.number(f"seated_posture.{k}")
    fall = f.number("fall_pelvis_height_m")
    if fall <= 0:
        raise f.fail("fall_pelvis_height_m", "must be a height above the floor [m]")
    half = f.numbers("sole.half_size_m", 3)
    if min(half) <= 0:
        raise f.fail("sole.half_size_m", "half sizes must be positive [m]")
    profile = RobotProfile(
        name=str(f.get("name", str)), source=str(path), urdf=_resolve_urdf(f), root_link=str(f.get("root_link", str)),
        legs=legs, foot_links=_foot_links(f, per_side),
        sole=Sole(half, f.number("sole.centre_x_m"), f.number("sole.below_foot_m")), trunk=trunk,
        upper_limbs=f.names("upper_limbs"), colliding_links=f.names("colliding_links"),
        seat_links=f.names("seat_links"), seated_posture={str(k): float(v) for k, v in seated.items()},
        fall_pelvis_height_m=fall, seat_point_x_m=f.number("seat_point_x_m", default=DEFAULT_SEAT_POINT_X_M),
        chair={k: f.number(f"chair.{k}") for k in CHAIR_FIELDS}, marker_links=markers,
        posture_ranges=ranges, title=str(f.get("title", default="")),
        sensors=str(f.get("sensors", default="")), gap=dict(f.get("gap", dict, default={})), sides=side_names,
        plants={str(k): str(v) for k, v in f.get("plants", dict, default={}).items()})
    if not re.fullmatch(r"[A-Za-z][A-Za-z0-9_\-]*", profile.name):
        raise f.fail("name", f"{profile.name!r}: letters, digits, '_' and '-' only")
    return profile


_FIELDS = ("name", "title", "urdf", "root_link", "sides", "legs", "foot_link", "sole", "trunk", "upper_limbs",
           "colliding_links", "seat_links", "seated_posture", "fall_pelvis_height_m", "seat_point_x_m", "chair",
           "marker_links", "posture_ranges", "sensors", "gap", "plants")


def _resolve_urdf(f: _Fields) -> Path:
    uri = str(f.get("urdf", str))
    try:
        path = resolve_uri(uri, f.path.parent)
    except FileNotFoundError as err:
        raise f.fail("urdf", str(err)) from None
    if not path.is_file():
        raise f.fail("urdf", f"no such file {path}")
    return path
