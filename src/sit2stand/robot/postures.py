"""Static postures for identification: plan statically stable stances, hold each on the plant, record the sensors.

:func:`plan_postures` samples hip, knee and torso pitch within the paper's ranges (hip 1.47, knee 1.69, torso 0.56
rad; left = right) and solves the ankle pitch that puts the **controller's** (CAD) COM over the middle of the feet,
plus a random offset; the ankle then spans ~0.56 rad. :func:`collect_postures` drives the plant to each posture,
lets it settle, averages the sensors and writes one bag message per posture; postures in which the robot tips
(the true COM is not where CAD thinks) are detected and dropped, as an operator would.

Bag topics (one message per posture, stamped at the end of its averaging window):
``/robot/joint_states`` (sensor_msgs/JointState: position, effort = measured torque), ``/robot/ft/left`` and
``/robot/ft/right`` (geometry_msgs/WrenchStamped: ground reaction in world axes about the sole point, frame
``sole_*_world_aligned``), ``/robot/cop`` (geometry_msgs/PointStamped), ``/robot/base_pose``
(geometry_msgs/PoseStamped, from the state estimator).
"""

from __future__ import annotations

import sys
from dataclasses import dataclass, replace
from pathlib import Path

import mujoco
import numpy as np
import pinocchio as pin

from ..io import messages as M
from ..io.bag import BagWriter
from ..io.topics import GROUND_TRUTH_ROBOT_COM_TOPIC, WORLD_FRAME
from ..io.typestore import typestore
from .model import SIDES, PlantConfig
from .profile import RobotProfile
from .plant import Plant, lowest_point

PAPER_RANGES = {"hip": 1.47, "knee": 1.69, "ankle": 0.56, "torso": 0.56}
"""The paper's ranges [rad]. A profile's ``posture_ranges`` take the trunk's whole flexion (TALOS: to its 0.785 rad
stop): a stand-up uses all of it, and a model identified only up to 0.56 rad misplaces the COM by ~3 cm there
(measured on TALOS's default plant)."""


def standup_ranges(profile: RobotProfile) -> dict[str, float]:
    """The ranges [rad] of the static postures of ``profile``'s robot (hip, knee and torso flexion)."""
    r = profile.posture_ranges
    return {"hip": r.hip, "knee": r.knee, "torso": r.trunk}


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
    cop_sd_m: float = 0.0    # standard deviation of the COP x over the averaging window


def _set_leg(plant: Plant, q: np.ndarray, hip: float, knee: float, ankle: float, torso: float) -> np.ndarray:
    """``q`` with both legs' sagittal joints at ``hip``, ``knee``, ``ankle``, the trunk pitch at ``torso`` [rad]
    (a robot without one: its trunk is leaned by the hips alone) and the legs' and trunk's lateral joints at zero."""
    profile = plant.cfg.profile
    q = q.copy()
    at = lambda joint: plant.qadr[plant.joint_names.index(joint)]  # noqa: E731
    for s in SIDES:
        for role, value in (("hip_pitch", hip), ("knee", knee), ("ankle_pitch", ankle)):
            q[at(profile.leg(s, role))] = value
    for joint in profile.lateral_joints():
        q[at(joint)] = 0.0
    if profile.trunk_pitch:
        q[at(profile.trunk_pitch)] = torso
    return q


def standing_qpos(plant: Plant, hip: float, knee: float, ankle: float, torso: float,
                  arms: dict[str, float] | None = None) -> np.ndarray:
    """MuJoCo qpos of a symmetric stance with both soles flat on the floor, feet centred at x = 0; ``arms``: joint
    name -> angle [rad] for arm joints (default: the seated posture's)."""
    q = _set_leg(plant, plant.q_seated, hip, knee, ankle, torso)
    for name, value in (arms or {}).items():
        q[plant.qadr[plant.joint_names.index(name)]] = value
    # base orientation that keeps the feet flat: pitch = -(hip + knee + ankle)
    pitch = -(hip + knee + ankle)
    q[3:7] = [np.cos(pitch / 2), 0.0, np.sin(pitch / 2), 0.0]
    q[:3] = [0.0, 0.0, 1.5]
    d = mujoco.MjData(plant.model)
    d.qpos[:] = q
    mujoco.mj_kinematics(plant.model, d)
    foot_z, _ = lowest_point(plant.model, d, tuple(plant.cfg.profile.foot_links.values()))
    sole_x = np.mean([d.site(f"sole_{s}").xpos[0] for s in SIDES])
    q[2] -= foot_z
    q[0] -= sole_x
    return q


