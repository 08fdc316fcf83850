"""Full-body human skeleton with de Leva inertia and a marker set (Plug-in-Gait by default), as a Pinocchio model.

Bodies (16): pelvis (floating base, origin at the mid-hip point), torso, head, upper_arm/forearm/hand, thigh/shank/
foot/toes on each side (suffix ``_l``/``_r``). 38 degrees of freedom: free-flyer 6, lumbar 3, neck 3, shoulders 3,
elbows 1, wrists 2, hips 3, knees 1, ankles 2 (flexion, inversion), toes 1. Multi-axis joints are chains of
revolute joints named ``<joint>_<axis>`` (``hip_l_y``: flexion/extension about y, then ``_x``, then ``_z``).

Frames follow REP-103 at the zero configuration (standing upright, arms hanging, feet flat, facing +x): x forward,
y left, z up in every body. Each angle is a right-handed rotation about its axis, so about y: trunk flexion
(``lumbar_y``), knee flexion and ankle plantarflexion are positive; hip and shoulder flexion and elbow flexion are
negative.

Subjects are described by stature, body mass, sex, optional per-segment length factors (``lengths``), optional
per-segment mass factors (``masses``, renormalised to the body mass) and optional extra rigid point masses
(:class:`ExtraMass`, e.g. a backpack), which the synthesiser uses to hide a mass distribution unlike the average.

The markers come from a marker set file (:mod:`sit2stand.human.marker_sets`): each marker's segment and offset are
data, placed on the built body by :func:`build_human`. The default, Vicon Plug-in-Gait (``plug_in_gait.yaml``),
gives the placements this module's builders carried before marker sets were data.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from .anthropometry import TOE_MASS_FRACTION, ankle_height_m, anthropometric_set, check_subject, segment_inertias
from .marker_sets import DEFAULT_MARKER_SET, MarkerSet, MarkerSetError, load_marker_set

SIDES = ("l", "r")
KNEE_JOINTS = tuple(f"knee_{s}_y" for s in SIDES)
"""The knees' flexion joints (positive flexion) of the skeleton, as ``/human/joint_states`` names them."""
SAGITTAL_FLEXION = {"trunk": (("lumbar_y",), 1.0), "hip": (tuple(f"hip_{s}_y" for s in SIDES), -1.0),
                    "knee": (KNEE_JOINTS, 1.0), "ankle": (tuple(f"ankle_{s}_y" for s in SIDES), -1.0)}
"""The sagittal flexions (trunk on the pelvis, hip, knee, ankle dorsiflexion): label -> (the skeleton's joints, the
sign that makes flexion positive; see above). :meth:`~sit2stand.robot.profile.RobotProfile.sagittal_flexion` is the
robot's counterpart."""
SEGMENTS = ["pelvis", "torso", "head"] + [f"{s}_{side}" for side in SIDES for s in
                                         ("upper_arm", "forearm", "hand", "thigh", "shank", "foot", "toes")]
LENGTH_GROUPS = ("pelvis", "torso", "head", "upper_arm", "forearm", "hand", "thigh", "shank", "foot")
"""Segment groups whose length can be scaled (left and right together)."""
SEGMENT_MASS_SD = 0.08
"""A person's segment mass relative to the table's (de Leva's, scaled to stature and mass), one standard deviation
across people: an assumption of this project, the spread its synthesiser draws (``human.synth``) and the human side
of the model gap allows a body (``gap.human``)."""
ALIASES = {"trunk": "torso", "back": "torso", "abdomen": "torso"}
REFERENCE_STATURE_M = 1.75
"""Marker offsets in millimetres (marker set files) are given for this stature [m] and scale with the subject's."""

PLUG_IN_GAIT = load_marker_set(DEFAULT_MARKER_SET).names
"""The default marker set's names (Vicon Plug-in-Gait full body, 35 markers), in its order."""


