"""Static postures for identification: plan statically stable stances, hold each on the plant, record the sensors.

:func:`plan_postures` samples hip, knee and torso pitch within the paper's ranges (hip 1.47, knee 1.69, torso 0.56
rad; left = right) and solves the ankle pitch that puts the **controller's** (CAD) COM over the middle of the feet,
plus a random offset; the ankle then spans ~0.56 rad. :func:`collect_postures` drives the plant to each posture,
lets it settle, averages the sensors and writes one bag message per posture; postures in which the robot tips
(the true COM is not where CAD thinks) are detected and dropped, as an operator would.

Bag topics (one message per posture, stamped at the end of its averaging window):
``/robot/joint_states`` (sensor_msgs/JointState: position, effort = measured torque), ``/robot/ft/left`` and
``/robot/ft/right`` (geometry_msgs/WrenchStamped: ground reaction in world axes about the sole, frame ``sole_*``),
``/robot/cop`` (geometry_msgs/PointStamped), ``/robot/base_pose`` (geometry_msgs/PoseStamped, from the state
estimator).
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np
import pinocchio as pin

from .model import SIDES, PlantConfig
from .plant import Plant, lowest_point

PAPER_RANGES = {"hip": 1.47, "knee": 1.69, "ankle": 0.56, "torso": 0.56}


@dataclass
class PostureSample:
    """Averaged sensor readings of one held posture."""

    q: np.ndarray            # joint positions [rad] (plant order)
    tau: np.ndarray          # measured joint torques [N m]
    wrench: dict[str, np.ndarray]   # side -> (6,) ground reaction, world axes, about the sole point
    sole: dict[str, np.ndarray]     # side -> sole position [m]
    cop: np.ndarray          # (3,)
    base_pose: np.ndarray    # (7,) MuJoCo order: x y z qw qx qy qz
    true_com: np.ndarray     # the plant's COM (evaluation only; never used for identification)


def _set_leg(plant: Plant, q: np.ndarray, hip: float, knee: float, ankle: float, torso: float) -> np.ndarray:
    q = q.copy()
    for s in SIDES:
        q[plant.qadr[plant.joint_names.index(f"leg_{s}_3_joint")]] = hip
        q[plant.qadr[plant.joint_names.index(f"leg_{s}_4_joint")]] = knee
        q[plant.qadr[plant.joint_names.index(f"leg_{s}_5_joint")]] = ankle
        for j in (1, 2, 6):
            q[plant.qadr[plant.joint_names.index(f"leg_{s}_{j}_joint")]] = 0.0
    q[plant.qadr[plant.joint_names.index("torso_2_joint")]] = torso
    q[plant.qadr[plant.joint_names.index("torso_1_joint")]] = 0.0
    return q


def standing_qpos(plant: Plant, hip: float, knee: float, ankle: float, torso: float) -> np.ndarray:
    """MuJoCo qpos of a symmetric stance with both soles flat on the floor, feet centred at x = 0."""
    q = _set_leg(plant, plant.q_seated, hip, knee, ankle, torso)
    # base orientation that keeps the feet flat: pitch = -(hip + knee + ankle)
    pitch = -(hip + knee + ankle)
    q[3:7] = [np.cos(pitch / 2), 0.0, np.sin(pitch / 2), 0.0]
    q[:3] = [0.0, 0.0, 1.5]
    d = mujoco.MjData(plant.model)
    d.qpos[:] = q
    mujoco.mj_kinematics(plant.model, d)
    foot_z, _ = lowest_point(plant.model, d, tuple(f"leg_{s}_6_link" for s in SIDES))
    sole_x = np.mean([d.site(f"sole_{s}").xpos[0] for s in SIDES])
    q[2] -= foot_z
    q[0] -= sole_x
    return q


def cad_com_x(plant: Plant, qpos: np.ndarray) -> float:
    model, data = plant.ctrl, plant.ctrl_data
    return float(pin.centerOfMass(model, data, plant.pin_configuration(qpos))[0])


def plan_postures(plant: Plant, n: int, seed: int = 0, com_offset_m: float = 0.02,
                  ranges: dict[str, float] = PAPER_RANGES) -> list[np.ndarray]:
    """``n`` statically stable (by CAD) symmetric stances spanning the paper's joint ranges (qpos, MuJoCo order)."""
    rng = np.random.default_rng(seed)
    lo = {n_: plant.model.joint(n_).range[0] for n_ in ("leg_left_3_joint", "leg_left_4_joint", "leg_left_5_joint",
                                                         "torso_2_joint")}
    hi = {n_: plant.model.joint(n_).range[1] for n_ in lo}
    out: list[np.ndarray] = []
    tries = 0
    while len(out) < n and tries < 50 * n:
        tries += 1
        hip = -rng.uniform(0.0, ranges["hip"])
        knee = rng.uniform(0.0, ranges["knee"])
        torso = rng.uniform(0.0, ranges["torso"])
        target = rng.uniform(-com_offset_m, com_offset_m)
        # bisection on the ankle so that the CAD COM is at the target x (COM x decreases as the ankle plantarflexes)
        a_lo, a_hi = max(lo["leg_left_5_joint"], -ranges["ankle"] - 0.2), min(hi["leg_left_5_joint"], 0.4)
        f = lambda a: cad_com_x(plant, standing_qpos(plant, hip, knee, a, torso)) - target  # noqa: E731
        f_lo, f_hi = f(a_lo), f(a_hi)
        if np.sign(f_lo) == np.sign(f_hi):
            continue
        for _ in range(30):
            mid = 0.5 * (a_lo + a_hi)
            if np.sign(f(mid)) == np.sign(f_lo):
                a_lo, f_lo = mid, f(mid)
            else:
                a_hi = mid
        q = standing_qpos(plant, hip, knee, 0.5 * (a_lo + a_hi), torso)
        if q[2] < 0.45:   # too deep for the knees' torque at this mass
            continue
        out.append(q)
    return out