def standing_pelvis_height_m(plant: Plant) -> float:
    """The pelvis height [m] of the robot standing upright on straight legs, soles on the floor."""
    return float(standing_qpos(plant, 0.0, 0.0, 0.0, 0.0)[2])


def random_arms(rng: np.random.Generator, profile: RobotProfile) -> dict[str, float]:
    """Angles [rad] of the profile's posture arm joints (shoulders, elbows) for both arms, each side drawn on its own
    within the profile's ranges (the right arm's mirrored where the profile says)."""
    ranges = profile.posture_ranges
    out = {}
    for side in SIDES:
        for template, (lo, hi) in ranges.arms.items():
            sign = -1.0 if side == "right" and template in ranges.mirrored else 1.0
            out[profile.side_name(template, side)] = sign * rng.uniform(lo, hi)
    return out


def cad_com_x(plant: Plant, qpos: np.ndarray) -> float:
    model, data = plant.ctrl, plant.onboard.data
    return float(pin.centerOfMass(model, data, plant.pin_configuration(qpos))[0])


def solve_ankle(plant: Plant, hip: float, knee: float, torso: float, com_x_m: float,
                arms: dict[str, float] | None = None) -> float | None:
    """Ankle pitch [rad] putting the controller's (CAD) COM at ``com_x_m`` (feet centred at 0), or None."""
    ankle = plant.model.joint(plant.cfg.profile.leg("left", "ankle_pitch")).range
    search = plant.cfg.profile.posture_ranges.ankle
    a_lo, a_hi = max(ankle[0], search[0]), min(ankle[1], search[1])
    f = lambda a: cad_com_x(plant, standing_qpos(plant, hip, knee, a, torso, arms)) - com_x_m  # noqa: E731
    f_lo, f_hi = f(a_lo), f(a_hi)
    if np.sign(f_lo) == np.sign(f_hi):
        return None
    for _ in range(30):       # COM x falls as the ankle pitch rises: bisection
        mid = 0.5 * (a_lo + a_hi)
        f_mid = f(mid)
        if np.sign(f_mid) == np.sign(f_lo):
            a_lo, f_lo = mid, f_mid
        else:
            a_hi = mid
    return 0.5 * (a_lo + a_hi)


def plan_postures(plant: Plant, n: int, seed: int = 0, com_offset_m: float = 0.025, com_centre_m: float = 0.02,
                  ranges: dict[str, float] | None = None, com_bias_m: float = 0.0,
                  move_arms: bool = True) -> list[np.ndarray]:
    """``n`` statically stable symmetric stances spanning the paper's joint ranges (qpos, MuJoCo order): the ankle
    puts the CAD COM at a random x within +-``com_offset_m`` of the sole's middle (``com_centre_m`` ahead of the
    ankles), corrected by ``com_bias_m`` (how far the
    real COM was measured from CAD's, e.g. by :func:`collect_postures` in its home stance). With ``move_arms`` the
    arms take random shoulder and elbow angles: with the arms always hanging, the arms' parameters cannot be told
    from the torso's, and a model identified so misplaces the COM by 2-3 cm once the arms move (measured)."""
    profile = plant.cfg.profile
    ranges = ranges or standup_ranges(profile)
    rng = np.random.default_rng(seed)
    out: list[np.ndarray] = []
    tries = 0
    while len(out) < n and tries < 50 * n:
        tries += 1
        hip = -rng.uniform(0.0, ranges["hip"])
        knee = rng.uniform(0.0, ranges["knee"])
        torso = rng.uniform(0.0, ranges["torso"])
        arms = random_arms(rng, profile) if move_arms else None
        ankle = solve_ankle(plant, hip, knee, torso,
                            com_centre_m + rng.uniform(-com_offset_m, com_offset_m) - com_bias_m, arms)
        if ankle is None:
            continue
        q = standing_qpos(plant, hip, knee, ankle, torso, arms)
        if q[2] < profile.posture_ranges.min_pelvis_height_m:   # too deep for the knees' torque at this mass
            continue
        out.append(q)
    return out


def settle(plant: Plant, qpos: np.ndarray, seconds: float = 3.5) -> bool:
    """Put the robot in ``qpos`` (feet flat) and hold it there under PD + gravity feed-forward for ``seconds``;
    False if it tipped over."""
    plant.reset(qpos)
    plant.command(qpos[plant.qadr], feedforward="gravity")
    plant.step(int(round(seconds / plant.cfg.timestep_s)))
    return not plant.fallen