@dataclass(frozen=True)
class ExtraMass:
    """A rigid point mass fixed to a segment: ``mass_kg`` at ``offset_m`` from the segment's COM (segment axes)."""

    segment: str
    mass_kg: float
    offset_m: tuple[float, float, float] = (0.0, 0.0, 0.0)

    @staticmethod
    def parse(text: str) -> ExtraMass:
        """``SEGMENT:KG[:x,y,z]`` as on the command line, e.g. ``trunk:8`` or ``torso:6:-0.15,0,0.1``."""
        parts = text.split(":")
        if len(parts) not in (2, 3):
            raise ValueError(f"extra mass {text!r} is not SEGMENT:KG[:x,y,z]")
        segment = ALIASES.get(parts[0], parts[0])
        if segment not in SEGMENTS:
            raise ValueError(f"extra mass {text!r}: unknown segment {parts[0]!r} (one of {', '.join(SEGMENTS)})")
        try:
            mass = float(parts[1])
            offset = tuple(float(v) for v in parts[2].split(",")) if len(parts) == 3 else (0.0, 0.0, 0.0)
        except ValueError:
            raise ValueError(f"extra mass {text!r}: mass and offset must be numbers") from None
        if mass <= 0 or len(offset) != 3:
            raise ValueError(f"extra mass {text!r}: needs a positive mass and three offset values")
        return ExtraMass(segment, mass, offset)


@dataclass
class Subject:
    """Who the skeleton describes. ``lengths``/``masses``: factors per length group / per segment (default 1);
    ``marker_set``: the markers the subject wears (a :class:`~sit2stand.human.marker_sets.MarkerSet`, a packaged
    set's name or a file; None: Plug-in-Gait)."""

    height_m: float = 1.75
    mass_kg: float = 75.0
    sex: str = "male"
    lengths: dict[str, float] = field(default_factory=dict)
    masses: dict[str, float] = field(default_factory=dict)
    extra: list[ExtraMass] = field(default_factory=list)
    marker_set: MarkerSet | str | None = None

    def __post_init__(self) -> None:
        check_subject(self.height_m, self.mass_kg, self.sex)
        for name in self.lengths:
            if name not in LENGTH_GROUPS:
                raise ValueError(f"length factor for unknown group {name!r} (one of {', '.join(LENGTH_GROUPS)})")
        for name in self.masses:
            if name not in SEGMENTS:
                raise ValueError(f"mass factor for unknown segment {name!r}")


@dataclass
class HumanModel:
    """A built skeleton: the Pinocchio model plus the names needed to use it."""

    subject: Subject
    model: pin.Model
    marker_names: list[str]
    marker_frames: dict[str, int]
    segment_joint: dict[str, int]          # segment -> joint id its inertia hangs on
    segment_mass: dict[str, float]         # [kg], extra masses included
    segment_com: dict[str, np.ndarray]     # COM in the joint frame [m], extra masses included
    geometry: dict[str, dict]              # segment -> {"from": xyz, "to": xyz, "radius": m} for drawing
    marker_set: MarkerSet | None = None    # where the markers came from (its pelvis rule tells MarkerIK what it needs)
    ankle_height_m: float = float("nan")   # ankle joint above the sole [m]

    @property
    def total_mass(self) -> float:
        """Body mass [kg], extra masses included."""
        return float(sum(self.segment_mass.values()))

    def joint_names(self) -> list[str]:
        """Names of the 32 non-root joints, in configuration order (q[7:])."""
        return list(self.model.names[2:])


def _rev(axis: str) -> pin.JointModel:
    """Revolute joint model about ``axis`` (x, y or z)."""
    return {"x": pin.JointModelRX(), "y": pin.JointModelRY(), "z": pin.JointModelRZ()}[axis]


def _limits(name: str) -> tuple[float, float]:
    """Anatomical range of motion [rad] of a joint axis (sign convention in the module docstring)."""
    table = {
        "lumbar_y": (-0.6, 1.3), "lumbar_x": (-0.5, 0.5), "lumbar_z": (-0.6, 0.6),
        "neck_y": (-1.0, 1.0), "neck_x": (-0.7, 0.7), "neck_z": (-1.2, 1.2),
        "shoulder_y": (-3.0, 1.0), "shoulder_x": (-1.0, 3.0), "shoulder_z": (-1.5, 1.5),
        "elbow_y": (-2.6, 0.05), "wrist_y": (-1.2, 1.2), "wrist_x": (-0.6, 0.6),
        "hip_y": (-2.4, 0.6), "hip_x": (-0.6, 0.8), "hip_z": (-0.8, 0.8),
        "knee_y": (-0.1, 2.6), "ankle_y": (-0.8, 0.9), "ankle_x": (-0.5, 0.5), "toe_y": (-1.0, 0.6),
    }
    base = name.rsplit("_", 2)
    key = f"{base[0]}_{base[-1]}" if len(base) == 3 else name
    lo, hi = table[key]
    if name.endswith("_r_x") or name.endswith("_r_z"):  # mirror abduction/rotation on the right side
        lo, hi = -hi, -lo
    return lo, hi


