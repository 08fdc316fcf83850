"""``sit2stand export``: a simulated stand-up as a motion file that humanoid learning pipelines read.

Input: a ``sit2stand retarget --simulate`` output folder (its ``robot`` bag: the simulated robot's sensed state once
per frame) or a stand-up graph's bag (the driver's ``/robot/joint_states`` and ``/robot/base_pose``, 500 Hz). The
robot is the packaged profile whose actuated joints the states name (``robot``: a profile to use instead).

* **CSV**: one row per frame at ``rate_hz``, no header: root position x y z [m] (world), root orientation as a unit
  quaternion x y z w, then the joint positions [rad] in the profile's actuated order (the model's: MuJoCo's and
  Pinocchio's). This is the layout of the retargeted LAFAN1 motions (Unitree's release for G1, H1 and H1-2) that
  motion-tracking pipelines convert to their own files.
* **NPZ** (``numpy.load``): ``fps``, ``joint_names``, ``root_pos`` (N, 3), ``root_quat_xyzw`` (N, 4), ``dof_pos``
  and ``dof_vel`` (N, n) [rad, rad/s], ``body_names``, ``body_pos`` (N, B, 3) [m, world], ``foot_contacts`` (N, 2:
  left, right; a sole carrying more than ``CONTACT_FORCE_N``), ``com`` (N, 3) [m] (the model's COM, CAD inertias).

Both are in the robot's URDF file's own frames and joint senses, the file a pipeline loads: a robot whose file
sit2stand reads turned or with joints reversed (iCub's: :mod:`~sit2stand.robot.conventions`) has its root
orientation turned back and those joints negated.

Frames are at ``t0 + k / rate_hz`` for the ``round(span * rate_hz)`` instants the states cover (``span``: the first
to the last state plus one state period). An instant that falls on a state takes it exactly; others interpolate
linearly (the quaternion normalised).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import pinocchio as pin

from ..errors import InputError
from ..io.bag import BagReader
from ..io.messages import stamp_ns
from ..io.topics import ROBOT_BASE_POSE_TOPIC, ROBOT_JOINT_STATES_TOPIC, ft_topic
from ..robot.conventions import Conventions
from ..robot.model import SIDES, PlantConfig, actuated_joint_names, controller_model
from ..robot.profile import RobotProfile, load_profile, packaged_names

FORMATS = ("csv", "npz")
CONTACT_FORCE_N = 20.0
"""A sole is in contact while its ground reaction's vertical force exceeds this [N]."""
EXACT_S = 1e-6


@dataclass
class StateSeries:
    """A robot's sensed states over time (world frame): stamps [s], base pose, joints, feet's vertical forces."""

    t_s: np.ndarray                 # (N,)
    root_pos: np.ndarray            # (N, 3) [m]
    root_quat_xyzw: np.ndarray      # (N, 4)
    joint_names: list[str]
    q: np.ndarray                   # (N, n) [rad]
    qd: np.ndarray | None           # (N, n) [rad/s], when the states carry velocities
    feet_fz: np.ndarray | None      # (N, 2) [N]: left, right


def read_states(run: Path) -> StateSeries:
    """The robot's states of ``run`` (a ``retarget --simulate`` folder or a stand-up bag).

    Raises:
        InputError: no robot states there (naming the bag and the topic).
    """
    bag_path = run / "robot" if (run / "robot" / "metadata.yaml").exists() else run
    with BagReader(bag_path) as bag:
        topics = bag.topics()
        for needed in (ROBOT_JOINT_STATES_TOPIC, ROBOT_BASE_POSE_TOPIC):
            if needed not in topics:
                raise InputError(f"{bag_path}: no {needed}: not a simulated stand-up (a retarget --simulate folder "
                                 f"or a stand-up bag)")
        js, base = bag.read(ROBOT_JOINT_STATES_TOPIC), bag.read(ROBOT_BASE_POSE_TOPIC)
        feet = [bag.read(ft_topic(s)) if ft_topic(s) in topics else [] for s in SIDES]
    t = np.array([stamp_ns(m.header) for _, m in js]) * 1e-9
    tb = np.array([stamp_ns(m.header) for _, m in base]) * 1e-9
    pose = np.array([[m.pose.position.x, m.pose.position.y, m.pose.position.z, m.pose.orientation.x,
                      m.pose.orientation.y, m.pose.orientation.z, m.pose.orientation.w] for _, m in base])
    at = np.clip(np.searchsorted(tb, t - EXACT_S), 0, len(tb) - 1)       # the base pose stamped with each state
    q = np.array([m.position for _, m in js], float)
    qd = np.array([m.velocity for _, m in js], float) if len(js[0][1].velocity) else None
    fz = None
    if all(feet):
        fz = np.column_stack([np.interp(t, np.array([stamp_ns(m.header) for _, m in f]) * 1e-9,
                                        [m.wrench.force.z for _, m in f]) for f in feet])
    return StateSeries(t, pose[at, :3], pose[at, 3:], list(js[0][1].name), q, qd, fz)


def robot_of(names: list[str], robot: str | None = None) -> RobotProfile:
    """The profile ``robot``, or the packaged one whose actuated joints are exactly ``names``."""
    if robot is not None:
        return load_profile(robot)
    for name in packaged_names():
        if load_profile(name).moving_joints() == set(names):
            return load_profile(name)
    raise InputError(f"no packaged robot profile has the joints {', '.join(names[:4])} ...: pass --robot FILE")


