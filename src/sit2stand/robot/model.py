"""The robot of a profile (:mod:`sit2stand.robot.profile`) as a MuJoCo plant and as the controller's Pinocchio model.

* :class:`PlantConfig` (YAML): robot, chair, seated posture, gains, control rate, sensor noise, and ``unmodeled``:
  what only the simulated plant has (extra rigid masses fixed to links, joint friction, sensor biases, actuator
  delay). Nothing outside :mod:`sit2stand.robot.plant` reads ``unmodeled``.
* :func:`build_spec` makes the MuJoCo spec: free-floating base, torque motors limited to the URDF efforts, a small
  armature, ``jointactuatorfrc`` sensors, 6-axis force/torque at a site on each foot link, a sole box under it, a
  floor and a box chair; only the profile's colliding links (legs, pelvis) touch them.
* :func:`controller_model` is the "CAD" model the controller and the identification start from: the URDF's
  inertias, built by Pinocchio from the MJCF MuJoCo compiles (same joint order as the plant).

Facts and pitfalls: ``../shared/notes/robot-talos.md`` and ``robot-g1.md``.
"""

from __future__ import annotations

import fnmatch
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import mujoco
import numpy as np
import pinocchio as pin
import yaml

from ..data import DataFileNotFound, plant_path
from ..errors import Sit2StandError
from .meshes import shown_rgba
from .mujoco_urdf import urdf_for_mujoco
from .profile import SIDES, RobotProfile, load_profile, profile_of

DEFAULT_ROBOT = "talos"
"""The robot of a plant that names none, and of commands not told ``--robot``: the paper's closest public analog."""
GENERIC_PLANTS = ("default", "cad")
"""Plants every robot has: a profile names its own (``plants``); one that does not gets its robot with nothing
unmodeled for both."""
SEAT_CLEARANCE_BELOW_M = 0.002
"""A chair's top is this far below the lowest seat link of the seated posture (when the plant gives no height)."""


class PlantConfigError(Sit2StandError, ValueError):
    """A plant file that cannot be used; the message names the file and the field."""


def sole_corners_local(profile: RobotProfile, margin_m: float = 0.0) -> np.ndarray:
    """(4, 3) corners of a sole of ``profile``'s robot in the sole frame [m], ``margin_m`` inside its edges."""
    sole = profile.sole
    hx, hy = sole.half_size_m[0] - margin_m, sole.half_size_m[1] - margin_m
    return np.array([[sole.centre_x_m + sx * hx, sy * hy, 0.0] for sx in (-1, 1) for sy in (-1, 1)])


def sole_corners_world(model: pin.Model, data: pin.Data) -> np.ndarray:
    """(8, 3) corners of both soles in the world [m] (left's four, then right's), from ``data``'s frame placements
    (after ``pin.framesForwardKinematics``)."""
    local = sole_corners_local(profile_of(model))
    return np.vstack([[data.oMf[model.getFrameId(f"sole_{side}")].act(c) for c in local] for side in SIDES])


@dataclass
class ExtraBodyMass:
    """A rigid point mass [kg] fixed to ``link`` at ``pos_m`` in the link frame (unmodeled)."""

    link: str
    mass_kg: float
    pos_m: tuple[float, float, float]
    name: str = ""


@dataclass
class Unmodeled:
    masses: list[ExtraBodyMass] = field(default_factory=list)
    viscous_friction: dict[str, float] = field(default_factory=dict)   # joint glob -> N m s/rad
    coulomb_friction: dict[str, float] = field(default_factory=dict)   # joint glob -> N m
    torque_bias_nm: dict[str, float] = field(default_factory=dict)     # joint glob -> N m
    torque_gain: dict[str, float] = field(default_factory=dict)        # joint glob -> measured / true torque
    joint_offset_rad: dict[str, float] = field(default_factory=dict)   # joint glob -> encoder reading - true angle
    ft_force_bias_n: tuple[float, float, float] = (0.0, 0.0, 0.0)      # both F/T sensors, sensor axes
    ft_torque_bias_nm: tuple[float, float, float] = (0.0, 0.0, 0.0)
    ft_bias: dict[str, tuple[float, ...]] = field(default_factory=dict)   # side -> (fx fy fz [N], tx ty tz [N m])
    actuator_delay_s: float = 0.0
    # joint glob -> half the gear's play [rad]: the joint PD's torque has a dead zone of that width (robot.plant)
    backlash_rad: dict[str, float] = field(default_factory=dict)
    # side -> rotation vector [rad]: the F/T sensor mounted turned by it reads the wrench in axes turned so
    ft_rotation_rad: dict[str, tuple[float, float, float]] = field(default_factory=dict)