def _segment_masses(subject: Subject, seg: dict) -> dict[str, float]:
    """Segment masses [kg] with the subject's factors, renormalised to the body mass (extra masses come on top)."""
    base_mass = {"pelvis": seg["pelvis"].mass_kg, "torso": seg["torso"].mass_kg, "head": seg["head"].mass_kg}
    for side in SIDES:
        for name in ("upper_arm", "forearm", "hand", "thigh", "shank"):
            base_mass[f"{name}_{side}"] = seg[name].mass_kg
        base_mass[f"foot_{side}"] = seg["foot"].mass_kg * (1 - TOE_MASS_FRACTION)
        base_mass[f"toes_{side}"] = seg["foot"].mass_kg * TOE_MASS_FRACTION
    factored = {k: v * subject.masses.get(k, 1.0) for k, v in base_mass.items()}
    norm = subject.mass_kg / sum(factored.values())
    return {k: v * norm for k, v in factored.items()}


@dataclass
class _Builder:
    """The skeleton under construction: joints, segment inertias, drawing geometry and marker offsets (SI units)."""

    subject: Subject
    seg: dict                              # de Leva segments (anthropometry.segment_inertias) of this body
    mass: dict[str, float]                 # segment -> mass [kg]; extra masses added as segments are attached
    L: dict[str, float]                    # length factor per group
    s: float                               # stature / REFERENCE_STATURE_M
    h_ankle: float                         # ankle height above the sole [m]
    model: pin.Model = field(default_factory=pin.Model)
    segment_joint: dict[str, int] = field(default_factory=dict)
    segment_com: dict[str, np.ndarray] = field(default_factory=dict)
    geometry: dict[str, dict] = field(default_factory=dict)
    mm: float = field(init=False)          # 1 mm at the reference stature, scaled to this body [m]

    def __post_init__(self) -> None:
        self.model.name = "human"
        self.mm = 1e-3 * self.s

    def inertia_of(self, group: str, name: str) -> np.ndarray:
        """Principal inertia [kg m^2] scaled with mass and length^2 (about COM), foot/toes lying along x."""
        ref = self.seg[group]
        i = np.array(ref.inertia_kgm2) * self.mass[name] / (ref.mass_kg * (TOE_MASS_FRACTION if group == "toes" else 1))
        i *= self.L.get(group, 1.0) ** 2
        return i

    def add_chain(self, parent: int, joint: str, axes: str, origin) -> int:
        """Revolute joints ``<joint>_<axis>`` for each axis, the first at ``origin`` [m] in the parent; the last id."""
        jid = parent
        for k, axis in enumerate(axes):
            name = f"{joint}_{axis}"
            lo, hi = _limits(name)
            placement = pin.SE3(np.eye(3), np.asarray(origin, float) if k == 0 else np.zeros(3))
            jid = self.model.addJoint(jid, _rev(axis), placement, name, np.array([200.0]), np.array([20.0]),
                                      np.array([lo]), np.array([hi]))
        return jid

    def attach(self, jid: int, name: str, com, inertia_diag, from_xyz, to_xyz, radius) -> None:
        """Segment ``name`` on joint ``jid``: COM [m], principal inertia [kg m^2], its extra masses, a capsule [m]."""
        com = np.asarray(com, float)
        m = self.mass[name]
        inertia = pin.Inertia(m, com, np.diag(inertia_diag))
        for extra in self.subject.extra:
            if extra.segment == name:
                inertia = inertia + pin.Inertia(extra.mass_kg, com + np.asarray(extra.offset_m), np.zeros((3, 3)))
        self.model.appendBodyToJoint(jid, inertia, pin.SE3.Identity())
        self.model.addFrame(pin.Frame(name, jid, pin.SE3.Identity(), pin.FrameType.BODY))
        self.segment_joint[name] = jid
        self.segment_com[name] = inertia.lever.copy()
        self.mass[name] = inertia.mass
        self.geometry[name] = {"from": np.asarray(from_xyz, float), "to": np.asarray(to_xyz, float), "radius": radius}

    def segment_length(self, segment: str) -> float:
        """Length [m] of a segment with its length factor (the toes take the foot's: the offsets' unit)."""
        group = segment.rsplit("_", 1)[0] if segment.endswith(("_l", "_r")) else segment
        group = "foot" if group == "toes" else group
        return self.seg[group].length_m * self.L[group]

    def marker_frames(self, marker_set: MarkerSet) -> dict[str, int]:
        """Add the set's markers as operational frames on their segments, in the set's order; name -> frame id.

        Raises:
            MarkerSetError: a marker on a segment the skeleton lacks (the message names the file and the segments).
        """
        frames = {}
        # a child's head is larger than an adult's of its stature: head offsets grow as the segment table's head does
        head_mm = self.mm * anthropometric_set(self.subject.height_m, self.subject.sex).length_factors["head"]
        for spec in marker_set.markers:
            if spec.segment not in self.segment_joint:
                raise MarkerSetError(f"{marker_set.source or marker_set.name}: marker {spec.name} is on segment "
                                     f"{spec.segment!r}, not one of {', '.join(SEGMENTS)}")
            group = spec.segment.rsplit("_", 1)[0] if spec.segment.endswith(("_l", "_r")) else spec.segment
            xyz = spec.offset_m(head_mm if group == "head" else self.mm, self.L.get(group, 1.0),
                                self.segment_length(spec.segment), self.h_ankle)
            frames[spec.name] = self.model.addFrame(pin.Frame(spec.name, self.segment_joint[spec.segment],
                                                              pin.SE3(np.eye(3), np.array(xyz)),
                                                              pin.FrameType.OP_FRAME))
        return frames