def measure(plant: Plant, average_s: float = 0.3) -> PostureSample | None:
    """Average the sensors over ``average_s`` while holding; None if the feet moved or the COP was lost."""
    feet0 = {s: plant.data.site(f"sole_{s}").xpos.copy() for s in SIDES}
    samples = []
    for _ in range(int(average_s / plant.cfg.timestep_s / 10)):
        plant.step(10)
        samples.append(plant.sensors())
    moved = max(np.linalg.norm(plant.data.site(f"sole_{s}").xpos - feet0[s]) for s in SIDES)
    if plant.fallen or moved > 0.002 or not all(s.cop_valid for s in samples):
        return None
    mean = lambda xs: np.mean(xs, axis=0)  # noqa: E731
    return PostureSample(q=mean([s.q for s in samples]), tau=mean([s.tau for s in samples]),
                         wrench={side: mean([s.wrench_world[side] for s in samples]) for side in SIDES},
                         sole={side: plant.data.site(f"sole_{side}").xpos.copy() for side in SIDES},
                         cop=mean([s.cop_m for s in samples]), base_pose=plant.data.qpos[:7].copy(),
                         true_com=plant.true_com(), cop_sd_m=float(np.std([s.cop_m[0] for s in samples])))


def home_com_bias(plant: Plant) -> float:
    """As an operator would: stand still upright with the CAD COM 5 cm forward (room for mass the CAD model does
    not know about) and measure how far the real COM (the COP) is from CAD's [m, forward]."""
    for forward in (0.10, 0.05, 0.15, 0.0, 0.2):
        home = standing_qpos(plant, -0.1, 0.2, solve_ankle(plant, -0.1, 0.2, 0.0, forward), 0.0)
        if settle(plant, home) and plant.sensors().cop_valid:
            break
    else:
        raise RuntimeError("the robot cannot stand upright with its CAD COM anywhere over its feet; check the "
                           "plant's hidden masses")
    sample = measure(plant, 0.5)
    return float(sample.cop[0] - cad_com_x(plant, plant.data.qpos)) if sample is not None else 0.0


def collect_postures(cfg: PlantConfig, n: int, out: str | Path, seed: int = 0, progress: bool = True,
                     move_arms: bool = True) -> dict:
    """Plan, hold and record ``n`` postures into a bag (see the module docstring); returns counts."""


    # squats tilt the pelvis far forward: only a pelvis near the floor or unloaded feet count as a fall here
    plant = Plant(replace(cfg, fall_tilt_rad=np.pi), with_chair=False)
    bias = home_com_bias(plant)
    planned = plan_postures(plant, 3 * n + 10, seed=seed, com_bias_m=bias, move_arms=move_arms)
    store = typestore().types
    kept, dropped = 0, 0
    with BagWriter(out, custom_data={"source": "sit2stand collect-postures", "plant": cfg.name,
                                     "joint_names": ",".join(plant.joint_names)}) as bag:
        for topic, msgtype in M.ROBOT_STATE_TOPICS.items():
            bag.add_topic(topic, msgtype)
        bag.add_topic(GROUND_TRUTH_ROBOT_COM_TOPIC, "geometry_msgs/msg/PointStamped")
        for qpos in planned:
            if kept >= n:
                break
            sample = measure(plant) if settle(plant, qpos) else None
            if sample is not None and sample.cop_sd_m > 0.002:   # still swaying: give it another second
                plant.step(1000)
                sample = None if plant.fallen else measure(plant)
            if sample is None or sample.cop_sd_m > 0.002:
                dropped += 1
                continue
            kept += 1
            t_ns = kept * 2_000_000_000
            for topic, msg in M.robot_state(t_ns, plant.joint_names, sample.q, None, sample.tau, sample.wrench,
                                            sample.cop, sample.base_pose, plant.cfg.profile.root_link):
                bag.write(topic, t_ns, msg)
            bag.write(GROUND_TRUTH_ROBOT_COM_TOPIC, t_ns, store["geometry_msgs/msg/PointStamped"](
                header=M.header(t_ns, WORLD_FRAME), point=M.point(*sample.true_com)))
            if progress and kept % 10 == 0:
                print(f"  {kept}/{n} postures held ({dropped} tipped and dropped)", file=sys.stderr, flush=True)
    return {"kept": kept, "dropped": dropped, "home_com_bias_m": bias}