def hold_and_measure(plant: Plant, qpos: np.ndarray, settle_s: float = 1.5, average_s: float = 0.3,
                     cop_target_m: float = 0.02, gain_rad_per_m: float = 0.3) -> PostureSample | None:
    """Start in ``qpos``, hold it under PD + gravity feed-forward while trimming both ankle pitches from the
    measured COP (from the feet's F/T sensors, as an operator balancing the robot would) until it sits over the
    mid-foot; then average the sensors. None if the robot tipped or a foot moved."""
    plant.reset(qpos)
    ref = qpos[plant.qadr].copy()
    ankles = [plant.joint_names.index(f"leg_{s}_5_joint") for s in SIDES]
    plant.command(ref, feedforward="gravity")
    steps = int(0.05 / plant.cfg.timestep_s)
    for k in range(int(settle_s / 0.05)):
        plant.step(steps)
        sens = plant.sensors()
        if plant.fallen or (k >= 4 and not sens.cop_valid):
            return None
        if sens.cop_valid:   # COM behind the target -> lower the ankle pitch (COM x falls ~0.76 m/rad as it rises)
            ref[ankles] += gain_rad_per_m * (sens.cop_m[0] - cop_target_m)
            plant.command(ref)
    feet0 = {s: plant.data.site(f"sole_{s}").xpos.copy() for s in SIDES}
    samples = []
    for _ in range(int(average_s / plant.cfg.timestep_s / 10)):
        plant.step(10)
        samples.append(plant.sensors())
    moved = max(np.linalg.norm(plant.data.site(f"sole_{s}").xpos - feet0[s]) for s in SIDES)
    if plant.fallen or moved > 0.003 or not all(s.cop_valid for s in samples):
        return None
    mean = lambda xs: np.mean(xs, axis=0)  # noqa: E731
    return PostureSample(q=mean([s.q for s in samples]), tau=mean([s.tau for s in samples]),
                         wrench={side: mean([s.wrench_world[side] for s in samples]) for side in SIDES},
                         sole={side: plant.data.site(f"sole_{side}").xpos.copy() for side in SIDES},
                         cop=mean([s.cop_m for s in samples]), base_pose=plant.data.qpos[:7].copy(),
                         true_com=plant.true_com())