def build_human(subject: Subject | None = None, marker_set: MarkerSet | str | None = None) -> HumanModel:
    """Build the skeleton of ``subject`` (default: a 1.75 m, 75 kg average male) with the markers of
    ``marker_set`` (a :class:`~sit2stand.human.marker_sets.MarkerSet`, a packaged set's name or a YAML file; default:
    the subject's, else Plug-in-Gait)."""
    subject = subject or Subject()
    markers = load_marker_set(marker_set if marker_set is not None else subject.marker_set)
    H, sex = subject.height_m, subject.sex
    seg = segment_inertias(H, subject.mass_kg, sex)
    L = {g: subject.lengths.get(g, 1.0) for g in LENGTH_GROUPS}
    b = _Builder(subject, seg, _segment_masses(subject, seg), L, H / REFERENCE_STATURE_M,
                 ankle_height_m(H, sex) * L["foot"])
    root = _add_pelvis(b)
    torso = _add_torso_and_head(b, root)
    for side, sy in (("l", 1.0), ("r", -1.0)):
        _add_arm(b, torso, side, sy)
        _add_leg(b, root, side, sy)
    marker_frames = b.marker_frames(markers)
    return HumanModel(subject, b.model, markers.names, marker_frames, b.segment_joint, b.mass, b.segment_com,
                      b.geometry, markers, b.h_ankle)


def _add_pelvis(b: _Builder) -> int:
    """The pelvis: floating base at the mid-hip point; the root joint id."""
    seg, L, s = b.seg, b.L, b.s
    root = b.model.addJoint(0, pin.JointModelFreeFlyer(), pin.SE3.Identity(), "pelvis")
    l_pel = seg["pelvis"].length_m * L["pelvis"]
    b.attach(root, "pelvis", [0, 0, seg["pelvis"].com_from_proximal_m * L["pelvis"]], b.inertia_of("pelvis", "pelvis"),
             [0, 0, 0], [0, 0, l_pel], 0.085 * s)
    return root


def _add_torso_and_head(b: _Builder, root: int) -> int:
    """Lumbar joints, torso, neck joints and head; the torso's joint id."""
    seg, L, s = b.seg, b.L, b.s
    l_pel = seg["pelvis"].length_m * L["pelvis"]
    l_to = seg["torso"].length_m * L["torso"]
    torso = b.add_chain(root, "lumbar", "yxz", [0, 0, l_pel])
    b.attach(torso, "torso", [0, 0, seg["torso"].com_from_proximal_m * L["torso"]], b.inertia_of("torso", "torso"),
             [0, 0, 0], [0, 0, l_to], 0.12 * s)
    l_head = seg["head"].length_m * L["head"]
    head = b.add_chain(torso, "neck", "yxz", [0, 0, l_to])
    b.attach(head, "head", [0.01 * s, 0, seg["head"].com_from_proximal_m * L["head"]], b.inertia_of("head", "head"),
             [0.01 * s, 0, 0.05 * s], [0.01 * s, 0, l_head - 0.07 * s], 0.085 * s)
    return torso