@dataclass
class PlantConfig:
    """Everything about the simulated robot and its surroundings (see ``sit2stand/data/plants/default.yaml``)."""

    name: str = "default"
    robot: str = DEFAULT_ROBOT           # the robot profile: a packaged profile's name or a file
    timestep_s: float = 0.001
    armature: float = 0.1
    control_rate_hz: float = 1000.0
    feedforward_rate_hz: float = 200.0   # contact-consistent gravity / inverse dynamics refreshed at this rate
    kp_per_effort: float = 10.0          # kp = effort limit / 0.1 rad
    kd_ratio: float = 0.05               # kd = kd_ratio * kp (implicit: no cap needed)
    chair_height_m: float | None = None  # None: 1 cm below the lowest pelvis/thigh point when seated
    chair_front_gap_m: float | None = None   # chair front edge this far behind the heels; None: the profile's
    chair_depth_m: float | None = None       # None: the profile's
    chair_width_m: float | None = None       # None: the profile's
    chair_friction: float = 0.9
    floor_friction: float = 1.0
    seated_posture: dict[str, float] | None = None   # joint glob -> angle [rad]; None: the robot profile's
    joint_torque_noise_nm: float = 0.2
    ft_force_noise_n: float = 0.5
    ft_torque_noise_nm: float = 0.05
    encoder_noise_rad: float = 0.0
    fall_pelvis_height_m: float | None = None        # None: the robot profile's
    fall_tilt_rad: float = 1.3
    seed: int = 0
    unmodeled: Unmodeled = field(default_factory=Unmodeled)
    source: str = ""

    @staticmethod
    def load(path: str | Path | None, robot: str | None = None) -> PlantConfig:
        """Read a plant YAML, a file or a packaged plant's name (``default``; None: the defaults, which carry no
        unmodeled effects).

        ``robot``: the robot profile the plant must be for. A packaged plant's name then means that robot's own
        (``default`` is ``g1_default`` for G1; a profile without one of its own gets its robot with nothing
        unmodeled for ``default`` and ``cad``), a file that names no robot is taken as this robot's, and one that
        names another is refused. None: the plant file's robot (TALOS where it names none).
        """
        own = _robots_own_plant(path, robot) if path is not None else None
        vouched = own is not None and robot is not None and \
            str(path).removesuffix(".yaml") in load_profile(robot).plants
        if own is None:
            return PlantConfig(robot=robot or DEFAULT_ROBOT, name=str(path or "default"))
        try:
            path = plant_path(own)
        except DataFileNotFound as err:
            raise PlantConfigError(str(err)) from None
        try:
            doc = yaml.safe_load(path.read_text()) or {}
        except yaml.YAMLError as err:
            raise PlantConfigError(f"{path}: not valid YAML: {err}") from None
        cfg = PlantConfig(source=str(path))
        known = set(PlantConfig.__dataclass_fields__) - {"unmodeled", "source"}
        for key, value in doc.items():
            if key == "unmodeled":
                continue
            if key not in known:
                raise PlantConfigError(f"{path}: unknown field {key!r} (known: {', '.join(sorted(known))})")
            setattr(cfg, key, value)
        um = doc.get("unmodeled") or {}
        try:
            cfg.unmodeled = Unmodeled(
                masses=[ExtraBodyMass(m["link"], float(m["mass_kg"]), tuple(map(float, m.get("pos_m", (0, 0, 0)))),
                                      m.get("name", f"extra_{i}")) for i, m in enumerate(um.get("masses", []))],
                viscous_friction={k: float(v) for k, v in (um.get("viscous_friction") or {}).items()},
                coulomb_friction={k: float(v) for k, v in (um.get("coulomb_friction") or {}).items()},
                torque_bias_nm={k: float(v) for k, v in (um.get("torque_bias_nm") or {}).items()},
                torque_gain={k: float(v) for k, v in (um.get("torque_gain") or {}).items()},
                joint_offset_rad={k: float(v) for k, v in (um.get("joint_offset_rad") or {}).items()},
                ft_bias={str(k): _six(v, f"ft_bias.{k}") for k, v in (um.get("ft_bias") or {}).items()},
                ft_force_bias_n=tuple(map(float, um.get("ft_force_bias_n", (0, 0, 0)))),
                ft_torque_bias_nm=tuple(map(float, um.get("ft_torque_bias_nm", (0, 0, 0)))),
                actuator_delay_s=float(um.get("actuator_delay_s", 0.0)),
                backlash_rad={k: float(v) for k, v in (um.get("backlash_rad") or {}).items()},
                ft_rotation_rad={str(k): _three(v, f"ft_rotation_rad.{k}")
                                 for k, v in (um.get("ft_rotation_rad") or {}).items()})
        except (KeyError, TypeError, ValueError) as err:
            raise PlantConfigError(f"{path}: unmodeled section: {err!r}") from None
        if vouched:
            cfg.robot = robot            # one of the profile's own plants (its ``plants``): the profile vouches for it
        elif robot is not None:
            _check_robot(cfg, doc, robot, path)
        return cfg

    @property
    def profile(self) -> RobotProfile:
        """The robot's profile (:mod:`sit2stand.robot.profile`)."""
        return load_profile(self.robot)

    @property
    def seated(self) -> dict[str, float]:
        """The seated posture: joint glob -> angle [rad] (the plant file's, else the profile's), in sit2stand's sense
        (both files give the URDF's: :mod:`~sit2stand.robot.conventions`)."""
        if self.seated_posture is None:
            return self.profile.seated_posture
        return self.profile.in_own_sense(self.seated_posture) if self.profile.conventions.changed else \
            self.seated_posture

    def chair(self, dimension: str) -> float:
        """The chair's ``front_gap_m``, ``depth_m`` or ``width_m`` [m]: the plant file's, else the profile's."""
        value = getattr(self, f"chair_{dimension}")
        return float(value) if value is not None else float(self.profile.chair[dimension])

    @property
    def fall_height_m(self) -> float:
        """A pelvis lower than this [m] has fallen (the plant file's, else the profile's)."""
        return self.fall_pelvis_height_m if self.fall_pelvis_height_m is not None else \
            self.profile.fall_pelvis_height_m

    def total_extra_mass(self) -> float:
        """Sum of the unmodeled extra masses [kg]."""
        return sum(m.mass_kg for m in self.unmodeled.masses)