def resample(states: StateSeries, rate_hz: float) -> tuple[np.ndarray, StateSeries]:
    """The states at ``rate_hz`` (see the module docstring): (frame times [s], states at them)."""
    if not rate_hz > 0:
        raise InputError(f"--rate {rate_hz!r}: a frame rate above 0 Hz")
    t = states.t_s
    period = float(np.median(np.diff(t))) if len(t) > 1 else 1.0 / rate_hz
    n = int(round((t[-1] - t[0] + period) * rate_hz))
    times = t[0] + np.arange(n) / rate_hz
    times = times[times <= t[-1] + EXACT_S]
    lerp = lambda x: None if x is None else np.column_stack(  # noqa: E731
        [np.interp(times, t, x[:, i]) for i in range(x.shape[1])])
    quat = lerp(states.root_quat_xyzw)
    quat /= np.linalg.norm(quat, axis=1, keepdims=True)
    out = StateSeries(times, lerp(states.root_pos), quat, states.joint_names, lerp(states.q), lerp(states.qd),
                      lerp(states.feet_fz))
    exact = np.abs(t[np.clip(np.searchsorted(t, times - EXACT_S), 0, len(t) - 1)] - times) < EXACT_S
    k = np.clip(np.searchsorted(t, times[exact] - EXACT_S), 0, len(t) - 1)
    out.root_pos[exact], out.root_quat_xyzw[exact], out.q[exact] = states.root_pos[k], states.root_quat_xyzw[k], \
        states.q[k]
    return times, out


def in_model_order(states: StateSeries, profile: RobotProfile) -> tuple[pin.Model, StateSeries]:
    """The profile's controller model and the states' joints in its actuated order."""
    model = controller_model(PlantConfig(robot=profile.name))       # a loaded profile is found by its name
    order = actuated_joint_names(model)
    missing = [n for n in order if n not in states.joint_names]
    if missing:
        raise InputError(f"the states lack joints of {profile.name}: {', '.join(missing[:4])}")
    idx = [states.joint_names.index(n) for n in order]
    pick = lambda x: None if x is None else x[:, idx]  # noqa: E731
    return model, StateSeries(states.t_s, states.root_pos, states.root_quat_xyzw, order, states.q[:, idx],
                              pick(states.qd), states.feet_fz)


def in_file_sense(states: StateSeries, conventions: Conventions) -> StateSeries:
    """``states`` in the URDF file's own base frame and joint senses (sit2stand's turned back)."""
    if not conventions.changed:
        return states
    sign = np.array([-1.0 if n in conventions.flipped else 1.0 for n in states.joint_names])
    turn = pin.Quaternion(pin.utils.rpyToMatrix(0.0, 0.0, conventions.base_yaw_rad))
    quat = np.array([(pin.Quaternion(np.asarray(x)) * turn).coeffs() for x in states.root_quat_xyzw])
    return replace(states, root_quat_xyzw=quat, q=states.q * sign, qd=None if states.qd is None else states.qd * sign)


def write_csv(states: StateSeries, path: Path) -> int:
    """The CSV rows (see the module docstring), every number to full precision; the row count."""
    rows = np.hstack([states.root_pos, states.root_quat_xyzw, states.q])
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savetxt(path, rows, delimiter=",", fmt="%.17g")
    return len(rows)


def write_npz(states: StateSeries, model: pin.Model, rate_hz: float, path: Path,
              conventions: Conventions | None = None) -> int:
    """The NPZ arrays (see the module docstring; ``states`` in sit2stand's conventions, written in the file's); the
    frame count."""
    data = model.createData()
    bodies = [f for f in range(model.nframes) if model.frames[f].type == pin.FrameType.BODY and f > 0]
    body_pos = np.empty((len(states.t_s), len(bodies), 3))
    com = np.empty((len(states.t_s), 3))
    for k in range(len(states.t_s)):
        x = np.concatenate([states.root_pos[k], states.root_quat_xyzw[k], states.q[k]])
        pin.framesForwardKinematics(model, data, x)
        body_pos[k] = [data.oMf[f].translation for f in bodies]
        com[k] = pin.centerOfMass(model, data, x)
    if states.qd is None:
        states = replace(states, qd=np.gradient(states.q, states.t_s, axis=0))
    states = in_file_sense(states, conventions or Conventions())
    contacts = states.feet_fz > CONTACT_FORCE_N if states.feet_fz is not None else \
        np.zeros((len(states.t_s), 2), bool)
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez(path, fps=float(rate_hz), joint_names=np.array(states.joint_names), root_pos=states.root_pos,
             root_quat_xyzw=states.root_quat_xyzw, dof_pos=states.q, dof_vel=states.qd,
             body_names=np.array([model.frames[f].name for f in bodies]), body_pos=body_pos,
             foot_contacts=contacts, com=com)
    return len(states.t_s)


def export(run: Path, out: Path, fmt: str = "csv", rate_hz: float = 50.0, robot: str | None = None) -> dict:
    """``sit2stand export``: write ``run``'s motion to ``out`` as ``fmt``; what was written."""
    if fmt not in FORMATS:
        raise InputError(f"--format {fmt!r}: one of {', '.join(FORMATS)}")
    states = read_states(run)
    profile = robot_of(states.joint_names, robot)
    model, ordered = in_model_order(states, profile)
    _, frames = resample(ordered, rate_hz)
    n = write_csv(in_file_sense(frames, profile.conventions), out) if fmt == "csv" else \
        write_npz(frames, model, rate_hz, out, profile.conventions)
    return {"robot": profile.name, "frames": n, "rate_hz": rate_hz, "duration_s": n / rate_hz,
            "joints": len(frames.joint_names), "out": str(out)}