def collect_postures(cfg: PlantConfig, n: int, out: str | Path, seed: int = 0, progress: bool = True) -> dict:
    """Plan, hold and record ``n`` postures into a bag (see the module docstring); returns counts."""
    from ..io import messages as M
    from ..io.bag import BagWriter
    from ..io.typestore import typestore

    from dataclasses import replace

    # squats tilt the pelvis far forward: only a pelvis near the floor or unloaded feet count as a fall here
    plant = Plant(replace(cfg, fall_tilt_rad=np.pi), with_chair=False)
    planned = plan_postures(plant, int(n * 1.6) + 5, seed=seed)
    store = typestore().types
    kept, dropped = 0, 0
    with BagWriter(out, custom_data={"source": "sit2stand collect-postures", "plant": cfg.name,
                                     "joint_names": ",".join(plant.joint_names)}) as bag:
        for topic, msgtype in (("/robot/joint_states", "sensor_msgs/msg/JointState"),
                               ("/robot/ft/left", "geometry_msgs/msg/WrenchStamped"),
                               ("/robot/ft/right", "geometry_msgs/msg/WrenchStamped"),
                               ("/robot/cop", "geometry_msgs/msg/PointStamped"),
                               ("/robot/base_pose", "geometry_msgs/msg/PoseStamped"),
                               ("/ground_truth/robot_com", "geometry_msgs/msg/PointStamped")):
            bag.add_topic(topic, msgtype)
        V = lambda v: store["geometry_msgs/msg/Vector3"](x=float(v[0]), y=float(v[1]), z=float(v[2]))  # noqa
        P = lambda v: store["geometry_msgs/msg/Point"](x=float(v[0]), y=float(v[1]), z=float(v[2]))  # noqa
        for qpos in planned:
            if kept >= n:
                break
            sample = hold_and_measure(plant, qpos)
            if sample is None:
                dropped += 1
                continue
            kept += 1
            t_ns = kept * 2_000_000_000
            h = lambda frame: M.header(t_ns, frame)  # noqa: E731
            bag.write("/robot/joint_states", t_ns, store["sensor_msgs/msg/JointState"](
                header=h("base_link"), name=plant.joint_names, position=sample.q, velocity=np.zeros(0),
                effort=sample.tau))
            for side in SIDES:
                w = sample.wrench[side]
                bag.write(f"/robot/ft/{side}", t_ns, store["geometry_msgs/msg/WrenchStamped"](
                    header=h(f"sole_{side}@{sample.sole[side][0]:.6f},{sample.sole[side][1]:.6f},"
                             f"{sample.sole[side][2]:.6f}"),
                    wrench=store["geometry_msgs/msg/Wrench"](force=V(w[:3]), torque=V(w[3:]))))
            bag.write("/robot/cop", t_ns, store["geometry_msgs/msg/PointStamped"](header=h("world"), point=P(sample.cop)))
            b = sample.base_pose
            bag.write("/robot/base_pose", t_ns, store["geometry_msgs/msg/PoseStamped"](
                header=h("world"), pose=store["geometry_msgs/msg/Pose"](
                    position=P(b[:3]), orientation=store["geometry_msgs/msg/Quaternion"](
                        x=float(b[4]), y=float(b[5]), z=float(b[6]), w=float(b[3])))))
            bag.write("/ground_truth/robot_com", t_ns, store["geometry_msgs/msg/PointStamped"](
                header=h("world"), point=P(sample.true_com)))
            if progress and kept % 10 == 0:
                print(f"  {kept}/{n} postures held ({dropped} tipped and dropped)", file=sys.stderr, flush=True)
    return {"kept": kept, "dropped": dropped}