def _robots_own_plant(name_or_path: str | Path, robot: str | None) -> str | Path | None:
    """A packaged plant's name for ``robot``: the profile's own plant of that name (its ``plants``), else the name;
    None for ``default`` or ``cad`` when the profile has none of its own (the robot with nothing unmodeled)."""
    name = str(name_or_path)
    if robot is None or Path(name).name != name:
        return name_or_path
    profile = load_profile(robot)
    if name.removesuffix(".yaml") in profile.plants:
        return profile.plants[name.removesuffix(".yaml")]
    return None if name.removesuffix(".yaml") in GENERIC_PLANTS else name_or_path


def _check_robot(cfg: PlantConfig, doc: dict, robot: str, path: Path) -> None:
    """Refuse a plant file written for another robot than ``robot``; one that names none is ``robot``'s."""
    if "robot" not in doc:
        cfg.robot = robot
        return
    want, have = load_profile(robot), cfg.profile
    if want.name != have.name:
        raise PlantConfigError(f"{path}: field 'robot': this plant is for {have.name}, not {want.name} (pass a "
                               f"plant of {want.name}, or --robot {have.name})")


def _six(values, what: str) -> tuple[float, ...]:
    """Six floats (a wrench: force [N], torque [N m]); ValueError naming ``what`` otherwise."""
    out = tuple(float(v) for v in values)
    if len(out) != 6:
        raise ValueError(f"{what}: needs 6 values (fx fy fz [N], tx ty tz [N m]), got {len(out)}")
    return out


