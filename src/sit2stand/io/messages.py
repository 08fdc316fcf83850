"""Build our bag messages (rosbags objects) from arrays, and read arrays back out of them.

Topic names, types and frame ids are in :mod:`sit2stand.io.topics`.
"""

from __future__ import annotations

import struct
from collections.abc import Iterator
from typing import Any

import numpy as np

from .topics import (COM_TYPE, LAB_FRAME, MOCAP_TYPE, PLATE_TYPE, ROBOT_BASE_POSE_TOPIC, ROBOT_COP_TOPIC,
                     ROBOT_FT_LEFT_TOPIC, ROBOT_FT_RIGHT_TOPIC, ROBOT_JOINT_STATES_TOPIC, SUBJECT_TYPE, WORLD_FRAME,
                     ft_topic, sole_world_aligned_frame)
from ..forceplate import PlateSeries
from .typestore import typestore



def stamp(t_ns: int) -> Any:
    """builtin_interfaces/Time of an integer time in ns."""
    t = typestore().types["builtin_interfaces/msg/Time"]
    t_ns = int(t_ns)
    return t(sec=t_ns // 1_000_000_000, nanosec=t_ns % 1_000_000_000)


def header(t_ns: int, frame_id: str = LAB_FRAME) -> Any:
    return typestore().types["std_msgs/msg/Header"](stamp=stamp(t_ns), frame_id=frame_id)


def stamp_ns(msg_header: Any) -> int:
    """ns of a message header's stamp (rosbags or rclpy object)."""
    return int(msg_header.stamp.sec) * 1_000_000_000 + int(msg_header.stamp.nanosec)


def cdr_header_stamp_ns(data: bytes | memoryview) -> int:
    """ns of the header stamp of a serialized (CDR, little or big endian) message whose first field is a
    std_msgs/Header: read from the raw bytes, without deserializing."""
    fmt = "<iI" if bytes(data[1:2]) == b"\x01" else ">iI"      # the encapsulation's byte order
    sec, nanosec = struct.unpack_from(fmt, data, 4)
    return sec * 1_000_000_000 + nanosec


def point(x: float, y: float, z: float) -> Any:
    return typestore().types["geometry_msgs/msg/Point"](x=float(x), y=float(y), z=float(z))


def _vector(v: np.ndarray) -> Any:
    return typestore().types["geometry_msgs/msg/Vector3"](x=float(v[0]), y=float(v[1]), z=float(v[2]))


def mocap_frame(t_ns: int, names: list[str], positions_m: np.ndarray, valid: np.ndarray,
                residuals_m: np.ndarray | None = None, frame_id: str = LAB_FRAME) -> Any:
    """A sit2stand_msgs/MocapFrame; invalid markers get NaN positions whatever ``positions_m`` holds."""
    pos = np.asarray(positions_m, float)
    ok = np.asarray(valid, bool)
    res = np.full(len(names), np.nan, np.float32) if residuals_m is None else np.asarray(residuals_m, np.float32)
    nan = float("nan")
    pts = [point(*p) if v else point(nan, nan, nan) for p, v in zip(pos, ok)]
    return typestore().types[MOCAP_TYPE](header=header(t_ns, frame_id), marker_names=list(names), positions=pts,
                                         valid=ok.copy(), residuals_m=res.copy())


def mocap_arrays(msg: Any) -> tuple[list[str], np.ndarray, np.ndarray]:
    """(names, positions (M, 3) [m] with NaN where invalid, valid (M,)) of a MocapFrame."""
    pos = np.array([[p.x, p.y, p.z] for p in msg.positions], float).reshape(-1, 3)
    valid = np.asarray(msg.valid, bool)
    pos[~valid] = np.nan
    return list(msg.marker_names), pos, valid


def reorder_markers(names: list[str], positions_m: np.ndarray, valid: np.ndarray,
                    target_names: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """Positions (M', 3) [m] and validity (M',) in the order of ``target_names``, from a frame whose markers are
    ``names`` (a capture system may drop or add labels mid-trial). Markers the frame lacks are NaN and invalid."""
    if names == target_names:
        return positions_m, valid
    where = {n: i for i, n in enumerate(names)}
    pos = np.full((len(target_names), 3), np.nan)
    ok = np.zeros(len(target_names), bool)
    for j, n in enumerate(target_names):
        i = where.get(n)
        if i is not None:
            pos[j], ok[j] = positions_m[i], valid[i]
    return pos, ok


def force_plate_sample(t_ns: int, plate_name: str, force_n: np.ndarray, moment_origin_nm: np.ndarray,
                       cop_m: np.ndarray, cop_valid: bool, free_moment_nm: float,
                       frame_id: str = LAB_FRAME) -> Any:
    """A sit2stand_msgs/ForcePlateSample (moment about the lab origin)."""
    s = typestore().types
    wrench = s["geometry_msgs/msg/Wrench"](force=_vector(force_n), torque=_vector(moment_origin_nm))
    nan = float("nan")
    cop = point(*cop_m) if cop_valid else point(nan, nan, nan)
    return s[PLATE_TYPE](header=header(t_ns, frame_id), plate_name=plate_name, wrench=wrench, cop=cop,
                         cop_valid=bool(cop_valid), free_moment_z=float(free_moment_nm) if cop_valid else nan)


def plate_sample_from_cdr(data: bytes | memoryview) -> tuple[float, float, float, float, float, float, float]:
    """Stamp [s] and wrench (force [N], moment [N m]) of one serialized ForcePlateSample (CDR, as a raw
    subscription or a bag holds it), without building the message: a 1 kHz plate is 1000 Python messages a second
    otherwise. Layout: encapsulation (4 bytes), header (stamp sec int32, nanosec uint32, frame_id string),
    plate_name string, then the wrench's six float64, 8-byte aligned from the end of the encapsulation."""
    end = "<" if data[1] == 1 else ">"         # CDR_LE = 0x0001, CDR_BE = 0x0000
    sec, nsec, n = struct.unpack_from(end + "iII", data, 4)
    o = 16 + n                                  # past frame_id (length includes its NUL)
    o = (o + 3) & ~3
    (n,) = struct.unpack_from(end + "I", data, o)
    o += 4 + n                                  # past plate_name
    o = 4 + ((o - 4 + 7) & ~7)
    return ((sec * 1_000_000_000 + nsec) * 1e-9,) + struct.unpack_from(end + "6d", data, o)   # as stamp_ns() * 1e-9


def plate_messages(plate: PlateSeries, offset_s: float = 0.0) -> Iterator[tuple[int, Any]]:
    """(stamp [ns], ForcePlateSample) of each sample of ``plate``, stamped ``offset_s`` after its own times, for
    its topic :func:`~sit2stand.io.topics.plate_topic`."""
    for k, t in enumerate(plate.t_s):
        t_ns = int(round((offset_s + float(t)) * 1e9))
        yield t_ns, force_plate_sample(t_ns, plate.name, plate.force_n[k], plate.moment_origin_nm[k],
                                       plate.cop_m[k], bool(plate.cop_valid[k]), float(plate.free_moment_nm[k]))


def plate_series(name: str, stamped: list[tuple[int, Any]]) -> PlateSeries:
    """A :class:`~sit2stand.forceplate.PlateSeries` from (log time [ns], ForcePlateSample) pairs: force (K, 3)
    [N], moment about the lab origin (K, 3) [N m], COP (K, 3) [m] and its validity, free moment (K,) [N m]."""
    msgs = [m for _, m in stamped]
    force = np.array([[m.wrench.force.x, m.wrench.force.y, m.wrench.force.z] for m in msgs], float).reshape(-1, 3)
    moment = np.array([[m.wrench.torque.x, m.wrench.torque.y, m.wrench.torque.z] for m in msgs],
                      float).reshape(-1, 3)
    cop = np.array([[m.cop.x, m.cop.y, m.cop.z] for m in msgs], float).reshape(-1, 3)
    valid = np.array([m.cop_valid for m in msgs], bool)
    free = np.array([m.free_moment_z for m in msgs], float)
    t_s = np.array([t for t, _ in stamped], float) * 1e-9
    return PlateSeries(name, t_s, force, moment, cop, valid, free)


def center_of_mass(t_ns: int, position_m: np.ndarray, velocity_mps: np.ndarray, acceleration_mps2: np.ndarray,
                   source: str, valid: bool = True, marker_rms_m: float = float("nan"),
                   cop_error_m: float = float("nan"), n_markers: int = 0, frame_id: str = LAB_FRAME) -> Any:
    """A sit2stand_msgs/CenterOfMass."""
    s = typestore().types
    return s[COM_TYPE](header=header(t_ns, frame_id), position=point(*position_m), velocity=_vector(velocity_mps),
                       acceleration=_vector(acceleration_mps2), source=source, valid=bool(valid),
                       marker_rms_m=float(marker_rms_m), cop_error_m=float(cop_error_m), n_markers=int(n_markers))


ROBOT_STATE_TOPICS = {
    ROBOT_JOINT_STATES_TOPIC: "sensor_msgs/msg/JointState",
    ROBOT_FT_LEFT_TOPIC: "geometry_msgs/msg/WrenchStamped",
    ROBOT_FT_RIGHT_TOPIC: "geometry_msgs/msg/WrenchStamped",
    ROBOT_COP_TOPIC: "geometry_msgs/msg/PointStamped",
    ROBOT_BASE_POSE_TOPIC: "geometry_msgs/msg/PoseStamped",
}
"""What the robot driver publishes per state sample (and what robot bags written offline carry)."""


def robot_state(t_ns: int, joint_names: list[str], q: np.ndarray, qd: np.ndarray | None, tau: np.ndarray,
                wrench_world: dict[str, np.ndarray], cop_m: np.ndarray, base_pose: np.ndarray,
                root_frame: str) -> list[tuple[str, Any]]:
    """(topic, message) of one robot state sample, as the driver publishes it: joint states (frame: the robot's
    root link ``root_frame``; effort = measured torque [N m]), ground reaction per foot (world axes, torque about the
    sole point: frame ``sole_<side>_world_aligned``), COP (NaN when unloaded) and the base pose (``base_pose`` in MuJoCo
    order x y z qw qx qy qz)."""
    s = typestore().types
    out: list[tuple[str, Any]] = [(ROBOT_JOINT_STATES_TOPIC, s["sensor_msgs/msg/JointState"](
        header=header(t_ns, root_frame), name=list(joint_names), position=np.asarray(q, float),
        velocity=np.zeros(0) if qd is None else np.asarray(qd, float), effort=np.asarray(tau, float)))]
    for side, w in wrench_world.items():
        wrench = s["geometry_msgs/msg/Wrench"](force=_vector(w[:3]), torque=_vector(w[3:]))
        out.append((ft_topic(side), s["geometry_msgs/msg/WrenchStamped"](
            header=header(t_ns, sole_world_aligned_frame(side)), wrench=wrench)))
    out.append((ROBOT_COP_TOPIC, s["geometry_msgs/msg/PointStamped"](header=header(t_ns, WORLD_FRAME),
                                                                      point=point(*cop_m))))
    b = base_pose
    out.append((ROBOT_BASE_POSE_TOPIC, s["geometry_msgs/msg/PoseStamped"](
        header=header(t_ns, WORLD_FRAME), pose=s["geometry_msgs/msg/Pose"](
            position=point(*b[:3]), orientation=s["geometry_msgs/msg/Quaternion"](
                x=float(b[4]), y=float(b[5]), z=float(b[6]), w=float(b[3]))))))
    return out


def joint_trajectory_point(t_ns: int, joint_names: list[str], q: np.ndarray, qd: np.ndarray,
                           qdd: np.ndarray, root_frame: str) -> Any:
    """A one-point trajectory_msgs/JointTrajectory (frame: the robot's root link): the reference the driver applies
    at once."""
    s = typestore().types
    point = s["trajectory_msgs/msg/JointTrajectoryPoint"](
        positions=np.asarray(q, float), velocities=np.asarray(qd, float), accelerations=np.asarray(qdd, float),
        effort=np.zeros(0), time_from_start=s["builtin_interfaces/msg/Duration"](sec=0, nanosec=0))
    return s["trajectory_msgs/msg/JointTrajectory"](header=header(t_ns, root_frame), joint_names=list(joint_names),
                                                    points=[point])


def subject(t_ns: int, height_m: float, mass_kg: float, sex: str, age_years: float = float("nan")) -> Any:
    """sit2stand_msgs/Subject: the person a demonstration recorded (stature [m], body mass [kg], sex, age)."""
    return typestore().types[SUBJECT_TYPE](header=header(t_ns, ""), height_m=float(height_m),
                                           mass_kg=float(mass_kg), sex=str(sex), age_years=float(age_years))