def _add_arm(b: _Builder, torso: int, side: str, sy: float) -> None:
    """Shoulder, elbow and wrist joints with upper arm, forearm and hand of one side (sy: +1 left, -1 right)."""
    seg, L, s, H = b.seg, b.L, b.s, b.subject.height_m
    l_to = seg["torso"].length_m * L["torso"]
    l_ua, l_fa, l_ha = (seg[g].length_m * L[g] for g in ("upper_arm", "forearm", "hand"))
    shoulder = b.add_chain(torso, f"shoulder_{side}", "yxz", [0, sy * 0.095 * H, l_to - 0.04 * H])
    b.attach(shoulder, f"upper_arm_{side}", [0, 0, -seg["upper_arm"].com_from_proximal_m * L["upper_arm"]],
             b.inertia_of("upper_arm", f"upper_arm_{side}"), [0, 0, 0], [0, 0, -l_ua], 0.045 * s)
    elbow = b.add_chain(shoulder, f"elbow_{side}", "y", [0, 0, -l_ua])
    b.attach(elbow, f"forearm_{side}", [0, 0, -seg["forearm"].com_from_proximal_m * L["forearm"]],
             b.inertia_of("forearm", f"forearm_{side}"), [0, 0, 0], [0, 0, -l_fa], 0.035 * s)
    wrist = b.add_chain(elbow, f"wrist_{side}", "yx", [0, 0, -l_fa])
    b.attach(wrist, f"hand_{side}", [0, 0, -seg["hand"].com_from_proximal_m * L["hand"]],
             b.inertia_of("hand", f"hand_{side}"), [0, 0, 0], [0, 0, -l_ha], 0.03 * s)


def _add_leg(b: _Builder, root: int, side: str, sy: float) -> None:
    """Hip and knee joints with thigh and shank of one side (sy: +1 left, -1 right), then its foot."""
    seg, L, s = b.seg, b.L, b.s
    hip_y = 0.048 * b.subject.height_m * L["pelvis"]
    l_th, l_sh = (seg[g].length_m * L[g] for g in ("thigh", "shank"))
    hip = b.add_chain(root, f"hip_{side}", "yxz", [0, sy * hip_y, 0])
    b.attach(hip, f"thigh_{side}", [0, 0, -seg["thigh"].com_from_proximal_m * L["thigh"]],
             b.inertia_of("thigh", f"thigh_{side}"), [0, 0, 0], [0, 0, -l_th], 0.075 * s)
    knee = b.add_chain(hip, f"knee_{side}", "y", [0, 0, -l_th])
    b.attach(knee, f"shank_{side}", [0, 0, -seg["shank"].com_from_proximal_m * L["shank"]],
             b.inertia_of("shank", f"shank_{side}"), [0, 0, 0], [0, 0, -l_sh], 0.055 * s)
    _add_foot(b, knee, side, sy, l_sh)


def _add_foot(b: _Builder, knee: int, side: str, sy: float, l_sh: float) -> None:
    """Ankle and toe joints with hindfoot and toes of one side, below a shank of length ``l_sh`` [m]."""
    seg, L, s, h_ankle = b.seg, b.L, b.s, b.h_ankle
    l_ft = seg["foot"].length_m * L["foot"]
    ankle = b.add_chain(knee, f"ankle_{side}", "yx", [0, 0, -l_sh])
    heel_x, mtp_x, tip_x = -0.22 * l_ft, 0.52 * l_ft, 0.78 * l_ft
    # hindfoot COM chosen so that foot + toes (at zero) has de Leva's COM (44.15 % heel -> tip for males)
    com_total = np.array([heel_x + seg["foot"].com_from_proximal_m * L["foot"], 0, -0.5 * h_ankle])
    toes_com_rel = np.array([0.5 * (tip_x - mtp_x), 0, 0.0])
    mtp = np.array([mtp_x, 0, -h_ankle + 0.015 * s])
    m_f, m_t = b.mass[f"foot_{side}"], b.mass[f"toes_{side}"]
    foot_com = (com_total * (m_f + m_t) - (mtp + toes_com_rel) * m_t) / m_f
    b.attach(ankle, f"foot_{side}", foot_com, b.inertia_of("foot", f"foot_{side}") * (1 - TOE_MASS_FRACTION),
             [heel_x, 0, -h_ankle + 0.02 * s], [mtp_x, 0, -h_ankle + 0.02 * s], 0.035 * s)
    toe = b.add_chain(ankle, f"toe_{side}", "y", mtp)
    b.attach(toe, f"toes_{side}", toes_com_rel, b.inertia_of("foot", f"foot_{side}") * TOE_MASS_FRACTION,
             [0, 0, 0.005 * s], [tip_x - mtp_x, 0, 0.005 * s], 0.02 * s)