def _three(values, what: str) -> tuple[float, float, float]:
    """Three floats (a rotation vector [rad]); ValueError naming ``what`` otherwise."""
    out = tuple(float(v) for v in values)
    if len(out) != 3:
        raise ValueError(f"{what}: needs 3 values (a rotation vector x y z [rad]), got {len(out)}")
    return out


def expand(pattern_values: dict[str, float], joint_names: list[str]) -> dict[str, float]:
    """Joint-name globs (``*_knee_joint``) to per-joint values; later patterns win."""
    out: dict[str, float] = {}
    for pattern, value in pattern_values.items():
        matches = fnmatch.filter(joint_names, pattern)
        if not matches:
            raise PlantConfigError(f"pattern {pattern!r} matches no joint")
        for name in matches:
            out[name] = float(value)
    return out


def build_spec(cfg: PlantConfig, *, plant: bool) -> mujoco.MjSpec:
    """MuJoCo spec of the robot on its floor with the chair; ``plant=True`` adds the ``unmodeled`` masses and
    friction (the simulated truth), ``plant=False`` gives the CAD robot."""
    profile = cfg.profile
    spec = mujoco.MjSpec.from_string(urdf_for_mujoco(profile))
    spec.modelname = profile.name
    spec.option.timestep = cfg.timestep_s
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    # elliptic friction cones with a high impedance ratio: with MuJoCo's default pyramidal cones and impratio 1 the
    # soft contacts let the loaded seat creep backward 2-4 mm/s under the legs' push (measured: 6 cm in 10 s)
    spec.option.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
    spec.option.impratio = 10.0
    root = spec.worldbody.first_body()
    if root.name != profile.root_link:
        raise PlantConfigError(f"{profile.source}: field 'root_link': {profile.root_link!r}, but the URDF's root "
                               f"link is {root.name!r}")
    root.add_freejoint(name="root")
    names = _add_joint_actuators(spec, cfg)
    _add_soles(spec, profile)
    root.add_site(name="pelvis", pos=[0, 0, 0])
    _add_contacts_and_floor(spec, cfg, profile)
    for geom in spec.geoms:                # drawing only: a black mesh vanishes in the rendered frames
        if geom.type == mujoco.mjtGeom.mjGEOM_MESH:
            geom.rgba = shown_rgba(geom.rgba)
    if plant:
        _add_unmodeled(spec, cfg, names)
    return spec


def _add_joint_actuators(spec: mujoco.MjSpec, cfg: PlantConfig) -> list[str]:
    """Per joint: armature, no friction, a PD position servo, a torque motor [N m] and a torque sensor; the names."""
    joints = [j for j in spec.joints if j.type != mujoco.mjtJoint.mjJNT_FREE]
    for j in joints:
        j.armature = cfg.armature
        j.damping = [0.0, 0.0, 0.0]                  # friction is an unmodeled effect, given below for the plant
        j.frictionloss = 0.0
        effort = float(j.actfrcrange[1]) if j.actfrcrange[1] > 0 else 100.0
        j.actfrcrange = [-effort, effort]             # the joint's total actuator torque is clamped here
        kp = cfg.kp_per_effort * effort
        kd = cfg.kd_ratio * kp
        # joint PD as a position servo, so that MuJoCo integrates its damping implicitly (explicit PD at 1 kHz
        # must cap kd and leaves the whole-body sway on the feet lightly damped); ctrl = q_ref + kd/kp qd_ref
        pd = spec.add_actuator(name=j.name, target=j.name, trntype=mujoco.mjtTrn.mjTRN_JOINT)
        pd.gaintype = mujoco.mjtGain.mjGAIN_FIXED
        pd.gainprm[0] = kp
        pd.biastype = mujoco.mjtBias.mjBIAS_AFFINE
        pd.biasprm[0], pd.biasprm[1], pd.biasprm[2] = 0.0, -kp, -kd
        pd.ctrllimited = False
        ff = spec.add_actuator(name=f"ff_{j.name}", target=j.name, trntype=mujoco.mjtTrn.mjTRN_JOINT)
        ff.set_to_motor()
        ff.ctrllimited = True
        ff.ctrlrange = [-effort, effort]
        spec.add_sensor(name=f"tau_{j.name}", type=mujoco.mjtSensor.mjSENS_JOINTACTFRC,
                        objtype=mujoco.mjtObj.mjOBJ_JOINT, objname=j.name)
    return [j.name for j in joints]


