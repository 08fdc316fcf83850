"""The robot as the retargeter knows it: its kinematics with the COM parameters to use, and its seated start.

:func:`robot_model` builds the model from a robot profile, a plant file (only its posture and chair, never
``unmodeled``) and identified parameters; :func:`robot_setup` adds the soles, the support polygon and the leg's
measures the COM map and the marker calibration need.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin

from ..dynamics import G
from ..errors import InputError
from ..robot.identify import read_link_parameters
from ..robot.model import SIDES, PlantConfig, add_seat_frame, compiled_robot, controller_model, sole_corners_world
from ..robot.plant import seat_top_height, seated_configuration
from ..robot.profile import profile_of
from ..vectors import xyzw_from_wxyz
from .feasibility import support_polygon


@dataclass
class RobotSetup:
    """The robot as the retargeter knows it: kinematics with the COM parameters to use, and its seated start."""

    model: pin.Model
    joint_names: list[str]
    q_seated: np.ndarray                 # Pinocchio configuration (free flyer x y z qx qy qz qw + joints)
    sole_frames: list[int]
    sole_targets: list[pin.SE3]
    support_xy: np.ndarray               # support polygon of both soles (counter-clockwise), within the ankles' reach
    heel_x_m: float                      # the support's rear and front world x [m] (:func:`_ankles_reach_x`)
    toe_x_m: float
    ankle_left: np.ndarray               # left ankle projected on the floor [m]
    leg_length_m: float                  # hip joint -> knee -> ankle
    ankle_height_m: float                # the ankle joint's height above the sole [m]
    parameters: str                      # "CAD" or the identified YAML


def robot_model(plant_yaml: str | Path | None = None, params_yaml: str | Path | None = None,
                link_parameters: dict | None = None, robot: str | None = None) -> tuple[pin.Model, np.ndarray, str]:
    """The retargeter's robot model (``robot``'s profile, or the plant file's; with the identified COM parameters of
    ``params_yaml``, ``sit2stand identify --model full`` output, or CAD's), its nominal seated configuration from
    the plant file (Pinocchio order; only the posture and chair, never ``unmodeled``), and the parameters' label.
    The slow part of :func:`robot_setup` (~0.6 s): a node builds it before the stream starts. ``link_parameters``:
    those of ``params_yaml`` when the caller has read them already."""

    cfg = PlantConfig.load(plant_yaml, robot)
    links = link_parameters or (read_link_parameters(params_yaml) if params_yaml else None)
    model = controller_model(cfg, links)
    label = str(params_yaml) if params_yaml else "CAD"
    probe, _ = compiled_robot(cfg, plant=False)
    qpos = seated_configuration(probe, cfg)
    add_seat_frame(model, seat_top_height(probe, qpos, cfg), float(qpos[2]))
    q = qpos.copy()
    q[3:7] = xyzw_from_wxyz(qpos[3:7])
    return model, q, label


def robot_setup(plant_yaml: str | Path | None = None, params_yaml: str | Path | None = None,
                q_start: np.ndarray | None = None, start_joint_names: list[str] | None = None,
                prebuilt: tuple[pin.Model, np.ndarray, str] | None = None, robot: str | None = None) -> RobotSetup:
    """The robot (``robot``'s profile, or the plant file's) seated as in the plant file, with the identified COM
    parameters of ``params_yaml`` or the CAD ones (see :func:`robot_model`; ``prebuilt``: its result, made earlier).
    ``q_start``: the robot's measured seated configuration (Pinocchio order), as the paper calibrates on the robot's
    measured sitting posture; default: the plant file's nominal one. ``start_joint_names``: the joint of each of
    ``q_start[7:]`` when they come in another order (e.g. a JointState's)."""

    model, prebuilt_q, label = prebuilt if prebuilt is not None else robot_model(plant_yaml, params_yaml, robot=robot)
    q = prebuilt_q.copy()
    if q_start is not None:
        if np.shape(q_start) != q.shape or not np.all(np.isfinite(q_start)):
            raise InputError(f"start configuration: {np.shape(q_start)} values (finite), expected {q.shape}")
        q = np.asarray(q_start, float).copy()
        if start_joint_names is not None:
            by_name = dict(zip(start_joint_names, q_start[7:]))
            missing = [n for n in model.names[2:] if n not in by_name]
            if missing:
                raise InputError(f"start configuration: no position for {', '.join(missing[:5])}")
            q[7:] = [by_name[n] for n in model.names[2:]]
    data = model.createData()
    profile = profile_of(model)
    soles = [model.getFrameId(f"sole_{s}") for s in SIDES]
    pin.framesForwardKinematics(model, data, _lateral_as_nominal(model, q, prebuilt_q, profile))
    targets = [data.oMf[f].copy() for f in soles]
    pin.framesForwardKinematics(model, data, q)
    corners = sole_corners_world(model, data)[:, :2]
    for side, (lo, hi) in enumerate(_ankles_reach_x(model, data, profile)):     # the corners: left's four, right's
        corners[4 * side:4 * side + 4, 0] = np.clip(corners[4 * side:4 * side + 4, 0], lo, hi)
    hip, knee, ankle = (data.oMi[model.getJointId(joint)].translation
                        for joint in (profile.leg("left", "hip_pitch"), profile.leg("left", "knee"),
                                      profile.foot_joint("left")))
    ankle_floor = targets[0].translation.copy()
    return RobotSetup(model, list(model.names[2:]), q, soles, targets, support_polygon(corners),
                      float(corners[:, 0].min()), float(corners[:, 0].max()), ankle_floor,
                      float(np.linalg.norm(knee - hip) + np.linalg.norm(ankle - knee)),
                      float(ankle[2] - ankle_floor[2]), label)


def _lateral_as_nominal(model: pin.Model, q: np.ndarray, q_nominal: np.ndarray, profile) -> np.ndarray:
    """``q`` for the soles' targets: as measured, but for legs without an ankle roll
    (:attr:`~sit2stand.robot.profile.RobotProfile.redundant_sole_contacts`) with the lateral joints at the nominal
    seated pose's (``q_nominal``: the plant file's, or the profile's). Straight, such legs put their flat soles
    exactly as far apart as their hips: a hip yaw of 0.6 mrad, as H1 settles on its chair, put its seated feet 0.24 mm
    wider, and the IK had no solution for any frame once the knees straightened (191 of the natural rise's 391)."""
    if not profile.redundant_sole_contacts:
        return q
    out = q.copy()
    for name in profile.lateral_joints():
        if model.existJointName(name):
            i = model.joints[model.getJointId(name)].idx_q
            out[i] = q_nominal[i]
    return out


def _ankles_reach_x(model: pin.Model, data: pin.Data, profile) -> list[tuple[float, float]]:
    """Per side (:data:`SIDES`), the forward extent [m] (world x, at the placements in ``data``) within which the
    ankle's pitch motor can hold the centre of pressure with half the robot's weight on the foot: the ankle's x -+ its
    torque limit (the model's: :func:`~sit2stand.robot.model.controller_model` gives a joint whose file has none
    100 N m, as the plant) over that load. Where it is shorter than the sole (H1's 40 N m ankles reach 13.7 cm ahead
    of them, its soles 18 cm; Romeo's 13 of 14.8), the COM map's seat-off and its cap ahead come from it: held at its
    toes' 18 cm, H1 fell back on the natural rise."""
    load_n = float(pin.computeTotalMass(model)) * G / 2.0
    reach = []
    for side in SIDES:
        joint = model.getJointId(profile.leg(side, "ankle_pitch"))
        x = float(data.oMi[joint].translation[0])
        arm = float(model.effortLimit[model.joints[joint].idx_v]) / load_n
        reach.append((x - arm, x + arm))
    return reach