def standing_configuration(human: HumanModel) -> np.ndarray:
    """q of upright standing with the soles on the floor (z = 0), at the origin, facing +x."""
    q = pin.neutral(human.model)
    data = human.model.createData()
    pin.forwardKinematics(human.model, data, q)
    ankle = data.oMi[human.segment_joint["foot_l"]].translation
    q[2] = -(ankle[2] - human.ankle_height_m)
    return q


def to_mjcf(human: HumanModel, name: str = "human") -> str:
    """MJCF of the same skeleton (same masses, COMs, inertias, joints, limits), capsules for drawing and contact,
    sites at the markers. Loads in MuJoCo with a free root joint."""
    model = human.model
    children: dict[int, list[int]] = {}
    for jid in range(1, model.njoints):
        children.setdefault(model.parents[jid], []).append(jid)
    seg_of_joint = {j: s for s, j in human.segment_joint.items()}
    sites: dict[int, list[tuple[str, np.ndarray]]] = {}
    for mname, fid in human.marker_frames.items():
        frame = model.frames[fid]
        sites.setdefault(frame.parentJoint, []).append((mname, frame.placement.translation))

    def fmt(v) -> str:
        """Numbers as MJCF attribute text."""
        return " ".join(f"{x:.6g}" for x in np.asarray(v, float).ravel())

    lines = [f'<mujoco model="{name}">', '  <compiler angle="radian" autolimits="true"/>',
             '  <option timestep="0.001" gravity="0 0 -9.81"/>',
             '  <default><geom contype="0" conaffinity="0" rgba="0.8 0.6 0.5 1"/>'
             '<site size="0.008" rgba="0.1 0.4 1 1"/><joint damping="0.5" armature="0.01"/></default>',
             '  <worldbody>']

    def body(jid: int, indent: str) -> None:
        """The MJCF body of joint ``jid`` and, recursively, of its children."""
        joint = model.joints[jid]
        placement = model.jointPlacements[jid].translation
        jname = model.names[jid]
        lines.append(f'{indent}<body name="{seg_of_joint.get(jid, jname + "_link")}" pos="{fmt(placement)}">')
        if jid == 1:
            lines.append(f'{indent}  <freejoint name="{jname}"/>')
        else:
            axis = {"JointModelRX": "1 0 0", "JointModelRY": "0 1 0", "JointModelRZ": "0 0 1"}[joint.shortname()]
            lo, hi = model.lowerPositionLimit[joint.idx_q], model.upperPositionLimit[joint.idx_q]
            lines.append(f'{indent}  <joint name="{jname}" axis="{axis}" range="{lo:.6g} {hi:.6g}"/>')
        inertia = model.inertias[jid]
        if inertia.mass > 0:
            ixx, iyy, izz = (inertia.inertia[i, i] for i in range(3))
            lines.append(f'{indent}  <inertial pos="{fmt(inertia.lever)}" mass="{inertia.mass:.6g}" '
                         f'fullinertia="{ixx:.6g} {iyy:.6g} {izz:.6g} {inertia.inertia[0, 1]:.6g} '
                         f'{inertia.inertia[0, 2]:.6g} {inertia.inertia[1, 2]:.6g}"/>')
        else:
            lines.append(f'{indent}  <inertial pos="0 0 0" mass="1e-6" diaginertia="1e-9 1e-9 1e-9"/>')
        if jid in seg_of_joint:
            g = human.geometry[seg_of_joint[jid]]
            lines.append(f'{indent}  <geom type="capsule" fromto="{fmt(g["from"])} {fmt(g["to"])}" '
                         f'size="{g["radius"]:.4g}" mass="0"/>')
        for mname, xyz in sites.get(jid, []):
            lines.append(f'{indent}  <site name="{mname}" pos="{fmt(xyz)}"/>')
        for child in children.get(jid, []):
            body(child, indent + "  ")
        lines.append(f"{indent}</body>")

    body(1, "    ")
    lines += ["  </worldbody>", "</mujoco>"]
    return "\n".join(lines)