def _add_soles(spec: mujoco.MjSpec, profile: RobotProfile) -> None:
    """Per foot: the sole box that makes contact, the F/T and sole sites, and the force [N] and torque [N m] sensors
    (the F/T site at the foot link's origin: a site on a link without contact geometry reads nothing)."""
    sole = profile.sole
    for side in SIDES:
        body = spec.body(profile.foot_links[side])
        if body is None:
            raise PlantConfigError(f"{profile.source}: field 'foot_link': {profile.foot_links[side]!r} is not a link "
                                   f"of {profile.urdf.name}")
        for geom in body.geoms:            # the foot mesh stays for drawing; the sole box does the contact
            geom.contype, geom.conaffinity = 0, 0
        box = body.add_geom(name=f"sole_box_{side}", type=mujoco.mjtGeom.mjGEOM_BOX, size=list(sole.half_size_m),
                            pos=[sole.centre_x_m, 0, -sole.below_foot_m + sole.half_size_m[2]],
                            rgba=[0.3, 0.3, 0.3, 1], mass=0.0)
        box.group = 3
        body.add_site(name=f"ft_{side}", pos=[0, 0, 0])
        body.add_site(name=f"sole_{side}", pos=[0, 0, -sole.below_foot_m])
        spec.add_sensor(name=f"force_{side}", type=mujoco.mjtSensor.mjSENS_FORCE,
                        objtype=mujoco.mjtObj.mjOBJ_SITE, objname=f"ft_{side}")
        spec.add_sensor(name=f"torque_{side}", type=mujoco.mjtSensor.mjSENS_TORQUE,
                        objtype=mujoco.mjtObj.mjOBJ_SITE, objname=f"ft_{side}")


def _add_contacts_and_floor(spec: mujoco.MjSpec, cfg: PlantConfig, profile: RobotProfile) -> None:
    """Which robot geoms collide (with the environment only: the profile's colliding links, the feet by their sole
    boxes alone), their friction, and the floor plane."""
    feet = set(profile.foot_links.values())
    for geom in spec.geoms:
        body_name = geom.parent.name if hasattr(geom.parent, "name") else ""
        collide = profile.matches(profile.colliding_links, body_name) and \
            (body_name not in feet or geom.name.startswith("sole_box"))
        # robot geoms (bit 1) touch only the environment (bit 2): no self-collision in deep hip flexion
        geom.contype, geom.conaffinity = (1, 2) if collide else (0, 0)
        geom.friction = [cfg.floor_friction, 0.005, 0.0001]
    floor = spec.worldbody.add_geom(name="floor", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[5, 5, 0.1],
                                    rgba=[0.8, 0.8, 0.8, 1])
    floor.contype, floor.conaffinity = 2, 1
    floor.friction = [cfg.floor_friction, 0.005, 0.0001]


def _add_unmodeled(spec: mujoco.MjSpec, cfg: PlantConfig, names: list[str]) -> None:
    """The plant's unmodeled effects: extra point masses [kg], viscous [N m s/rad] and Coulomb [N m] friction."""
    um = cfg.unmodeled
    for extra in um.masses:
        try:
            parent = spec.body(extra.link)
        except Exception:  # noqa: BLE001 - mujoco raises a generic error for a missing name
            parent = None
        if parent is None:
            raise PlantConfigError(f"{cfg.source or 'plant'}: unmodeled mass on unknown link {extra.link!r}")
        b = parent.add_body(name=extra.name or f"extra_{extra.link}", pos=list(extra.pos_m))
        b.mass = extra.mass_kg
        b.ipos = [0.0, 0.0, 0.0]         # the mass sits at the body's origin (MjSpec copies pos into ipos)
        b.inertia = [1e-4 * extra.mass_kg] * 3
        b.explicitinertial = True
    for name, value in expand(um.viscous_friction, names).items():
        spec.joint(name).damping = [value, 0.0, 0.0]
    for name, value in expand(um.coulomb_friction, names).items():
        spec.joint(name).frictionloss = value


COMPILED_CACHE_SIZE = 8
"""Compiled robots kept per process (:func:`compiled_robot`): a batch worker runs case after case on one robot."""
_compiled: dict[tuple, tuple[mujoco.MjModel, str]] = {}


def compiled_robot(cfg: PlantConfig, *, plant: bool) -> tuple[mujoco.MjModel, str]:
    """:func:`build_spec` compiled, without the chair, and its MJCF text; kept for the next call with an equal
    ``cfg`` (its fields, the profile's URDF and that file's time stamp). Treat both as read-only.

    A compile costs 35-70 ms and the MJCF text as much again; a simulated case asks for them four times, and a batch
    worker for each of its cases."""
    urdf = cfg.profile.urdf
    key = (repr(cfg), plant, str(urdf), urdf.stat().st_mtime_ns)
    if key not in _compiled:
        spec = build_spec(cfg, plant=plant)
        model = spec.compile()
        if len(_compiled) >= COMPILED_CACHE_SIZE:
            _compiled.pop(next(iter(_compiled)))
        _compiled[key] = (model, spec.to_xml())
    return _compiled[key]


def add_chair(spec: mujoco.MjSpec, cfg: PlantConfig, seat_top_z: float, front_x: float) -> None:
    """A box chair whose seat top is at ``seat_top_z`` and front edge at ``front_x`` (lab x)."""
    half = [cfg.chair("depth_m") / 2, cfg.chair("width_m") / 2, seat_top_z / 2]
    chair = spec.worldbody.add_body(name="chair", pos=[front_x - half[0], 0.0, half[2]])
    g = chair.add_geom(name="chair_seat", type=mujoco.mjtGeom.mjGEOM_BOX, size=half, rgba=[0.55, 0.35, 0.2, 1])
    g.contype, g.conaffinity = 2, 1
    g.friction = [cfg.chair_friction, 0.005, 0.0001]


def controller_model(cfg: PlantConfig | None = None, link_parameters: dict | None = None):
    """The controller's Pinocchio model of the robot: the URDF ("CAD") inertias, or the identified
    ``link_parameters`` (:func:`apply_link_parameters`), in the plant's joint order.

    Built from the MJCF that MuJoCo compiles from the same spec (without chair, floor or unmodeled effects);
    Pinocchio's free-flyer quaternion is (x, y, z, w), MuJoCo's (w, x, y, z).
    """
    cfg = cfg or PlantConfig()
    profile = cfg.profile
    _, xml = compiled_robot(cfg, plant=False)
    # Pinocchio's MJCF parser reads a file; sensors/actuators/floor are irrelevant to it
    with tempfile.NamedTemporaryFile("w", suffix=".xml", delete=False) as f:
        f.write(xml)
        path = f.name
    try:
        model = pin.buildModelFromMJCF(path)
    finally:
        Path(path).unlink(missing_ok=True)
    model.name = profile.name               # profile_of(model) finds the profile by it
    for side in SIDES:
        _place_foot_frames(model, profile, side)
    if link_parameters:
        apply_link_parameters(model, link_parameters)
    return model


def _place_foot_frames(model: pin.Model, profile: RobotProfile, side: str) -> None:
    """The ``sole_{side}`` and ``ft_{side}`` frames on the foot link's frame, as the plant's sites are: the ankle's
    own (TALOS, G1) or one welded below it (iCub's sole frame). The MJCF's sites come in as frames already, but
    Pinocchio 4.0's MJCF parser put the sites of iCub's welded sole body 5.5 cm from where MuJoCo has them: where it
    differs, the site frame is put where its body says."""
    foot = model.frames[model.getFrameId(profile.foot_links[side], pin.FrameType.BODY)]
    below = pin.SE3(np.eye(3), np.array([0.0, 0.0, -profile.sole.below_foot_m]))
    for name, placement in ((f"sole_{side}", foot.placement * below), (f"ft_{side}", foot.placement)):
        if not model.existFrame(name):
            model.addFrame(pin.Frame(name, foot.parentJoint, placement, pin.FrameType.OP_FRAME))
            continue
        frame = model.frames[model.getFrameId(name)]
        if frame.parentJoint != foot.parentJoint or not frame.placement.isApprox(placement, 1e-9):
            frame.parentJoint, frame.placement = foot.parentJoint, placement


def add_seat_frame(model, seat_top_z_m: float, base_z_m: float) -> int:
    """Add the frame ``seat`` on the pelvis where a seat of top height ``seat_top_z_m`` supports it when the base is
    at height ``base_z_m`` (upright), ``seat_point_x_m`` along the base's x (the robot profile's); returns its id.
    A robot whose trunk only turns leans with its pelvis, about its hips: the seat holds the hips' axis (see
    :func:`hips_axis_in_base`)."""
    point = hips_axis_in_base(model) if profile_of(model).trunk_pitch is None else \
        np.array([profile_of(model).seat_point_x_m, 0.0, seat_top_z_m - base_z_m])
    return model.addFrame(pin.Frame("seat", 1, pin.SE3(np.eye(3), point), pin.FrameType.OP_FRAME))


def held_on_seat_b(model) -> np.ndarray:
    """The point of the base [m, base frame] a seated plan holds still: its origin, or the seat frame's (the hips'
    axis: :func:`hips_axis_in_base`) on a robot whose trunk only turns."""
    return model.frames[model.getFrameId("seat")].placement.translation.copy() \
        if profile_of(model).trunk_pitch is None else np.zeros(3)


def hips_axis_in_base(model) -> np.ndarray:
    """The midpoint of the hip pitch joints in the base frame (x, 0, z) [m]: where a robot whose trunk only turns
    (Romeo, Unitree H1, G1's 23-DoF waist) is held on its seat. Its thighs rest on the seat, so while it leans its
    pelvis forward (the trunk's lean, by the hips), the hips' axis stays where it is; held at the base's origin
    instead (Romeo's is 20 cm above its hips) the lean swings the hips back and off the seat: not 2 cm of it had a
    solution, and the robot fell back; held at a point on the seat's surface, the
    whole-body controller's seat contact fought the lean (the simulated COM 6 cm short at seat-off)."""
    data = model.createData()
    pin.forwardKinematics(model, data, pin.neutral(model))      # the base at the origin, upright
    hips = [data.oMi[model.getJointId(profile_of(model).leg(side, "hip_pitch"))].translation for side in SIDES]
    return np.mean(hips, axis=0) * [1.0, 0.0, 1.0]


def actuated_joint_names(model) -> list[str]:
    """Names of the actuated joints of a Pinocchio model (all but the universe and the free flyer)."""
    return list(model.names[2:])


def apply_link_parameters(model, params: dict) -> None:
    """Set link masses [kg] and COMs [m, link frame] of a Pinocchio model from ``{link_joint: {mass, com}}``
    (``sit2stand identify --model full``'s ``links``, :func:`sit2stand.robot.identify.read_link_parameters`): the
    one way identified parameters enter a model. Rotational inertias scale with the mass.

    Raises:
        PlantConfigError: the parameters name joints the model lacks (identified on another robot).
    """
    foreign = [j for j in params if not model.existJointName(j)]
    if foreign:
        raise PlantConfigError(f"identified parameters of joints {', '.join(foreign[:4])}"
                               f"{' ...' if len(foreign) > 4 else ''}, which {model.name or 'the robot'} does not "
                               f"have: they were identified on another robot")
    for joint, p in params.items():
        jid = model.getJointId(joint)
        old = model.inertias[jid]
        mass = float(p["mass"])
        com = np.asarray(p.get("com", old.lever), float)
        scale = mass / old.mass if old.mass > 0 else 1.0
        model.inertias[jid] = pin.Inertia(mass, com, old.inertia * scale)
